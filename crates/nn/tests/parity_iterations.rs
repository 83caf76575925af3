//! Numerical parity of the refinement iterations (geo encoding lookup, disp_warp, scale/shift
//! alignment, ConvGRU update blocks, upsample_disp, REMP and the whole loop) against the upstream
//! fixtures (`fixtures/monsterpp-tiny`). Inputs come from the fixture intermediates
//! (`inter.cost_agg.0`, `inter.init_disp_q.0`, `inter.cnet_*`, `inter.feat_transfer_0.*`,
//! `inter.stem_*`, `output.depth_mono`); matching features go through the `conv`/`desc` weights.

mod support;

use support::tiny::{Parts, FIXTURE};
use support::Fixture;

use burn::tensor::Tensor;

use nn::monster::scale_shift::align_mono;
use nn::monster::update::{iterate, iterate_traced};
use nn::monster::upsample::{freeze_bn, upsample_disp};
use nn::monster::warp::disp_warp;

const ITERS: usize = 8;

/// Each stage fed with fixture tensors (no error accumulation).
#[test]
fn stages_in_isolation() {
    testdata::require!(FIXTURE);
    let fx = Fixture::load(FIXTURE);
    let dev = fx.device.clone();
    let parts = Parts::load(&dev);
    let inp = parts.inputs(&fx);

    // Geo encoding lookup at the initial disparity.
    let init = fx.t::<4>("inter.init_disp_q.0");
    let geo0 = inp.geo.lookup(&init);
    fx.assert_close(&geo0, "inter.geo_feat.0", 1e-4);

    // Plain update block, iteration 0.
    let out = parts
        .update_block
        .forward(inp.net.clone(), &inp.inp, geo0, init.clone());
    fx.assert_close(&out.delta, "inter.update_block.delta.0", 1e-5);
    fx.assert_close(&out.mask_feat, "inter.update_block.mask_feat.0", 1e-5);
    for i in 0..3 {
        fx.assert_close(&out.net[i], &format!("inter.update_block.net{i}.0"), 1e-5);
    }
    let disp1 = init + fx.t::<4>("inter.update_block.delta.0");
    let up0 = upsample_disp(
        &parts.spx_2_gru,
        &parts.spx_gru[0],
        disp1.clone(),
        fx.t::<4>("inter.update_block.mask_feat.0"),
        inp.stem_2x.clone(),
    );
    fx.assert_close(&up0, "inter.upsample_disp.0", 1e-4);
    fx.assert_close(&inp.geo.lookup(&disp1), "inter.geo_feat.1", 1e-4);

    // Scale/shift alignment at iteration 1 and the two feature warps.
    let (aligned, params) = align_mono(inp.disp_mono_4x.clone(), &disp1);
    let want = &fx.raw("scale_shift").1;
    println!("scale_shift got {:?} want {:?}", params[0], want);
    support::check_scale_shift(params[0], want, fx.mono_max());
    fx.assert_close(
        &disp_warp(inp.features_right0.clone(), aligned),
        "inter.feat_warp.0",
        1e-4,
    );
    fx.assert_close(
        &disp_warp(inp.features_right0.clone(), disp1),
        "inter.feat_warp.1",
        1e-4,
    );

    // REMP on the fixture's last upsampled mono/stereo disparities.
    let refined = parts.remp.forward(
        fx.t::<4>("inter.upsample_disp.13"),
        fx.t::<4>("inter.upsample_disp.14"),
        inp.image1.clone(),
        inp.image2.clone(),
    );
    fx.assert_close(&refined, "inter.REMP.0", 1e-4);
}

