//! Reading and writing the raster formats users already have.
