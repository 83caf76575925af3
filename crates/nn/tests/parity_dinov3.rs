//! DINOv3 ViT and the similarity score against the upstream reference
//! (`fixtures/dinov3-tiny`: HF `DINOv3ViTModel`, random F16-rounded weights, hidden 128,
//! 4 layers, 2 heads of 64, eager attention, CPU f32; transformers 4.57.6, torch 2.4.1).
//!
//! Each test prints the max abs differences it measured (`--nocapture`). The tolerances asserted
//! are the fixture's suggested ones; measured values are listed in the report of issue 6 and in
//! the `nn::dinov3` module docs.

mod support;

use std::collections::BTreeMap;

use burn::tensor::{Tensor, TensorData};
use nn::dinov3::{
    cosine_similarity, hf_keys, load_dinov3, mask_to_u8, Dinov3Config, Dinov3Error, Dinov3Features,
    Dinov3Preprocess, Dinov3Vit, Normalization,
};
use nn::weights::WeightsError;
use raster::geometry::{warp_by_disparity, warp_by_disparity_grid_sample};
use raster::{Image, Mask};
use support::{fixture_dir, max_abs_diff, Fixture};

const FIX: &str = "fixtures/dinov3-tiny";

fn tiny_model(fx: &Fixture) -> Dinov3Vit {
    let mut model = Dinov3Vit::new(&Dinov3Config::tiny(), &fx.device);
    let report =
        load_dinov3(&mut model, &support::fixture_weights(FIX)).expect("fixture weights load");
    assert!(
        report.is_complete() && report.unexpected.is_empty(),
        "{report}"
    );
    model
}

fn values<const N: usize>(t: Tensor<N>) -> Vec<f32> {
    t.into_data().try_into_vec_as::<f32>().unwrap()
}

/// Compares `got` with fixture tensor `name` (same shape), prints and asserts the max abs diff.
fn check<const N: usize>(fx: &Fixture, name: &str, got: Tensor<N>, tol: f32) -> f32 {
    let (shape, want) = fx.raw(name);
    assert_eq!(&got.dims().to_vec(), shape, "{name}: shape");
    let (diff, scale) = max_abs_diff(&values(got), want);
    eprintln!("{name:32} max abs diff {diff:.3e} (max |ref| {scale:.3})");
    assert!(diff <= tol, "{name}: max abs diff {diff} > {tol}");
    diff
}

fn hwc(fx: &Fixture, name: &str) -> Image {
    let (shape, v) = fx.raw(name);
    let c = if shape.len() == 3 { shape[2] } else { 1 };
    Image::new(shape[1], shape[0], c, v.clone()).unwrap()
}

fn mask_of(fx: &Fixture, name: &str) -> Mask {
    let img = hwc(fx, name);
    Mask::new(
        img.width(),
        img.height(),
        img.data().iter().map(|&v| v != 0.0).collect(),
    )
    .unwrap()
}

/// The processor size of the fixture: 64×96 (upstream uses 224×224).
fn fixture_preprocess() -> Dinov3Preprocess {
    Dinov3Preprocess {
        width: 96,
        height: 64,
        normalization: Normalization::IMAGENET,
    }
}

#[test]
fn embeddings_rope_and_layer0_intermediates() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let model = tiny_model(&fx);
    let px = fx.t::<4>("input.pixel_values");
    let emb = model.embeddings.forward(px.clone());
    check(&fx, "inter.embeddings", emb.clone(), 1e-5);

    let rope = model.rope(64, 96, &fx.device);
    check(&fx, "inter.rope_cos", rope.cos.clone(), 1e-6);
    check(&fx, "inter.rope_sin", rope.sin.clone(), 1e-6);

    let l0 = &model.layer[0];
    let prefix = model.num_prefix_tokens();
    let n1 = l0.norm1.forward(emb.clone());
    check(&fx, "inter.layer0.norm1", n1.clone(), 1e-5);
    check(
        &fx,
        "inter.layer0.q_proj",
        l0.attention.q_proj.forward(n1.clone()),
        1e-5,
    );
    let attn = l0.attention.forward(n1, &rope, prefix);
    check(&fx, "inter.layer0.attn", attn.clone(), 1e-5);
    let h = emb.clone() + l0.layer_scale1.forward(attn);
    check(
        &fx,
        "inter.layer0.mlp",
        l0.mlp.forward(l0.norm2.forward(h)),
        1e-5,
    );
    check(
        &fx,
        "inter.layer0.out",
        l0.forward(emb, &rope, prefix),
        1e-5,
    );
}

