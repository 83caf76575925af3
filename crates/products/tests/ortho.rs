//! The true orthoimage against a procedural world whose every surface is known: its colours must
//! stand on the true DSM's footprints, the cells behind buildings must be found hidden, and the
//! image's sample type must not matter.

use std::path::{Path, PathBuf};

use camera::{DsmGrid, RpcModel, UtmZone};
use products::{orthoimage, visibility, write_ortho, OrthoBlend, OrthoView};
use raster::formats::{read_tiff, write_tiled_u8, GeoTiffMeta};
use raster::{Homography, Image};
use world::camera::{AffineCamera, ViewCamera};
use world::{class, World, WorldParams};

const SIZE: usize = 160;
const EARTH_RADIUS_M: f64 = 6_378_137.0;

/// A world on the equator, so that a Web Mercator grid of the world's GSD has its cell (c, r)
/// exactly on the world's ground pixel (c, r) (the world's truth `ortho_height` is then the true
/// DSM of the grid, with no resampling).
fn equatorial_world(seed: u64) -> World {
    equatorial_world_seen(seed, |_| {})
}

/// [`equatorial_world`] with its views changed by `views`.
fn equatorial_world_seen(seed: u64, views: impl Fn(&mut WorldParams)) -> World {
    let mut params = WorldParams::new(SIZE, seed);
    params.lat0 = 0.0;
    params.lon0 = 10.0;
    views(&mut params);
    world::generate(&params, &world::Neutral, &|_, _| {}).unwrap()
}

/// The Web Mercator grid whose cells are the world's ground pixels.
fn ground_grid(world: &World) -> DsmGrid {
    let gsd = world.params.scene.gsd;
    let x = EARTH_RADIUS_M * world.geo.lon0.to_radians();
    DsmGrid::new(x - gsd / 2.0, gsd / 2.0, gsd, SIZE, SIZE, 3857).unwrap()
}

/// The camera of the world's rectified image seen through `view`.
fn rpc_of(world: &World, view: &ViewCamera) -> RpcModel {
    let camera = AffineCamera::from_view(view, &world.geo, &Homography::IDENTITY);
    RpcModel::from_rpcm_json(&world.camera_json(&camera, "view")).unwrap()
}

fn write_u8(dir: &Path, name: &str, image: &Image) -> PathBuf {
    let path = dir.join(name);
    write_tiled_u8(&path, image, &GeoTiffMeta::default()).unwrap();
    path
}

/// The world's class map of a view as a grey image: class k → 20 + 25·k.
fn class_picture(classes: &Image) -> Image {
    Image::from_fn(classes.width(), classes.height(), |x, y| {
        20.0 + 25.0 * classes.get(x, y, 0)
    })
}

/// The class a grey level of [`class_picture`] stands for.
fn class_of(level: f32) -> f32 {
    ((level - 20.0) / 25.0).round()
}

/// The share of the cells in `cells` whose ortho class (channel 0 of `ortho`, shifted by `shift`
/// columns) is their true class.
fn class_agreement(ortho: &Image, truth: &Image, cells: &[(usize, usize)], shift: usize) -> f64 {
    let hits = cells
        .iter()
        .filter(|&&(x, _)| x + shift < SIZE)
        .filter(|&&(x, y)| class_of(ortho.get(x + shift, y, 0)) == truth.get(x, y, 0))
        .count();
    hits as f64 / cells.len() as f64
}

/// Cells within `reach` cells of a building's outline (on either side), away from the border.
fn outline_band(truth: &Image, reach: usize) -> Vec<(usize, usize)> {
    let building = |x: usize, y: usize| truth.get(x, y, 0) == class::BUILDING as f32;
    let mut cells = Vec::new();
    for y in 8..SIZE - 8 {
        for x in 8..SIZE - 8 {
            let b = building(x, y);
            let near = (y - reach..=y + reach)
                .any(|v| (x - reach..=x + reach).any(|u| building(u, v) != b));
            if near {
                cells.push((x, y));
            }
        }
    }
    cells
}

/// Whether the cells around (x, y) (3 × 3) all have its class.
fn uniform(truth: &Image, x: usize, y: usize) -> bool {
    let k = truth.get(x, y, 0);
    (y - 1..=y + 1).all(|v| (x - 1..=x + 1).all(|u| truth.get(u, v, 0) == k))
}

