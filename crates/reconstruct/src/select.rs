//! Which pairs of a set of acquisitions to reconstruct, from metadata and geometry alone (no
//! image is matched): the acquisition dates, each view's incidence and the pair's convergence
//! angle from the RPCs, and the sun's directions.
//!
//! The rule follows Facciolo, de Franchis and Meinhardt-Llopis, "Automatic 3D reconstruction
//! from multi-date satellite images" (CVPRW 2017): pairs close in time match best (the ground,
//! the vegetation and the shadows have changed least), a convergence angle in a moderate band
//! gives a usable baseline (a tiny one turns every pixel of disparity error into metres of
//! height; a wide one hides the ground behind buildings), and views close to nadir see more of
//! the ground. The score of a pair is the product of four terms in [0, 1] ([`PairTerms`]):
//!
//! | term | formula | effect |
//! |---|---|---|
//! | date | `1 / (1 + Δdays / 45)` | 5 days 0.90, 45 days 0.50, 200 days 0.18; 0.5 when a date is unknown |
//! | convergence | 0 below 1°, linear to 1 at 5°, 1 up to 45°, linear to 0 at 60° | tiny or very wide baselines out |
//! | incidence | `cos(max(incidence_a, incidence_b))` | mild preference for near-nadir views |
//! | sun | `1 − 0.5 · min(Δsun / 60°, 1)` | shadows that moved; at most a factor 2 |
//!
//! A cross-season pair can therefore beat a near-date pair whose baseline is too short, which
//! is when it helps the geometry. The best `K` pairs by score are kept ([`choose_pairs`]).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use camera::{RpcModel, UtmZone};
use chrono::{NaiveDate, NaiveTime};
use serde::Serialize;

/// Days of date gap at which the date term is one half.
pub const DATE_HALF_DAYS: f64 = 45.0;
/// The convergence band, degrees: zero below `[0]`, rising to one at `[1]`, one up to `[2]`,
/// falling to zero at `[3]`.
pub const CONVERGENCE_BAND: [f64; 4] = [1.0, 5.0, 45.0, 60.0];
/// Sun direction change, degrees, at which the sun term reaches its floor of one half.
pub const SUN_FULL_PENALTY_DEG: f64 = 60.0;

/// One acquisition as the selection sees it.
#[derive(Clone, Debug, Serialize)]
pub struct View {
    pub image: PathBuf,
    /// The camera's JSON, when given (else the image's RPC tag).
    pub rpc_file: Option<PathBuf>,
    /// `acquisition_date` of the JSON (`YYYYMMDDhhmmss`), as days since 1970-01-01.
    pub day: Option<f64>,
    /// The acquisition date as written in the JSON.
    pub date: Option<String>,
    /// Sun elevation and azimuth, degrees (the JSON's `sun_elevation`, `sun_azimuth`).
    pub sun: Option<(f64, f64)>,
    /// UTM bounds `[x_min, y_min, x_max, y_max]` of the image's ground footprint over the
    /// scene's altitudes.
    pub footprint: [f64; 4],
    #[serde(skip)]
    pub rpc: RpcModel,
}

/// The terms of a pair's score ([module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PairTerms {
    /// Days between the acquisitions (`None`: a date is unknown).
    pub days: Option<f64>,
    /// Angle between the two lines of sight at the overlap's centre, degrees.
    pub convergence_deg: f64,
    /// Off-nadir angles of the two lines of sight at the ground, degrees.
    pub incidence_deg: (f64, f64),
    /// Angle between the two sun directions, degrees (`None`: unknown).
    pub sun_deg: Option<f64>,
    pub date_term: f64,
    pub convergence_term: f64,
    pub incidence_term: f64,
    pub sun_term: f64,
    /// The product of the four terms.
    pub score: f64,
}

/// The measured quantities of a pair, before scoring.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairGeometry {
    pub days: Option<f64>,
    pub convergence_deg: f64,
    pub incidence_deg: (f64, f64),
    pub sun_deg: Option<f64>,
}

