//! `teacher` and `curate` on procedural worlds: resumability, shards, and the ranking of
//! consistent pairs above pairs whose right image changed appearance or lost registration.

use std::path::Path;

use dataset::Shard;
use matching::SgmParams;
use raster::Image;
use stages::curate::features::HistogramDescriptor;
use stages::curate::select::{roc_auc, Keep};
use stages::curate::{run_curate, ColourStatistic, CurateOptions, SsimScale};
use stages::teacher::{run_teacher, TeacherOptions};
use workflow::matcher::Matcher;
use workflow::Silent;

const SIZE: usize = 112;

/// Deterministic uniform numbers in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let (u, v) = (self.next().max(1e-12), self.next());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

/// What happened to the right image of a pair.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Change {
    None,
    ColourRemap,
    Haze,
    Winter,
    Autumn,
    Noise,
    ShiftDown,
    ShiftDiagonal,
}

fn map_pixels(img: &Image, f: impl Fn([f32; 3]) -> [f32; 3]) -> Image {
    let mut out = img.clone();
    for p in out.data_mut().chunks_exact_mut(3) {
        let q = f([p[0], p[1], p[2]]);
        for k in 0..3 {
            p[k] = q[k].clamp(0.0, 255.0);
        }
    }
    out
}

/// `img` moved by (dx, dy) pixels, edges repeated.
fn shifted(img: &Image, dx: isize, dy: isize) -> Image {
    let (w, h) = img.size();
    let mut out = img.clone();
    for y in 0..h {
        for x in 0..w {
            let sx = (x as isize - dx).clamp(0, w as isize - 1) as usize;
            let sy = (y as isize - dy).clamp(0, h as isize - 1) as usize;
            for c in 0..3 {
                out.set(x, y, c, img.get(sx, sy, c));
            }
        }
    }
    out
}

fn apply(change: Change, right: &Image, seed: u64) -> Image {
    match change {
        Change::None => right.clone(),
        Change::ColourRemap => map_pixels(right, |[r, g, b]| [b * 1.1, r * 0.9, g]),
        Change::Haze => map_pixels(right, |p| p.map(|v| 0.45 * v + 0.55 * 210.0)),
        Change::Winter => map_pixels(right, |[r, g, b]| {
            let v = (r + g + b) / 3.0;
            [0.6 * v + 90.0, 0.6 * v + 95.0, 0.6 * v + 110.0]
        }),
        Change::Autumn => map_pixels(right, |[r, g, b]| {
            if g > r && g > b {
                [g * 1.5, g * 0.8, b * 0.5]
            } else {
                [r * 1.1, g, b * 0.8]
            }
        }),
        Change::Noise => {
            let mut rng = Rng(seed * 7919 + 1);
            let mut out = right.clone();
            for v in out.data_mut() {
                *v = (*v as f64 + 35.0 * rng.gauss()).clamp(0.0, 255.0) as f32;
            }
            out
        }
        Change::ShiftDown => shifted(right, 0, 3),
        Change::ShiftDiagonal => shifted(right, 3, 2),
    }
}

const CHANGES: [Change; 7] = [
    Change::ColourRemap,
    Change::Haze,
    Change::Winter,
    Change::Autumn,
    Change::Noise,
    Change::ShiftDown,
    Change::ShiftDiagonal,
];

/// Writes `n_consistent` untouched world pairs and two pairs per kind of change; returns the
/// stems with their change, sorted by stem, and the disparity range covering every world.
fn write_pairs(root: &Path, n_consistent: usize) -> (Vec<(String, Change)>, (i32, i32)) {
    let mut list = Vec::new();
    let mut changes: Vec<Change> = vec![Change::None; n_consistent];
    for c in CHANGES {
        changes.extend([c, c]);
    }
    let mut range = (i32::MAX, i32::MIN);
    for (i, change) in changes.into_iter().enumerate() {
        let seed = 100 + i as u64;
        let world = world::generate(
            &world::WorldParams::new(SIZE, seed),
            &world::Neutral,
            &|_, _| {},
        )
        .unwrap();
        let (lo, hi) = world.disparity_range();
        range = (range.0.min(lo), range.1.max(hi));
        let stem = format!("W{seed:03}_A-W{seed:03}_B");
        raster::write_image(
            root.join("L").join(format!("{stem}.iio")),
            &world.left.image,
        )
        .unwrap();
        let right = apply(change, &world.right.image, seed);
        raster::write_image(root.join("R").join(format!("{stem}.iio")), &right).unwrap();
        list.push((stem, change));
    }
    list.sort_by(|a, b| a.0.cmp(&b.0));
    // Room for the diagonal shift, which a re-matching teacher absorbs as a disparity offset.
    (list, (range.0 - 4, range.1 + 4))
}

fn sgm_teacher(pairs: &Path, out: &Path, range: (i32, i32), shard: Shard) -> TeacherOptions {
    TeacherOptions {
        pairs_dir: pairs.to_path_buf(),
        out_dir: out.to_path_buf(),
        matcher: Matcher::Classical(SgmParams::default()),
        range: Some(range),
        shard,
    }
}

