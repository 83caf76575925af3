//! The SeasonStereo loss on constructed inputs with known values, empty masks, finite-difference
//! gradients, the z-buffer mask on a constructed scene and the sequence weights.

use burn::tensor::{Device, Tensor, TensorData};
use raster::{Image, Mask};
use train::loss::{
    prediction_loss, sequence_loss, sequence_weights, BatchItem, DisparityPenalty, Experiment,
    LossBatch, LossConfig, SupervisionTarget,
};
use train::mask::{photometric_mask, supervision_mask, zbuffer_visible, SupervisionParams};

const W: usize = 48;
const H: usize = 24;

fn device() -> Device {
    Device::flex().autodiff()
}

/// A smooth, textured RGB image in [0.1, 0.9] (SSIM needs texture), as a function of (x, y).
fn texture(x: f32, y: f32, c: usize) -> f32 {
    let c = c as f32;
    0.5 + 0.2 * (0.37 * x + 0.9 * c).sin() * (0.23 * y + 0.5).cos()
        + 0.15 * (0.11 * x * (1.0 + 0.1 * c) - 0.31 * y).sin()
}

fn rgb(f: impl Fn(usize, usize, usize) -> f32) -> Image {
    let mut data = Vec::with_capacity(W * H * 3);
    for y in 0..H {
        for x in 0..W {
            for c in 0..3 {
                data.push(f(x, y, c));
            }
        }
    }
    Image::new(W, H, 3, data).unwrap()
}

fn map(f: impl Fn(usize, usize) -> f32) -> Image {
    Image::from_fn(W, H, f)
}

struct Scene {
    input_left: Image,
    real_left: Image,
    real_right: Image,
    target: Image,
    valid: Mask,
    building: Mask,
}

impl Scene {
    /// Real right = real left shifted by `shift` px (x_R = x_L − shift), target `shift`.
    fn shifted(shift: usize) -> Self {
        let left = rgb(|x, y, c| texture(x as f32, y as f32, c));
        let right = rgb(|x, y, c| texture((x + shift) as f32, y as f32, c));
        Self {
            input_left: left.clone(),
            real_left: left,
            real_right: right,
            // Any positive target (the supervision mask needs d > 0).
            target: map(|_, _| shift.max(1) as f32),
            valid: Mask::filled(W, H, true),
            building: Mask::filled(W, H, true),
        }
    }

    fn item(&self) -> BatchItem<'_> {
        BatchItem {
            input_left: &self.input_left,
            real_left: &self.real_left,
            real_right: &self.real_right,
            target: &self.target,
            valid_left: &self.valid,
            building_left: &self.building,
        }
    }

    fn batch(&self, config: &LossConfig) -> LossBatch {
        LossBatch::new(&[self.item()], config, &device()).unwrap()
    }
}

fn disparity(f: impl Fn(usize, usize) -> f32) -> Tensor<4> {
    let data: Vec<f32> = (0..H * W).map(|i| f(i % W, i / W)).collect();
    Tensor::from_data(TensorData::new(data, [1, 1, H, W]), &device())
}

fn only(lambda_disp: f32, lambda_photo: f32, lambda_smooth: f32) -> LossConfig {
    LossConfig {
        lambda_disp,
        lambda_photo,
        lambda_smooth,
        ignore_border: 8,
        ..LossConfig::full()
    }
}

fn scalar(t: Tensor<1>) -> f32 {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .unwrap()[0]
}

fn assert_close(got: f32, want: f32, tol: f32, what: &str) {
    assert!(
        (got - want).abs() <= tol,
        "{what}: got {got}, want {want} (tol {tol})"
    );
}

