//! Rectified-pair geometry on rasters: bilinear sampling, homography warps, centre crops and
//! horizontal disparity warps (x_R = x_L − d).

/// A 3×3 projective transform of pixel coordinates, row-major, `f64`. In the public release,
/// `Hleft`/`Hright` map raw image coordinates to rectified coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homography(pub [[f64; 3]; 3]);

impl Homography {
    pub const IDENTITY: Homography =
        Homography([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);

    /// A pure translation by `(tx, ty)`.
    pub fn translation(tx: f64, ty: f64) -> Self {
        Homography([[1.0, 0.0, tx], [0.0, 1.0, ty], [0.0, 0.0, 1.0]])
    }

    /// Maps the point `(x, y)`.
    #[inline]
    pub fn apply(&self, x: f64, y: f64) -> (f64, f64) {
        let m = &self.0;
        let w = m[2][0] * x + m[2][1] * y + m[2][2];
        (
            (m[0][0] * x + m[0][1] * y + m[0][2]) / w,
            (m[1][0] * x + m[1][1] * y + m[1][2]) / w,
        )
    }

    /// `self ∘ other`: first `other`, then `self`.
    pub fn compose(&self, other: &Homography) -> Homography {
        let (a, b) = (&self.0, &other.0);
        let mut m = [[0.0; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        Homography(m)
    }

    /// The inverse transform, or `None` when the matrix is singular.
    pub fn inverse(&self) -> Option<Homography> {
        let m = &self.0;
        let cof = |r0: usize, r1: usize, c0: usize, c1: usize| {
            m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
        };
        let det = m[0][0] * cof(1, 2, 1, 2) - m[0][1] * cof(1, 2, 0, 2) + m[0][2] * cof(1, 2, 0, 1);
        if !det.is_finite() || det.abs() < 1e-300 {
            return None;
        }
        let inv = [
            [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
            [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
            [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
        ];
        Some(Homography(inv.map(|row| row.map(|v| v / det))))
    }

    /// True when every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.0.iter().flatten().all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_and_compose() {
        let h = Homography([[1.2, 0.1, 5.0], [-0.2, 0.9, -3.0], [1e-4, 2e-4, 1.0]]);
        let id = h.compose(&h.inverse().unwrap());
        for i in 0..3 {
            for j in 0..3 {
                assert!((id.0[i][j] - Homography::IDENTITY.0[i][j]).abs() < 1e-12);
            }
        }
        let (x, y) = h.apply(10.0, 20.0);
        let (bx, by) = h.inverse().unwrap().apply(x, y);
        assert!((bx - 10.0).abs() < 1e-9 && (by - 20.0).abs() < 1e-9);
        assert!(Homography([[0.0; 3]; 3]).inverse().is_none());
    }
}
