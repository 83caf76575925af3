//! Cutting the region of interest of the left raw image into tiles with overlap collars.

use camera::rectify::Roi;
use serde::{Deserialize, Serialize};

/// One tile: the `core` it is responsible for (tiles' cores partition the region) and the
/// `extended` region it matches (core + collar, inside the image), both in left raw pixels.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tile {
    /// Position in the plan (row-major), the order of shards and merges.
    pub index: usize,
    /// `r<row>_c<col>`: the name of its files.
    pub id: String,
    pub core: Roi,
    pub extended: Roi,
}

/// Tiles of `tile` × `tile` pixels over `roi` (the last row and column take the remainder, never
/// a sliver under half a tile), each extended by `collar` pixels on every side within the
/// `width` × `height` image.
pub fn plan_tiles(roi: Roi, tile: usize, collar: usize, width: usize, height: usize) -> Vec<Tile> {
    let cuts = |start: usize, len: usize| -> Vec<(usize, usize)> {
        let tile = tile.max(1);
        let mut n = len.div_ceil(tile).max(1);
        if n > 1 && len - (n - 1) * tile < tile / 2 {
            n -= 1;
        }
        (0..n)
            .map(|i| {
                let a = start + i * tile;
                let b = if i + 1 == n { start + len } else { a + tile };
                (a, b - a)
            })
            .collect()
    };
    let rows = cuts(roi.y, roi.height);
    let cols = cuts(roi.x, roi.width);
    let mut tiles = Vec::with_capacity(rows.len() * cols.len());
    for (r, &(y, h)) in rows.iter().enumerate() {
        for (c, &(x, w)) in cols.iter().enumerate() {
            let (ex, ey) = (x.saturating_sub(collar), y.saturating_sub(collar));
            let (ex1, ey1) = ((x + w + collar).min(width), (y + h + collar).min(height));
            tiles.push(Tile {
                index: tiles.len(),
                id: format!("r{r:03}_c{c:03}"),
                core: Roi::new(x, y, w, h),
                extended: Roi::new(ex, ey, ex1 - ex, ey1 - ey),
            });
        }
    }
    tiles
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cores_partition_the_region_and_collars_stay_inside_the_image() {
        let roi = Roi::new(10, 20, 1000, 700);
        let tiles = plan_tiles(roi, 256, 32, 1100, 730);
        // 1000 = 3×256 + 232 (kept: ≥ half a tile); 700 = 2×256 + 188 (kept).
        assert_eq!(tiles.len(), 4 * 3);
        let mut covered = vec![0u8; 1100 * 730];
        for t in &tiles {
            for y in t.core.y..t.core.y + t.core.height {
                for x in t.core.x..t.core.x + t.core.width {
                    covered[y * 1100 + x] += 1;
                }
            }
            let e = t.extended;
            assert!(e.x <= t.core.x && e.y <= t.core.y);
            assert!(e.x + e.width <= 1100 && e.y + e.height <= 730);
            assert!(e.x + e.width >= t.core.x + t.core.width);
        }
        for y in 0..730 {
            for x in 0..1100 {
                let inside = (10..1010).contains(&x) && (20..720).contains(&y);
                assert_eq!(covered[y * 1100 + x], inside as u8, "({x}, {y})");
            }
        }
        assert_eq!(tiles[5].id, "r001_c001");
        assert_eq!(
            tiles[0].extended,
            Roi::new(0, 0, 256 + 32 + 10, 256 + 32 + 20)
        );
        // A last strip under half a tile joins its neighbour; a region smaller than a tile is one.
        let t = plan_tiles(Roi::new(0, 0, 600, 100), 256, 0, 600, 100);
        assert_eq!(t.len(), 2);
        assert_eq!(t[1].core.width, 600 - 256);
        assert_eq!(
            plan_tiles(Roi::new(0, 0, 800, 800), 1024, 64, 800, 800).len(),
            1
        );
    }
}
