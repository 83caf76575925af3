//! The built-in seasonal model on the procedural world: strong appearance change, zero geometric
//! change (SGM between source and variant finds disparity 0), determinism.

use matching::{match_pair, SgmParams};
use raster::Image;
use synth::{BuiltinSeasons, Season, SeasonGenerator, SourceImage};

fn world() -> world::World {
    world::generate(
        &world::WorldParams::new(128, 3),
        &world::Neutral,
        &|_, _| {},
    )
    .unwrap()
}

/// Mean Euclidean RGB distance, 0–255 units.
fn mean_colour_distance(a: &Image, b: &Image) -> f64 {
    let n = a.width() * a.height();
    let sum: f64 = a
        .data()
        .chunks_exact(3)
        .zip(b.data().chunks_exact(3))
        .map(|(p, q)| {
            let d2: f32 = p.iter().zip(q).map(|(x, y)| (x - y) * (x - y)).sum();
            f64::from(d2.sqrt())
        })
        .sum();
    sum / n as f64
}

/// (share of matched pixels with |d| < 0.5, share of pixels matched).
fn zero_disparity_share(source: &Image, variant: &Image) -> (f64, f64) {
    let d = match_pair(source, variant, (-4, 4), &SgmParams::default()).unwrap();
    let matched: Vec<f32> = d.data().iter().copied().filter(|v| v.is_finite()).collect();
    let good = matched.iter().filter(|v| v.abs() < 0.5).count();
    (
        good as f64 / matched.len().max(1) as f64,
        matched.len() as f64 / d.data().len() as f64,
    )
}

#[test]
fn every_season_changes_colour_but_not_geometry() {
    let world = world();
    let model = BuiltinSeasons::new(11);
    for with_classes in [true, false] {
        let mut source = SourceImage::new("JAX_000_001_RGB", &world.left.image);
        if with_classes {
            source = source.with_classes(&world.left.classes);
        }
        for season in Season::ALL {
            let variant = model.generate(&source, season).unwrap();
            assert_eq!(variant.size(), world.left.image.size());
            assert_eq!(variant.channels(), 3);
            assert!(variant.data().iter().all(|v| (0.0..=255.0).contains(v)));
            let dist = mean_colour_distance(&world.left.image, &variant);
            let (zero, matched) = zero_disparity_share(&world.left.image, &variant);
            println!(
                "{season:>6} classes={with_classes:<5} colour distance {dist:6.1} DN, \
                 |d|<0.5 on {:.2}% of {:.1}% matched",
                100.0 * zero,
                100.0 * matched
            );
            assert!(dist > 12.0, "{season}: colour distance only {dist:.1} DN");
            assert!(
                matched > 0.5,
                "{season}: SGM matched only {:.1}%",
                100.0 * matched
            );
            assert!(
                zero >= 0.95,
                "{season}: |d| < 0.5 on only {:.2}%",
                100.0 * zero
            );
        }
    }
}

#[test]
fn seasons_differ_from_each_other() {
    let world = world();
    let model = BuiltinSeasons::new(5);
    let source = SourceImage::new("a", &world.left.image).with_classes(&world.left.classes);
    let variants: Vec<Image> = Season::ALL
        .iter()
        .map(|&s| model.generate(&source, s).unwrap())
        .collect();
    for i in 0..4 {
        for j in i + 1..4 {
            let d = mean_colour_distance(&variants[i], &variants[j]);
            assert!(
                d > 8.0,
                "{:?} vs {:?}: {d:.1} DN",
                Season::ALL[i],
                Season::ALL[j]
            );
        }
    }
    // Winter lays snow on fields and roofs: it is the brightest season on open ground.
    let mean = |img: &Image| {
        img.data().iter().map(|&v| f64::from(v)).sum::<f64>() / img.data().len() as f64
    };
    assert!(mean(&variants[2]) > mean(&variants[0]) + 10.0);
}

#[test]
fn variants_are_deterministic_per_seed_id_and_season() {
    let world = world();
    let source = SourceImage::new("OMA_042_004_RGB", &world.left.image);
    let a = BuiltinSeasons::new(1)
        .generate(&source, Season::Autumn)
        .unwrap();
    let b = BuiltinSeasons::new(1)
        .generate(&source, Season::Autumn)
        .unwrap();
    assert_eq!(a.data(), b.data());
    let other_seed = BuiltinSeasons::new(2)
        .generate(&source, Season::Autumn)
        .unwrap();
    assert_ne!(a.data(), other_seed.data());
    let other_id = BuiltinSeasons::new(1)
        .generate(
            &SourceImage::new("OMA_042_005_RGB", &world.left.image),
            Season::Autumn,
        )
        .unwrap();
    assert_ne!(a.data(), other_id.data());
}

#[test]
fn invalid_pixels_stay_invalid_and_bad_inputs_are_refused() {
    let mut img = Image::filled(8, 6, 3, 100.0);
    img.set(2, 3, 1, f32::NAN);
    let model = BuiltinSeasons::new(0);
    let out = model
        .generate(&SourceImage::new("x", &img), Season::Winter)
        .unwrap();
    assert!(out.pixel(2, 3).iter().all(|v| v.is_nan()));
    assert!(out.pixel(3, 3).iter().all(|v| v.is_finite()));

    let grey = Image::filled(8, 6, 1, 100.0);
    let err = model
        .generate(&SourceImage::new("g", &grey), Season::Summer)
        .unwrap_err();
    assert!(err.to_string().contains("RGB"), "{err}");
    let classes = Image::filled(7, 6, 1, 5.0);
    let err = model
        .generate(
            &SourceImage::new("c", &img).with_classes(&classes),
            Season::Summer,
        )
        .unwrap_err();
    assert!(err.to_string().contains("class map"), "{err}");
}