#[test]
fn disparity_term_known_values() {
    let scene = Scene::shifted(3);
    let l1 = LossConfig {
        disparity_penalty: DisparityPenalty::L1,
        ..only(1.0, 0.0, 0.0)
    };
    let batch = scene.batch(&l1);
    // Constant error 2 px → L1 = 2; smooth L1 (beta 1) = 2 − 0.5; error 0.5 → 0.5·0.25.
    let l = prediction_loss(&l1, &batch, disparity(|_, _| 5.0)).unwrap();
    assert_close(scalar(l.disp), 2.0, 1e-6, "L1");
    let smooth_l1 = only(1.0, 0.0, 0.0);
    let l = prediction_loss(&smooth_l1, &batch, disparity(|_, _| 1.0)).unwrap();
    assert_close(scalar(l.total), 1.5, 1e-6, "smooth L1, |e| = 2");
    let l = prediction_loss(&smooth_l1, &batch, disparity(|_, _| 3.5)).unwrap();
    assert_close(scalar(l.total), 0.125, 1e-6, "smooth L1, |e| = 0.5");
    // λ_disp scales; a half-wrong map only counts its supervised pixels: errors 4 on the left
    // half, 0 on the right half → mean over V (ignore_border 8 on each side) of the L1.
    let half = LossConfig {
        lambda_disp: 0.05,
        ..l1.clone()
    };
    let l = prediction_loss(
        &half,
        &batch,
        disparity(|x, _| if x < W / 2 { 7.0 } else { 3.0 }),
    )
    .unwrap();
    // V spans x in 8..40: 16 columns with error 4, 16 with 0 → mean 2, × 0.05.
    assert_close(scalar(l.total), 0.1, 1e-6, "masked mean × λ");
}

#[test]
fn supervision_uses_the_target_validity_and_max_disp() {
    // NaN, non-positive and too large targets are unsupervised; so is the sample's mask.
    let mut scene = Scene::shifted(3);
    scene.target = map(|x, _| match x {
        10..=14 => f32::NAN,
        15..=19 => 0.0,
        20..=24 => 1000.0,
        _ => 3.0,
    });
    scene.valid = Mask::from_fn(W, H, |x, _| x < 36);
    let config = LossConfig {
        disparity_penalty: DisparityPenalty::L1,
        ..only(1.0, 0.0, 0.0)
    };
    let batch = scene.batch(&config);
    let v = batch.supervision();
    let cols: Vec<usize> = (0..W).filter(|&x| v[12 * W + x]).collect();
    let want: Vec<usize> = (8..10).chain(25..36).collect();
    assert_eq!(cols, want);
    assert!(!v[3 * W + 30], "top border");
    // The loss only sees supervised pixels: error 1 there, NaN targets leak nothing.
    let l = prediction_loss(&config, &batch, disparity(|_, _| 4.0)).unwrap();
    assert_close(scalar(l.total), 1.0, 1e-6, "L1 over V");
}

#[test]
fn photometric_term_known_values() {
    let config = only(0.0, 1.0, 0.0);
    // Identical images, zero disparity → 0. (Disparity 0 is in bounds everywhere.)
    let scene = Scene::shifted(0);
    let l = prediction_loss(&config, &scene.batch(&config), disparity(|_, _| 0.0)).unwrap();
    assert_close(scalar(l.total), 0.0, 1e-6, "identical images");

    // A known integer shift warped exactly → 0; a wrong disparity → clearly > 0.
    let scene = Scene::shifted(3);
    let batch = scene.batch(&config);
    let l = prediction_loss(&config, &batch, disparity(|_, _| 3.0)).unwrap();
    assert_close(scalar(l.total), 0.0, 1e-5, "exact shift");
    let wrong = prediction_loss(&config, &batch, disparity(|_, _| 4.0)).unwrap();
    let wrong = scalar(wrong.total);
    assert!(wrong > 0.01, "{wrong}");

    // Constant images 0.5 and 0.3: SSIM = (2·0.15 + C1)/(0.25 + 0.09 + C1) in the interior
    // (the variances vanish and C2 cancels), L1 = 0.2.
    let mut scene = Scene::shifted(0);
    scene.real_left = rgb(|_, _, _| 0.5);
    scene.real_right = rgb(|_, _, _| 0.3);
    let c1 = 1e-4f32;
    let ssim = (0.3 + c1) / (0.34 + c1);
    let want = 0.85 * (1.0 - ssim) / 2.0 + 0.15 * 0.2;
    let l = prediction_loss(&config, &scene.batch(&config), disparity(|_, _| 0.0)).unwrap();
    // Tolerance: the release's variance `E[x²] − μ²` cancels catastrophically in f32 (~2e-7
    // against C2 = 9e-4), so SSIM is only good to a few 1e-4 here, in torch as in burn.
    assert_close(scalar(l.total), want, 3e-4, "constant images");
}

