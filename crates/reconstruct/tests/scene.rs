//! Whole-scene reconstruction on raw (unrectified) procedural world views with exact truth: a
//! scene cut into tiles gives the DSM of one tile away from the tiles' edges, seams do not show
//! in the error, shards assemble the same DSM, and a broken input fails its tiles only.

use std::path::{Path, PathBuf};

use camera::{read_dsm, Gridding};
use matching::SgmParams;
use reconstruct::dsm::GridChoice;
use reconstruct::finishing::Finishing;
use reconstruct::tile::TileStatus;
use reconstruct::{reconstruct, ReconstructOptions, ReconstructSummary};
use workflow::matcher::Matcher;
use workflow::Silent;

const SIZE: usize = 320;

/// A world written with its raw views; returns its folder.
fn raw_world(dir: &Path) -> PathBuf {
    let world = world::generate(
        &world::WorldParams::new(SIZE, 11),
        &world::Neutral,
        &|_, _| {},
    )
    .unwrap();
    let root = dir.join("world");
    eval::world_io::save_world(&world, &root, "W11").unwrap();
    eval::world_io::save_raw_views(&world, &root, "W11").unwrap();
    root
}

fn options(root: &Path, out: &Path, tile: usize) -> ReconstructOptions {
    let truth = root.join("truth/W11_DSM.tif");
    ReconstructOptions {
        rpc_left: Some(root.join("rpc/W11_A.json")),
        rpc_right: Some(root.join("rpc/W11_B.json")),
        truth: Some(truth.clone()),
        // The benchmark's gridding and no post-processing: what tiling changes shows unblurred.
        finishing: Finishing::new(Gridding::Max, None, None, None),
        tile,
        collar: 32,
        ..ReconstructOptions::new(
            root.join("raw/W11_A.tif"),
            root.join("raw/W11_B.tif"),
            Matcher::Classical(SgmParams::default()),
            GridChoice::Like(truth),
            out.to_path_buf(),
        )
    }
}

/// The confidence sidecar covers exactly the measured cells, in `[0, 1]`, and says which are
/// right: the most confident half of the cells errs less than the least confident half.
fn confident_cells_are_the_accurate_ones(
    path: &Path,
    dsm: &raster::Image,
    truth: &raster::Image,
    s: &ReconstructSummary,
) {
    let confidence = read_dsm(reconstruct::dsm::confidence_path(path), None)
        .unwrap()
        .image;
    let sc = s.scores.as_ref().unwrap();
    let (w, h) = dsm.size();
    let mut cells = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let (z, c) = (dsm.get(x, y, 0), confidence.get(x, y, 0));
            assert_eq!(z.is_finite(), c.is_finite(), "cell {x},{y}: unfilled DSM");
            let (tx, ty) = (x as i64 + sc.dx as i64, y as i64 + sc.dy as i64);
            if !c.is_finite() || tx < 0 || ty < 0 || tx >= w as i64 || ty >= h as i64 {
                continue;
            }
            assert!((0.0..=1.0).contains(&c), "{c}");
            let g = truth.get(tx as usize, ty as usize, 0);
            if g.is_finite() {
                cells.push((c, (z as f64 + sc.offset.unwrap() - g as f64).abs()));
            }
        }
    }
    cells.sort_by(|a, b| a.0.total_cmp(&b.0));
    let half = cells.len() / 2;
    let mean = |v: &[(f32, f64)]| v.iter().map(|c| c.1).sum::<f64>() / v.len() as f64;
    let (low, high) = (mean(&cells[..half]), mean(&cells[half..]));
    eprintln!("MAE of the least confident half {low:.3} m, of the most confident {high:.3} m");
    assert!(cells.len() > 10_000 && high < 0.8 * low, "{high} vs {low}");
}

fn mae(s: &ReconstructSummary) -> f64 {
    s.scores.as_ref().unwrap().mae_filtered.unwrap()
}

