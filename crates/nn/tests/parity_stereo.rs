//! Numerical parity of the stereo features, the cost volume / 3-D aggregation / initial disparity,
//! the superpixel head and the context network against the upstream fixtures
//! (`fixtures/monsterpp-tiny`). Upstream parts are fed from the fixture intermediates
//! (`inter.dpt_feat_*`), and each stage is checked both in isolation (fixture inputs) and chained.

mod support;

use support::Fixture;

use burn::module::Module;
use burn::tensor::activation::softmax;
use burn::tensor::ops::PadMode;
use burn::tensor::{Device, Tensor};

use nn::monster::context::ContextNet;
use nn::monster::cost::{
    build_gwc_volume, disparity_regression, CostAggregation, SpxHead, GWC_GROUPS,
};
use nn::monster::features::StereoFeatures;

const FIXTURE: &str = "fixtures/monsterpp-tiny";
/// DPT `features` of the tiny fixture (= vits).
const DPT_F: usize = 64;
/// Hidden dim of the tiny fixture.
const HIDDEN: usize = 32;
/// max_disp / 4 of the tiny fixture.
const D: usize = 16;

impl Fixture {
    fn dpt(&self, side: &str) -> [Tensor<4>; 4] {
        std::array::from_fn(|i| self.t(&format!("inter.dpt_feat_{side}_{i}.0")))
    }

    /// Compares and prints; `rel_tol` is relative to the max |reference|. Returns the max abs error.
    fn check<const N: usize>(&self, label: &str, got: Tensor<N>, name: &str, rel_tol: f32) -> f32 {
        let (shape, want) = self.raw(name);
        assert_eq!(&got.dims().to_vec(), shape, "{label}: shape of {name}");
        let got: Vec<f32> = got.into_data().try_into_vec::<f32>().expect("f32 data");
        let (diff, scale) = support::max_abs_diff(&got, want);
        let rel = diff / scale.max(1e-12);
        println!("{label:<40} vs {name:<28} max|ref| {scale:>10.4e}  max abs err {diff:>10.3e}  rel {rel:>9.2e}");
        assert!(
            rel <= rel_tol,
            "{label}: relative error {rel:e} > {rel_tol:e} (abs {diff:e}, max|ref| {scale:e})"
        );
        diff
    }
}

/// Loads a root-level group (field names = upstream root keys) with an empty prefix.
fn load<M: Module>(mut m: M) -> M {
    let report = nn::weights::load_submodule(&mut m, support::fixture_weights(FIXTURE), "")
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(report.applied > 0);
    println!("loaded {} tensors", report.applied);
    m
}

#[test]
fn stereo_features() {
    testdata::require!(FIXTURE);
    let fx = Fixture::load(FIXTURE);
    let feats = load(StereoFeatures::new(DPT_F, &fx.device));

    for (side, idx) in [("left", 0), ("right", 1)] {
        let ft = feats.feat_transfer.forward(fx.dpt(side));
        for (i, t) in ft.into_iter().enumerate() {
            fx.check(
                &format!("feat_transfer[{i}] {side}"),
                t,
                &format!("inter.feat_transfer_{i}.{idx}"),
                2e-5,
            );
        }
        let stems = feats.stems(fx.image(side), idx == 0);
        let names = ["stem_2", "stem_4", "stem_8", "stem_16"];
        for (t, n) in stems.into_iter().zip(names) {
            fx.check(&format!("{n} {side}"), t, &format!("inter.{n}.{idx}"), 2e-5);
        }
    }

    // The assembled forward (left) gives the same tensors.
    let out = feats.forward(fx.dpt("left"), fx.image("left"), true);
    assert_eq!(out.stems.len(), 4);
    assert_eq!(out.features[0].dims(), [1, 96, 16, 32]);
    fx.check(
        "forward: features[1]",
        out.features[1].clone(),
        "inter.feat_transfer_1.0",
        2e-5,
    );
    let f0_ref = Tensor::cat(
        vec![
            fx.t::<4>("inter.feat_transfer_0.0"),
            fx.t::<4>("inter.stem_4.0"),
        ],
        1,
    );
    let diff: f32 = (out.features[0].clone() - f0_ref).abs().max().into_scalar();
    println!("forward: features[0] = cat(f4, stem_4): max abs err {diff:.3e}");
    assert!(diff < 1e-4);
}

