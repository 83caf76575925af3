//! The assembled MonSter++ model: end-to-end parity against the upstream tiny fixture
//! (`fixtures/monsterpp-tiny`), key sets and parameter counts at the real configs,
//! load errors on a whole checkpoint, and the save/reload round trip.

mod support;
use support::Fixture;

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::{Device, Tensor};
use nn::config::MonsterConfig;
use nn::monster::{Monster, MonsterOutput};
use nn::weights::{load_weights, module_keys, save_checkpoint, WeightsError};
use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};

const FIX: &str = "fixtures/monsterpp-tiny";
const ITERS: usize = 8;

fn tiny_loaded(device: &Device) -> Monster {
    let mut model = Monster::new(&MonsterConfig::tiny(), device);
    let report =
        load_weights(&mut model, support::fixture_weights(FIX)).unwrap_or_else(|e| panic!("{e}"));
    assert!(report.is_complete(), "{report}");
    assert!(
        report.unexpected.is_empty(),
        "unexpected keys in the fixture: {report}"
    );
    println!(
        "loaded {} tensors ({} num_batches_tracked ignored)",
        report.applied,
        report.ignored.len()
    );
    model
}

fn run(model: &Monster, fx: &Fixture, test_mode: bool) -> MonsterOutput {
    let t0 = std::time::Instant::now();
    let out = model.forward(
        fx.t::<4>("input.left"),
        fx.t::<4>("input.right"),
        ITERS,
        test_mode,
    );
    println!(
        "forward (test_mode = {test_mode}, 64×128, {ITERS} iters): {:.2?}",
        t0.elapsed()
    );
    out
}

/// The one sample's scale/shift against the fixture's.
fn check_scale_shift(got: &[(f32, f32)], want: &[f32], mono_max: f32) {
    assert_eq!(got.len(), 1, "one sample");
    support::check_scale_shift(got[0], want, mono_max);
}

#[test]
fn end_to_end_parity_test_mode() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let model = tiny_loaded(&Device::flex());
    assert_eq!(model.config(), &MonsterConfig::tiny());
    let out = run(&model, &fx, true);
    let err = fx.assert_close(&out.disp, "output.disp", 1e-3);
    println!("END-TO-END output.disp max abs error: {err:.3e} px");
    assert!(out.disp_preds.is_empty());
    assert!(out.init_disp_up.is_none());
    fx.assert_close(&out.depth_mono, "output.depth_mono", 1e-4);
    check_scale_shift(&out.scale_shift, &fx.raw("scale_shift").1, fx.mono_max());
}

#[test]
fn end_to_end_parity_train_mode() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let model = tiny_loaded(&Device::flex());
    let out = run(&model, &fx, false);
    assert_eq!(out.disp_preds.len(), ITERS + 7);
    assert_eq!(out.disp_preds.len(), fx.raw("output.disp_preds").0[0]);
    let preds = Tensor::stack::<5>(out.disp_preds.clone(), 0);
    fx.assert_close(&preds, "output.disp_preds", 1e-3);
    support::print_prediction_errors(&out.disp_preds, &fx.raw("output.disp_preds").1);
    let last = out.disp_preds.last().unwrap().clone();
    let same: f32 = (last - out.disp.clone()).abs().max().into_scalar();
    assert_eq!(same, 0.0, "the last prediction is the output");
    fx.assert_close(&out.disp, "output.disp", 1e-3);
    let init_up = out
        .init_disp_up
        .as_ref()
        .expect("train mode gives init_disp_up");
    fx.assert_close(init_up, "output.init_disp_up", 1e-4);
    fx.assert_close(&out.depth_mono, "output.depth_mono", 1e-4);
    check_scale_shift(&out.scale_shift, &fx.raw("scale_shift").1, fx.mono_max());
}

// ---------------------------------------------------------------- key sets and counts

