//! The demo's HTML report: the story of one run, section by section, with the commands that
//! reproduce it.

use std::path::{Path, PathBuf};

use anyhow::Result;
use raster::Image;
use synth::Season;

use super::dsms::{DFC_CLASSES, DSM_ERROR_MAX};
use super::format::{matcher_flags, metres, percent, pixels};
use super::options::DemoOptions;
use super::summary::PairResult;
use super::ManyDatesResult;
use eval::metrics::DsmScores;
use workflow::metrics::DisparityScores;
use workflow::pairs::PairPaths;
use workflow::report::Report;

/// What the report says about the run besides the scores.
pub struct ReportContext<'a> {
    pub opts: &'a DemoOptions,
    pub pair: &'a PairPaths,
    pub truth_dsm: PathBuf,
    /// The winter left and summer right images, as the commands name them.
    pub cross_season: [PathBuf; 2],
    pub range: (i32, i32),
    pub generator: String,
}

/// Writes the report of a run: the synchronic pair first, then the winter ↔ summer one.
pub fn write_report(
    path: &Path,
    c: &ReportContext<'_>,
    pairs: &[PairResult],
    many_dates: &ManyDatesResult,
    disparity_errors: [&Image; 2],
    dsm_errors: [&Image; 2],
    seconds: &[(String, f64)],
) -> Result<()> {
    let (sync, cross) = (&pairs[0], &pairs[1]);
    let mut r = Report::new("seasonstereo demo: a satellite pair across the seasons, to a DSM");
    intro(&mut r, c.opts);
    seasons(&mut r, &c.generator);
    two_pairs(&mut r);
    disparities(&mut r, c.range);
    dsms(&mut r);
    dsm_scores(&mut r, sync, cross);
    dsm_scores_by_class(&mut r, sync, cross);
    dsm_error_histograms(&mut r, dsm_errors);
    disparity_scores_by_class(&mut r, pairs, disparity_errors);
    many_dates_section(&mut r, many_dates);
    matcher_and_timings(&mut r, c.opts, seconds);
    reproduce(&mut r, c, many_dates)?;
    r.write(path)
}

/// What the demo shows, on which world.
fn intro(r: &mut Report, opts: &DemoOptions) {
    r.paragraph(&format!(
        "SeasonStereo matches satellite pairs whose two images were taken in different seasons and turns \
         them into Digital Surface Models. This report runs that story on a procedural {s}×{s} px world \
         (seed {seed}, 0.5 m per pixel) with exact ground truth: a rectified pair from two pushbroom cameras \
         with different incidence angles, its RPC cameras and its true DSM. The classical matcher (census + \
         MGM) matches the synchronic pair and a winter ↔ summer pair with the same geometry; both \
         disparities are triangulated through the RPCs into DSMs and scored against the truth with the \
         benchmark's protocol. Everything ran offline on the CPU. The built-in seasons only recolour the \
         scene; real multi-date pairs also move shadows, hide texture under snow and change the ground, so \
         real cross-season pairs are usually harder than this one.",
        s = opts.size,
        seed = opts.seed
    ));
}

/// 1: the built-in seasons of the left image.
fn seasons(r: &mut Report, generator: &str) {
    r.heading("1. One scene, four seasons");
    r.paragraph(&format!(
        "The left image through the four seasons of the {}, with the world's \
         classes as hints. It only changes colours, pointwise or through smooth low-frequency fields \
         (snow, foliage, haze, illumination), so every edge stays where it is and the true disparity \
         of any season pair is the synchronic one. SeasonStereo trains on such synthetic pairs; \
         `seasonstereo synthesize` applies the same model (or a generative API) to real pairs.",
        generator
    ));
    let thumbs: Vec<(String, String)> = Season::ALL
        .iter()
        .map(|s| {
            (
                format!("seasons/left_{s}_thumb.png"),
                format!("left image, {s}"),
            )
        })
        .collect();
    let thumb_refs: Vec<(&str, &str)> = thumbs
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect();
    r.figures(&thumb_refs);
}

/// 2: the synchronic and the cross-season pair.
fn two_pairs(r: &mut Report) {
    r.heading("2. Two pairs: synchronic and winter ↔ summer");
    r.figures(&[
        ("left.png", "synchronic pair: left"),
        ("right.png", "synchronic pair: right"),
        ("occlusion.png", "left pixels hidden in the right view"),
    ]);
    r.figures(&[
        ("left_winter.png", "cross-season pair: left in winter"),
        ("right_summer.png", "cross-season pair: right in summer"),
    ]);
}

