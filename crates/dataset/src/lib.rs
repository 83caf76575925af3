//! Training sets on disk (see the crate description).