/// Builds the model at a real config (lazy: nothing is allocated), compares the key sets and
/// returns (total, trainable) parameters.
fn check_keys(name: &str) -> (usize, usize) {
    let cfg = MonsterConfig::preset(name).unwrap();
    let model = Monster::new(&cfg, &Device::flex());
    let ours: BTreeMap<String, Vec<usize>> = module_keys(&model).into_iter().collect();
    let theirs = support::listed_keys(FIX, &format!("state_dict_keys_{name}.txt"), "");
    let missing: Vec<_> = theirs.keys().filter(|k| !ours.contains_key(*k)).collect();
    let extra: Vec<_> = ours.keys().filter(|k| !theirs.contains_key(*k)).collect();
    let wrong: Vec<_> = theirs
        .iter()
        .filter(|(k, s)| ours.get(*k).is_some_and(|o| o != *s))
        .map(|(k, s)| format!("{k}: ours {:?}, upstream {s:?}", ours[k]))
        .collect();
    assert!(
        missing.is_empty() && extra.is_empty() && wrong.is_empty(),
        "{name}: missing {missing:?}\nextra {extra:?}\nwrong shapes {wrong:?}"
    );
    let (total, trainable) = (model.num_params(), model.num_trainable_params());
    println!(
        "{name}: {} keys, {:.2} M parameters, {:.2} M trainable with the mono branch frozen",
        ours.len(),
        total as f64 / 1e6,
        trainable as f64 / 1e6
    );
    (total, trainable)
}

fn assert_millions(got: usize, want_m: f64, what: &str) {
    let m = got as f64 / 1e6;
    assert!(
        (m - want_m).abs() <= 0.005 + 1e-9,
        "{what}: {m:.4} M, expected {want_m} M"
    );
}

#[test]
fn key_sets_and_param_counts_vits() {
    testdata::require!(FIX);
    let (t, tr) = check_keys("vits");
    assert_millions(t, 47.79, "vits total");
    assert_millions(tr, 23.00, "vits trainable");
}

#[test]
fn key_sets_and_param_counts_vitb() {
    testdata::require!(FIX);
    let (t, tr) = check_keys("vitb");
    assert_millions(t, 129.39, "vitb total");
    assert_millions(tr, 31.92, "vitb trainable");
}

#[test]
fn key_sets_and_param_counts_vitl() {
    testdata::require!(FIX);
    let (t, tr) = check_keys("vitl");
    // Exact values from the upstream listing (PyTorch `parameters()`, buffers excluded).
    assert_eq!(t, 388_690_818);
    assert_eq!(tr, 53_375_169);
    assert_millions(t, 388.69, "vitl total");
    assert_millions(tr, 53.38, "vitl trainable");
}

#[test]
fn param_count_tiny_matches_fixture_meta() {
    let model = Monster::new(&MonsterConfig::tiny(), &Device::flex());
    assert_eq!(model.num_params(), 10_310_914); // meta.json `param_count_total`
    assert_eq!(
        model.num_params() - model.num_trainable_params(),
        528_832 + 831_169 // mono_encoder + mono_decoder
    );
}

// ---------------------------------------------------------------- load errors

fn load_err(path: &PathBuf) -> (WeightsError, String) {
    let mut model = Monster::new(&MonsterConfig::tiny(), &Device::flex());
    let err = load_weights(&mut model, path).expect_err("the load must fail");
    let msg = err.to_string();
    eprintln!("{msg}");
    (err, msg)
}

#[test]
fn missing_keys_are_an_error_naming_them() {
    testdata::require!(FIX);
    let path = support::tmp("missing.safetensors");
    let gone = [
        "update_block_mix_mono.gru08.convq.weight",
        "REMP.RefinementBlock.conv3b.conv2.bn.running_var",
        "mono_encoder.pos_embed",
    ];
    // (This file's header length happens to end in the byte 0x80, which `weights` once took for
    // a legacy PyTorch pickle; see `safetensors_header_length_0x80_is_not_pickle`.)
    support::write_edited_weights(FIX, &path, |n, s, b| (!gone.contains(&n)).then_some((s, b)));
    let (err, msg) = load_err(&path);
    assert!(matches!(err, WeightsError::Mismatch { .. }));
    assert!(msg.contains("missing.safetensors"), "{msg}");
    for k in gone {
        assert!(msg.contains(k), "{k} not named in:\n{msg}");
    }
    let WeightsError::Mismatch { report } = err else {
        unreachable!()
    };
    assert_eq!(report.missing.len(), 3, "{report}");
}

