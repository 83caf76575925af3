//! `masks`: the offline segmenter's accuracy on worlds it was not trained on, and the release's
//! file conventions of the writer.

use dataset::masks::{from_segmentation, MaskFile};
use dataset::segmentation::MaskKind;
use dataset::Shard;
use stages::masks::offline::{class_iou, PixelClassifier, TRAINING_SEEDS};
use stages::masks::{
    mask_path, prob_path, run_masks, ImageSegmenter, MasksOptions, OfflineSegmenter,
};
use workflow::Silent;
use world::class;

/// Seeds never used for training.
const TEST_SEEDS: [u64; 3] = [41, 42, 43];

#[test]
fn offline_segmenter_iou_on_unseen_worlds() {
    let t = std::time::Instant::now();
    let model = PixelClassifier::shared().unwrap();
    let train_s = t.elapsed().as_secs_f64();
    assert!(TEST_SEEDS.iter().all(|s| !TRAINING_SEEDS.contains(s)));
    let seg = OfflineSegmenter::default();
    let mut iou = [0.0f64; 3];
    let mut raw_iou = [0.0f64; 3];
    let worlds: Vec<world::World> = TEST_SEEDS
        .iter()
        .map(|&seed| {
            world::generate(
                &world::WorldParams::new(192, seed),
                &world::Neutral,
                &|_, _| {},
            )
            .unwrap()
        })
        .collect();
    let t = std::time::Instant::now();
    for w in &worlds {
        let probs = model.probabilities(&w.left.image);
        assert_eq!(probs.len(), 9 * 192 * 192);
        let s = seg.segment(&w.left.image).unwrap();
        for (k, (kind, id)) in [
            (MaskKind::Water, class::WATER),
            (MaskKind::Tree, class::TREE),
            (MaskKind::Building, class::BUILDING),
        ]
        .into_iter()
        .enumerate()
        {
            raw_iou[k] +=
                class_iou(&s.classes, &w.left.classes, id).unwrap_or(1.0) / TEST_SEEDS.len() as f64;
            // IoU of the final (cleaned) mask against the true class.
            let m = s.get(kind);
            let truth: Vec<bool> = w
                .left
                .classes
                .data()
                .iter()
                .map(|&c| c == id as f32)
                .collect();
            let inter = m
                .mask
                .data()
                .iter()
                .zip(&truth)
                .filter(|(a, b)| **a && **b)
                .count();
            let union = m
                .mask
                .data()
                .iter()
                .zip(&truth)
                .filter(|(a, b)| **a || **b)
                .count();
            iou[k] += if union == 0 {
                1.0
            } else {
                inter as f64 / union as f64
            } / TEST_SEEDS.len() as f64;
        }
    }
    let seg_s = t.elapsed().as_secs_f64() / TEST_SEEDS.len() as f64;
    println!(
        "offline segmenter on unseen worlds {TEST_SEEDS:?} (192 px): IoU water {:.3} tree {:.3} building {:.3} \
         (class map before clean-up: {:.3} / {:.3} / {:.3}); training {train_s:.2} s (3 worlds of 160² rendered \
         and fitted), {seg_s:.3} s per 192² image",
        iou[0], iou[1], iou[2], raw_iou[0], raw_iou[1], raw_iou[2]
    );
    // Measured 0.93 / 0.73 / 0.34: colour and texture find water and trees; roofs share colours
    // with roads and pavements, so buildings are the weak class of a per-pixel classifier.
    assert!(iou[0] >= 0.85, "water IoU {}", iou[0]);
    assert!(iou[1] >= 0.65, "tree IoU {}", iou[1]);
    assert!(iou[2] >= 0.28, "building IoU {}", iou[2]);
}