/// 3: the true and predicted disparities, and their errors.
fn disparities(r: &mut Report, range: (i32, i32)) {
    r.heading("3. Disparities");
    r.paragraph(&format!(
        "Search range {lo}:{hi} px, derived from the cameras and the scene's altitude range (not from image \
         matches, which miss tall buildings on multi-date pairs). Disparity is on the left view: the left \
         pixel (x, y) matches the right pixel (x − d, y). Black: rejected by the consistency checks.",
        lo = range.0,
        hi = range.1
    ));
    r.figures(&[
        ("truth.png", "true disparity"),
        ("prediction.png", "synchronic disparity"),
        ("prediction_cross_season.png", "winter ↔ summer disparity"),
    ]);
    r.figures(&[
        ("error.png", "synchronic |error|, 0–3 px"),
        ("error_cross_season.png", "winter ↔ summer |error|, 0–3 px"),
    ]);
}

/// 4: the DSMs through the RPC cameras, and their errors.
fn dsms(r: &mut Report) {
    r.heading("4. DSMs through the RPC cameras");
    r.paragraph(
        "Each disparity is triangulated with the full RPCs (s2p's iteration) and gridded on the truth \
         DSM's UTM grid, highest point per cell, after the benchmark's evaluation mask (32 px border). \
         Colour: altitude (the truth's 2–98th percentile); shading: hillshade lit from the north-west. \
         Black: no point fell in the cell.",
    );
    r.figures(&[
        ("dsm_truth.png", "truth DSM"),
        ("dsm_synchronic.png", "DSM from the synchronic pair"),
        ("dsm_cross_season.png", "DSM from the winter ↔ summer pair"),
    ]);
    r.figures(&[
        (
            "dsm_error_synchronic.png",
            "synchronic |altitude error|, 0–3 m",
        ),
        (
            "dsm_error_cross_season.png",
            "winter ↔ summer |altitude error|, 0–3 m",
        ),
    ]);
    r.paragraph(
        "Error maps: after the benchmark's registration (integer shift by NCC, then vertical offset), on \
         the cells of its headline score (water and foliage masked, black).",
    );
}

/// 5: the benchmark's altitude scores of both pairs, with their disparity scores.
fn dsm_scores(r: &mut Report, sync: &PairResult, cross: &PairResult) {
    r.heading("5. Synchronic vs cross-season");
    r.paragraph(
        "Altitude MAE as the benchmark computes it: each score after its own registration on the truth \
         masked for it; \"filtered\" (water and foliage masked) is the headline number of the paper's \
         tables. Coverage: share of the truth's cells with a predicted height (the 32 px border the \
         protocol trims is never covered). Disparity scores are on the left pixels visible in both views.",
    );
    let dsm_row = |p: &PairResult| {
        let s = &p.dsm.scores;
        vec![
            p.name.clone(),
            metres(s.mae_filtered),
            metres(s.mae_no_water),
            metres(s.mae_raw),
            percent(s.coverage),
            percent(p.visible.coverage),
            pixels(p.visible.mae),
            percent(p.visible.bad1),
            percent(p.visible.bad2),
        ]
    };
    r.table(
        &[
            "pair",
            "DSM MAE (filtered)",
            "DSM MAE (no water)",
            "DSM MAE (all)",
            "DSM coverage",
            "disparity coverage",
            "disparity MAE",
            "bad-1",
            "bad-2",
        ],
        &[dsm_row(sync), dsm_row(cross)],
    );
}

/// 5, continued: the altitude MAE per class of the truth.
fn dsm_scores_by_class(r: &mut Report, sync: &PairResult, cross: &PairResult) {
    r.paragraph(
        "Altitude MAE per class of the truth (after the all-cells registration; cells finite in both):",
    );
    let class_rows: Vec<Vec<String>> = DFC_CLASSES
        .iter()
        .enumerate()
        .map(|(i, (_, name))| {
            let (s, x) = (&sync.dsm.by_class[i], &cross.dsm.by_class[i]);
            vec![
                name.to_string(),
                s.2.to_string(),
                metres(s.1),
                x.2.to_string(),
                metres(x.1),
            ]
        })
        .collect();
    r.table(
        &[
            "truth class",
            "cells (synchronic)",
            "MAE (synchronic)",
            "cells (winter ↔ summer)",
            "MAE (winter ↔ summer)",
        ],
        &class_rows,
    );
}