/// The score of a pair: the four terms of the [module docs](self) and their product.
pub fn score_pair(g: &PairGeometry) -> PairTerms {
    let date_term = g
        .days
        .map_or(0.5, |d| 1.0 / (1.0 + d.abs() / DATE_HALF_DAYS));
    let [c0, c1, c2, c3] = CONVERGENCE_BAND;
    let c = g.convergence_deg;
    let convergence_term = if c <= c0 || c >= c3 {
        0.0
    } else if c < c1 {
        (c - c0) / (c1 - c0)
    } else if c <= c2 {
        1.0
    } else {
        (c3 - c) / (c3 - c2)
    };
    let incidence_term = g
        .incidence_deg
        .0
        .max(g.incidence_deg.1)
        .to_radians()
        .cos()
        .max(0.0);
    let sun_term = g.sun_deg.map_or(1.0, |s| {
        1.0 - 0.5 * (s / SUN_FULL_PENALTY_DEG).clamp(0.0, 1.0)
    });
    PairTerms {
        days: g.days,
        convergence_deg: g.convergence_deg,
        incidence_deg: g.incidence_deg,
        sun_deg: g.sun_deg,
        date_term,
        convergence_term,
        incidence_term,
        sun_term,
        score: date_term * convergence_term * incidence_term * sun_term,
    }
}

/// A candidate pair: indices into the views (the left one, the reference of the tiles, is the
/// more nadir view) and its score.
#[derive(Clone, Debug, Serialize)]
pub struct PairChoice {
    pub left: usize,
    pub right: usize,
    /// `<left stem>-<right stem>`.
    pub stem: String,
    pub terms: PairTerms,
    /// UTM bounds of the two footprints' intersection.
    pub overlap: [f64; 4],
}

/// Days since 1970-01-01 of a `YYYYMMDD[hhmmss]` date (the SatNeRF JSON's `acquisition_date`).
pub fn parse_day(text: &str) -> Option<f64> {
    let t = text.trim();
    if t.len() < 8 || !t.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let date = NaiveDate::parse_from_str(t.get(..8)?, "%Y%m%d").ok()?;
    let time = t
        .get(8..14)
        .and_then(|hms| NaiveTime::parse_from_str(hms, "%H%M%S").ok())
        .unwrap_or(NaiveTime::MIN);
    Some(date.and_time(time).and_utc().timestamp() as f64 / 86_400.0)
}

/// What a SatNeRF JSON camera says of its acquisition besides the RPC.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Acquisition {
    /// `acquisition_date` as written (`YYYYMMDDhhmmss`).
    pub date: Option<String>,
    /// `sun_elevation`, `sun_azimuth`, degrees.
    pub sun: Option<(f64, f64)>,
}

/// The date and sun angles of a SatNeRF JSON camera (fields absent → `None`).
pub fn json_metadata(path: &Path) -> Result<Acquisition> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let number = |key: &str| -> Option<f64> {
        match &v[key] {
            serde_json::Value::Number(n) => n.as_f64(),
            serde_json::Value::String(s) => s.trim().trim_start_matches('+').parse().ok(),
            _ => None,
        }
    };
    let date = v["acquisition_date"].as_str().map(str::to_owned);
    let sun = number("sun_elevation").zip(number("sun_azimuth"));
    Ok(Acquisition { date, sun })
}

/// The unit line of sight from the ground point (lon, lat, alt) towards the camera, in local
/// east-north-up metres: the ground point is projected into the image and that pixel localized
/// 100 m higher.
pub fn line_of_sight(rpc: &RpcModel, lon: f64, lat: f64, alt: f64) -> Result<[f64; 3]> {
    const RISE: f64 = 100.0;
    let zone = UtmZone::from_lonlat(lon, lat);
    let (col, row) = rpc.projection(lon, lat, alt);
    let (lon1, lat1) = rpc
        .localization(col, row, alt + RISE)
        .context("localizing the scene centre 100 m higher")?;
    let (e0, n0) = zone.forward(lon, lat);
    let (e1, n1) = zone.forward(lon1, lat1);
    let v = [e1 - e0, n1 - n0, RISE];
    let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    Ok([v[0] / norm, v[1] / norm, v[2] / norm])
}

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    dot.clamp(-1.0, 1.0).acos().to_degrees()
}

