//! Writes a procedural world in the public release's folder layout, so every stage reads it exactly
//! like real data:
//!
//! ```text
//! L/<stem>.iio  R/<stem>.iio        rectified images, NPY float32 (H, W, 3), 0–255
//! homography/<stem>.npz             Hleft, Hright (raw → rectified), float64 3×3
//! disparity/<stem>.iio              true disparity of the left view, x_R = x_L − d (every pixel)
//! occlusion/<stem>.png              255 where the left pixel is not visible in the right view
//! height/<stem>.iio                 altitude (m) of the surface seen by each left pixel
//! classes/<ID>.png                  OpenEarthMap class ids of each view (8-bit)
//! rpc/<ID>.json                     the raw camera as a degree-1 RPC (SatNeRF/rpcm JSON)
//! truth/<AOI>_DSM.tif               ground-truth DSM, float32 GeoTIFF in the world's UTM zone
//! truth/<AOI>_CLS.tif               DFC2019 classes on the DSM's grid (5 foliage, 9 water, …)
//! world.json                        the parameters, disparity range and appearance model
//! ```
//! with `<stem>` = `<LEFTID>-<RIGHTID>` and `<AOI>` the AOI of the left id under the default
//! [`AoiRule`] (`WORLD_1_A` → `WORLD_1`), so `seasonstereo eval --world DIR` (split = DIR,
//! `--rpc-dir DIR/rpc`, `--truth-dir DIR/truth`) reads it like the benchmark's test data.
//!
//! The ground-truth DSM is, by design, the evaluation protocol's own rasterisation (max per cell,
//! floor to the cell, [`camera::rasterize_max`]) of the EXACT surface points seen at the left
//! image's pixel centres: pixel (u, v) with altitude z sees ground point (u − slope·z − offset, v),
//! converted to lon/lat with the world's geographic frame and to UTM. It is computed from the
//! scene geometry, never through disparity, homographies or RPC triangulation, so evaluating the
//! world's true disparity through the whole chain measures only the chain's error. The grid has
//! the world's GSD (0.5 m) and covers every such point.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use camera::{DsmGrid, Points, UtmZone};
use raster::formats::{
    write_geotiff, write_homographies, write_npy, write_png, GeoTiffMeta, PngDepth,
};
use raster::{Homography, Image};
use serde_json::json;
use world::World;

use crate::layout::{AoiRule, TruthFiles};
use workflow::pairs::{PairFolder, PairPaths};
use workflow::stage::write_json;

/// Image ids of a world named `name`: `<name>_A` (left) and `<name>_B` (right).
pub fn image_ids(name: &str) -> Result<(String, String)> {
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        bail!("world name {name:?} must be non-empty ASCII letters, digits and '_' (a '-' would split the pair stem)");
    }
    Ok((format!("{name}_A"), format!("{name}_B")))
}

/// Writes `world` under `root` as pair `<name>_A-<name>_B`; returns its paths.
pub fn save_world(world: &World, root: &Path, name: &str) -> Result<PairPaths> {
    let (left_id, right_id) = image_ids(name)?;
    let stem = format!("{left_id}-{right_id}");
    let paths = PairFolder::new(root).paths(&stem);
    let (w, h) = world.disparity.size();
    write_npy(&paths.left, &world.left.image)?;
    write_npy(&paths.right, &world.right.image)?;
    write_homographies(&paths.homography, &world.rectify_left, &world.rectify_right)?;
    write_npy(&paths.disparity, &world.disparity)?;
    write_npy(
        root.join("height").join(format!("{stem}.iio")),
        &world.left.height,
    )?;
    write_png(
        root.join("occlusion").join(format!("{stem}.png")),
        &mask_picture(&world.occluded),
        PngDepth::Eight,
    )?;

    for (id, view, camera) in [
        (&left_id, &world.left, &world.camera_left),
        (&right_id, &world.right, &world.camera_right),
    ] {
        write_png(
            root.join("classes").join(format!("{id}.png")),
            &view.classes,
            PngDepth::Eight,
        )?;
        write_json(
            &root.join("rpc").join(format!("{id}.json")),
            &world.camera_json(camera, id),
        )?;
    }
    let (d_lo, d_hi) = world.disparity_range();
    let aoi = AoiRule::default().aoi_of(&left_id);
    write_world_truth(world, &TruthFiles::new(&root.join("truth"), &aoi))?;
    let p = &world.params;
    let meta = json!({
        "generator": "seasonstereo world",
        "pair": stem,
        "width": w, "height": h,
        "seed": p.scene.seed,
        "gsd_m": p.scene.gsd,
        "disparity_per_metre": p.left.slope - p.right.slope,
        "disparity_at_altitude_0": p.disparity_at(0.0),
        "disparity_range": [d_lo, d_hi],
        "sun_elevation_deg": p.sun_elevation_deg,
        "sun_azimuth_deg": p.sun_azimuth_deg,
        "appearance": world.appearance,
        "occluded_fraction": world.occluded.count() as f64 / (w * h) as f64,
        "note": "raw images are not rendered: the rectified pair, the homographies and the RPCs define the geometry",
    });
    write_json(&root.join("world.json"), &meta)?;
    Ok(paths)
}

