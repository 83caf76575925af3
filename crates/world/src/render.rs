//! Scanline rendering of the 2.5D scene into rectified views, with exact ground truth.
//!
//! In a rectified view every image row is one ground row, so rendering is a 1-D visibility problem
//! per row: the row's height profile is projected with u = x + slope·z + offset. The profile is
//! piecewise linear where the surface is continuous (terrain, pitched roofs) and has vertical walls
//! where it jumps (building and tree edges). Scanning from the side the camera looks from, a piece is
//! visible exactly where its projection goes beyond everything seen so far. Colours are integrated
//! over each pixel's footprint (box filter); the ground truth is the visible point at each pixel
//! centre, so the disparity is exact for the rendered geometry.

use crate::camera::ViewCamera;
use crate::scene::Surface;

/// A height step between neighbouring samples larger than this is a wall, not a slope (metres).
const WALL_STEP_M: f64 = 0.5;

/// One ground row sampled finely along x: pieces of width `step` centred on
/// `x_lo + (k + ½)·step`, linear between their end heights, joined by vertical walls.
pub struct Profile<'a> {
    pub x_lo: f64,
    pub step: f64,
    pub surfaces: &'a [Surface],
    /// Shaded colour of each piece.
    pub colours: &'a [[f32; 3]],
    /// Heights at the −x and +x ends of each piece.
    ends: Vec<(f64, f64)>,
}

impl<'a> Profile<'a> {
    pub fn new(x_lo: f64, step: f64, surfaces: &'a [Surface], colours: &'a [[f32; 3]]) -> Self {
        let h = |k: usize| surfaces[k].height as f64;
        let n = surfaces.len();
        // Where the neighbour is close in height the surface is continuous: meet half-way.
        let joint = |k: usize, other: Option<usize>| match other {
            Some(o) if (h(o) - h(k)).abs() <= WALL_STEP_M => (h(o) + h(k)) / 2.0,
            _ => h(k),
        };
        let ends = (0..n)
            .map(|k| {
                (
                    joint(k, k.checked_sub(1)),
                    joint(k, (k + 1 < n).then_some(k + 1)),
                )
            })
            .collect();
        Profile {
            x_lo,
            step,
            surfaces,
            colours,
            ends,
        }
    }

    fn len(&self) -> usize {
        self.surfaces.len()
    }

    fn centre(&self, k: usize) -> f64 {
        self.x_lo + (k as f64 + 0.5) * self.step
    }

    /// x of the wall between pieces `boundary − 1` and `boundary`.
    fn wall_x(&self, boundary: usize) -> f64 {
        self.x_lo + boundary as f64 * self.step
    }
}

/// What a visible span of a view shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Piece {
    /// Flat piece `k` of the profile.
    Flat(usize),
    /// The wall at `boundary` (between pieces `boundary − 1` and `boundary`), belonging to the
    /// taller piece `owner` and rising from the height of piece `foot`.
    Wall {
        boundary: usize,
        owner: usize,
        foot: usize,
    },
}

/// A visible interval [u0, u1] of image columns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Span {
    pub u0: f64,
    pub u1: f64,
    pub piece: Piece,
}

/// The point of the ground profile seen at column `u` of a span: (x, z).
pub fn point_at(profile: &Profile, cam: &ViewCamera, span: &Span, u: f64) -> (f64, f64) {
    match span.piece {
        Piece::Flat(k) => {
            let x0 = profile.centre(k) - profile.step / 2.0;
            let (z0, z1) = profile.ends[k];
            let run = profile.step + cam.slope * (z1 - z0);
            let t = if run.abs() > 1e-12 {
                ((u - x0 - cam.slope * z0 - cam.offset) / run).clamp(0.0, 1.0)
            } else {
                0.5
            };
            (x0 + t * profile.step, z0 + t * (z1 - z0))
        }
        Piece::Wall { boundary, .. } => {
            let x = profile.wall_x(boundary);
            (x, (u - x - cam.offset) / cam.slope)
        }
    }
}

