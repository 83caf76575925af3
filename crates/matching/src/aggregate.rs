//! Semi-global aggregation of the cost volume along 8 (or 4) straight paths.
//!
//! For a path direction `r` and a pixel `p` with predecessor `p − r`:
//!
//! ```text
//! L(p, d) = C(p, d) + min( L(p−r, d), L(p−r, d±1) + P1, min_k L(p−r, k) + P2' ) − min_k L(p−r, k)
//! S(p, d) = Σ_r L_r(p, d)
//! ```
//!
//! with `L = C` where a path enters the image. `L ≤ C_max + P2`, so with 8 paths `S` fits in a
//! `u16` as long as `8 · (C_max + P2) < 65536` (checked by the caller).
//!
//! Scheme (memory-bounded, cache-friendly, parallel):
//!
//! * Horizontal paths: rows are independent; each row does left→right (assigning `S`) then
//!   right→left (adding), rows in parallel (disjoint `&mut` row slices, no `unsafe`).
//! * Vertical and diagonal paths: a top-down sweep (directions ↓, ↘, ↙) then a bottom-up sweep
//!   (↑, ↗, ↖). A sweep walks the rows in order and keeps, per path, the previous row's `L` in a
//!   line buffer (`width · (n + 2)` `u16`); the pixels of one row depend only on the previous
//!   row, so each row is split into x-chunks processed in parallel, each writing its own chunk of
//!   `S` and of the new line buffer (again plain disjoint slices).
//!
//! The per-pixel kernel ([`step`]) runs over the disparities of one pixel with slices and no
//! bounds checks; line buffers carry one `u16::MAX` sentinel at each end so `d ± 1` needs no
//! test. It auto-vectorises; on x86-64 the row functions are also compiled for AVX2 (16 `u16`
//! lanes, native unsigned min) and chosen at run time.

use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Smoothness penalties.
#[derive(Clone, Copy)]
pub(crate) struct Penalties<'a> {
    pub p1: u16,
    pub p2: u16,
    /// Gradient adaptation of P2: the left grey image normalised to a unit robust range, and `k`.
    /// `P2' = max(P1 + 1, P2 / (1 + |ΔI| / k))` with `ΔI` the normalised grey difference
    /// between the pixel and its predecessor on the path.
    pub adapt: Option<(&'a [f32], f32)>,
}

impl Penalties<'_> {
    /// `P2'` between pixels of flat indices `a` and `b`.
    #[inline]
    pub fn p2_between(&self, a: usize, b: usize) -> u16 {
        match self.adapt {
            None => self.p2,
            Some((g, k)) => {
                let dg = (g[a] - g[b]).abs();
                if dg.is_nan() {
                    return self.p2;
                }
                let p = (f32::from(self.p2) / (1.0 + dg / k)).round() as u16;
                p.max(self.p1 + 1).min(self.p2)
            }
        }
    }
}

/// One path step for one pixel.
///
/// `prev` is the predecessor's `L` with a sentinel at each end (`n + 2` values), `prev_min` its
/// minimum (`u16::MAX` with an all-`u16::MAX` `prev` starts a path: then `L = C`). Writes
/// `L(p, ·)` into `out[1..=n]`, adds it to (or, with `ASSIGN`, stores it in) `acc[..n]` and
/// returns `min_d L(p, d)`.
#[inline(always)]
fn step<const ASSIGN: bool>(
    cost: &[u8],
    prev: &[u16],
    prev_min: u16,
    p1: u16,
    p2: u16,
    out: &mut [u16],
    acc: &mut [u16],
) -> u16 {
    let n = cost.len();
    let lo = &prev[..n];
    let mid = &prev[1..n + 1];
    let hi = &prev[2..n + 2];
    let out = &mut out[1..n + 1];
    let acc = &mut acc[..n];
    let jump = prev_min.saturating_add(p2);
    let mut m = u16::MAX;
    for i in 0..n {
        let near = lo[i].min(hi[i]).saturating_add(p1);
        let v = mid[i]
            .min(near)
            .min(jump)
            .wrapping_sub(prev_min)
            .wrapping_add(u16::from(cost[i]));
        out[i] = v;
        acc[i] = if ASSIGN { v } else { acc[i].wrapping_add(v) };
        m = m.min(v);
    }
    m
}

