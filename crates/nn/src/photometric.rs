//! The photometric error map of self-supervised stereo losses,
//! `α·mean_c (1 − SSIM)/2 + (1 − α)·mean_c |x − y|`, as one burn operation on the CPU device,
//! differentiable in the reconstruction `y` (the reference image `x` is data).
//!
//! Why: on tensors the map is about twenty element-wise operations and ten box pools per
//! prediction, forward and backward, each a pass of burn's single-threaded CPU kernels over the
//! full-resolution images; MonSter++'s loss evaluates it for every one of its `iters + 7`
//! predictions. Here the forward is five box means and one pass per pixel, and the backward
//! three box means of per-pixel coefficients: the box mean with zero padding (PyTorch's
//! `avg_pool2d(k, 1, k/2)`, padding counted) is its own adjoint.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex};
use burn::tensor::{DType, Device, Tensor};
use rayon::prelude::*;

use crate::custom_op::{register, step_inputs, RecordOp};
use crate::flex_tensor::{dims, tensor, values};

/// SSIM stabilisers for images in `[0, 1]`: `C1 = 0.01²`, `C2 = 0.03²` (Monodepth's).
const C1: f32 = 0.01 * 0.01;
const C2: f32 = 0.03 * 0.03;

/// Smallest SSIM denominator (the release clamps it to 1e-8).
const MIN_DENOMINATOR: f32 = 1e-8;

/// How the map weighs SSIM against L1, and the SSIM window (odd).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Photometric {
    pub alpha: f32,
    pub window: usize,
}

/// The photometric error map `[B, 1, H, W]` between `x` and `y` (`[B, C, H, W]`), differentiable
/// in `y`; `None` where the kernel does not apply (not the CPU device, not `f32`), for the caller
/// to compose it from tensor operations.
pub fn photometric_map(x: Tensor<4>, y: Tensor<4>, options: Photometric) -> Option<Tensor<4>> {
    let cpu = x.device().inner() == Device::flex() && y.device().inner() == Device::flex();
    if !cpu
        || x.dtype() != DType::F32
        || y.dtype() != DType::F32
        || options.window.is_multiple_of(2)
    {
        return None;
    }
    Some(Tensor::from_dispatch(
        <Dispatch as PhotometricKernels>::kernel_photometric(
            x.detach().into_dispatch(),
            y.into_dispatch(),
            options,
        ),
    ))
}

/// `(1/k²)·Σ` over the `k × k` window centred on each pixel of an `h × w` plane, zeros outside
/// (separable: along rows, then along columns).
fn box_mean(plane: &[f32], [h, w]: [usize; 2], k: usize) -> Vec<f32> {
    let r = k / 2;
    let mut rows = vec![0.0f32; h * w];
    for (src, dst) in plane.chunks_exact(w).zip(rows.chunks_exact_mut(w)) {
        for (x, d) in dst.iter_mut().enumerate() {
            *d = src[x.saturating_sub(r)..(x + r + 1).min(w)].iter().sum();
        }
    }
    let scale = 1.0 / (k * k) as f32;
    let mut out = vec![0.0f32; h * w];
    for y in 0..h {
        let dst = &mut out[y * w..][..w];
        for source in y.saturating_sub(r)..(y + r + 1).min(h) {
            for (d, s) in dst.iter_mut().zip(&rows[source * w..][..w]) {
                *d += s;
            }
        }
        dst.iter_mut().for_each(|d| *d *= scale);
    }
    out
}

/// The window statistics of one channel plane.
struct Statistics {
    mu_x: Vec<f32>,
    mu_y: Vec<f32>,
    xx: Vec<f32>,
    yy: Vec<f32>,
    xy: Vec<f32>,
}

impl Statistics {
    fn new(x: &[f32], y: &[f32], size: [usize; 2], k: usize) -> Self {
        let product =
            |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(a, b)| a * b).collect::<Vec<_>>();
        Statistics {
            mu_x: box_mean(x, size, k),
            mu_y: box_mean(y, size, k),
            xx: box_mean(&product(x, x), size, k),
            yy: box_mean(&product(y, y), size, k),
            xy: box_mean(&product(x, y), size, k),
        }
    }

    /// SSIM at pixel `p` and its partial derivatives with respect to the box means of `y`, `y²`
    /// and `x·y`.
    fn ssim(&self, p: usize) -> (f32, [f32; 3]) {
        let (mx, my) = (self.mu_x[p], self.mu_y[p]);
        let a1 = 2.0 * mx * my + C1;
        let a2 = 2.0 * (self.xy[p] - mx * my) + C2;
        let d1 = mx * mx + my * my + C1;
        let d2 = (self.xx[p] - mx * mx) + (self.yy[p] - my * my) + C2;
        let raw = d1 * d2;
        let d = raw.max(MIN_DENOMINATOR);
        let s = a1 * a2 / d;
        // ∂S/∂D is zero where the denominator is clamped.
        let ds_dd = if raw > MIN_DENOMINATOR { -s / d } else { 0.0 };
        let d_my = 2.0 * mx * (a2 - a1) / d + ds_dd * 2.0 * my * (d2 - d1);
        (s, [d_my, ds_dd * d1, 2.0 * a1 / d])
    }
}