/// The visible spans of a profile in a view, sorted by increasing u and tiling the covered columns.
pub fn visible_spans(profile: &Profile, cam: &ViewCamera) -> Vec<Span> {
    let n = profile.len();
    // Scan from the side the camera looks from; in the scan frame (s = sign·u) visible pieces are
    // those that reach beyond the running maximum.
    let sign = if cam.slope >= 0.0 { 1.0 } else { -1.0 };
    let mut spans = Vec::with_capacity(n + n / 8);
    let mut reach = f64::NEG_INFINITY;
    let mut push = |a: f64, b: f64, piece: Piece| {
        let (s0, s1) = (sign * a, sign * b);
        if s1 > reach {
            let s0 = s0.max(reach);
            reach = s1;
            spans.push(Span {
                u0: sign * s0,
                u1: sign * s1,
                piece,
            });
        }
    };
    let half = profile.step / 2.0;
    for i in 0..n {
        let k = if sign > 0.0 { i } else { n - 1 - i };
        let x = profile.centre(k);
        // The piece's ends in scan order: (position, height) nearest the camera first.
        let (lo, hi) = profile.ends[k];
        let (near, far) = if sign > 0.0 {
            ((x - half, lo), (x + half, hi))
        } else {
            ((x + half, hi), (x - half, lo))
        };
        push(
            cam.column(near.0, near.1),
            cam.column(far.0, far.1),
            Piece::Flat(k),
        );
        // The wall towards the next piece in scan order; it faces the camera when it rises.
        let next = if sign > 0.0 { k + 1 } else { k.wrapping_sub(1) };
        if next >= n || cam.slope == 0.0 {
            continue;
        }
        let next_near = if sign > 0.0 {
            profile.ends[next].0
        } else {
            profile.ends[next].1
        };
        if next_near > far.1 {
            let boundary = k.max(next);
            push(
                cam.column(far.0, far.1),
                cam.column(far.0, next_near),
                Piece::Wall {
                    boundary,
                    owner: next,
                    foot: k,
                },
            );
        }
    }
    if sign < 0.0 {
        spans.reverse();
        for s in &mut spans {
            std::mem::swap(&mut s.u0, &mut s.u1);
        }
    }
    spans
}

/// Index of the span containing column `u`, if any.
pub fn span_at(spans: &[Span], u: f64) -> Option<usize> {
    let i = spans.partition_point(|s| s.u1 < u);
    (i < spans.len() && spans[i].u0 <= u).then_some(i)
}

