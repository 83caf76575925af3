//! Seasonal variants that keep the geometry (see the crate description).