#[backend_extension(Flex, Autodiff)]
pub trait PhotometricKernels: Backend {
    /// See [`photometric_map`]; `x` is detached.
    fn kernel_photometric(
        x: FloatTensor<Self>,
        y: FloatTensor<Self>,
        options: Photometric,
    ) -> FloatTensor<Self>;
}

/// The gradient of [`PhotometricKernels::kernel_photometric`] with respect to `y`.
pub trait PhotometricGradKernels: PhotometricKernels {
    fn kernel_photometric_grad(
        x: FloatTensor<Self>,
        y: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        options: Photometric,
    ) -> FloatTensor<Self>;
}

impl PhotometricKernels for Flex {
    fn kernel_photometric(x: FlexTensor, y: FlexTensor, options: Photometric) -> FlexTensor {
        let [b, c, h, w] = dims(&x);
        assert_eq!(
            dims(&y),
            [b, c, h, w],
            "photometric map: image sizes differ"
        );
        let (x, y) = (values(&x), values(&y));
        let plane = h * w;
        // Per image and channel, the channel's share of the map.
        let shares: Vec<Vec<f32>> = (0..b * c)
            .into_par_iter()
            .map(|i| {
                let (x, y) = (&x[i * plane..][..plane], &y[i * plane..][..plane]);
                let stats = Statistics::new(x, y, [h, w], options.window);
                (0..plane)
                    .map(|p| {
                        let (s, _) = stats.ssim(p);
                        let l1 = (x[p] - y[p]).abs();
                        (options.alpha * 0.5 * (1.0 - s) + (1.0 - options.alpha) * l1) / c as f32
                    })
                    .collect()
            })
            .collect();
        let mut map = vec![0.0f32; b * plane];
        for (i, share) in shares.iter().enumerate() {
            let dst = &mut map[i / c * plane..][..plane];
            dst.iter_mut().zip(share).for_each(|(d, s)| *d += s);
        }
        tensor(map, [b, 1, h, w])
    }
}

impl PhotometricGradKernels for Flex {
    fn kernel_photometric_grad(
        x: FlexTensor,
        y: FlexTensor,
        grad: FlexTensor,
        options: Photometric,
    ) -> FlexTensor {
        let [b, c, h, w] = dims(&x);
        let (x, y, grad) = (values(&x), values(&y), values(&grad));
        let plane = h * w;
        let size = [h, w];
        let k = options.window;
        let mut dy = vec![0.0f32; b * c * plane];
        dy.par_chunks_exact_mut(plane)
            .enumerate()
            .for_each(|(i, dst)| {
                let (x, y) = (&x[i * plane..][..plane], &y[i * plane..][..plane]);
                let g = &grad[i / c * plane..][..plane];
                let stats = Statistics::new(x, y, size, k);
                // dL/dS at each pixel, times ∂S/∂(box means of y, y², x·y).
                let ssim_scale = -options.alpha * 0.5 / c as f32;
                let mut coefficients = [
                    vec![0.0f32; plane],
                    vec![0.0f32; plane],
                    vec![0.0f32; plane],
                ];
                for p in 0..plane {
                    let (_, partials) = stats.ssim(p);
                    for (coefficient, partial) in coefficients.iter_mut().zip(partials) {
                        coefficient[p] = ssim_scale * g[p] * partial;
                    }
                }
                let [by, byy, bxy] = coefficients.map(|f| box_mean(&f, size, k));
                let l1_scale = (1.0 - options.alpha) / c as f32;
                for p in 0..plane {
                    let diff = y[p] - x[p];
                    let sign = if diff > 0.0 {
                        1.0
                    } else if diff < 0.0 {
                        -1.0
                    } else {
                        0.0
                    };
                    dst[p] = by[p] + 2.0 * y[p] * byy[p] + x[p] * bxy[p] + l1_scale * g[p] * sign;
                }
            });
        tensor(dy, [b, c, h, w])
    }
}

/// The backward step of [`PhotometricKernels::kernel_photometric`]; state: both images and the
/// options.
#[derive(Debug)]
struct PhotometricBackward;

impl<B: PhotometricGradKernels> Backward<B, 1> for PhotometricBackward {
    type State = (FloatTensor<B>, FloatTensor<B>, Photometric);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let (grad, (x, y, options), [y_parent]) = step_inputs::<B, _, 1>(ops, grads);
        register::<B>(grads, y_parent, || {
            B::kernel_photometric_grad(x, y, grad, options)
        });
    }
}

impl<B: PhotometricGradKernels, C: CheckpointStrategy> PhotometricKernels for Autodiff<B, C> {
    fn kernel_photometric(
        x: FloatTensor<Self>,
        y: FloatTensor<Self>,
        options: Photometric,
    ) -> FloatTensor<Self> {
        PhotometricBackward.record::<C, _>(
            [y],
            x.into_primitive(),
            |_, [y], x| (x.clone(), y.primitive().clone(), options),
            |[y], x| B::kernel_photometric(x, y, options),
        )
    }
}
