//! Census transform: each pixel becomes a bit string saying which of its neighbours are darker
//! than it, so the matching cost (the Hamming distance of two strings) is invariant to any
//! monotonic change of the grey levels between the two dates.
//!
//! * Window: `width × height` pixels centred on the pixel (both odd), the centre excluded; bits
//!   in row-major order of the window, the first neighbour in the most significant used bit. The
//!   default 9 × 7 window (9 wide, 7 high) gives 62 bits in a `u64`.
//! * A bit is 1 when the neighbour is strictly darker than the centre.
//! * Border policy: coordinates outside the image are clamped to the nearest edge pixel
//!   (replicated border), so border pixels get a full-length code.
//! * NaN pixels: a NaN centre makes the pixel invalid ([`Census::valid`] false); a NaN
//!   neighbour gives a 0 bit (a comparison with NaN is false).

use rayon::prelude::*;

/// Census window size in pixels, both odd, at most 65 pixels in all (64 bits).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CensusWindow {
    pub width: usize,
    pub height: usize,
}

impl Default for CensusWindow {
    /// 5 × 5: 24 bits. Chosen on real WorldView-3 pairs (BENCHMARKS.md, "Real imagery: DFC2019
    /// JAX_068 development pairs"): with MGM's 2-D aggregation it matches more of the changed and
    /// shadowed areas of multi-date pairs than 7 × 7 or 9 × 7 (more cross-season DSM coverage
    /// before filling) at the same accuracy, and fattens building edges less.
    fn default() -> Self {
        Self {
            width: 5,
            height: 5,
        }
    }
}

impl CensusWindow {
    /// Number of bits of a code: the window minus its centre.
    pub fn bits(&self) -> usize {
        self.width * self.height - 1
    }

    /// Whether the window is usable: odd sides, 1 to 64 bits.
    pub fn is_valid(&self) -> bool {
        self.width % 2 == 1 && self.height % 2 == 1 && (1..=64).contains(&self.bits())
    }
}

/// Census codes of one image.
#[derive(Clone, Debug)]
pub struct Census {
    pub width: usize,
    pub height: usize,
    /// One code per pixel, row-major.
    pub codes: Vec<u64>,
    /// False where the input grey value is NaN.
    pub valid: Vec<bool>,
}

/// Census transform of a single-channel, row-major `grey` image of `width × height` pixels.
///
/// Panics when the window is invalid or `grey.len() != width * height`.
pub fn census_transform(grey: &[f32], width: usize, height: usize, window: CensusWindow) -> Census {
    assert!(window.is_valid(), "invalid census window {window:?}");
    assert_eq!(grey.len(), width * height, "grey image size");
    let rx = window.width / 2;
    let ry = window.height / 2;
    let pw = width + 2 * rx;
    // Padded copy with replicated borders, so the inner loop has no edge tests.
    let mut padded = vec![0f32; pw * (height + 2 * ry)];
    padded
        .par_chunks_mut(pw)
        .enumerate()
        .for_each(|(py, prow)| {
            let y = py.saturating_sub(ry).min(height.saturating_sub(1));
            let src = &grey[y * width..(y + 1) * width];
            for (px, v) in prow.iter_mut().enumerate() {
                *v = src[px.saturating_sub(rx).min(width - 1)];
            }
        });
    let offsets: Vec<(usize, usize)> = (0..window.height)
        .flat_map(|dy| (0..window.width).map(move |dx| (dx, dy)))
        .filter(|&(dx, dy)| (dx, dy) != (rx, ry))
        .collect();
    let mut codes = vec![0u64; width * height];
    #[cfg(target_arch = "x86_64")]
    let avx2 = is_x86_feature_detected!("avx2");
    if width > 0 {
        codes
            .par_chunks_mut(width)
            .enumerate()
            .for_each(|(y, out)| {
                let rows = &padded[y * pw..(y + window.height) * pw];
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: AVX2 support was checked at run time.
                    unsafe { census_row_avx2(rows, pw, (rx, ry), &offsets, out) };
                    return;
                }
                census_row(rows, pw, (rx, ry), &offsets, out);
            });
    }
    let valid = grey.iter().map(|v| !v.is_nan()).collect();
    Census {
        width,
        height,
        codes,
        valid,
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn census_row_avx2(
    rows: &[f32],
    pw: usize,
    centre: (usize, usize),
    offsets: &[(usize, usize)],
    out: &mut [u64],
) {
    census_row(rows, pw, centre, offsets, out)
}

/// Codes of one row from the `window.height` padded rows around it (`pw` wide).
#[inline(always)]
fn census_row(
    rows: &[f32],
    pw: usize,
    (rx, ry): (usize, usize),
    offsets: &[(usize, usize)],
    out: &mut [u64],
) {
    let width = out.len();
    let centre = &rows[ry * pw + rx..][..width];
    for &(dx, dy) in offsets {
        let nb = &rows[dy * pw + dx..][..width];
        for ((code, &n), &c) in out.iter_mut().zip(nb).zip(centre) {
            *code = (*code << 1) | u64::from(n < c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_bits() {
        assert_eq!(CensusWindow::default().bits(), 24);
        assert!(CensusWindow::default().is_valid());
        assert!(!CensusWindow {
            width: 9,
            height: 9
        }
        .is_valid());
        assert!(!CensusWindow {
            width: 4,
            height: 3
        }
        .is_valid());
    }

    #[test]
    fn codes_match_definition_with_clamped_border() {
        let (w, h) = (7, 5);
        let grey: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 11) as f32).collect();
        let win = CensusWindow {
            width: 3,
            height: 3,
        };
        let c = census_transform(&grey, w, h, win);
        let at = |x: isize, y: isize| {
            grey[(y.clamp(0, h as isize - 1) as usize) * w + x.clamp(0, w as isize - 1) as usize]
        };
        for y in 0..h as isize {
            for x in 0..w as isize {
                let mut code = 0u64;
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        if (dx, dy) != (0, 0) {
                            code = (code << 1) | u64::from(at(x + dx, y + dy) < at(x, y));
                        }
                    }
                }
                assert_eq!(c.codes[y as usize * w + x as usize], code, "pixel {x},{y}");
            }
        }
    }

    #[test]
    fn invariant_to_monotonic_change_and_nan_is_invalid() {
        let (w, h) = (16, 9);
        let mut grey: Vec<f32> = (0..w * h).map(|i| ((i * 7919) % 97) as f32).collect();
        let a = census_transform(&grey, w, h, CensusWindow::default());
        let mapped: Vec<f32> = grey.iter().map(|v| 1000.0 + 3.0 * v * v).collect();
        let b = census_transform(&mapped, w, h, CensusWindow::default());
        assert_eq!(a.codes, b.codes);
        grey[20] = f32::NAN;
        let c = census_transform(&grey, w, h, CensusWindow::default());
        assert!(!c.valid[20]);
        assert_eq!(c.valid.iter().filter(|v| !**v).count(), 1);
    }
}