#[test]
fn cost_volume_and_init_disp() {
    testdata::require!(FIXTURE);
    let fx = Fixture::load(FIXTURE);
    let feats = load(StereoFeatures::new(DPT_F, &fx.device));
    let cost = load(CostAggregation::new(&fx.device));

    // Stereo features from the fixture intermediates.
    let features = |idx: usize| -> [Tensor<4>; 4] {
        let f0 = Tensor::cat(
            vec![
                fx.t::<4>(&format!("inter.feat_transfer_0.{idx}")),
                fx.t::<4>(&format!("inter.stem_4.{idx}")),
            ],
            1,
        );
        [
            f0,
            fx.t(&format!("inter.feat_transfer_1.{idx}")),
            fx.t(&format!("inter.feat_transfer_2.{idx}")),
            fx.t(&format!("inter.feat_transfer_3.{idx}")),
        ]
    };
    let fl = features(0);
    let fr = features(1);
    let match_l = feats.matching(fl[0].clone());
    let match_r = feats.matching(fr[0].clone());

    // Isolated stages (each fed with the fixture output of the previous one).
    let gwc = build_gwc_volume(match_l.clone(), match_r.clone(), D, GWC_GROUPS);
    fx.check("gwc_volume", gwc, "inter.gwc_volume.0", 2e-5);
    fx.check(
        "corr_stem (fixture gwc)",
        cost.corr_stem.forward(fx.t("inter.gwc_volume.0")),
        "inter.corr_stem.0",
        2e-5,
    );
    let att = cost
        .corr_feature_att
        .forward(fx.t("inter.corr_stem.0"), fl[0].clone());
    fx.check(
        "cost_agg (fixture corr_stem)",
        cost.cost_agg.forward(att, &fl),
        "inter.cost_agg.0",
        1e-4,
    );
    let logits: Tensor<5> = cost.classifier.forward(fx.t("inter.cost_agg.0"));
    fx.check(
        "classifier (fixture cost_agg)",
        logits,
        "inter.classifier.0",
        1e-4,
    );
    let prob = softmax(fx.t::<5>("inter.classifier.0").squeeze_dim::<4>(1), 1);
    fx.check(
        "init_disp (fixture logits)",
        disparity_regression(prob),
        "inter.init_disp_q.0",
        1e-5,
    );

    // Chained from the matching features.
    let out = cost.forward(match_l.clone(), match_r.clone(), &fl, D);
    fx.check(
        "chained: cost_agg",
        out.geo_volume.clone(),
        "inter.cost_agg.0",
        1e-4,
    );
    fx.check(
        "chained: classifier",
        cost.logits(out.geo_volume).unsqueeze_dim::<5>(1),
        "inter.classifier.0",
        1e-4,
    );
    let e = fx.check(
        "chained: init_disp",
        out.init_disp,
        "inter.init_disp_q.0",
        1e-4,
    );
    println!("init_disp chained max abs err {e:.3e} px (1/4 resolution)");

    // Fully chained from the DPT paths and the images.
    let l = feats.forward(fx.dpt("left"), fx.image("left"), true);
    let r = feats.forward(fx.dpt("right"), fx.image("right"), false);
    let out = cost.forward(l.matching, r.matching, &l.features, D);
    fx.check(
        "from DPT paths: init_disp",
        out.init_disp,
        "inter.init_disp_q.0",
        1e-4,
    );
}

