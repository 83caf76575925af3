//! Rectification of a raw satellite pair from its RPC cameras, written in the public release's
//! layout:
//!
//! ```text
//! L/<stem>.iio  R/<stem>.iio     rectified images, NPY float32 (H, W, C), NaN outside the raw images
//! homography/<stem>.npz          Hleft, Hright (raw → rectified, any left/right flip included)
//! rectify/<stem>.json            the pair, region, altitude and disparity ranges, sizes, accuracy
//! ```
//!
//! The cameras come from the GeoTIFF RPC tag (50844) or from SatNeRF/rpcm JSON files; the
//! disparity search range to give `seasonstereo predict --range` comes from the cameras and an
//! altitude range (the user's, else `min_alt`/`max_alt` of the JSON, else the RPCs' altitude
//! offset ± scale), never from image matches.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use camera::rectify::{rectify_pair, Rectification, Roi};
use camera::RpcModel;
use raster::formats::{write_homographies, write_npy};
use raster::Image;

use crate::raw::RawImage;
use workflow::pairs::{PairFolder, PairPaths, RectifiedFiles, RectifyRecord};
use workflow::progress::{track, Progress};
use workflow::stage::write_json;

/// What to rectify and where.
#[derive(Clone, Debug)]
pub struct RectifyOptions {
    /// Left raw image: a GeoTIFF with the RPC tag, or any raster with `rpc_left`.
    pub left: PathBuf,
    /// Right raw image.
    pub right: PathBuf,
    /// Output folder (L/, R/, homography/, rectify/).
    pub out_dir: PathBuf,
    /// Region of interest of the left raw image; the whole image when `None`.
    pub roi: Option<Roi>,
    /// SatNeRF/rpcm JSON of the left camera (instead of the TIFF tag).
    pub rpc_left: Option<PathBuf>,
    /// SatNeRF/rpcm JSON of the right camera.
    pub rpc_right: Option<PathBuf>,
    /// Altitude range of the scene, metres.
    pub alt_range: Option<(f64, f64)>,
    /// Pair name; `<LEFT file stem>-<RIGHT file stem>` when `None`.
    pub stem: Option<String>,
}

impl RectifyOptions {
    /// Refuses an output folder that is one of the inputs or cannot be written (its files are
    /// the work of this pair, replaced by a rerun): the rule of every caller, before any work.
    pub fn check_output(&self) -> Result<()> {
        let inputs = [
            Some(&self.left),
            Some(&self.right),
            self.rpc_left.as_ref(),
            self.rpc_right.as_ref(),
        ];
        let inputs: Vec<&Path> = inputs.into_iter().flatten().map(|p| p.as_path()).collect();
        workflow::outputs::check_output_folder("-o", &self.out_dir, &inputs, false)
    }
}

/// What [`rectify`] wrote and found.
#[derive(Clone, Debug)]
pub struct RectifySummary {
    pub stem: String,
    pub left: PathBuf,
    pub right: PathBuf,
    pub homography: PathBuf,
    pub report: PathBuf,
    pub roi: Roi,
    /// Altitude range used, metres, and where it came from.
    pub alt_range: (f64, f64),
    pub alt_source: &'static str,
    /// Inclusive disparity search range for `predict --range`.
    pub disparity_range: (i32, i32),
    /// `(width, height)` of the rectified images.
    pub size: (usize, usize),
    /// Largest row misalignment of the cameras' virtual matches, pixels.
    pub max_row_error: f64,
    /// Disparity per metre of altitude, pixels.
    pub pixels_per_metre: f64,
    /// Fraction of the region of interest's rectified box that the right image covers.
    pub right_coverage: f64,
}

/// A raw image: its pixels (nodata → NaN) and the RPC of its TIFF tag when there is one.
fn read_raw(path: &Path, which: &str) -> Result<(Image, Option<RpcModel>)> {
    let raw = RawImage::open(path, which)?;
    let (w, h) = raw.size();
    let image = raw
        .window(0, 0, w, h)
        .with_context(|| format!("reading the {which} image {}", path.display()))?;
    Ok((image, raw.rpc))
}

