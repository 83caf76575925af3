//! The ablation's `report.html`: the training set, the training curves, the table on the
//! held-out worlds, what the run shows and what it does not, timings and the commands.

use anyhow::Result;
use raster::formats::{write_png, PngDepth};
use raster::{colormap, Image};

use super::heldout::CROSS_SEASON;
use super::runs::RunResult;
use super::summary::{AblationOptions, AblationSummary};
use crate::{dsm_picture, metres, percent, thumbnail};
use eval::layout::{AoiRule, TruthFiles};
use eval::table::format_stat;
use eval::{saved_dsm_path, Table};
use workflow::report::Report;

/// Steps of the moving mean of the training-loss curves (batch 1 makes single steps noisy).
const LOSS_WINDOW: usize = 5;

/// Writes `summary.report`.
pub fn write_report(opts: &AblationOptions, s: &AblationSummary) -> Result<()> {
    let pictures = write_pictures(opts, s)?;
    let mut r = Report::new("seasonstereo demo --ablation: the data ablation in miniature");
    intro(&mut r, opts, s);
    training_set(&mut r, s);
    training(&mut r, opts, s);
    results(&mut r, s, &pictures);
    reading(&mut r, opts, s);
    timings_and_commands(&mut r, opts, s)?;
    r.write(&s.report)
}

fn intro(r: &mut Report, opts: &AblationOptions, s: &AblationSummary) {
    r.paragraph(&format!(
        "SeasonStereo's Table 2 asks whether synthetic seasonal pairs help a stereo network on \
         cross-season pairs: the same network is fine-tuned on S1 (the real synchronic pairs only) \
         and on S3 (S1 plus synthetic synchronic and diachronic pairs in equal shares, same \
         budget), then both are scored on test pairs. This report runs that experiment in \
         miniature, offline on the CPU: {tw} of {n}×{n} px (seed {seed} onwards) go through the real stages, the tiny MonSter++ is fine-tuned on each subset for \
         {steps} steps from the same initial weights and seed, and both networks and the classical \
         teacher ({classical}) are scored with the benchmark's DSM metric on {hw} no stage has seen, synchronic and winter ↔ summer. The numbers are whatever this run \
         gives; section 4 says what they can and cannot mean.",
        tw = count(opts.train_worlds, "procedural training world"),
        n = opts.size,
        seed = opts.seed,
        steps = opts.steps,
        classical = s.classical,
        hw = count(opts.heldout_worlds, "held-out world"),
    ));
}

/// "1 world", "3 worlds".
fn count(n: usize, noun: &str) -> String {
    format!("{n} {noun}{}", if n == 1 { "" } else { "s" })
}

fn training_set(r: &mut Report, s: &AblationSummary) {
    let d = &s.dataset;
    r.heading("1. The training set, through the real stages");
    r.paragraph(&format!(
        "Per training world: the rectified pair and its homographies; the teacher disparity by the \
         classical matcher over the cameras' range {lo}..{hi} px (`teacher`); four seasonal \
         variants of each view by the built-in model, kept only when they pass the fidelity check \
         (`synthesize`: {acc} accepted, {rej} rejected); water, tree and building masks by the \
         offline segmenter on the raw images (`masks`); then `dataset build` writes every \
         combination, its masks and the subset lists. The validation worlds are built the same \
         way and scored against their exact disparity.",
        lo = d.range.0,
        hi = d.range.1,
        acc = d.train.synthesize.accepted,
        rej = d.train.synthesize.rejected,
    ));
    let rows: Vec<Vec<String>> = s
        .runs
        .iter()
        .map(|run| {
            let c = &run.samples;
            vec![
                run.name.clone(),
                c.real.to_string(),
                c.synchronic_synthetic.to_string(),
                c.diachronic.to_string(),
                c.total.to_string(),
            ]
        })
        .collect();
    r.table(
        &[
            "subset",
            "real pairs",
            "synchronic synthetic",
            "diachronic synthetic",
            "training samples",
        ],
        &rows,
    );
}