#[test]
fn photometric_term_is_restricted_to_buildings_and_visible_pixels() {
    let config = only(0.0, 1.0, 0.0);
    let mut scene = Scene::shifted(0);
    scene.real_right = rgb(|x, y, c| {
        if x < W / 2 {
            texture(x as f32, y as f32, c)
        } else {
            0.3
        }
    });
    // Buildings only on the left half, where the pair agrees → 0 even though the right half differs.
    scene.building = Mask::from_fn(W, H, |x, _| x < W / 2 - 6);
    let l = prediction_loss(&config, &scene.batch(&config), disparity(|_, _| 0.0)).unwrap();
    assert_close(scalar(l.total), 0.0, 1e-6, "building mask");
    // Without the restriction the disagreeing half counts.
    let all = LossConfig {
        photometric_on_buildings_only: false,
        ..config
    };
    let l = prediction_loss(&all, &scene.batch(&all), disparity(|_, _| 0.0)).unwrap();
    assert!(scalar(l.total) > 0.01);
}

#[test]
fn smoothness_term_known_values() {
    let config = LossConfig {
        ignore_border: 0,
        ..only(0.0, 0.0, 1.0)
    };
    let scene = Scene::shifted(0);
    let batch = scene.batch(&config);
    let l = prediction_loss(&config, &batch, disparity(|_, _| 7.0)).unwrap();
    assert_close(scalar(l.total), 0.0, 1e-7, "constant disparity");

    // Ramp d = 10 + x on an image whose channels all step by 0.01 per column:
    // |∂x D̂| = 1/mean(d), weight e^(−0.01); no vertical change → L = e^(−0.01)/mean(d).
    let mut scene = Scene::shifted(0);
    scene.input_left = rgb(|x, _, _| 0.01 * x as f32);
    let batch = scene.batch(&config);
    let mean = 10.0 + (W as f32 - 1.0) / 2.0;
    let l = prediction_loss(&config, &batch, disparity(|x, _| 10.0 + x as f32)).unwrap();
    assert_close(scalar(l.total), (-0.01f32).exp() / mean, 1e-6, "ramp");
    // Without the normalisation the slope itself counts.
    let raw = LossConfig {
        smooth_normalise_by_mean: false,
        ..config
    };
    let l = prediction_loss(&raw, &batch, disparity(|x, _| 10.0 + 2.0 * x as f32)).unwrap();
    assert_close(scalar(l.total), 2.0 * (-0.01f32).exp(), 1e-5, "raw ramp");
}

#[test]
fn empty_masks_give_zero_loss_and_finite_gradients() {
    let mut scene = Scene::shifted(3);
    scene.valid = Mask::filled(W, H, false);
    scene.building = Mask::filled(W, H, false);
    let config = LossConfig {
        lambda_smooth: 0.0,
        ..only(0.05, 0.1, 0.0)
    };
    let batch = scene.batch(&config);
    let pred = disparity(|_, _| 2.5).require_grad();
    let out = sequence_loss(&config, &batch, pred.clone(), &[pred.clone(), pred.clone()]).unwrap();
    assert_eq!(out.terms.total, 0.0);
    assert_eq!(out.terms.valid_fraction, 0.0);
    let grads = out.total.backward();
    let g: Vec<f32> = pred
        .grad(&grads)
        .unwrap()
        .into_data()
        .try_into_vec()
        .unwrap();
    assert!(g.iter().all(|v| *v == 0.0), "gradient must be exactly 0");

    // NaN predictions are excluded: no NaN in the value or the gradient.
    let scene = Scene::shifted(3);
    let config = only(0.05, 0.1, 0.1);
    let batch = scene.batch(&config);
    let pred = disparity(|x, y| if (x, y) == (20, 10) { f32::NAN } else { 3.0 }).require_grad();
    let out = sequence_loss(&config, &batch, pred.clone(), std::slice::from_ref(&pred)).unwrap();
    assert!(out.terms.total.is_finite());
    assert_eq!(out.terms.non_finite_pixels, 1);
    let grads = out.total.backward();
    let g: Vec<f32> = pred
        .grad(&grads)
        .unwrap()
        .into_data()
        .try_into_vec()
        .unwrap();
    assert!(g.iter().all(|v| v.is_finite()));
}

