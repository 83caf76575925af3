//! The options as people type them, shared by every front end (the command line's flags, the
//! Python package's keywords): plain numbers where 0 turns a filter off, a census window as
//! `"WxH"`, a method by name, memory in GiB. They become the typed options here, once, so the
//! front ends cannot drift apart in defaults, in what "0" means or in their error messages.
//!
//! Messages name the command line's flags (`--p1`, `--max-memory`): the Python keywords carry
//! the same names with underscores.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use matching::{Aggregation, CensusWindow, Paths, SgmParams, Speckle};

use crate::dsm::GridChoice;
use workflow::matcher::Matcher;

/// The classical matcher's settings as typed: census + MGM/SGM and its filters, 0 = filter off.
#[derive(Clone, Debug, PartialEq)]
pub struct ClassicalFlags {
    /// `mgm` (default) or `sgm`.
    pub method: Aggregation,
    /// Penalty of ±1 px disparity changes (census bits).
    pub p1: u16,
    /// Penalty of larger disparity jumps (census bits).
    pub p2: u16,
    /// 4 aggregation paths instead of 8 (SGM).
    pub four_paths: bool,
    /// Left-right tolerance, pixels; 0 disables the check.
    pub lr_tolerance: f32,
    /// Gradient adaptation of P2; 0 keeps P2 constant.
    pub p2_adaptive: f32,
    /// Census window.
    pub census: CensusWindow,
    /// Uniqueness ratio; 0 disables the test.
    pub uniqueness: f32,
    /// Smallest kept region of disparity, pixels; 0 or 1 keeps every region.
    pub speckle: usize,
    /// Largest disparity step inside one speckle region, pixels.
    pub speckle_diff: f32,
}

impl Default for ClassicalFlags {
    /// The library's defaults ([`SgmParams::default`]) written as flags.
    fn default() -> Self {
        let d = SgmParams::default();
        ClassicalFlags {
            method: d.aggregation,
            p1: d.p1,
            p2: d.p2,
            four_paths: d.paths == Paths::Four,
            lr_tolerance: d.lr_tolerance.unwrap_or(0.0),
            p2_adaptive: d.p2_adaptive.unwrap_or(0.0),
            census: d.census,
            uniqueness: d.uniqueness.unwrap_or(0.0),
            speckle: d.speckle.map_or(0, |s| s.min_area),
            speckle_diff: d.speckle.map_or(1.0, |s| s.max_diff),
        }
    }
}

impl ClassicalFlags {
    /// The matcher's parameters, checked.
    pub fn params(&self) -> Result<SgmParams> {
        let params = SgmParams {
            p1: self.p1,
            p2: self.p2,
            aggregation: self.method,
            paths: if self.four_paths {
                Paths::Four
            } else {
                Paths::Eight
            },
            lr_tolerance: (self.lr_tolerance > 0.0).then_some(self.lr_tolerance),
            p2_adaptive: (self.p2_adaptive > 0.0).then_some(self.p2_adaptive),
            census: self.census,
            uniqueness: (self.uniqueness > 0.0).then_some(self.uniqueness),
            speckle: (self.speckle > 1).then_some(Speckle {
                min_area: self.speckle,
                max_diff: self.speckle_diff,
            }),
            ..SgmParams::default()
        };
        params
            .check()
            .context("the classical matcher's flags (--p1, --p2, --census, --lr-tolerance, ...)")?;
        Ok(params)
    }

    /// The classical [`Matcher`] of these settings.
    pub fn matcher(&self) -> Result<Matcher> {
        Ok(Matcher::Classical(self.params()?))
    }
}

/// The classical method by name: `mgm` or `sgm`.
pub fn method(name: &str) -> Result<Aggregation> {
    match name.trim().to_ascii_lowercase().as_str() {
        "mgm" => Ok(Aggregation::Mgm),
        "sgm" => Ok(Aggregation::Sgm),
        _ => bail!("unknown method {name:?}: expected mgm or sgm"),
    }
}

/// A census window `WxH`, e.g. `9x7`: odd sides, at most 65 pixels.
pub fn census_window(s: &str) -> Result<CensusWindow, String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WxH, e.g. 9x7, got {s:?}"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<usize>()
            .map_err(|e| format!("{v:?} in {s:?}: {e}"))
    };
    let c = CensusWindow {
        width: parse(w)?,
        height: parse(h)?,
    };
    if !c.is_valid() {
        return Err(format!(
            "census window {s:?} needs odd sides and at most 65 pixels"
        ));
    }
    Ok(c)
}

/// A census window as [`census_window`] reads it.
pub fn format_census(c: CensusWindow) -> String {
    format!("{}x{}", c.width, c.height)
}

/// Hole filling within `cells` cells; 0 leaves the holes.
pub fn fill_cells(cells: usize) -> Option<usize> {
    (cells > 0).then_some(cells)
}

