//! A small training set from the procedural world, in the training layout.