/// Cells away from the border whose class is `k` (any class for `None`).
fn cells_of(truth: &Image, k: Option<u8>) -> Vec<(usize, usize)> {
    let mut cells = Vec::new();
    for y in 8..SIZE - 8 {
        for x in 8..SIZE - 8 {
            if k.is_none_or(|k| truth.get(x, y, 0) == k as f32) {
                cells.push((x, y));
            }
        }
    }
    cells
}

#[test]
fn roofs_stand_on_their_footprints() {
    let world = equatorial_world(4);
    let dir = tempfile::tempdir().unwrap();
    let grid = ground_grid(&world);
    let dsm = &world.ortho_height;
    let view = OrthoView {
        image: write_u8(
            dir.path(),
            "classes.tif",
            &class_picture(&world.left.classes),
        ),
        rpc: rpc_of(&world, &world.params.left),
    };
    let ortho = orthoimage(
        dsm,
        &grid,
        std::slice::from_ref(&view),
        OrthoBlend::MostNadir,
    )
    .unwrap();
    // A single band gives grey.
    assert!(ortho
        .data()
        .chunks_exact(3)
        .all(|p| p[0] == p[1] && p[1] == p[2]));

    // The classes the view sees on the true DSM are the truth's where the view sees the cell.
    let seen = visibility(dsm, &grid, &view.rpc).unwrap();
    let truth = &world.ortho_classes;
    let visible: Vec<_> = cells_of(truth, None)
        .into_iter()
        .filter(|&(x, y)| seen.get(x, y))
        .collect();
    let all = class_agreement(&ortho, truth, &visible, 0);
    // Where the view is found not to see the cell, it shows something else: mostly a roof.
    let hidden: Vec<_> = cells_of(truth, None)
        .into_iter()
        .filter(|&(x, y)| !seen.get(x, y) && dsm.get(x, y, 0).is_finite())
        .collect();
    let behind = class_agreement(&ortho, truth, &hidden, 0);
    let shifted = class_agreement(&ortho, truth, &visible, 3);

    // Near the buildings' outlines, where a wrong geometry shows first.
    let outlines: Vec<_> = outline_band(truth, 3)
        .into_iter()
        .filter(|&(x, y)| seen.get(x, y))
        .collect();
    let edges = class_agreement(&ortho, truth, &outlines, 0);
    let edges_shifted = class_agreement(&ortho, truth, &outlines, 3);
    println!(
        "visible cells {}: agreement {all:.3} (shifted by 3: {shifted:.3}); cells near building \
         outlines {}: {edges:.3} (shifted: {edges_shifted:.3}); hidden cells {}: {behind:.3}",
        visible.len(),
        outlines.len(),
        hidden.len()
    );
    assert!(hidden.len() > 300, "{} hidden cells", hidden.len());
    assert!(behind < 0.5, "hidden cells show their own class: {behind}");
    assert!(outlines.len() > 1000, "the world needs buildings");
    assert!(all > 0.95, "{all}");
    assert!(all - shifted > 0.1, "{all} vs {shifted}");
    assert!(edges > 0.88, "{edges}");
    assert!(edges - edges_shifted > 0.12, "{edges} vs {edges_shifted}");
}

/// Luminance of an RGB image.
fn luminance(image: &Image) -> Image {
    Image::from_fn(image.width(), image.height(), |x, y| {
        let p = image.pixel(x, y);
        0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]
    })
}

/// The largest absolute difference of `image` between cell (x, y) and its right and lower
/// neighbours.
fn step(image: &Image, x: usize, y: usize) -> f32 {
    let v = image.get(x, y, 0);
    (image.get(x + 1, y, 0) - v)
        .abs()
        .max((image.get(x, y + 1, 0) - v).abs())
}

