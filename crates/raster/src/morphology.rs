//! Binary morphology on masks: connected components, small-component removal, hole filling, dilation.
//!
//! These are the clean-up steps of the reference segmentation scripts (scipy.ndimage `label` with a
//! full 3×3 structure, `binary_dilation`), reproduced exactly. Every operation runs in linear time
//! with an explicit work list (no recursion), so large masks cannot overflow the stack.

use crate::Mask;

/// 8-connected components of the pixels of a mask that equal a chosen value.
///
/// Labels are numbered from 1 in raster order of each component's first pixel (scipy's order);
/// 0 marks pixels that do not take part.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Components {
    width: usize,
    height: usize,
    labels: Vec<u32>,
    /// `sizes[l]` = pixel count of label `l`; `sizes[0]` counts the pixels not labelled.
    sizes: Vec<usize>,
}

impl Components {
    /// Number of components.
    pub fn count(&self) -> usize {
        self.sizes.len() - 1
    }

    /// Label of pixel `(x, y)` (0 = not part of any component).
    #[inline]
    pub fn label(&self, x: usize, y: usize) -> u32 {
        self.labels[y * self.width + x]
    }

    /// All labels, row-major.
    pub fn labels(&self) -> &[u32] {
        &self.labels
    }

    /// Pixel count of component `label` (1-based).
    pub fn size(&self, label: u32) -> usize {
        self.sizes[label as usize]
    }

    /// Sizes of components 1..=count, in label order.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes[1..]
    }

    /// For each label (index 0 included), whether the component has a pixel on the first or last
    /// row or column.
    pub fn touches_border(&self) -> Vec<bool> {
        let mut touches = vec![false; self.sizes.len()];
        let (w, h) = (self.width, self.height);
        if w == 0 || h == 0 {
            return touches;
        }
        for x in 0..w {
            touches[self.label(x, 0) as usize] = true;
            touches[self.label(x, h - 1) as usize] = true;
        }
        for y in 0..h {
            touches[self.label(0, y) as usize] = true;
            touches[self.label(w - 1, y) as usize] = true;
        }
        touches
    }
}

/// Labels the 8-connected components of the pixels equal to `value`.
pub fn label_components(mask: &Mask, value: bool) -> Components {
    let (w, h) = mask.size();
    let data = mask.data();
    let mut labels = vec![0u32; w * h];
    let mut sizes = vec![data.iter().filter(|&&v| v != value).count()];
    let mut stack: Vec<usize> = Vec::new();
    for start in 0..w * h {
        if data[start] != value || labels[start] != 0 {
            continue;
        }
        let label = sizes.len() as u32;
        labels[start] = label;
        stack.push(start);
        let mut size = 0usize;
        while let Some(i) = stack.pop() {
            size += 1;
            let (x, y) = (i % w, i / w);
            let (x0, x1) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let (y0, y1) = (y.saturating_sub(1), (y + 1).min(h - 1));
            for ny in y0..=y1 {
                for nx in x0..=x1 {
                    let j = ny * w + nx;
                    if data[j] == value && labels[j] == 0 {
                        labels[j] = label;
                        stack.push(j);
                    }
                }
            }
        }
        sizes.push(size);
    }
    Components {
        width: w,
        height: h,
        labels,
        sizes,
    }
}

/// Drops the 8-connected True components with fewer than `min_pixels` pixels (a component of
/// exactly `min_pixels` is kept). `min_pixels == 0` (or 1) changes nothing.
pub fn remove_small_components(mask: &Mask, min_pixels: usize) -> Mask {
    if min_pixels <= 1 {
        return mask.clone();
    }
    let comps = label_components(mask, true);
    let data = comps
        .labels
        .iter()
        .map(|&l| l != 0 && comps.sizes[l as usize] >= min_pixels)
        .collect();
    Mask::new(mask.width(), mask.height(), data).expect("same size")
}

/// Sets True every 8-connected False component ("hole") that touches no image border and has
/// fewer than `max_pixels` pixels (strictly). `max_pixels == 0` changes nothing.
pub fn fill_holes(mask: &Mask, max_pixels: usize) -> Mask {
    if max_pixels == 0 {
        return mask.clone();
    }
    let holes = label_components(mask, false);
    let border = holes.touches_border();
    let fill: Vec<bool> = (0..holes.sizes.len())
        .map(|l| l != 0 && !border[l] && holes.sizes[l] < max_pixels)
        .collect();
    let data = mask
        .data()
        .iter()
        .zip(&holes.labels)
        .map(|(&v, &l)| v || fill[l as usize])
        .collect();
    Mask::new(mask.width(), mask.height(), data).expect("same size")
}

