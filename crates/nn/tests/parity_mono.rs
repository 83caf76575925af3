//! Parity of the mono branch (DINOv2 + both DPT heads) against the upstream tiny fixture
//! `fixtures/monsterpp-tiny` (`inter.vit_*`, `inter.depth_mono`, `inter.dpt_feat_*`).

mod support;

use burn::tensor::{Device, Tensor, TensorData};
use nn::config::MonsterConfig;
use nn::monster::dpt::{infer_mono, DptHead};
use nn::monster::vit::{mono_input, normalize_image, DinoVisionTransformer};
use nn::weights::load_submodule;

const FIX: &str = "fixtures/monsterpp-tiny";

fn input(name: &str, device: &Device) -> Tensor<4> {
    let (shape, v) = support::tensor(FIX, "tensors.safetensors", name);
    Tensor::from_data(
        TensorData::new(v, [shape[0], shape[1], shape[2], shape[3]]),
        device,
    )
}

fn values<const D: usize>(t: Tensor<D>) -> (Vec<usize>, Vec<f32>) {
    let shape = t.dims().to_vec();
    (
        shape,
        t.into_data().convert::<f32>().try_to_vec::<f32>().unwrap(),
    )
}

/// Compares with the reference; returns (max abs error, max |ref|).
fn check<const D: usize>(got: Tensor<D>, name: &str, rel_tol: f32) -> (f32, f32) {
    let (want_shape, want) = support::tensor(FIX, "tensors.safetensors", name);
    let (shape, got) = values(got);
    assert_eq!(shape, want_shape, "{name}: shape");
    let (err, scale) = support::max_abs_diff(&got, &want);
    eprintln!(
        "{name:32} max abs err {err:.3e}  (max |ref| {scale:.3e}, rel {:.3e})",
        err / scale.max(1e-12)
    );
    assert!(
        err <= rel_tol * scale.max(1.0),
        "{name}: max abs err {err} > {rel_tol} x {scale}"
    );
    (err, scale)
}

#[test]
fn vit_matches_fixture() {
    testdata::require!(FIX);
    let device = Device::default();
    let cfg = MonsterConfig::tiny();
    let mut vit = DinoVisionTransformer::new(&cfg.vit, &device);
    let report = load_submodule(&mut vit, support::fixture_weights(FIX), "mono_encoder.")
        .expect("load mono_encoder");
    assert!(report.unexpected.is_empty(), "{report}");

    let x = mono_input(normalize_image(input("input.left", &device)));
    check(x.clone(), "inter.vit_in.0", 1e-5);
    let feats = vit.forward_intermediate(x);
    for i in 0..4 {
        check(
            feats.tokens[i].clone(),
            &format!("inter.vit_layer{i}_tokens.0"),
            1e-4,
        );
        check(
            feats.cls[i].clone(),
            &format!("inter.vit_layer{i}_cls.0"),
            1e-4,
        );
    }
}

#[test]
fn dpt_heads_match_fixture() {
    testdata::require!(FIX);
    let device = Device::default();
    let cfg = MonsterConfig::tiny();
    let mut vit = DinoVisionTransformer::new(&cfg.vit, &device);
    load_submodule(&mut vit, support::fixture_weights(FIX), "mono_encoder.")
        .expect("load mono_encoder");
    let mut mono = DptHead::new(cfg.vit.embed_dim, &cfg.dpt, true, &device);
    let r = load_submodule(&mut mono, support::fixture_weights(FIX), "mono_decoder.")
        .expect("load mono_decoder");
    assert!(r.unexpected.is_empty(), "{r}");
    let mut feat = DptHead::new(cfg.vit.embed_dim, &cfg.dpt, false, &device);
    let r = load_submodule(&mut feat, support::fixture_weights(FIX), "feat_decoder.")
        .expect("load feat_decoder");
    assert!(r.unexpected.is_empty(), "{r}");

    let left = input("input.left", &device);
    let [_, _, h, w] = left.dims();
    let fl = vit.forward_intermediate(mono_input(normalize_image(left)));
    let fr = vit.forward_intermediate(mono_input(normalize_image(input("input.right", &device))));

    // The one-call form gives the same tensors.
    let all = infer_mono(
        &vit,
        &mono,
        &feat,
        normalize_image(input("input.left", &device)),
        normalize_image(input("input.right", &device)),
    );
    check(all.depth_mono, "output.depth_mono", 1e-4);
    check(
        all.features_right[0].clone(),
        "inter.dpt_feat_right_0.0",
        1e-4,
    );

    let depth = mono.forward_depth(&fl, [h, w]);
    check(depth.clone(), "inter.depth_mono.0", 1e-4);
    check(depth, "output.depth_mono", 1e-4);
    for (side, f) in [("left", &fl), ("right", &fr)] {
        let paths = feat.forward_features(f);
        for (i, p) in paths.into_iter().enumerate() {
            check(p, &format!("inter.dpt_feat_{side}_{i}.0"), 1e-4);
        }
    }
}