/// `context_upsample(disp·4, w)` written here only to check the spx head (the op belongs to
/// `upsample.rs`): 3×3 unfold with zero padding (tap order ky·3+kx), nearest ×4, Σ_k w_k·tap_k.
fn context_upsample_ref(disp: Tensor<4>, weights: Tensor<4>) -> Tensor<4> {
    let [b, _, h, w] = disp.dims();
    let padded = disp.pad([(0, 0), (0, 0), (1, 1), (1, 1)], PadMode::Constant(0.0));
    let taps: Vec<Tensor<4>> = (0..9)
        .map(|k| {
            let (ky, kx) = (k / 3, k % 3);
            padded.clone().narrow(2, ky, h).narrow(3, kx, w)
        })
        .collect();
    let taps = Tensor::cat(taps, 1); // [b, 9, h, w]
                                     // nearest ×4
    let up: Tensor<6> = taps.reshape([b, 9, h, 1, w, 1]);
    let up = up
        .repeat_dim(3, 4)
        .repeat_dim(5, 4)
        .reshape([b, 9, 4 * h, 4 * w]);
    (up * weights).sum_dim(1)
}

#[test]
fn spx_init_disp_up() {
    testdata::require!(FIXTURE);
    let fx = Fixture::load(FIXTURE);
    let spx = load(SpxHead::new(&fx.device));
    let f0 = Tensor::cat(
        vec![
            fx.t::<4>("inter.feat_transfer_0.0"),
            fx.t::<4>("inter.stem_4.0"),
        ],
        1,
    );
    let w = spx.forward(f0, fx.t("inter.stem_2.0"));
    assert_eq!(w.dims(), [1, 9, 64, 128]);
    let up = context_upsample_ref(fx.t::<4>("inter.init_disp_q.0").mul_scalar(4.0), w);
    fx.check("init_disp_up (spx head)", up, "output.init_disp_up", 1e-5);
}

#[test]
fn context() {
    testdata::require!(FIXTURE);
    let fx = Fixture::load(FIXTURE);
    let ctx = load(ContextNet::new(DPT_F, HIDDEN, &fx.device));
    let stems = [
        fx.t("inter.stem_4.0"),
        fx.t("inter.stem_8.0"),
        fx.t("inter.stem_16.0"),
    ];
    let out = ctx.forward(&fx.dpt("left"), stems);
    for (i, c) in out.cnet.iter().enumerate() {
        fx.check(
            &format!("cnet[{i}]"),
            c.clone(),
            &format!("inter.cnet_{i}.0"),
            2e-5,
        );
    }
    for i in 0..3 {
        let reference = fx.t::<4>(&format!("inter.cnet_{i}.0"));
        let dn: f32 = (out.net[i].clone() - reference.clone().tanh())
            .abs()
            .max()
            .into_scalar();
        let di: f32 = (out.inp[i].clone() - burn::tensor::activation::relu(reference))
            .abs()
            .max()
            .into_scalar();
        assert!(dn < 1e-5 && di < 1e-4, "net/inp level {i}: {dn:e} {di:e}");
        for part in &out.czqr[i] {
            assert_eq!(part.dims()[1], HIDDEN);
        }
    }
}