/// Defines `$name(avx2, args…)`: `$imp(args…)` compiled with AVX2 enabled when `avx2` (checked
/// at run time by the caller), the portable build otherwise. The kernels are plain Rust that the
/// compiler vectorises for the wider registers.
macro_rules! avx2_dispatch {
    (fn $name:ident => $imp:ident ($($arg:ident: $ty:ty),* $(,)?)) => {
        fn $name(avx2: bool, $($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                #[target_feature(enable = "avx2")]
                unsafe fn fast($($arg: $ty),*) {
                    $imp($($arg),*)
                }
                // SAFETY: AVX2 support was checked at run time.
                unsafe { fast($($arg),*) };
                return;
            }
            let _ = avx2;
            $imp($($arg),*)
        }
    };
}
pub(crate) use avx2_dispatch;

/// Whether the AVX2 variants can run on this CPU (SGM's and MGM's).
#[inline]
pub(crate) fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Geometry of the volumes.
#[derive(Clone, Copy)]
pub(crate) struct Dims {
    pub width: usize,
    pub height: usize,
    pub n_disp: usize,
}

impl Dims {
    /// `(width, height, n_disp)`.
    #[inline(always)]
    pub fn sizes(self) -> (usize, usize, usize) {
        (self.width, self.height, self.n_disp)
    }

    /// Asserts that `cost` and `sum` are volumes of these dimensions; false when they are empty
    /// (nothing to aggregate).
    pub fn check_volumes(self, cost: &[u8], sum: &[u16]) -> bool {
        let len = self.width * self.height * self.n_disp;
        assert_eq!(cost.len(), len);
        assert_eq!(sum.len(), len);
        len != 0
    }
}

/// Aggregates `cost` into `sum` (both `height · width · n_disp`, `sum` fully overwritten).
/// `diagonals`: 8 paths when true, 4 (horizontal and vertical) otherwise. `tick` is called
/// once per row of each of the three stages.
pub(crate) fn aggregate(
    cost: &[u8],
    sum: &mut [u16],
    dims: Dims,
    pen: &Penalties,
    diagonals: bool,
    tick: &(dyn Fn() + Sync),
) {
    if !dims.check_volumes(cost, sum) {
        return;
    }
    let (w, n) = (dims.width, dims.n_disp);
    let avx2 = has_avx2();
    // The `u16::MAX` state before the first pixel of a row, shared by every row.
    let start = vec![u16::MAX; n + 2];
    sum.par_chunks_mut(w * n)
        .zip(cost.par_chunks(w * n))
        .enumerate()
        .for_each_init(
            || vec![u16::MAX; 2 * (n + 2)],
            |lines, (y, (srow, crow))| {
                let row = RowSweep {
                    crow,
                    n,
                    base: y * w,
                    pen,
                    start: &start,
                };
                horizontal_row(avx2, &row, srow, lines);
                tick();
            },
        );
    let npath = if diagonals { 3 } else { 1 };
    let mut sweep = Sweep {
        state: vec![u16::MAX; w * npath * (n + 2)],
        mins: vec![u16::MAX; w * npath],
        next: vec![u16::MAX; w * npath * (n + 2)],
        next_mins: vec![u16::MAX; w * npath],
        start: vec![u16::MAX; n + 2],
    };
    sweep.run(cost, sum, dims, pen, npath, true, avx2, tick);
    sweep.run(cost, sum, dims, pen, npath, false, avx2, tick);
}

