//! Parity of the SegFormer port with HF transformers and the release's mask scripts, against the
//! random-weight fixture `fixtures/segformer-tiny` (see its README): every listed
//! intermediate, the logits, the post-processing tensors, the masks, the PIL resize, the
//! morphology on the synthetic mask, and the key set of the real mit-b2 checkpoint.

mod support;

use std::collections::BTreeMap;

use burn::tensor::Device;
use dataset::segmentation::{
    argmax_classes, percentages_header, softmax_classes, upsample_scores, MaskKind, Segmentation,
};
use nn::segformer::postprocess::postprocess;
use nn::segformer::preprocess::{pixel_values, to_rgb_u8};
use nn::segformer::{Segformer, SegformerConfig, Segmenter, SegmenterConfig, Trace};
use nn::weights::WeightsError;
use raster::morphology::{dilate_square, fill_holes, label_components, remove_small_components};
use raster::resize::resize_pil_bilinear_u8;
use raster::{Image, Mask};
use support::Fixture;

const FIX: &str = "fixtures/segformer-tiny";

fn tiny_model(device: &Device) -> Segformer {
    let mut model = Segformer::new(&SegformerConfig::tiny(), device);
    let report = model.load(support::fixture_weights(FIX)).unwrap();
    assert!(report.unexpected.is_empty(), "{report}");
    assert_eq!(
        report.ignored,
        vec!["decode_head.batch_norm.num_batches_tracked"]
    );
    model
}

/// Max abs difference of `got` (any shape with the reference's element count, same order).
fn diff(fx: &Fixture, name: &str, got: &[f32], shape: &[usize]) -> (f32, f32) {
    let (want_shape, want) = fx.raw(name);
    assert_eq!(shape, &want_shape[..], "{name}: shape");
    let (err, scale) = support::max_abs_diff(got, want);
    eprintln!("{name:32} max abs diff {err:.3e} (max |ref| {scale:.3e})");
    (err, scale)
}

fn hwc_image(fx: &Fixture, name: &str) -> Image {
    let (shape, v) = fx.raw(name);
    let c = if shape.len() == 3 { shape[2] } else { 1 };
    Image::new(shape[1], shape[0], c, v.clone()).unwrap()
}

fn mask_of(fx: &Fixture, name: &str) -> Mask {
    let (shape, v) = fx.raw(name);
    Mask::new(shape[1], shape[0], v.iter().map(|&x| x != 0.0).collect()).unwrap()
}

fn floats(m: &Mask) -> Vec<f32> {
    m.data().iter().map(|&b| b as u8 as f32).collect()
}

#[test]
fn network_intermediates_and_logits_match() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let model = tiny_model(&fx.device);
    let mut trace = Trace::on();
    let logits = model.forward_traced(fx.t::<4>("input.pixel_values"), &mut trace);

    let names = [
        "stage1.patch_embed",
        "stage1.block0.ln1",
        "stage1.block0.sr_kv",
        "stage1.block0.attn",
        "stage1.block0.mlp",
        "stage1.block0.out",
        "stage1.out",
        "stage2.patch_embed",
        "stage2.out",
        "stage3.patch_embed",
        "stage3.out",
        "stage4.patch_embed",
        "stage4.block0.attn",
        "stage4.out",
        "decoder.concat",
        "decoder.fused",
    ];
    for name in names {
        let data = trace
            .get(name)
            .unwrap_or_else(|| panic!("trace has no {name}"));
        let got = data.clone().try_to_vec::<f32>().unwrap();
        let (err, _) = diff(&fx, &format!("inter.{name}"), &got, &data.shape().to_vec());
        assert!(err < 2e-5, "{name}: max abs diff {err}");
    }
    assert!(
        trace.get("stage4.block0.sr_kv").is_none(),
        "stage 4 has no reduction"
    );
    let shape = logits.dims().to_vec();
    let got = logits.into_data().try_to_vec::<f32>().unwrap();
    let (err, _) = diff(&fx, "output.logits", &got, &shape);
    assert!(err < 1e-4, "logits: max abs diff {err}");

    // The production path folds the decoder's fuse into the projections.
    let logits = model.forward(fx.t::<4>("input.pixel_values"));
    let got = logits.into_data().try_to_vec::<f32>().unwrap();
    let (err, _) = diff(&fx, "output.logits", &got, &shape);
    eprintln!("(folded decoder)");
    assert!(
        err < 1e-4,
        "logits of the folded decoder: max abs diff {err}"
    );
}

