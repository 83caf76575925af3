//! End-to-end training on a tiny procedural-world set (the release's layout, built by
//! `stages::world_training`): exact resume, initialisation from the MonSter++ fixture weights,
//! the frozen mono branch, checkpoints, logs and the stop request.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, OnceLock};

use train::{train, Quiet, TrainConfig, TrainOptions};

/// A 1-train-world, 1-validation-world set of 128² px, built once per test binary.
fn world_set() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir =
            std::env::temp_dir().join(format!("seasonstereo-train-tests-{}", std::process::id()));
        let opts = stages::world_training::WorldTrainingOptions::new(&dir, 128, 1, 1);
        stages::world_training::build_world_training(&opts, &workflow::Silent)
            .expect("world training set");
        dir
    })
}

/// The tiny preset at the smallest useful size, validation off.
fn config(output: &Path, extra: &[&str]) -> TrainConfig {
    let mut o: Vec<String> = vec![
        format!("data.root={:?}", world_set().display().to_string()),
        format!("run.output={:?}", output.display().to_string()),
        "run.batch_size=1".into(),
        "run.train_iters=7".into(),
        "run.valid_iters=7".into(),
        "run.validate_every=0".into(),
        "run.validate_at_start=false".into(),
        "run.keep_checkpoints=0".into(),
        "augment.crop_height=32".into(),
        "augment.crop_width=64".into(),
        "model.max_disp=32".into(),
        "loss.max_disp=32.0".into(),
        "loss.ignore_border=2".into(),
    ];
    o.extend(extra.iter().map(|s| s.to_string()));
    TrainConfig::load("tiny", &o).unwrap()
}

/// `total` steps straight vs `stop` steps, stop (checkpoint), resume in a "new process" (new
/// model, new parameter ids, optimiser and schedule from files), `total − stop` more: the same
/// losses.
fn check_resume(total: usize, stop: usize) {
    let tmp = tempfile::tempdir().unwrap();
    let steps = format!("run.steps={total}");
    let every = format!("run.checkpoint_every={stop}");
    let extra = [steps.as_str(), every.as_str()];
    let straight = config(&tmp.path().join("straight"), &extra);
    let a = train(&straight, &TrainOptions::default(), &mut Quiet).unwrap();
    assert_eq!(a.losses.len(), total);
    assert!(!a.interrupted);

    let split = config(&tmp.path().join("split"), &extra);
    let first = TrainOptions {
        stop_after: Some(stop),
        ..TrainOptions::default()
    };
    let b = train(&split, &first, &mut Quiet).unwrap();
    assert!(b.interrupted);
    assert_eq!(b.steps_done, stop);
    let ck = b.checkpoint.clone().unwrap();
    assert!(
        ck.ends_with(format!("checkpoints/step-{stop:07}")),
        "{}",
        ck.display()
    );

    let resume_cfg = train::trainer::resume_config(&tmp.path().join("split"), &[]).unwrap();
    assert_eq!(resume_cfg, split);
    let second = TrainOptions {
        resume: Some(tmp.path().join("split")),
        ..TrainOptions::default()
    };
    let c = train(&resume_cfg, &second, &mut Quiet).unwrap();
    assert_eq!(c.steps_done, total);
    assert_eq!(c.losses.len(), total - stop);

    for (k, (x, y)) in a.losses[..stop].iter().zip(&b.losses).enumerate() {
        assert_eq!(x.total, y.total, "step {k} before the stop");
    }
    for (k, (x, y)) in a.losses[stop..].iter().zip(&c.losses).enumerate() {
        let tol = 1e-5 * x.total.abs().max(1.0);
        assert!(
            (x.total - y.total).abs() <= tol,
            "step {}: straight {} vs resumed {}",
            k + stop,
            x.total,
            y.total
        );
    }
    // The loss moves: the comparison is not between constants.
    assert!(a
        .losses
        .iter()
        .any(|l| (l.total - a.losses[0].total).abs() > 1e-3));

    // The resumed log reads as one run: rows 1..=total.
    let log = std::fs::read_to_string(tmp.path().join("split/metrics.csv")).unwrap();
    let steps: Vec<usize> = log
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(steps, (1..=total).collect::<Vec<_>>());
    assert!(tmp.path().join("split/final.safetensors").is_file());
}