/// Writes the two raw (unrectified) views of `world` as satellite imagery ships: tiled uint8
/// RGB GeoTIFFs `raw/<ID>.tif` (nodata 0 outside the rendered area), beside the RPCs
/// `rpc/<ID>.json` of [`save_world`]. `seasonstereo reconstruct` reads them like a real pair, and
/// the world's truth DSM scores the result. Returns the left and right paths.
pub fn save_raw_views(world: &World, root: &Path, name: &str) -> Result<(PathBuf, PathBuf)> {
    let (left_id, right_id) = image_ids(name)?;
    let mut paths = Vec::new();
    for (id, view, rectify) in [
        (&left_id, &world.left, &world.rectify_left),
        (&right_id, &world.right, &world.rectify_right),
    ] {
        let path = root.join("raw").join(format!("{id}.tif"));
        write_raw_view(&view.image, rectify, &path)?;
        paths.push(path);
    }
    Ok((paths[0].clone(), paths[1].clone()))
}

/// Writes a rectified view `image` back in the raw geometry of `rectify` (raw → rectified) as a
/// tiled uint8 GeoTIFF at `path`, 0 (nodata) outside the rendered area.
pub fn write_raw_view(image: &Image, rectify: &Homography, path: &Path) -> Result<()> {
    let (w, h) = image.size();
    let inverse = rectify
        .inverse()
        .context("the world's rectifying homography is singular")?;
    let (mut raw, inside) = raster::geometry::warp_homography(image, &inverse, w, h)?;
    let c = raw.channels();
    for (px, &ok) in raw.data_mut().chunks_exact_mut(c).zip(inside.data()) {
        // 0 is nodata: rendered pixels keep at least 1.
        px.iter_mut()
            .for_each(|v| *v = if ok { v.round().clamp(1.0, 255.0) } else { 0.0 });
    }
    let meta = GeoTiffMeta {
        nodata: Some(0.0),
        ..GeoTiffMeta::default()
    };
    raster::formats::write_tiled_u8(path, &raw, &meta)
        .with_context(|| format!("writing {}", path.display()))
}

/// DFC2019 class of an OpenEarthMap id of the world: tree → 5 (foliage), water → 9, building → 6,
/// everything else → 2 (ground).
pub fn dfc_class(oem: u8) -> u8 {
    match oem {
        world::class::TREE => 5,
        world::class::WATER => 9,
        world::class::BUILDING => 6,
        _ => 2,
    }
}

/// DFC2019 "unlabeled": the class of DSM cells no point falls in.
pub const DFC_UNLABELED: u8 = 65;

/// The exact surface points seen at the left image's pixel centres, `[lon, lat, alt]` per pixel
/// (NaN where the pixel sees nothing), and their DFC classes.
pub fn world_surface_points(world: &World) -> (Points, Vec<u8>) {
    let (w, h) = world.left.height.size();
    let cam = &world.params.left;
    let mut lonlatalt = Vec::with_capacity(w * h);
    let mut classes = Vec::with_capacity(w * h);
    for v in 0..h {
        for u in 0..w {
            let z = world.left.height.get(u, v, 0) as f64;
            if !z.is_finite() {
                lonlatalt.push([f64::NAN; 3]);
                classes.push(DFC_UNLABELED);
                continue;
            }
            let x = u as f64 - cam.slope * z - cam.offset;
            let (lon, lat) = world.geo.lonlat(x, v as f64);
            lonlatalt.push([lon, lat, z]);
            classes.push(dfc_class(world.left.classes.get(u, v, 0) as u8));
        }
    }
    let points = Points {
        width: w,
        height: h,
        lonlatalt,
    };
    (points, classes)
}

