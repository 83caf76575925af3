//! Colour maps for disparity and height rasters.