#[test]
fn wrong_shapes_are_an_error_naming_them() {
    testdata::require!(FIX);
    let path = support::tmp("shape.safetensors");
    support::write_edited_weights(FIX, &path, |n, s, b| match n {
        // Halved output channels.
        "classifier.weight" => Some((
            vec![s[0], s[1] / 2, s[2], s[3], s[4]],
            b[..b.len() / 2].to_vec(),
        )),
        // Same element count, different layout ([1, 32, 3, 3] → [32, 1, 3, 3]).
        "REMP.final_conv.weight" => Some((vec![s[1], s[0], s[2], s[3]], b)),
        "context_zqr_convs.1.bias" => Some((vec![s[0] / 3], b[..b.len() / 3].to_vec())),
        _ => Some((s, b)),
    });
    let (err, msg) = load_err(&path);
    let WeightsError::Mismatch { report } = err else {
        panic!("expected a mismatch error, got {msg}")
    };
    assert!(msg.contains("shape.safetensors"), "{msg}");
    for k in [
        "classifier.weight",
        "context_zqr_convs.1.bias",
        "REMP.final_conv.weight",
    ] {
        assert!(
            report.mismatched.iter().any(|m| m.contains(k)),
            "{k} not reported:\n{msg}"
        );
    }
    assert!(msg.contains("shape"), "{msg}");
    assert_eq!(report.mismatched.len(), 3, "{report}");
}

#[test]
fn truncated_or_foreign_file_is_an_error_naming_it() {
    testdata::require!(FIX);
    let bytes = std::fs::read(support::fixture_weights(FIX)).unwrap();
    let path = support::tmp("truncated.safetensors");
    std::fs::write(&path, &bytes[..bytes.len() - 1000]).unwrap();
    let (err, msg) = load_err(&path);
    assert!(matches!(err, WeightsError::Format { .. }), "{msg}");
    assert!(
        msg.contains("truncated.safetensors") && msg.contains("truncated"),
        "{msg}"
    );

    let path = support::tmp("header-only.safetensors");
    std::fs::write(&path, &bytes[..100]).unwrap();
    let (_, msg) = load_err(&path);
    assert!(msg.contains("header-only.safetensors"), "{msg}");

    let (err, msg) = load_err(&support::tmp("does-not-exist.pth"));
    assert!(matches!(err, WeightsError::Io { .. }), "{msg}");
    assert!(msg.contains("does-not-exist.pth"), "{msg}");
}

/// A safetensors file whose u64 header length has 0x80 as its first (low) byte is still read as
/// safetensors, not as a legacy PyTorch pickle (which also starts with 0x80).
#[test]
fn safetensors_header_length_0x80_is_not_pickle() {
    let data = vec![0u8; 8];
    let path = support::tmp("header-0x80.safetensors");
    let bytes = (0..512)
        .map(|k| {
            let view = TensorView::new(Dtype::F32, vec![2], &data).unwrap();
            let meta = HashMap::from([("pad".to_string(), "x".repeat(k))]);
            safetensors::serialize([("w", view)], Some(meta)).unwrap()
        })
        .find(|b| b[0] == 0x80)
        .expect("some padding gives a header length ending in 0x80");
    std::fs::write(&path, bytes).unwrap();
    let keys = nn::weights::file_keys(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(keys, vec![("w".to_string(), vec![2])]);
}

/// A checkpoint of another layout (here: an encoder with 6 instead of 12 blocks) names the keys
/// it lacks instead of failing somewhere in the forward pass.
#[test]
fn wrong_config_is_an_error() {
    testdata::require!(FIX);
    let path = support::tmp("other-config.safetensors");
    support::write_edited_weights(FIX, &path, |n, s, b| {
        let deep = n
            .strip_prefix("mono_encoder.blocks.")
            .and_then(|r| r.split('.').next())
            .and_then(|i| i.parse::<usize>().ok())
            .is_some_and(|i| i >= 6);
        (!deep).then_some((s, b))
    });
    let (_, msg) = load_err(&path);
    assert!(
        msg.contains("mono_encoder.blocks.11.attn.qkv.weight"),
        "{msg}"
    );
}

// ---------------------------------------------------------------- save / reload

#[test]
fn save_and_reload_gives_identical_output() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let device = Device::flex();
    let model = tiny_loaded(&device);
    let path = support::tmp("roundtrip.safetensors");
    save_checkpoint(&model, &path).unwrap();
    let mut back = Monster::new(&MonsterConfig::tiny(), &device);
    let report = load_weights(&mut back, &path).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        report.is_complete() && report.unexpected.is_empty(),
        "{report}"
    );
    // The saved file has exactly the upstream key set (minus num_batches_tracked).
    let saved: Vec<String> = nn::weights::file_keys(&path)
        .unwrap()
        .into_iter()
        .map(|(k, _)| k)
        .collect();
    let want: Vec<String> = nn::weights::file_keys(support::fixture_weights(FIX))
        .unwrap()
        .into_iter()
        .map(|(k, _)| k)
        .filter(|k| !k.ends_with("num_batches_tracked"))
        .collect();
    assert_eq!(saved, want);

    let a = run(&model, &fx, true).disp;
    let b = run(&back, &fx, true).disp;
    let diff: f32 = (a.clone() - b).abs().max().into_scalar();
    println!("save/reload: max abs output difference {diff:e}");
    assert_eq!(diff, 0.0);
    fx.assert_close(&a, "output.disp", 1e-3);
}

