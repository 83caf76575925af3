//! The cells of a DSM that become points, and the points they become.

use camera::DsmGrid;
use raster::Image;

/// One point of the cloud: the centre of a cell, its height and its colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct CloudPoint {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub rgb: Option<[u8; 3]>,
}

/// The cells that become points, in row order.
pub(super) struct Cells<'a> {
    pub dsm: &'a Image,
    pub grid: &'a DsmGrid,
    pub colours: Option<&'a Image>,
    pub keep: Option<&'a [bool]>,
}

impl Cells<'_> {
    pub fn iter(&self) -> impl Iterator<Item = CloudPoint> + '_ {
        let w = self.grid.width;
        self.dsm
            .data()
            .iter()
            .enumerate()
            .filter(|&(i, z)| z.is_finite() && self.keep.is_none_or(|k| k[i]))
            .map(move |(i, &z)| {
                let (x, y) = self.grid.cell_centre(i % w, i / w);
                let rgb = self.colours.map(|c| {
                    let px = &c.data()[i * 3..i * 3 + 3];
                    [px[0], px[1], px[2]].map(|v| v.round().clamp(0.0, 255.0) as u8)
                });
                CloudPoint {
                    x,
                    y,
                    z: z as f64,
                    rgb,
                }
            })
    }

    pub fn count(&self) -> usize {
        self.dsm
            .data()
            .iter()
            .enumerate()
            .filter(|&(i, z)| z.is_finite() && self.keep.is_none_or(|k| k[i]))
            .count()
    }
}
