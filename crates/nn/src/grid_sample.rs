//! Bilinear `grid_sample` (zeros or border padding) as one burn operation on the CPU in training,
//! with a backward for the sampled image and for the grid.
//!
//! Why: burn's autodiff runs `grid_sample` as its reference composition (some forty tracked
//! tensor operations: slices, clamps, floors, four gathers, masks), each with its backward (four
//! scatters among them), single-threaded below a few million elements. MonSter++ warps the right
//! features every iteration (`disp_warp`, REMP) and the SeasonStereo loss warps the right image
//! for every prediction. Here the forward is one pass over the output, the backward one pass per
//! image channel for the image gradient and one over the output for the grid's.
//!
//! Semantics are burn's (and PyTorch's): the grid is unnormalised with `(g + 1)·(size − 1)/2`
//! (`align_corners`) or `(g + 1)·size/2 − 0.5`; border padding clamps the position to
//! `[0, size − 1]` (gradient 0 where clamped, as burn's clamp), zeros padding reads 0 outside.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex};
use burn::tensor::ops::{GridSampleOptions, GridSamplePaddingMode, InterpolateMode};
use burn::tensor::{DType, Tensor};
use rayon::prelude::*;

use crate::cpu_mode::on_cpu_training;
use crate::custom_op::{register, step_inputs, RecordOp};
use crate::flex_tensor::{dims, tensor, values};

/// `input.grid_sample_2d(grid, options)` (`input` `[N, C, H, W]`, `grid` `[N, Ho, Wo, 2]` of
/// normalised `(x, y)`): the one-pass kernel on the CPU in training for bilinear sampling with
/// zeros or border padding, burn's elsewhere.
pub fn grid_sample_2d(input: Tensor<4>, grid: Tensor<4>, options: GridSampleOptions) -> Tensor<4> {
    let border = match options.padding_mode {
        GridSamplePaddingMode::Border => Some(true),
        GridSamplePaddingMode::Zeros => Some(false),
        _ => None,
    };
    let bilinear = matches!(options.mode, InterpolateMode::Bilinear);
    match border {
        Some(border)
            if bilinear
                && on_cpu_training(&input)
                && input.dtype() == DType::F32
                && grid.dtype() == DType::F32 =>
        {
            let sampling = Sampling {
                border,
                align_corners: options.align_corners,
            };
            Tensor::from_dispatch(<Dispatch as GridSampleKernels>::kernel_grid_sample(
                input.into_dispatch(),
                grid.into_dispatch(),
                sampling,
            ))
        }
        _ => input.grid_sample_2d(grid, options),
    }
}

/// Padding and grid convention of a bilinear sampling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sampling {
    /// Border padding (positions clamped) rather than zeros.
    pub border: bool,
    pub align_corners: bool,
}

/// One axis of a sampled position: the two taps, their weights' fraction, and the factor that
/// carries `∂/∂position` back to the normalised grid coordinate.
#[derive(Debug, Clone, Copy)]
struct Taps {
    /// The lower tap and whether each tap reads the image (zeros padding: inside it).
    lo: usize,
    hi: usize,
    lo_in: bool,
    hi_in: bool,
    frac: f32,
    /// `∂position/∂g` (0 where the border clamped it).
    dpos: f32,
}

impl Sampling {
    fn taps(self, g: f32, size: usize) -> Taps {
        let n = size as f64;
        let (scale, shift) = if self.align_corners {
            (((n - 1.0) / 2.0) as f32, 0.0)
        } else {
            ((n / 2.0) as f32, 0.5)
        };
        let mut p = (g + 1.0) * scale - shift;
        let mut dpos = scale;
        let max = (size - 1) as f32;
        if self.border {
            if !(0.0..=max).contains(&p) {
                dpos = 0.0;
            }
            p = p.clamp(0.0, max);
        }
        let floor = p.floor();
        let frac = p - floor;
        let (i0, i1) = (floor as i64, floor as i64 + 1);
        let inside = |i: i64| i >= 0 && i < size as i64;
        let clamp = |i: i64| i.clamp(0, size as i64 - 1) as usize;
        Taps {
            lo: clamp(i0),
            hi: clamp(i1),
            lo_in: self.border || inside(i0),
            hi_in: self.border || inside(i1),
            frac,
            dpos,
        }
    }
}

