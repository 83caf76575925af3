//! `compute_scale_shift` (upstream `core/monster.py`): least-squares alignment of the monocular
//! disparity to the current stereo disparity, run once per forward pass at iteration `N-7`.

use burn::tensor::{Tensor, TensorData};

/// Scale and shift `(s, t)` such that `s·mono + t ≈ gt`, exactly as upstream:
/// `thr = sort(mono)[int(0.2·n)]`; `mask = (gt > 0) & (mono > 1e-2) & (mono > thr)` (strict);
/// `[s, t] = solve(XᵀX + 1e-6·I, Xᵀy)` with `X = [mono, 1]`, all in **f32** like upstream: the
/// sums are accumulated sequentially in f32 (products rounded, no FMA) and the 2×2 system is
/// solved by LU with partial pivoting in f32 (LAPACK `sgesv`). This reproduces the fixture's
/// `scale_shift` to ~1 ulp, whereas exact (f64) sums differ by ~3e-4 relative on the fixture
/// (the system is mildly ill-conditioned and upstream's f32 rounding is part of the result).
/// With an empty mask the system is `1e-6·I·[s,t] = 0`, i.e. `(0, 0)` as upstream.
pub fn compute_scale_shift(mono: &[f32], gt: &[f32]) -> (f32, f32) {
    assert_eq!(mono.len(), gt.len(), "compute_scale_shift: length mismatch");
    let n = mono.len();
    if n == 0 {
        return (0.0, 0.0);
    }
    let mut sorted = mono.to_vec();
    // torch.sort: NaN sorts last; total_cmp puts positive NaN last too.
    sorted.sort_by(|a, b| a.total_cmp(b));
    let idx = ((0.2f64 * n as f64) as usize).min(n - 1);
    let thr = sorted[idx];
    let (mut sxx, mut sx, mut cnt, mut sxy, mut sy) = (0f32, 0f32, 0f32, 0f32, 0f32);
    for (&m, &g) in mono.iter().zip(gt) {
        if g > 0.0 && m > 1e-2 && m > thr {
            let mm = m * m;
            let mg = m * g;
            sxx += mm;
            sx += m;
            cnt += 1.0;
            sxy += mg;
            sy += g;
        }
    }
    let a = [[sxx + 1e-6f32, sx], [sx, cnt + 1e-6f32]];
    let b = [sxy, sy];
    // LU with partial pivoting (sgesv on a 2×2).
    let (a, b) = if a[1][0].abs() > a[0][0].abs() {
        ([a[1], a[0]], [b[1], b[0]])
    } else {
        (a, b)
    };
    let l = a[1][0] / a[0][0];
    let u11 = a[1][1] - l * a[0][1];
    let y1 = b[1] - l * b[0];
    let t = y1 / u11;
    let s = (b[0] - a[0][1] * t) / a[0][0];
    (s, t)
}

/// Applies the alignment per batch sample as upstream does at iteration `N-7`:
/// `disp_mono[b] = s_b·disp_mono[b] + t_b` with `(s_b, t_b) = compute_scale_shift(disp_mono[b],
/// disp[b])`. Both `[B, 1, h, w]`. Returns the aligned disparity (detached from the statistics:
/// the scalars are constants, as upstream's `.item()`) and the per-sample `(s, t)`.
pub fn align_mono(disp_mono: Tensor<4>, disp: &Tensor<4>) -> (Tensor<4>, Vec<(f32, f32)>) {
    let [b, c, h, w] = disp_mono.dims();
    let device = disp_mono.device();
    let mono_v: Vec<f32> = disp_mono
        .to_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .expect("mono to vec");
    let gt_v: Vec<f32> = disp
        .to_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .expect("disp to vec");
    let per = c * h * w;
    let mut scales = Vec::with_capacity(b);
    let mut shifts = Vec::with_capacity(b);
    let mut params = Vec::with_capacity(b);
    for i in 0..b {
        let (s, t) = compute_scale_shift(
            &mono_v[i * per..(i + 1) * per],
            &gt_v[i * per..(i + 1) * per],
        );
        scales.push(s);
        shifts.push(t);
        params.push((s, t));
    }
    let s = Tensor::<4>::from_data(TensorData::new(scales, [b, 1, 1, 1]), &device);
    let t = Tensor::<4>::from_data(TensorData::new(shifts, [b, 1, 1, 1]), &device);
    (disp_mono * s + t, params)
}
