//! `seasonstereo score`: the benchmark's metric on any DSM against a ground truth.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;
use seasonstereo::outputs::write_text;
use seasonstereo::{
    flags, read_truth, score, score_against, truth_zone, CellsMae, DsmGrid, DsmScores, Truth,
    UtmZone, Versus,
};

/// A share as a percentage, `-` when undefined.
fn percent(v: Option<f64>) -> String {
    v.map_or("-".into(), |c| format!("{:.1} %", 100.0 * c))
}

/// Metres, `-` when undefined.
fn metres(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.3} m"))
}

/// One line with the benchmark's scores.
pub fn format_scores(s: &DsmScores) -> String {
    format!(
        "MAE filtered {} (raw {}, no water {}), coverage {}, shift {},{} cells, offset {}, \
         within 1 m {}, within 2 m {}",
        metres(s.mae_filtered),
        metres(s.mae_raw),
        metres(s.mae_no_water),
        percent(s.coverage),
        s.dx,
        s.dy,
        s.offset.map_or("-".into(), |o| format!("{o:+.3} m")),
        percent(s.within_1m),
        percent(s.within_2m),
    )
}

/// The comparison's line: both MAEs on the common cells, then each one's own cells.
fn format_versus(v: &Versus) -> String {
    let own = |c: &CellsMae| format!("{} over {} cells", metres(c.mae), c.cells);
    format!(
        "common cells {}: ours {}, other {}; only ours: {}; only other: {}; neither: {} cells",
        v.common_ours.cells,
        metres(v.common_ours.mae),
        metres(v.common_other.mae),
        own(&v.only_ours),
        own(&v.only_other),
        v.neither
    )
}

#[derive(Args)]
#[command(
    after_help = "The benchmark's metric on any georeferenced DSM (e.g. from `reconstruct \
    --like`, `dsm --like`, or s2p on its own grid). A DSM on another window, cell size or UTM \
    zone is first cut onto the truth's grid as the benchmark crops it (the nearest cell to each \
    truth cell's centre, NaN outside; the log says so). Then: integer (dx, dy) shift within ±5 cells \
    maximising NCC, vertical offset b = mean(truth) − mean(DSM), MAE over cells where both exist \
    (filtered: without foliage 5 and water 9 of <AOI>_CLS.tif), coverage = share of truth cells \
    with a value, within 1 m / 2 m = share of the truth cells outside foliage and water whose \
    registered height is within 1 m / 2 m (a missing cell is a miss: the figure rewards \
    coverage and accuracy at once).\n\n\
    With --against OTHER each DSM and OTHER (e.g. s2p's DSM) are \
    registered on their own, then compared cell by cell: the MAE of each on the truth cells \
    both cover (the fair ranking), the MAE of the cells only one covers, and the cells neither \
    covers."
)]
pub struct ScoreArgs {
    /// DSMs to score (GeoTIFF, on the truth's grid or cut onto it).
    #[arg(required = true)]
    dsm: Vec<PathBuf>,
    /// Ground truth <AOI>_DSM.tif (GeoTIFF, or DFC2019 plain TIFF + <AOI>_DSM.txt); its
    /// <AOI>_CLS.tif (and optional <AOI>_WATER.png) beside it.
    #[arg(long, value_name = "DSM")]
    truth: PathBuf,
    /// UTM zone of a DFC2019 truth's .txt georeference, e.g. 17N (Jacksonville), 15N (Omaha),
    /// 21S (Buenos Aires). Default: the zone of the first DSM scored (its GeoTIFF EPSG code).
    #[arg(long, value_name = "ZONE", value_parser = flags::utm_zone)]
    utm_zone: Option<UtmZone>,
    /// Compare each DSM with this one (another method's DSM, cut onto the truth's grid) on the cells
    /// both cover and on those only one covers.
    #[arg(long, value_name = "DSM")]
    against: Option<PathBuf>,
    /// Write the scores as JSON lines to this file too (with --against, one comparison per
    /// line: `ours`, `other`, `common_ours`, `common_other`, `only_ours`, `only_other`,
    /// `neither`).
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
    let zone = truth_zone(&a.dsm[0], a.utm_zone)?;
    let truth = read_truth(&a.truth, zone)?;
    let mut lines = String::new();
    for path in &a.dsm {
        let mut v = match &a.against {
            Some(other) => score_one_against(path, other, &truth)?,
            None => score_one(path, &truth)?,
        };
        v["dsm"] = serde_json::Value::String(path.display().to_string());
        lines.push_str(&v.to_string());
        lines.push('\n');
    }
    if let Some(j) = &a.json {
        write_text(j, &lines)?;
    }
    Ok(())
}

/// Says when the DSM at `path` is not on the truth's grid and is cut onto it, so that no one
/// takes its scores for those of a DSM made on that grid. (A DSM that cannot be read is
/// reported by the scoring itself.)
fn note_cut(path: &Path, truth: &Truth) {
    let Ok(grid) = DsmGrid::read(path, truth.grid.zone()) else {
        return;
    };
    if grid != truth.grid {
        eprintln!(
            "{}: on its own grid ({grid} from {:.2}, {:.2}); cut onto the truth's grid \
             (nearest cell, NaN outside)",
            path.display(),
            grid.x0,
            grid.y0,
        );
    }
}

/// Prints one DSM's scores; its JSON record.
fn score_one(path: &Path, truth: &Truth) -> Result<serde_json::Value> {
    note_cut(path, truth);
    let s = score(path, truth)?;
    println!("{}: {}", path.display(), format_scores(&s));
    Ok(serde_json::to_value(&s)?)
}

/// Prints a DSM's and the other's scores and their comparison; the comparison's JSON record.
fn score_one_against(path: &Path, other: &Path, truth: &Truth) -> Result<serde_json::Value> {
    note_cut(path, truth);
    note_cut(other, truth);
    let v = score_against(path, other, truth)?;
    println!("{}: {}", path.display(), format_scores(&v.ours));
    println!("{}: {}", other.display(), format_scores(&v.other));
    println!(
        "{} vs {}: {}",
        path.display(),
        other.display(),
        format_versus(&v)
    );
    let mut j = serde_json::to_value(&v)?;
    j["against"] = serde_json::Value::String(other.display().to_string());
    Ok(j)
}