#[test]
fn every_layer_last_hidden_state_pooler_and_similarity() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let model = tiny_model(&fx);
    let (last, layers) = model.forward_layers(fx.t::<4>("input.pixel_values"), true);
    assert_eq!(layers.len(), 4);
    for (i, out) in layers.into_iter().enumerate() {
        check(&fx, &format!("inter.layer{i}.out"), out, 5e-5);
    }
    check(&fx, "output.last_hidden_state", last.clone(), 1e-4);
    let pooled = Dinov3Vit::pooler(last);
    check(&fx, "output.pooler_output", pooled.clone(), 1e-4);
    let f = values(pooled);
    let score = cosine_similarity(&f[..128], &f[128..]);
    let want = fx.raw("output.cosine_similarity").1[0];
    eprintln!(
        "cosine similarity {score} vs {want}: diff {:.3e}",
        (score - want).abs()
    );
    assert!((score - want).abs() <= 1e-6);
}

#[test]
fn warp_masks_and_uint8_inputs_match_the_reference() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let left = hwc(&fx, "input.left");
    let right = hwc(&fx, "input.right");
    let gt = hwc(&fx, "input.gt_disp");
    let want_hat = hwc(&fx, "warp.left_hat");
    let want_valid = mask_of(&fx, "warp.valid");
    let want_final = mask_of(&fx, "warp.final_mask");

    // The reference semantics, operation by operation.
    let (hat, valid) = warp_by_disparity_grid_sample(&right, &gt).unwrap();
    let finite = Mask::from_fn(gt.width(), gt.height(), |x, y| gt.get(x, y, 0).is_finite());
    let final_mask = valid.and(&finite).unwrap();
    assert_eq!(valid, want_valid, "warp.valid");
    assert_eq!(final_mask, want_final, "warp.final_mask");
    assert_eq!(final_mask.count(), 10671);
    let (diff, _) = max_abs_diff(hat.data(), want_hat.data());
    eprintln!("warp.left_hat (grid_sample port)  max abs diff {diff:.3e} over all pixels");
    assert_eq!(diff, 0.0, "warp.left_hat: bit-exact expected");

    // The training warp (`warp_by_disparity`) differs by design: 0 outside its mask and a 1e-6
    // border slack; inside the final mask it agrees with the reference to float rounding.
    let (old_hat, old_valid) = warp_by_disparity(&right, &gt).unwrap();
    let inside: Vec<usize> = (0..final_mask.data().len())
        .filter(|&i| final_mask.data()[i])
        .collect();
    let old_diff = inside
        .iter()
        .flat_map(|&i| (0..3).map(move |c| 3 * i + c))
        .map(|k| (old_hat.data()[k] - want_hat.data()[k]).abs())
        .fold(0.0f32, f32::max);
    let mask_flips = old_valid
        .data()
        .iter()
        .zip(want_final.data())
        .filter(|(a, b)| a != b)
        .count();
    eprintln!(
        "warp_by_disparity (training warp): max abs diff inside the final mask {old_diff:.3e}, \
         {mask_flips} pixels where its mask differs from warp.final_mask"
    );

    // Masking + uint8 truncation, from our warp and from the reference warp.
    let want_left_u8 = hwc(&fx, "pre.left_u8");
    let want_hat_u8 = hwc(&fx, "pre.left_hat_u8");
    let left_u8 = mask_to_u8(&left, Some(&final_mask), "left").unwrap();
    assert_eq!(left_u8, want_left_u8, "pre.left_u8");
    let hat_u8_ref = mask_to_u8(&want_hat, Some(&final_mask), "left_hat").unwrap();
    assert_eq!(
        hat_u8_ref, want_hat_u8,
        "pre.left_hat_u8 from the reference warp"
    );
    let hat_u8 = mask_to_u8(&hat, Some(&final_mask), "left_hat").unwrap();
    let flips = hat_u8
        .data()
        .iter()
        .zip(want_hat_u8.data())
        .filter(|(a, b)| a != b)
        .count();
    eprintln!("pre.left_hat_u8 from our warp: {flips} values differ");
    assert_eq!(flips, 0, "pre.left_hat_u8 from our warp");

    // The processor: bit-exact pixel values.
    let pre = fixture_preprocess();
    let mut px = pre.pixel_values(&left_u8).unwrap();
    px.extend(pre.pixel_values(&hat_u8).unwrap());
    let (diff, _) = max_abs_diff(&px, &fx.raw("input.pixel_values").1);
    eprintln!("input.pixel_values from the images  max abs diff {diff:.3e}");
    assert!(diff <= 1e-6, "input.pixel_values: {diff}");
}