/// The world's ground truth in the evaluation layout: `_DSM.tif` (max per cell of
/// [`world_surface_points`] on a UTM grid at the world's GSD covering them) and `_CLS.tif` (the
/// class of the point that gave each cell its height; 65 where empty). Returns the grid.
pub fn write_world_truth(world: &World, files: &TruthFiles) -> Result<DsmGrid> {
    let (points, classes) = world_surface_points(world);
    let (w, h) = world.left.height.size();
    let (lon_c, lat_c) = world.geo.lonlat(w as f64 / 2.0, h as f64 / 2.0);
    let zone = UtmZone::from_lonlat(lon_c, lat_c);
    let res = world.params.scene.gsd;
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    let utm: Vec<Option<(f64, f64)>> = points
        .lonlatalt
        .iter()
        .map(|p| {
            p[2].is_finite().then(|| {
                let (e, n) = zone.forward(p[0], p[1]);
                b = [b[0].min(e), b[1].min(n), b[2].max(e), b[3].max(n)];
                (e, n)
            })
        })
        .collect();
    if !b.iter().all(|v| v.is_finite()) {
        bail!("the world has no visible surface point to build a DSM from");
    }
    let snap_lo = |v: f64| (v / res).floor() * res - res;
    let snap_hi = |v: f64| (v / res).ceil() * res + res;
    let grid = DsmGrid::from_bounds(
        snap_lo(b[0]),
        snap_lo(b[1]),
        snap_hi(b[2]),
        snap_hi(b[3]),
        res,
        zone.epsg(),
    )?;
    let dsm = camera::rasterize_max(&points, &grid);
    let mut cls = Image::filled(grid.width, grid.height, 1, DFC_UNLABELED as f32);
    for ((p, en), &c) in points.lonlatalt.iter().zip(&utm).zip(&classes) {
        let Some((e, n)) = *en else { continue };
        if let Some((col, row)) = grid.cell_of(e, n) {
            if dsm.get(col, row, 0) == p[2] as f32 && cls.get(col, row, 0) == DFC_UNLABELED as f32 {
                cls.set(col, row, 0, c as f32);
            }
        }
    }
    camera::write_dsm(&files.dsm, &dsm, &grid)
        .with_context(|| format!("writing {}", files.dsm.display()))?;
    let meta = GeoTiffMeta {
        georef: Some(grid.georeference()),
        nodata: None,
        rpc: None,
        gdal_metadata: None,
    };
    write_geotiff(&files.cls, &cls, &meta)
        .with_context(|| format!("writing {}", files.cls.display()))?;
    Ok(grid)
}

/// A mask as an 8-bit picture: 255 where true, 0 elsewhere.
pub fn mask_picture(mask: &raster::Mask) -> raster::Image {
    let data = mask
        .data()
        .iter()
        .map(|&v| if v { 255.0 } else { 0.0 })
        .collect();
    raster::Image::new(mask.width(), mask.height(), 1, data).expect("sizes match")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_the_release_layout_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let world =
            world::generate(&world::WorldParams::new(64, 2), &world::Neutral, &|_, _| {}).unwrap();
        let paths = save_world(&world, dir.path(), "W1").unwrap();
        assert_eq!(paths.stem, "W1_A-W1_B");
        assert_eq!(raster::read_image(&paths.left).unwrap(), world.left.image);
        assert_eq!(
            raster::read_image(&paths.disparity).unwrap(),
            world.disparity
        );
        let (hl, hr) = raster::formats::read_homographies(&paths.homography).unwrap();
        assert_eq!((hl, hr), (world.rectify_left, world.rectify_right));
        let classes = raster::read_image(dir.path().join("classes/W1_A.png")).unwrap();
        assert_eq!(classes, world.left.classes);
        let rpc: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.path().join("rpc/W1_B.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(rpc["rpc"]["col_num"].as_array().unwrap().len(), 20);
        assert!(image_ids("bad-name").is_err());
    }
}