/// The four bilinear weights and addresses of one output position in an `h × w` plane.
#[derive(Debug, Clone, Copy)]
struct Corners {
    at: [usize; 4],
    weight: [f32; 4],
    used: [bool; 4],
    x: Taps,
    y: Taps,
}

fn corners(sampling: Sampling, gx: f32, gy: f32, [h, w]: [usize; 2]) -> Corners {
    let (x, y) = (sampling.taps(gx, w), sampling.taps(gy, h));
    let (fx, fy) = (x.frac, y.frac);
    Corners {
        at: [
            y.lo * w + x.lo,
            y.lo * w + x.hi,
            y.hi * w + x.lo,
            y.hi * w + x.hi,
        ],
        weight: [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ],
        used: [
            x.lo_in && y.lo_in,
            x.hi_in && y.lo_in,
            x.lo_in && y.hi_in,
            x.hi_in && y.hi_in,
        ],
        x,
        y,
    }
}

/// The corners of every output position of an `[n, ho, wo, 2]` grid (row-major), computed once
/// and shared by all channel planes and both gradient passes.
fn corner_table(grid: &[f32], sampling: Sampling, size: [usize; 2]) -> Vec<Corners> {
    grid.par_chunks_exact(2)
        .map(|xy| corners(sampling, xy[0], xy[1], size))
        .collect()
}

#[backend_extension(Flex, Autodiff)]
pub trait GridSampleKernels: Backend {
    /// [`grid_sample_2d`], bilinear.
    fn kernel_grid_sample(
        input: FloatTensor<Self>,
        grid: FloatTensor<Self>,
        sampling: Sampling,
    ) -> FloatTensor<Self>;
}

/// The gradients of [`GridSampleKernels::kernel_grid_sample`]: `(∂L/∂input, ∂L/∂grid)`.
pub trait GridSampleGradKernels: GridSampleKernels {
    fn kernel_grid_sample_grad(
        input: FloatTensor<Self>,
        grid: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        sampling: Sampling,
    ) -> (FloatTensor<Self>, FloatTensor<Self>);
}

impl GridSampleKernels for Flex {
    fn kernel_grid_sample(input: FlexTensor, grid: FlexTensor, sampling: Sampling) -> FlexTensor {
        let [n, c, h, w] = dims(&input);
        let [_, ho, wo, _] = dims(&grid);
        let image = values(&input);
        let table = corner_table(&values(&grid), sampling, [h, w]);
        let mut out = vec![0.0f32; n * c * ho * wo];
        out.par_chunks_exact_mut(ho * wo)
            .enumerate()
            .for_each(|(plane, dst)| {
                let b = plane / c;
                let src = &image[plane * h * w..][..h * w];
                let table = &table[b * ho * wo..][..ho * wo];
                for (d, k) in dst.iter_mut().zip(table) {
                    *d = (0..4)
                        .filter(|&i| k.used[i])
                        .map(|i| k.weight[i] * src[k.at[i]])
                        .sum();
                }
            });
        tensor(out, [n, c, ho, wo])
    }
}

impl GridSampleGradKernels for Flex {
    fn kernel_grid_sample_grad(
        input: FlexTensor,
        grid: FlexTensor,
        grad: FlexTensor,
        sampling: Sampling,
    ) -> (FlexTensor, FlexTensor) {
        let [n, c, h, w] = dims(&input);
        let [_, ho, wo, _] = dims(&grid);
        let (image, grad) = (values(&input), values(&grad));
        let table = corner_table(&values(&grid), sampling, [h, w]);
        // ∂L/∂input: each plane scatters its own output gradient (planes are independent).
        let mut d_input = vec![0.0f32; n * c * h * w];
        d_input
            .par_chunks_exact_mut(h * w)
            .enumerate()
            .for_each(|(plane, dst)| {
                let b = plane / c;
                let table = &table[b * ho * wo..][..ho * wo];
                let up = &grad[plane * ho * wo..][..ho * wo];
                for (&u, k) in up.iter().zip(table) {
                    for i in (0..4).filter(|&i| k.used[i]) {
                        dst[k.at[i]] += k.weight[i] * u;
                    }
                }
            });
        // ∂L/∂grid: per output position, the channels' sum of the gradient times the bilinear
        // surface's slope along x and y.
        let mut d_grid = vec![0.0f32; n * ho * wo * 2];
        d_grid
            .par_chunks_exact_mut(wo * 2)
            .enumerate()
            .for_each(|(row, dst)| {
                let b = row / ho;
                let table = &table[row * wo..][..wo];
                for (ox, (d, k)) in dst.chunks_exact_mut(2).zip(table).enumerate() {
                    let (fx, fy) = (k.x.frac, k.y.frac);
                    let (mut sx, mut sy) = (0.0f32, 0.0f32);
                    for ch in 0..c {
                        let plane = b * c + ch;
                        let src = &image[plane * h * w..][..h * w];
                        let v = |i: usize| if k.used[i] { src[k.at[i]] } else { 0.0 };
                        let (v00, v10, v01, v11) = (v(0), v(1), v(2), v(3));
                        let u = grad[plane * ho * wo + (row % ho) * wo + ox];
                        sx += u * ((1.0 - fy) * (v10 - v00) + fy * (v11 - v01));
                        sy += u * ((1.0 - fx) * (v01 - v00) + fx * (v11 - v10));
                    }
                    d[0] = sx * k.x.dpos;
                    d[1] = sy * k.y.dpos;
                }
            });
        (
            tensor(d_input, [n, c, h, w]),
            tensor(d_grid, [n, ho, wo, 2]),
        )
    }
}

