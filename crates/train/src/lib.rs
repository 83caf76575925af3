//! Fine-tuning MonSter++ with the SeasonStereo loss (see the crate description).
