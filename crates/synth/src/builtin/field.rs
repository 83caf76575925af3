//! Smooth low-frequency fields (haze, illumination, snow patches, foliage hue): value noise on a
//! coarse lattice in normalised image coordinates. A lattice cell spans a sizeable fraction of
//! the image, and interpolation is C¹ (smoothstep), so a field changes slowly everywhere and can
//! never create or move an edge.

use super::random::Rng;

pub(crate) struct SmoothField {
    cells: usize,
    /// `(cells + 1)²` lattice values in [−1, 1].
    values: Vec<f32>,
}

impl SmoothField {
    /// A field with `cells` lattice cells across the image (features about `1 / cells` of the
    /// image wide), drawn from `rng`.
    pub(crate) fn new(rng: &mut Rng, cells: usize) -> Self {
        let cells = cells.max(1);
        let n = (cells + 1) * (cells + 1);
        let values = (0..n).map(|_| rng.range(-1.0, 1.0)).collect();
        Self { cells, values }
    }

    /// Value at normalised position `(u, v)` ∈ [0, 1]², in [−1, 1].
    pub(crate) fn at(&self, u: f32, v: f32) -> f32 {
        let n = self.cells;
        let (fx, fy) = (u.clamp(0.0, 1.0) * n as f32, v.clamp(0.0, 1.0) * n as f32);
        let (ix, iy) = ((fx as usize).min(n - 1), (fy as usize).min(n - 1));
        let (tx, ty) = (smooth(fx - ix as f32), smooth(fy - iy as f32));
        let at = |i: usize, j: usize| self.values[j * (n + 1) + i];
        let top = at(ix, iy) + (at(ix + 1, iy) - at(ix, iy)) * tx;
        let bottom = at(ix, iy + 1) + (at(ix + 1, iy + 1) - at(ix, iy + 1)) * tx;
        top + (bottom - top) * ty
    }
}

fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_is_bounded_and_slow() {
        let f = SmoothField::new(&mut Rng::new(3), 4);
        let step = 1.0 / 1024.0;
        let mut max_jump = 0.0f32;
        for j in 0..200 {
            for i in 0..1023 {
                let (u, v) = (i as f32 * step, j as f32 * 5.0 * step);
                let a = f.at(u, v);
                assert!((-1.0..=1.0).contains(&a));
                max_jump = max_jump.max((f.at(u + step, v) - a).abs());
            }
        }
        // Slope at most 1.5 · 2 · cells per unit length: ≤ 0.012 per pixel of a 1024² image.
        assert!(max_jump < 0.013, "max change per pixel {max_jump}");
    }
}
