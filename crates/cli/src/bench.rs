//! `seasonstereo bench`: how fast the networks run here, with random weights: one warm-up run,
//! then N timed runs; the median and the minimum, and the process's peak RSS. `bench merge`
//! times the assembly of a DSM instead ([`crate::bench_merge`]).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{anyhow, Result};
use clap::{Args, ValueEnum};
use seasonstereo::bench::{
    dinov3, median, monster, peak_rss_bytes, segformer, step_config, train_step, Device, GroupTime,
    Recording, Workload,
};

use crate::args::DeviceArg;

/// What to time.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum BenchWorkload {
    /// One MonSter++ inference pass (default vits, 256×512, 12 iterations).
    Monsterpp,
    /// One SegFormer pass (default mit-b2, the release's OpenEarthMap model, 1000×1000).
    Segformer,
    /// One DINOv3 pass (default vits16, a batch of 2 crops of 224×224).
    Dinov3,
    /// One training step of MonSter++ with the SeasonStereo loss and AdamW (default tiny,
    /// 64×128, batch 1, 7 iterations).
    TrainStep,
    /// The assembly of a whole-scene DSM from fabricated finished tiles (no stereo, no network):
    /// one run, its time and peak RSS.
    Merge,
}

#[derive(Args)]
#[command(
    after_help = "Examples:\n  seasonstereo bench monsterpp --config vits --height 256 \
    --width 512 \\\n      --iters 12 --max-disp 192 --runs 3 --json\n  seasonstereo bench segformer \
    --height 1000\n  seasonstereo bench train-step --config vits --height 128 --width 128\n  \
    seasonstereo bench merge --cells 16384 --work merge16k\n\n\
    Weights are random: the time of a pass does not depend on them. Compare with the PyTorch \
    reference the same way (BENCHMARKS.md)."
)]
pub struct BenchArgs {
    workload: BenchWorkload,
    /// Preset of the network (monsterpp: tiny, vits, vitb, vitl; segformer: mit-b2, tiny;
    /// dinov3: vits16, vitb16, vitl16, tiny; train-step: a MonSter++ preset).
    #[arg(long = "config", value_name = "PRESET")]
    preset: Option<String>,
    /// Input height, pixels (SegFormer and DINOv3: the square side).
    #[arg(long)]
    height: Option<usize>,
    /// Input width, pixels.
    #[arg(long)]
    width: Option<usize>,
    /// MonSter++ refinement iterations.
    #[arg(long)]
    iters: Option<usize>,
    /// MonSter++ maximum disparity (a multiple of 32); default: the preset's (train-step: 64
    /// for tiny, 192 otherwise).
    #[arg(long)]
    max_disp: Option<usize>,
    /// Batch size (DINOv3, train-step).
    #[arg(long)]
    batch: Option<usize>,
    /// Timed runs after the warm-up.
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// Print one JSON line instead of the sentence.
    #[arg(long)]
    json: bool,
    /// After the timed runs, one more run with the time of every module group (MonSter++:
    /// DINOv2, DPT heads, stems, GWC volume, hourglass, geo lookup, ConvGRU, refinement,
    /// upsampling, REMP; the groups of `scripts/peers/monsterpp_torch.py --profile`).
    #[arg(long)]
    profile: bool,
    /// merge: cells on each side of the fabricated square grid.
    #[arg(long, default_value_t = 16384)]
    cells: usize,
    /// merge: rows of the DSM finished at once (default 256; the grid's side merges it whole).
    #[arg(long)]
    block_rows: Option<usize>,
    /// merge: the fabricated work folder, made once and reused (default: in the temporary
    /// folder).
    #[arg(long)]
    work: Option<PathBuf>,
    #[command(flatten)]
    device: DeviceArg,
}

pub fn run(a: BenchArgs) -> Result<()> {
    if let BenchWorkload::Merge = a.workload {
        return crate::bench_merge::run(a.cells, a.block_rows, a.work, a.json);
    }
    if a.runs == 0 {
        anyhow::bail!("--runs must be at least 1");
    }
    let device = a.device.device.device().map_err(|e| anyhow!(e))?;
    let shape = BenchShape::of(&a);
    let mut work = shape.workload(&a, &device)?;
    let warmup = timed(&mut work)?;
    let times = (0..a.runs)
        .map(|_| timed(&mut work))
        .collect::<Result<Vec<f64>>>()?;
    let profile = if a.profile {
        Some(profiled(&mut work, &device)?)
    } else {
        None
    };
    let timing = Timing {
        median: median(&times).expect("at least one run"),
        min: times.iter().copied().fold(f64::INFINITY, f64::min),
        peak_mib: peak_rss_bytes().map(|b| b as f64 / (1u64 << 20) as f64),
        warmup,
        times,
    };
    if a.json {
        println!("{}", json_line(&a, &shape, &timing, profile.as_ref()));
    } else {
        print_sentence(&a, &shape, &timing, profile.as_ref());
    }
    Ok(())
}

/// The workload's preset and sizes: the flags, else the workload's defaults.
struct BenchShape {
    preset: String,
    height: usize,
    width: usize,
    iters: usize,
    batch: usize,
}