/// The share of the DSM's height edges (a step over 2 m) at cells in `cells` that have a
/// luminance edge of `ortho` (a step over `threshold`) within one cell, the ortho shifted by
/// `shift` columns.
fn edges_explained(
    dsm: &Image,
    ortho: &Image,
    cells: &[(usize, usize)],
    threshold: f32,
    shift: isize,
) -> f64 {
    let lum = luminance(ortho);
    let (mut edges, mut explained) = (0, 0);
    for &(x, y) in cells {
        if step(dsm, x, y) <= 2.0 {
            continue;
        }
        edges += 1;
        let near = (y - 1..=y + 1).any(|v| {
            (x - 1..=x + 1).any(|u| step(&lum, u.wrapping_add_signed(shift), v) > threshold)
        });
        explained += near as usize;
    }
    assert!(edges > 300, "{edges} height edges");
    explained as f64 / edges as f64
}

#[test]
fn colour_edges_follow_height_edges() {
    let world = equatorial_world(4);
    let dir = tempfile::tempdir().unwrap();
    let grid = ground_grid(&world);
    let dsm = &world.ortho_height;
    let views = [
        OrthoView {
            image: write_u8(dir.path(), "left.tif", &world.left.image),
            rpc: rpc_of(&world, &world.params.left),
        },
        OrthoView {
            image: write_u8(dir.path(), "right.tif", &world.right.image),
            rpc: rpc_of(&world, &world.params.right),
        },
    ];
    let ortho = orthoimage(dsm, &grid, &views, OrthoBlend::MostNadir).unwrap();
    // Cells whose neighbourhood one view at least sees (elsewhere an occluder's colour is used).
    let seen: Vec<_> = views
        .iter()
        .map(|v| visibility(dsm, &grid, &v.rpc).unwrap())
        .collect();
    let cells: Vec<_> = cells_of(&world.ortho_classes, None)
        .into_iter()
        .filter(|&(x, y)| {
            (y - 1..=y + 2).all(|v| (x - 1..=x + 2).all(|u| seen.iter().any(|m| m.get(u, v))))
        })
        .collect();
    let aligned = edges_explained(dsm, &ortho, &cells, 20.0, 0);
    let shifted = [-3, 3].map(|s| edges_explained(dsm, &ortho, &cells, 20.0, s));
    println!(
        "height edges with a colour edge within a cell: {aligned:.3} (shifted by ±3: {shifted:.3?})"
    );
    assert!(aligned > 0.88, "{aligned}");
    assert!(
        shifted.iter().all(|s| aligned - s > 0.2),
        "{aligned} vs {shifted:?}"
    );
}

/// An affine camera over a local frame at (lon0, lat0) whose line of sight leans `slope` ground
/// pixels per metre towards the west, as an RPC.
fn oblique_rpc(lon0: f64, lat0: f64, slope: f64) -> RpcModel {
    let geo = world::GeoFrame {
        lon0,
        lat0,
        gsd: 0.5,
    };
    let view = ViewCamera { slope, offset: 0.0 };
    let camera = AffineCamera::from_view(&view, &geo, &Homography::IDENTITY);
    let centre = geo.lonlat(64.0, 64.0);
    let json = camera.to_satnerf_json("oblique", 128, 128, centre, (0.001, 0.001), (-10.0, 60.0));
    RpcModel::from_rpcm_json(&json).unwrap()
}

#[test]
fn cells_behind_a_tower_are_hidden_from_an_oblique_view() {
    // A UTM grid of 0.5 m cells: flat ground at 2 m, a 20 m tower over cells [40, 50)².
    let (lon0, lat0) = (-81.0, 30.3);
    let zone = UtmZone::from_lonlat(lon0, lat0);
    let (e, n) = zone.forward(lon0, lat0);
    let grid = DsmGrid::new(e, n, 0.5, 100, 100, zone.epsg()).unwrap();
    let tower = |x: usize, y: usize| (40..50).contains(&x) && (40..50).contains(&y);
    let mut dsm = Image::from_fn(100, 100, |x, y| if tower(x, y) { 22.0 } else { 2.0 });
    dsm.set(5, 5, 0, f32::NAN);
    // 1 cell of lean per metre: the 20 m tower hides 19 cells east of it (the satellite is west).
    let seen = visibility(&dsm, &grid, &oblique_rpc(lon0, lat0, 1.0)).unwrap();
    for x in 0..100 {
        let expected = !(50..69).contains(&x);
        if (x as i64 - 50).abs() > 1 && (x as i64 - 69).abs() > 1 {
            assert_eq!(seen.get(x, 45), expected, "column {x}");
        }
        assert!(
            seen.get(x, 30) && seen.get(x, 60),
            "rows beside the tower, column {x}"
        );
    }
    assert!(
        (40..50).all(|x| (40..50).all(|y| seen.get(x, y))),
        "the roof is seen"
    );
    assert!(!seen.get(5, 5), "a cell without height is not seen");
    // Nearly nadir, the tower hides no more than a cell.
    let nadir = visibility(&dsm, &grid, &oblique_rpc(lon0, lat0, 0.04)).unwrap();
    assert!((51..100).all(|x| nadir.get(x, 45)));
}

