//! Soft land cover of one pixel: how much of it is tree, grass, crop, bare ground, pavement,
//! road, water or roof. From a class map it is one-hot; without one it is derived from the
//! pixel's own colour (see [`Cover::from_colour`]). Both are pointwise, so the seasonal colour
//! built on them changes only where the cover changes: along edges that already exist.

/// Weights in [0, 1] summing to 1.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Cover {
    pub tree: f32,
    pub grass: f32,
    pub crop: f32,
    pub bare: f32,
    pub developed: f32,
    pub road: f32,
    pub water: f32,
    pub roof: f32,
    /// Background or unknown: only the global changes apply.
    pub other: f32,
}

pub(crate) fn luminance(c: [f32; 3]) -> f32 {
    0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2]
}

pub(crate) fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl Cover {
    /// One-hot cover of an OpenEarthMap class id (rounded; NaN or unknown ids are `other`).
    pub(crate) fn from_class(id: f32) -> Self {
        let mut c = Cover::default();
        let slot = match id.round() as i64 {
            1 => &mut c.bare,
            2 => &mut c.grass,
            3 => &mut c.developed,
            4 => &mut c.road,
            5 => &mut c.tree,
            6 => &mut c.water,
            7 => &mut c.crop,
            8 => &mut c.roof,
            _ => &mut c.other,
        };
        *slot = 1.0;
        c
    }

    /// Cover likelihoods from the colour `c` (RGB in [0, 1]) alone:
    /// - vegetation from the normalised excess-green index `ExG = (2G − R − B)/(R + G + B)`,
    ///   `veg = smoothstep(0.06, 0.16, ExG)`; dark vegetation is canopy,
    ///   `tree = veg · (1 − smoothstep(0.12, 0.36, L))`, the rest grass (fields included);
    /// - water is dark and bluish: `water = (1 − veg) · (1 − smoothstep(0.12, 0.30, L)) ·
    ///   smoothstep(0.05, 0.20, (B − R)/(R + G + B))`;
    /// - of what is left, bright pixels are roofs (`smoothstep(0.45, 0.70, L)`), mid-grey ones
    ///   open ground (`smoothstep(0.25, 0.40, L)`), dark ones road or pavement;
    ///
    /// with `L` the Rec. 601 luminance. Shadows fall in the dark classes, which keeps snow and
    /// bright tints off them.
    pub(crate) fn from_colour(c: [f32; 3]) -> Self {
        let sum = (c[0] + c[1] + c[2]).max(0.03);
        let l = luminance(c);
        let exg = (2.0 * c[1] - c[0] - c[2]) / sum;
        let veg = smoothstep(0.06, 0.16, exg);
        let tree = veg * (1.0 - smoothstep(0.12, 0.36, l));
        let grass = veg - tree;
        let blue = (c[2] - c[0]) / sum;
        let water = (1.0 - veg) * (1.0 - smoothstep(0.12, 0.30, l)) * smoothstep(0.05, 0.20, blue);
        let rest = (1.0 - veg - water).max(0.0);
        let roof = rest * smoothstep(0.45, 0.70, l);
        let open = (rest - roof) * smoothstep(0.25, 0.40, l);
        let road = (rest - roof - open).max(0.0);
        Cover {
            tree,
            grass,
            water,
            roof,
            bare: open,
            road,
            ..Cover::default()
        }
    }

    /// The cover-weighted sum of a value given per land cover (`per_cover.tree` for trees, …).
    pub(crate) fn weighted(&self, per_cover: &Cover) -> f32 {
        per_cover.tree * self.tree
            + per_cover.grass * self.grass
            + per_cover.crop * self.crop
            + per_cover.bare * self.bare
            + per_cover.developed * self.developed
            + per_cover.road * self.road
            + per_cover.roof * self.roof
            + per_cover.other * self.other
            + per_cover.water * self.water
    }

    /// Typical sunlit luminance of this cover: the reference that tells a shadowed pixel (much
    /// darker) from a sunlit one when snow is laid on it.
    pub(crate) fn sunlit_luminance(&self) -> f32 {
        0.17 * self.tree
            + 0.26 * self.grass
            + 0.36 * self.crop
            + 0.42 * self.bare
            + 0.50 * self.developed
            + 0.28 * self.road
            + 0.10 * self.water
            + 0.45 * self.roof
            + 0.35 * self.other
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn total(c: &Cover) -> f32 {
        c.tree + c.grass + c.crop + c.bare + c.developed + c.road + c.water + c.roof + c.other
    }

    #[test]
    fn colour_rule_recognises_typical_surfaces() {
        let tree = Cover::from_colour([0.08, 0.20, 0.06]);
        assert!(tree.tree > 0.9, "{tree:?}");
        let grass = Cover::from_colour([0.28, 0.46, 0.18]);
        assert!(grass.grass > 0.9, "{grass:?}");
        let water = Cover::from_colour([0.05, 0.11, 0.16]);
        assert!(water.water > 0.9, "{water:?}");
        let roof = Cover::from_colour([0.80, 0.78, 0.75]);
        assert!(roof.roof > 0.9, "{roof:?}");
        let asphalt = Cover::from_colour([0.20, 0.20, 0.21]);
        assert!(asphalt.road > 0.9, "{asphalt:?}");
        for c in [tree, grass, water, roof, asphalt] {
            assert!((total(&c) - 1.0).abs() < 1e-5, "{c:?}");
        }
    }

    #[test]
    fn class_ids_are_one_hot() {
        assert_eq!(Cover::from_class(5.0).tree, 1.0);
        assert_eq!(Cover::from_class(6.0).water, 1.0);
        assert_eq!(Cover::from_class(8.0).roof, 1.0);
        assert_eq!(Cover::from_class(f32::NAN).other, 1.0);
        assert_eq!(Cover::from_class(42.0).other, 1.0);
    }
}
