//! The shapes of the 2-D convolution kernels: an NCHW tensor's, and a convolution's and a
//! transposed convolution's kernel, stride, padding and dilation.

/// Shape of an NCHW tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Nchw {
    pub b: usize,
    pub c: usize,
    pub h: usize,
    pub w: usize,
}

/// Kernel size, stride, zero padding `[top, left, bottom, right]` and dilation of a convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Geometry {
    pub kernel: [usize; 2],
    pub stride: [usize; 2],
    pub padding: [usize; 4],
    pub dilation: [usize; 2],
}

impl Geometry {
    /// `[hp, wp]`: the size of an `h × w` input with its padding.
    pub fn padded(&self, [h, w]: [usize; 2]) -> [usize; 2] {
        let [top, left, bottom, right] = self.padding;
        [h + top + bottom, w + left + right]
    }

    /// Output `[oh, ow]` for an `h × w` input.
    pub fn output(&self, [h, w]: [usize; 2]) -> [usize; 2] {
        let span = |k: usize, d: usize| d * (k - 1) + 1;
        let [hp, wp] = self.padded([h, w]);
        let (kh, kw) = (
            span(self.kernel[0], self.dilation[0]),
            span(self.kernel[1], self.dilation[1]),
        );
        assert!(
            hp >= kh && wp >= kw,
            "convolution: kernel larger than the padded input"
        );
        [
            (hp - kh) / self.stride[0] + 1,
            (wp - kw) / self.stride[1] + 1,
        ]
    }
}

/// Kernel size, stride, padding `[ph, pw]` (removed from both sides), dilation and extra
/// output padding of a transposed convolution (PyTorch's `ConvTranspose2d` arguments).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TransposeGeometry {
    pub kernel: [usize; 2],
    pub stride: [usize; 2],
    pub padding: [usize; 2],
    pub dilation: [usize; 2],
    pub padding_out: [usize; 2],
}

impl TransposeGeometry {
    /// Output `[oh, ow]` for an `h × w` input: `(h−1)·s − 2p + d·(k−1) + p_out + 1`.
    pub fn output(&self, [h, w]: [usize; 2]) -> [usize; 2] {
        let size = |n: usize, a: usize| {
            ((n - 1) * self.stride[a]
                + self.dilation[a] * (self.kernel[a] - 1)
                + self.padding_out[a]
                + 1)
            .checked_sub(2 * self.padding[a])
            .expect("transposed convolution: padding larger than the output")
        };
        [size(h, 0), size(w, 1)]
    }
}
