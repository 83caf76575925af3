//! Pair stems: `<LEFTID>[__<tag>]-<RIGHTID>[__<tag>]`.
//!
//! As in the release, the stem splits at its FIRST `-` (image ids never contain one) and each side
//! at its first `__` (id, then the synthetic variant's tag). No tag = the real image.

use std::fmt;
use std::str::FromStr;

use crate::{DatasetError, Result};

/// Separator between an image id and its synthetic tag.
pub const TAG_SEPARATOR: &str = "__";

/// Characters of the left image id that name the AOI (`JAX_004_006_RGB` → `JAX_004`).
pub const AOI_CHARS: usize = 7;

/// One side of a pair: an image id and, for a synthetic variant, its tag.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ImageRef {
    pub id: String,
    pub tag: Option<String>,
}

impl ImageRef {
    /// The real image `id`.
    pub fn real(id: impl Into<String>) -> Self {
        ImageRef {
            id: id.into(),
            tag: None,
        }
    }

    /// The variant `tag` of image `id`.
    pub fn variant(id: impl Into<String>, tag: impl Into<String>) -> Self {
        ImageRef {
            id: id.into(),
            tag: Some(tag.into()),
        }
    }

    /// True for the real image (no tag).
    pub fn is_real(&self) -> bool {
        self.tag.is_none()
    }

    /// The tag, or `real` for the real image (for tables and manifests).
    pub fn tag_or_real(&self) -> &str {
        self.tag.as_deref().unwrap_or("real")
    }

    fn parse(side: &str, whole: &str) -> Result<Self> {
        let (id, tag) = match side.split_once(TAG_SEPARATOR) {
            Some((id, tag)) => (id, Some(tag)),
            None => (side, None),
        };
        if id.is_empty() || tag == Some("") {
            return Err(DatasetError::Invalid(format!(
                "malformed pair stem {whole:?}: expected <LEFTID>[__<tag>]-<RIGHTID>[__<tag>]"
            )));
        }
        Ok(ImageRef {
            id: id.to_string(),
            tag: tag.map(str::to_string),
        })
    }
}

impl fmt::Display for ImageRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.tag {
            Some(t) => write!(f, "{}{TAG_SEPARATOR}{t}", self.id),
            None => f.write_str(&self.id),
        }
    }
}

/// How a combination relates to its real pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PairKind {
    /// The real synchronic pair (no tags).
    Real,
    /// Both views carry the same synthetic tag (one synthetic season on both sides).
    SynchronicSynthetic,
    /// The two views have different tags (real vs season, or two seasons).
    Diachronic,
}

/// A pair stem: left and right image references.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PairStem {
    pub left: ImageRef,
    pub right: ImageRef,
}

impl PairStem {
    /// The real pair of two image ids.
    pub fn real(left: impl Into<String>, right: impl Into<String>) -> Self {
        PairStem {
            left: ImageRef::real(left),
            right: ImageRef::real(right),
        }
    }

    /// Parses `<LEFTID>[__<tag>]-<RIGHTID>[__<tag>]`; a file name's extension is NOT stripped.
    pub fn parse(stem: &str) -> Result<Self> {
        let (l, r) = stem.split_once('-').ok_or_else(|| {
            DatasetError::Invalid(format!(
                "malformed pair stem {stem:?}: no '-' between the left and right image ids"
            ))
        })?;

        Ok(PairStem {
            left: ImageRef::parse(l, stem)?,
            right: ImageRef::parse(r, stem)?,
        })
    }

    /// The real pair this combination derives from (tags removed).
    pub fn base(&self) -> PairStem {
        PairStem::real(&self.left.id, &self.right.id)
    }

    /// The base pair's stem as a string (`<LEFTID>-<RIGHTID>`): names masks, homographies and
    /// disparities.
    pub fn base_name(&self) -> String {
        format!("{}-{}", self.left.id, self.right.id)
    }