fn training(r: &mut Report, opts: &AblationOptions, s: &AblationSummary) {
    let c = &s.runs[0].config;
    r.heading("2. Fine-tuning on S1 and on S3");
    r.paragraph(&format!(
        "Both runs use the `tiny` training preset: MonSter++ `tiny`, {h}×{w} px crops, batch {b}, \
         {it} refinement iterations, AdamW at a peak rate of {lr} with the one-cycle schedule, the \
         paper's loss (disparity λ {ld}, photometric λ {lp}, smoothness λ {ls}) against the \
         teacher, mono branch frozen. Same initial weights (one file drawn from seed {seed}, \
         `runs/init.safetensors`), same seed for the data order and the augmentation, same \
         {steps} steps: only the training list differs. Validation every {ve} steps on the first \
         {vp} pairs of the validation world(s) (exact disparity, synchronic and diachronic).",
        h = c.augment.crop_height,
        w = c.augment.crop_width,
        b = c.run.batch_size,
        it = c.run.train_iters,
        lr = c.optim.lr,
        ld = c.loss.lambda_disp,
        lp = c.loss.lambda_photo,
        ls = c.loss.lambda_smooth,
        seed = opts.seed,
        steps = opts.steps,
        ve = opts.validate_every,
        vp = opts.valid_pairs,
    ));
    r.paragraph(&format!(
        "Training loss per step (mean over the last {LOSS_WINDOW} steps). The two losses are on \
         different samples, so their levels are not comparable; their trends are."
    ));
    curves(r, &s.runs, "step", "training loss", |run| {
        let v: Vec<f64> = run.steps.iter().map(|x| x.terms.total as f64).collect();
        moving_mean(&v, LOSS_WINDOW)
    });
    r.paragraph(&format!(
        "Validation end-point error (px) against the exact disparity; pass k is at step \
         (k − 1)·{} (pass 1: the shared initial weights).",
        opts.validate_every
    ));
    curves(
        r,
        &s.runs,
        "validation pass",
        "validation EPE (px)",
        |run| run.validations.iter().map(|v| v.scores.epe).collect(),
    );
    let px = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.2} px"));
    let rows: Vec<Vec<String>> = s
        .runs
        .iter()
        .map(|run| {
            let (first, last) = (run.validations.first(), run.validations.last());
            let pick = |v: Option<&train::ValidationRecord>,
                        f: fn(&train::ValidationRecord) -> Option<f64>| {
                px(v.and_then(f))
            };
            vec![
                run.name.clone(),
                format!("{:.3} → {:.3}", first_loss(run), last_loss(run)),
                pick(first, |v| Some(v.scores.epe)),
                pick(last, |v| Some(v.scores.epe)),
                pick(last, |v| v.scores.epe_synchronic),
                pick(last, |v| v.scores.epe_diachronic),
                format!("{:.0} s", run.seconds),
            ]
        })
        .collect();
    r.table(
        &[
            "run",
            "training loss, first → last step",
            "validation EPE at start",
            "validation EPE at the end",
            "synchronic pairs",
            "diachronic pairs",
            "wall clock",
        ],
        &rows,
    );
}

/// One line per run of `values(run)` against its index + 1.
fn curves(
    r: &mut Report,
    runs: &[RunResult],
    x_label: &str,
    y_label: &str,
    values: impl Fn(&RunResult) -> Vec<f64>,
) {
    let data: Vec<Vec<f64>> = runs.iter().map(values).collect();
    let series: Vec<(&str, &[f64])> = runs
        .iter()
        .zip(&data)
        .map(|(run, v)| (run.name.as_str(), v.as_slice()))
        .collect();
    r.line_plot(&series, x_label, y_label, None);
}

fn first_loss(run: &RunResult) -> f32 {
    run.steps.first().map_or(f32::NAN, |x| x.terms.total)
}

fn last_loss(run: &RunResult) -> f32 {
    run.steps.last().map_or(f32::NAN, |x| x.terms.total)
}

/// Mean of each value and the `window − 1` before it (fewer at the start).
fn moving_mean(values: &[f64], window: usize) -> Vec<f64> {
    (0..values.len())
        .map(|i| {
            let from = (i + 1).saturating_sub(window.max(1));
            let part = &values[from..=i];
            part.iter().sum::<f64>() / part.len() as f64
        })
        .collect()
}

/// Rows of the table: per method, each split's "mean ± std" and mean coverage.
fn table_rows(t: &Table) -> (Vec<String>, Vec<Vec<String>>) {
    let mut header = vec!["method".to_string()];
    for c in &t.columns {
        header.push(format!("{}: DSM MAE", c.title));
        header.push(format!("{}: coverage", c.title));
    }
    let rows = t
        .rows
        .iter()
        .map(|row| {
            let mut line = vec![row.method.clone()];
            for cell in &row.splits {
                line.push(format_stat(cell.as_ref()).replace("± –", "(one world)"));
                line.push(percent(cell.as_ref().and_then(|c| c.coverage)));
            }
            line
        })
        .collect();
    (header, rows)
}

/// The pictures of the first held-out world (relative paths beside the report).
struct Pictures {
    views: Vec<(String, String)>,
    dsms: Vec<(String, String)>,
}

