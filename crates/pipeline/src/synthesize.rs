//! `synthesize`: seasonal variants of the selected images, checked for geometry and rectified.
