//! `dataset build`: the 25 left/right combinations per selected pair in the training layout.
