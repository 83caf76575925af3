//! Weight import: key sets of the mono-branch modules at the real configs, parameter counts,
//! error reports (missing key, wrong shape, truncated file) and the checkpoint round trip.

mod support;

use std::collections::BTreeMap;

use burn::module::Module;
use burn::tensor::Device;
use nn::config::MonsterConfig;
use nn::monster::dpt::DptHead;
use nn::monster::vit::DinoVisionTransformer;
use nn::weights::{
    file_keys, load_submodule, load_weights, module_keys, save_checkpoint, WeightsError,
};
use safetensors::tensor::TensorView;
use safetensors::SafeTensors;

const FIX: &str = "fixtures/monsterpp-tiny";
const PARTS: [&str; 3] = ["mono_encoder.", "mono_decoder.", "feat_decoder."];

struct Parts {
    encoder: DinoVisionTransformer,
    mono: DptHead,
    feat: DptHead,
}

fn build(cfg: &MonsterConfig, device: &Device) -> Parts {
    cfg.validate().unwrap();
    Parts {
        encoder: DinoVisionTransformer::new(&cfg.vit, device),
        mono: DptHead::new(cfg.vit.embed_dim, &cfg.dpt, true, device),
        feat: DptHead::new(cfg.vit.embed_dim, &cfg.dpt, false, device),
    }
}

fn keys_of(parts: &Parts, prefix: &str) -> BTreeMap<String, Vec<usize>> {
    match prefix {
        "mono_encoder." => module_keys(&parts.encoder),
        "mono_decoder." => module_keys(&parts.mono),
        _ => module_keys(&parts.feat),
    }
    .into_iter()
    .collect()
}

fn check_keys(name: &str, cfg: MonsterConfig) -> Parts {
    let parts = build(&cfg, &Device::default());
    for prefix in PARTS {
        let want = support::listed_keys(FIX, &format!("state_dict_keys_{name}.txt"), prefix);
        let got = keys_of(&parts, prefix);
        assert!(!want.is_empty());
        let missing: Vec<_> = want.keys().filter(|k| !got.contains_key(*k)).collect();
        let extra: Vec<_> = got.keys().filter(|k| !want.contains_key(*k)).collect();
        assert!(
            missing.is_empty() && extra.is_empty(),
            "{name} {prefix}: missing {missing:?}, extra {extra:?}"
        );
        for (k, s) in &want {
            assert_eq!(&got[k], s, "{name} {prefix}{k}: shape");
        }
    }
    parts
}

#[test]
fn key_sets_vits() {
    testdata::require!(FIX);
    check_keys("vits", MonsterConfig::vits());
}

#[test]
fn key_sets_vitb() {
    testdata::require!(FIX);
    check_keys("vitb", MonsterConfig::vitb());
}

/// Lazy parameters: building ViT-L allocates nothing, so this is cheap.
#[test]
fn key_sets_and_param_counts_vitl() {
    testdata::require!(FIX);
    let parts = check_keys("vitl", MonsterConfig::vitl());
    let m = |n: usize| (n as f64 / 1e6 * 100.0).round() / 100.0;
    assert_eq!(m(parts.encoder.num_params()), 304.37);
    assert_eq!(m(parts.mono.num_params()), 30.95);
    assert_eq!(m(parts.feat.num_params()), 30.62);
    // Everything is still lazy (nothing was materialised by counting or listing).
}

#[test]
fn param_counts_tiny_exact() {
    let parts = build(&MonsterConfig::tiny(), &Device::default());
    // meta.json param_count_by_child
    assert_eq!(parts.encoder.num_params(), 528_832);
    assert_eq!(parts.mono.num_params(), 831_169);
    assert_eq!(parts.feat.num_params(), 803_424);
}

#[test]
fn config_validation() {
    for c in [
        MonsterConfig::tiny(),
        MonsterConfig::vits(),
        MonsterConfig::vitb(),
        MonsterConfig::vitl(),
    ] {
        c.validate().unwrap();
    }
    let mut c = MonsterConfig::tiny();
    c.max_disp = 60;
    assert!(c.validate().unwrap_err().to_string().contains("max_disp"));
    let mut c = MonsterConfig::tiny();
    c.iters = 6;
    assert!(c.validate().unwrap_err().to_string().contains("iters"));
    let mut c = MonsterConfig::vitl();
    c.hidden_dims = [128, 64, 128];
    assert!(c
        .validate()
        .unwrap_err()
        .to_string()
        .contains("hidden_dims"));
    let mut c = MonsterConfig::vits();
    c.vit.intermediate_layers = [2, 5, 8, 12];
    assert!(c
        .validate()
        .unwrap_err()
        .to_string()
        .contains("intermediate_layers"));
    assert!(MonsterConfig::preset("vitg").is_err());
    assert_eq!(
        MonsterConfig::preset("tiny").unwrap(),
        MonsterConfig::tiny()
    );
}

// ---------------------------------------------------------------- error cases

fn tiny_encoder() -> DinoVisionTransformer {
    DinoVisionTransformer::new(&MonsterConfig::tiny().vit, &Device::default())
}

