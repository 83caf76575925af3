//! The geometry-preserving prompts of the generative backend, in a user-editable TOML file.
//!
//! The wording follows the facts of the release's prompts (paper Fig. 4): a shared part that
//! pins viewpoint, framing, scale and every contour, and a season-specific part (snow on roofs,
//! fields and open ground in winter; fall colours in autumn; ...). The default is embedded in
//! the binary; [`Prompts::write_default`] writes it out for editing and [`Prompts::load`] reads
//! an edited copy back.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::{Season, SynthError};

/// The embedded default prompts file.
pub const DEFAULT_PROMPTS_TOML: &str = include_str!("prompts.toml");

/// A parsed prompts file.
#[derive(Clone, Debug, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Prompts {
    /// Text common to all seasons, first; `{season}` is replaced by the season's tag.
    pub shared: String,
    /// Text common to all seasons, last.
    #[serde(default)]
    pub closing: String,
    /// Season-specific text, keyed by tag (`summer`, `autumn`, `winter`, `spring`).
    pub seasons: BTreeMap<String, String>,
}

impl Default for Prompts {
    fn default() -> Self {
        Self::parse(DEFAULT_PROMPTS_TOML, Path::new("<embedded prompts.toml>"))
            .expect("the embedded prompts file is valid")
    }
}

impl Prompts {
    /// Parses a prompts file's text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &Path) -> Result<Self, SynthError> {
        let err = |message: String| SynthError::Prompts {
            path: origin.to_path_buf(),
            message,
        };
        let prompts: Prompts =
            toml::from_str(text).map_err(|e| err(format!("not a valid prompts file: {e}")))?;
        for key in prompts.seasons.keys() {
            key.parse::<Season>().map_err(|_| {
                err(format!(
                    "unknown season [seasons].{key}: use summer, autumn, winter and spring"
                ))
            })?;
        }
        for season in Season::ALL {
            match prompts.seasons.get(season.tag()) {
                Some(t) if !t.trim().is_empty() => {}
                _ => {
                    return Err(err(format!(
                        "[seasons].{} is missing or empty: every season needs its text",
                        season.tag()
                    )))
                }
            }
        }
        if prompts.shared.trim().is_empty() {
            return Err(err(
                "`shared` is empty: it must carry the geometry-preserving instructions".into(),
            ));
        }
        Ok(prompts)
    }

    /// Reads a prompts file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, SynthError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| SynthError::Prompts {
            path: path.to_path_buf(),
            message: format!("cannot read the prompts file: {e}"),
        })?;
        Self::parse(&text, path)
    }

    /// Writes the embedded default prompts to `path` for editing (atomically); refuses to
    /// overwrite an existing file, which may hold a user's edits.
    pub fn write_default(path: impl AsRef<Path>) -> Result<PathBuf, SynthError> {
        let path = path.as_ref();
        if path.exists() {
            return Err(SynthError::Prompts {
                path: path.to_path_buf(),
                message: "already exists: edit it, or remove it to get the default back".into(),
            });
        }
        raster::formats::write_atomically(path, |f| f.write_all(DEFAULT_PROMPTS_TOML.as_bytes()))?;
        Ok(path.to_path_buf())
    }

    /// The full prompt of `season`.
    pub fn prompt(&self, season: Season) -> String {
        let parts = [
            self.shared.replace("{season}", season.tag()),
            self.seasons.get(season.tag()).cloned().unwrap_or_default(),
            self.closing.clone(),
        ];
        parts
            .iter()
            .map(|p| p.trim())
            .filter(|p| !p.is_empty())
            .collect::<Vec<_>>()
            .join(" ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_prompts_cover_every_season_and_keep_geometry() {
        let p = Prompts::default();
        for season in Season::ALL {
            let text = p.prompt(season);
            assert!(text.contains(season.tag()), "{text}");
            assert!(text.contains("exactly the same position"), "{text}");
            assert!(text.contains("warp"), "{text}");
            assert!(!text.contains("{season}"));
        }
        assert!(p.prompt(Season::Winter).contains("snow on rooftops"));
    }

    #[test]
    fn written_default_loads_back_and_edits_are_used() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("prompts.toml");
        Prompts::write_default(&path).unwrap();
        assert_eq!(Prompts::load(&path).unwrap(), Prompts::default());
        let err = Prompts::write_default(&path).unwrap_err().to_string();
        assert!(err.contains("already exists"), "{err}");

        let edited = DEFAULT_PROMPTS_TOML.replace("Winter look only", "Deep winter look only");
        std::fs::write(&path, edited).unwrap();
        assert!(Prompts::load(&path)
            .unwrap()
            .prompt(Season::Winter)
            .contains("Deep winter"));
    }

    #[test]
    fn incomplete_or_unknown_seasons_are_refused() {
        let missing = "shared = \"keep geometry\"\n[seasons]\nsummer = \"x\"\n";
        let err = Prompts::parse(missing, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("p.toml") && err.contains("autumn"), "{err}");
        let extra = format!("{DEFAULT_PROMPTS_TOML}\nmonsoon = \"rain\"\n");
        let err = Prompts::parse(&extra, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("monsoon"), "{err}");
        let err = Prompts::parse("shared = 3", Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("not a valid prompts file"), "{err}");
    }
}