#[test]
fn similarity_from_the_images_end_to_end() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let dino = Dinov3Features::from_file(
        &support::fixture_weights(FIX),
        Dinov3Config::tiny(),
        fx.device.clone(),
    )
    .unwrap()
    .with_preprocess(fixture_preprocess())
    .unwrap();
    let left = hwc(&fx, "input.left");
    let right = hwc(&fx, "input.right");
    let gt = hwc(&fx, "input.gt_disp");
    let (hat, valid) = warp_by_disparity_grid_sample(&right, &gt).unwrap();
    let finite = Mask::from_fn(gt.width(), gt.height(), |x, y| gt.get(x, y, 0).is_finite());
    let final_mask = valid.and(&finite).unwrap();
    let score = dino.similarity(&left, &hat, &final_mask).unwrap();
    let want = fx.raw("output.cosine_similarity").1[0];
    eprintln!(
        "similarity from input.left/right/gt_disp {score} vs {want}: diff {:.3e}",
        (score - want).abs()
    );
    assert!((score - want).abs() <= 1e-6);

    // `features` on an already-masked image equals the pooler output of that batch entry.
    let masked_left = mask_to_u8(&left, Some(&final_mask), "left").unwrap();
    let f = dino.features(&masked_left).unwrap();
    let (diff, _) = max_abs_diff(&f, &fx.raw("output.pooler_output").1[..128]);
    eprintln!("features(left masked) vs pooler_output[0]  max abs diff {diff:.3e}");
    assert!(diff <= 1e-4);

    // Bad inputs are errors, not scores.
    let empty = Mask::filled(left.width(), left.height(), false);
    assert!(matches!(
        dino.similarity(&left, &hat, &empty),
        Err(Dinov3Error::Input(_))
    ));
    let small = Image::filled(10, 10, 3, 0.0);
    assert!(dino.similarity(&left, &small, &final_mask).is_err());
}

#[test]
fn processor_and_model_at_224() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let model = tiny_model(&fx);
    let image = hwc(&fx, "pre224.image_u8");
    let pre = Dinov3Preprocess::default();
    assert_eq!((pre.width, pre.height), (224, 224));
    let px = pre.pixel_values(&image).unwrap();
    let (diff, _) = max_abs_diff(&px, &fx.raw("pre224.pixel_values").1);
    eprintln!("pre224.pixel_values  max abs diff {diff:.3e}");
    assert!(diff <= 1e-6, "pre224.pixel_values: {diff}");

    let x = Tensor::<4>::from_data(TensorData::new(px, [1, 3, 224, 224]), &fx.device);
    let last = model.forward(x);
    check(&fx, "output224.last_hidden_state", last.clone(), 1e-4);
    check(
        &fx,
        "output224.pooler_output",
        Dinov3Vit::pooler(last),
        1e-4,
    );
}