avx2_dispatch! {
    fn horizontal_row => horizontal_row_impl(row: &RowSweep, srow: &mut [u16], lines: &mut [u16])
}

/// Left→right then right→left along one row. `lines` holds two line buffers of `n + 2` values,
/// all `u16::MAX` on entry (their sentinels stay so).
#[inline(always)]
fn horizontal_row_impl(row: &RowSweep, srow: &mut [u16], lines: &mut [u16]) {
    let w = srow.len() / row.n;
    let (a, b) = lines.split_at_mut(row.n + 2);
    // Left to right assigns, right to left adds.
    row.sweep::<true>(srow, a, b, 0..w, |x| x - 1);
    row.sweep::<false>(srow, a, b, (0..w).rev(), |x| x + 1);
}

/// One row of the cost volume swept in one sense.
struct RowSweep<'a> {
    crow: &'a [u8],
    n: usize,
    /// Index of the row's first pixel in the image (for the adaptive `P2`).
    base: usize,
    pen: &'a Penalties<'a>,
    /// The `u16::MAX` state before the first pixel.
    start: &'a [u16],
}

impl RowSweep<'_> {
    /// Visits the pixels `xs` in order, each after `prev(x)`; `ASSIGN` writes the path costs into
    /// `srow`, otherwise adds them. `a` and `b` are the line buffers.
    #[inline(always)]
    fn sweep<'b, const ASSIGN: bool>(
        &self,
        srow: &mut [u16],
        mut a: &'b mut [u16],
        mut b: &'b mut [u16],
        mut xs: impl Iterator<Item = usize>,
        prev: impl Fn(usize) -> usize,
    ) {
        let (n, pen) = (self.n, self.pen);
        let Some(x0) = xs.next() else { return };
        let mut pm = step::<ASSIGN>(
            &self.crow[x0 * n..(x0 + 1) * n],
            self.start,
            u16::MAX,
            pen.p1,
            pen.p2,
            a,
            &mut srow[x0 * n..(x0 + 1) * n],
        );
        for x in xs {
            let p2 = pen.p2_between(self.base + x, self.base + prev(x));
            pm = step::<ASSIGN>(
                &self.crow[x * n..(x + 1) * n],
                a,
                pm,
                pen.p1,
                p2,
                b,
                &mut srow[x * n..(x + 1) * n],
            );
            std::mem::swap(&mut a, &mut b);
        }
    }
}

/// Line buffers of a vertical sweep. Per pixel and path: `n + 2` values (sentinels at both
/// ends), pixel-major then path.
struct Sweep {
    state: Vec<u16>,
    mins: Vec<u16>,
    next: Vec<u16>,
    next_mins: Vec<u16>,
    /// All `u16::MAX`: the predecessor of a pixel where a path enters the image.
    start: Vec<u16>,
}

/// Read-only inputs of one row of a sweep.
struct RowCtx<'a> {
    crow: &'a [u8],
    /// Previous row's line buffers and minima, `None` on the first row of the sweep.
    prev: Option<(&'a [u16], &'a [u16])>,
    start: &'a [u16],
    /// Flat index of the row's first pixel and of the predecessor row's first pixel.
    base: usize,
    pred_base: usize,
    dims: Dims,
    npath: usize,
    pen: Penalties<'a>,
}

