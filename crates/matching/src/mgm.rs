//! More Global Matching (Facciolo, de Franchis, Meinhardt, BMVC 2015): SGM whose path recursion
//! averages two predecessors instead of following one straight line.
//!
//! For a direction `r` and its perpendicular `r⊥` (`r` turned by +90° in image coordinates):
//!
//! ```text
//! T_q(d)   = min( L(q, d), L(q, d±1) + P1, min_k L(q, k) + P2' ) − min_k L(q, k)
//! L(p, d)  = C(p, d) + ½ (T_{p−r}(d) + T_{p−r⊥}(d))      (one term where only one q exists)
//! S(p, d)  = Σ_r L_r(p, d)                                 (8 directions)
//! ```
//!
//! Why: each pixel's cost then depends on a 2-D quadrant of the image instead of 8 lines, which
//! removes SGM's streaks and most of the small wrong islands it leaves on weakly textured or
//! changed (multi-date) surfaces. This is the matcher s2p runs on satellite pairs.
//!
//! Scheme: every direction is a scan of "lines" (rows or columns) that keeps the previous line's
//! `L` in a line buffer (`len · (n + 2)` `u16`, sentinels at both ends):
//!
//! * axis directions (→ ← ↓ ↑): predecessors are the previous pixel of the same row and the same
//!   pixel of the previous row, so a row is scanned pixel after pixel;
//! * diagonal directions: both predecessors lie on the previous line (at ±1 along it), so the
//!   pixels of a line are independent and processed in parallel chunks.
//!
//! Memory is that of SGM: the `u8` cost and `u16` sum volumes plus line buffers.

use crate::aggregate::{avx2_dispatch, has_avx2, Dims, Penalties};
use rayon::prelude::*;

/// The two predecessors' terms averaged (or the one that exists), plus the cost: the kernel of
/// one pixel. `a`/`b` are the predecessors' `L` with sentinels (`n + 2` values) and their minima;
/// `p2a`/`p2b` their adapted `P2`. Writes `L(p, ·)` into `out[1..=n]`, adds it to `acc` and
/// returns its minimum.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn step2(
    cost: &[u8],
    a: Option<(&[u16], u16, u16)>,
    b: Option<(&[u16], u16, u16)>,
    p1: u16,
    out: &mut [u16],
    acc: &mut [u16],
) -> u16 {
    let n = cost.len();
    let out = &mut out[1..n + 1];
    let acc = &mut acc[..n];
    let mut m = u16::MAX;
    match (a, b) {
        (Some((pa, ma, p2a)), Some((pb, mb, p2b))) => {
            let (alo, amid, ahi) = (&pa[..n], &pa[1..n + 1], &pa[2..n + 2]);
            let (blo, bmid, bhi) = (&pb[..n], &pb[1..n + 1], &pb[2..n + 2]);
            let (ja, jb) = (ma.saturating_add(p2a), mb.saturating_add(p2b));
            for i in 0..n {
                let ta = amid[i]
                    .min(alo[i].min(ahi[i]).saturating_add(p1))
                    .min(ja)
                    .wrapping_sub(ma);
                let tb = bmid[i]
                    .min(blo[i].min(bhi[i]).saturating_add(p1))
                    .min(jb)
                    .wrapping_sub(mb);
                let v = ((ta + tb) >> 1) + u16::from(cost[i]);
                out[i] = v;
                acc[i] = acc[i].wrapping_add(v);
                m = m.min(v);
            }
        }
        (Some((p, mq, p2)), None) | (None, Some((p, mq, p2))) => {
            let (lo, mid, hi) = (&p[..n], &p[1..n + 1], &p[2..n + 2]);
            let j = mq.saturating_add(p2);
            for i in 0..n {
                let t = mid[i]
                    .min(lo[i].min(hi[i]).saturating_add(p1))
                    .min(j)
                    .wrapping_sub(mq);
                let v = t + u16::from(cost[i]);
                out[i] = v;
                acc[i] = acc[i].wrapping_add(v);
                m = m.min(v);
            }
        }
        (None, None) => {
            for i in 0..n {
                let v = u16::from(cost[i]);
                out[i] = v;
                acc[i] = acc[i].wrapping_add(v);
                m = m.min(v);
            }
        }
    }
    m
}

/// One scan direction: which image axis the lines run along and the senses of the scan.
#[derive(Clone, Copy, Debug)]
struct Scan {
    /// Lines are rows (true) or columns (false).
    rows: bool,
    /// Lines are visited in increasing order of their index (y for rows, x for columns).
    forward_lines: bool,
    /// Axis kind only: pixels of a line are visited in increasing order.
    forward_pixels: bool,
    /// Axis kind (predecessors: previous pixel on the line, same pixel on the previous line) or
    /// diagonal kind (predecessors: ±1 on the previous line).
    axis: bool,
}

