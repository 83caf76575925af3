//! Where each view's satellite is, seen from the DSM: per block of cells, the horizontal
//! displacement (grid cells per metre of rise) of the line of sight through a ground point. It
//! changes slowly across a scene (the satellite is hundreds of kilometres away), so one direction
//! per [`BLOCK`]² cells is exact enough and costs two RPC evaluations per block instead of per
//! cell.

use camera::{DsmGrid, RpcModel};
use raster::Image;

/// Side of the blocks sharing one direction, cells.
pub(super) const BLOCK: usize = 32;
/// Rise over which the line of sight is followed, metres.
const RISE_M: f64 = 10.0;

/// A representative height per block: the mean of its finite heights, or the DSM's mean where
/// the block has none.
pub(super) struct BlockHeights {
    blocks_x: usize,
    heights: Vec<f64>,
}

impl BlockHeights {
    /// The block heights of `dsm`; `None` when it has no finite height at all.
    pub(super) fn new(dsm: &Image) -> Option<Self> {
        let (w, h) = dsm.size();
        let (bx, by) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
        let mut sums = vec![(0.0f64, 0usize); bx * by];
        for (i, &z) in dsm.data().iter().enumerate() {
            if z.is_finite() {
                let s = &mut sums[(i / w / BLOCK) * bx + (i % w) / BLOCK];
                s.0 += z as f64;
                s.1 += 1;
            }
        }
        let (total, n) = sums.iter().fold((0.0, 0), |(t, n), s| (t + s.0, n + s.1));
        if n == 0 {
            return None;
        }
        let mean = total / n as f64;
        let heights = sums
            .iter()
            .map(|&(s, k)| if k > 0 { s / k as f64 } else { mean })
            .collect();
        Some(BlockHeights {
            blocks_x: bx,
            heights,
        })
    }
}

/// One view's direction towards its satellite per block: (columns, rows) of the grid per metre of
/// rise along the line of sight. NaN where the RPC could not be inverted.
pub(super) struct ViewDirections {
    blocks_x: usize,
    directions: Vec<(f64, f64)>,
}

impl ViewDirections {
    /// The directions of the view of `rpc` over `grid`, at each block's representative height.
    pub(super) fn new(rpc: &RpcModel, grid: &DsmGrid, heights: &BlockHeights) -> Self {
        let bx = heights.blocks_x;
        let directions = heights
            .heights
            .iter()
            .enumerate()
            .map(|(b, &z)| {
                let (c0, r0) = ((b % bx) * BLOCK, (b / bx) * BLOCK);
                let col = c0 as f64 + (BLOCK.min(grid.width - c0) as f64) / 2.0;
                let row = r0 as f64 + (BLOCK.min(grid.height - r0) as f64) / 2.0;
                direction(rpc, grid, (col, row), z).unwrap_or((f64::NAN, f64::NAN))
            })
            .collect();
        ViewDirections {
            blocks_x: bx,
            directions,
        }
    }

    /// The direction at cell (col, row).
    #[inline]
    pub(super) fn at(&self, col: usize, row: usize) -> (f64, f64) {
        self.directions[(row / BLOCK) * self.blocks_x + col / BLOCK]
    }
}

/// How far from nadir a direction looks: cells of displacement per metre of rise (the tangent
/// of the off-nadir angle over the cell size); infinite for an unknown direction.
fn obliquity((dc, dr): (f64, f64)) -> f64 {
    let d = dc.hypot(dr);
    if d.is_finite() {
        d
    } else {
        f64::INFINITY
    }
}

/// Per block, the views from the most nadir to the most oblique there.
pub(super) struct NadirOrder {
    blocks_x: usize,
    views: usize,
    order: Vec<usize>,
}

impl NadirOrder {
    pub(super) fn new(directions: &[&ViewDirections]) -> Self {
        let views = directions.len();
        let blocks = directions.first().map_or(0, |d| d.directions.len());
        let mut order = Vec::with_capacity(blocks * views);
        for b in 0..blocks {
            let start = order.len();
            order.extend(0..views);
            order[start..].sort_by(|&i, &j| {
                let (a, c) = (directions[i].directions[b], directions[j].directions[b]);
                obliquity(a).total_cmp(&obliquity(c))
            });
        }
        NadirOrder {
            blocks_x: directions.first().map_or(1, |d| d.blocks_x),
            views,
            order,
        }
    }

    /// The views' indices at cell (col, row), most nadir first.
    #[inline]
    pub(super) fn at(&self, col: usize, row: usize) -> &[usize] {
        let b = (row / BLOCK) * self.blocks_x + col / BLOCK;
        &self.order[b * self.views..(b + 1) * self.views]
    }
}

/// The direction at grid point (col, row) (continuous cell coordinates, cell (0, 0) covering
/// [0, 1)²) and height `z`: the image point of the ground point, then the ground point the same
/// image point sees [`RISE_M`] higher.
fn direction(rpc: &RpcModel, grid: &DsmGrid, (col, row): (f64, f64), z: f64) -> Option<(f64, f64)> {
    let crs = grid.crs();
    let x = grid.x0 + col * grid.resolution;
    let y = grid.y0 - row * grid.resolution;
    let (lon, lat) = crs.inverse(x, y);
    let (c, r) = rpc.projection(lon, lat, z);
    let (lon2, lat2) = rpc.localization_from(c, r, z + RISE_M, lon, lat).ok()?;
    let (x2, y2) = crs.forward(lon2, lat2);
    let d = (
        (x2 - x) / grid.resolution / RISE_M,
        (y - y2) / grid.resolution / RISE_M,
    );
    (d.0.is_finite() && d.1.is_finite()).then_some(d)
}