fn curate_options(
    pairs: &Path,
    teacher: &Path,
    out: &Path,
    keep: Keep,
    shard: Shard,
) -> CurateOptions {
    CurateOptions {
        pairs_dir: pairs.to_path_buf(),
        teacher_dir: teacher.to_path_buf(),
        out_dir: out.to_path_buf(),
        keep,
        colour: ColourStatistic::Mean,
        ssim_scale: SsimScale::Clamp,
        shard,
        features: Box::new(HistogramDescriptor),
    }
}

fn modified_times(dir: &Path) -> Vec<(String, std::time::SystemTime)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().to_string(),
                e.metadata().unwrap().modified().unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn curate_ranks_consistent_pairs_first() {
    let dir = tempfile::tempdir().unwrap();
    let (pairs, teacher, out) = (
        dir.path().join("pairs"),
        dir.path().join("teacher"),
        dir.path().join("curate"),
    );
    let (list, range) = write_pairs(&pairs, 14);
    let t = std::time::Instant::now();
    let s = run_teacher(&sgm_teacher(&pairs, &teacher, range, Shard::ALL), &Silent).unwrap();
    assert_eq!((s.done, s.skipped, s.total), (list.len(), 0, list.len()));
    let t_teacher = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let summary = run_curate(
        &curate_options(&pairs, &teacher, &out, Keep::Fraction(0.5), Shard::ALL),
        &Silent,
    )
    .unwrap();
    let t_curate = t.elapsed().as_secs_f64();
    let ranking = summary.ranking.expect("every pair scored: ranked");
    assert_eq!(ranking.rows.len(), list.len());
    let positive: Vec<bool> = list.iter().map(|(_, c)| *c == Change::None).collect();
    for (row, (stem, _)) in ranking.rows.iter().zip(&list) {
        assert_eq!(&row.stem, stem, "rows in stem order");
        assert_eq!(row.status, "ok");
    }
    let col = |f: &dyn Fn(&stages::curate::RankedPair) -> f64| -> Vec<f64> {
        ranking.rows.iter().map(f).collect()
    };
    let comb = col(&|r| r.s_comb.unwrap());
    let feat = col(&|r| r.s_feat.unwrap());
    let joint = col(&|r| -(r.joint_rank.unwrap() as f64));
    let auc_comb = roc_auc(&comb, &positive).unwrap();
    let auc_feat = roc_auc(&feat, &positive).unwrap();
    let auc_joint = roc_auc(&joint, &positive).unwrap();
    // AUC of S_feat on the appearance changes only (misregistration barely moves global
    // histograms; S_comb's SSIM is what catches it).
    let appearance: Vec<usize> = (0..list.len())
        .filter(|&i| !matches!(list[i].1, Change::ShiftDown | Change::ShiftDiagonal))
        .collect();
    let auc_feat_appearance = roc_auc(
        &appearance.iter().map(|&i| feat[i]).collect::<Vec<_>>(),
        &appearance.iter().map(|&i| positive[i]).collect::<Vec<_>>(),
    )
    .unwrap();
    for (r, (_, c)) in ranking.rows.iter().zip(&list) {
        println!(
            "{:<14} {:?}: S_color {:.3} SSIM {:.3} S_comb {:.3} S_feat {:.3} ranks {}/{}",
            r.stem,
            c,
            r.s_color.unwrap(),
            r.ssim.unwrap(),
            r.s_comb.unwrap(),
            r.s_feat.unwrap(),
            r.rank_comb.unwrap(),
            r.rank_feat.unwrap()
        );
    }
    println!(
        "ROC AUC (consistent vs changed, {} vs {} pairs): S_comb {auc_comb:.4}, S_feat {auc_feat:.4} \
         (appearance changes only {auc_feat_appearance:.4}), joint rank {auc_joint:.4}; d_max {:.2}; \
         teacher {t_teacher:.2} s, curate {t_curate:.2} s for {} pairs of {SIZE}²",
        positive.iter().filter(|&&p| p).count(),
        positive.iter().filter(|&&p| !p).count(),
        ranking.d_max,
        list.len()
    );
    assert!(auc_comb >= 0.95, "S_comb AUC {auc_comb}");
    assert!(auc_joint >= 0.95, "joint-rank AUC {auc_joint}");
    assert!(
        auc_feat_appearance >= 0.9,
        "S_feat AUC on appearance changes {auc_feat_appearance}"
    );
    // The selection is the intersection of both top-K: only pairs within K in both ranks.
    let k = ranking.k;
    assert_eq!(k, list.len() / 2);
    for r in &ranking.rows {
        assert_eq!(
            r.selected,
            r.rank_comb.unwrap() <= k && r.rank_feat.unwrap() <= k
        );
    }
    let precision = ranking
        .rows
        .iter()
        .zip(&positive)
        .filter(|(r, &p)| r.selected && p)
        .count() as f64
        / ranking.selected.len().max(1) as f64;
    println!(
        "selected {} pairs, {:.0} % of them consistent",
        ranking.selected.len(),
        100.0 * precision
    );
    assert!(precision >= 0.9);
    // Files: every score, the selection, the settings, the report.
    let csv = std::fs::read_to_string(out.join("scores.csv")).unwrap();
    assert!(csv.starts_with("stem,status,valid_ratio,d_color_mean,"));
    assert_eq!(csv.lines().count(), list.len() + 1);
    assert!(csv.contains("offline histogram descriptor"));
    let sel = std::fs::read_to_string(out.join("selected.txt")).unwrap();
    assert_eq!(
        sel.lines().collect::<Vec<_>>(),
        ranking
            .selected
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>()
    );
    let js: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("curate.json")).unwrap()).unwrap();
    assert_eq!(js["teacher"]["teacher"], "sgm");
    assert_eq!(js["selected"], ranking.selected.len());
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<polyline") && html.contains("S_feat"));

    // Rerun: nothing is recomputed and the outputs are identical.
    let before = modified_times(&out.join("scores"));
    let again = run_curate(
        &curate_options(&pairs, &teacher, &out, Keep::Fraction(0.5), Shard::ALL),
        &Silent,
    )
    .unwrap();
    assert_eq!((again.scoring.done, again.scoring.skipped), (0, list.len()));
    assert_eq!(modified_times(&out.join("scores")), before);
    assert_eq!(
        std::fs::read_to_string(out.join("scores.csv")).unwrap(),
        csv
    );
    let t = run_teacher(&sgm_teacher(&pairs, &teacher, range, Shard::ALL), &Silent).unwrap();
    assert_eq!(
        (t.done, t.skipped),
        (0, list.len()),
        "the teacher writes nothing the second time"
    );
}