/// Box-filters the visible spans into `width` pixels (pixel i covers [i − ½, i + ½)).
/// `wall_colour(owner, foot, z)` gives the colour of a wall at altitude z.
pub fn rasterise(
    profile: &Profile,
    cam: &ViewCamera,
    spans: &[Span],
    width: usize,
    wall_colour: impl Fn(usize, usize, f64) -> [f32; 3],
) -> Vec<[f32; 3]> {
    let mut acc = vec![[0.0f32; 3]; width];
    let mut weight = vec![0.0f32; width];
    let mut splat = |u0: f64, u1: f64, c: [f32; 3]| {
        let first = (u0 + 0.5).floor().max(0.0) as usize;
        let last = ((u1 + 0.5).floor() as i64).min(width as i64 - 1);
        for i in first as i64..=last {
            let i = i as usize;
            let overlap = (u1.min(i as f64 + 0.5) - u0.max(i as f64 - 0.5)) as f32;
            if overlap > 0.0 {
                for ch in 0..3 {
                    acc[i][ch] += overlap * c[ch];
                }
                weight[i] += overlap;
            }
        }
    };
    for span in spans {
        if span.u1 < -0.5 || span.u0 > width as f64 - 0.5 {
            continue;
        }
        match span.piece {
            Piece::Flat(k) => splat(span.u0, span.u1, profile.colours[k]),
            Piece::Wall { owner, foot, .. } => {
                // Walls change colour with altitude (storeys): integrate in quarter-pixel slices.
                let slices = ((span.u1 - span.u0) * 4.0).ceil().max(1.0) as usize;
                let du = (span.u1 - span.u0) / slices as f64;
                for s in 0..slices {
                    let u = span.u0 + (s as f64 + 0.5) * du;
                    let (_, z) = point_at(profile, cam, span, u);
                    splat(u - du / 2.0, u + du / 2.0, wall_colour(owner, foot, z));
                }
            }
        }
    }
    acc.iter()
        .zip(&weight)
        .map(|(c, &w)| if w > 0.0 { c.map(|v| v / w) } else { [0.0; 3] })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::class;

    fn flat(height: f32) -> Surface {
        Surface {
            height,
            class: class::BARELAND,
            albedo: [0.5; 3],
            facade: [0.5; 3],
            normal: [0.0, 0.0, 1.0],
            texture: 0.5,
        }
    }

    /// A 10-pixel-wide block of height 10 m on flat ground at 0 m.
    fn block_profile() -> Vec<Surface> {
        (0..40)
            .map(|k| flat(if (15..25).contains(&k) { 10.0 } else { 0.0 }))
            .collect()
    }

    #[test]
    fn spans_tile_the_view_and_show_the_facing_wall() {
        let surfaces = block_profile();
        let colours = vec![[0.5f32; 3]; surfaces.len()];
        let profile = Profile::new(0.0, 1.0, &surfaces, &colours);
        for slope in [0.5, -0.5] {
            let cam = ViewCamera { slope, offset: 0.0 };
            let spans = visible_spans(&profile, &cam);
            for w in spans.windows(2) {
                assert!(
                    (w[0].u1 - w[1].u0).abs() < 1e-9,
                    "gap between {:?} and {:?}",
                    w[0],
                    w[1]
                );
            }
            let walls: Vec<_> = spans
                .iter()
                .filter(|s| matches!(s.piece, Piece::Wall { .. }))
                .collect();
            assert_eq!(walls.len(), 1, "slope {slope}: one wall faces the camera");
            assert!(
                (walls[0].u1 - walls[0].u0 - 5.0).abs() < 1e-9,
                "wall spans 10 m × 0.5 px/m"
            );
            // The roof is shifted by slope·10 = ±5 px.
            let roof = spans.iter().find(|s| s.piece == Piece::Flat(20)).unwrap();
            assert!((roof.u0 - (20.0 + 5.0 * slope.signum())).abs() < 1e-9);
        }
    }

    #[test]
    fn ground_behind_the_block_is_hidden() {
        let surfaces = block_profile();
        let colours = vec![[0.5f32; 3]; surfaces.len()];
        let profile = Profile::new(0.0, 1.0, &surfaces, &colours);
        // Camera looking from −x: the ground just behind (x in [25, 30)) falls under the roof's projection.
        let cam = ViewCamera {
            slope: 0.5,
            offset: 0.0,
        };
        let spans = visible_spans(&profile, &cam);
        assert!(!spans
            .iter()
            .any(|s| matches!(s.piece, Piece::Flat(k) if (25..30).contains(&k))));
        assert!(spans.iter().any(|s| s.piece == Piece::Flat(30)));
        // Each visible column maps back to a point that projects onto it.
        for u in [3.0, 17.5, 22.0, 27.0, 33.0] {
            let s = &spans[span_at(&spans, u).unwrap()];
            let (x, z) = point_at(&profile, &cam, s, u);
            assert!((cam.column(x, z) - u).abs() < 1e-9);
        }
    }

    #[test]
    fn gentle_slopes_are_continuous_and_fully_visible() {
        // A gable: up 0.2 m per piece, then down: no walls, every piece seen by both cameras.
        let surfaces: Vec<Surface> = (0..40)
            .map(|k| flat(0.2 * (20.0 - (k as f32 - 20.0).abs())))
            .collect();
        let colours = vec![[0.5f32; 3]; surfaces.len()];
        let profile = Profile::new(0.0, 1.0, &surfaces, &colours);
        for slope in [0.5, -0.5] {
            let cam = ViewCamera { slope, offset: 0.0 };
            let spans = visible_spans(&profile, &cam);
            assert!(spans.iter().all(|s| matches!(s.piece, Piece::Flat(_))));
            assert_eq!(spans.len(), 40, "slope {slope}");
            // Points on a slope interpolate linearly: the ridge at x = 20.5 is 4.1 m high... and
            // every point found projects back onto its column.
            for s in &spans {
                let u = (s.u0 + s.u1) / 2.0;
                let (x, z) = point_at(&profile, &cam, s, u);
                assert!((cam.column(x, z) - u).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn rasterise_conserves_colour() {
        let surfaces = block_profile();
        let colours: Vec<[f32; 3]> = (0..surfaces.len()).map(|k| [k as f32 / 40.0; 3]).collect();
        let profile = Profile::new(-0.5, 1.0, &surfaces, &colours);
        // A nadir view (slope 0) shows each piece exactly in its pixel.
        let cam = ViewCamera {
            slope: 0.0,
            offset: 0.0,
        };
        let spans = visible_spans(&profile, &cam);
        let px = rasterise(&profile, &cam, &spans, 30, |_, _, _| [9.0; 3]);
        for (i, p) in px.iter().enumerate() {
            assert!((p[0] - i as f32 / 40.0).abs() < 1e-6, "pixel {i}: {p:?}");
        }
    }
}
