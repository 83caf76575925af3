//! Scoring a DSM file against a ground truth with the benchmark's metric (registration by an
//! integer NCC shift and a vertical offset, foliage and water masked), whoever made the DSM:
//! `seasonstereo reconstruct`, `dsm`, or another tool such as s2p, on the truth's grid or cut
//! onto it as the benchmark crops any georeferenced DSM; and
//! two DSMs against each other on the cells both cover ([`score_versus_files`]).

use std::path::Path;

use anyhow::{bail, Context, Result};
use camera::{DsmRaster, UtmZone};

use crate::layout::TruthFiles;
use crate::metrics::{score_dsm, DsmScores};
use crate::versus::{score_versus, Versus};
use crate::Truth;

/// The UTM zone of a truth without its own (a DFC2019 plain TIFF + `.txt`): `zone` when given,
/// else that of the DSM to score (its GeoTIFF EPSG code, or its centre's zone in another CRS).
pub fn truth_zone(dsm: &Path, zone: Option<UtmZone>) -> Result<UtmZone> {
    if let Some(z) = zone {
        return Ok(z);
    }
    if !dsm.is_file() {
        let missing = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        return Err(anyhow::Error::new(missing).context(dsm.display().to_string()));
    }
    let grid = camera::DsmGrid::read(dsm, None).with_context(|| {
        format!(
            "{}: cannot take the UTM zone from this DSM; give --utm-zone",
            dsm.display()
        )
    })?;
    Ok(grid.nearest_zone())
}

/// The truth of a `<AOI>_DSM.tif` path: the DSM, and the `<AOI>_CLS.tif` and `<AOI>_WATER.png`
/// beside it. `zone` is used when the DSM is a DFC2019 plain TIFF with a `.txt` georeference.
pub fn read_truth(dsm: &Path, zone: UtmZone) -> Result<Truth> {
    let name = dsm
        .file_name()
        .and_then(|n| n.to_str())
        .with_context(|| format!("{}: not a file name", dsm.display()))?;
    let Some(aoi) = name
        .strip_suffix("_DSM.tif")
        .or_else(|| name.strip_suffix("_DSM.tiff"))
    else {
        bail!(
            "{}: a ground-truth DSM is named <AOI>_DSM.tif (its classes <AOI>_CLS.tif beside it)",
            dsm.display()
        );
    };
    let dir = dsm.parent().unwrap_or(Path::new("."));
    let mut files = TruthFiles::new(dir, aoi);
    files.dsm = dsm.to_path_buf();
    Truth::read(&files, aoi, zone)
}

/// Scores the DSM at `path` (on the truth's grid or cut onto it) against `truth`.
pub fn score_dsm_file(path: &Path, truth: &Truth) -> Result<DsmScores> {
    let image = read_on_truth_grid(path, truth)?;
    score_dsm(&image, &truth.dsm, &truth.exclusions, &Default::default())
        .with_context(|| format!("scoring {}", path.display()))
}

/// Scores the DSMs at `ours` and `other` (each on the truth's grid or cut onto it) against
/// `truth`, each registered on its own, and compares them on the cells both cover and on those
/// only one covers ([`crate::versus`]).
pub fn score_versus_files(ours: &Path, other: &Path, truth: &Truth) -> Result<Versus> {
    let a = read_on_truth_grid(ours, truth)?;
    let b = read_on_truth_grid(other, truth)?;
    score_versus(&a, &b, &truth.dsm, &truth.exclusions, &Default::default())
        .with_context(|| format!("scoring {} against {}", ours.display(), other.display()))
}

/// The heights of the DSM at `path` on the truth's grid: as they are when the DSM lies on it,
/// else cut onto it as the benchmark crops any georeferenced DSM onto the truth's window
/// ([`camera::resample_nearest`]: the nearest cell, NaN outside; a resampling for another cell
/// size or CRS). A DSM that covers none of the truth is an error.
pub fn read_on_truth_grid(path: &Path, truth: &Truth) -> Result<raster::Image> {
    let DsmRaster { image, grid, .. } = camera::read_dsm(path, truth.grid.zone())
        .with_context(|| format!("reading the DSM {}", path.display()))?;
    if grid == truth.grid {
        return Ok(image);
    }
    let cut = camera::resample_nearest(&image, &grid, &truth.grid);
    if !cut.data().iter().any(|v| v.is_finite()) {
        bail!(
            "{}: the DSM has no height inside the ground truth's area ({grid} from {:.2}, \
             {:.2}; the truth's {} from {:.2}, {:.2}): is it of another area, or in another \
             CRS than its tags say?",
            path.display(),
            grid.x0,
            grid.y0,
            truth.grid,
            truth.grid.x0,
            truth.grid.y0,
        );
    }
    Ok(cut)
}
