//! Resampling to a new size with the exact filters of the reference pre-processing (PIL, torch antialias).
