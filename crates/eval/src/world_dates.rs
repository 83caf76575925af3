//! One procedural world seen on several dates from several orbits: the input `reconstruct-many`
//! expects (raw GeoTIFFs and SatNeRF JSON cameras carrying the acquisition date and the sun's
//! angles) with its exact truth, so the multi-date selection and fusion can be tested against
//! ground truth, not only on the real dev images.
//!
//! Every acquisition renders the same scene (same seed) through its own view (incidence) under
//! its own sun, which moves the shadows, and is then coloured by the built-in seasonal model for
//! its season (the view's exact classes as hints; colours change, geometry does not):
//!
//! ```text
//! raw/<NAME>_D<k>.tif      the raw view, tiled uint8 RGB GeoTIFF (0 = nodata)
//! rpc/<NAME>_D<k>.json     its degree-1 RPC with acquisition_date, sun_elevation, sun_azimuth
//! truth/<NAME>_DSM.tif     the truth DSM and classes of the scene (from the first acquisition,
//! truth/<NAME>_CLS.tif     the nearest to nadir), as [`crate::world_io`] writes them
//! ```

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde_json::Value;
use synth::{BuiltinSeasons, Season, SeasonGenerator, SourceImage};
use world::{ViewCamera, WorldParams};

use crate::layout::TruthFiles;
use crate::world_io::{image_ids, write_raw_view, write_world_truth};
use workflow::progress::{track, Progress};
use workflow::stage::write_json;

/// One acquisition of the stack.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Acquisition {
    /// `YYYYMMDDhhmmss`, as the SatNeRF JSONs write it.
    pub date: &'static str,
    pub season: Season,
    /// Parallax of the view, pixels per metre of altitude (its incidence; the sign is the side).
    pub slope: f64,
    pub sun_elevation_deg: f64,
    pub sun_azimuth_deg: f64,
}

/// Six acquisitions over a year, two per season a week apart from opposite sides (a usable
/// baseline within the season), the sun as it is at 30° N at 10:30 on those dates. The first is
/// the nearest to nadir.
pub const ACQUISITIONS: [Acquisition; 6] = [
    Acquisition {
        date: "20240312153000",
        season: Season::Spring,
        slope: 0.05,
        sun_elevation_deg: 52.0,
        sun_azimuth_deg: 140.0,
    },
    Acquisition {
        date: "20240318153000",
        season: Season::Spring,
        slope: -0.40,
        sun_elevation_deg: 54.0,
        sun_azimuth_deg: 138.0,
    },
    Acquisition {
        date: "20240620153000",
        season: Season::Summer,
        slope: 0.45,
        sun_elevation_deg: 72.0,
        sun_azimuth_deg: 112.0,
    },
    Acquisition {
        date: "20240627153000",
        season: Season::Summer,
        slope: -0.20,
        sun_elevation_deg: 71.0,
        sun_azimuth_deg: 110.0,
    },
    Acquisition {
        date: "20241210153000",
        season: Season::Winter,
        slope: 0.35,
        sun_elevation_deg: 34.0,
        sun_azimuth_deg: 156.0,
    },
    Acquisition {
        date: "20241217153000",
        season: Season::Winter,
        slope: -0.45,
        sun_elevation_deg: 33.0,
        sun_azimuth_deg: 158.0,
    },
];

/// What [`write_dated_stack`] wrote.
#[derive(Clone, Debug)]
pub struct DatedStack {
    /// The raw images, in the order of the acquisitions.
    pub images: Vec<PathBuf>,
    /// Their cameras, `<image stem>.json` each.
    pub rpc_dir: PathBuf,
    /// The truth DSM (its `_CLS.tif` beside it).
    pub truth: PathBuf,
}

/// Renders the world of `size` pixels and `seed` on every acquisition and writes the stack under
/// `root` (layout in the module's documentation), its images named `<name>_D1`, `<name>_D2`, ….
pub fn write_dated_stack(
    size: usize,
    seed: u64,
    name: &str,
    acquisitions: &[Acquisition],
    root: &Path,
    progress: &dyn Progress,
) -> Result<DatedStack> {
    image_ids(name)?;
    let seasons = BuiltinSeasons::new(seed);
    let rpc_dir = root.join("rpc");
    let mut images = Vec::with_capacity(acquisitions.len());
    let mut truth = None;
    for (k, a) in acquisitions.iter().enumerate() {
        let id = format!("{name}_D{}", k + 1);
        let mut params = WorldParams::new(size, seed);
        params.left = ViewCamera {
            slope: a.slope,
            offset: 0.0,
        };
        params.sun_elevation_deg = a.sun_elevation_deg;
        params.sun_azimuth_deg = a.sun_azimuth_deg;
        let label = format!("rendering {id} ({}, {})", a.season, &a.date[..8]);
        let world = track(progress, &label, size, |cb| {
            world::generate(&params, &world::Neutral, cb)
        })
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("rendering acquisition {id}"))?;
        let source = SourceImage::new(&id, &world.left.image).with_classes(&world.left.classes);
        let image = seasons
            .generate(&source, a.season)
            .with_context(|| format!("the {} colours of {id}", a.season))?;
        let path = root.join("raw").join(format!("{id}.tif"));
        write_raw_view(&image, &world.rectify_left, &path)?;
        let mut camera = world.camera_json(&world.camera_left, &id);
        camera["acquisition_date"] = Value::from(a.date);
        camera["sun_elevation"] = Value::from(a.sun_elevation_deg);
        camera["sun_azimuth"] = Value::from(a.sun_azimuth_deg);
        write_json(&rpc_dir.join(format!("{id}.json")), &camera)?;
        images.push(path);
        if truth.is_none() {
            let files = TruthFiles::new(&root.join("truth"), name);
            write_world_truth(&world, &files)?;
            truth = Some(files.dsm);
        }
    }
    Ok(DatedStack {
        images,
        rpc_dir,
        truth: truth.context("a stack needs at least one acquisition")?,
    })
}