/// The 8 directions of MGM as scans (see the module doc for the predecessors of each).
const SCANS: [Scan; 8] = [
    // → : left and up.
    Scan {
        rows: true,
        forward_lines: true,
        forward_pixels: true,
        axis: true,
    },
    // ← : right and down.
    Scan {
        rows: true,
        forward_lines: false,
        forward_pixels: false,
        axis: true,
    },
    // ↓ : up and right.
    Scan {
        rows: true,
        forward_lines: true,
        forward_pixels: false,
        axis: true,
    },
    // ↑ : down and left.
    Scan {
        rows: true,
        forward_lines: false,
        forward_pixels: true,
        axis: true,
    },
    // ↘ : up-left and up-right.
    Scan {
        rows: true,
        forward_lines: true,
        forward_pixels: true,
        axis: false,
    },
    // ↖ : down-right and down-left.
    Scan {
        rows: true,
        forward_lines: false,
        forward_pixels: true,
        axis: false,
    },
    // ↙ : up-right and down-right.
    Scan {
        rows: false,
        forward_lines: false,
        forward_pixels: true,
        axis: false,
    },
    // ↗ : up-left and down-left.
    Scan {
        rows: false,
        forward_lines: true,
        forward_pixels: true,
        axis: false,
    },
];

/// Aggregates `cost` into `sum` over the 8 MGM directions (`sum` is overwritten). `tick` is
/// called 3 times per row in all (progress), as SGM's aggregation does.
pub(crate) fn aggregate_mgm(
    cost: &[u8],
    sum: &mut [u16],
    dims: Dims,
    pen: &Penalties,
    tick: &(dyn Fn() + Sync),
) {
    if !dims.check_volumes(cost, sum) {
        return;
    }
    sum.fill(0);
    let h = dims.height;
    let avx2 = has_avx2();
    for (i, scan) in SCANS.iter().enumerate() {
        let ticks = if i % 3 == 0 { h } else { 0 };
        run_scan(avx2, cost, sum, dims, pen, *scan);
        for _ in 0..ticks {
            tick();
        }
    }
}

avx2_dispatch! {
    fn run_scan => run_scan_impl(
        cost: &[u8],
        sum: &mut [u16],
        dims: Dims,
        pen: &Penalties,
        scan: Scan,
    )
}

/// A raw view of the sum volume shared by the parallel chunks of one line: each pixel is written
/// by exactly one chunk.
#[derive(Clone, Copy)]
struct SumPtr(*mut u16);
// SAFETY: chunks of one line write disjoint pixels; lines are processed one after the other.
unsafe impl Send for SumPtr {}
unsafe impl Sync for SumPtr {}

impl SumPtr {
    /// The `n` values of pixel `p`.
    ///
    /// # Safety
    /// `(p + 1) · n` must not exceed the volume's length, and no other live slice may cover
    /// pixel `p`.
    #[allow(clippy::mut_from_ref)]
    unsafe fn pixel(&self, p: usize, n: usize) -> &mut [u16] {
        std::slice::from_raw_parts_mut(self.0.add(p * n), n)
    }
}