#[test]
fn shards_cover_every_pair_once_and_rank_at_the_end() {
    let dir = tempfile::tempdir().unwrap();
    let (pairs, teacher, out) = (
        dir.path().join("pairs"),
        dir.path().join("teacher"),
        dir.path().join("curate"),
    );
    let (list, range) = write_pairs(&pairs, 3);
    let n = 3;
    let mut done = 0;
    for i in 0..n {
        let shard = Shard::new(i, n).unwrap();
        let s = run_teacher(&sgm_teacher(&pairs, &teacher, range, shard), &Silent).unwrap();
        assert_eq!(s.skipped, 0, "shards are disjoint");
        done += s.done;
    }
    assert_eq!(done, list.len(), "the shards cover every pair");
    for (stem, _) in &list {
        assert!(teacher.join(format!("{stem}.iio")).is_file());
    }
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(teacher.join("teacher.json")).unwrap())
            .unwrap();
    assert_eq!(record["teacher"], "sgm");
    // Another teacher into the same folder is refused.
    let other = TeacherOptions {
        matcher: Matcher::Classical(SgmParams::default()),
        range: Some((0, 10)),
        ..sgm_teacher(&pairs, &teacher, range, Shard::ALL)
    };
    let err = format!("{:#}", run_teacher(&other, &Silent).unwrap_err());
    assert!(err.contains("another teacher"), "{err}");

    let mut scored = 0;
    for i in 0..n {
        let s = run_curate(
            &curate_options(
                &pairs,
                &teacher,
                &out,
                Keep::Count(5),
                Shard::new(i, n).unwrap(),
            ),
            &Silent,
        )
        .unwrap();
        assert_eq!(s.scoring.skipped, 0);
        scored += s.scoring.done;
        assert_eq!(
            s.ranking.is_some(),
            i == n - 1,
            "the ranking waits for the last shard"
        );
        if i < n - 1 {
            assert!(s.missing > 0);
        }
    }
    assert_eq!(scored, list.len());
    let r = run_curate(
        &curate_options(&pairs, &teacher, &out, Keep::Count(5), Shard::ALL),
        &Silent,
    )
    .unwrap();
    assert_eq!(r.scoring.done, 0);
    assert_eq!(r.ranking.unwrap().k, 5);
}

#[test]
fn missing_teacher_disparity_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let (pairs, out) = (dir.path().join("pairs"), dir.path().join("curate"));
    let img = Image::from_fn(16, 16, |x, y| (x * 7 + y * 3) as f32);
    raster::write_image(pairs.join("L").join("A-B.iio"), &img).unwrap();
    raster::write_image(pairs.join("R").join("A-B.iio"), &img).unwrap();
    let err = run_curate(
        &curate_options(
            &pairs,
            &dir.path().join("none"),
            &out,
            Keep::Count(1),
            Shard::ALL,
        ),
        &Silent,
    )
    .unwrap_err();
    let msg = format!("{err:#}");
    assert!(
        msg.contains("A-B.iio") && msg.contains("seasonstereo teacher"),
        "{msg}"
    );
    // A left image without its right image.
    raster::write_image(pairs.join("L").join("C-D.iio"), &img).unwrap();
    let msg = format!(
        "{:#}",
        workflow::pairs::PairFolder::new(&pairs).list().unwrap_err()
    );
    assert!(msg.contains("R/C-D.iio"), "{msg}");
}