#[test]
fn gradients_match_finite_differences() {
    // The prediction: a gentle x-ramp on integer steps between rows, so that (i) `x − d` keeps a
    // fractional part in [0.66, 0.9] (the z-buffer rounding and the warp bounds never change under
    // the perturbation), (ii) horizontal disparity differences are 0.004 px and vertical ones ≥ 1
    // (the |∂D| kinks stay farther than h), (iii) errors to the target stay away from 0.
    let mut scene = Scene::shifted(3);
    scene.target = map(|x, y| 3.0 + (y % 3) as f32 + if (x + y) % 3 == 0 { 1.7 } else { -0.4 });
    scene.building = Mask::from_fn(W, H, |x, y| (x / 6 + y / 6) % 2 == 0);
    // For the smoothness term alone, a plain ramp (no row steps) keeps its value, and so its f32
    // rounding, small: differences 0.004 px in x and 0.003 px in y.
    let base = |x: usize, y: usize, steps: bool| {
        if steps {
            3.1 + (y % 3) as f32 + 0.004 * x as f32
        } else {
            3.1 + 0.003 * y as f32 + 0.004 * x as f32
        }
    };
    let run = |config: &LossConfig,
               steps: bool,
               delta: Option<(usize, f32)>|
     -> (f32, Option<Vec<f32>>) {
        let batch = scene.batch(config);
        let data: Vec<f32> = (0..H * W)
            .map(|i| base(i % W, i / W, steps) + delta.filter(|d| d.0 == i).map_or(0.0, |d| d.1))
            .collect();
        let pred =
            Tensor::<4>::from_data(TensorData::new(data, [1, 1, H, W]), &device()).require_grad();
        let preds = [pred.clone().add_scalar(0.05), pred.clone()];
        let out = sequence_loss(config, &batch, pred.clone(), &preds).unwrap();
        let total = out.terms.total;
        let grad = delta.is_none().then(|| {
            let grads = out.total.backward();
            pred.grad(&grads)
                .unwrap()
                .into_data()
                .try_into_vec()
                .unwrap()
        });
        (total, grad)
    };
    let config = |ld, lp, ls| LossConfig {
        ignore_border: 2,
        ..only(ld, lp, ls)
    };
    let pixels = [(10, 10), (20, 5), (30, 15), (5, 20), (41, 12), (25, 11)];
    // Each term alone at λ = 1 (its own step: the smoothness kinks are 0.004 px away).
    for ((ld, lp, ls), h) in [
        ((1.0, 0.0, 0.0), 1e-2f32),
        ((0.0, 1.0, 0.0), 1e-2),
        ((0.0, 0.0, 1.0), 1e-3),
    ] {
        let config = config(ld, lp, ls);
        let steps = ls == 0.0;
        let grad = run(&config, steps, None).1.unwrap();
        let gmax = grad.iter().fold(0f32, |m, v| m.max(v.abs()));
        assert!(gmax > 0.0);
        for (x, y) in pixels {
            let i = y * W + x;
            let fd = (run(&config, steps, Some((i, h))).0 - run(&config, steps, Some((i, -h))).0)
                / (2.0 * h);
            let ad = grad[i];
            assert!(
                (fd - ad).abs() <= 0.02 * ad.abs() + 0.005 * gmax,
                "λ = ({ld}, {lp}, {ls}), pixel ({x}, {y}): autodiff {ad}, finite difference {fd} (max |g| {gmax})"
            );
        }
    }
    // The total's gradient is the sum of the terms' gradients (on one prediction).
    let mut sum_of_parts = vec![0f32; H * W];
    for (ld, lp, ls) in [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)] {
        let g = run(&config(ld, lp, ls), true, None).1.unwrap();
        sum_of_parts.iter_mut().zip(g).for_each(|(s, g)| *s += g);
    }
    let grad = run(&config(1.0, 1.0, 1.0), true, None).1.unwrap();
    for (a, b) in grad.iter().zip(&sum_of_parts) {
        assert!((a - b).abs() <= 1e-6 + 1e-4 * b.abs(), "{a} vs {b}");
    }
}

