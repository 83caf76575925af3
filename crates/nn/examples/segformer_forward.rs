//! CPU time of one SegFormer forward pass and of the whole segmentation of one image (flex
//! backend, random weights: timing only).
//!
//! ```sh
//! cargo run --release -p nn --example segformer_forward -- [mit_b2|tiny] [input size] [image size]
//! ```
//!
//! Defaults: mit-b2 (9 classes) at the release's 1000×1000 input, image 1024×1024.

use std::time::Instant;

use burn::tensor::{Device, Distribution, Tensor};
use nn::segformer::{Segformer, SegformerConfig, Segmenter, SegmenterConfig};
use raster::Image;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let preset = args.first().map_or("mit_b2", String::as_str);
    let arg = |i: usize, default: usize| {
        args.get(i)
            .map(|s| s.parse().expect("sizes are integers"))
            .unwrap_or(default)
    };
    let (size, image_size) = (arg(1, 1000), arg(2, 1024));
    let config = match preset {
        "mit_b2" => SegformerConfig::mit_b2(9),
        "tiny" => SegformerConfig::tiny(),
        other => panic!("unknown preset {other} (mit_b2, tiny)"),
    };
    let device = Device::flex();
    let model = Segformer::new(&config, &device);
    let x = Tensor::<4>::random([1, 3, size, size], Distribution::Normal(0.0, 1.0), &device);
    let t = Instant::now();
    let logits = model.forward(x);
    let n = logits
        .into_data()
        .try_into_vec_as::<f32>()
        .expect("f32")
        .len();
    let forward = t.elapsed().as_secs_f64();
    println!(
        "SegFormer {preset} forward at {size}x{size} ({n} logits), {} threads: {forward:.3} s",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );

    let mut seg_config = SegmenterConfig::with_model(config);
    seg_config.input_size = (size, size);
    let segmenter = Segmenter::new(model, seg_config, &device).expect("valid configuration");
    let image = Image::from_fn(image_size, image_size, |x, y| {
        ((x * 7 + y * 13) % 256) as f32
    });
    let t = Instant::now();
    let seg = segmenter.segment(&image).expect("segmentation");
    println!(
        "whole segmentation of a {image_size}x{image_size} image (resize, forward, post-processing): {:.3} s ({} water px)",
        t.elapsed().as_secs_f64(),
        seg.water.pixels()
    );
}