/// 5, continued: the headline cells' altitude errors.
fn dsm_error_histograms(r: &mut Report, dsm_errors: [&Image; 2]) {
    r.histograms(
        &[
            ("synchronic", dsm_errors[0].data()),
            ("winter ↔ summer", dsm_errors[1].data()),
        ],
        DSM_ERROR_MAX,
        30,
        "absolute altitude error (m), headline cells",
    );
}

/// 6: the disparity scores per class of each pair.
fn disparity_scores_by_class(r: &mut Report, pairs: &[PairResult], disparity_errors: [&Image; 2]) {
    r.heading("6. Disparity scores per class (visible pixels)");
    let header = [
        "region", "pixels", "coverage", "MAE", "RMSE", "bad-1", "bad-2",
    ];
    for p in pairs {
        r.paragraph(&format!("{} pair:", p.name));
        let mut rows = vec![score_row("all visible", &p.visible)];
        rows.extend(p.by_class.iter().map(|(n, s)| score_row(n, s)));
        r.table(&header, &rows);
    }
    r.histograms(
        &[
            ("synchronic", disparity_errors[0].data()),
            ("winter ↔ summer", disparity_errors[1].data()),
        ],
        3.0,
        30,
        "absolute disparity error (px), visible matched pixels",
    );
}

/// One row of the per-class disparity tables.
fn score_row(name: &str, s: &DisparityScores) -> Vec<String> {
    vec![
        name.to_string(),
        s.evaluated.to_string(),
        percent(s.coverage),
        pixels(s.mae),
        pixels(s.rmse),
        percent(s.bad1),
        percent(s.bad2),
    ]
}

/// The matcher's settings and the wall time of each step.
fn matcher_and_timings(r: &mut Report, opts: &DemoOptions, seconds: &[(String, f64)]) {
    r.heading("Matcher");
    r.paragraph(&opts.sgm.describe());
    r.heading("Timings");
    let mut rows: Vec<Vec<String>> = seconds
        .iter()
        .map(|(n, s)| vec![n.clone(), format!("{s:.2} s")])
        .collect();
    let total: f64 = seconds.iter().map(|(_, s)| s).sum();
    rows.push(vec!["total".into(), format!("{total:.2} s")]);
    r.table(&["step", "wall clock"], &rows);
}

/// 7: the six-date world, its chosen pairs and the fused DSM against the best pair alone.
fn many_dates_section(r: &mut Report, m: &ManyDatesResult) {
    r.heading("7. Many dates, one DSM");
    r.paragraph(&format!(
        "The same scene on six dates of a year ({s}×{s} px): spring, summer and winter, two \
         acquisitions a week apart from opposite sides in each season. The sun moves the shadows \
         and the built-in model recolours each season; the geometry never changes. \
         `reconstruct-many` scores the fifteen pairs from the cameras alone (date gap, convergence, \
         incidence, sun), reconstructs the best {n} without filling, and fuses them cell by cell \
         (clusters of agreeing heights, at least 2 pairs agreeing; the rest filled, then a median).",
        s = m.size,
        n = m.chosen.len()
    ));
    let rows: Vec<Vec<String>> = m
        .chosen
        .iter()
        .map(|c| {
            let s = c.scores.as_ref();
            vec![
                c.stem.clone(),
                c.days.map_or("?".into(), |d| format!("{d:.0}")),
                format!("{:.1}°", c.convergence_deg),
                format!("{:.3}", c.score),
                s.map_or("–".into(), |s| metres(s.mae_filtered)),
                s.map_or("–".into(), |s| percent(s.coverage)),
            ]
        })
        .collect();
    r.table(
        &[
            "chosen pair",
            "days apart",
            "convergence",
            "score",
            "its DSM's MAE (unfilled)",
            "its coverage",
        ],
        &rows,
    );
    let row = |name: &str, s: &DsmScores| {
        vec![
            name.to_string(),
            metres(s.mae_filtered),
            percent(s.coverage),
            percent(s.within_1m),
        ]
    };
    r.table(
        &["DSM", "MAE (filtered)", "coverage", "within 1 m"],
        &[
            row(&format!("fused, {} pairs", m.chosen.len()), &m.fused),
            row(
                &format!("best-scored pair alone ({}), `reconstruct`", m.best_pair.0),
                &m.best_pair.1,
            ),
        ],
    );
    r.paragraph(&format!(
        "Files under `{}`: the stack (`raw/`, `rpc/`, `truth/`, as `seasonstereo world --dates` \
         writes it), `fused.tif` with its count, spread and report, and `best_pair.tif`.",
        m.folder.display()
    ));
}