#[inline(always)]
fn run_scan_impl(cost: &[u8], sum: &mut [u16], dims: Dims, pen: &Penalties, scan: Scan) {
    let (w, h, n) = dims.sizes();
    let np = n + 2;
    let (n_lines, len) = if scan.rows { (h, w) } else { (w, h) };
    // Flat pixel index of position `v` on line `u`.
    let pixel = |u: usize, v: usize| if scan.rows { u * w + v } else { v * w + u };
    let mut prev = vec![u16::MAX; len * np];
    let mut prev_min = vec![u16::MAX; len];
    let mut cur = vec![u16::MAX; len * np];
    let mut cur_min = vec![u16::MAX; len];
    let sum_ptr = SumPtr(sum.as_mut_ptr());
    let sum_len = sum.len();
    for li in 0..n_lines {
        let u = if scan.forward_lines {
            li
        } else {
            n_lines - 1 - li
        };
        let has_prev = li > 0;
        let pred_u = if scan.forward_lines {
            u.wrapping_sub(1)
        } else {
            u + 1
        };
        if scan.axis {
            // Sequential along the line.
            let mut last: Option<usize> = None;
            for vi in 0..len {
                let v = if scan.forward_pixels {
                    vi
                } else {
                    len - 1 - vi
                };
                let p = pixel(u, v);
                let c = &cost[p * n..(p + 1) * n];
                let (before, rest) = cur.split_at_mut(v * np);
                let (out, after) = rest.split_at_mut(np);
                let a = last.map(|lv| {
                    let buf: &[u16] = if lv < v {
                        &before[lv * np..(lv + 1) * np]
                    } else {
                        &after[(lv - v - 1) * np..(lv - v) * np]
                    };
                    (buf, cur_min[lv], pen.p2_between(p, pixel(u, lv)))
                });
                let b = has_prev.then(|| {
                    (
                        &prev[v * np..(v + 1) * np],
                        prev_min[v],
                        pen.p2_between(p, pixel(pred_u, v)),
                    )
                });
                // SAFETY: p < w·h; this loop is the only writer.
                let acc = unsafe { sum_ptr.pixel(p, n) };
                debug_assert!((p + 1) * n <= sum_len);
                cur_min[v] = step2(c, a, b, pen.p1, out, acc);
                last = Some(v);
            }
        } else {
            let threads = rayon::current_num_threads().max(1);
            let chunk = len.div_ceil(threads * 2).max(32).min(len);
            let (prev, prev_min) = (&prev[..], &prev_min[..]);
            cur.par_chunks_mut(chunk * np)
                .zip(cur_min.par_chunks_mut(chunk))
                .enumerate()
                .for_each(|(ci, (cbuf, cmin))| {
                    for (k, (out, m)) in cbuf.chunks_exact_mut(np).zip(cmin.iter_mut()).enumerate()
                    {
                        let v = ci * chunk + k;
                        let p = pixel(u, v);
                        let c = &cost[p * n..(p + 1) * n];
                        let pred = |q: Option<usize>| {
                            q.filter(|&q| has_prev && q < len).map(|q| {
                                (
                                    &prev[q * np..(q + 1) * np],
                                    prev_min[q],
                                    pen.p2_between(p, pixel(pred_u, q)),
                                )
                            })
                        };
                        let a = pred(v.checked_sub(1));
                        let b = pred(Some(v + 1));
                        // SAFETY: p < w·h and each pixel of this line belongs to one chunk.
                        let acc = unsafe { sum_ptr.pixel(p, n) };
                        debug_assert!((p + 1) * n <= sum_len);
                        *m = step2(c, a, b, pen.p1, out, acc);
                    }
                });
        }
        std::mem::swap(&mut prev, &mut cur);
        std::mem::swap(&mut prev_min, &mut cur_min);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// MGM written out directly in `i64`: every direction with its two predecessors, a full
    /// `L` volume per direction, pixels in an order where predecessors come first.
    fn reference(cost: &[u8], dims: Dims, pen: &Penalties) -> Vec<u16> {
        let (w, h, n) = dims.sizes();
        let dirs = raster::geometry::EIGHT_DIRECTIONS;
        let mut total = vec![0i64; w * h * n];
        for (rx, ry) in dirs {
            // r⊥ = (−ry, rx): +90° in image coordinates.
            let preds = [(rx, ry), (-ry, rx)];
            let mut l = vec![i64::MIN; w * h * n];
            // Relax until every pixel is computed: a pixel is ready when its in-image
            // predecessors are.
            let mut remaining = w * h;
            while remaining > 0 {
                for y in 0..h {
                    for x in 0..w {
                        let p = y * w + x;
                        if l[p * n] != i64::MIN {
                            continue;
                        }
                        let qs: Vec<usize> = preds
                            .iter()
                            .filter_map(|&(dx, dy)| {
                                let (qx, qy) = (x as i64 - dx, y as i64 - dy);
                                (qx >= 0 && qy >= 0 && qx < w as i64 && qy < h as i64)
                                    .then(|| qy as usize * w + qx as usize)
                            })
                            .collect();
                        if qs.iter().any(|&q| l[q * n] == i64::MIN) {
                            continue;
                        }
                        let mut terms = vec![0i64; n];
                        for &q in &qs {
                            let lq = &l[q * n..(q + 1) * n];
                            let mq = *lq.iter().min().unwrap();
                            let p2 = i64::from(pen.p2_between(p, q));
                            for (d, t) in terms.iter_mut().enumerate() {
                                let mut best = lq[d].min(mq + p2);
                                if d > 0 {
                                    best = best.min(lq[d - 1] + i64::from(pen.p1));
                                }
                                if d + 1 < n {
                                    best = best.min(lq[d + 1] + i64::from(pen.p1));
                                }
                                *t += best - mq;
                            }
                        }
                        for d in 0..n {
                            let t = if qs.len() == 2 {
                                terms[d] >> 1
                            } else {
                                terms[d]
                            };
                            l[p * n + d] = i64::from(cost[p * n + d]) + t;
                        }
                        remaining -= 1;
                    }
                }
            }
            for (t, v) in total.iter_mut().zip(&l) {
                *t += v;
            }
        }
        total.into_iter().map(|v| v as u16).collect()
    }

    fn check(w: usize, h: usize, n: usize, adapt: bool) {
        let (cost, grey) = crate::aggregate::random_inputs(w, h, n, 987);
        let (pen, dims) = crate::aggregate::test_setup(&grey, adapt, (w, h, n));
        let mut sum = vec![7u16; w * h * n];
        aggregate_mgm(&cost, &mut sum, dims, &pen, &|| {});
        assert_eq!(sum, reference(&cost, dims, &pen), "{w}x{h}x{n}");
    }

    #[test]
    fn matches_the_direct_definition() {
        check(23, 17, 9, false);
        check(23, 17, 9, true);
        // Lines long enough to be cut into parallel chunks.
        check(130, 70, 4, true);
        check(1, 1, 1, false);
        check(1, 9, 3, true);
        check(9, 1, 3, true);
    }
}