#[test]
fn missing_key_is_an_error_naming_it() {
    testdata::require!(FIX);
    let path = support::tmp("missing.safetensors");
    support::write_edited_weights(FIX, &path, |n, s, b| {
        (n != "mono_encoder.blocks.3.attn.qkv.weight" && n != "mono_encoder.norm.weight")
            .then_some((s, b))
    });
    let err = load_submodule(&mut tiny_encoder(), &path, "mono_encoder.").unwrap_err();
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(matches!(err, WeightsError::Mismatch { .. }));
    assert!(msg.contains("missing.safetensors"), "{msg}");
    assert!(
        msg.contains("mono_encoder.blocks.3.attn.qkv.weight"),
        "{msg}"
    );
    assert!(msg.contains("mono_encoder.norm.weight"), "{msg}");
}

#[test]
fn wrong_shape_is_an_error_naming_it() {
    testdata::require!(FIX);
    let path = support::tmp("shape.safetensors");
    support::write_edited_weights(FIX, &path, |n, s, b| {
        if n == "mono_encoder.blocks.0.mlp.fc1.bias" {
            let half = b.len() / 2;
            Some((vec![s[0] / 2], b[..half].to_vec()))
        } else {
            Some((s, b))
        }
    });
    let err = load_submodule(&mut tiny_encoder(), &path, "mono_encoder.").unwrap_err();
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(msg.contains("mono_encoder.blocks.0.mlp.fc1.bias"), "{msg}");
    assert!(msg.contains("shape"), "{msg}");
}

#[test]
fn unexpected_keys_are_reported_not_fatal() {
    testdata::require!(FIX);
    let path = support::fixture_dir(FIX).join("weights.safetensors");
    // A feat_decoder-shaped head loaded from the mono_decoder keys: the output convs are extra.
    let mut dec = DptHead::new(64, &MonsterConfig::tiny().dpt, false, &Device::default());
    let report = load_submodule(&mut dec, &path, "mono_decoder.").unwrap();
    assert_eq!(report.unexpected.len(), 6, "{report}"); // output_conv1/2 weights + biases
    assert!(report
        .unexpected
        .iter()
        .all(|k| k.starts_with("mono_decoder.scratch.output_conv")));
}

#[test]
fn truncated_file_is_an_error_naming_the_file() {
    testdata::require!(FIX);
    let bytes = std::fs::read(support::fixture_dir(FIX).join("weights.safetensors")).unwrap();
    let path = support::tmp("truncated.safetensors");
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let err = load_submodule(&mut tiny_encoder(), &path, "mono_encoder.").unwrap_err();
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(
        msg.contains("truncated.safetensors") && msg.contains("truncated"),
        "{msg}"
    );
    let path = support::tmp("tiny.bin");
    std::fs::write(&path, [1u8, 2, 3]).unwrap();
    let msg = load_weights(&mut tiny_encoder(), &path)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("tiny.bin"), "{msg}");
    let msg = load_weights(
        &mut tiny_encoder(),
        support::tmp("does-not-exist.safetensors"),
    )
    .unwrap_err()
    .to_string();
    assert!(msg.contains("does-not-exist.safetensors"), "{msg}");
}

#[test]
fn module_prefix_and_wrapper_are_stripped() {
    testdata::require!(FIX);
    let path = support::tmp("wrapped.safetensors");
    // `model.module.mono_encoder.*`, as a flattened `{'model': DataParallel state_dict}`.
    let bytes = std::fs::read(support::fixture_dir(FIX).join("weights.safetensors")).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let views: Vec<(String, TensorView)> = st
        .tensors()
        .into_iter()
        .map(|(n, v)| (format!("model.module.{n}"), v))
        .collect();
    std::fs::write(&path, safetensors::serialize(views, None).unwrap()).unwrap();
    let report = load_submodule(&mut tiny_encoder(), &path, "mono_encoder.").unwrap();
    assert_eq!(report.applied, 12 * 14 + 7, "{report}"); // 14 per block + cls/pos/mask/patch(2)/norm(2)
    assert!(
        report.unexpected.is_empty() && report.ignored.is_empty(),
        "{report}"
    );
}

#[test]
fn checkpoint_round_trip() {
    testdata::require!(FIX);
    let device = Device::default();
    let mut enc = tiny_encoder();
    load_submodule(
        &mut enc,
        support::fixture_dir(FIX).join("weights.safetensors"),
        "mono_encoder.",
    )
    .unwrap();
    let path = support::tmp("ckpt.safetensors");
    save_checkpoint(&enc, &path).unwrap();
    save_checkpoint(&enc, &path).unwrap(); // overwrites
                                           // Saved in PyTorch naming (LayerNorm weight/bias, Linear [out, in]).
    let keys: BTreeMap<_, _> = file_keys(&path).unwrap().into_iter().collect();
    assert_eq!(keys["norm.weight"], vec![64]);
    assert_eq!(keys["blocks.0.mlp.fc1.weight"], vec![128, 64]);
    let mut back = DinoVisionTransformer::new(&MonsterConfig::tiny().vit, &device);
    load_weights(&mut back, &path).unwrap();
    let a = enc.blocks[4].mlp.fc1.weight.val().into_data();
    let b = back.blocks[4].mlp.fc1.weight.val().into_data();
    assert_eq!(a, b);
    // f16 fixture weights are upcast to f32 on load.
    assert_eq!(
        enc.blocks[0].attn.qkv.weight.val().dtype(),
        burn::tensor::DType::F32
    );
    assert_eq!(back.pos_embed.val().dtype(), burn::tensor::DType::F32);
    let a = enc.norm.gamma.val().into_data();
    let b = back.norm.gamma.val().into_data();
    assert_eq!(a, b);
}
