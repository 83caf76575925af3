//! From per-pair statistics to the selected pairs: the dataset-wide colour normalisation, the two
//! rankings and the intersection of their top-K (paper Sec. 3.1).

use std::cmp::Ordering;

/// The `q`-th percentile (0–100) of `values` with numpy's default (`method='linear'`):
/// sorted `v`, position `(n − 1)·q/100`, linear interpolation between its two neighbours. NaN
/// values must be removed first; `None` for an empty slice. Sorts `values` in place.
pub fn percentile_linear(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(|a, b| a.partial_cmp(b).unwrap_or(Ordering::Equal));
    let pos = (values.len() - 1) as f64 * (q / 100.0).clamp(0.0, 1.0);
    let lo = pos.floor() as usize;
    let hi = (lo + 1).min(values.len() - 1);
    let f = pos - lo as f64;
    Some(values[lo] + (values[hi] - values[lo]) * f)
}

/// `d_max`: the `q`-th percentile of the finite colour distances; as in the release, 1.0 when
/// that percentile is not positive (all pairs identical), so `S_color` never divides by zero.
/// `None` when no distance is finite.
pub fn colour_normaliser(distances: &[f64], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = distances
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .collect();
    let p = percentile_linear(&mut v, q)?;
    Some(if p > 0.0 { p } else { 1.0 })
}

/// `S_color = 1 − min(d_color, d_max)/d_max`.
pub fn colour_score(d_color: f64, d_max: f64) -> f64 {
    1.0 - d_color.min(d_max) / d_max
}

/// 1-based ranks by decreasing score, ties broken by the name (the release sorts by
/// `(−value, …, id)`); non-finite scores get no rank.
pub fn rank_desc(scores: &[f64], names: &[&str]) -> Vec<Option<usize>> {
    let mut order: Vec<usize> = (0..scores.len())
        .filter(|&i| scores[i].is_finite())
        .collect();
    order.sort_by(|&a, &b| {
        scores[b]
            .partial_cmp(&scores[a])
            .unwrap_or(Ordering::Equal)
            .then_with(|| names[a].cmp(names[b]))
    });
    let mut ranks = vec![None; scores.len()];
    for (r, &i) in order.iter().enumerate() {
        ranks[i] = Some(r + 1);
    }
    ranks
}

/// How many pairs each ranking keeps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Keep {
    /// The K best (paper: 1000 of 1,565).
    Count(usize),
    /// This share of the ranked pairs, K = round(share · N) (at least 1 when N > 0).
    Fraction(f64),
}

impl Keep {
    /// K for `ranked` pairs with finite scores (never more than `ranked`).
    pub fn k(&self, ranked: usize) -> usize {
        match *self {
            Keep::Count(k) => k.min(ranked),
            Keep::Fraction(f) => {
                let k = (f.clamp(0.0, 1.0) * ranked as f64).round() as usize;
                if ranked > 0 {
                    k.clamp(1, ranked)
                } else {
                    0
                }
            }
        }
    }

    /// Parses `K` (an integer) or `F%` / a fraction in (0, 1) such as `0.64`.
    pub fn parse(s: &str) -> Result<Keep, String> {
        let s = s.trim();
        if let Some(p) = s.strip_suffix('%') {
            let v: f64 = p
                .trim()
                .parse()
                .map_err(|e| format!("{s:?}: expected a percentage such as 64%: {e}"))?;
            if !(v > 0.0 && v <= 100.0) {
                return Err(format!("{s:?}: the percentage must be in (0, 100]"));
            }
            return Ok(Keep::Fraction(v / 100.0));
        }
        if let Ok(k) = s.parse::<usize>() {
            if k == 0 {
                return Err("K must be at least 1".into());
            }
            return Ok(Keep::Count(k));
        }
        match s.parse::<f64>() {
            Ok(f) if f > 0.0 && f < 1.0 => Ok(Keep::Fraction(f)),
            _ => Err(format!(
                "{s:?}: expected a count (1000), a percentage (64%) or a fraction in (0, 1) (0.64)"
            )),
        }
    }

