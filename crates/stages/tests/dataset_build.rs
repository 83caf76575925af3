//! `dataset build` and `dataset world` on procedural worlds: 25 combinations per pair, the three
//! subsets, masks against the worlds' exact classes, and resuming a build killed midway.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use dataset::experiment::read_experiment_csv;
use dataset::layout::{DatasetDir, MaskKind};
use dataset::manifest::Manifest;
use dataset::{load_sample, PairKind, PairStem, SampleIndex, Shard, Side, Subset};
use stages::dataset_build::{run_build, BuildOptions, MaskDirs};
use stages::synthesize::{run_synthesize, SynthesizeOptions};
use stages::teacher::{run_teacher, TeacherOptions};
use stages::world_training::{
    build_world_training, world_ids, world_range, write_world_sources, WorldTrainingOptions,
};
use synth::BuiltinSeasons;
use workflow::matcher::Matcher;
use workflow::Silent;

const SIZE: usize = 96;

fn count_kind(rows: &[dataset::experiment::ExperimentRow], k: PairKind) -> usize {
    rows.iter().filter(|r| r.stem.kind() == k).count()
}

#[test]
fn world_training_set_has_25_combinations_subsets_and_exact_masks() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("set");
    let mut opts = WorldTrainingOptions::new(&out, SIZE, 2, 1);
    opts.seed = 3;
    let s = build_world_training(&opts, &Silent).unwrap();
    assert_eq!(
        s.train.synthesize.rejected, 0,
        "built-in variants must pass the fidelity check"
    );
    assert!(s.train.build.finalized && s.val.build.finalized);
    assert_eq!(s.train.build.combinations_written, 50);

    let dir = DatasetDir::new(&out);
    let layout = dir.train("sgm");
    assert!(
        layout.lidar_dir.is_some(),
        "the exact disparity is the LiDAR folder"
    );
    // 25 combinations per pair, both views.
    for seed in [3, 4] {
        let (a, b) = world_ids(seed);
        let pair = PairStem::real(&a, &b);
        let tags: Vec<Option<String>> = std::iter::once(None)
            .chain(["summer", "autumn", "winter", "spring"].map(|t| Some(t.to_string())))
            .collect();
        for combo in pair.combinations(&tags) {
            for side in Side::BOTH {
                assert!(layout.image(side, &combo).is_file(), "{combo} {side:?}");
            }
        }
        assert_eq!(pair.combinations(&tags).len(), 25);
    }

    // The subsets.
    let list = |s: Subset| read_experiment_csv(&dir.experiment_csv(s.csv_name())).unwrap();
    let (s1, s2, s3, all) = (
        list(Subset::S1),
        list(Subset::S2),
        list(Subset::S3),
        list(Subset::All),
    );
    assert_eq!(s1.len(), 2);
    assert!(s1.iter().all(|r| r.stem.is_real()));
    assert_eq!(count_kind(&s2, PairKind::SynchronicSynthetic), 8);
    assert_eq!(count_kind(&s2, PairKind::Diachronic), 0);
    assert_eq!(s3.len(), s2.len(), "S3 has the augmentation budget of S2");
    assert_eq!(count_kind(&s3, PairKind::SynchronicSynthetic), 4);
    assert_eq!(count_kind(&s3, PairKind::Diachronic), 4);
    assert_eq!(all.len(), 50);
    assert_eq!(count_kind(&all, PairKind::Diachronic), 40);
    let val = read_experiment_csv(&dir.experiment_csv("sub_val")).unwrap();
    assert_eq!(val.len(), 25);

    // The manifest.
    let m = Manifest::read(&dir.manifest()).unwrap();
    assert_eq!(m.teacher, "sgm");
    assert!(m.generator.starts_with("builtin"), "{}", m.generator);
    let train = &m.splits["train"];
    assert_eq!(train.pairs, 2);
    assert_eq!(
        (
            train.combinations.real,
            train.combinations.synchronic_synthetic,
            train.combinations.diachronic
        ),
        (2, 8, 40)
    );
    assert_eq!(train.subsets["S3"].counts.total, 10);
    assert_eq!(train.missing_masks, 0);
    assert_eq!(m.splits["val"].pairs, 1);

    // A diachronic sample: linked to its real pair, teacher, exact disparity and masks.
    let (a, b) = world_ids(3);
    let stem = PairStem::parse(&format!("{a}__winter-{b}__summer")).unwrap();
    let sample = load_sample(&layout, &stem).unwrap();
    assert!(sample.diachronic);
    let world = world::generate(
        &world::WorldParams::new(SIZE, 3),
        &world::Neutral,
        &|_, _| {},
    )
    .unwrap();
    assert_eq!(sample.real_left.data(), world.left.image.data());
    assert_eq!(
        sample.lidar.as_ref().unwrap().data(),
        world.disparity.data()
    );
    let diff: f64 = sample
        .input_left
        .data()
        .iter()
        .zip(sample.real_left.data())
        .map(|(a, b)| (a - b).abs() as f64)
        .sum::<f64>()
        / sample.real_left.data().len() as f64;
    assert!(
        diff > 5.0,
        "the winter view must differ from the real one (mean |Δ| {diff})"
    );
    // The teacher (SGM) agrees with the exact disparity on most supervised pixels.
    let sup = sample.supervision_mask(false);
    let (mut n, mut good) = (0usize, 0usize);
    for (i, &v) in sup.data().iter().enumerate() {
        if v {
            n += 1;
            good += ((sample.teacher.data()[i] - world.disparity.data()[i]).abs() < 2.0) as usize;
        }
    }
    assert!(n > SIZE * SIZE / 3, "supervised pixels: {n}");
    assert!(
        good as f64 > 0.85 * n as f64,
        "teacher within 2 px on {good}/{n}"
    );
    // Masks follow the exact classes inside the footprint.
    let footprint =
        dataset::masks::read_mask(&layout.mask(MaskKind::Valid, Side::Left, &stem), "").unwrap();
    assert!(
        footprint.count() > SIZE * SIZE * 8 / 10,
        "footprint {}",
        footprint.count()
    );
    let (mut agree, mut inside) = (0usize, 0usize);
    let (mut agree_b, mut buildings) = (0usize, 0usize);
    for i in 0..SIZE * SIZE {
        if !footprint.data()[i] {
            assert!(!sample.valid_left.data()[i]);
            continue;
        }
        inside += 1;
        let c = world.left.classes.data()[i] as u8;
        let excluded = c == world::class::WATER || c == world::class::TREE;
        agree += (sample.valid_left.data()[i] != excluded) as usize;
        let is_b = c == world::class::BUILDING;
        buildings += is_b as usize;
        agree_b += (is_b && sample.building_left.data()[i]) as usize;
    }
    assert!(
        agree as f64 > 0.97 * inside as f64,
        "validity agrees on {agree}/{inside}"
    );
    assert!(
        buildings > 0 && agree_b as f64 > 0.95 * buildings as f64,
        "{agree_b}/{buildings}"
    );

    // The index reads the lists; the validation split is supervised by the exact disparity.
    let index =
        SampleIndex::from_experiment(layout.clone(), &dir.experiment_csv("sub5_syndiach")).unwrap();
    index.check_files().unwrap();
    assert_eq!(index.len(), 10);
    let v = SampleIndex::from_experiment(dir.val(), &dir.experiment_csv("sub_val")).unwrap();
    let vs = v.load(0).unwrap();
    assert_eq!(vs.teacher.data(), vs.lidar.as_ref().unwrap().data());
}