/// The unit direction towards the sun from its elevation and azimuth (degrees, azimuth
/// clockwise from north), east-north-up.
fn sun_direction((elevation, azimuth): (f64, f64)) -> [f64; 3] {
    let (e, a) = (elevation.to_radians(), azimuth.to_radians());
    [e.cos() * a.sin(), e.cos() * a.cos(), e.sin()]
}

/// The intersection of two UTM boxes, `None` when empty.
pub fn intersect(a: [f64; 4], b: [f64; 4]) -> Option<[f64; 4]> {
    let r = [
        a[0].max(b[0]),
        a[1].max(b[1]),
        a[2].min(b[2]),
        a[3].min(b[3]),
    ];
    (r[2] > r[0] && r[3] > r[1]).then_some(r)
}

/// The geometry of views `a`, `b` at the centre of their overlap (at the middle of the scene's
/// altitudes), `None` when their footprints do not overlap.
pub fn pair_geometry(
    a: &View,
    b: &View,
    zone: UtmZone,
    alt: f64,
) -> Result<Option<(PairGeometry, [f64; 4])>> {
    let Some(overlap) = intersect(a.footprint, b.footprint) else {
        return Ok(None);
    };
    let (lon, lat) = zone.inverse(
        0.5 * (overlap[0] + overlap[2]),
        0.5 * (overlap[1] + overlap[3]),
    );
    let los = |v: &View| {
        line_of_sight(&v.rpc, lon, lat, alt)
            .with_context(|| format!("the line of sight of {}", v.image.display()))
    };
    let (la, lb) = (los(a)?, los(b)?);
    let incidence = |l: [f64; 3]| angle_deg(l, [0.0, 0.0, 1.0]);
    let g = PairGeometry {
        days: a.day.zip(b.day).map(|(x, y)| (x - y).abs()),
        convergence_deg: angle_deg(la, lb),
        incidence_deg: (incidence(la), incidence(lb)),
        sun_deg: a
            .sun
            .zip(b.sun)
            .map(|(x, y)| angle_deg(sun_direction(x), sun_direction(y))),
    };
    Ok(Some((g, overlap)))
}

/// Every overlapping pair of `views` scored, best first (ties by the order of the images).
/// The left image of a pair is its more nadir view.
pub fn rank_pairs(views: &[View], zone: UtmZone, alt: f64) -> Result<Vec<PairChoice>> {
    let mut pairs = Vec::new();
    for i in 0..views.len() {
        for j in i + 1..views.len() {
            let Some((g, overlap)) = pair_geometry(&views[i], &views[j], zone, alt)? else {
                continue;
            };
            let (left, right) = if g.incidence_deg.1 < g.incidence_deg.0 {
                (j, i)
            } else {
                (i, j)
            };
            let mut terms = score_pair(&g);
            if left == j {
                terms.incidence_deg = (g.incidence_deg.1, g.incidence_deg.0);
            }
            pairs.push(PairChoice {
                left,
                right,
                stem: format!(
                    "{}-{}",
                    crate::rectify::file_stem(&views[left].image)?,
                    crate::rectify::file_stem(&views[right].image)?
                ),
                terms,
                overlap,
            });
        }
    }
    pairs.sort_by(|a, b| b.terms.score.total_cmp(&a.terms.score));
    Ok(pairs)
}