    pub fn describe(&self) -> String {
        match self {
            Keep::Count(k) => format!("top {k}"),
            Keep::Fraction(f) => format!("top {:.1} %", 100.0 * f),
        }
    }
}

/// The rank at which a pair enters the intersection of the two top-K sets: it is selected for
/// every K ≥ max(rank_comb, rank_feat). `None` when either rank is missing.
pub fn joint_rank(a: Option<usize>, b: Option<usize>) -> Option<usize> {
    Some(a?.max(b?))
}

/// ROC AUC of `scores` separating `positive` items (higher score = more likely positive): the
/// probability that a random positive outscores a random negative, ties counting one half
/// (Mann–Whitney). `None` without both classes.
pub fn roc_auc(scores: &[f64], positive: &[bool]) -> Option<f64> {
    let pos: Vec<f64> = scores
        .iter()
        .zip(positive)
        .filter(|(_, &p)| p)
        .map(|(&s, _)| s)
        .collect();
    let neg: Vec<f64> = scores
        .iter()
        .zip(positive)
        .filter(|(_, &p)| !p)
        .map(|(&s, _)| s)
        .collect();
    if pos.is_empty() || neg.is_empty() {
        return None;
    }
    let mut wins = 0.0;
    for p in &pos {
        for n in &neg {
            wins += match p.partial_cmp(n) {
                Some(Ordering::Greater) => 1.0,
                Some(Ordering::Equal) => 0.5,
                _ => 0.0,
            };
        }
    }
    Some(wins / (pos.len() * neg.len()) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_is_numpy_linear() {
        // np.percentile([1, 2, 3, 4, 10], 95) = 8.8; np.percentile([5], 95) = 5.
        assert!(
            (percentile_linear(&mut [10.0, 2.0, 1.0, 4.0, 3.0], 95.0).unwrap() - 8.8).abs() < 1e-12
        );
        assert_eq!(percentile_linear(&mut [5.0], 95.0), Some(5.0));
        assert_eq!(percentile_linear(&mut [], 95.0), None);
        assert_eq!(colour_normaliser(&[0.0, 0.0, f64::NAN], 95.0), Some(1.0));
        assert_eq!(colour_normaliser(&[f64::NAN], 95.0), None);
        assert_eq!(colour_score(30.0, 20.0), 0.0);
        assert_eq!(colour_score(5.0, 20.0), 0.75);
    }

    #[test]
    fn ranks_keep_and_auc() {
        let r = rank_desc(&[0.5, 0.9, f64::NAN, 0.5], &["b", "a", "c", "a2"]);
        assert_eq!(r, vec![Some(3), Some(1), None, Some(2)]);
        assert_eq!(Keep::parse("1000"), Ok(Keep::Count(1000)));
        assert_eq!(Keep::parse("64%"), Ok(Keep::Fraction(0.64)));
        assert_eq!(Keep::parse("0.5"), Ok(Keep::Fraction(0.5)));
        assert!(
            Keep::parse("0").is_err() && Keep::parse("1.5").is_err() && Keep::parse("x").is_err()
        );
        assert_eq!(Keep::Count(1000).k(1565), 1000);
        assert_eq!(Keep::Count(1000).k(10), 10);
        assert_eq!(Keep::Fraction(0.64).k(1565), 1002);
        assert_eq!(Keep::Fraction(0.01).k(10), 1);
        assert_eq!(joint_rank(Some(3), Some(7)), Some(7));
        assert_eq!(joint_rank(None, Some(7)), None);
        assert_eq!(roc_auc(&[3.0, 2.0, 1.0], &[true, false, false]), Some(1.0));
        assert_eq!(roc_auc(&[1.0, 2.0, 1.0], &[true, false, false]), Some(0.25));
        assert_eq!(roc_auc(&[1.0], &[true]), None);
    }
}