/// Sources of two worlds (pairs, raw images, segmentations, teacher, variants).
fn sources(root: &Path) -> (PathBuf, PathBuf, PathBuf) {
    for seed in [11, 12] {
        write_world_sources(root, SIZE, seed).unwrap();
    }
    let pairs = root.join("pairs");
    let teacher = root.join("teacher");
    run_teacher(
        &TeacherOptions {
            pairs_dir: pairs.clone(),
            out_dir: teacher.clone(),
            matcher: Matcher::Classical(matching::SgmParams::default()),
            range: Some(world_range(SIZE)),
            shard: Shard::ALL,
        },
        &Silent,
    )
    .unwrap();
    let mut syn = SynthesizeOptions::new(&pairs, &root.join("raw"), &root.join("synthetic"));
    syn.classes_dir = Some(root.join("classes"));
    run_synthesize(&syn, &BuiltinSeasons::new(0), &Silent).unwrap();
    (pairs, teacher, root.join("synthetic"))
}

fn mtimes(dir: &Path) -> BTreeMap<PathBuf, SystemTime> {
    let mut out = BTreeMap::new();
    for side in ["L", "R"] {
        for e in std::fs::read_dir(dir.join(side)).unwrap() {
            let p = e.unwrap().path();
            out.insert(
                p.clone(),
                std::fs::metadata(&p).unwrap().modified().unwrap(),
            );
        }
    }
    out
}

