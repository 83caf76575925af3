//! The geometry-fidelity check: built-in variants pass; shifted, blurred and warped images fail.

use raster::geometry::sample_bilinear;
use raster::Image;
use synth::fidelity::{check, FidelityParams};
use synth::{BuiltinSeasons, Season, SeasonGenerator, SourceImage};

fn world_image() -> (Image, Image) {
    let w = world::generate(
        &world::WorldParams::new(256, 7),
        &world::Neutral,
        &|_, _| {},
    )
    .unwrap();
    (w.left.image, w.left.classes)
}

/// `image` resampled at `(x + dx(x, y), y + dy(x, y))`, edges clamped.
fn remap(image: &Image, f: impl Fn(usize, usize) -> (f64, f64)) -> Image {
    let (w, h) = image.size();
    let mut out = Image::filled(w, h, image.channels(), 0.0);
    let mut px = vec![0f32; image.channels()];
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = f(x, y);
            let sx = (x as f64 + dx).clamp(0.0, (w - 1) as f64);
            let sy = (y as f64 + dy).clamp(0.0, (h - 1) as f64);
            sample_bilinear(image, sx, sy, &mut px);
            for (c, v) in px.iter().enumerate() {
                out.set(x, y, c, *v);
            }
        }
    }
    out
}

/// Separable Gaussian blur of standard deviation `sigma`.
fn blur(image: &Image, sigma: f64) -> Image {
    let r = (3.0 * sigma).ceil() as isize;
    let k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    let (w, h) = image.size();
    let pass = |img: &Image, horizontal: bool| {
        let mut out = Image::filled(w, h, img.channels(), 0.0);
        for y in 0..h {
            for x in 0..w {
                for c in 0..img.channels() {
                    let mut acc = 0.0;
                    for (t, kt) in k.iter().enumerate() {
                        let o = t as isize - r;
                        let (sx, sy) = if horizontal {
                            ((x as isize + o).clamp(0, w as isize - 1) as usize, y)
                        } else {
                            (x, (y as isize + o).clamp(0, h as isize - 1) as usize)
                        };
                        acc += kt * f64::from(img.get(sx, sy, c));
                    }
                    out.set(x, y, c, (acc / s) as f32);
                }
            }
        }
        out
    };
    pass(&pass(image, true), false)
}

#[test]
fn every_builtin_variant_passes() {
    let (image, classes) = world_image();
    let params = FidelityParams::default();
    let model = BuiltinSeasons::new(3);
    for with_classes in [true, false] {
        for season in Season::ALL {
            let mut source = SourceImage::new("tile", &image);
            if with_classes {
                source = source.with_classes(&classes);
            }
            let variant = model.generate(&source, season).unwrap();
            let report = check(&image, &variant, &params).unwrap();
            println!("{season} classes={with_classes}: {report}");
            assert!(report.passed, "{season}: {report}");
            assert!(report.shift() < 0.25, "{season}: {report}");
            assert!(report.tiles_checked >= 4, "{report}");
        }
    }
}

#[test]
fn the_source_itself_is_perfectly_aligned() {
    let (image, _) = world_image();
    let report = check(&image, &image, &FidelityParams::default()).unwrap();
    assert!(report.passed);
    assert!(
        report.shift() < 0.05 && (report.edge_score - 1.0).abs() < 1e-9,
        "{report}"
    );
}

#[test]
fn shifted_images_are_rejected_with_the_measured_shift() {
    let (image, _) = world_image();
    let params = FidelityParams::default();
    // variant(x) = source(x − 2): everything moved 2 px to the right.
    let shifted = remap(&image, |_, _| (-2.0, 0.0));
    let report = check(&image, &shifted, &params).unwrap();
    println!("2 px: {report}");
    assert!(!report.passed);
    assert!(
        (report.shift_x - 2.0).abs() < 0.1 && report.shift_y.abs() < 0.1,
        "{report}"
    );
    assert!(report.to_string().contains("REJECTED") && report.to_string().contains("moved"));

    // A sub-pixel shift is measured to a tenth of a pixel; 0.7 px fails, 0.2 px passes.
    let shifted = remap(&image, |_, _| (0.0, -0.7));
    let report = check(&image, &shifted, &params).unwrap();
    println!("0.7 px: {report}");
    assert!(
        !report.passed && (report.shift_y - 0.7).abs() < 0.15,
        "{report}"
    );
    let shifted = remap(&image, |_, _| (-0.2, 0.0));
    let report = check(&image, &shifted, &params).unwrap();
    println!("0.2 px: {report}");
    assert!((report.shift_x - 0.2).abs() < 0.1, "{report}");
}

#[test]
fn blurred_and_warped_images_are_rejected() {
    let (image, _) = world_image();
    let params = FidelityParams::default();
    let blurred = blur(&image, 2.0);
    let report = check(&image, &blurred, &params).unwrap();
    println!("blur σ=2: {report}");
    assert!(!report.passed, "{report}");
    assert!(report.shift() < 0.5, "blur moves nothing: {report}");
    assert!(report.to_string().contains("blurred"), "{report}");

    // A smooth local warp of ±2 px: no global shift, but the tiles move.
    let warped = remap(&image, |x, y| {
        let t = std::f64::consts::TAU;
        (
            2.0 * (t * y as f64 / 128.0).sin(),
            2.0 * (t * x as f64 / 128.0).cos(),
        )
    });
    let report = check(&image, &warped, &params).unwrap();
    println!("warp ±2 px: {report}");
    assert!(!report.passed, "{report}");
}

#[test]
fn mismatched_sizes_are_an_error() {
    let a = Image::filled(64, 64, 3, 1.0);
    let b = Image::filled(64, 63, 3, 1.0);
    assert!(check(&a, &b, &FidelityParams::default()).is_err());
}