#[test]
fn cells_without_height_have_no_colour() {
    let world = equatorial_world(4);
    let dir = tempfile::tempdir().unwrap();
    let grid = ground_grid(&world);
    let mut dsm = world.ortho_height.clone();
    for y in 50..70 {
        for x in 60..90 {
            dsm.set(x, y, 0, f32::NAN);
        }
    }
    let view = OrthoView {
        image: write_u8(dir.path(), "left.tif", &world.left.image),
        rpc: rpc_of(&world, &world.params.left),
    };
    let ortho = orthoimage(&dsm, &grid, &[view], OrthoBlend::Median).unwrap();
    let (mut coloured, mut finite) = (0, 0);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let p = ortho.pixel(x, y);
            if dsm.get(x, y, 0).is_nan() {
                assert_eq!(p, [0.0; 3], "({x}, {y})");
            } else {
                finite += 1;
                coloured += (p != [0.0; 3]) as usize;
                // Only no data is black.
                assert!(
                    p == [0.0; 3] || p.iter().all(|&v| v >= 1.0),
                    "({x}, {y}) {p:?}"
                );
            }
        }
    }
    // The view covers the grid but for the strips its lean takes out of the image.
    assert!(
        coloured as f64 > 0.9 * finite as f64,
        "{coloured} of {finite}"
    );
}

/// Writes `image` (3 channels, 0–255) as a uint16 TIFF of `bands` bands: `dn = 40·v + 1000`, and
/// a fourth band, when asked, of huge values that must not be used.
fn write_u16(path: &Path, image: &Image, bands: usize) {
    use tiff::encoder::{colortype, TiffEncoder};
    let mut data = Vec::with_capacity(image.width() * image.height() * bands);
    for px in image.data().chunks_exact(3) {
        data.extend(px.iter().map(|&v| (40.0 * v + 1000.0) as u16));
        if bands == 4 {
            data.push(60_000);
        }
    }
    let file = std::fs::File::create(path).unwrap();
    let mut encoder = TiffEncoder::new(file).unwrap();
    let (w, h) = (image.width() as u32, image.height() as u32);
    match bands {
        3 => encoder.write_image::<colortype::RGB16>(w, h, &data),
        4 => encoder.write_image::<colortype::RGBA16>(w, h, &data),
        _ => unreachable!("3 or 4 bands"),
    }
    .unwrap();
}

