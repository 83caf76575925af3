//! `seasonstereo demo` and `demo --ablation`: arguments and what the terminal prints (the work is
//! in the library's `seasonstereo::demo`).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use seasonstereo::demo::{
    metres, percent, pixels, run_ablation, run_demo, AblationOptions, DemoOptions, DemoSummary,
    ManyDatesResult,
};
use seasonstereo::train::ValidationRecord;
use seasonstereo::{Aggregation, Progress};

#[derive(Args)]
pub struct DemoArgs {
    /// Output folder of the report (report.html) and everything it shows
    /// [default: out/demo; out/demo-ablation with --ablation].
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// World size, pixels [default: 512; 256 with --ablation].
    #[arg(long)]
    size: Option<usize>,
    /// World seed (with --ablation: the first training world, the initial weights and the data
    /// order).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The data ablation instead (the paper's Table 2 in miniature, about 10 minutes on 2 cores):
    /// a training set from world pairs through the real stages, the tiny MonSter++ fine-tuned on
    /// S1 (real only) and on S3 (+ synthetic seasons) with the same budget, both and the
    /// classical matcher scored on held-out worlds, synchronic and winter ↔ summer.
    #[arg(long)]
    ablation: bool,
    /// Optimiser steps of each ablation run: the training budget (about 4 s a step on 2 cores)
    /// [default: 60].
    #[arg(long, requires = "ablation")]
    steps: Option<usize>,
    /// Training worlds of the ablation [default: 4].
    #[arg(long, requires = "ablation")]
    train_worlds: Option<usize>,
    /// Held-out test worlds of the ablation [default: 3].
    #[arg(long, requires = "ablation")]
    heldout_worlds: Option<usize>,
    #[command(flatten)]
    sgm: crate::args::SgmArgs,
}

pub fn run(a: DemoArgs, progress: &dyn Progress) -> Result<()> {
    if a.ablation {
        return run_ablation_command(a, progress);
    }
    let opts = DemoOptions {
        size: a.size.unwrap_or(512),
        seed: a.seed,
        out_dir: a.output.unwrap_or_else(|| "out/demo".into()),
        sgm: a.sgm.params(Aggregation::Mgm)?,
    };
    print_demo(&run_demo(&opts, progress)?);
    Ok(())
}

/// What the demo measured: the disparities, each pair's DSM, the many-date fusion, the report.
fn print_demo(s: &DemoSummary) {
    let v = &s.visible;
    println!(
        "disparity range {}..{} px (from the cameras); on pixels visible in both views: coverage {}, MAE {}, bad-1 {}, bad-2 {}",
        s.range.0,
        s.range.1,
        percent(v.coverage),
        pixels(v.mae),
        percent(v.bad1),
        percent(v.bad2)
    );
    for p in &s.pairs {
        let d = &p.dsm.scores;
        println!(
            "{} pair: disparity MAE {}, bad-2 {} (visible); DSM MAE {} filtered, {} all cells, coverage {} ({})",
            p.name,
            pixels(p.visible.mae),
            percent(p.visible.bad2),
            metres(d.mae_filtered),
            metres(d.mae_raw),
            percent(d.coverage),
            p.dsm.path.display()
        );
    }
    print_many_dates(&s.many_dates);
    let total: f64 = s.seconds.iter().map(|(_, t)| t).sum();
    println!("report: {} ({total:.1} s)", s.report.display());
}

/// The many-date fusion against the best-scored pair alone.
fn print_many_dates(m: &ManyDatesResult) {
    println!(
        "six dates ({}² px), {} pairs fused: DSM MAE {} filtered, coverage {}, within 1 m {}; the \
         best-scored pair alone ({}): {}, {}, {} ({})",
        m.size,
        m.chosen.len(),
        metres(m.fused.mae_filtered),
        percent(m.fused.coverage),
        percent(m.fused.within_1m),
        m.best_pair.0,
        metres(m.best_pair.1.mae_filtered),
        percent(m.best_pair.1.coverage),
        percent(m.best_pair.1.within_1m),
        m.folder.display()
    );
}

fn run_ablation_command(a: DemoArgs, progress: &dyn Progress) -> Result<()> {
    let s = run_ablation(&ablation_options(a)?, progress)?;
    for run in &s.runs {
        let c = &run.samples;
        let (first, last) = (run.validations.first(), run.validations.last());
        let epe = |v: Option<&ValidationRecord>| {
            v.map_or("–".to_string(), |v| format!("{:.2} px", v.scores.epe))
        };
        println!(
            "{}: {} steps on {} samples ({} real, {} synchronic synthetic, {} diachronic) in {:.0} s; validation EPE {} → {}",
            run.name,
            run.steps.len(),
            c.total,
            c.real,
            c.synchronic_synthetic,
            c.diachronic,
            run.seconds,
            epe(first),
            epe(last)
        );
    }
    println!("{}", s.table.to_text());
    let total: f64 = s.seconds.iter().map(|(_, t)| t).sum();
    println!("report: {} ({total:.1} s)", s.report.display());
    Ok(())
}

/// The ablation's options: its defaults, with the flags given.
fn ablation_options(a: DemoArgs) -> Result<AblationOptions> {
    let mut opts = AblationOptions::new(a.output.unwrap_or_else(|| "out/demo-ablation".into()));
    opts.seed = a.seed;
    opts.sgm = a.sgm.params(Aggregation::Mgm)?;
    if let Some(n) = a.size {
        opts.size = n;
    }
    if let Some(n) = a.steps {
        opts.steps = n;
    }
    if let Some(n) = a.train_worlds {
        opts.train_worlds = n;
    }
    if let Some(n) = a.heldout_worlds {
        opts.heldout_worlds = n;
    }
    Ok(opts)
}