/// A median filter over `cells` (odd); 0 or 1: none.
pub fn median_cells(cells: usize) -> Option<usize> {
    (cells > 1).then_some(cells)
}

/// Bytes in GiB, as messages say memory.
pub fn gib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 30) as f64
}

/// `--max-memory`: a positive number of GiB, in bytes.
pub fn memory_bytes(gib: f64) -> Result<u64> {
    if !(gib.is_finite() && gib > 0.0) {
        bail!("--max-memory must be a positive number of GiB, got {gib}");
    }
    Ok((gib * (1u64 << 30) as f64) as u64)
}

/// The DSM's grid: that of the `like` DSM when given, else `resolution` metres over `bounds` (or
/// the points' extent) in `epsg` (or the points' zone).
pub fn grid(
    like: Option<PathBuf>,
    resolution: f64,
    bounds: Option<[f64; 4]>,
    epsg: Option<u32>,
) -> GridChoice {
    match like {
        Some(path) => GridChoice::Like(path),
        None => GridChoice::Resolution {
            resolution,
            bounds,
            epsg,
        },
    }
}

/// A UTM zone like `17N` (Jacksonville) or `21S` (Buenos Aires).
pub fn utm_zone(s: &str) -> Result<camera::UtmZone, String> {
    let t = s.trim().to_ascii_uppercase();
    let (num, hemi) = t.split_at(t.len().saturating_sub(1));
    let north = match hemi {
        "N" => true,
        "S" => false,
        _ => return Err(format!("expected a zone like 17N or 21S, got {s:?}")),
    };
    let zone: u8 = num
        .parse()
        .map_err(|e| format!("zone number in {s:?}: {e}"))?;
    camera::UtmZone::new(zone, north).map_err(|e| e.to_string())
}

/// DSM cell size when none is asked for, metres: about the GSD of WorldView-3 and the
/// benchmark's truth.
pub const RESOLUTION: f64 = 0.5;

/// How a cell's height comes from its points, by name: `max` or `median`.
pub fn gridding(name: &str) -> Result<camera::Gridding> {
    match name.trim().to_ascii_lowercase().as_str() {
        "max" => Ok(camera::Gridding::Max),
        "median" => Ok(camera::Gridding::Median),
        _ => bail!("unknown gridding {name:?}: expected max or median"),
    }
}

/// `--heights`: `ellipsoid` or `egm96`.
pub fn heights(name: &str) -> Result<camera::Heights> {
    match name.trim().to_ascii_lowercase().as_str() {
        "ellipsoid" => Ok(camera::Heights::Ellipsoid),
        "egm96" | "geoid" => Ok(camera::Heights::Egm96),
        _ => bail!("unknown heights {name:?}: expected ellipsoid or egm96"),
    }
}

/// `--ortho-blend`: `nadir` or `median`.
pub fn ortho_blend(name: &str) -> Result<products::OrthoBlend> {
    match name.trim().to_ascii_lowercase().as_str() {
        "nadir" => Ok(products::OrthoBlend::MostNadir),
        "median" => Ok(products::OrthoBlend::Median),
        _ => bail!("unknown ortho_blend {name:?}: expected nadir or median"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_flags_are_the_library_defaults() {
        assert_eq!(
            ClassicalFlags::default().params().unwrap(),
            SgmParams::default()
        );
    }

    #[test]
    fn zero_turns_the_filters_off() {
        let flags = ClassicalFlags {
            lr_tolerance: 0.0,
            uniqueness: 0.0,
            speckle: 0,
            ..ClassicalFlags::default()
        };
        let p = flags.params().unwrap();
        assert_eq!(
            (p.lr_tolerance, p.uniqueness, p.speckle),
            (None, None, None)
        );
        assert_eq!(
            (fill_cells(0), median_cells(1), median_cells(7)),
            (None, None, Some(7))
        );
    }

    #[test]
    fn names_and_windows_parse_or_say_what_is_expected() {
        assert_eq!(
            census_window("9x7").unwrap(),
            CensusWindow {
                width: 9,
                height: 7
            }
        );
        assert!(census_window("4x4").unwrap_err().contains("odd sides"));
        assert_eq!(format_census(census_window("5X5").unwrap()), "5x5");
        assert_eq!(method("SGM").unwrap(), Aggregation::Sgm);
        assert!(method("bm").unwrap_err().to_string().contains("mgm or sgm"));
        assert!(gridding("mean").is_err());
        assert_eq!(utm_zone("17N").unwrap().epsg(), 32617);
        assert!(utm_zone("17X").is_err());
        assert!(memory_bytes(-1.0).is_err());
        assert_eq!(memory_bytes(2.0).unwrap(), 2 << 30);
    }
}