/// The backward step of [`GridSampleKernels::kernel_grid_sample`]; state: the image, the grid
/// and the sampling.
#[derive(Debug)]
struct GridSampleBackward;

impl<B: GridSampleGradKernels> Backward<B, 2> for GridSampleBackward {
    type State = (FloatTensor<B>, FloatTensor<B>, Sampling);

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let (grad, (input, grid, sampling), parents) = step_inputs::<B, _, 2>(ops, grads);
        let (d_input, d_grid) = B::kernel_grid_sample_grad(input, grid, grad, sampling);
        for (parent, d) in parents.into_iter().zip([d_input, d_grid]) {
            register::<B>(grads, parent, || d);
        }
    }
}

impl<B: GridSampleGradKernels, C: CheckpointStrategy> GridSampleKernels for Autodiff<B, C> {
    fn kernel_grid_sample(
        input: FloatTensor<Self>,
        grid: FloatTensor<Self>,
        sampling: Sampling,
    ) -> FloatTensor<Self> {
        GridSampleBackward.record::<C, _>(
            [input, grid],
            (),
            |_, [input, grid], ()| {
                (
                    input.primitive().clone(),
                    grid.primitive().clone(),
                    sampling,
                )
            },
            |[input, grid], ()| B::kernel_grid_sample(input, grid, sampling),
        )
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};

    use crate::test_support::output_and_grads;

    use super::*;

    /// Values and both gradients against burn's `grid_sample_2d`, on both CPU devices, for both
    /// paddings and grid conventions, with positions inside, on and beyond the border.
    #[test]
    fn matches_burn() {
        for device in [Device::flex(), Device::flex().autodiff()] {
            let input = Tensor::<4>::random([2, 3, 5, 7], Distribution::Normal(0.0, 1.0), &device);
            // Normalised positions in [-1.3, 1.3]: some outside the image.
            let grid = Tensor::<4>::random([2, 4, 6, 2], Distribution::Uniform(-1.3, 1.3), &device);
            for padding in [GridSamplePaddingMode::Zeros, GridSamplePaddingMode::Border] {
                for align_corners in [false, true] {
                    let options = GridSampleOptions::new(InterpolateMode::Bilinear)
                        .with_padding_mode(padding)
                        .with_align_corners(align_corners);
                    let ours = output_and_grads([&input, &grid], |[x, g]| {
                        grid_sample_2d(x, g, options.clone())
                    });
                    let theirs = output_and_grads([&input, &grid], |[x, g]| {
                        x.grid_sample_2d(g, options.clone())
                    });
                    let what = format!("{device:?} {padding:?} align_corners={align_corners}");
                    let d: f32 = (ours.0 - theirs.0).abs().max().into_scalar();
                    assert!(d < 1e-5, "{what}: values differ by {d}");
                    if let (Some([xa, ga]), Some([xb, gb])) = (ours.1, theirs.1) {
                        let d: f32 = (xa - xb).abs().max().into_scalar();
                        assert!(d < 1e-5, "{what}: image gradients differ by {d}");
                        let d: f32 = (ga - gb).abs().max().into_scalar();
                        assert!(d < 1e-4, "{what}: grid gradients differ by {d}");
                    }
                }
            }
        }
    }
}