/// The best `k` of the ranked pairs with a positive score; an error when none has one.
pub fn choose_pairs(ranked: &[PairChoice], k: usize) -> Result<Vec<PairChoice>> {
    if k == 0 {
        bail!("--pairs must be at least 1");
    }
    let chosen: Vec<PairChoice> = ranked
        .iter()
        .filter(|p| p.terms.score > 0.0)
        .take(k)
        .cloned()
        .collect();
    if chosen.is_empty() {
        bail!(
            "none of the {} overlapping pairs has a usable geometry (convergence between {}° and \
             {}°): add acquisitions seen from other directions",
            ranked.len(),
            CONVERGENCE_BAND[0],
            CONVERGENCE_BAND[3]
        );
    }
    Ok(chosen)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn g(days: f64, convergence: f64) -> PairGeometry {
        PairGeometry {
            days: Some(days),
            convergence_deg: convergence,
            incidence_deg: (15.0, 20.0),
            sun_deg: Some(3.0),
        }
    }

    #[test]
    fn a_short_gap_and_a_good_baseline_win() {
        let best = score_pair(&g(5.0, 15.0)).score;
        let late = score_pair(&g(200.0, 15.0)).score;
        let tiny = score_pair(&g(5.0, 1.0)).score;
        let short = score_pair(&g(5.0, 3.0)).score;
        let wide = score_pair(&g(5.0, 55.0)).score;
        assert!(best > late && best > tiny && best > short && best > wide);
        assert_eq!(tiny, 0.0);
        // A cross-season pair with a good baseline beats a near-date pair with a tiny one.
        assert!(late > score_pair(&g(5.0, 1.5)).score);
        // Inside the band the baseline does not matter; the date decides.
        assert_eq!(
            score_pair(&g(5.0, 10.0)).score,
            score_pair(&g(5.0, 40.0)).score
        );
        assert!(score_pair(&g(12.0, 20.0)).score > score_pair(&g(60.0, 20.0)).score);
    }

    #[test]
    fn terms_are_as_documented() {
        let t = score_pair(&PairGeometry {
            days: Some(45.0),
            convergence_deg: 3.0,
            incidence_deg: (60.0, 10.0),
            sun_deg: Some(30.0),
        });
        assert!((t.date_term - 0.5).abs() < 1e-12);
        assert!((t.convergence_term - 0.5).abs() < 1e-12);
        assert!((t.incidence_term - 0.5).abs() < 1e-12);
        assert!((t.sun_term - 0.75).abs() < 1e-12);
        assert!((t.score - 0.5 * 0.5 * 0.5 * 0.75).abs() < 1e-12);
        // Unknown date and sun: neutral-ish terms, documented.
        let u = score_pair(&PairGeometry {
            days: None,
            sun_deg: None,
            ..g(0.0, 20.0)
        });
        assert_eq!((u.date_term, u.sun_term), (0.5, 1.0));
    }

    #[test]
    fn dates_parse_to_days() {
        assert_eq!(parse_day("19700101"), Some(0.0));
        let a = parse_day("20141011155720").unwrap();
        let b = parse_day("20141018160700").unwrap();
        assert!((b - a - 7.0).abs() < 0.01, "{}", b - a);
        // Across a leap day: 2016-02-28 → 2016-03-01 is two days.
        let d = parse_day("20160301").unwrap() - parse_day("20160228").unwrap();
        assert_eq!(d, 2.0);
        assert_eq!(parse_day("2014-10-11"), None);
        assert_eq!(parse_day("20141311"), None);
    }

    #[test]
    fn sun_and_view_angles() {
        assert!((angle_deg(sun_direction((45.0, 90.0)), sun_direction((45.0, 90.0)))).abs() < 1e-6);
        let d = angle_deg(sun_direction((90.0, 0.0)), sun_direction((60.0, 123.0)));
        assert!((d - 30.0).abs() < 1e-9, "{d}");
        assert_eq!(
            intersect([0.0, 0.0, 2.0, 2.0], [1.0, 1.0, 3.0, 3.0]),
            Some([1.0, 1.0, 2.0, 2.0])
        );
        assert_eq!(intersect([0.0, 0.0, 1.0, 1.0], [2.0, 2.0, 3.0, 3.0]), None);
    }
}
