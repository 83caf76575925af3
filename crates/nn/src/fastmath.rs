//! `exp`, the logistic sigmoid and `tanh` on `f32` without calls into libm, so that loops over
//! them vectorise.
//!
//! Why: the ConvGRU's gates (`σ` twice, `tanh` once per hidden value, every iteration) spent a
//! visible share of a MonSter++ pass in scalar libm calls (BENCHMARKS.md, "MonSter++ against
//! PyTorch, and where the time goes"). These stay within a few ulp of libm's (`exp`:
//! relative 3e-7; `tanh`: absolute 2e-7), far inside the parity tolerances.

/// `eˣ` (Cephes' range reduction and polynomial): relative error ≤ 3e-7 on `[−87, 88]`; inputs
/// outside are clamped (0 < result < 2.2e38, never infinite).
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 in two parts: n·LN2_HI is exact for the n that occur.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // Adding and subtracting 1.5·2²³ rounds to the nearest integer without a libm call.
    const ROUND: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let n = (x * LOG2E + ROUND) - ROUND;
    let r = x - n * LN2_HI - n * LN2_LO;
    let p = 1.987_569_1e-4;
    let p = p * r + 1.398_199_9e-3;
    let p = p * r + 8.333_452e-3;
    let p = p * r + 4.166_579_6e-2;
    let p = p * r + 1.666_666_5e-1;
    let p = p * r + 0.5;
    let y = p * r * r + r + 1.0;
    y * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

/// `1 / (1 + e⁻ˣ)`.
#[inline(always)]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp(-x))
}

/// `tanh x`: `(1 − e^{−2|x|}) / (1 + e^{−2|x|})` with the sign restored, and its Taylor series
/// near 0, where that quotient would lose the relative precision of small values.
#[inline(always)]
pub fn tanh(x: f32) -> f32 {
    let a = x.abs();
    let t = exp(-2.0 * a);
    let far = (1.0 - t) / (1.0 + t);
    let a2 = a * a;
    // x − x³/3 + 2x⁵/15 − 17x⁷/315 + 62x⁹/2835: truncation below 1e-9 relative for |x| < 0.125.
    let near = a
        * (1.0
            + a2 * (-1.0 / 3.0 + a2 * (2.0 / 15.0 + a2 * (-17.0 / 315.0 + a2 * (62.0 / 2835.0)))));
    let y = if a < 0.125 { near } else { far };
    y.copysign(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples() -> impl Iterator<Item = f32> {
        (0..=200_000).map(|i| -100.0 + i as f32 * 1e-3)
    }

    #[test]
    fn exp_matches_libm() {
        let worst = samples()
            .filter(|x| (-87.0..=88.0).contains(x))
            .map(|x| ((exp(x) as f64 - (x as f64).exp()) / (x as f64).exp()).abs())
            .fold(0.0, f64::max);
        assert!(worst < 3e-7, "relative error {worst:e}");
        assert!(exp(-1000.0) >= 0.0 && exp(1000.0).is_finite());
    }

    #[test]
    fn sigmoid_and_tanh_match_libm() {
        let mut worst = [0.0f64; 2];
        for x in samples().chain((0..2000).map(|i| i as f32 * 1e-4 - 0.1)) {
            let xs = x as f64;
            worst[0] = worst[0].max((sigmoid(x) as f64 - 1.0 / (1.0 + (-xs).exp())).abs());
            worst[1] = worst[1].max((tanh(x) as f64 - xs.tanh()).abs());
            let small = x.abs() < 0.125 && x != 0.0;
            if small {
                let rel = ((tanh(x) as f64 - xs.tanh()) / xs.tanh()).abs();
                assert!(rel < 1e-6, "tanh({x}) relative error {rel:e}");
            }
        }
        assert!(worst[0] < 1.5e-7, "sigmoid absolute error {:e}", worst[0]);
        assert!(worst[1] < 2e-7, "tanh absolute error {:e}", worst[1]);
        assert_eq!(tanh(0.0), 0.0);
        assert_eq!(tanh(-30.0), -1.0);
    }
}
