//! The four seasons of the method and their file-name tags.

use std::fmt;
use std::str::FromStr;

use crate::SynthError;

/// A season of a synthetic variant. Its [`tag`](Season::tag) is the suffix of variant file names
/// (`<ID>__<tag>`) in the training layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Season {
    Summer,
    Autumn,
    Winter,
    Spring,
}

impl Season {
    /// Every season, in the paper's order (summer, autumn, winter, spring).
    pub const ALL: [Season; 4] = [
        Season::Summer,
        Season::Autumn,
        Season::Winter,
        Season::Spring,
    ];

    /// Lower-case tag used in file names and prompts files.
    pub fn tag(self) -> &'static str {
        match self {
            Season::Summer => "summer",
            Season::Autumn => "autumn",
            Season::Winter => "winter",
            Season::Spring => "spring",
        }
    }
}

impl fmt::Display for Season {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.tag())
    }
}

impl FromStr for Season {
    type Err = SynthError;

    /// Accepts the tags in any case (`winter`, `WINTER` as in the release's prompt keys) and `fall`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "summer" => Ok(Season::Summer),
            "autumn" | "fall" => Ok(Season::Autumn),
            "winter" => Ok(Season::Winter),
            "spring" => Ok(Season::Spring),
            _ => Err(SynthError::Input(format!(
                "unknown season {s:?}: expected one of summer, autumn, winter, spring"
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tags_round_trip_and_reject_unknown() {
        for s in Season::ALL {
            assert_eq!(s.tag().parse::<Season>().unwrap(), s);
            assert_eq!(s.to_string(), s.tag());
        }
        assert_eq!("WINTER".parse::<Season>().unwrap(), Season::Winter);
        assert_eq!("fall".parse::<Season>().unwrap(), Season::Autumn);
        let err = "monsoon".parse::<Season>().unwrap_err().to_string();
        assert!(err.contains("monsoon") && err.contains("summer"), "{err}");
    }
}