#[test]
fn tiles_give_the_single_tile_dsm_away_from_their_edges_without_seams() {
    let dir = tempfile::tempdir().unwrap();
    let root = raw_world(dir.path());
    let one = reconstruct(&options(&root, &dir.path().join("one.tif"), 1024), &Silent).unwrap();
    let tiled_path = dir.path().join("tiled.tif");
    let tiled = reconstruct(&options(&root, &tiled_path, 160), &Silent).unwrap();
    assert_eq!(one.records.len(), 1);
    assert_eq!(tiled.records.len(), 4, "2 × 2 tiles of 160 px");
    assert_eq!(tiled.count(TileStatus::Done), 4);
    let (a, b) = (mae(&one), mae(&tiled));
    eprintln!("single tile MAE {a:.3} m, 160-px tiles {b:.3} m");
    assert!(a < 1.5, "single tile MAE {a}");
    assert!((a - b).abs() < 0.1, "single {a}, tiled {b}");

    // Cell by cell: mostly the same heights. Each tile has its own rectified frame, offset from
    // the whole image's by a fraction of a pixel, so the images are resampled differently and a
    // share of the sub-pixel disparities move a little; the median cell is unchanged.
    let read = |p: &Path| read_dsm(p, None).unwrap().image;
    let (u, t) = (read(&dir.path().join("one.tif")), read(&tiled_path));
    let truth = read(&root.join("truth/W11_DSM.tif"));
    let mut diffs: Vec<f32> = u
        .data()
        .iter()
        .zip(t.data())
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(x, y)| (x - y).abs())
        .collect();
    let same = diffs.iter().filter(|d| **d <= 0.01).count() as f64 / diffs.len() as f64;
    let mid = diffs.len() / 2;
    let median = *diffs.select_nth_unstable_by(mid, f32::total_cmp).1;
    eprintln!(
        "cells equal within 0.01 m: {:.1} %, median |difference| {median:.4} m",
        100.0 * same
    );
    assert!(same > 0.8 && median <= 0.01, "{same} {median}");
    confident_cells_are_the_accurate_ones(&dir.path().join("one.tif"), &u, &truth, &one);
    // No seam: along the tiles' inner edges the tiled DSM errs no more than the untiled one in
    // the same cells (each aligned to the truth as its scores found).
    let cores: Vec<_> = tiled.records.iter().map(|r| r.tile.core).collect();
    let inner_x: Vec<usize> = cores.iter().map(|c| c.x).filter(|&x| x > 0).collect();
    let inner_y: Vec<usize> = cores.iter().map(|c| c.y).filter(|&y| y > 0).collect();
    // Raw pixels and DSM cells are close to parallel in the world (0.5 m each, a few degrees of
    // rotation): the seam band is the cells within 6 of the inner edges' lines, shifted by the
    // grid's origin (the cells window of the first tile starts at the image's corner).
    let (c0, r0) = tiled.records[0].cells.map(|(c, r, _, _)| (c, r)).unwrap();
    let error_in_band = |dsm: &raster::Image, s: &ReconstructSummary| {
        let sc = s.scores.as_ref().unwrap();
        let (w, h) = dsm.size();
        let mut e = Vec::new();
        for yy in 0..h {
            for xx in 0..w {
                let near = inner_x
                    .iter()
                    .any(|&x| (xx as i64 - (c0 + x) as i64).abs() <= 6)
                    || inner_y
                        .iter()
                        .any(|&y| (yy as i64 - (r0 + y) as i64).abs() <= 6);
                let (tx, ty) = (xx as i64 + sc.dx as i64, yy as i64 + sc.dy as i64);
                if !near || tx < 0 || ty < 0 || tx >= w as i64 || ty >= h as i64 {
                    continue;
                }
                let (p, g) = (dsm.get(xx, yy, 0), truth.get(tx as usize, ty as usize, 0));
                if p.is_finite() && g.is_finite() {
                    e.push((p as f64 + sc.offset.unwrap() - g as f64).abs());
                }
            }
        }
        (e.iter().sum::<f64>() / e.len().max(1) as f64, e.len())
    };
    let (seam_tiled, n) = error_in_band(&t, &tiled);
    let (seam_whole, _) = error_in_band(&u, &one);
    eprintln!("error along the inner tile edges: tiled {seam_tiled:.3} m, untiled {seam_whole:.3} m ({n} cells)");
    assert!(n > 1000);
    assert!(
        seam_tiled <= 1.1 * seam_whole + 0.05,
        "{seam_tiled} vs {seam_whole}"
    );
}

#[test]
fn shards_assemble_the_dsm_of_one_run_and_resume_skips_finished_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let root = raw_world(dir.path());
    let whole_path = dir.path().join("whole.tif");
    let whole = reconstruct(&options(&root, &whole_path, 160), &Silent).unwrap();

    let out = dir.path().join("sharded.tif");
    let shard = |i| ReconstructOptions {
        shard: dataset::Shard::new(i, 3).unwrap(),
        ..options(&root, &out, 160)
    };
    let first = reconstruct(&shard(0), &Silent).unwrap();
    assert_eq!(first.ran, 2, "tiles 0 and 3 of 4");
    assert!(
        first.dsm.is_none() && !out.exists(),
        "other shards are missing"
    );
    let merge_early = ReconstructOptions {
        merge_only: true,
        ..options(&root, &out, 160)
    };
    let msg = format!("{:#}", reconstruct(&merge_early, &Silent).unwrap_err());
    assert!(
        msg.contains("missing shards") && msg.contains("r000_c001"),
        "{msg}"
    );
    reconstruct(&shard(1), &Silent).unwrap();
    let last = reconstruct(&shard(2), &Silent).unwrap();
    assert_eq!(last.ran, 1);
    assert!(last.dsm.is_some(), "the last shard writes the DSM");
    let read = |p: &Path| read_dsm(p, None).unwrap().image;
    let (a, b) = (read(&whole_path), read(&out));
    assert!(a
        .data()
        .iter()
        .zip(b.data())
        .all(|(x, y)| x == y || (x.is_nan() && y.is_nan())));
    assert_eq!(mae(&last), mae(&whole));

    // A rerun resumes: nothing left to run. Other settings in the same folder are refused.
    let again = reconstruct(&options(&root, &out, 160), &Silent).unwrap();
    assert_eq!(again.ran, 0);
    let msg = format!(
        "{:#}",
        reconstruct(&options(&root, &out, 256), &Silent).unwrap_err()
    );
    assert!(
        msg.contains("other settings") && msg.contains("--work"),
        "{msg}"
    );
}

