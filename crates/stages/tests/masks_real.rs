//! The offline masks on real WorldView-3 imagery: DFC2019 JAX_068 development images (read in
//! place from the `data/dfc2019-jax068-dev` set, see `testdata`), heights from one
//! near-synchronic pair reconstructed by the classical chain, masks scored against the LiDAR
//! classes projected into the images. Bounds sit below what `scripts/jax-dev-masks.sh` measures
//! (BENCHMARKS.md, "Masks on real imagery") and above what the procedural-world pixel classifier
//! reaches.

use std::path::Path;

use matching::SgmParams;
use reconstruct::dsm::GridChoice;
use reconstruct::finishing::Finishing;
use reconstruct::{reconstruct, ReconstructOptions};
use stages::dataset_build::rectify_mask;
use stages::masks::heights::PairIndex;
use stages::masks::score::{
    read_masks, registration, score_folder, score_masks, ClassTruth, ImageScore,
};
use stages::masks::{run_masks, ImageSegmenter, MasksOptions, OfflineSegmenter, RulesSegmenter};
use workflow::matcher::Matcher;
use workflow::Silent;

use testdata::jax;

fn masks_of(images: &Path, out: &Path, segmenter: Box<dyn ImageSegmenter>) -> Vec<ImageScore> {
    run_masks(
        &MasksOptions {
            images_dir: images.to_path_buf(),
            out_dir: out.to_path_buf(),
            shard: Default::default(),
            segmenter,
        },
        &Silent,
    )
    .unwrap();
    score_folder(
        out,
        &jax("rpcs/ba"),
        &jax("truth/JAX_068_DSM.tif"),
        None,
        &[out.join("../dsm.tif")],
    )
    .unwrap()
    .scores
}

#[test]
fn rules_with_heights_find_the_trees_and_buildings_of_014_015() {
    testdata::require!(testdata::JAX_DEV);
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().join("images");
    std::fs::create_dir_all(&images).unwrap();
    for id in ["014", "015"] {
        let name = format!("JAX_068_{id}_RGB.tif");
        std::os::unix::fs::symlink(jax(&format!("images/{name}")), images.join(&name)).unwrap();
    }
    let pairs = dir.path().join("pairs");
    reconstruct(
        &ReconstructOptions {
            rpc_left: Some(jax("rpcs/ba/JAX_068_014_RGB.json")),
            rpc_right: Some(jax("rpcs/ba/JAX_068_015_RGB.json")),
            work_dir: Some(pairs.clone()),
            finishing: Finishing {
                fill_holes: None,
                median_filter: None,
                ..Finishing::default()
            },
            keep_intermediates: true,
            ..ReconstructOptions::new(
                images.join("JAX_068_014_RGB.tif"),
                images.join("JAX_068_015_RGB.tif"),
                Matcher::Classical(SgmParams::default()),
                GridChoice::Like(jax("truth/JAX_068_DSM.tif")),
                dir.path().join("dsm.tif"),
            )
        },
        &Silent,
    )
    .unwrap();
    let index = PairIndex::read(&pairs, &pairs.join("disparity")).unwrap();
    assert_eq!(index.len(), 1);
    let rules = masks_of(
        &images,
        &dir.path().join("rules"),
        Box::new(RulesSegmenter::new(Some(index))),
    );
    let old = masks_of(
        &images,
        &dir.path().join("old"),
        Box::new(OfflineSegmenter::default()),
    );
    assert_eq!(rules.len(), 2);
    for (r, o) in rules.iter().zip(&old) {
        eprintln!(
            "{}: rules tree IoU {:.3} R {:.3}, building IoU {:.3}, water {:.4}; pixel classifier tree IoU {:.3}, building IoU {:.3}",
            r.stem, r.tree.iou(), r.tree.recall(), r.building.iou(), r.water_share, o.tree.iou(), o.building.iou()
        );
        assert!(
            r.labelled > 300_000,
            "{}: {} labelled pixels",
            r.stem,
            r.labelled
        );
        assert!(
            r.building.iou() > 0.7,
            "{}: building IoU {}",
            r.stem,
            r.building.iou()
        );
        assert!(
            r.tree.iou() > 0.25 && r.tree.recall() > 0.45,
            "{}: tree {:?}",
            r.stem,
            r.tree
        );
        assert!(
            r.water_share < 0.01,
            "{}: no water in JAX_068, {}",
            r.stem,
            r.water_share
        );
        assert!(r.tree.iou() > o.tree.iou() + 0.1 && r.building.iou() > o.building.iou() + 0.2);
    }
    // `dataset build` rectifies the raw-frame tree mask with the pair's homography: the trees it
    // excludes there are the same (the truth classes rectified alike).
    let stem = "JAX_068_014_RGB";
    let [tree, ..] = read_masks(&dir.path().join("rules"), stem).unwrap();
    let rpc = reconstruct::dsm::read_camera(&jax("rpcs/ba/JAX_068_014_RGB.json")).unwrap();
    let zone = camera::UtmZone::from_lonlat(rpc.lon_offset, rpc.lat_offset);
    let truth = ClassTruth::read(&jax("truth/JAX_068_DSM.tif"), None, zone).unwrap();
    let (shift, _) = registration(&truth, &[dir.path().join("dsm.tif")]).unwrap();
    let projected = truth.classes_in_image(&rpc, tree.size(), shift);
    let (h_left, _) = raster::formats::read_homographies(
        pairs.join("homography/JAX_068_014_RGB-JAX_068_015_RGB.npz"),
    )
    .unwrap();
    let size = raster::read_image(pairs.join("L/JAX_068_014_RGB-JAX_068_015_RGB.iio"))
        .unwrap()
        .size();
    let class = |k: f32| {
        let m = raster::Mask::from_fn(tree.width(), tree.height(), |x, y| {
            projected.get(x, y, 0) == k
        });
        rectify_mask(&m, &h_left, size).unwrap()
    };
    let (t, g, b) = (class(5.0), class(2.0), class(6.0));
    let rect_tree = rectify_mask(&tree, &h_left, size).unwrap();
    let labels = raster::Image::from_fn(size.0, size.1, |x, y| {
        [(&t, 5.0), (&g, 2.0), (&b, 6.0)]
            .iter()
            .find(|(m, _)| m.get(x, y))
            .map_or(f32::NAN, |(_, k)| *k)
    });
    let none = raster::Mask::filled(size.0, size.1, false);
    let rectified = score_masks(stem, &labels, &rect_tree, &none, &none);
    eprintln!(
        "{stem} rectified: tree IoU {:.3} R {:.3} (raw frame {:.3} / {:.3})",
        rectified.tree.iou(),
        rectified.tree.recall(),
        rules[0].tree.iou(),
        rules[0].tree.recall()
    );
    assert!((rectified.tree.iou() - rules[0].tree.iou()).abs() < 0.03);
    assert!((rectified.tree.recall() - rules[0].tree.recall()).abs() < 0.03);
    // The records say where the heights came from.
    let record =
        std::fs::read_to_string(dir.path().join("rules/records/JAX_068_015_RGB.json")).unwrap();
    assert!(
        record.contains("JAX_068_014_RGB-JAX_068_015_RGB"),
        "{record}"
    );
}
