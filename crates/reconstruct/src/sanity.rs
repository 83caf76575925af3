//! Checks of a raw pair before any tile runs: the same image on both sides, RPCs that do not
//! belong to the images, an altitude range that misses the scene. Each error says what is wrong
//! and the likely fix, naming the files once.

use std::path::Path;

use anyhow::{bail, Result};
use camera::RpcModel;

use super::options::ReconstructOptions;
use super::raw::RawImage;
use workflow::outputs::same_file;

/// The side of the central windows compared to tell identical images.
const PROBE: usize = 256;

/// Refuses the same file, or two files with identical pixels, on both sides; and one RPC file
/// given for both cameras.
pub fn check_distinct_images(
    opts: &ReconstructOptions,
    left: &RawImage,
    right: &RawImage,
) -> Result<()> {
    if same_file(&opts.left, &opts.right) {
        bail!(
            "the left and right images are the same file {}: give the two views of a pair",
            opts.left.display()
        );
    }
    if let (Some(a), Some(b)) = (&opts.rpc_left, &opts.rpc_right) {
        if same_file(a, b) || std::fs::read(a).ok() == std::fs::read(b).ok() {
            bail!(
                "--rpc-left and --rpc-right are the same camera ({}): give each image its own \
                 RPC",
                a.display()
            );
        }
    }
    if left.size() == right.size() && left.bands() == right.bands() {
        let (w, h) = left.size();
        let (pw, ph) = (w.min(PROBE), h.min(PROBE));
        let (x0, y0) = ((w - pw) / 2, (h - ph) / 2);
        if let (Ok(a), Ok(b)) = (left.window(x0, y0, pw, ph), right.window(x0, y0, pw, ph)) {
            let same = a
                .data()
                .iter()
                .zip(b.data())
                .all(|(p, q)| p == q || (p.is_nan() && q.is_nan()));
            if same {
                bail!(
                    "the left image {} and the right image {} have identical pixels: give the \
                     two views of a pair",
                    opts.left.display(),
                    opts.right.display()
                );
            }
        }
    }
    Ok(())
}

/// Refuses RPCs that do not see the same place: the centre of the left image, localized at
/// the middle of the altitude range with the left RPC, must project inside the right image with
/// the right RPC (and back).
pub fn check_cameras_overlap(
    opts: &ReconstructOptions,
    (left, right): (&RawImage, &RawImage),
    (rpc_left, rpc_right): (&RpcModel, &RpcModel),
    alt_range: (f64, f64),
) -> Result<()> {
    let alt = 0.5 * (alt_range.0 + alt_range.1);
    let sides = [
        (
            left,
            rpc_left,
            &opts.left,
            right,
            rpc_right,
            &opts.right,
            "--rpc-right",
            &opts.rpc_right,
        ),
        (
            right,
            rpc_right,
            &opts.right,
            left,
            rpc_left,
            &opts.left,
            "--rpc-left",
            &opts.rpc_left,
        ),
    ];
    for (from, from_rpc, from_path, to, to_rpc, to_path, flag, to_rpc_file) in sides {
        let (w, h) = from.size();
        let Ok((lon, lat)) = from_rpc.localization(w as f64 / 2.0, h as f64 / 2.0, alt) else {
            continue;
        };
        let (x, y) = to_rpc.projection(lon, lat, alt);
        let (tw, th) = to.size();
        // A quarter of the image of slack: the overlap of a pair need not hold the centre.
        let (mx, my) = (tw as f64 * 0.25, th as f64 * 0.25);
        let inside = x.is_finite()
            && y.is_finite()
            && (-mx..tw as f64 + mx).contains(&x)
            && (-my..th as f64 + my).contains(&y);
        if !inside {
            let camera = match to_rpc_file {
                Some(p) => format!("{flag} {}", p.display()),
                None => format!("the RPC tag of {}", to_path.display()),
            };
            bail!(
                "the centre of {} (lon {lon:.5}, lat {lat:.5}) falls at pixel ({x:.0}, {y:.0}) \
                 of {} ({tw}x{th} px) through {camera}: is this the RPC of another image? Give \
                 each image its own RPC",
                from_path.display(),
                to_path.display(),
            );
        }
    }
    Ok(())
}