#[test]
fn killed_build_resumes_without_redoing_finished_items() {
    let tmp = tempfile::tempdir().unwrap();
    let (pairs, teacher, synthetic) = sources(&tmp.path().join("src"));
    let out = tmp.path().join("set");
    let mut opts = BuildOptions::new(&pairs, &teacher, &out);
    opts.synthetic_dir = Some(synthetic);
    opts.masks = MaskDirs::release(&tmp.path().join("src").join("masks"));

    // "Killed" after 30 of the 50 combinations: the first pair finished, the second midway.
    opts.stop_after = Some(30);
    let first = run_build(&opts, &Silent).unwrap();
    assert_eq!(first.combinations_written, 30);
    assert_eq!(first.pairs_done, 1);
    assert_eq!(first.pending, 1);
    assert!(!first.finalized, "no subsets before every pair is finished");
    let dir = DatasetDir::new(&out);
    assert!(!dir.manifest().exists());
    let before = mtimes(&out.join("train"));
    assert_eq!(before.len(), 60);

    std::thread::sleep(std::time::Duration::from_millis(20));
    opts.stop_after = None;
    let second = run_build(&opts, &Silent).unwrap();
    assert_eq!(second.combinations_written, 20, "only the rest is written");
    assert_eq!(second.combinations_skipped, 5);
    assert_eq!(second.pairs_skipped, 1);
    assert!(second.finalized);
    let after = mtimes(&out.join("train"));
    assert_eq!(after.len(), 100);
    for (p, t) in &before {
        assert_eq!(after[p], *t, "{} was rewritten", p.display());
    }
    let all = read_experiment_csv(&dir.experiment_csv("sub3_diachronic")).unwrap();
    assert_eq!(all.len(), 50);

    // A third run does nothing.
    let third = run_build(&opts, &Silent).unwrap();
    assert_eq!((third.combinations_written, third.pairs_skipped), (0, 2));
    assert!(third.finalized);
}

#[test]
fn sharded_build_and_missing_masks() {
    let tmp = tempfile::tempdir().unwrap();
    let (pairs, teacher, synthetic) = sources(&tmp.path().join("src"));
    let masks = tmp.path().join("src").join("masks");
    // One building segmentation is missing: the release's default (no building) is used and listed.
    let (a, _) = world_ids(11);
    std::fs::remove_file(
        masks
            .join("building_segmentation/masks")
            .join(format!("{a}_mask.png")),
    )
    .unwrap();
    let out = tmp.path().join("set");
    let mut opts = BuildOptions::new(&pairs, &teacher, &out);
    opts.synthetic_dir = Some(synthetic);
    opts.masks = MaskDirs::release(&masks);
    opts.shard = Shard::parse("1/2").unwrap();
    let s1 = run_build(&opts, &Silent).unwrap();
    assert_eq!((s1.pairs_in_shard, s1.pairs_done, s1.pending), (1, 1, 1));
    assert!(!s1.finalized);
    opts.shard = Shard::parse("0/2").unwrap();
    let s0 = run_build(&opts, &Silent).unwrap();
    assert_eq!((s0.pairs_done, s0.pending), (1, 0));
    assert!(s0.finalized, "the last shard to finish writes the lists");
    assert_eq!(s0.missing_masks, 1);
    let missing = std::fs::read_to_string(out.join("train/missing_files.txt")).unwrap();
    assert!(missing.contains(&format!("{a}_mask.png")), "{missing}");
    let layout = DatasetDir::new(&out).train("sgm");
    let stem = PairStem::real(world_ids(11).0, world_ids(11).1);
    let b =
        dataset::masks::read_mask(&layout.mask(MaskKind::Building, Side::Left, &stem), "").unwrap();
    assert_eq!(b.count(), 0);
    let b = dataset::masks::read_mask(&layout.mask(MaskKind::Building, Side::Right, &stem), "")
        .unwrap();
    assert!(b.count() > 0);
}

#[test]
fn missing_teacher_names_the_file_and_the_stage() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    write_world_sources(&src, 64, 21).unwrap();
    let opts = BuildOptions::new(
        &src.join("pairs"),
        &tmp.path().join("no-teacher"),
        &tmp.path().join("set"),
    );
    let err = format!("{:#}", run_build(&opts, &Silent).unwrap_err());
    assert!(
        err.contains("seasonstereo teacher") && err.contains(".iio"),
        "{err}"
    );
}