#[test]
fn zbuffer_mask_on_a_tall_block() {
    // Background at d = 2, a tall block at d = 8 on columns 20..30 of rows 5..15.
    // The block lands on right columns 12..22, where background x = 14..19 would land:
    // those six columns are occluded by the block; x = 0, 1 leave the right image.
    let (w, h) = (40usize, 20usize);
    let block = |x: usize, y: usize| (20..30).contains(&x) && (5..15).contains(&y);
    let d: Vec<f32> = (0..w * h)
        .map(|i| if block(i % w, i / w) { 8.0 } else { 2.0 })
        .collect();
    let vis = zbuffer_visible(&d, w).unwrap();
    for y in 0..h {
        let hidden: Vec<usize> = (0..w).filter(|&x| !vis[y * w + x]).collect();
        let want: Vec<usize> = if (5..15).contains(&y) {
            vec![0, 1, 14, 15, 16, 17, 18, 19]
        } else {
            vec![0, 1]
        };
        assert_eq!(hidden, want, "row {y}");
    }
    // Near-ties stay visible (release tolerance 0.5): x = 3 (d = 2.0) and x = 4 (d = 2.6) both
    // land on column 1 (round(1.4) = 1); d = 2.6 wins, 2.0 is 0.6 behind → hidden; with
    // d = 2.4 at x = 4 (round(1.6) = 2) they do not collide at all.
    let row = [5.0, 5.0, 5.0, 2.0, 2.6, 2.0, 9.0];
    let v = zbuffer_visible(&row, 7).unwrap();
    assert_eq!(v, vec![false, false, false, false, true, true, false]);
    let row = [0.0, 0.6, 0.0, 0.0];
    // x = 0 → 0; x = 1, d = 0.6 → round(0.4) = 0: |0.6 − 0| ≥ 0.5 → x = 0 hidden. With d = 0.4 at
    // x = 1 → round(0.6) = 1: no collision.
    assert_eq!(
        zbuffer_visible(&row, 4).unwrap(),
        vec![false, true, true, true]
    );
    let row = [1.0, 1.4, f32::NAN, 0.0];
    // x = 0 → −1 out; x = 1 → round(−0.4) = 0 visible; NaN invisible; x = 3 → 3.
    assert_eq!(
        zbuffer_visible(&row, 4).unwrap(),
        vec![false, true, false, true]
    );
    // Half to even, as torch.round: x − d = 2.5 → 2 collides with x = 2 (d = 0) and wins
    // (0.5 ahead, not within the tolerance); half-up rounding would send it to 3.
    let row = [9.0, 9.0, 0.0, 0.5];
    assert_eq!(
        zbuffer_visible(&row, 4).unwrap(),
        vec![false, false, false, true]
    );

    // The photometric mask combines supervision, warp bounds, z-buffer and buildings.
    let sup: Vec<bool> = (0..w * h).map(|i| i % w != 25).collect();
    let building: Vec<bool> = (0..w * h).map(|i| i % w != 30).collect();
    let m = photometric_mask(&sup, &d, w, Some(&building)).unwrap();
    let y = 10;
    let masked: Vec<usize> = (0..w).filter(|&x| !m[y * w + x]).collect();
    assert_eq!(masked, vec![0, 1, 14, 15, 16, 17, 18, 19, 25, 30]);
}