#[test]
fn pixel_values_from_the_resized_image_match() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let resized = hwc_image(&fx, "pre.resized_u8");
    let x = pixel_values(&resized, &fx.device).unwrap();
    let shape = x.dims().to_vec();
    let got = x.into_data().try_to_vec::<f32>().unwrap();
    let (err, _) = diff(&fx, "input.pixel_values", &got, &shape);
    assert_eq!(err, 0.0, "the f32 normalisation is exact");
}

#[test]
fn pil_resize_is_bit_exact() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let original = to_rgb_u8(&hwc_image(&fx, "input.image_u8")).unwrap();
    let [h, w] = [76, 92];
    let resized = resize_pil_bilinear_u8(&original, w, h).unwrap();
    assert_eq!(resized.data(), fx.raw("pre.resized_u8").1.as_slice());
    let test_in = hwc_image(&fx, "pre.pil_test.in_u8");
    let test_out = resize_pil_bilinear_u8(&test_in, 125, 125).unwrap();
    assert_eq!(test_out.data(), fx.raw("pre.pil_test.out_u8").1.as_slice());
}

/// Checks every post-processing tensor of one class; `clear` marks the pixels whose top-2
/// probability gap is large enough for the comparison to be meaningful.
fn check_class(fx: &Fixture, seg: &Segmentation, kind: MaskKind, clear: &[bool]) -> usize {
    let c = seg.get(kind);
    let name = kind.name();
    let mut mismatches = 0;
    for (what, got) in [
        ("raw", floats(&c.raw)),
        ("clean", floats(&c.mask)),
        ("mask_png", c.png_values().into_data()),
        ("prob_u8", c.probability_u8().into_data()),
    ] {
        let want = &fx.raw(&format!("post.{name}.{what}")).1;
        let bad = got
            .iter()
            .zip(want)
            .zip(clear)
            .filter(|((g, w), &ok)| ok && g != w)
            .count();
        eprintln!("post.{name}.{what:10} {bad} differing pixels");
        mismatches += bad;
    }
    mismatches
}

#[test]
fn postprocessing_of_the_reference_logits_is_exact() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let (w, h) = (96, 64);
    let logits = fx.t::<4>("output.logits");

    // logits_up, probs, pred
    let up = upsample_scores(&fx.raw("output.logits").1, 9, (23, 19), (w, h));
    let up_shape = [9, h, w];
    let (err, _) = diff(&fx, "post.logits_up", &up, &up_shape);
    assert_eq!(err, 0.0, "logits_up is bit-exact");
    let probs = softmax_classes(&up, 9);
    let (err, _) = diff(&fx, "post.probs", &probs, &up_shape);
    assert!(err < 1e-6, "probs: {err}");
    let pred = argmax_classes(&probs, 9);
    let want_pred = &fx.raw("post.pred").1;
    let differing = pred
        .iter()
        .zip(want_pred)
        .filter(|(&p, &q)| p as f32 != q)
        .count();
    assert_eq!(differing, 0, "argmax of the reference logits");

    let options = SegmenterConfig::release().masks;
    let seg = postprocess(logits.clone(), w, h, &options).unwrap();
    assert_eq!(
        seg.classes.data(),
        want_pred.as_slice(),
        "segmentation class map"
    );
    let everywhere = vec![true; w * h];
    for kind in MaskKind::ALL {
        assert_eq!(check_class(&fx, &seg, kind, &everywhere), 0, "{kind:?}");
    }

    // The percentage lines of the fixture (meta.json).
    assert_eq!(
        seg.water.percentage_line("x.png"),
        "x.png 12.076823 742 6144"
    );
    assert_eq!(
        seg.tree.percentage_line("x.png"),
        "x.png 12.109375 744 6144"
    );
    assert_eq!(
        seg.building.percentage_line("x.png"),
        "x.png 28.938802 1778 6144"
    );
    assert_eq!(
        percentages_header(MaskKind::Water),
        "image_name water_percentage water_pixels total_pixels"
    );

    // The `--threshold 0.2` branch of the water script.
    let mut thresholded = options.clone();
    thresholded[0].threshold = Some(0.2);
    let seg = postprocess(logits, w, h, &thresholded).unwrap();
    assert_eq!(
        floats(&seg.water.raw),
        fx.raw("post.water.raw_threshold").1.as_slice()
    );
}

