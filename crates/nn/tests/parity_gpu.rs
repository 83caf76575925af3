//! Parity of the networks on a GPU backend (`--features wgpu` / `cuda`) against the upstream tiny
//! fixtures (`fixtures/*-tiny`): MonSter++ stage by stage (each stage fed with the
//! fixture's own inputs, so errors do not accumulate) and end to end, DINOv3 and SegFormer.
//!
//! Compiles to nothing without a GPU feature; with one, every test returns early with a printed
//! note when the backend has no usable adapter. Tolerances: see [`Tol`].

#![cfg(any(feature = "wgpu", feature = "cuda"))]

mod support;

use support::tiny::{features0, load, weights, Parts, FIXTURE, HIDDEN};
use support::Fixture;

use burn::tensor::activation::softmax;
use burn::tensor::ops::{GridSampleOptions, GridSamplePaddingMode, InterpolateMode};
use burn::tensor::{Device, Distribution, Tensor};

use nn::config::MonsterConfig;
use nn::dinov3::{load_dinov3, Dinov3Config, Dinov3Vit};
use nn::monster::context::ContextNet;
use nn::monster::cost::{
    build_gwc_volume, disparity_regression, CostAggregation, SpxHead, GWC_GROUPS,
};
use nn::monster::dpt::DptHead;
use nn::monster::features::StereoFeatures;
use nn::monster::scale_shift::align_mono;
use nn::monster::update::iterate_traced;
use nn::monster::upsample::upsample_disp;
use nn::monster::vit::{mono_input, normalize_image, DinoVisionTransformer};
use nn::monster::warp::{disp_warp, disp_warp_grid};
use nn::monster::Monster;
use nn::segformer::{Segformer, SegformerConfig};
use nn::weights::load_weights;

const DPT_F: usize = 64;
const D: usize = 16;
const ITERS: usize = 8;