#[test]
fn supervision_mask_border_and_errors() {
    let target = Image::filled(10, 8, 1, 4.0);
    let params = SupervisionParams {
        max_disp: 5.0,
        ignore_border: 2,
    };
    let m = supervision_mask(&Mask::filled(10, 8, true), &target, &params).unwrap();
    assert_eq!(m.count(), 6 * 4);
    let big = SupervisionParams {
        max_disp: 4.0,
        ..params
    };
    assert_eq!(
        supervision_mask(&Mask::filled(10, 8, true), &target, &big)
            .unwrap()
            .count(),
        0
    );
    assert!(supervision_mask(&Mask::filled(9, 8, true), &target, &params).is_err());
}

#[test]
fn sequence_weights_for_22_and_8_predictions() {
    for n in [22usize, 8] {
        let w = sequence_weights(n, 0.9);
        assert_eq!(w.len(), n);
        assert_close(w[n - 1], 1.0, 0.0, "last");
        assert_close(w[0], 0.9f32.powi(15), 1e-6, "first = γ^15");
        for (k, &wk) in w.iter().enumerate() {
            let want = 0.9f64.powf(15.0 * (n - 1 - k) as f64 / (n - 1) as f64) as f32;
            assert_close(wk, want, 1e-6, "w(k)");
        }
    }
    // N = 22: γ' = 0.9^(15/21) = 0.92755…
    let w = sequence_weights(22, 0.9);
    assert_close(w[20], 0.927_504_6, 1e-6, "γ' for N = 22");
    assert_eq!(sequence_weights(1, 0.9), vec![1.0]);
}

#[test]
fn sequence_loss_is_the_weighted_sum_of_the_predictions() {
    let scene = Scene::shifted(3);
    let config = only(0.05, 0.1, 0.1);
    let batch = scene.batch(&config);
    let init = disparity(|_, _| 2.0);
    let preds: Vec<Tensor<4>> = (0..8)
        .map(|k| disparity(move |x, _| 2.0 + 0.1 * k as f32 + 0.01 * x as f32))
        .collect();
    let out = sequence_loss(&config, &batch, init.clone(), &preds).unwrap();
    let w = sequence_weights(8, 0.9);
    let mut want = scalar(prediction_loss(&config, &batch, init).unwrap().total);
    for (p, wk) in preds.iter().zip(&w) {
        want += wk * scalar(prediction_loss(&config, &batch, p.clone()).unwrap().total);
    }
    assert_close(out.terms.total, want, 1e-5 * want.abs(), "total");
    assert_close(
        out.terms.disp + out.terms.photo + out.terms.smooth,
        out.terms.total,
        1e-5 * want.abs(),
        "terms add up",
    );
    assert!(out.terms.disp > 0.0 && out.terms.photo > 0.0 && out.terms.smooth > 0.0);
    // The last prediction is 2.7 + 0.01x against 3: EPE = mean over V (x in 8..40) of |0.01x − 0.3|.
    let epe = (8..40).map(|x| (0.01 * x as f32 - 0.3).abs()).sum::<f32>() / 32.0;
    assert_close(out.terms.epe, epe, 1e-5, "epe");
    assert_eq!(out.terms.within_1px, 1.0);
    assert!(sequence_loss(&config, &batch, disparity(|_, _| 2.0), &[]).is_err());
}

