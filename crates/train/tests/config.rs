//! Presets parse and carry the paper's values; overrides and bad input give clear errors.

use train::config::{preset_text, PRESETS};
use train::loss::SupervisionTarget;
use train::TrainConfig;

#[test]
fn every_preset_parses_and_validates() {
    for name in PRESETS {
        let c = TrainConfig::load(name, &[]).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(c.name, name);
        // The shipped file and the embedded text are the same.
        let file = std::fs::read_to_string(format!(
            "{}/presets/{name}.toml",
            env!("CARGO_MANIFEST_DIR")
        ))
        .unwrap();
        assert_eq!(preset_text(name).unwrap(), file);
    }
}

#[test]
fn paper_presets_have_the_paper_values() {
    for name in ["a-lidar", "b-disp", "c-photo", "d-full", "s1", "s2", "s3"] {
        let c = TrainConfig::load(name, &[]).unwrap();
        assert_eq!(c.model.preset, "vitl");
        assert_eq!(c.optim.lr, 5e-4);
        assert_eq!(c.optim.weight_decay, 1e-5);
        assert_eq!(c.optim.eps, 1e-8);
        assert_eq!(c.optim.grad_clip_norm, Some(1.0));
        assert_eq!(c.optim.feat_decoder_lr_factor, 0.5);
        assert_eq!(c.schedule.pct_start, 0.01);
        assert_eq!(c.schedule.extra_steps, 100);
        assert_eq!(
            (
                c.run.batch_size,
                c.run.steps,
                c.run.train_iters,
                c.run.valid_iters
            ),
            (4, 50_000, 22, 32)
        );
        assert_eq!(c.loss.lambda_disp, 0.05);
        assert!(!c.augment.do_flip);
    }
    let l = |n: &str| TrainConfig::load(n, &[]).unwrap().loss;
    assert_eq!(l("a-lidar").target, SupervisionTarget::Lidar);
    assert_eq!(
        (l("b-disp").lambda_photo, l("b-disp").lambda_smooth),
        (0.0, 0.0)
    );
    assert_eq!(
        (l("c-photo").lambda_photo, l("c-photo").lambda_smooth),
        (0.1, 0.0)
    );
    assert_eq!(
        (l("d-full").lambda_photo, l("d-full").lambda_smooth),
        (0.1, 0.1)
    );
    let e = |n: &str| TrainConfig::load(n, &[]).unwrap().data.experiment.unwrap();
    assert_eq!(e("s1"), "sub1_synchronic");
    assert_eq!(e("s2"), "sub2_synchronic");
    assert_eq!(e("s3"), "sub5_syndiach");
}

#[test]
fn overrides_apply_in_order_and_round_trip() {
    let c = TrainConfig::load(
        "tiny",
        &[
            "run.steps=7".into(),
            "optim.lr=1e-4".into(),
            "model.init=w/x.safetensors".into(),
            "augment.crop_width=96".into(),
            "run.steps=9".into(),
        ],
    )
    .unwrap();
    assert_eq!(c.run.steps, 9);
    assert_eq!(c.optim.lr, 1e-4);
    assert_eq!(
        c.model.init.as_deref(),
        Some(std::path::Path::new("w/x.safetensors"))
    );
    assert_eq!(c.augment.crop_width, 96);
    let again = TrainConfig::from_toml(&c.to_toml(), &[], "round trip").unwrap();
    assert_eq!(again, c);
}

#[test]
fn bad_input_is_named() {
    let err = |o: &str| {
        TrainConfig::load("tiny", &[o.into()])
            .unwrap_err()
            .to_string()
    };
    assert!(
        err("run.stepz=3").contains("stepz"),
        "{}",
        err("run.stepz=3")
    );
    assert!(err("augment.crop_height=50").contains("multiples of 32"));
    assert!(err("run.train_iters=3").contains("at least 7"));
    assert!(err("optim.lr=0").contains("optim.lr"));
    assert!(err("no_equals_sign").contains("key=value"));
    assert!(err("model.preset=vitg").contains("model.preset"));
    let missing = TrainConfig::load("/nonexistent/run.toml", &[])
        .unwrap_err()
        .to_string();
    assert!(
        missing.contains("/nonexistent/run.toml") && missing.contains("tiny"),
        "{missing}"
    );
}