#[test]
fn segmenter_end_to_end_matches_where_the_classes_are_clear() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let mut config = SegmenterConfig::with_model(SegformerConfig::tiny());
    config.input_size = (92, 76);
    let segmenter =
        Segmenter::from_file(support::fixture_weights(FIX), config, &fx.device).unwrap();
    let image = hwc_image(&fx, "input.image_u8");
    let seg = segmenter.segment(&image).unwrap();
    assert_eq!(seg.classes.size(), (96, 64));

    // Top-2 gap of the reference probabilities.
    let probs = &fx.raw("post.probs").1;
    let n = 96 * 64;
    let clear: Vec<bool> = (0..n)
        .map(|i| {
            let mut p: Vec<f32> = (0..9).map(|c| probs[c * n + i]).collect();
            p.sort_by(|a, b| b.total_cmp(a));
            p[0] - p[1] > 1e-4
        })
        .collect();
    let unclear = clear.iter().filter(|&&c| !c).count();
    eprintln!("{unclear} pixels with a top-2 gap ≤ 1e-4");
    let want_pred = &fx.raw("post.pred").1;
    let differing = (0..n)
        .filter(|&i| clear[i] && seg.classes.data()[i] != want_pred[i])
        .count();
    assert_eq!(differing, 0, "argmax where the classes are clear");
    // Masks: the clean-up is non-local, so compare everywhere when no pixel is ambiguous.
    let mask_clear = if unclear == 0 { vec![true; n] } else { clear };
    let mut total = 0;
    for kind in MaskKind::ALL {
        total += check_class(&fx, &seg, kind, &mask_clear);
    }
    // prob_u8 truncation may flip at a pixel whose p·255 sits within float noise of an integer.
    assert!(total <= 2, "{total} differing pixels in the masks");
    assert_eq!(
        seg.building.percentage_line("x.png"),
        "x.png 28.938802 1778 6144"
    );
}

#[test]
fn synthetic_morphology_matches_scipy() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let mask = mask_of(&fx, "post.synth.mask");
    let comps = label_components(&mask, true);
    let mut sizes = comps.sizes().to_vec();
    sizes.sort();
    assert_eq!(
        sizes,
        vec![1, 1, 2, 4, 7, 13, 13, 14, 15, 17, 22, 33, 49, 101, 500, 590]
    );
    let removed = remove_small_components(&mask, 12);
    assert_eq!(removed, mask_of(&fx, "post.synth.removed"));
    assert_eq!(label_components(&removed, true).count(), 11);
    assert_eq!(label_components(&removed, false).count(), 13);
    let filled = fill_holes(&removed, 10);
    assert_eq!(filled, mask_of(&fx, "post.synth.filled"));
    assert_eq!(label_components(&filled, false).count(), 11);
    let sparse = mask_of(&fx, "post.synth.sparse");
    assert_eq!(sparse.count(), 215);
    let dilated = dilate_square(&sparse, 3);
    assert_eq!(dilated, mask_of(&fx, "post.synth.sparse_dilated"));
    assert_eq!(dilated.count(), 1734);
}

#[test]
fn mit_b2_key_set_shapes_and_parameter_count() {
    testdata::require!(FIX);
    let cfg = SegformerConfig::mit_b2(9);
    let model = Segformer::new(&cfg, &Device::flex());
    let keys: BTreeMap<String, Vec<usize>> = model.torch_keys().into_iter().collect();
    let want = support::listed_keys(FIX, "state_dict_keys_mit-b2_9cls.txt", "");
    assert_eq!(want.len(), 379);
    let missing: Vec<_> = want.keys().filter(|k| !keys.contains_key(*k)).collect();
    let extra: Vec<_> = keys.keys().filter(|k| !want.contains_key(*k)).collect();
    assert!(
        missing.is_empty() && extra.is_empty(),
        "missing {missing:?}, extra {extra:?}"
    );
    for (k, shape) in &want {
        assert_eq!(&keys[k], shape, "{k}");
    }
    // The 27,355,081 of the fixture's meta.json counts every float value of the state dict; the
    // BatchNorm running statistics (2 × 768) are not parameters.
    let values: usize = keys.values().map(|s| s.iter().product::<usize>()).sum();
    assert_eq!(values, 27_355_081);
    assert_eq!(cfg.num_params(), 27_355_081 - 2 * 768);
    assert_eq!(SegformerConfig::tiny().num_params(), 331_761);
    assert_eq!(
        cfg.stage_sizes(1000, 1000),
        Some([(250, 250), (125, 125), (63, 63), (32, 32)])
    );
}

