//! `seasonstereo score`: the benchmark's metric on any DSM against a ground truth.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use seasonstereo::{read_truth, score, DsmScores};

/// One line with the benchmark's scores.
pub fn format_scores(s: &DsmScores) -> String {
    let m = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.3} m"));
    format!(
        "MAE filtered {} (raw {}, no water {}), coverage {}, shift {},{} cells, offset {}",
        m(s.mae_filtered),
        m(s.mae_raw),
        m(s.mae_no_water),
        s.coverage
            .map_or("-".into(), |c| format!("{:.1} %", 100.0 * c)),
        s.dx,
        s.dy,
        s.offset.map_or("-".into(), |o| format!("{o:+.3} m"))
    )
}

#[derive(Args)]
#[command(
    after_help = "The benchmark's metric on any DSM already on the truth's grid (e.g. \
    from `reconstruct --like`, `dsm --like`, or s2p): integer (dx, dy) shift within ±5 cells \
    maximising NCC, vertical offset b = mean(truth) − mean(DSM), MAE over cells where both exist \
    (filtered: without foliage 5 and water 9 of <AOI>_CLS.tif), coverage = share of truth cells \
    with a value."
)]
pub struct ScoreArgs {
    /// DSMs to score (GeoTIFF on the truth's grid).
    #[arg(required = true)]
    dsm: Vec<PathBuf>,
    /// Ground truth <AOI>_DSM.tif (GeoTIFF, or DFC2019 plain TIFF + <AOI>_DSM.txt); its
    /// <AOI>_CLS.tif (and optional <AOI>_WATER.png) beside it.
    #[arg(long, value_name = "DSM")]
    truth: PathBuf,
    /// UTM zone of a DFC2019 truth's .txt georeference, e.g. 17N (Jacksonville), 15N (Omaha),
    /// 21S (Buenos Aires). Default: the zone of the first DSM scored (its GeoTIFF EPSG code).
    #[arg(long, value_name = "ZONE", value_parser = parse_zone)]
    utm_zone: Option<camera::UtmZone>,
    /// Write the scores as JSON lines to this file too.
    #[arg(long)]
    json: Option<PathBuf>,
}

fn parse_zone(s: &str) -> Result<camera::UtmZone, String> {
    let t = s.trim().to_ascii_uppercase();
    let (num, hemi) = t.split_at(t.len().saturating_sub(1));
    let north = match hemi {
        "N" => true,
        "S" => false,
        _ => return Err(format!("expected a zone like 17N or 21S, got {s:?}")),
    };
    let zone: u8 = num
        .parse()
        .map_err(|e| format!("zone number in {s:?}: {e}"))?;
    camera::UtmZone::new(zone, north).map_err(|e| e.to_string())
}

/// The truth's UTM zone: `--utm-zone`, else the first DSM's.
fn utm_zone(a: &ScoreArgs) -> Result<camera::UtmZone> {
    if let Some(z) = a.utm_zone {
        return Ok(z);
    }
    let dsm = &a.dsm[0];
    if !dsm.is_file() {
        bail!("{}: no such file", dsm.display());
    }
    let grid = camera::DsmGrid::read(dsm, None).with_context(|| {
        format!(
            "{}: cannot take the UTM zone from this DSM; give --utm-zone",
            dsm.display()
        )
    })?;
    Ok(grid.zone())
}

pub fn run(a: ScoreArgs) -> Result<()> {
    if let Some(j) = &a.json {
        let inputs: Vec<&std::path::Path> = a
            .dsm
            .iter()
            .map(|p| p.as_path())
            .chain([a.truth.as_path()])
            .collect();
        crate::exit::guard_output("--json", j, &inputs)?;
    }
    let zone = utm_zone(&a)?;
    let truth = read_truth(&a.truth, zone)?;
    let mut lines = String::new();
    for path in &a.dsm {
        let s = score(path, &truth)?;
        println!("{}: {}", path.display(), format_scores(&s));
        let mut v = serde_json::to_value(&s)?;
        v["dsm"] = serde_json::Value::String(path.display().to_string());
        lines.push_str(&v.to_string());
        lines.push('\n');
    }
    if let Some(j) = &a.json {
        pipeline::stage::write_text(j, &lines)?;
    }
    Ok(())
}