// ---------------------------------------------------------------- training setup

struct GradCounter {
    path: Vec<String>,
    trainable: usize,
    frozen: usize,
    frozen_outside_mono: Vec<String>,
}

impl ModuleVisitor for GradCounter {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let key = self.path.join(".");
        if key.ends_with("running_mean") || key.ends_with("running_var") {
            return;
        }
        let n = param.lazy_shape().num_elements();
        if param.val().is_require_grad() {
            self.trainable += n;
        } else {
            self.frozen += n;
            if !key.starts_with("mono_") {
                self.frozen_outside_mono.push(key);
            }
        }
    }
}

/// `freeze_for_training` on the autodiff device: exactly the mono branch stops requiring
/// gradients (matching `num_trainable_params`).
#[test]
fn freeze_for_training_freezes_exactly_the_mono_branch() {
    let device = Device::flex().autodiff();
    let model = Monster::new(&MonsterConfig::tiny(), &device).freeze_for_training();
    let mut v = GradCounter {
        path: Vec::new(),
        trainable: 0,
        frozen: 0,
        frozen_outside_mono: Vec::new(),
    };
    model.visit(&mut v);
    assert!(
        v.frozen_outside_mono.is_empty(),
        "{:?}",
        v.frozen_outside_mono
    );
    assert_eq!(v.trainable, model.num_trainable_params());
    assert_eq!(v.trainable + v.frozen, model.num_params());
}

#[test]
fn depth_anything_checkpoint_loads_into_the_mono_branch_and_the_dpt_copy() {
    testdata::require!(FIX);
    // A Depth Anything V2 checkpoint made from the fixture's mono branch: `pretrained.*` and
    // `depth_head.*` keys, nothing else.
    let path = support::tmp("depth_anything.safetensors");
    let bytes = std::fs::read(support::fixture_weights(FIX)).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let renamed: Vec<(String, TensorView)> = st
        .tensors()
        .into_iter()
        .filter_map(|(name, view)| {
            let key = name
                .strip_prefix("mono_encoder.")
                .map(|k| format!("pretrained.{k}"))
                .or_else(|| {
                    name.strip_prefix("mono_decoder.")
                        .map(|k| format!("depth_head.{k}"))
                })?;
            Some((key, view))
        })
        .collect();
    std::fs::write(&path, safetensors::serialize(renamed, None).unwrap()).unwrap();

    let mut model = Monster::new(&MonsterConfig::tiny(), &Device::flex());
    let [encoder, head, copy] = model.load_depth_anything(&path).unwrap();
    assert!(encoder.is_complete() && head.is_complete() && copy.is_complete());
    assert!(
        !copy.unexpected.is_empty(),
        "the DPT copy leaves the output convolutions unused"
    );
    // The encoder holds the fixture's ViT weights, the DPT copy the depth head's.
    let fixture = support::read_all(&support::fixture_weights(FIX));
    let value = |key: &str| fixture.iter().find(|(n, _, _)| n == key).unwrap().2.clone();
    let got = |t: Tensor<4>| t.into_data().try_into_vec::<f32>().unwrap();
    assert_eq!(
        got(model.mono_encoder.patch_embed.proj.weight.val()),
        value("mono_encoder.patch_embed.proj.weight")
    );
    assert_eq!(
        got(model.feat_decoder.scratch.layer1_rn.weight.val()),
        value("mono_decoder.scratch.layer1_rn.weight")
    );
    let _ = std::fs::remove_file(&path);
}