#[test]
fn release_checkpoint_naming_loads_and_optimizer_state_is_dropped() {
    testdata::require!(FIX);
    // The release's `.pt` flattened: `model_state_dict.module.model.<HF key>`, plus optimizer state.
    let bytes = std::fs::read(support::fixture_weights(FIX)).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut views: Vec<(String, safetensors::tensor::TensorView)> = st
        .tensors()
        .into_iter()
        .map(|(n, v)| (format!("model_state_dict.module.model.{n}"), v))
        .collect();
    let extra = st.tensor("decode_head.classifier.bias").unwrap();
    views.push(("optimizer_state_dict.state.0.exp_avg".into(), extra));
    let wrapped = support::tmp("wrapped.safetensors");
    std::fs::write(&wrapped, safetensors::serialize(views, None).unwrap()).unwrap();

    let device = Device::flex();
    let mut model = Segformer::new(&SegformerConfig::tiny(), &device);
    let report = model.load(&wrapped).unwrap();
    assert!(report.unexpected.is_empty(), "{report}");
    let fx = Fixture::load(FIX);
    let logits = model.forward(fx.t::<4>("input.pixel_values"));
    let got = logits.into_data().try_to_vec::<f32>().unwrap();
    let (err, _) = support::max_abs_diff(&got, &fx.raw("output.logits").1);
    assert!(err < 1e-4, "{err}");
}

#[test]
fn load_errors_name_the_keys() {
    testdata::require!(FIX);
    let device = Device::flex();
    // Missing tensor.
    let path = support::tmp("missing.safetensors");
    support::write_edited_weights(FIX, &path, |n, s, b| {
        (n != "segformer.encoder.block.1.0.attention.self.sr.weight").then_some((s, b))
    });
    let mut model = Segformer::new(&SegformerConfig::tiny(), &device);
    let msg = model.load(&path).unwrap_err().to_string();
    assert!(
        msg.contains("segformer.encoder.block.1.0.attention.self_attn.sr.weight")
            || msg.contains("segformer.encoder.block.1.0.attention.self.sr.weight"),
        "{msg}"
    );
    assert!(msg.contains("missing.safetensors"), "{msg}");

    // Unexpected key (a stray tensor) is an error for the strict loader.
    let bytes = std::fs::read(support::fixture_weights(FIX)).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut views: Vec<_> = st.tensors();
    views.push((
        "decode_head.extra.bias".into(),
        st.tensor("decode_head.classifier.bias").unwrap(),
    ));
    let path2 = support::tmp("unexpected2.safetensors");
    std::fs::write(&path2, safetensors::serialize(views, None).unwrap()).unwrap();
    let err = Segformer::new(&SegformerConfig::tiny(), &device)
        .load(&path2)
        .unwrap_err();
    assert!(matches!(err, WeightsError::Mismatch { .. }));
    assert!(err.to_string().contains("decode_head.extra.bias"), "{err}");

    // Wrong configuration: the tiny weights do not fit mit-b2.
    let msg = Segformer::new(&SegformerConfig::mit_b2(9), &device)
        .load(support::fixture_weights(FIX))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("wrong shape"), "{msg}");
}

#[test]
fn bad_images_are_rejected() {
    testdata::require!(FIX);
    let fx = Fixture::load(FIX);
    let mut config = SegmenterConfig::with_model(SegformerConfig::tiny());
    config.input_size = (92, 76);
    let segmenter =
        Segmenter::from_file(support::fixture_weights(FIX), config, &fx.device).unwrap();
    let float_image = Image::filled(8, 8, 3, 0.5);
    let msg = segmenter.segment(&float_image).unwrap_err().to_string();
    assert!(msg.contains("8-bit"), "{msg}");
    let nan_image = Image::filled(8, 8, 3, f32::NAN);
    assert!(segmenter.segment(&nan_image).is_err());
    // Grey images are replicated to RGB as PIL's convert("RGB") does.
    let grey = Image::filled(9, 7, 1, 100.0);
    let seg = segmenter.segment(&grey).unwrap();
    assert_eq!(seg.water.mask.size(), (9, 7));
    let rgb = to_rgb_u8(&grey).unwrap();
    assert_eq!(rgb.pixel(3, 3), &[100.0, 100.0, 100.0]);
    assert!(pixel_values(&grey, &fx.device).is_err(), "RGB expected");
}

/// Pickle (protocol 2) helpers for a minimal `torch.save` zip file.
mod torch_file {
    use std::io::Write;