/// The GPU devices compiled in, with their names.
#[allow(clippy::vec_init_then_push)] // the pushes are feature-gated
fn compiled_gpus() -> Vec<(&'static str, Device)> {
    #[allow(unused_mut)]
    let mut all: Vec<(&'static str, Device)> = Vec::new();
    #[cfg(feature = "cuda")]
    all.push(("cuda", Device::cuda(0)));
    #[cfg(feature = "wgpu")]
    all.push((
        "wgpu",
        Device::wgpu(burn::tensor::DeviceKind::DefaultDevice),
    ));
    all
}

/// The GPU devices compiled in that answer a tiny computation correctly (probed once per test
/// binary; a backend without an adapter panics inside burn, which is caught and noted).
fn gpu_devices() -> Vec<(&'static str, Device)> {
    static USABLE: std::sync::OnceLock<Vec<&'static str>> = std::sync::OnceLock::new();
    let usable = USABLE.get_or_init(|| {
        compiled_gpus()
            .into_iter()
            .filter(|(name, device)| {
                let d = device.clone();
                let probe = std::panic::catch_unwind(move || {
                    let t = Tensor::<1>::from_floats([1.0, 2.0, 3.5], &d);
                    let s: f32 = t.sum().into_scalar();
                    s
                });
                let ok = matches!(probe, Ok(s) if s == 6.5);
                if !ok {
                    eprintln!("note: no usable {name} adapter, GPU parity on {name} skipped");
                }
                ok
            })
            .map(|(name, _)| name)
            .collect()
    });
    compiled_gpus()
        .into_iter()
        .filter(|(name, _)| usable.contains(name))
        .collect()
}

/// (max, mean) abs error of `got` against fixture tensor `name`; printed under `label`.
fn err<const N: usize>(fx: &Fixture, label: &str, got: &Tensor<N>, name: &str) -> (f32, f32) {
    let (shape, want) = fx.raw(name);
    assert_eq!(&got.dims().to_vec(), shape, "{label}: shape of {name}");
    let got: Vec<f32> = got.to_data().convert::<f32>().try_to_vec::<f32>().unwrap();
    let (max, scale) = support::max_abs_diff(&got, want);
    let mean = got
        .iter()
        .zip(want)
        .map(|(a, b)| (a - b).abs() as f64)
        .sum::<f64>()
        / got.len().max(1) as f64;
    println!(
        "{label:<34} vs {name:<30} max |ref| {scale:>9.3e}  max err {max:>9.3e}  mean err {:>9.3e}",
        mean
    );
    (max, mean as f32)
}

/// Asserts the max abs error of `got` against `name` is at most `tol`; returns it.
fn check<const N: usize>(fx: &Fixture, label: &str, got: &Tensor<N>, name: &str, tol: f32) -> f32 {
    let (max, _) = err(fx, label, got, name);
    assert!(max <= tol, "{label}: max abs error {max:e} > {tol:e}");
    max
}

/// The fixture with its tensors handed out on `device`.
fn fixture_on(name: &str, device: &Device) -> Fixture {
    let mut fx = Fixture::load(name);
    fx.device = device.clone();
    fx
}

fn dpt(fx: &Fixture, side: &str) -> [Tensor<4>; 4] {
    std::array::from_fn(|i| fx.t(&format!("inter.dpt_feat_{side}_{i}.0")))
}

/// Mono branch: DINOv2 from the normalised image; the DPT heads run on the GPU's DINOv2 output
/// (the fixture has no DINOv2 outputs in the layout the heads take, so they are chained).
fn mono_stages(fx: &Fixture) {
    let dev = &fx.device;
    let cfg = MonsterConfig::tiny();
    let vit = load(DinoVisionTransformer::new(&cfg.vit, dev), "mono_encoder.");
    let mono = load(
        DptHead::new(cfg.vit.embed_dim, &cfg.dpt, true, dev),
        "mono_decoder.",
    );
    let feat = load(
        DptHead::new(cfg.vit.embed_dim, &cfg.dpt, false, dev),
        "feat_decoder.",
    );
    let left = fx.t::<4>("input.left");
    let [_, _, h, w] = left.dims();
    let x = mono_input(normalize_image(left));
    check(fx, "vit input", &x, "inter.vit_in.0", 1e-4);
    let fl = vit.forward_intermediate(x);
    for i in 0..4 {
        check(
            fx,
            &format!("dinov2 tokens[{i}]"),
            &fl.tokens[i],
            &format!("inter.vit_layer{i}_tokens.0"),
            Tol::FEATURES,
        );
    }
    let depth = mono.forward_depth(&fl, [h, w]);
    check(
        fx,
        "dpt depth (chained)",
        &depth,
        "inter.depth_mono.0",
        Tol::FEATURES,
    );
    for (i, p) in feat.forward_features(&fl).iter().enumerate() {
        check(
            fx,
            &format!("dpt features[{i}] (chained)"),
            p,
            &format!("inter.dpt_feat_left_{i}.0"),
            Tol::FEATURES,
        );
    }
}

/// Feature stems, GWC volume, 3-D hourglass, classifier, soft-argmin, context network.
fn stereo_stages(fx: &Fixture) {
    let dev = &fx.device;
    let feats = load(StereoFeatures::new(DPT_F, dev), "");
    let cost = load(CostAggregation::new(dev), "");
    let spx = load(SpxHead::new(dev), "");
    let ctx = load(ContextNet::new(DPT_F, HIDDEN, dev), "");

    for (side, idx) in [("left", 0), ("right", 1)] {
        let ft = feats.feat_transfer.forward(dpt(fx, side));
        for (i, t) in ft.iter().enumerate() {
            check(
                fx,
                &format!("feat_transfer[{i}] {side}"),
                t,
                &format!("inter.feat_transfer_{i}.{idx}"),
                Tol::FEATURES,
            );
        }
        let stems = feats.stems(fx.image(side), idx == 0);
        for (t, n) in stems.iter().zip(["stem_2", "stem_4", "stem_8", "stem_16"]) {
            check(
                fx,
                &format!("{n} {side}"),
                t,
                &format!("inter.{n}.{idx}"),
                Tol::FEATURES,
            );
        }
    }

    let fl: [Tensor<4>; 4] = [
        features0(fx, 0),
        fx.t("inter.feat_transfer_1.0"),
        fx.t("inter.feat_transfer_2.0"),
        fx.t("inter.feat_transfer_3.0"),
    ];
    let match_l = feats.matching(fl[0].clone());
    let match_r = feats.matching(features0(fx, 1));
    let gwc = build_gwc_volume(match_l.clone(), match_r.clone(), D, GWC_GROUPS);
    check(fx, "gwc volume", &gwc, "inter.gwc_volume.0", Tol::FEATURES);
    let corr = cost.corr_stem.forward(fx.t("inter.gwc_volume.0"));
    check(fx, "corr_stem", &corr, "inter.corr_stem.0", Tol::FEATURES);
    let att = cost
        .corr_feature_att
        .forward(fx.t("inter.corr_stem.0"), fl[0].clone());
    let agg = cost.cost_agg.forward(att, &fl);
    check(
        fx,
        "hourglass (cost_agg)",
        &agg,
        "inter.cost_agg.0",
        Tol::FEATURES,
    );
    let logits: Tensor<5> = cost.classifier.forward(fx.t("inter.cost_agg.0"));
    check(
        fx,
        "classifier",
        &logits,
        "inter.classifier.0",
        Tol::FEATURES,
    );
    let prob = softmax(fx.t::<5>("inter.classifier.0").squeeze_dim::<4>(1), 1);
    let init = disparity_regression(prob);
    check(
        fx,
        "init_disp (soft-argmin)",
        &init,
        "inter.init_disp_q.0",
        Tol::DISP_STAGE,
    );
    let chained = cost.forward(match_l, match_r, &fl, D);
    check(
        fx,
        "init_disp (chained from matching)",
        &chained.init_disp,
        "inter.init_disp_q.0",
        Tol::DISP_STAGE,
    );

    let w = spx.forward(fl[0].clone(), fx.t("inter.stem_2.0"));
    assert_eq!(w.dims(), [1, 9, 64, 128]);

    let stems = [
        fx.t("inter.stem_4.0"),
        fx.t("inter.stem_8.0"),
        fx.t("inter.stem_16.0"),
    ];
    let out = ctx.forward(&dpt(fx, "left"), stems);
    for (i, c) in out.cnet.iter().enumerate() {
        check(
            fx,
            &format!("context cnet[{i}]"),
            c,
            &format!("inter.cnet_{i}.0"),
            Tol::FEATURES,
        );
    }
}

fn iteration_stages(fx: &Fixture) {
    let parts = Parts::load(&fx.device);
    let inp = parts.inputs(fx);
    let init = fx.t::<4>("inter.init_disp_q.0");
    let geo0 = inp.geo.lookup(&init);
    check(fx, "geo lookup", &geo0, "inter.geo_feat.0", Tol::FEATURES);
    let out = parts
        .update_block
        .forward(inp.net.clone(), &inp.inp, geo0, init.clone());
    check(
        fx,
        "update_block delta",
        &out.delta,
        "inter.update_block.delta.0",
        Tol::DISP_STAGE,
    );
    check(
        fx,
        "update_block mask_feat",
        &out.mask_feat,
        "inter.update_block.mask_feat.0",
        Tol::FEATURES,
    );
    for i in 0..3 {
        check(
            fx,
            &format!("update_block net{i}"),
            &out.net[i],
            &format!("inter.update_block.net{i}.0"),
            Tol::FEATURES,
        );
    }
    let disp1 = init + fx.t::<4>("inter.update_block.delta.0");
    let (aligned, params) = align_mono(inp.disp_mono_4x.clone(), &disp1);
    let want = &fx.raw("scale_shift").1;
    println!("scale_shift got {:?} want {:?}", params[0], want);
    let warp = disp_warp(inp.features_right0.clone(), aligned);
    check(
        fx,
        "disp_warp (aligned mono)",
        &warp,
        "inter.feat_warp.0",
        Tol::FEATURES,
    );
    let warp = disp_warp(inp.features_right0.clone(), disp1.clone());
    check(
        fx,
        "disp_warp (stereo)",
        &warp,
        "inter.feat_warp.1",
        Tol::FEATURES,
    );
    let up0 = upsample_disp(
        &parts.spx_2_gru,
        &parts.spx_gru[0],
        disp1,
        fx.t::<4>("inter.update_block.mask_feat.0"),
        inp.stem_2x.clone(),
    );
    check(
        fx,
        "upsample_disp",
        &up0,
        "inter.upsample_disp.0",
        Tol::DISP_STAGE,
    );
    let refined = parts.remp.forward(
        fx.t::<4>("inter.upsample_disp.13"),
        fx.t::<4>("inter.upsample_disp.14"),
        inp.image1.clone(),
        inp.image2.clone(),
    );
    check(fx, "REMP", &refined, "inter.REMP.0", Tol::DISP_STAGE);

    // The loop from the fixture inputs, every traced intermediate.
    let mut worst = 0.0f32;
    let out = iterate_traced(
        &parts.blocks(),
        parts.inputs(fx),
        ITERS,
        false,
        &mut |n, t| {
            let key = format!("inter.{n}");
            if fx.tensors.contains_key(&key) {
                let (e, _) = err(fx, &format!("loop {n}"), t, &key);
                if key.contains("delta") || key.contains("upsample") || key.contains("REMP") {
                    worst = worst.max(e);
                }
            }
        },
    );
    check(fx, "loop: disp", &out.disp, "output.disp", Tol::DISP_END);
    assert!(
        worst <= Tol::DISP_END,
        "loop: worst disparity error {worst:e}"
    );
}

/// Tolerances of the GPU parity, in the fixture's units (features: activations of magnitude
/// ≲ 20; disparities: pixels). Measured on Mesa's lavapipe (llvmpipe, LLVM 15, `--features wgpu`,
/// burn's fusion and autotune off as this crate builds it): every feature map / volume within
/// 1.8e-5 (geo lookup, max |ref| 19), every single disparity stage within 1.2e-5 px, the whole
/// 8-iteration loop within 3.1e-5 px (mean 4.9e-6 px; the CPU backend: 2.7e-5 px). The bounds
/// leave ~5–30× room for other GPUs' FMA contraction and reduction orders, and are ~100× below
/// the 0.12 px that the permuted `grid_sample` grid cost (see [`grid_sample_grid_layout`]).
struct Tol;

impl Tol {
    /// Any feature map / volume of a single stage.
    const FEATURES: f32 = 1e-4;
    /// A single disparity stage (soft-argmin, one update, upsampling, REMP), px.
    const DISP_STAGE: f32 = 1e-4;
    /// End to end (8 iterations), px.
    const DISP_END: f32 = 1e-3;
}

#[test]
fn monsterpp_tiny_stages() {
    testdata::require!(FIXTURE);
    for (name, device) in gpu_devices() {
        println!("== {name}: mono branch");
        let fx = fixture_on(FIXTURE, &device);
        mono_stages(&fx);
        println!("== {name}: stereo features, cost volume, context");
        stereo_stages(&fx);
        println!("== {name}: iterations");
        iteration_stages(&fx);
    }
}

#[test]
fn monsterpp_tiny_end_to_end() {
    testdata::require!(FIXTURE);
    for (name, device) in gpu_devices() {
        let fx = fixture_on(FIXTURE, &device);
        let mut model = Monster::new(&MonsterConfig::tiny(), &device);
        let report = load_weights(&mut model, weights()).unwrap_or_else(|e| panic!("{e}"));
        assert!(report.is_complete(), "{report}");
        let t0 = std::time::Instant::now();
        let out = model.forward(fx.t("input.left"), fx.t("input.right"), ITERS, false);
        println!("== {name}: forward {:.2?}", t0.elapsed());
        check(
            &fx,
            "depth_mono",
            &out.depth_mono,
            "output.depth_mono",
            Tol::FEATURES,
        );
        let up = out.init_disp_up.as_ref().expect("train mode");
        check(
            &fx,
            "init_disp_up",
            up,
            "output.init_disp_up",
            Tol::DISP_END,
        );
        support::print_prediction_errors(&out.disp_preds, &fx.raw("output.disp_preds").1);
        let (max, mean) = err(&fx, "END-TO-END disp", &out.disp, "output.disp");
        println!("{name}: end to end max {max:.3e} px, mean {mean:.3e} px");
        assert!(max <= Tol::DISP_END, "end to end: {max:e} px");
    }
}

/// `grid_sample_2d` with a grid that is a permuted view (as `disp_warp_grid` used to build it) and
/// with the same grid made contiguous, against the CPU backend. burn-cubecl 0.22.1's bilinear
/// grid-sample kernel reads `gy` at `grid[offset + 1]`, ignoring the grid's last-axis stride: on
/// the GPU a permuted grid samples wrong rows (measured on lavapipe: max error of the order of the
/// values themselves), which is why `disp_warp_grid` must hand out a contiguous grid.
#[test]
fn grid_sample_grid_layout() {
    for (name, device) in gpu_devices() {
        let cpu = Device::flex();
        let img = Tensor::<4>::random([1, 3, 6, 9], Distribution::Normal(0.0, 1.0), &cpu);
        let g = Tensor::<4>::random([1, 2, 5, 7], Distribution::Uniform(-1.2, 1.2), &cpu);
        let opts = || {
            GridSampleOptions::new(InterpolateMode::Bilinear)
                .with_padding_mode(GridSamplePaddingMode::Border)
                .with_align_corners(false)
        };
        let want: Vec<f32> = img
            .clone()
            .grid_sample_2d(g.clone().permute([0, 2, 3, 1]), opts())
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let on = |t: &Tensor<4>| Tensor::<4>::from_data(t.to_data(), &device);
        let gpu_img = on(&img);
        let permuted = on(&g).permute([0, 2, 3, 1]);
        let contiguous = Tensor::<4>::from_data(permuted.to_data(), &device);
        let run = |grid: Tensor<4>| -> f32 {
            let got: Vec<f32> = gpu_img
                .clone()
                .grid_sample_2d(grid, opts())
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            support::max_abs_diff(&got, &want).0
        };
        let e_contiguous = run(contiguous);
        let e_permuted = run(permuted);
        println!(
            "{name}: grid_sample vs CPU: contiguous grid {e_contiguous:.3e}, \
             permuted-view grid {e_permuted:.3e}"
        );
        assert!(e_contiguous <= 1e-5, "contiguous grid: {e_contiguous:e}");
        // The grid `disp_warp` hands to grid_sample must be safe on this backend.
        let disp = Tensor::<4>::random([1, 1, 6, 9], Distribution::Uniform(0.0, 4.0), &cpu);
        let ref_warp: Vec<f32> = disp_warp(img.clone(), disp.clone())
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let got: Vec<f32> = disp_warp(gpu_img.clone(), on(&disp))
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let e_warp = support::max_abs_diff(&got, &ref_warp).0;
        println!("{name}: disp_warp vs CPU {e_warp:.3e}");
        assert_eq!(disp_warp_grid(on(&disp)).dims(), [1, 6, 9, 2]);
        assert!(e_warp <= 1e-5, "disp_warp on {name}: {e_warp:e}");
    }
}

#[test]
fn dinov3_tiny() {
    testdata::require!("fixtures/dinov3-tiny");
    for (name, device) in gpu_devices() {
        let fx = fixture_on("fixtures/dinov3-tiny", &device);
        let mut model = Dinov3Vit::new(&Dinov3Config::tiny(), &device);
        let path = support::fixture_dir("fixtures/dinov3-tiny").join("weights.safetensors");
        let report = load_dinov3(&mut model, &path).expect("fixture weights load");
        assert!(report.is_complete(), "{report}");
        let (last, layers) = model.forward_layers(fx.t::<4>("input.pixel_values"), true);
        println!("== {name}: DINOv3 tiny");
        for (i, out) in layers.iter().enumerate() {
            check(
                &fx,
                &format!("layer {i}"),
                out,
                &format!("inter.layer{i}.out"),
                Tol::FEATURES,
            );
        }
        check(
            &fx,
            "last_hidden_state",
            &last,
            "output.last_hidden_state",
            Tol::FEATURES,
        );
        let pooled = Dinov3Vit::pooler(last);
        check(
            &fx,
            "pooler",
            &pooled,
            "output.pooler_output",
            Tol::FEATURES,
        );
    }
}

#[test]
fn segformer_tiny() {
    testdata::require!("fixtures/segformer-tiny");
    for (name, device) in gpu_devices() {
        let fx = fixture_on("fixtures/segformer-tiny", &device);
        let mut model = Segformer::new(&SegformerConfig::tiny(), &device);
        let report = model
            .load(support::fixture_dir("fixtures/segformer-tiny").join("weights.safetensors"))
            .unwrap();
        assert!(report.unexpected.is_empty(), "{report}");
        println!("== {name}: SegFormer tiny");
        let logits = model.forward(fx.t::<4>("input.pixel_values"));
        check(&fx, "logits", &logits, "output.logits", Tol::FEATURES);
    }
}