fn write_pictures(opts: &AblationOptions, s: &AblationSummary) -> Result<Pictures> {
    let out = &opts.out_dir;
    let (seed, stem) = &s.heldout.worlds[0];
    let sync = &s.heldout.splits[0].dir;
    let mut views = Vec::new();
    for (file, source, caption) in [
        ("left", sync.join("L").join(format!("{stem}.iio")), "left"),
        ("right", sync.join("R").join(format!("{stem}.iio")), "right"),
        (
            "left_winter",
            s.heldout.first_winter.clone(),
            "left in winter",
        ),
        (
            "right_summer",
            s.heldout.first_summer.clone(),
            "right in summer",
        ),
    ] {
        let image = raster::read_image(&source)?;
        let path = format!("pictures/{file}.png");
        write_png(out.join(&path), &thumbnail(&image, 256)?, PngDepth::Eight)?;
        views.push((path, format!("held-out world {seed}: {caption}")));
    }
    let aoi = AoiRule::default().aoi_of(&dataset::PairStem::parse(stem)?.left.id);
    let truth = camera::read_dsm(TruthFiles::new(&s.heldout.truth_dir, &aoi).dsm, None)?;
    let cell = truth.grid.resolution;
    let range = colormap::robust_range(&truth.image);
    let mut dsms = Vec::new();
    let mut picture = |dsm: &Image, file: &str, caption: String| -> Result<()> {
        let path = format!("pictures/{file}.png");
        write_png(
            out.join(&path),
            &dsm_picture(dsm, cell, range),
            PngDepth::Eight,
        )?;
        dsms.push((path, caption));
        Ok(())
    };
    picture(&truth.image, "dsm_truth", "truth DSM".into())?;
    let methods = std::iter::once(s.classical.clone()).chain(s.runs.iter().map(|r| r.name.clone()));
    for (k, method) in methods.enumerate() {
        let path = saved_dsm_path(&out.join("eval"), &method, CROSS_SEASON, stem);
        let dsm = camera::read_dsm(&path, None)?;
        picture(
            &dsm.image,
            &format!("dsm_cross_season_{k}"),
            format!("{method}, winter ↔ summer"),
        )?;
    }
    Ok(Pictures { views, dsms })
}

fn as_refs(items: &[(String, String)]) -> Vec<(&str, &str)> {
    items
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect()
}

fn results(r: &mut Report, s: &AblationSummary, pictures: &Pictures) {
    r.heading("3. Held-out worlds: the table");
    r.paragraph(
        "Each held-out world is written in the benchmark's layout (rectified pair, RPC cameras, \
         truth DSM with its classes); its winter ↔ summer pair has the left view in winter and \
         the right one in summer, from a seasonal model seeded apart from the training set's, \
         with the same geometry. `eval` triangulates every disparity through the RPCs into a DSM \
         on the truth's grid and scores it as the benchmark does: altitude MAE after an integer \
         shift by NCC and a vertical offset, foliage and water masked; per split the mean ± \
         sample std over the worlds (one AOI each). Coverage beside it: an MAE alone rewards \
         holes.",
    );
    let (header, rows) = table_rows(&s.table);
    let header: Vec<&str> = header.iter().map(String::as_str).collect();
    r.table(&header, &rows);
    r.paragraph("Per world (DSM MAE, filtered):");
    let mut header = vec!["method".to_string()];
    let mut keys = Vec::new();
    for split in &s.heldout.splits {
        for (seed, stem) in &s.heldout.worlds {
            header.push(format!("world {seed}, {}", short_split(&split.name)));
            keys.push((split.name.clone(), stem.clone()));
        }
    }
    let methods: Vec<String> = s.table.rows.iter().map(|r| r.method.clone()).collect();
    let rows: Vec<Vec<String>> = methods
        .iter()
        .map(|m| {
            let mut line = vec![m.clone()];
            for (split, stem) in &keys {
                let mae = s
                    .records
                    .iter()
                    .find(|p| &p.method == m && &p.split == split && &p.stem == stem)
                    .and_then(|p| p.mae_filtered);
                line.push(metres(mae));
            }
            line
        })
        .collect();
    let header: Vec<&str> = header.iter().map(String::as_str).collect();
    r.table(&header, &rows);
    r.paragraph("The first held-out world, and its DSMs from the winter ↔ summer pair:");
    r.figures(&as_refs(&pictures.views));
    r.figures(&as_refs(&pictures.dsms));
    r.paragraph(
        "Colour: altitude (the truth's 2–98th percentile); shading: hillshade from the north-west; \
         black: no height.",
    );
}

fn short_split(name: &str) -> &str {
    name.strip_prefix("held-out ").unwrap_or(name)
}

/// Mean filtered MAE of `method` on `split` in the table.
fn mean_of(t: &Table, method: &str, split: &str) -> Option<f64> {
    let col = t.columns.iter().position(|c| c.title == split)?;
    let row = t.rows.iter().find(|r| r.method == method)?;
    row.splits[col].as_ref().map(|s| s.mean)
}