impl Sweep {
    #[allow(clippy::too_many_arguments)]
    fn run(
        &mut self,
        cost: &[u8],
        sum: &mut [u16],
        dims: Dims,
        pen: &Penalties,
        npath: usize,
        down: bool,
        avx2: bool,
        tick: &(dyn Fn() + Sync),
    ) {
        let (w, h, n) = dims.sizes();
        let np = n + 2;
        // Enough chunks to balance threads, few enough to keep the per-row join cheap.
        let threads = rayon::current_num_threads().max(1);
        let chunk = w.div_ceil(threads * 2).max(16).min(w);
        for i in 0..h {
            let y = if down { i } else { h - 1 - i };
            let pred_y = if down { y.wrapping_sub(1) } else { y + 1 };
            let ctx = RowCtx {
                crow: &cost[y * w * n..(y + 1) * w * n],
                prev: (i > 0).then_some((&self.state[..], &self.mins[..])),
                start: &self.start,
                base: y * w,
                pred_base: pred_y.wrapping_mul(w),
                dims,
                npath,
                pen: *pen,
            };
            let srow = &mut sum[y * w * n..(y + 1) * w * n];
            if chunk >= w {
                sweep_chunk(avx2, &ctx, 0, srow, &mut self.next, &mut self.next_mins);
            } else {
                srow.par_chunks_mut(chunk * n)
                    .zip(self.next.par_chunks_mut(chunk * npath * np))
                    .zip(self.next_mins.par_chunks_mut(chunk * npath))
                    .enumerate()
                    .for_each(|(c, ((s, st), mn))| sweep_chunk(avx2, &ctx, c * chunk, s, st, mn));
            }
            std::mem::swap(&mut self.state, &mut self.next);
            std::mem::swap(&mut self.mins, &mut self.next_mins);
            tick();
        }
    }
}

avx2_dispatch! {
    fn sweep_chunk => sweep_chunk_impl(
        ctx: &RowCtx,
        x0: usize,
        s: &mut [u16],
        state: &mut [u16],
        mins: &mut [u16],
    )
}

/// Pixels `x0 .. x0 + s.len() / n` of one sweep row: path 0 comes from `(x, pred_y)`, path 1
/// from `(x − 1, pred_y)`, path 2 from `(x + 1, pred_y)`.
#[inline(always)]
fn sweep_chunk_impl(ctx: &RowCtx, x0: usize, s: &mut [u16], state: &mut [u16], mins: &mut [u16]) {
    let Dims {
        width: w,
        n_disp: n,
        ..
    } = ctx.dims;
    let np = n + 2;
    let npath = ctx.npath;
    let pen = &ctx.pen;
    for (i, ((sx, st), mn)) in s
        .chunks_exact_mut(n)
        .zip(state.chunks_exact_mut(npath * np))
        .zip(mins.chunks_exact_mut(npath))
        .enumerate()
    {
        let x = x0 + i;
        let cx = &ctx.crow[x * n..(x + 1) * n];
        for (j, (out, m)) in st.chunks_exact_mut(np).zip(mn.iter_mut()).enumerate() {
            let px = match j {
                0 => Some(x),
                1 => x.checked_sub(1),
                _ => Some(x + 1).filter(|&v| v < w),
            };
            let (prev, pm, p2) = match (ctx.prev, px) {
                (Some((state, mins)), Some(px)) => {
                    let k = px * npath + j;
                    (
                        &state[k * np..(k + 1) * np],
                        mins[k],
                        pen.p2_between(ctx.base + x, ctx.pred_base + px),
                    )
                }
                _ => (ctx.start, u16::MAX, pen.p2),
            };
            *m = step::<false>(cx, prev, pm, pen.p1, p2, out, sx);
        }
    }
}

/// The penalties (P1 7, P2 90, optionally adapted to `grey`) and dimensions of the
/// aggregation tests of SGM and MGM.
#[cfg(test)]
pub(crate) fn test_setup(
    grey: &[f32],
    adapt: bool,
    (width, height, n_disp): (usize, usize, usize),
) -> (Penalties<'_>, Dims) {
    let pen = Penalties {
        p1: 7,
        p2: 90,
        adapt: adapt.then_some((grey, 0.1)),
    };
    let dims = Dims {
        width,
        height,
        n_disp,
    };
    (pen, dims)
}

