//! How the demo's reports and the CLI write numbers and matcher settings.

use matching::{Aggregation, Paths, SgmParams};

/// Formats an optional fraction as a percentage.
pub fn percent(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{:.2} %", 100.0 * v))
}

/// Formats an optional error in pixels.
pub fn pixels(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{v:.3} px"))
}

/// Formats an optional altitude error in metres.
pub fn metres(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{v:.3} m"))
}

/// Command-line flags of `predict`/`eval` giving the matcher `p` (empty for the defaults).
pub fn matcher_flags(p: &SgmParams) -> String {
    let d = SgmParams::default();
    let mut f = Vec::new();
    if p.aggregation != d.aggregation {
        f.push(match p.aggregation {
            Aggregation::Mgm => "--method mgm".to_string(),
            Aggregation::Sgm => "--method sgm".to_string(),
        });
    }
    if p.census != d.census {
        f.push(format!("--census {}x{}", p.census.width, p.census.height));
    }
    if p.p1 != d.p1 {
        f.push(format!("--p1 {}", p.p1));
    }
    if p.p2 != d.p2 {
        f.push(format!("--p2 {}", p.p2));
    }
    if p.p2_adaptive != d.p2_adaptive {
        f.push(format!("--p2-adaptive {}", p.p2_adaptive.unwrap_or(0.0)));
    }
    if p.paths != d.paths && p.paths == Paths::Four {
        f.push("--four-paths".into());
    }
    if p.lr_tolerance != d.lr_tolerance {
        f.push(format!("--lr-tolerance {}", p.lr_tolerance.unwrap_or(0.0)));
    }
    if p.uniqueness != d.uniqueness {
        f.push(format!("--uniqueness {}", p.uniqueness.unwrap_or(0.0)));
    }
    if p.speckle != d.speckle {
        match &p.speckle {
            Some(s) => f.push(format!(
                "--speckle {} --speckle-diff {}",
                s.min_area, s.max_diff
            )),
            None => f.push("--speckle 0".into()),
        }
    }
    f.iter().map(|s| format!(" {s}")).collect()
}