    /// The same base pair with the given tags (`None` = real).
    pub fn with_tags(&self, left: Option<&str>, right: Option<&str>) -> PairStem {
        PairStem {
            left: ImageRef {
                id: self.left.id.clone(),
                tag: left.map(str::to_string),
            },
            right: ImageRef {
                id: self.right.id.clone(),
                tag: right.map(str::to_string),
            },
        }
    }

    /// True for the real pair.
    pub fn is_real(&self) -> bool {
        self.left.is_real() && self.right.is_real()
    }

    /// True when the two views differ in tag (the release's `diachronic` flag).
    pub fn is_diachronic(&self) -> bool {
        self.left.tag != self.right.tag
    }

    /// Real, synchronic synthetic or diachronic.
    pub fn kind(&self) -> PairKind {
        if self.is_diachronic() {
            PairKind::Diachronic
        } else if self.is_real() {
            PairKind::Real
        } else {
            PairKind::SynchronicSynthetic
        }
    }

    /// The AOI: first [`AOI_CHARS`] characters of the left image id (`JAX_004`).
    pub fn aoi(&self) -> &str {
        let id = &self.left.id;
        match id.char_indices().nth(AOI_CHARS) {
            Some((i, _)) => &id[..i],
            None => id,
        }
    }

    /// Every left/right combination of `tags` (`None` = real) on both views, real pair first:
    /// with the real image and 4 seasons, the 25 combinations (5 synchronic + 20 diachronic).
    pub fn combinations(&self, tags: &[Option<String>]) -> Vec<PairStem> {
        let mut out = Vec::with_capacity(tags.len() * tags.len());
        for l in tags {
            for r in tags {
                out.push(self.with_tags(l.as_deref(), r.as_deref()));
            }
        }
        out.sort_by_key(|s| (!s.is_real(), s.clone()));
        out
    }
}

impl fmt::Display for PairStem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}-{}", self.left, self.right)
    }
}

impl FromStr for PairStem {
    type Err = DatasetError;
    fn from_str(s: &str) -> Result<Self> {
        PairStem::parse(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_formats_release_stems() {
        let s = PairStem::parse("JAX_004_006_RGB__winter-JAX_004_009_RGB").unwrap();
        assert_eq!(s.left, ImageRef::variant("JAX_004_006_RGB", "winter"));
        assert_eq!(s.right, ImageRef::real("JAX_004_009_RGB"));
        assert_eq!(s.to_string(), "JAX_004_006_RGB__winter-JAX_004_009_RGB");
        assert_eq!(s.base_name(), "JAX_004_006_RGB-JAX_004_009_RGB");
        assert_eq!(s.aoi(), "JAX_004");
        assert!(s.is_diachronic());
        assert_eq!(s.kind(), PairKind::Diachronic);
        let sync = PairStem::parse("A__summer-B__summer").unwrap();
        assert_eq!(sync.kind(), PairKind::SynchronicSynthetic);
        assert!(!sync.is_diachronic());
        assert_eq!(PairStem::parse("A-B").unwrap().kind(), PairKind::Real);
        // Only the first '-' splits, as in the release.
        assert_eq!(PairStem::parse("A-B-C").unwrap().right.id, "B-C");
    }

    #[test]
    fn rejects_malformed_stems() {
        for bad in ["AB", "-B", "A-", "A__-B", "A-B__"] {
            assert!(PairStem::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn twenty_five_combinations() {
        let tags: Vec<Option<String>> = std::iter::once(None)
            .chain(["summer", "autumn", "winter", "spring"].map(|t| Some(t.to_string())))
            .collect();
        let c = PairStem::real("A", "B").combinations(&tags);
        assert_eq!(c.len(), 25);
        assert!(c[0].is_real());
        let count = |k| c.iter().filter(|s| s.kind() == k).count();
        assert_eq!(count(PairKind::Real), 1);
        assert_eq!(count(PairKind::SynchronicSynthetic), 4);
        assert_eq!(count(PairKind::Diachronic), 20);
        assert!(c.iter().all(|s| s.base_name() == "A-B"));
    }

    #[test]
    fn short_ids_are_their_own_aoi() {
        assert_eq!(PairStem::real("W1_A", "W1_B").aoi(), "W1_A");
    }
}