/// The whole loop from the fixture inputs, train mode (every intermediate and prediction) and
/// test mode (the output disparity).
#[test]
fn iterations_end_to_end() {
    testdata::require!(FIXTURE);
    let fx = Fixture::load(FIXTURE);
    let dev = fx.device.clone();
    let parts = Parts::load(&dev);
    let blocks = parts.blocks();

    let t0 = std::time::Instant::now();
    let mut worst: Vec<(String, f32)> = Vec::new();
    let out = iterate_traced(&blocks, parts.inputs(&fx), ITERS, false, &mut |name, t| {
        let key = format!("inter.{name}");
        if fx.tensors.contains_key(&key) {
            let (e, s) = fx.err(t, &key);
            println!("{key:<45} max abs err {e:.3e}  (max |ref| {s:.3e})");
            worst.push((key, e));
        }
    });
    println!("train-mode loop: {:.2?}", t0.elapsed());
    for (k, e) in &worst {
        let tol = if k.contains("upsample_disp") || k.contains("REMP") {
            2e-4
        } else {
            1e-4
        };
        assert!(*e <= tol, "{k}: {e:e} > {tol:e}");
    }
    let want = &fx.raw("scale_shift").1;
    println!("scale_shift got {:?} want {:?}", out.scale_shift, want);
    support::check_scale_shift(out.scale_shift[0], want, fx.mono_max());
    assert_eq!(out.disp_preds.len(), fx.raw("output.disp_preds").0[0]);
    let preds = Tensor::stack::<5>(out.disp_preds.clone(), 0);
    fx.assert_close(&preds, "output.disp_preds", 1e-3);
    fx.assert_close(&out.disp, "output.disp", 1e-3);

    let t0 = std::time::Instant::now();
    let test = iterate(&blocks, parts.inputs(&fx), ITERS, true);
    println!("test-mode loop: {:.2?}", t0.elapsed());
    assert!(test.disp_preds.is_empty());
    fx.assert_close(&test.disp, "output.disp", 1e-3);
}

/// The loop is differentiable on an autodiff device (training): a backward from the final
/// disparity reaches every block, with finite gradients.
#[test]
fn iterations_backward_smoke() {
    testdata::require!(FIXTURE);
    let fx = Fixture::load(FIXTURE);
    let ad = fx.device.clone().autodiff();
    // Load on the autodiff device: a module loaded on the plain device and moved with
    // `to_device(&ad)` has untracked parameters (backward panics).
    let mut parts = Parts::load(&ad);
    // Upstream trains with `freeze_bn()`: BatchNorm2d use running statistics.
    parts.spx_2_gru = freeze_bn(parts.spx_2_gru);
    parts.remp = freeze_bn(parts.remp);
    let fx_ad = Fixture {
        tensors: fx.tensors.clone(),
        device: ad.clone(),
    };
    let out = iterate(&parts.blocks(), parts.inputs(&fx_ad), ITERS, false);
    let loss = out
        .disp_preds
        .iter()
        .fold(Tensor::<1>::zeros([1], &ad), |acc, p| {
            acc + p.clone().abs().mean().reshape([1])
        });
    // With frozen BN the training-device forward equals the inference one.
    fx.assert_close(&out.disp, "output.disp", 1e-3);
    let grads = loss.backward();
    let checks: Vec<(&str, Tensor<4>)> = vec![
        (
            "update_block.encoder.convc1",
            parts.update_block.encoder.convc1.weight.val(),
        ),
        (
            "update_block.gru16.convz",
            parts.update_block.gru16.convz.weight.val(),
        ),
        (
            "mix_stereo.encoder.convc1_mono",
            parts.mix_stereo.encoder.convc1_mono.weight.val(),
        ),
        (
            "mix_mono.disp_head.conv2",
            parts.mix_mono.disp_head.conv2.weight.val(),
        ),
        ("spx_2_gru.conv1", parts.spx_2_gru.conv1.conv.weight.val()),
        ("REMP.final_conv", parts.remp.final_conv.weight.val()),
        ("REMP.conv1_mono", parts.remp.conv1_mono.0.weight.val()),
        (
            "desc (through the correlation volume)",
            parts.desc.weight.val(),
        ),
        ("context_zqr_convs.0", parts.zqr[0].weight.val()),
    ];
    for (name, w) in checks {
        let g = w
            .grad(&grads)
            .unwrap_or_else(|| panic!("{name}: no gradient"));
        let v: Vec<f32> = g.to_data().convert::<f32>().try_to_vec::<f32>().unwrap();
        let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        println!("grad |{name}| = {norm:.3e}");
        assert!(
            v.iter().all(|x| x.is_finite()),
            "{name}: non-finite gradient"
        );
        assert!(norm > 0.0, "{name}: zero gradient");
    }
}
