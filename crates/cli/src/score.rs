//! `seasonstereo score`: the benchmark's metric on any DSM against a ground truth.

use std::path::PathBuf;

use anyhow::Result;
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
    #[arg(long, value_name = "ZONE", value_parser = pipeline::flags::utm_zone)]
    utm_zone: Option<camera::UtmZone>,
    /// Write the scores as JSON lines to this file too.
    #[arg(long)]
    json: Option<PathBuf>,
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
    let zone = pipeline::score::truth_zone(&a.dsm[0], a.utm_zone)?;
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
