//! Structural similarity (SSIM).
