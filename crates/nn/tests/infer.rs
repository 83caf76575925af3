//! `nn::infer::MonsterPredictor` on the upstream fixture (`fixtures/monsterpp-tiny`):
//! the whole pipeline (image → padding → network → unpadding) reproduces `output.disp`; tiling,
//! NaN handling and the error messages.

mod support;

use burn::tensor::Device;
use nn::config::MonsterConfig;
use nn::infer::{InferError, MonsterPredictor};
use raster::Image;

const FIXTURE: &str = "fixtures/monsterpp-tiny";

/// NCHW (1×3×H×W) → (H, W, 3) image.
fn image(name: &str) -> Image {
    let (shape, v) = support::tensor(FIXTURE, "tensors.safetensors", name);
    let (h, w) = (shape[2], shape[3]);
    let mut data = vec![0f32; h * w * 3];
    for c in 0..3 {
        for i in 0..h * w {
            data[i * 3 + c] = v[c * h * w + i];
        }
    }
    Image::new(w, h, 3, data).unwrap()
}

fn predictor() -> MonsterPredictor {
    let weights = support::fixture_dir(FIXTURE).join("weights.safetensors");
    MonsterPredictor::load(MonsterConfig::tiny(), &weights, Device::flex()).expect("load")
}

#[test]
fn predictor_reproduces_fixture() {
    testdata::require!(FIXTURE);
    let p = predictor();
    assert_eq!(p.iters, 8);
    let (l, r) = (image("input.left"), image("input.right"));
    let d = p.predict(&l, &r).unwrap();
    assert_eq!((d.width(), d.height(), d.channels()), (128, 64, 1));
    let (_, want) = support::tensor(FIXTURE, "tensors.safetensors", "output.disp");
    let (diff, scale) = support::max_abs_diff(d.data(), &want);
    println!("max abs err {diff:.3e} px (max |disp| {scale:.3})");
    assert!(diff <= 1e-3, "max abs error {diff} px");

    // A grey copy, with a NaN: runs, and the NaN pixel is NaN in the output.
    let mut g = l.to_gray();
    g.set(5, 7, 0, f32::NAN);
    let d = p.predict(&g, &r.to_gray()).unwrap();
    assert!(d.get(5, 7, 0).is_nan());
    assert_eq!(d.data().iter().filter(|v| !v.is_finite()).count(), 1);
}

#[test]
fn strips_blend_and_odd_sizes() {
    testdata::require!(FIXTURE);
    let mut p = predictor();
    let (l, r) = (image("input.left"), image("input.right"));
    // Odd size: padding on every side.
    let crop = |im: &Image| raster::geometry::crop(im, 3, 2, 121, 59).unwrap();
    let d = p.predict(&crop(&l), &crop(&r)).unwrap();
    assert_eq!(d.size(), (121, 59));
    assert!(d.data().iter().all(|v| v.is_finite()));
    // Strips of 32 rows overlapping by 16: close to the whole-image answer on a constant scene.
    let whole = p.predict(&l, &r).unwrap();
    p.tile_rows = Some(32);
    p.tile_overlap = 16;
    assert_eq!(p.plan(128, 64).unwrap(), vec![(0, 32), (16, 48), (32, 64)]);
    let tiled = p.predict(&l, &r).unwrap();
    let (diff, _) = support::max_abs_diff(tiled.data(), whole.data());
    let mean: f32 = tiled
        .data()
        .iter()
        .zip(whole.data())
        .map(|(a, b)| (a - b).abs())
        .sum::<f32>()
        / tiled.data().len() as f32;
    println!("tiled vs whole: max {diff:.3} px, mean {mean:.3} px");
    assert!(tiled.data().iter().all(|v| v.is_finite()));
    // A tiny budget forces strips or a clear error.
    p.tile_rows = None;
    p.memory_budget = 1;
    let msg = p.predict(&l, &r).unwrap_err().to_string();
    assert!(
        msg.contains("budget") && msg.contains("--strip-rows"),
        "{msg}"
    );
}

#[test]
fn errors_name_the_problem() {
    testdata::require!(FIXTURE);
    let dir = support::fixture_dir(FIXTURE);
    let missing = MonsterPredictor::load(
        MonsterConfig::tiny(),
        &dir.join("no-such.pth"),
        Device::flex(),
    )
    .err()
    .expect("missing file");
    let msg = missing.to_string();
    assert!(msg.contains("no-such.pth"), "{msg}");

    let wrong = MonsterPredictor::load(
        MonsterConfig::vits(),
        &dir.join("weights.safetensors"),
        Device::flex(),
    )
    .err()
    .expect("vits config on tiny weights");
    let msg = wrong.to_string();
    println!("{msg}");
    assert!(matches!(wrong, InferError::Mismatch { .. }));
    assert!(
        msg.contains("`vits`") && msg.contains("--config tiny"),
        "{msg}"
    );
    assert!(msg.contains("mono_encoder."), "names the keys: {msg}");
}