/// Binary dilation by a (2·radius+1)² square, pixels outside the image counting as False: equal to
/// `radius` iterations of a 3×3 dilation (scipy `binary_dilation(structure=ones((3,3)),
/// iterations=radius)`). Separable, linear time whatever the radius.
pub fn dilate_square(mask: &Mask, radius: usize) -> Mask {
    if radius == 0 {
        return mask.clone();
    }
    let (w, h) = mask.size();
    let rows = dilate_runs(mask.data(), w, h, 1, w, radius);
    let out = dilate_runs(&rows, h, w, w, 1, radius);
    Mask::new(w, h, out).expect("same size")
}

/// 1-D dilation of `lines` lines of length `len` (element stride `step`, line stride `line_step`):
/// out[i] is true when any of in[i−r..=i+r] (clipped to the line) is true.
fn dilate_runs(
    data: &[bool],
    len: usize,
    lines: usize,
    step: usize,
    line_step: usize,
    r: usize,
) -> Vec<bool> {
    let mut out = vec![false; data.len()];
    // prefix[i] = number of true samples among the first i of the line.
    let mut prefix = vec![0u32; len + 1];
    for line in 0..lines {
        let base = line * line_step;
        for i in 0..len {
            prefix[i + 1] = prefix[i] + data[base + i * step] as u32;
        }
        for i in 0..len {
            let lo = i.saturating_sub(r);
            let hi = (i + r + 1).min(len);
            out[base + i * step] = prefix[hi] > prefix[lo];
        }
    }
    out
}

/// Pixel count of an area given in percent of `total_pixels`: Python's
/// `int(round((pct / 100.0) * total))`, rounding half to even. Negative results give 0.
pub fn area_from_percent(pct: f64, total_pixels: usize) -> usize {
    let px = ((pct / 100.0) * total_pixels as f64).round_ties_even();
    if px.is_finite() && px > 0.0 {
        px as usize
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(rows: &[&str]) -> Mask {
        let h = rows.len();
        let w = rows[0].len();
        let data = rows
            .iter()
            .flat_map(|r| r.bytes().map(|b| b == b'#'))
            .collect();
        Mask::new(w, h, data).unwrap()
    }

    #[test]
    fn diagonal_pixels_are_one_component() {
        let m = mask(&["#..", ".#.", "..#", "#.."]);
        let c = label_components(&m, true);
        assert_eq!(c.count(), 2);
        assert_eq!(c.sizes(), &[3, 1]);
        assert_eq!(c.label(2, 2), 1);
        assert_eq!(c.label(0, 3), 2);
    }

    #[test]
    fn removal_keeps_components_of_exactly_the_threshold() {
        let m = mask(&["##..#", ".....", "###.."]);
        let out = remove_small_components(&m, 2);
        assert_eq!(out, mask(&["##...", ".....", "###.."]));
        assert_eq!(remove_small_components(&m, 0), m);
    }

    #[test]
    fn holes_touching_the_border_are_never_filled() {
        let m = mask(&["#####", "#..##", "#####", "##.##", "##.##"]);
        let out = fill_holes(&m, 3);
        assert_eq!(out, mask(&["#####", "#####", "#####", "##.##", "##.##"]));
        // strictly smaller than the threshold
        assert_eq!(fill_holes(&m, 2), m);
    }

    #[test]
    fn dilation_is_a_clipped_square() {
        let m = mask(&[".....", ".....", "....#"]);
        assert_eq!(dilate_square(&m, 1), mask(&[".....", "...##", "...##"]));
        assert_eq!(dilate_square(&m, 2).count(), 9);
    }

    #[test]
    fn percent_rounds_half_to_even() {
        assert_eq!(area_from_percent(0.1, 1024 * 1024), 1049);
        assert_eq!(area_from_percent(0.05, 1024 * 1024), 524);
        assert_eq!(area_from_percent(50.0, 5), 2); // 2.5 → 2
        assert_eq!(area_from_percent(50.0, 7), 4); // 3.5 → 4
        assert_eq!(area_from_percent(-1.0, 100), 0);
    }

    #[test]
    fn large_mask_does_not_overflow_the_stack() {
        let m = Mask::filled(1500, 1500, true);
        let c = label_components(&m, true);
        assert_eq!(c.sizes(), &[1500 * 1500]);
    }
}