/// The commands that reproduce the report, step by step, and run it on real data.
fn reproduce(r: &mut Report, c: &ReportContext<'_>, m: &ManyDatesResult) -> Result<()> {
    let opts = c.opts;
    r.heading("Reproduce");
    let out = opts.out_dir.display().to_string();
    let world = format!("{out}/world");
    let stem = &c.pair.stem;
    let ids = dataset::PairStem::parse(stem)?;
    let (left_id, right_id) = (ids.left.id.as_str(), ids.right.id.as_str());
    let flags = matcher_flags(&opts.sgm);
    let truth = c.truth_dsm.display().to_string();
    let (lo, hi) = c.range;
    let dates = m.folder.display().to_string();
    let dates_truth = m
        .folder
        .join("truth")
        .join(format!("WORLD_{}_DSM.tif", opts.seed));
    let dates_truth = dates_truth.display();
    let dsm_cmd = |disparity: &str, dsm: &str| {
        format!(
            "seasonstereo dsm {disparity} --homography {world}/homography/{stem}.npz \
             --rpc-left {world}/rpc/{left_id}.json --rpc-right {world}/rpc/{right_id}.json \
             --like {truth} --border 32 -o {dsm}"
        )
    };
    r.paragraph("This whole report:");
    r.code(&format!(
        "seasonstereo demo --size {} --seed {} -o {out}{flags}",
        opts.size, opts.seed
    ));
    r.paragraph(
        "Step by step on the demo's files (`dsm --border 32` keeps a few more pixels than the protocol's \
         evaluation mask, so the all-cells MAE may differ in the last digit; `eval` applies the protocol \
         exactly):",
    );
    r.code(&[
        "# the world, its RPCs and its truth DSM, in the benchmark's layout".to_string(),
        format!("seasonstereo world --size {} --seed {} -o {world}", opts.size, opts.seed),
        "# disparities of the synchronic and the winter ↔ summer pair".to_string(),
        format!(
            "seasonstereo predict --range {lo}:{hi}{flags} {world}/L/{stem}.iio {world}/R/{stem}.iio -o {out}/prediction.iio"
        ),
        format!(
            "seasonstereo predict --range {lo}:{hi}{flags} {} {} -o {out}/prediction_cross_season.iio",
            c.cross_season[0].display(),
            c.cross_season[1].display()
        ),
        "# DSMs on the truth's grid (highest point per cell, 32 px border as the benchmark)".to_string(),
        dsm_cmd(&format!("{out}/prediction.iio"), &format!("{out}/dsm/synchronic.tif")),
        dsm_cmd(
            &format!("{out}/prediction_cross_season.iio"),
            &format!("{out}/dsm/cross_season.tif"),
        ),
        "# the benchmark's scores of DSMs on the truth's grid".to_string(),
        format!("seasonstereo score {out}/dsm/synchronic.tif {out}/dsm/cross_season.tif --truth {truth}"),
        "# the benchmark's whole protocol on the world's synchronic pair (Table 1 layout)".to_string(),
        format!("seasonstereo eval --world {world}{flags} -o {out}/eval"),
        "# section 7: the six-date world, its fused DSM and its best pair alone".to_string(),
        format!(
            "seasonstereo world --dates --size {} --seed {} -o {dates}",
            m.size, opts.seed
        ),
        format!(
            "seasonstereo reconstruct-many {dates}/raw/*.tif --rpc-dir {dates}/rpc --pairs {}{flags} \\\n    \
             --like {dates_truth} --truth {dates_truth} -o {dates}/fused.tif",
            m.chosen.len()
        ),
    ]
    .join("\n"));
    r.paragraph("On your own data (raw images and RPCs; a truth DSM <AOI>_DSM.tif with <AOI>_CLS.tif beside it):");
    r.code(
        "# raw pair → rectified → disparity → DSM, scored with the benchmark's metric\n\
         seasonstereo reconstruct LEFT.tif RIGHT.tif --rpc-left LEFT.json --rpc-right RIGHT.json \\\n    \
         --like TRUTH_DSM.tif --truth TRUTH_DSM.tif -o dsm.tif\n\
         # score DSMs you already have on the truth's grid\n\
         seasonstereo score dsm.tif --truth TRUTH_DSM.tif\n\
         # rectified test splits in the release's layout, the paper's Table 1\n\
         seasonstereo eval --split Jacksonville=DATA/JAX --rpc-dir DATA/root_dir \\\n    \
         --truth-dir DATA/Track3-Truth --method mgm -o out/eval",
    );
    Ok(())
}