#[test]
fn writes_the_release_layout_resumably() {
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().join("images");
    let out = dir.path().join("seg");
    let mut truth = Vec::new();
    for (i, seed) in [51u64, 52].into_iter().enumerate() {
        let w = world::generate(
            &world::WorldParams::new(96, seed),
            &world::Neutral,
            &|_, _| {},
        )
        .unwrap();
        // One image in a sub-folder: the search is recursive and outputs are flat.
        let path = if i == 0 {
            images.join(format!("IMG_{seed}.iio"))
        } else {
            images.join("sub").join(format!("IMG_{seed}.png"))
        };
        raster::write_image(&path, &w.left.image).unwrap();
        truth.push(format!("IMG_{seed}"));
    }
    let opts = |shard| MasksOptions {
        images_dir: images.clone(),
        out_dir: out.clone(),
        shard,
        segmenter: Box::new(OfflineSegmenter::default()),
    };
    let first = run_masks(&opts(Shard::new(0, 2).unwrap()), &Silent).unwrap();
    assert_eq!((first.done, first.in_shard, first.total), (1, 1, 2));
    let second = run_masks(&opts(Shard::new(1, 2).unwrap()), &Silent).unwrap();
    assert_eq!((second.done, second.skipped), (1, 0));
    for stem in &truth {
        let water = raster::read_image(mask_path(&out, MaskKind::Water, stem)).unwrap();
        let tree = raster::read_image(mask_path(&out, MaskKind::Tree, stem)).unwrap();
        let building = raster::read_image(mask_path(&out, MaskKind::Building, stem)).unwrap();
        assert_eq!(water.size(), (96, 96));
        assert!(
            water.data().iter().all(|&v| v == 0.0 || v == 255.0),
            "water: 0 = water, 255 = other"
        );
        assert!(
            tree.data().iter().all(|&v| v == 0.0 || v == 1.0),
            "tree: 0 = tree, 1 = other"
        );
        assert!(
            building.data().iter().all(|&v| v == 0.0 || v == 1.0),
            "building: 0 = building, 1 = other"
        );
        assert!(building.data().contains(&0.0), "the world has buildings");
        // The dataset reader's polarity agrees: buildings are where the file is 0.
        let b = from_segmentation(&building, MaskFile::Building);
        assert_eq!(
            b.count(),
            building.data().iter().filter(|&&v| v == 0.0).count()
        );
        let p = raster::read_image(prob_path(&out, MaskKind::Building, stem)).unwrap();
        assert!(p
            .data()
            .iter()
            .all(|&v| (0.0..=255.0).contains(&v) && v.fract() == 0.0));
        assert!(out.join("classes").join(format!("{stem}.png")).is_file());
    }
    for kind in MaskKind::ALL {
        let name = kind.name();
        let text = std::fs::read_to_string(
            out.join(format!("{name}_segmentation/{name}_percentages.txt")),
        )
        .unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[0],
            format!("image_name {name}_percentage {name}_pixels total_pixels")
        );
        assert_eq!(lines.len(), 3, "{text}");
        assert!(
            lines[1].starts_with("IMG_51.iio ") && lines[2].starts_with("IMG_52.png "),
            "{text}"
        );
        let f: Vec<&str> = lines[1].split(' ').collect();
        let mask = raster::read_image(mask_path(&out, kind, "IMG_51")).unwrap();
        let n = mask.data().iter().filter(|&&v| v == 0.0).count();
        assert_eq!(f[2].parse::<usize>().unwrap(), n);
        assert_eq!(f[3], "9216");
        assert_eq!(f[1], format!("{:.6}", 100.0 * n as f64 / 9216.0));
    }
    // Rerun: nothing to do; another segmenter is refused.
    let again = run_masks(&opts(Shard::ALL), &Silent).unwrap();
    assert_eq!((again.done, again.skipped), (0, 2));
    std::fs::write(
        out.join("masks.json"),
        "{\"segmenter\": \"something else\"}",
    )
    .unwrap();
    let err = format!("{:#}", run_masks(&opts(Shard::ALL), &Silent).unwrap_err());
    assert!(err.contains("another segmenter"), "{err}");
}

#[test]
fn bad_inputs_are_explained() {
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().join("images");
    let sixteen = raster::Image::filled(16, 16, 3, 4000.0);
    raster::write_image(images.join("big.iio"), &sixteen).unwrap();
    let opts = MasksOptions {
        images_dir: images.clone(),
        out_dir: dir.path().join("out"),
        shard: Shard::ALL,
        segmenter: Box::new(OfflineSegmenter::default()),
    };
    let err = format!("{:#}", run_masks(&opts, &Silent).unwrap_err());
    assert!(err.contains("big.iio") && err.contains("8-bit"), "{err}");
    raster::write_image(
        images.join("sub").join("big.png"),
        &raster::Image::filled(4, 4, 3, 1.0),
    )
    .unwrap();
    let err = format!("{:#}", stages::masks::list_images(&images).unwrap_err());
    assert!(err.contains("same stem"), "{err}");
}

/// The rules segmenter on the procedural world, with the world's exact heights above the ground
/// (what a perfect teacher would give): its classes remain a test on synthetic data.
#[test]
fn rules_segmenter_on_unseen_worlds_with_exact_heights() {
    use stages::masks::heights::{ground_level, ImageHeights};
    let mut iou = [0.0f64; 3];
    for &seed in &TEST_SEEDS {
        let params = world::WorldParams::new(192, seed);
        let gsd = params.scene.gsd;
        let w = world::generate(&params, &world::Neutral, &|_, _| {}).unwrap();
        let ground = ground_level(&w.left.height, gsd);
        let above = raster::Image::new(
            192,
            192,
            1,
            w.left
                .height
                .data()
                .iter()
                .zip(ground.data())
                .map(|(a, g)| a - g)
                .collect(),
        )
        .unwrap();
        let heights = ImageHeights {
            measured: above.clone(),
            filled: above,
            pairs: vec![],
        };
        let options = MaskKind::ALL.map(dataset::segmentation::MaskOptions::defaults);
        let s = stages::masks::rules::segment(&w.left.image, Some(&heights), &options).unwrap();
        for (k, (kind, id)) in [
            (MaskKind::Tree, class::TREE),
            (MaskKind::Building, class::BUILDING),
            (MaskKind::Water, class::WATER),
        ]
        .into_iter()
        .enumerate()
        {
            let m = &s.get(kind).mask;
            let truth = w.left.classes.data().iter().map(|&c| c == id as f32);
            let (inter, union) = m.data().iter().zip(truth).fold((0, 0), |(i, u), (&a, b)| {
                (i + (a && b) as usize, u + (a || b) as usize)
            });
            iou[k] += inter as f64 / union.max(1) as f64 / TEST_SEEDS.len() as f64;
        }
    }
    println!(
        "rules on unseen worlds, exact heights: IoU tree {:.3} building {:.3} water {:.3}",
        iou[0], iou[1], iou[2]
    );
    // Measured 0.57 / 0.65 / 0.83 (the pixel classifier trained on such worlds: 0.73 / 0.34 /
    // 0.93): heights make the buildings; the world's water is blue but brighter and noisier
    // than the dark-and-smooth rule wants (0.44 without the blue rule).
    assert!(iou[0] >= 0.5, "tree IoU {}", iou[0]);
    assert!(iou[1] >= 0.55, "building IoU {}", iou[1]);
    assert!(iou[2] >= 0.75, "water IoU {}", iou[2]);
}