#[test]
fn presets_have_the_released_key_sets_and_sizes() {
    testdata::require!(FIX);
    let device = burn::tensor::Device::flex();
    for (name, cfg, count) in [
        ("vits16", Dinov3Config::vits16(), 21_596_544usize),
        ("vitb16", Dinov3Config::vitb16(), 85_660_416),
        ("vitl16", Dinov3Config::vitl16(), 303_129_600),
    ] {
        cfg.validate().unwrap();
        assert_eq!(cfg.head_dim(), 64);
        let model = Dinov3Vit::new(&cfg, &device);
        let keys: BTreeMap<String, Vec<usize>> = hf_keys(&model).into_iter().collect();
        assert_eq!(
            keys,
            support::listed_keys(FIX, &format!("state_dict_keys_{name}.txt"), ""),
            "{name}: key set"
        );
        let n: usize = keys.values().map(|s| s.iter().product::<usize>()).sum();
        assert_eq!(n, count, "{name}: parameter count");
    }
    assert_eq!(
        Dinov3Config::from_checkpoint(&support::fixture_weights(FIX)).unwrap(),
        Dinov3Config::tiny()
    );
    // The fixture's HF config (`meta.json["config_tiny"]`) read as a `config.json`.
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture_dir(FIX).join("meta.json")).unwrap())
            .unwrap();
    let dir = tempdir();
    let json = dir.join("config.json");
    std::fs::write(&json, meta["config_tiny"].to_string()).unwrap();
    assert_eq!(
        Dinov3Config::from_hf_json(&json).unwrap(),
        Dinov3Config::tiny()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn wrong_or_damaged_checkpoints_are_reported_in_hf_names() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    // A size mismatch (ViT-S on the tiny weights) names HF keys.
    let err = Dinov3Features::from_file(
        &support::fixture_weights(FIX),
        Dinov3Config::vits16(),
        fx.device.clone(),
    )
    .err()
    .expect("vits16 must not load the tiny weights");
    let text = err.to_string();
    assert!(text.contains("layer.0.mlp.up_proj.weight"), "{text}");
    assert!(text.contains("layer.11."), "{text}");

    let dir = tempdir();
    // A missing layer scale is reported under its HF name.
    let missing = dir.join("missing.safetensors");
    support::write_edited_weights(FIX, &missing, |name, shape, data| {
        (name != "layer.2.layer_scale2.lambda1").then_some((shape, data))
    });
    let mut model = Dinov3Vit::new(&Dinov3Config::tiny(), &fx.device);
    match load_dinov3(&mut model, &missing) {
        Err(WeightsError::Mismatch { report }) => {
            assert_eq!(
                report.missing,
                vec!["layer.2.layer_scale2.lambda1".to_string()]
            );
        }
        other => panic!("expected a mismatch, got {other:?}"),
    }
    // A key the model does not have is an error too (strict loading).
    let extra = dir.join("extra.safetensors");
    let bytes = std::fs::read(support::fixture_weights(FIX)).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let norm = st.tensor("norm.weight").unwrap();
    let mut views: Vec<(String, safetensors::tensor::TensorView)> = st.tensors();
    views.push(("layer.4.norm1.weight".to_string(), norm));
    std::fs::write(&extra, safetensors::serialize(views, None).unwrap()).unwrap();
    let mut model = Dinov3Vit::new(&Dinov3Config::tiny(), &fx.device);
    match load_dinov3(&mut model, &extra) {
        Err(WeightsError::Mismatch { report }) => {
            assert!(report.missing.is_empty(), "{report}");
            assert_eq!(report.unexpected, vec!["layer.4.norm1.weight".to_string()]);
        }
        other => panic!("expected a mismatch, got {other:?}"),
    }
    // A truncated file names the problem.
    let mut cut = std::fs::read(support::fixture_weights(FIX)).unwrap();
    cut.truncate(cut.len() / 2);
    let truncated = dir.join("truncated.safetensors");
    std::fs::write(&truncated, &cut).unwrap();
    let err = Dinov3Features::from_file(&truncated, Dinov3Config::tiny(), fx.device.clone())
        .err()
        .expect("a truncated file must not load");
    assert!(err.to_string().contains("truncated"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A fresh scratch folder per call (tests run in parallel).
fn tempdir() -> std::path::PathBuf {
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("parity_dinov3_{}_{n}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
