//! How the views' colours of one cell become the orthoimage's colour.

use super::view::OrthoBlend;

/// One view's colour of a cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Sample {
    pub rgb: [u8; 3],
    /// Whether the view sees the cell (its colour is the cell's, not an occluder's).
    pub seen: bool,
}

/// Working memory of [`OrthoBlend::pick`], one per thread.
#[derive(Default)]
pub(super) struct Scratch {
    samples: Vec<Sample>,
    levels: Vec<u8>,
}

impl OrthoBlend {
    /// The colour of a cell from its samples, given from the most nadir view to the most
    /// oblique and computed as they are pulled (the most nadir view that sees the cell ends
    /// [`OrthoBlend::MostNadir`]'s search); `None` without samples. Views that see the cell
    /// are used; when none does, all of them (better an occluder's colour than a hole).
    pub(super) fn pick(
        self,
        mut samples: impl Iterator<Item = Sample>,
        scratch: &mut Scratch,
    ) -> Option<[u8; 3]> {
        match self {
            OrthoBlend::MostNadir => {
                let first = samples.next()?;
                if first.seen {
                    return Some(first.rgb);
                }
                Some(samples.find(|s| s.seen).unwrap_or(first).rgb)
            }
            OrthoBlend::Median => {
                scratch.samples.clear();
                scratch.samples.extend(samples);
                let any_seen = scratch.samples.iter().any(|s| s.seen);
                let mut out = [0u8; 3];
                for (c, o) in out.iter_mut().enumerate() {
                    scratch.levels.clear();
                    let used = scratch.samples.iter().filter(|s| s.seen || !any_seen);
                    scratch.levels.extend(used.map(|s| s.rgb[c]));
                    *o = median(&mut scratch.levels)?;
                }
                Some(out)
            }
        }
    }
}

/// The median of `values` (the mean of the two middle ones for an even count, rounded).
fn median(values: &mut [u8]) -> Option<u8> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    values.sort_unstable();
    let (a, b) = (values[(n - 1) / 2] as u16, values[n / 2] as u16);
    Some((a + b).div_ceil(2) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(v: u8, seen: bool) -> Sample {
        Sample {
            rgb: [v, v + 1, v + 2],
            seen,
        }
    }

    #[test]
    fn most_nadir_takes_the_first_view_that_sees_the_cell() {
        let mut scratch = Scratch::default();
        let mut pick = |s: &[Sample]| OrthoBlend::MostNadir.pick(s.iter().copied(), &mut scratch);
        let samples = [sample(10, false), sample(90, true), sample(50, true)];
        assert_eq!(pick(&samples), Some([90, 91, 92]));
        // Nobody sees it: the most nadir view all the same.
        assert_eq!(
            pick(&[sample(50, false), sample(10, false)]),
            Some([50, 51, 52])
        );
        assert_eq!(pick(&[]), None);
        // Samples after the first that sees the cell are never computed.
        let mut pulled = 0;
        let lazy = [sample(10, true), sample(20, true)]
            .into_iter()
            .inspect(|_| pulled += 1);
        OrthoBlend::MostNadir.pick(lazy, &mut Scratch::default());
        assert_eq!(pulled, 1);
    }

    #[test]
    fn median_is_per_channel_over_the_views_that_see() {
        let mut scratch = Scratch::default();
        let mut pick = |s: &[Sample]| OrthoBlend::Median.pick(s.iter().copied(), &mut scratch);
        let samples = [
            sample(10, true),
            sample(200, false),
            Sample {
                rgb: [30, 5, 100],
                seen: true,
            },
            sample(20, true),
        ];
        // Channels over the three seen: [10, 30, 20] → 20, [11, 5, 21] → 11, [12, 100, 22] → 22.
        assert_eq!(pick(&samples), Some([20, 11, 22]));
        assert_eq!(
            pick(&[sample(10, true), sample(21, true)]),
            Some([16, 17, 18])
        );
        // None seen: all of them.
        assert_eq!(
            pick(&[sample(10, false), sample(21, false)]),
            Some([16, 17, 18])
        );
        assert_eq!(pick(&[]), None);
    }
}