/// Refuses a user's altitude range that does not overlap the one the RPCs' metadata give.
pub fn check_altitude_range(
    user: Option<(f64, f64)>,
    rpc_left: &RpcModel,
    rpc_right: &RpcModel,
) -> Result<()> {
    let Some((lo, hi)) = user else {
        return Ok(());
    };
    let Ok(((mlo, mhi), source)) = crate::rectify::altitude_range(None, rpc_left, rpc_right) else {
        return Ok(());
    };
    if hi < mlo || lo > mhi {
        bail!(
            "--alt-range {lo}:{hi} m misses the scene: the RPCs' metadata ({source}) put it at \
             {mlo:.1}:{mhi:.1} m; no tile would find a match. Use --alt-range {mlo:.0}:{mhi:.0} \
             or leave it out"
        );
    }
    Ok(())
}

/// All the checks of the pair, in order: the altitude range, distinct images, overlapping
/// cameras.
pub fn check_pair(
    opts: &ReconstructOptions,
    images: (&RawImage, &RawImage),
    cameras: (&RpcModel, &RpcModel),
    alt_range: (f64, f64),
) -> Result<()> {
    check_altitude_range(opts.alt_range, cameras.0, cameras.1)?;
    check_distinct_images(opts, images.0, images.1)?;
    check_cameras_overlap(opts, images, cameras, alt_range)
}

/// Refuses a DSM path that is not a GeoTIFF, or a DSM path or a work folder that is one of the
/// run's inputs.
pub fn check_outputs(opts: &ReconstructOptions, work: &Path) -> Result<()> {
    let mut inputs: Vec<&Path> = vec![&opts.left, &opts.right];
    inputs.extend(opts.rpc_left.as_deref());
    inputs.extend(opts.rpc_right.as_deref());
    inputs.extend(opts.truth.as_deref());
    if let crate::dsm::GridChoice::Like(p) = &opts.grid {
        inputs.push(p);
    }
    workflow::outputs::check_output_file("-o", &opts.output, &inputs, true)?;
    workflow::outputs::check_dsm_extension("-o", &opts.output)?;
    workflow::outputs::check_output_folder("--work", work, &inputs, false)
}

/// The error of a run whose tiles all ended without points: nothing to write.
pub fn nothing_produced(records: &[super::tile::TileRecord]) -> workflow::outputs::Incomplete {
    use super::tile::TileStatus;
    let failed: Vec<&super::tile::TileRecord> = records
        .iter()
        .filter(|r| r.status == TileStatus::Failed)
        .collect();
    let empty = records.len() - failed.len();
    let first = failed
        .first()
        .map(|r| {
            format!(
                "; first failure, tile {}: {}",
                r.tile.id,
                r.error.as_deref().unwrap_or("unknown")
            )
        })
        .unwrap_or_default();
    workflow::outputs::Incomplete::Nothing {
        message: format!(
            "no DSM written: none of the {} tiles produced a point ({} failed, {empty} empty: \
             nothing matched; check --alt-range and that each RPC belongs to its image){first}",
            records.len(),
            failed.len()
        ),
    }
}

/// Refuses to assemble a DSM while tiles are failed (a cluster job's merge without
/// `--allow-partial`): exit code 3, naming them and the way to rerun only them.
pub fn check_complete(
    records: &[super::tile::TileRecord],
    work: &std::path::Path,
) -> Result<(), workflow::outputs::Incomplete> {
    use super::tile::TileStatus;
    let failed: Vec<String> = records
        .iter()
        .filter(|r| r.status == TileStatus::Failed)
        .map(|r| r.tile.id.clone())
        .collect();
    if failed.is_empty() {
        return Ok(());
    }
    Err(workflow::outputs::Incomplete::Nothing {
        message: format!(
            "no DSM written: {} of {} tiles failed ({}): see `seasonstereo jobs status --work \
             {}` for their errors and the command that reruns only them, or merge without them \
             with --allow-partial",
            failed.len(),
            records.len(),
            workflow::outputs::first_names(&failed),
            workflow::shell::quote(&work.display().to_string())
        ),
    })
}