/// The built-in model, except that winter comes out shifted by 2 px (a hallucinated geometry);
/// counts its calls.
struct ShiftedWinter {
    inner: BuiltinSeasons,
    calls: std::sync::atomic::AtomicUsize,
}

impl synth::SeasonGenerator for ShiftedWinter {
    fn name(&self) -> String {
        "shifted-winter".into()
    }

    fn generate(
        &self,
        source: &synth::SourceImage<'_>,
        season: synth::Season,
    ) -> Result<raster::Image, synth::SynthError> {
        self.calls.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        let v = self.inner.generate(source, season)?;
        if season != synth::Season::Winter {
            return Ok(v);
        }
        let (w, h, c) = (v.width(), v.height(), v.channels());
        let mut out = v.clone();
        for y in 0..h {
            for x in 0..w {
                for k in 0..c {
                    out.set(x, y, k, v.get(x.saturating_sub(2), y, k));
                }
            }
        }
        Ok(out)
    }
}

#[test]
fn rejected_variants_are_listed_and_never_used() {
    use synth::SeasonGenerator as _;
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    write_world_sources(&src, SIZE, 31).unwrap();
    let pairs = src.join("pairs");
    let generator = ShiftedWinter {
        inner: BuiltinSeasons::new(0),
        calls: Default::default(),
    };
    let syn_dir = src.join("synthetic");
    let mut syn = SynthesizeOptions::new(&pairs, &src.join("raw"), &syn_dir);
    syn.classes_dir = Some(src.join("classes"));
    let s = run_synthesize(&syn, &generator, &Silent).unwrap();
    assert_eq!((s.accepted, s.rejected), (6, 2));
    assert_eq!(generator.calls.load(std::sync::atomic::Ordering::SeqCst), 8);
    let (a, b) = world_ids(31);
    let rejected = std::fs::read_to_string(syn_dir.join("rejected.csv")).unwrap();
    assert!(
        rejected.contains(&format!("{a},winter")) && rejected.contains(&format!("{b},winter")),
        "{rejected}"
    );
    assert!(syn_dir.join(format!("rejected/{a}_winter.tif")).is_file());
    assert!(!syn_dir
        .join(format!("cropped-synthetic/{a}_winter.tif"))
        .exists());
    assert!(syn_dir
        .join(format!("cropped-synthetic/{a}_summer.tif"))
        .is_file());
    assert_eq!(generator.name(), "shifted-winter");

    // A rerun generates nothing.
    let again = run_synthesize(&syn, &generator, &Silent).unwrap();
    assert_eq!((again.images.done, again.images.skipped), (0, 2));
    assert_eq!(generator.calls.load(std::sync::atomic::Ordering::SeqCst), 8);
    // Another generator into the same folder is refused.
    let err = run_synthesize(&syn, &BuiltinSeasons::new(0), &Silent).unwrap_err();
    assert!(format!("{err:#}").contains("shifted-winter"), "{err:#}");

    // The set has 4 × 4 combinations and no winter.
    let teacher = src.join("truth");
    let out = tmp.path().join("set");
    let mut opts = BuildOptions::new(&pairs, &teacher, &out);
    opts.synthetic_dir = Some(syn_dir);
    opts.teacher_name = Some("exact".into());
    let r = run_build(&opts, &Silent).unwrap();
    assert_eq!(r.combinations_written, 16);
    let all =
        read_experiment_csv(&DatasetDir::new(&out).experiment_csv("sub3_diachronic")).unwrap();
    assert_eq!(all.len(), 16);
    assert!(all.iter().all(|r| !r.stem.to_string().contains("winter")));
    let s2 = read_experiment_csv(&DatasetDir::new(&out).experiment_csv("sub2_synchronic")).unwrap();
    assert_eq!(count_kind(&s2, PairKind::SynchronicSynthetic), 3);
    let m = Manifest::read(&DatasetDir::new(&out).manifest()).unwrap();
    assert_eq!(m.splits["train"].rejected_variants, 2);
    assert_eq!(m.generator, "shifted-winter");
    // No segmentation given: the release's defaults, all listed.
    assert_eq!(m.splits["train"].missing_masks, 6);
}