#[test]
fn configs_presets_and_validation() {
    let d = LossConfig::default();
    assert_eq!(
        (d.lambda_disp, d.lambda_photo, d.lambda_smooth),
        (0.05, 0.1, 0.1)
    );
    assert_eq!(
        (d.max_disp, d.ignore_border, d.ssim_window),
        (576.0, 32, 11)
    );
    let a = LossConfig::preset(Experiment::A);
    assert_eq!(a.target, SupervisionTarget::Lidar);
    assert_eq!((a.lambda_photo, a.lambda_smooth), (0.0, 0.0));
    let b = LossConfig::preset(Experiment::B);
    assert_eq!(
        (b.target, b.lambda_photo),
        (SupervisionTarget::Teacher, 0.0)
    );
    let c = LossConfig::preset(Experiment::C);
    assert_eq!((c.lambda_photo, c.lambda_smooth), (0.1, 0.0));
    assert_eq!(LossConfig::preset(Experiment::D), d);
    // serde: partial files fill the rest with the defaults; unknown keys are refused.
    let parsed: LossConfig =
        serde_json::from_str(r#"{"lambda_photo": 0.0, "disparity_penalty": {"kind": "l1"}}"#)
            .unwrap();
    assert_eq!(parsed.lambda_photo, 0.0);
    assert_eq!(parsed.disparity_penalty, DisparityPenalty::L1);
    assert!(serde_json::from_str::<LossConfig>(r#"{"lamda_photo": 0.0}"#).is_err());
    let back: LossConfig = serde_json::from_str(&serde_json::to_string(&d).unwrap()).unwrap();
    assert_eq!(back, d);
    for bad in [
        LossConfig {
            ssim_window: 4,
            ..d.clone()
        },
        LossConfig {
            gamma: 0.0,
            ..d.clone()
        },
        LossConfig {
            lambda_disp: -1.0,
            ..d.clone()
        },
        LossConfig {
            lambda_disp: 0.0,
            lambda_photo: 0.0,
            lambda_smooth: 0.0,
            ..d.clone()
        },
    ] {
        assert!(bad.validate().is_err(), "{bad:?}");
    }
}

#[test]
fn batch_rejects_unnormalised_images_and_mismatched_sizes() {
    let mut scene = Scene::shifted(0);
    scene.real_left = rgb(|_, _, _| 200.0);
    let err = LossBatch::new(&[scene.item()], &LossConfig::full(), &device()).unwrap_err();
    assert!(err.to_string().contains("[0, 1]"), "{err}");
    let mut scene = Scene::shifted(0);
    scene.building = Mask::filled(W - 1, H, true);
    assert!(LossBatch::new(&[scene.item()], &LossConfig::full(), &device()).is_err());
    assert!(LossBatch::new(&[], &LossConfig::full(), &device()).is_err());
}

#[test]
fn batch_items_from_samples_pick_the_configured_target() {
    let scene = Scene::shifted(3);
    let sample = dataset::Sample {
        input_left: scene.input_left.clone(),
        input_right: scene.real_right.clone(),
        real_left: scene.real_left.clone(),
        real_right: scene.real_right.clone(),
        teacher: scene.target.clone(),
        lidar: None,
        valid_left: scene.valid.clone(),
        building_left: scene.building.clone(),
        stem: dataset::PairStem::real("JAX_004_001", "JAX_004_002"),
        diachronic: false,
    };
    let teacher = LossConfig::preset(Experiment::D);
    let item = BatchItem::from_sample(&sample, &teacher).unwrap();
    assert!(std::ptr::eq(item.target, &sample.teacher));
    let lidar = LossConfig::preset(Experiment::A);
    let err = BatchItem::from_sample(&sample, &lidar)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("LiDAR") && err.contains("JAX_004_001"),
        "{err}"
    );
    let with_lidar = dataset::Sample {
        lidar: Some(map(|_, _| 4.0)),
        ..sample.clone()
    };
    let item = BatchItem::from_sample(&with_lidar, &lidar).unwrap();
    assert_eq!(item.target.get(0, 0, 0), 4.0);
}

#[test]
fn separable_ssim_equals_the_two_dimensional_box() {
    use burn::tensor::module::avg_pool2d;
    use burn::tensor::ops::AvgPoolOptions;
    use train::loss::terms::ssim_loss_map;
    // A direct 11×11 zero-padded average pooling, as the release's avg_pool2d(11, 1, 5).
    let (a, b) = (Scene::shifted(0).real_left, Scene::shifted(2).real_right);
    let to_t = |im: &Image| {
        let mut chw = vec![0.0; W * H * 3];
        for (p, px) in im.data().chunks_exact(3).enumerate() {
            for c in 0..3 {
                chw[c * W * H + p] = px[c];
            }
        }
        Tensor::<4>::from_data(TensorData::new(chw, [1, 3, H, W]), &device())
    };
    let (x, y) = (to_t(&a), to_t(&b));
    let pool = |t: Tensor<4>| {
        avg_pool2d(
            t,
            AvgPoolOptions::new([11, 11])
                .with_stride([1, 1])
                .with_padding([5, 5])
                .with_count_include_pad(true),
        )
    };
    let (mx, my) = (pool(x.clone()), pool(y.clone()));
    let sx = pool(x.clone().powi_scalar(2)) - mx.clone().powi_scalar(2);
    let sy = pool(y.clone().powi_scalar(2)) - my.clone().powi_scalar(2);
    let sxy = pool(x.clone() * y.clone()) - mx.clone() * my.clone();
    let num = (mx.clone() * my.clone()).mul_scalar(2.0).add_scalar(1e-4)
        * sxy.mul_scalar(2.0).add_scalar(9e-4);
    let den = (mx.powi_scalar(2) + my.powi_scalar(2)).add_scalar(1e-4) * (sx + sy).add_scalar(9e-4);
    let want: Vec<f32> = (num / den.clamp_min(1e-8))
        .neg()
        .add_scalar(1.0)
        .mul_scalar(0.5)
        .mean_dim(1)
        .into_data()
        .try_into_vec()
        .unwrap();
    let got: Vec<f32> = ssim_loss_map(x, y, 11).into_data().try_into_vec().unwrap();
    let worst = got
        .iter()
        .zip(&want)
        .fold(0f32, |m, (g, w)| m.max((g - w).abs()));
    assert!(worst < 1e-4, "{worst}");
    assert!(want.iter().any(|v| *v > 0.01), "the images differ");
}

/// The fused photometric map (`nn::photometric`, what the loss runs on the CPU) equals its
/// tensor composition from `ssim_loss_map` and the L1 term, values and the gradient of the
/// reconstruction: batch 2, three channels, windows 3 and 7, and a black patch in both images
/// where the SSIM denominator is clamped.
#[test]
fn fused_photometric_map_matches_the_composition() {
    use burn::tensor::Distribution;
    use nn::photometric::{photometric_map, Photometric};
    use train::loss::terms::ssim_loss_map;
    let device = Device::flex().autodiff();
    let dims = [2, 3, 13, 17];
    let black = |t: Tensor<4>| t.slice_fill([0..2, 0..3, 2..7, 3..9], 0.0);
    let x = black(Tensor::<4>::random(
        dims,
        Distribution::Uniform(0.0, 1.0),
        &device,
    ));
    let y = black(Tensor::<4>::random(
        dims,
        Distribution::Uniform(0.0, 1.0),
        &device,
    ));
    let upstream = Tensor::<4>::random([2, 1, 13, 17], Distribution::Normal(0.0, 1.0), &device);
    for window in [3, 7] {
        let alpha = 0.85;
        let run = |fused: bool| {
            let y = y.clone().require_grad();
            let map = if fused {
                let options = Photometric { alpha, window };
                photometric_map(x.clone(), y.clone(), options).expect("the CPU kernel applies")
            } else {
                let l1 = (x.clone() - y.clone()).abs().mean_dim(1);
                ssim_loss_map(x.clone(), y.clone(), window)
                    .mul_scalar(alpha)
                    .add(l1.mul_scalar(1.0 - alpha))
            };
            let grads = (map.clone() * upstream.clone()).sum().backward();
            let dy = y.grad(&grads).expect("reconstruction gradient");
            let values = |t: Tensor<4>| t.into_data().try_into_vec::<f32>().unwrap();
            (values(map.inner()), values(dy))
        };
        let (ours, reference) = (run(true), run(false));
        for (what, a, b) in [
            ("map", &ours.0, &reference.0),
            ("∂y", &ours.1, &reference.1),
        ] {
            let scale = b.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
            let worst = a.iter().zip(b).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
            assert!(
                worst <= 1e-4 * scale.max(1.0),
                "window {window} {what}: {worst} (scale {scale})"
            );
        }
    }
}