/// The camera of one view: the given camera file when there is one (a SatNeRF/rpcm JSON, a
/// vendor `.RPB`, `_RPC.TXT` or DIMAP `RPC_*.XML`, or a GeoTIFF carrying the RPC tag, e.g. the
/// original image beside a resampled one), else the vendor sidecar found beside the image as
/// GDAL finds it, else the image's own RPC tag.
pub(crate) fn camera_of(
    image_path: &Path,
    tag: Option<RpcModel>,
    camera: Option<&Path>,
    which: &str,
) -> Result<RpcModel> {
    if let Some(path) = camera {
        return crate::dsm::read_camera(path).with_context(|| format!("the {which} camera"));
    }
    if camera::find_camera_file(image_path).is_some() || tag.is_none() {
        if let Some((rpc, _)) = camera::camera_beside(image_path)
            .with_context(|| format!("the {which} camera, found beside its image"))?
        {
            return Ok(rpc);
        }
    }
    match tag {
        Some(rpc) => Ok(rpc),
        None => bail!(
            "{}: no RPC camera: the image has no RPC tag 50844 and no sidecar beside it \
             (<name>.RPB, <name>_RPC.TXT, or a DIMAP RPC_<name>.XML); put the vendor's camera \
             file there, or {}",
            image_path.display(),
            match which {
                "left" | "right" => format!("pass --rpc-{which} with it (or a SatNeRF/rpcm JSON)"),
                _ =>
                    "pass --rpc-dir, a folder holding <image stem>.json (SatNeRF/rpcm JSON)".into(),
            }
        ),
    }
}

/// The altitude range the user or the cameras give: the user's, else the union of the JSONs'
/// `min_alt`/`max_alt`; `None` when neither does.
pub(crate) fn given_altitude_range(
    user: Option<(f64, f64)>,
    left: &RpcModel,
    right: &RpcModel,
) -> Result<Option<((f64, f64), &'static str)>> {
    if let Some((lo, hi)) = user {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            bail!("the altitude range must satisfy MIN < MAX, got {lo}:{hi}");
        }
        return Ok(Some(((lo, hi), "user")));
    }
    let lo = [left.min_alt, right.min_alt].into_iter().flatten();
    let hi = [left.max_alt, right.max_alt].into_iter().flatten();
    if let (Some(lo), Some(hi)) = (lo.reduce(f64::min), hi.reduce(f64::max)) {
        if lo < hi {
            return Ok(Some(((lo, hi), "min_alt/max_alt of the RPC JSON")));
        }
    }
    Ok(None)
}

/// The altitude range: the user's, else the union of the JSONs' `min_alt`/`max_alt`, else the
/// intersection of the RPCs' validity ranges (offset ± scale, usually far wider than the scene).
pub(crate) fn altitude_range(
    user: Option<(f64, f64)>,
    left: &RpcModel,
    right: &RpcModel,
) -> Result<((f64, f64), &'static str)> {
    if let Some(given) = given_altitude_range(user, left, right)? {
        return Ok(given);
    }
    let (l, r) = (left.altitude_range(), right.altitude_range());
    let (lo, hi) = (l.0.max(r.0), l.1.min(r.1));
    if lo.is_nan() || hi.is_nan() || lo >= hi {
        bail!(
            "the two RPCs' altitude ranges ({:.1}…{:.1} m and {:.1}…{:.1} m) do not overlap: give \
             the scene's altitudes with --alt-range MIN:MAX",
            l.0,
            l.1,
            r.0,
            r.1
        );
    }
    Ok(((lo, hi), "RPC altitude offset ± scale"))
}

/// The file name of `path` without its extension.
pub(crate) fn file_stem(path: &Path) -> Result<String> {
    path.file_stem()
        .and_then(|s| s.to_str())
        .map(str::to_owned)
        .with_context(|| format!("{}: cannot name the pair after this path", path.display()))
}

/// Fraction of the region of interest's rectified box that the rectified right image covers.
pub(crate) fn right_coverage(right: &Image, rect: &Rectification) -> f64 {
    let (rx, ry, rw, rh) = rect.roi_in_frame;
    let mut covered = 0usize;
    for y in ry..(ry + rh).min(rect.size.1) {
        for x in rx..(rx + rw).min(rect.size.0) {
            covered += !right.get(x, y, 0).is_nan() as usize;
        }
    }
    covered as f64 / (rw * rh).max(1) as f64
}

/// The raw inputs of a rectification, as recorded.
pub(crate) struct RawInputs<'a> {
    pub stem: &'a str,
    pub left: &'a Path,
    pub right: &'a Path,
    pub rpc_left: Option<&'a Path>,
    pub rpc_right: Option<&'a Path>,
    pub roi: Roi,
    pub alt_range: (f64, f64),
    pub alt_source: &'a str,
}

/// The record of a rectified pair (`<stem>.json` beside it): where it came from and how it
/// was rectified.
pub(crate) fn rectify_record(
    raw: &RawInputs,
    rect: &Rectification,
    right_coverage: f64,
    files: &PairPaths,
) -> RectifyRecord {
    let (x, y, width, height) = rect.roi_in_frame;
    RectifyRecord {
        stem: raw.stem.to_string(),
        left: raw.left.to_path_buf(),
        right: raw.right.to_path_buf(),
        rpc_left: raw.rpc_left.map(Path::to_path_buf),
        rpc_right: raw.rpc_right.map(Path::to_path_buf),
        roi: raw.roi,
        alt_range: raw.alt_range,
        alt_source: raw.alt_source.to_string(),
        disparity_range: rect.disparity_range,
        size: rect.size,
        roi_in_frame: Roi::new(x, y, width, height),
        flipped: rect.flipped,
        pixels_per_metre: rect.pixels_per_metre,
        max_row_error_px: rect.max_row_error,
        right_coverage,
        h_left: rect.h_left.0,
        h_right: rect.h_right.0,
        files: RectifiedFiles {
            left: files.left.clone(),
            right: files.right.clone(),
            homography: files.homography.clone(),
        },
    }
}

