//! `seasonstereo bench`: how fast the networks run here, with random weights: one warm-up run,
//! then N timed runs; the median and the minimum, and the process's peak RSS.

use std::time::Instant;

use anyhow::{anyhow, Result};
use clap::{Args, ValueEnum};

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
}

#[derive(Args)]
#[command(
    after_help = "Examples:\n  seasonstereo bench monsterpp --config vits --height 256 \
    --width 512 --iters 12 --max-disp 192 --runs 3 --json\n  seasonstereo bench segformer \
    --height 1000\n  seasonstereo bench train-step --config vits --height 128 --width 128\n\n\
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
    #[command(flatten)]
    device: DeviceArg,
}

pub fn run(a: BenchArgs) -> Result<()> {
    if a.runs == 0 {
        anyhow::bail!("--runs must be at least 1");
    }
    let device = a.device.device.device().map_err(|e| anyhow!(e))?;
    let (preset, h, w, iters, batch) = match a.workload {
        BenchWorkload::Monsterpp => ("vits", 256, 512, 12, 1),
        BenchWorkload::Segformer => ("mit-b2", 1000, 1000, 0, 1),
        BenchWorkload::Dinov3 => ("vits16", 224, 224, 0, 2),
        BenchWorkload::TrainStep => ("tiny", 64, 128, 7, 1),
    };
    let preset = a.preset.clone().unwrap_or_else(|| preset.to_string());
    let h = a.height.unwrap_or(h);
    let w = a.width.unwrap_or(if a.height.is_some() && iters == 0 {
        h
    } else {
        w
    });
    let iters = a.iters.unwrap_or(iters);
    let batch = a.batch.unwrap_or(batch);
    let mut work = match a.workload {
        BenchWorkload::Monsterpp => nn::bench::monster(&preset, h, w, iters, a.max_disp, &device),
        BenchWorkload::Segformer => nn::bench::segformer(&preset, h, &device),
        BenchWorkload::Dinov3 => nn::bench::dinov3(&preset, h, batch, &device),
        BenchWorkload::TrainStep => {
            train::bench::step_config(&preset, h, w, batch, iters, a.max_disp)
                .and_then(|c| train::bench::train_step(&c, &device))
        }
    }
    .map_err(|e| anyhow!("{e}"))?;
    let timed = |work: &mut nn::bench::Workload| -> Result<f64> {
        let t = Instant::now();
        work().map_err(|e| anyhow!("{e}"))?;
        Ok(t.elapsed().as_secs_f64())
    };
    let warmup = timed(&mut work)?;
    let times = (0..a.runs)
        .map(|_| timed(&mut work))
        .collect::<Result<Vec<f64>>>()?;
    let profile = if a.profile {
        let recording = nn::profile::Recording::start(&device)
            .ok_or_else(|| anyhow!("another profile is already recording"))?;
        let total = timed(&mut work)?;
        Some((total, recording.finish()))
    } else {
        None
    };
    let median = pipeline::eval::aggregate::median(&times).expect("at least one run");
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    let peak = train::metrics::peak_rss_bytes().map(|b| b as f64 / (1u64 << 20) as f64);
    let name = a
        .workload
        .to_possible_value()
        .map_or_else(String::new, |v| v.get_name().to_string());
    let shape = match a.workload {
        BenchWorkload::Segformer => format!("{h}x{h}"),
        BenchWorkload::Dinov3 => format!("{batch}x{h}x{h}"),
        _ => format!("{h}x{w}"),
    };
    let profile = profile.map(|(total, mut groups)| {
        let covered: f64 = groups.iter().map(|g| g.seconds).sum();
        groups.push(nn::profile::GroupTime {
            group: "other",
            seconds: (total - covered).max(0.0),
            calls: 0,
        });
        (total, groups)
    });
    if a.json {
        let mut v = serde_json::json!({
            "workload": name, "config": preset, "shape": shape, "iters": iters,
            "max_disp": a.max_disp, "batch": batch, "device": a.device.device.name(),
            "threads": std::thread::available_parallelism().map_or(1, |n| n.get()), "runs": a.runs, "warmup_s": warmup,
            "median_s": median, "min_s": min, "times_s": times, "peak_rss_mib": peak,
        });
        if let Some((total, groups)) = &profile {
            v["profile"] = serde_json::json!({ "total_s": total, "groups": groups });
        }
        println!("{v}");
    } else {
        println!(
            "{name} {preset} {shape}{} on {} ({} threads): median {median:.3} s, min {min:.3} s \
             over {} runs (warm-up {warmup:.3} s), peak RSS {}",
            if iters > 0 {
                format!(", {iters} iterations")
            } else {
                String::new()
            },
            a.device.device,
            std::thread::available_parallelism().map_or(1, |n| n.get()),
            a.runs,
            peak.map_or("n/a".into(), |m| format!("{m:.0} MiB"))
        );
        if let Some((total, groups)) = &profile {
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
    Ok(())
}