/// A seeded random cost volume (`w · h · n`, 0..63) and grey image (`w · h`, 0..1) for the
/// aggregation tests of SGM and MGM.
#[cfg(test)]
pub(crate) fn random_inputs(w: usize, h: usize, n: usize, mut seed: u64) -> (Vec<u8>, Vec<f32>) {
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 33) as u32
    };
    let cost: Vec<u8> = (0..w * h * n).map(|_| (rnd() % 63) as u8).collect();
    let grey: Vec<f32> = (0..w * h).map(|_| (rnd() % 100) as f32 / 100.0).collect();
    (cost, grey)
}

/// Counts ticks and forwards progress as `(done, total)`.
pub(crate) struct Progress<'a> {
    done: AtomicUsize,
    total: usize,
    callback: Option<&'a (dyn Fn(usize, usize) + Sync)>,
}

impl<'a> Progress<'a> {
    pub fn new(total: usize, callback: Option<&'a (dyn Fn(usize, usize) + Sync)>) -> Self {
        Self {
            done: AtomicUsize::new(0),
            total,
            callback,
        }
    }

    pub fn tick(&self) {
        if let Some(cb) = self.callback {
            let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
            cb(done.min(self.total), self.total);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Straightforward SGM in `i64`, one direction at a time.
    fn reference(cost: &[u8], dims: Dims, pen: &Penalties, diagonals: bool) -> Vec<u16> {
        let (w, h, n) = dims.sizes();
        let mut dirs = vec![(1i64, 0i64), (-1, 0), (0, 1), (0, -1)];
        if diagonals {
            dirs.extend([(1, 1), (-1, 1), (1, -1), (-1, -1)]);
        }
        let mut total = vec![0i64; w * h * n];
        for (dx, dy) in dirs {
            let mut l = vec![0i64; w * h * n];
            let ys: Vec<usize> = if dy >= 0 {
                (0..h).collect()
            } else {
                (0..h).rev().collect()
            };
            let xs: Vec<usize> = if dx >= 0 {
                (0..w).collect()
            } else {
                (0..w).rev().collect()
            };
            for &y in &ys {
                for &x in &xs {
                    let (qx, qy) = (x as i64 - dx, y as i64 - dy);
                    let p = y * w + x;
                    for d in 0..n {
                        l[p * n + d] = i64::from(cost[p * n + d]);
                    }
                    if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                        continue;
                    }
                    let q = qy as usize * w + qx as usize;
                    let lq = l[q * n..(q + 1) * n].to_vec();
                    let mq = *lq.iter().min().unwrap();
                    let p1 = i64::from(pen.p1);
                    let p2 = i64::from(pen.p2_between(p, q));
                    for d in 0..n {
                        let mut best = lq[d].min(mq + p2);
                        if d > 0 {
                            best = best.min(lq[d - 1] + p1);
                        }
                        if d + 1 < n {
                            best = best.min(lq[d + 1] + p1);
                        }
                        l[p * n + d] += best - mq;
                    }
                }
            }
            for (t, v) in total.iter_mut().zip(&l) {
                *t += v;
            }
        }
        total.into_iter().map(|v| v as u16).collect()
    }

    fn check(w: usize, h: usize, n: usize, diagonals: bool, adapt: bool) {
        let (cost, grey) = random_inputs(w, h, n, 12345);
        let (pen, dims) = test_setup(&grey, adapt, (w, h, n));
        let mut sum = vec![0u16; w * h * n];
        aggregate(&cost, &mut sum, dims, &pen, diagonals, &|| {});
        assert_eq!(sum, reference(&cost, dims, &pen, diagonals));
    }

    #[test]
    fn matches_reference_eight_paths() {
        check(37, 23, 13, true, false);
        check(37, 23, 13, true, true);
        // Wide enough rows to be split into parallel chunks.
        check(300, 5, 5, true, true);
    }

    #[test]
    fn matches_reference_four_paths_and_tiny() {
        check(19, 11, 8, false, false);
        check(1, 1, 1, true, false);
        check(1, 7, 3, true, true);
        check(7, 1, 3, true, true);
    }
}