impl BenchShape {
    fn of(a: &BenchArgs) -> Self {
        let (preset, h, w, iters, batch) = match a.workload {
            BenchWorkload::Monsterpp => ("vits", 256, 512, 12, 1),
            BenchWorkload::Segformer => ("mit-b2", 1000, 1000, 0, 1),
            BenchWorkload::Dinov3 => ("vits16", 224, 224, 0, 2),
            BenchWorkload::TrainStep => ("tiny", 64, 128, 7, 1),
            BenchWorkload::Merge => ("", 0, 0, 0, 1),
        };
        let height = a.height.unwrap_or(h);
        // The square networks take --height alone as their side.
        let square = a.height.is_some() && iters == 0;
        BenchShape {
            preset: a.preset.clone().unwrap_or_else(|| preset.to_string()),
            height,
            width: a.width.unwrap_or(if square { height } else { w }),
            iters: a.iters.unwrap_or(iters),
            batch: a.batch.unwrap_or(batch),
        }
    }

    /// The pass to time, with random weights on `device`.
    fn workload(&self, a: &BenchArgs, device: &Device) -> Result<Workload> {
        let (p, h, w) = (self.preset.as_str(), self.height, self.width);
        match a.workload {
            BenchWorkload::Monsterpp => monster(p, h, w, self.iters, a.max_disp, device),
            BenchWorkload::Segformer => segformer(p, h, device),
            BenchWorkload::Dinov3 => dinov3(p, h, self.batch, device),
            BenchWorkload::TrainStep => step_config(p, h, w, self.batch, self.iters, a.max_disp)
                .and_then(|c| train_step(&c, device)),
            BenchWorkload::Merge => unreachable!("bench merge runs before the networks' shapes"),
        }
        .map_err(|e| anyhow!("{e}"))
    }

    /// `HxW`, the square side twice, or the DINOv3 batch of squares.
    fn label(&self, workload: BenchWorkload) -> String {
        let (b, h, w) = (self.batch, self.height, self.width);
        match workload {
            BenchWorkload::Segformer => format!("{h}x{h}"),
            BenchWorkload::Dinov3 => format!("{b}x{h}x{h}"),
            _ => format!("{h}x{w}"),
        }
    }
}

/// What the timed runs measured, seconds and MiB.
struct Timing {
    warmup: f64,
    times: Vec<f64>,
    median: f64,
    min: f64,
    peak_mib: Option<f64>,
}

/// A profiled run's total time and its module groups, the rest as "other".
type Profile = (f64, Vec<GroupTime>);

/// Seconds of one run of `work`.
fn timed(work: &mut Workload) -> Result<f64> {
    let t = Instant::now();
    work().map_err(|e| anyhow!("{e}"))?;
    Ok(t.elapsed().as_secs_f64())
}

/// One more run with the time of every module group.
fn profiled(work: &mut Workload, device: &Device) -> Result<Profile> {
    let recording =
        Recording::start(device).ok_or_else(|| anyhow!("another profile is already recording"))?;
    let total = timed(work)?;
    let mut groups = recording.finish();
    let covered: f64 = groups.iter().map(|g| g.seconds).sum();
    groups.push(GroupTime {
        group: "other",
        seconds: (total - covered).max(0.0),
        calls: 0,
    });
    Ok((total, groups))
}

/// The workload's name as typed on the command line.
fn workload_name(w: BenchWorkload) -> String {
    w.to_possible_value()
        .map_or_else(String::new, |v| v.get_name().to_string())
}

fn threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// `--json`: one line with every figure.
fn json_line(a: &BenchArgs, s: &BenchShape, t: &Timing, profile: Option<&Profile>) -> String {
    let mut v = serde_json::json!({
        "workload": workload_name(a.workload), "config": s.preset, "shape": s.label(a.workload),
        "iters": s.iters, "max_disp": a.max_disp, "batch": s.batch,
        "device": a.device.device.name(), "threads": threads(), "runs": a.runs,
        "warmup_s": t.warmup, "median_s": t.median, "min_s": t.min, "times_s": t.times,
        "peak_rss_mib": t.peak_mib,
    });
    if let Some((total, groups)) = profile {
        v["profile"] = serde_json::json!({ "total_s": total, "groups": groups });
    }
    v.to_string()
}

/// The sentence, and the profile's table when there is one.
fn print_sentence(a: &BenchArgs, s: &BenchShape, t: &Timing, profile: Option<&Profile>) {
    let iters = if s.iters > 0 {
        format!(", {} iterations", s.iters)
    } else {
        String::new()
    };
    println!(
        "{} {} {}{iters} on {} ({} threads): median {:.3} s, min {:.3} s over {} runs (warm-up \
         {:.3} s), peak RSS {}",
        workload_name(a.workload),
        s.preset,
        s.label(a.workload),
        a.device.device,
        threads(),
        t.median,
        t.min,
        a.runs,
        t.warmup,
        t.peak_mib.map_or("n/a".into(), |m| format!("{m:.0} MiB"))
    );
    if let Some((total, groups)) = profile {
        println!("profiled run {total:.3} s:");
        for g in groups {
            println!(
                "  {:40} {:8.3} s {:5.1} %  ({} calls)",
                g.group,
                g.seconds,
                100.0 * g.seconds / total,
                g.calls
            );
        }
    }
}