fn reading(r: &mut Report, opts: &AblationOptions, s: &AblationSummary) {
    r.heading("4. What this shows, and what it does not");
    let names: Vec<&str> = s.runs.iter().map(|r| r.name.as_str()).collect();
    let classical = mean_of(&s.table, &s.classical, CROSS_SEASON);
    let verdict = match (
        mean_of(&s.table, names[0], CROSS_SEASON),
        mean_of(&s.table, names[1], CROSS_SEASON),
    ) {
        (Some(a), Some(b)) => format!(
            "On the held-out winter ↔ summer pairs this run gives {} for {} and {} for {}: S3 is \
             {} by {:.3} m. The classical teacher scores {} there{}.",
            metres(Some(a)),
            names[0],
            metres(Some(b)),
            names[1],
            if b < a { "better" } else { "worse" },
            (a - b).abs(),
            metres(classical),
            if classical.is_some_and(|c| c < a.min(b)) {
                ": at this budget both networks are still far from the labels they learn from, so \
                 the comparison is between two unfinished trainings"
            } else {
                ""
            }
        ),
        _ => "One of the networks scored no held-out winter ↔ summer pair (no overlap with the \
              truth), so this run cannot compare them."
            .to_string(),
    };
    r.paragraph(&verdict);
    r.paragraph(&format!(
        "What it shows: the whole SeasonStereo chain runs end to end on data with exact ground \
         truth — teacher, seasonal synthesis, segmentation, dataset build with its subsets, \
         fine-tuning from one initialisation, and the benchmark's DSM metric on unseen worlds — \
         and how the two data subsets move a small network under an identical budget. What it \
         does not show: the paper's result. The network is the tiny test configuration, trained \
         for {steps} steps from random weights (the paper fine-tunes the ViT-L MonSter++ from a \
         pretrained checkpoint for 50,000 steps); the worlds are procedural; the held-out \
         seasons come from the same built-in appearance model that made S3's synthetic pairs \
         (the paper tests on real multi-date pairs, whose changes no recolouring reproduces); \
         {hw} and one seed give a wide spread, so a difference smaller than the \
         std over the worlds is noise. Run it with more steps (`--steps`) or another seed \
         (`--seed`) to see how stable the ordering is.",
        steps = opts.steps,
        hw = count(opts.heldout_worlds, "held-out world"),
    ));
}

fn timings_and_commands(r: &mut Report, opts: &AblationOptions, s: &AblationSummary) -> Result<()> {
    r.heading("Classical matcher");
    r.paragraph(&opts.sgm.describe());
    r.heading("Timings");
    let mut rows: Vec<Vec<String>> = s
        .seconds
        .iter()
        .map(|(n, t)| vec![n.clone(), format!("{t:.1} s")])
        .collect();
    let total: f64 = s.seconds.iter().map(|(_, t)| t).sum();
    rows.push(vec!["total".into(), format!("{total:.1} s")]);
    r.table(&["step", "wall clock"], &rows);

    r.heading("Reproduce");
    let out = opts.out_dir.display().to_string();
    r.paragraph("This whole report:");
    let d = AblationOptions::new(&opts.out_dir);
    let mut flags = String::new();
    if opts.train_worlds != d.train_worlds {
        flags += &format!(" --train-worlds {}", opts.train_worlds);
    }
    if opts.heldout_worlds != d.heldout_worlds {
        flags += &format!(" --heldout-worlds {}", opts.heldout_worlds);
    }
    r.code(&format!(
        "seasonstereo demo --ablation --size {} --seed {} --steps {}{flags} -o {out}{}",
        opts.size,
        opts.seed,
        opts.steps,
        crate::matcher_flags(&opts.sgm)
    ));
    r.paragraph(
        "Pieces of it on the report's files: a run again from its resolved configuration, a \
         network on the held-out splits.",
    );
    let c = &s.runs[0].config;
    let splits: String = s
        .heldout
        .splits
        .iter()
        .map(|sp| format!(" --split \"{}={}\"", sp.name, sp.dir.display()))
        .collect();
    r.code(&format!(
        "seasonstereo train --config {out}/runs/S1/config.toml\n\
         seasonstereo eval{splits} --rpc-dir {rpc} --truth-dir {truth} \\\n    \
         --model monsterpp --weights {out}/runs/S3/final.safetensors --config tiny --iters {it} \
         --max-disp {md} --name S3 -o {out}/eval-again",
        rpc = s.heldout.rpc_dir.display(),
        truth = s.heldout.truth_dir.display(),
        it = c.run.valid_iters,
        md = c.monster_config()?.max_disp,
    ));
    Ok(())
}