/// Rectifies a raw pair from its cameras and writes `L/<stem>.iio`, `R/<stem>.iio`,
/// `homography/<stem>.npz` and `rectify/<stem>.json` under `opts.out_dir` (every file written
/// atomically).
pub fn rectify(opts: &RectifyOptions, progress: &dyn Progress) -> Result<RectifySummary> {
    let stem = match &opts.stem {
        Some(s) => s.clone(),
        None => format!("{}-{}", file_stem(&opts.left)?, file_stem(&opts.right)?),
    };
    if stem.is_empty() || stem.contains(['/', '\\']) {
        bail!("the pair name {stem:?} must be a non-empty file name");
    }
    let (left, tag_l) = read_raw(&opts.left, "left")?;
    let (right, tag_r) = read_raw(&opts.right, "right")?;
    let rpc_l = camera_of(&opts.left, tag_l, opts.rpc_left.as_deref(), "left")?;
    let rpc_r = camera_of(&opts.right, tag_r, opts.rpc_right.as_deref(), "right")?;
    let (alt_range, alt_source) = altitude_range(opts.alt_range, &rpc_l, &rpc_r)?;
    let roi = opts
        .roi
        .unwrap_or_else(|| Roi::full(left.width(), left.height()));
    roi.check_inside(left.width(), left.height())
        .with_context(|| format!("the region of interest of {}", opts.left.display()))?;

    let pair = track(progress, "rectifying", 1, |cb| {
        let r = rectify_pair(&left, &right, &rpc_l, &rpc_r, roi, alt_range);
        cb(1, 1);
        r
    })
    .with_context(|| {
        format!(
            "rectifying {} and {}",
            opts.left.display(),
            opts.right.display()
        )
    })?;
    let rect = &pair.rectification;

    let right_coverage = right_coverage(&pair.right, rect);

    let folder = PairFolder::new(&opts.out_dir);
    let files = folder.paths(&stem);
    let report = folder.rectify_record_path(&stem);
    write_npy(&files.left, &pair.left)?;
    write_npy(&files.right, &pair.right)?;
    write_homographies(&files.homography, &pair.h_left, &pair.h_right)?;
    let raw = RawInputs {
        stem: &stem,
        left: &opts.left,
        right: &opts.right,
        rpc_left: opts.rpc_left.as_deref(),
        rpc_right: opts.rpc_right.as_deref(),
        roi,
        alt_range,
        alt_source,
    };
    write_json(&report, &rectify_record(&raw, rect, right_coverage, &files))?;
    let PairPaths {
        left: left_path,
        right: right_path,
        homography,
        ..
    } = files;
    Ok(RectifySummary {
        stem,
        left: left_path,
        right: right_path,
        homography,
        report,
        roi,
        alt_range,
        alt_source,
        disparity_range: pair.disparity_range,
        size: pair.size,
        max_row_error: rect.max_row_error,
        pixels_per_metre: rect.pixels_per_metre,
        right_coverage,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use raster::geometry::warp_homography;
    use workflow::Silent;

    /// A procedural world's rectified pair "un-rectified" into raw images, with its RPC JSONs.
    fn raw_world(dir: &Path) -> (PathBuf, PathBuf, PathBuf, PathBuf, world::World) {
        let world = world::generate(
            &world::WorldParams::new(160, 3),
            &world::Neutral,
            &|_, _| {},
        )
        .unwrap();
        let root = dir.join("world");
        eval::world_io::save_world(&world, &root, "W3").unwrap();
        let unrect = |img: &Image, h: &raster::Homography| {
            let (raw, mask) = warp_homography(img, &h.inverse().unwrap(), 200, 200).unwrap();
            let mut raw = raw;
            let c = raw.channels();
            for (px, &v) in raw.data_mut().chunks_exact_mut(c).zip(mask.data()) {
                if !v {
                    px.fill(f32::NAN);
                }
            }
            raw
        };
        let (l, r) = (dir.join("W3_A.tif"), dir.join("W3_B.tif"));
        raster::write_image(&l, &unrect(&world.left.image, &world.rectify_left)).unwrap();
        raster::write_image(&r, &unrect(&world.right.image, &world.rectify_right)).unwrap();
        (
            l,
            r,
            root.join("rpc/W3_A.json"),
            root.join("rpc/W3_B.json"),
            world,
        )
    }

    #[test]
    fn rectifies_a_raw_world_pair_from_its_json_cameras() {
        let dir = tempfile::tempdir().unwrap();
        let (l, r, jl, jr, world) = raw_world(dir.path());
        let out = dir.path().join("out");
        let opts = RectifyOptions {
            left: l.clone(),
            right: r.clone(),
            out_dir: out.clone(),
            roi: Some(Roi::new(20, 20, 120, 120)),
            rpc_left: Some(jl),
            rpc_right: Some(jr),
            alt_range: None,
            stem: None,
        };
        let s = rectify(&opts, &Silent).unwrap();
        assert_eq!(s.stem, "W3_A-W3_B");
        assert_eq!(s.alt_source, "min_alt/max_alt of the RPC JSON");
        assert!(s.max_row_error < 1e-6, "{}", s.max_row_error);
        assert!(s.right_coverage > 0.5, "{}", s.right_coverage);
        let lr = raster::read_image(&s.left).unwrap();
        assert_eq!(lr.size(), s.size);
        assert_eq!(raster::read_image(&s.right).unwrap().size(), s.size);
        let (hl, hr) = raster::formats::read_homographies(&s.homography).unwrap();
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&s.report).unwrap()).unwrap();
        assert_eq!(report["disparity_range"][0], s.disparity_range.0);
        assert_eq!(report["roi"]["width"], 120);

        // The world's true matches land on one row of the new frame, inside the range, with a
        // disparity that grows with the world's height.
        let (wl, wr) = (
            world.rectify_left.inverse().unwrap(),
            world.rectify_right.inverse().unwrap(),
        );
        let (lo, hi) = s.disparity_range;
        let mut seen = 0;
        for y in (0..160).step_by(7) {
            for x in (0..160).step_by(7) {
                let d = world.disparity.get(x, y, 0) as f64;
                let (xl, yl) = wl.apply(x as f64, y as f64);
                let (xr, yr) = wr.apply(x as f64 - d, y as f64);
                if !(20.0..140.0).contains(&xl) || !(20.0..140.0).contains(&yl) {
                    continue;
                }
                let (pl, pr) = (hl.apply(xl, yl), hr.apply(xr, yr));
                assert!((pl.1 - pr.1).abs() < 1e-6, "rows {} {}", pl.1, pr.1);
                let dd = pl.0 - pr.0;
                assert!(dd >= lo as f64 && dd <= hi as f64, "{dd} not in {lo}..{hi}");
                seen += 1;
            }
        }
        assert!(seen > 100);

        // Idempotent: a rerun gives the same files.
        let again = rectify(&opts, &Silent).unwrap();
        assert_eq!(again.disparity_range, s.disparity_range);
        assert_eq!(
            raster::formats::read_homographies(&again.homography).unwrap(),
            (hl, hr)
        );
    }

    #[test]
    fn errors_name_the_file_and_the_fix() {
        let dir = tempfile::tempdir().unwrap();
        let (l, r, jl, jr, _) = raw_world(dir.path());
        let base = RectifyOptions {
            left: l.clone(),
            right: r.clone(),
            out_dir: dir.path().join("out"),
            roi: None,
            rpc_left: None,
            rpc_right: Some(jr.clone()),
            alt_range: None,
            stem: Some("P".into()),
        };
        let msg = format!("{:#}", rectify(&base, &Silent).unwrap_err());
        assert!(
            msg.contains("W3_A.tif") && msg.contains("--rpc-left"),
            "{msg}"
        );

        let missing = RectifyOptions {
            rpc_left: Some(dir.path().join("nope.json")),
            ..base.clone()
        };
        let msg = format!("{:#}", rectify(&missing, &Silent).unwrap_err());
        assert!(msg.contains("nope.json"), "{msg}");

        let roi = RectifyOptions {
            rpc_left: Some(jl.clone()),
            roi: Some(Roi::new(150, 0, 100, 100)),
            ..base.clone()
        };
        let msg = format!("{:#}", rectify(&roi, &Silent).unwrap_err());
        assert!(
            msg.contains("does not fit") && msg.contains("W3_A.tif"),
            "{msg}"
        );

        let alt = RectifyOptions {
            rpc_left: Some(jl),
            alt_range: Some((5.0, 5.0)),
            ..base.clone()
        };
        let msg = format!("{:#}", rectify(&alt, &Silent).unwrap_err());
        assert!(msg.contains("MIN < MAX"), "{msg}");

        let bad = RectifyOptions {
            left: dir.path().join("absent.tif"),
            ..base
        };
        let msg = format!("{:#}", rectify(&bad, &Silent).unwrap_err());
        assert!(msg.contains("absent.tif"), "{msg}");
    }
}