/// The acceptance check: a run stopped after its checkpoint at step 2 and resumed gives the same
/// losses for the next 20 iterations as 22 uninterrupted steps (about a minute on 2 cores).
#[test]
fn resume_continues_exactly_for_20_steps() {
    check_resume(22, 2);
}

fn tensor_f32(file: &Path, key: &str) -> Vec<f32> {
    let bytes = std::fs::read(file).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let t = st
        .tensor(key)
        .unwrap_or_else(|e| panic!("{}: {key}: {e}", file.display()));
    match t.dtype() {
        safetensors::Dtype::F32 => t
            .data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect(),
        safetensors::Dtype::F16 => t
            .data()
            .chunks_exact(2)
            .map(|b| half::f16::from_le_bytes(b.try_into().unwrap()).to_f32())
            .collect(),
        d => panic!("{key}: unexpected dtype {d:?}"),
    }
}

/// Training starts from the MonSter++ fixture weights (the import path in training): the frozen
/// mono branch keeps them exactly, the trained parts move, validation scores the model, and the
/// stop flag ends the run with a checkpoint.
#[test]
fn trains_from_fixture_weights_with_frozen_mono_branch() {
    let init = testdata::require!("fixtures/monsterpp-tiny").join("weights.safetensors");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let cfg = config(
        &out,
        &[
            &format!("model.init={:?}", init.display().to_string()),
            "run.steps=2",
            "run.checkpoint_every=1",
            "run.validate_every=2",
            "run.validate_at_start=true",
            "run.valid_crop=64",
            "data.valid_limit=1",
        ],
    );
    let s = train(&cfg, &TrainOptions::default(), &mut Quiet).unwrap();
    assert_eq!(s.steps_done, 2);
    assert!(s
        .losses
        .iter()
        .all(|l| l.total.is_finite() && l.total > 0.0));
    let (v0, v1) = (s.first_validation.unwrap(), s.last_validation.unwrap());
    assert!(v0.epe.is_finite() && v1.epe.is_finite() && v0.pairs == 1);

    let saved = out.join("final.safetensors");
    for key in [
        "mono_encoder.blocks.0.attn.qkv.weight",
        "mono_decoder.scratch.output_conv1.weight",
    ] {
        assert_eq!(
            tensor_f32(&saved, key),
            tensor_f32(&init, key),
            "{key} is frozen"
        );
    }
    for key in [
        "feat_decoder.projects.0.weight",
        "update_block_mix_stereo.encoder.convc1.weight",
        "classifier.weight",
    ] {
        assert_ne!(
            tensor_f32(&saved, key),
            tensor_f32(&init, key),
            "{key} is trained"
        );
    }
    // BatchNorm3d keeps training (running statistics move); BatchNorm2d is frozen.
    assert_ne!(
        tensor_f32(&saved, "corr_stem.bn.running_mean"),
        tensor_f32(&init, "corr_stem.bn.running_mean")
    );
    assert_eq!(
        tensor_f32(&saved, "spx_2_gru.conv1.bn.running_mean"),
        tensor_f32(&init, "spx_2_gru.conv1.bn.running_mean")
    );
    let vlog = std::fs::read_to_string(out.join("validation.csv")).unwrap();
    assert_eq!(vlog.lines().count(), 3, "{vlog}");
    assert!(out.join("checkpoints/step-0000001/optimizer.bpk").is_file());
    assert_eq!(
        std::fs::read_to_string(out.join("checkpoints/latest"))
            .unwrap()
            .trim(),
        "step-0000002"
    );

    // A stop request (what Ctrl-C sets) ends the next run after one step, with a checkpoint.
    let stop = Arc::new(AtomicBool::new(true));
    let out2 = tmp.path().join("stopped");
    let cfg2 = config(&out2, &["run.steps=5", "run.checkpoint_every=100"]);
    let opts = TrainOptions {
        stop: Some(stop),
        ..TrainOptions::default()
    };
    let s2 = train(&cfg2, &opts, &mut Quiet).unwrap();
    assert!(s2.interrupted);
    assert_eq!(s2.steps_done, 1);
    assert!(out2
        .join("checkpoints/step-0000001/model.safetensors")
        .is_file());
}

#[test]
fn bad_resume_folders_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let err = train::trainer::resume_config(tmp.path(), &[])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(&tmp.path().display().to_string()) && err.contains("checkpoints"),
        "{err}"
    );
}