/// Gradients flow through the whole stereo path (gwc volume, hourglass, soft-argmin, spx head,
/// context) on the autodiff device; BN layers run in burn's training mode there.
#[test]
fn gradients_flow() {
    testdata::require!(FIXTURE);
    let fx = Fixture::load(FIXTURE);
    let dev = Device::flex().autodiff();
    let feats = load(StereoFeatures::new(DPT_F, &dev));
    let cost = load(CostAggregation::new(&dev));
    let spx = load(SpxHead::new(&dev));
    let ctx = load(ContextNet::new(DPT_F, HIDDEN, &dev));
    let on = |t: Tensor<4>| Tensor::<4>::from_data(t.into_data(), &dev);
    let dpt_l = fx.dpt("left").map(on);
    let dpt_r = fx.dpt("right").map(on);
    let l = feats.forward(dpt_l.clone(), on(fx.image("left")), true);
    let r = feats.forward(dpt_r, on(fx.image("right")), false);
    let out = cost.forward(l.matching.clone(), r.matching, &l.features, D);
    let w = spx.forward(l.features[0].clone(), l.stems[0].clone());
    let c = ctx.forward(
        &dpt_l,
        [l.stems[1].clone(), l.stems[2].clone(), l.stems[3].clone()],
    );
    let up = context_upsample_ref(out.init_disp.clone().mul_scalar(4.0), w);
    let loss =
        out.init_disp.mean() + up.mean() + c.czqr[2][2].clone().mean() + c.net[0].clone().mean();
    let grads = loss.backward();
    fn l1<const N: usize>(g: Tensor<N>) -> f32 {
        g.abs().sum().into_scalar()
    }
    let norms = [
        (
            "classifier",
            cost.classifier.weight.val().grad(&grads).map(l1),
        ),
        (
            "cost_agg.conv1.0",
            cost.cost_agg.conv1.0.conv.weight.val().grad(&grads).map(l1),
        ),
        (
            "corr_stem",
            cost.corr_stem.conv.weight.val().grad(&grads).map(l1),
        ),
        ("desc", feats.desc.weight.val().grad(&grads).map(l1)),
        (
            "stem_2.0",
            feats.stem_2.0.conv.weight.val().grad(&grads).map(l1),
        ),
        (
            "feat_transfer.conv32x",
            feats.feat_transfer.conv32x[0]
                .weight
                .val()
                .grad(&grads)
                .map(l1),
        ),
        (
            "spx_4.0",
            spx.spx_4.0.conv.weight.val().grad(&grads).map(l1),
        ),
        (
            "context_zqr_convs.2",
            ctx.context_zqr_convs[2].weight.val().grad(&grads).map(l1),
        ),
    ];
    for (name, g) in norms {
        let n = g.unwrap_or_else(|| panic!("{name}: no gradient"));
        println!("grad |{name}|_1 = {n:.3e}");
        assert!(n.is_finite() && n > 0.0, "{name}: gradient {n}");
    }
}

/// Rough CPU timing of the stereo path at a realistic size (run with `--ignored --nocapture`).
#[test]
#[ignore]
fn timing_stereo_path() {
    use burn::tensor::Distribution;
    let dev = Device::flex();
    let (hh, ww, d) = (256usize, 512usize, 48usize);
    let feats = StereoFeatures::new(DPT_F, &dev);
    let cost = CostAggregation::new(&dev);
    let ctx = ContextNet::new(DPT_F, 128, &dev);
    let rnd = |shape: [usize; 4]| Tensor::<4>::random(shape, Distribution::Normal(0.0, 1.0), &dev);
    let dpt = |_: usize| -> [Tensor<4>; 4] {
        std::array::from_fn(|i| rnd([1, DPT_F, hh / (4 << i), ww / (4 << i)]))
    };
    let t0 = std::time::Instant::now();
    let l = feats.forward(dpt(0), rnd([1, 3, hh, ww]), true);
    let r = feats.forward(dpt(1), rnd([1, 3, hh, ww]), false);
    let _ = l.matching.clone().sum().into_scalar::<f32>();
    let t1 = std::time::Instant::now();
    let gwc = build_gwc_volume(l.matching.clone(), r.matching.clone(), d, GWC_GROUPS);
    let _ = gwc.sum().into_scalar::<f32>();
    let t2 = std::time::Instant::now();
    let out = cost.forward(l.matching, r.matching, &l.features, d);
    let _ = out.init_disp.sum().into_scalar::<f32>();
    let t3 = std::time::Instant::now();
    let c = ctx.forward(
        &dpt(0),
        [l.stems[1].clone(), l.stems[2].clone(), l.stems[3].clone()],
    );
    let _ = c.czqr[0][0].clone().sum().into_scalar::<f32>();
    let t4 = std::time::Instant::now();
    println!(
        "{hh}x{ww}, D={d}: features(2 images) {:?}, gwc alone {:?}, cost (gwc+hourglass+regression) {:?}, context {:?}",
        t1 - t0,
        t2 - t1,
        t3 - t2,
        t4 - t3
    );
}
