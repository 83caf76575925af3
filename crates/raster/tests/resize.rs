//! The resizers against the upstream reference tensors (the parity fixtures): Pillow's 8-bit
//! bilinear resize (SegFormer fixture) must match bit for bit, torch's antialiased bilinear
//! resize (DINOv3 fixture) too (the fixture's own tolerance is 2e-7; this port is bit-exact).

use raster::resize::{resize_antialias_bilinear, resize_pil_bilinear_u8};
use raster::Image;
use safetensors::{Dtype, SafeTensors};

const SEGFORMER: &str = "fixtures/segformer-tiny";
const DINOV3: &str = "fixtures/dinov3-tiny";

/// Tensor `name` of `<fixture>/tensors.safetensors` (F32) as (shape, values).
fn tensor(fixture: &str, name: &str) -> (Vec<usize>, Vec<f32>) {
    let path = testdata::checked(fixture).join("tensors.safetensors");
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let st = SafeTensors::deserialize(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let view = st
        .tensor(name)
        .unwrap_or_else(|e| panic!("{}: {name}: {e}", path.display()));
    assert_eq!(view.dtype(), Dtype::F32, "{name}");
    let values = view
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    (view.shape().to_vec(), values)
}

/// An HWC tensor as an image.
fn hwc(fixture: &str, name: &str) -> Image {
    let (shape, values) = tensor(fixture, name);
    assert_eq!(shape.len(), 3, "{name}: HWC expected, got {shape:?}");
    Image::new(shape[1], shape[0], shape[2], values).unwrap()
}

/// Image `b` of a `B×C×H×W` tensor as an HWC image.
fn nchw(fixture: &str, name: &str, b: usize) -> Image {
    let (shape, values) = tensor(fixture, name);
    let [_, c, h, w] = shape[..] else {
        panic!("{name}: NCHW expected, got {shape:?}")
    };
    let plane = &values[b * c * h * w..(b + 1) * c * h * w];
    let mut data = vec![0.0; c * h * w];
    for ch in 0..c {
        for i in 0..h * w {
            data[i * c + ch] = plane[ch * h * w + i];
        }
    }
    Image::new(w, h, c, data).unwrap()
}

fn count_differences(got: &Image, want: &Image) -> usize {
    assert_eq!(got.size(), want.size());
    assert_eq!(got.channels(), want.channels());
    got.data()
        .iter()
        .zip(want.data())
        .filter(|(a, b)| a != b)
        .count()
}

fn max_abs_diff(got: &Image, want: &Image) -> f32 {
    assert_eq!(got.size(), want.size());
    got.data()
        .iter()
        .zip(want.data())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max)
}

#[test]
fn pil_bilinear_matches_pillow_at_the_real_1024_to_1000_ratio() {
    testdata::require!(SEGFORMER);
    let input = hwc(SEGFORMER, "pre.pil_test.in_u8");
    let want = hwc(SEGFORMER, "pre.pil_test.out_u8");
    let got = resize_pil_bilinear_u8(&input, want.width(), want.height()).unwrap();
    assert_eq!(count_differences(&got, &want), 0);
}

#[test]
fn pil_bilinear_matches_pillow_when_up_and_down_scaling() {
    testdata::require!(SEGFORMER);
    // 96 -> 92 columns (down), 64 -> 76 rows (up): both branches of the filter scale.
    let input = hwc(SEGFORMER, "input.image_u8");
    let want = hwc(SEGFORMER, "pre.resized_u8");
    let got = resize_pil_bilinear_u8(&input, want.width(), want.height()).unwrap();
    assert_eq!(count_differences(&got, &want), 0);
}

#[test]
fn antialias_bilinear_matches_torch() {
    testdata::require!(DINOV3);
    // The processor multiplies the truncated uint8 images by float32(1/255), then resizes.
    let inv255 = (1.0f64 / 255.0) as f32;
    for (b, name) in [(0, "pre.left_u8"), (1, "pre.left_hat_u8")] {
        let u8_image = hwc(DINOV3, name);
        let rescaled = Image::new(
            u8_image.width(),
            u8_image.height(),
            3,
            u8_image.data().iter().map(|&v| v * inv255).collect(),
        )
        .unwrap();
        let want = nchw(DINOV3, "pre.resized", b);
        let got = resize_antialias_bilinear(&rescaled, want.width(), want.height()).unwrap();
        let diff = max_abs_diff(&got, &want);
        eprintln!("pre.resized[{b}] max abs diff {diff:e}");
        assert_eq!(diff, 0.0, "{name}: max abs diff {diff}");
    }
}
