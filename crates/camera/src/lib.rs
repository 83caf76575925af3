//! Satellite camera geometry.
