//! What ends a fused convolution: a per-channel affine map (bias, a folded BatchNorm) and an
//! activation, applied while the kernels write their output.

use rayon::prelude::*;

/// The activation that ends a fused layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Activation {
    Identity,
    Relu,
    LeakyRelu(f32),
}

impl Activation {
    #[inline]
    pub fn apply(self, v: f32) -> f32 {
        match self {
            Activation::Identity => v,
            Activation::Relu => v.max(0.0),
            Activation::LeakyRelu(slope) => {
                if v >= 0.0 {
                    v
                } else {
                    v * slope
                }
            }
        }
    }
}

/// `out[c] = act(scale[c]·acc[c] + shift[c])`, per output channel (`None`: 1 and 0).
#[derive(Debug, Clone, Copy)]
pub struct Epilogue<'a> {
    pub scale: Option<&'a [f32]>,
    pub shift: Option<&'a [f32]>,
    pub act: Activation,
}

impl<'a> Epilogue<'a> {
    /// A bias and nothing else.
    pub fn bias(bias: Option<&'a [f32]>) -> Self {
        Epilogue {
            scale: None,
            shift: bias,
            act: Activation::Identity,
        }
    }

    #[inline]
    pub(super) fn channel(&self, c: usize) -> (f32, f32) {
        (
            self.scale.map_or(1.0, |s| s[c]),
            self.shift.map_or(0.0, |s| s[c]),
        )
    }

    /// Applies the map in place to one image `[co, plane]`.
    pub(super) fn apply(&self, image: &mut [f32], plane: usize) {
        if self.scale.is_none() && self.shift.is_none() && self.act == Activation::Identity {
            return;
        }
        image
            .par_chunks_mut(plane)
            .enumerate()
            .for_each(|(c, values)| {
                let (scale, shift) = self.channel(c);
                for v in values {
                    *v = self.act.apply(*v * scale + shift);
                }
            });
    }
}