/// Pearson correlation of the luminances of two images over the cells where both have colour.
fn correlation(a: &Image, b: &Image) -> f64 {
    let (la, lb) = (luminance(a), luminance(b));
    let pairs: Vec<(f64, f64)> = la
        .data()
        .iter()
        .zip(lb.data())
        .filter(|&(&x, &y)| x > 0.0 && y > 0.0)
        .map(|(&x, &y)| (x as f64, y as f64))
        .collect();
    let n = pairs.len() as f64;
    let (ma, mb) = pairs
        .iter()
        .fold((0.0, 0.0), |(s, t), (x, y)| (s + x / n, t + y / n));
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in pairs {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

#[test]
fn sixteen_bit_imagery_is_stretched_and_extra_bands_ignored() {
    let world = equatorial_world(4);
    let dir = tempfile::tempdir().unwrap();
    let grid = ground_grid(&world);
    let dsm = &world.ortho_height;
    let rpc = rpc_of(&world, &world.params.left);
    let ortho_of = |image: PathBuf| {
        let view = OrthoView {
            image,
            rpc: rpc.clone(),
        };
        orthoimage(dsm, &grid, &[view], OrthoBlend::MostNadir).unwrap()
    };
    let bytes = ortho_of(write_u8(dir.path(), "left.tif", &world.left.image));
    let (rgb16, rgbn16) = (dir.path().join("rgb16.tif"), dir.path().join("rgbn16.tif"));
    write_u16(&rgb16, &world.left.image, 3);
    write_u16(&rgbn16, &world.left.image, 4);
    let wide = ortho_of(rgb16);
    assert_eq!(
        ortho_of(rgbn16).data(),
        wide.data(),
        "the fourth band changed the colours"
    );

    let r = correlation(&bytes, &wide);
    let mut levels: Vec<f32> = wide.data().iter().copied().filter(|&v| v > 0.0).collect();
    levels.sort_by(f32::total_cmp);
    let pct = |q: f64| levels[((levels.len() - 1) as f64 * q) as usize];
    println!(
        "uint16 vs uint8 correlation {r:.4}; levels p0.2 {} p99.8 {}",
        pct(0.002),
        pct(0.998)
    );
    assert!(r > 0.99, "{r}");
    // The stretch spans the 8-bit range: the darkest and brightest cells reach its ends.
    assert!(pct(0.002) <= 5.0 && pct(0.998) >= 240.0);
}

#[test]
fn the_most_nadir_view_that_sees_a_cell_colours_it() {
    // Two oblique views from opposite sides, the right one a little nearer nadir.
    let world = equatorial_world_seen(4, |p| {
        p.left.slope = 0.55;
        p.right.slope = -0.45;
    });
    let dir = tempfile::tempdir().unwrap();
    let grid = ground_grid(&world);
    let dsm = &world.ortho_height;
    let classes =
        |v: &world::View, name: &str| write_u8(dir.path(), name, &class_picture(&v.classes));
    let left = OrthoView {
        image: classes(&world.left, "left.tif"),
        rpc: rpc_of(&world, &world.params.left),
    };
    let right = OrthoView {
        image: classes(&world.right, "right.tif"),
        rpc: rpc_of(&world, &world.params.right),
    };
    let truth = &world.ortho_classes;
    let cells = cells_of(truth, None);
    let ortho_of = |views: &[OrthoView], blend| orthoimage(dsm, &grid, views, blend).unwrap();
    let only_left = ortho_of(std::slice::from_ref(&left), OrthoBlend::MostNadir);
    let only_right = ortho_of(std::slice::from_ref(&right), OrthoBlend::MostNadir);
    let both = ortho_of(&[left.clone(), right.clone()], OrthoBlend::MostNadir);
    let median = ortho_of(&[left.clone(), right.clone()], OrthoBlend::Median);
    let seen_left = visibility(dsm, &grid, &left.rpc).unwrap();
    let seen_right = visibility(dsm, &grid, &right.rpc).unwrap();
    // The right view (0.45 px/m) is nearer nadir than the left (0.55 px/m): it wins where it
    // sees the cell, the left one colours the cells only it sees.
    for &(x, y) in &cells {
        let (r, l) = (only_right.pixel(x, y), only_left.pixel(x, y));
        let (r_ok, l_ok) = (r != [0.0; 3], l != [0.0; 3]);
        let expected = if r_ok && (seen_right.get(x, y) || !(l_ok && seen_left.get(x, y))) {
            r
        } else {
            l
        };
        assert_eq!(both.pixel(x, y), expected, "({x}, {y})");
    }
    let score = |o: &Image| class_agreement(o, truth, &cells, 0);
    let (l, r, b, m) = (
        score(&only_left),
        score(&only_right),
        score(&both),
        score(&median),
    );
    // Behind the buildings as the right view sees them, the left view gives the right colour
    // (away from the class boundaries, where the bilinear sampling mixes the classes' levels).
    let filled: Vec<_> = cells
        .iter()
        .copied()
        .filter(|&(x, y)| !seen_right.get(x, y) && seen_left.get(x, y) && uniform(truth, x, y))
        .collect();
    let (fr, fb) = (
        class_agreement(&only_right, truth, &filled, 0),
        class_agreement(&both, truth, &filled, 0),
    );
    println!(
        "class agreement: left {l:.3}, right {r:.3}, both {b:.3}, median of both {m:.3}; \
         {} cells hidden from the right only: right {fr:.3}, both {fb:.3}",
        filled.len()
    );
    assert!(filled.len() > 50, "{}", filled.len());
    assert!(fr < 0.3 && fb > 0.8, "{fr} {fb}");
    assert!(b >= l.max(r) && b > 0.95 && m > 0.95, "{b} {m}");
}

#[test]
fn the_orthoimage_file_is_rgb_on_the_dsm_grid() {
    let world = equatorial_world(4);
    let dir = tempfile::tempdir().unwrap();
    let grid = ground_grid(&world);
    let view = OrthoView {
        image: write_u8(dir.path(), "left.tif", &world.left.image),
        rpc: rpc_of(&world, &world.params.left),
    };
    let ortho = orthoimage(&world.ortho_height, &grid, &[view], OrthoBlend::MostNadir).unwrap();
    let path = dir.path().join("out").join("ortho.tif");
    write_ortho(&path, &ortho, &grid).unwrap();
    let back = read_tiff(&path).unwrap();
    assert_eq!(back.image.channels(), 3);
    assert_eq!(back.image.data(), ortho.data());
    assert_eq!(back.nodata, Some(0.0));
    let georef = back.georef.unwrap();
    assert_eq!(georef.epsg, Some(3857));
    assert_eq!(georef.geotransform, grid.georeference().geotransform);
    // Nothing but the file is left in the folder.
    let names: Vec<_> = std::fs::read_dir(path.parent().unwrap()).unwrap().collect();
    assert_eq!(names.len(), 1);
    let wrong = Image::filled(SIZE, SIZE, 1, 1.0);
    assert!(write_ortho(&path, &wrong, &grid).is_err());
}

/// The cost on a 1024² grid (a 0.26 km² DSM at 0.5 m) with three views of 1400² pixels: run with
/// `cargo test -p products --release --test ortho -- --ignored --nocapture`.
#[test]
#[ignore = "timing"]
fn timing_1024_cells_three_views() {
    let (lon0, lat0) = (-81.0, 30.3);
    let zone = UtmZone::from_lonlat(lon0, lat0);
    let (e, n) = zone.forward(lon0, lat0);
    let size = 1024;
    let grid = DsmGrid::new(e, n, 0.5, size, size, zone.epsg()).unwrap();
    // Blocks of 8–40 m buildings on a gentle slope.
    let dsm = Image::from_fn(size, size, |x, y| {
        let (bx, by) = (x / 48, y / 48);
        let inside = (x % 48) > 8 && (y % 48) > 8 && (x % 48) < 40 && (y % 48) < 40;
        let h = 8.0 + ((bx * 7 + by * 13) % 33) as f32;
        (x + y) as f32 * 0.002 + if inside { h } else { 0.0 }
    });
    let dir = tempfile::tempdir().unwrap();
    let texture = Image::from_fn(size + 400, size + 400, |x, y| {
        ((x * 31 + y * 17) % 251) as f32
    });
    let texture = Image::new(
        texture.width(),
        texture.height(),
        3,
        texture
            .data()
            .iter()
            .flat_map(|&v| [v, 255.0 - v, v / 2.0])
            .collect(),
    )
    .unwrap();
    let image = write_u8(dir.path(), "texture.tif", &texture);
    let views: Vec<OrthoView> = [0.2, -0.35, 0.6]
        .into_iter()
        .map(|slope| OrthoView {
            image: image.clone(),
            rpc: oblique_rpc(lon0, lat0, slope),
        })
        .collect();
    for blend in [OrthoBlend::MostNadir, OrthoBlend::Median] {
        let start = std::time::Instant::now();
        let ortho = orthoimage(&dsm, &grid, &views, blend).unwrap();
        let coloured = ortho.data().chunks_exact(3).filter(|p| p[0] > 0.0).count();
        println!(
            "{blend:?}: {size}² cells, 3 views: {:.2} s on {} threads ({coloured} cells coloured)",
            start.elapsed().as_secs_f64(),
            rayon::current_num_threads()
        );
    }
    let start = std::time::Instant::now();
    visibility(&dsm, &grid, &views[2].rpc).unwrap();
    println!(
        "visibility of the most oblique view alone: {:.2} s",
        start.elapsed().as_secs_f64()
    );
}
