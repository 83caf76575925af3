//! `masks`: water, tree and building masks from one segmentation pass per image.
