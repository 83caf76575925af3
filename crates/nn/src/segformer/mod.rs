//! SegFormer semantic segmentation (OpenEarthMap classes).