#[test]
fn a_broken_image_fails_its_tiles_only_and_a_tight_budget_names_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let root = raw_world(dir.path());
    // Cut the right image's file: the tiles whose windows read its last strips fail, the others
    // finish, and the DSM is written from them.
    let right = root.join("raw/W11_B.tif");
    let bytes = std::fs::read(&right).unwrap();
    let broken = dir.path().join("broken_B.tif");
    std::fs::write(&broken, &bytes[..bytes.len() * 3 / 4]).unwrap();
    let opts = ReconstructOptions {
        right: broken,
        ..options(&root, &dir.path().join("dsm.tif"), 160)
    };
    let s = reconstruct(&opts, &Silent).unwrap();
    let failed = s.count(TileStatus::Failed);
    assert!((1..4).contains(&failed), "failed {failed} of 4");
    let r = s
        .records
        .iter()
        .find(|r| r.status == TileStatus::Failed)
        .unwrap();
    assert!(
        r.error.as_deref().unwrap().contains("broken_B.tif"),
        "{r:?}"
    );
    assert!(s.dsm.is_some() && dir.path().join("dsm.tif").is_file());

    let tight = ReconstructOptions {
        max_memory: 100 << 20,
        ..options(&root, &dir.path().join("tight.tif"), 1024)
    };
    let msg = format!("{:#}", reconstruct(&tight, &Silent).unwrap_err());
    assert!(
        msg.contains("--max-memory") && msg.contains("--tile"),
        "{msg}"
    );
}

/// A grid 16 times finer than the truth's (5120 × 5120 cells): assembled whole it would need
/// about 26 bytes a cell, more than a 512 MiB budget; a block of rows at a time it fits, and the
/// DSM is written. A budget under even one block's needs is refused with the fix.
#[test]
fn a_grid_too_large_to_assemble_whole_merges_in_blocks_within_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    let root = raw_world(dir.path());
    let truth = read_dsm(root.join("truth/W11_DSM.tif"), None).unwrap().grid;
    let fine = |out: &str, max_memory: u64| ReconstructOptions {
        truth: None,
        grid: GridChoice::Resolution {
            resolution: truth.resolution / 16.0,
            bounds: Some([
                truth.x0,
                truth.y0 - truth.height as f64 * truth.resolution,
                truth.x0 + truth.width as f64 * truth.resolution,
                truth.y0,
            ]),
            epsg: Some(truth.epsg),
        },
        max_memory,
        ..options(&root, &dir.path().join(out), 160)
    };
    let budget = 512u64 << 20;
    let s = reconstruct(&fine("fine.tif", budget), &Silent).unwrap();
    let dsm = s.dsm.unwrap();
    let cells = (dsm.grid.width * dsm.grid.height) as u64;
    assert_eq!(
        (dsm.grid.width, dsm.grid.height),
        (16 * truth.width, 16 * truth.height)
    );
    assert!(cells * 26 > budget, "the whole grid would not fit");
    assert!(s.merge_memory < budget / 4, "{} bytes", s.merge_memory);
    assert!(dsm.measured_cells > 10_000, "{}", dsm.measured_cells);
    let written = read_dsm(dir.path().join("fine.tif"), None).unwrap().image;
    let finite = written.data().iter().filter(|v| v.is_finite()).count();
    assert_eq!(finite, dsm.filled_cells);

    let msg = format!(
        "{:#}",
        reconstruct(&fine("tiny.tif", 40 << 20), &Silent).unwrap_err()
    );
    let size = format!(
        "assembling the {0}x{1}-cell DSM",
        16 * truth.width,
        16 * truth.height
    );
    assert!(
        msg.contains(&size) && msg.contains("raise --max-memory"),
        "{msg}"
    );
}

/// With weights, every tile is matched by MonSter++ (the tiny parity fixture: the geometry runs,
/// the accuracy of random-ish weights is not the point), its strips planned inside the budget.
#[cfg(feature = "network")]
#[test]
fn the_network_matches_every_tile_when_weights_are_given() {
    let weights = testdata::require!("fixtures/monsterpp-tiny").join("weights.safetensors");
    let dir = tempfile::tempdir().unwrap();
    let root = raw_world(dir.path());
    let mut net = workflow::matcher::MonsterOptions::new(weights, "tiny");
    net.device = nn::device::DeviceChoice::Cpu;
    let opts = ReconstructOptions {
        matcher: Matcher::Network(net.load().unwrap()),
        ..options(&root, &dir.path().join("net.tif"), 160)
    };
    let s = reconstruct(&opts, &Silent).unwrap();
    assert_eq!(s.records.len(), 4);
    assert_eq!(s.in_flight, 1, "one network, tiles take turns");
    assert_eq!(s.count(TileStatus::Failed), 0, "{:?}", s.records);
    assert!(s.matched().unwrap() > 0.3, "{:?}", s.matched());
    assert!(dir.path().join("net.tif").is_file());
}