    fn unicode(out: &mut Vec<u8>, s: &str) {
        out.push(b'X');
        out.extend((s.len() as u32).to_le_bytes());
        out.extend(s.as_bytes());
    }

    fn int(out: &mut Vec<u8>, v: usize) {
        out.push(b'J');
        out.extend((v as i32).to_le_bytes());
    }

    fn tuple(out: &mut Vec<u8>, values: &[usize]) {
        out.push(b'(');
        for &v in values {
            int(out, v);
        }
        out.push(b't');
    }

    /// `torch.save({wrapper: OrderedDict(tensors), "epoch": 7}, path)` with f32 tensors, as
    /// PyTorch ≥ 1.6 writes it (zip of `archive/data.pkl`, `archive/data/<n>`, `version`, ...).
    pub fn save(path: &std::path::Path, wrapper: &str, tensors: &[(String, Vec<usize>, Vec<f32>)]) {
        let mut p = vec![0x80, 2, b'}', b'('];
        unicode(&mut p, wrapper);
        p.extend(b"ccollections\nOrderedDict\n)R(");
        for (i, (name, shape, _)) in tensors.iter().enumerate() {
            unicode(&mut p, name);
            p.extend(b"ctorch._utils\n_rebuild_tensor_v2\n(");
            // persistent id ('storage', FloatStorage, key, 'cpu', numel)
            p.push(b'(');
            unicode(&mut p, "storage");
            p.extend(b"ctorch\nFloatStorage\n");
            unicode(&mut p, &i.to_string());
            unicode(&mut p, "cpu");
            int(&mut p, shape.iter().product());
            p.extend(b"tQ");
            int(&mut p, 0);
            tuple(&mut p, shape);
            let mut strides = vec![1usize; shape.len()];
            for d in (0..shape.len().saturating_sub(1)).rev() {
                strides[d] = strides[d + 1] * shape[d + 1];
            }
            tuple(&mut p, &strides);
            p.push(0x89); // False
            p.extend(b"ccollections\nOrderedDict\n)R");
            p.extend(b"tR");
        }
        p.push(b'u');
        unicode(&mut p, "epoch");
        int(&mut p, 7);
        p.extend(b"u.");

        let file = std::fs::File::create(path).unwrap();
        let mut zip = zip::ZipWriter::new(file);
        let opts = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored);
        let mut put = |name: &str, bytes: &[u8]| {
            zip.start_file(format!("archive/{name}"), opts).unwrap();
            zip.write_all(bytes).unwrap();
        };
        put("data.pkl", &p);
        put("byteorder", b"little");
        for (i, (_, _, values)) in tensors.iter().enumerate() {
            let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
            put(&format!("data/{i}"), &bytes);
        }
        put("version", b"3\n");
        zip.finish().unwrap();
    }
}

#[test]
fn release_pt_checkpoint_loads() {
    testdata::require!(FIX);
    // The tiny weights as the release stores its checkpoint: a torch.save zip pickle with the
    // state dict under `model_state_dict`, keys carrying `module.` and `model.`.
    let tensors: Vec<(String, Vec<usize>, Vec<f32>)> =
        support::read_all(&support::fixture_weights(FIX))
            .into_iter()
            .map(|(n, s, v)| (format!("module.model.{n}"), s, v))
            .collect();
    let path = support::tmp("openearthmap_segformer_tiny.pt");
    torch_file::save(&path, "model_state_dict", &tensors);

    let fx = Fixture::load(FIX);
    let mut config = SegmenterConfig::with_model(SegformerConfig::tiny());
    config.input_size = (92, 76);
    let (segmenter, report) = Segmenter::from_file_with_report(&path, config, &fx.device).unwrap();
    // Every float tensor applied (num_batches_tracked is I64 and not in this file).
    assert_eq!(report.applied, tensors.len(), "{report}");
    let logits = segmenter
        .model()
        .forward(fx.t::<4>("input.pixel_values"))
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let (err, _) = support::max_abs_diff(&logits, &fx.raw("output.logits").1);
    assert!(err < 1e-4, "{err}");

    // A `.pt` without the expected wrapper is read as a bare state dict: every key is reported.
    let bare = support::tmp("bare.pt");
    torch_file::save(&bare, "weights", &tensors[..3]);
    let msg = Segformer::new(&SegformerConfig::tiny(), &fx.device)
        .load(&bare)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("bare.pt") && msg.contains("missing"), "{msg}");
}
