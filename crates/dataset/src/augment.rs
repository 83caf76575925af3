//! Image preparation and training augmentation, as the release configures it
//! (`datasets/augmentations.py` `StereoAugmentor`, the RAFT-Stereo protocol MonSter++ adopts, with
//! the values of `training_configs/*.yaml`).
//!
//! [`normalize_unit_range`] / [`normalize_sample`] bring images to `[0, 1]` (the release's
//! `_normalize_image`, done before augmentation). [`augment_sample`] then applies, in the
//! release's order, to every raster of a [`Sample`] consistently:
//! 1. **scale and stretch** `2^U(min,max)` (× `2^U(±max_stretch)` per axis with `stretch_prob`):
//!    images bilinear with antialiasing (torchvision `resize`), the building mask the same then
//!    `> 0.5` (as the release), the validity mask nearest-neighbour, disparities bilinear and
//!    multiplied by the exact x scale `new_width / width`;
//! 2. **flips**, only with `do_flip` (off in every release config): vertical flips are applied to
//!    every raster (rows stay epipolar lines, disparities unchanged). Horizontal flips are refused
//!    by [`AugmentConfig::validate`]: a stereo-valid horizontal flip mirrors AND swaps the views,
//!    which needs the right view's disparity and masks; a sample has only the left ones. (The
//!    release's flip mirrors without swapping and negates the disparity, which MonSter++ cannot
//!    predict and its z-buffer does not handle.)
//! 3. **random crop** `crop_height × crop_width` (images smaller than the crop are padded at the
//!    bottom/right: images reflected, disparities replicated, validity false);
//! 4. **overlap shift**: with `shift_prob`, both right images move left by `s ~ Exp(shift_scale)`
//!    px (capped at `shift_max`, default W/2), zero-filled; disparities grow by `s`, and targets
//!    whose match falls in the emptied strip become NaN (unknown);
//! 5. **colour jitter** (torchvision `ColorJitter` + gamma) of the INPUT pair only, the same draw
//!    for both views unless the asymmetric case is drawn (`asymmetric_prob`);
//! 6. **eraser** on the INPUT right image (1–3 boxes of 50–100 px filled with its mean colour).
//!
//! The real pair, the disparities and the masks never see steps 5–6: they are the supervision.
//! All randomness comes from the [`SplitMix64`] passed in, so the same seed gives the same sample.

use raster::resize::resize_antialias_bilinear;
use raster::{Image, Mask};
use serde::{Deserialize, Serialize};

use crate::rng::SplitMix64;
use crate::sample::Sample;
use crate::{DatasetError, Result};

/// The release's image normalisation: `/255` when the image spans exactly 0–255, else min–max to
/// [0, 1] (unchanged when flat). NaN are ignored for the range.
pub fn normalize_unit_range(image: &Image) -> Image {
    let mut out = image.clone();
    let Some((lo, hi)) = image.finite_range() else {
        return out;
    };
    if lo == 0.0 && hi == 255.0 {
        out.data_mut().iter_mut().for_each(|v| *v /= 255.0);
    } else if hi - lo > 1e-5 {
        out.data_mut()
            .iter_mut()
            .for_each(|v| *v = (*v - lo) / (hi - lo));
    }
    out
}

/// [`normalize_unit_range`] on the four images of a sample, each on its own range (as the
/// release's dataset does): the step before [`augment_sample`] and the loss.
pub fn normalize_sample(sample: &mut Sample) {
    for image in [
        &mut sample.input_left,
        &mut sample.input_right,
        &mut sample.real_left,
        &mut sample.real_right,
    ] {
        *image = normalize_unit_range(image);
    }
}

/// Every parameter of the augmentation; `Default` = the release's training configs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AugmentConfig {
    /// Output size (release `crop_size: 512`, square).
    pub crop_height: usize,
    pub crop_width: usize,
    /// log2 range of the isotropic scale (release −0.2, 0.4).
    pub min_scale: f64,
    pub max_scale: f64,
    /// Probability and log2 range of the per-axis stretch (0.8, 0.2).
    pub stretch_prob: f64,
    pub max_stretch: f64,
    /// Flips on/off (release false). Only vertical flips are supported (see the module docs).
    pub do_flip: bool,
    /// Must be 0 when `do_flip` is true (release default 0.5, unused there).
    pub h_flip_prob: f64,
    pub v_flip_prob: f64,
    /// ±2-row jitter of the input right image's crop (release false).
    pub yjitter: bool,
    /// ColorJitter ranges (release: saturation [0, 1.4], brightness 0.4, contrast 0.4,
    /// hue 0.159 ≈ 0.5/π).
    pub saturation_range: [f64; 2],
    pub brightness: f64,
    pub contrast: f64,
    pub hue: f64,
    /// `[gamma_lo, gamma_hi, gain_lo, gain_hi]` (release all 1: no-op).
    pub gamma_range: [f64; 4],
    /// Probability of jittering the two views independently (0.2).
    pub asymmetric_prob: f64,
    /// Eraser on the input right image: probability (0.5), box side range and box count (1–3).
    pub eraser_prob: f64,
    pub eraser_min_size: usize,
    pub eraser_max_size: usize,
    pub eraser_max_boxes: usize,
    /// Overlap shift of the right images: probability (0.5), mean of the exponential draw
    /// (100 px) and cap (None = half the width).
    pub shift_prob: f64,
    pub shift_scale: f64,
    pub shift_max: Option<usize>,
}

impl Default for AugmentConfig {
    fn default() -> Self {
        Self {
            crop_height: 512,
            crop_width: 512,
            min_scale: -0.2,
            max_scale: 0.4,
            stretch_prob: 0.8,
            max_stretch: 0.2,
            do_flip: false,
            h_flip_prob: 0.0,
            v_flip_prob: 0.1,
            yjitter: false,
            saturation_range: [0.0, 1.4],
            brightness: 0.4,
            contrast: 0.4,
            hue: 0.159,
            gamma_range: [1.0, 1.0, 1.0, 1.0],
            asymmetric_prob: 0.2,
            eraser_prob: 0.5,
            eraser_min_size: 50,
            eraser_max_size: 100,
            eraser_max_boxes: 3,
            shift_prob: 0.5,
            shift_scale: 100.0,
            shift_max: None,
        }
    }
}

impl AugmentConfig {
    /// Only the geometric part (scale, crop, shift) of the defaults: what a test of disparity
    /// consistency, or a run without photometric augmentation, needs.
    pub fn geometric_only(crop_height: usize, crop_width: usize) -> Self {
        Self {
            crop_height,
            crop_width,
            brightness: 0.0,
            contrast: 0.0,
            saturation_range: [1.0, 1.0],
            hue: 0.0,
            asymmetric_prob: 0.0,
            eraser_prob: 0.0,
            ..Self::default()
        }
    }

    /// Checks every value; the error names the field and the fix.
    pub fn validate(&self) -> Result<()> {
        let bad = |why: String| Err(DatasetError::Invalid(format!("augmentation.{why}")));
        if self.crop_height == 0 || self.crop_width == 0 {
            return bad("crop_height/crop_width must be > 0".into());
        }
        if self.min_scale.is_nan() || self.max_scale.is_nan() || self.min_scale > self.max_scale {
            return bad(format!(
                "min_scale ({}) must not exceed max_scale ({})",
                self.min_scale, self.max_scale
            ));
        }
        if self.do_flip && self.h_flip_prob > 0.0 {
            return bad(
                "h_flip_prob must be 0: a horizontal flip of a stereo pair must swap the views and \
                 needs right-view disparity and masks, which samples do not have (the release \
                 trains with do_flip: false); vertical flips (v_flip_prob) are supported"
                    .into(),
            );
        }
        for (name, p) in [
            ("stretch_prob", self.stretch_prob),
            ("v_flip_prob", self.v_flip_prob),
            ("asymmetric_prob", self.asymmetric_prob),
            ("eraser_prob", self.eraser_prob),
            ("shift_prob", self.shift_prob),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return bad(format!("{name} must be a probability in [0, 1], got {p}"));
            }
        }
        if self.brightness < 0.0 || self.contrast < 0.0 || !(0.0..=0.5).contains(&self.hue) {
            return bad("brightness and contrast must be ≥ 0, hue in [0, 0.5]".into());
        }
        if self.saturation_range[0] < 0.0 || self.saturation_range[0] > self.saturation_range[1] {
            return bad("saturation_range must be [lo, hi] with 0 ≤ lo ≤ hi".into());
        }
        if self.eraser_min_size > self.eraser_max_size || self.eraser_max_boxes == 0 {
            return bad("eraser_min_size ≤ eraser_max_size and eraser_max_boxes ≥ 1".into());
        }
        if self.shift_scale <= 0.0 {
            return bad(format!("shift_scale must be > 0, got {}", self.shift_scale));
        }
        Ok(())
    }
}

/// Random draws used by the augmentation (uniform floats, inclusive integer ranges, exponential).
trait Draw {
    fn unit(&mut self) -> f64;
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
    /// Inclusive `lo..=hi`, as Python's `random.randint`.
    fn randint(&mut self, lo: i64, hi: i64) -> i64;
}

impl Draw for SplitMix64 {
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    fn randint(&mut self, lo: i64, hi: i64) -> i64 {
        lo + self.below((hi - lo + 1) as usize) as i64
    }
}

/// One augmented copy of `sample` (images already in `[0, 1]`, see [`normalize_sample`]), drawn
/// from `rng`. Sizes of all rasters must agree.
pub fn augment_sample(
    sample: &Sample,
    config: &AugmentConfig,
    rng: &mut SplitMix64,
) -> Result<Sample> {
    config.validate()?;
    check_sample(sample)?;
    let mut s = sample.clone();
    scale_and_stretch(&mut s, config, rng)?;
    // Flips are vertical only (validated).
    if config.do_flip && rng.chance(config.v_flip_prob) {
        flip_vertically(&mut s);
    }
    random_crop(&mut s, config, rng)?;
    overlap_shift(&mut s, config, rng);
    jitter_input_colours(&mut s, config, rng);
    if rng.chance(config.eraser_prob) {
        erase(&mut s.input_right, config, rng);
    }
    Ok(s)
}

/// Step 1: a random isotropic scale, sometimes stretched per axis; disparities scale with x.
fn scale_and_stretch(s: &mut Sample, config: &AugmentConfig, rng: &mut SplitMix64) -> Result<()> {
    let (w, h) = s.teacher.size();
    let scale = 2f64.powf(rng.uniform(config.min_scale, config.max_scale));
    let (mut sx, mut sy) = (scale, scale);
    if rng.chance(config.stretch_prob) {
        sx *= 2f64.powf(rng.uniform(-config.max_stretch, config.max_stretch));
        sy *= 2f64.powf(rng.uniform(-config.max_stretch, config.max_stretch));
    }
    let nw = ((w as f64 * sx) as usize).max(1);
    let nh = ((h as f64 * sy) as usize).max(1);
    if (nw, nh) != (w, h) {
        for image in images_mut(s) {
            *image = resize_antialias_bilinear(image, nw, nh)?;
        }
        let building = resize_antialias_bilinear(&s.building_left.to_image(), nw, nh)?;
        s.building_left = threshold(&building);
        s.valid_left = resize_nearest(&s.valid_left, nw, nh);
        let x_scale = nw as f32 / w as f32;
        for d in disparities_mut(s) {
            *d = resize_bilinear(d, nw, nh);
            d.data_mut().iter_mut().for_each(|v| *v *= x_scale);
        }
    }
    Ok(())
}

/// Step 2: every raster and mask upside down (rows of a rectified pair stay matched).
fn flip_vertically(s: &mut Sample) {
    for image in rasters_mut(s) {
        *image = flip_vertical(image);
    }
    s.valid_left = threshold(&flip_vertical(&s.valid_left.to_image()));
    s.building_left = threshold(&flip_vertical(&s.building_left.to_image()));
}

/// Step 3: a random crop of the configured size (reflect-padded first when the sample is
/// smaller), the input right image optionally jittered by ±2 rows.
fn random_crop(s: &mut Sample, config: &AugmentConfig, rng: &mut SplitMix64) -> Result<()> {
    let (th, tw) = (config.crop_height, config.crop_width);
    let (w, h) = s.teacher.size();
    if h < th || w < tw {
        let (pw, ph) = (w.max(tw), h.max(th));
        for image in images_mut(s) {
            *image = pad(image, pw, ph, Padding::Reflect);
        }
        s.building_left = threshold(&pad(&s.building_left.to_image(), pw, ph, Padding::Reflect));
        for d in disparities_mut(s) {
            *d = pad(d, pw, ph, Padding::Replicate);
        }
        s.valid_left = threshold(&pad(&s.valid_left.to_image(), pw, ph, Padding::Zero));
    }
    let (w, h) = s.teacher.size();
    let y0 = rng.randint(0, (h - th) as i64) as usize;
    let x0 = rng.randint(0, (w - tw) as i64) as usize;
    let y_right = if config.yjitter && rng.chance(0.5) {
        (y0 as i64 + rng.randint(-2, 2)).clamp(0, (h - th) as i64) as usize
    } else {
        y0
    };
    let crop = |im: &Image, y: usize| raster::geometry::crop(im, x0, y, tw, th);
    s.input_left = crop(&s.input_left, y0)?;
    s.input_right = crop(&s.input_right, y_right)?;
    s.real_left = crop(&s.real_left, y0)?;
    s.real_right = crop(&s.real_right, y0)?;
    for d in disparities_mut(s) {
        *d = crop(d, y0)?;
    }
    s.valid_left = threshold(&crop(&s.valid_left.to_image(), y0)?);
    s.building_left = threshold(&crop(&s.building_left.to_image(), y0)?);
    Ok(())
}

/// Step 4: both right images shifted left by an exponential draw (less overlap), disparities
/// reduced to match.
fn overlap_shift(s: &mut Sample, config: &AugmentConfig, rng: &mut SplitMix64) {
    let tw = config.crop_width;
    if rng.chance(config.shift_prob) {
        let cap = config.shift_max.unwrap_or(tw / 2);
        let shift = ((-(1.0 - rng.unit()).ln() * config.shift_scale) as usize).min(cap);
        if shift > 0 {
            s.input_right = shift_left(&s.input_right, shift);
            s.real_right = shift_left(&s.real_right, shift);
            for d in disparities_mut(s) {
                shift_disparity(d, shift);
            }
        }
    }
}

/// Step 5: colour jitter (sometimes drawn separately per view) and gamma of the input pair.
fn jitter_input_colours(s: &mut Sample, config: &AugmentConfig, rng: &mut SplitMix64) {
    let (left, right) = if rng.chance(config.asymmetric_prob) {
        let a = Jitter::draw(config, rng);
        let b = Jitter::draw(config, rng);
        (a.apply(&s.input_left), b.apply(&s.input_right))
    } else {
        let j = Jitter::draw(config, rng);
        (j.apply(&s.input_left), j.apply(&s.input_right))
    };
    let gamma = rng.uniform(config.gamma_range[0], config.gamma_range[1]) as f32;
    let gain = rng.uniform(config.gamma_range[2], config.gamma_range[3]) as f32;
    s.input_left = adjust_gamma(left, gamma, gain);
    s.input_right = adjust_gamma(right, gamma, gain);
}

fn check_sample(s: &Sample) -> Result<()> {
    let size = s.teacher.size();
    let mut sizes = vec![
        ("input_left", s.input_left.size()),
        ("input_right", s.input_right.size()),
        ("real_left", s.real_left.size()),
        ("real_right", s.real_right.size()),
        ("valid_left", s.valid_left.size()),
        ("building_left", s.building_left.size()),
    ];
    if let Some(l) = &s.lidar {
        sizes.push(("lidar", l.size()));
    }
    for (name, got) in sizes {
        if got != size {
            return Err(DatasetError::Invalid(format!(
                "augment_sample: {}: {name} is {}x{} but the teacher is {}x{}",
                s.stem, got.0, got.1, size.0, size.1
            )));
        }
    }
    for (name, im) in [
        ("input_left", &s.input_left),
        ("input_right", &s.input_right),
        ("real_left", &s.real_left),
        ("real_right", &s.real_right),
    ] {
        if let Some((lo, hi)) = im.finite_range() {
            if lo < -1e-3 || hi > 1.0 + 1e-3 {
                return Err(DatasetError::Invalid(format!(
                    "augment_sample: {}: {name} spans [{lo}, {hi}]; normalise the sample to [0, 1] \
                     first (dataset::augment::normalize_sample)",
                    s.stem
                )));
            }
        }
    }
    Ok(())
}

fn images_mut(s: &mut Sample) -> [&mut Image; 4] {
    [
        &mut s.input_left,
        &mut s.input_right,
        &mut s.real_left,
        &mut s.real_right,
    ]
}

fn disparities_mut(s: &mut Sample) -> Vec<&mut Image> {
    let mut v = vec![&mut s.teacher];
    if let Some(l) = s.lidar.as_mut() {
        v.push(l);
    }
    v
}

fn rasters_mut(s: &mut Sample) -> Vec<&mut Image> {
    let mut v: Vec<&mut Image> = vec![
        &mut s.input_left,
        &mut s.input_right,
        &mut s.real_left,
        &mut s.real_right,
        &mut s.teacher,
    ];
    if let Some(l) = s.lidar.as_mut() {
        v.push(l);
    }
    v
}

fn threshold(image: &Image) -> Mask {
    let (w, h) = image.size();
    Mask::from_fn(w, h, |x, y| image.get(x, y, 0) > 0.5)
}

/// torch `F.interpolate(mode="nearest")`: source index `floor(dst · in / out)`.
fn resize_nearest(mask: &Mask, width: usize, height: usize) -> Mask {
    let (w, h) = mask.size();
    let (fx, fy) = (w as f32 / width as f32, h as f32 / height as f32);
    Mask::from_fn(width, height, |x, y| {
        let sx = ((x as f32 * fx) as usize).min(w - 1);
        let sy = ((y as f32 * fy) as usize).min(h - 1);
        mask.get(sx, sy)
    })
}

/// Source index and weight of torch bilinear `align_corners=False` (no antialias).
fn linear_source(dst: usize, scale: f32, size: usize) -> (usize, usize, f32) {
    let src = ((dst as f32 + 0.5) * scale - 0.5).max(0.0);
    let i0 = (src as usize).min(size - 1);
    let i1 = (i0 + 1).min(size - 1);
    (i0, i1, src - i0 as f32)
}

/// torch `F.interpolate(bilinear, align_corners=False)` of a single-channel map; a NaN neighbour
/// makes the output NaN (an unknown disparity spreads, it is never blended into a known one).
fn resize_bilinear(image: &Image, width: usize, height: usize) -> Image {
    let (w, h) = image.size();
    let (sx, sy) = (w as f32 / width as f32, h as f32 / height as f32);
    Image::from_fn(width, height, |x, y| {
        let (x0, x1, fx) = linear_source(x, sx, w);
        let (y0, y1, fy) = linear_source(y, sy, h);
        let p = |xx, yy| image.get(xx, yy, 0);
        let top = p(x0, y0) * (1.0 - fx) + p(x1, y0) * fx;
        let bottom = p(x0, y1) * (1.0 - fx) + p(x1, y1) * fx;
        top * (1.0 - fy) + bottom * fy
    })
}

fn flip_vertical(image: &Image) -> Image {
    let (w, h) = image.size();
    let row = w * image.channels();
    let data: Vec<f32> = (0..h)
        .rev()
        .flat_map(|y| image.data()[y * row..(y + 1) * row].iter().copied())
        .collect();
    Image::new(w, h, image.channels(), data).expect("same size")
}

#[derive(Clone, Copy)]
enum Padding {
    Reflect,
    Replicate,
    Zero,
}

/// Pads at the bottom and right to `width × height`.
fn pad(image: &Image, width: usize, height: usize, mode: Padding) -> Image {
    let (w, h) = image.size();
    let c = image.channels();
    let index = |i: usize, n: usize| -> Option<usize> {
        if i < n {
            return Some(i);
        }
        match mode {
            Padding::Zero => None,
            Padding::Replicate => Some(n - 1),
            // Mirror without repeating the edge (torch "reflect"), folded for any pad length.
            Padding::Reflect if n == 1 => Some(0),
            Padding::Reflect => {
                let period = 2 * (n - 1);
                let k = i % period;
                Some(if k < n { k } else { period - k })
            }
        }
    };
    let mut data = vec![0.0; width * height * c];
    for y in 0..height {
        for x in 0..width {
            if let (Some(sx), Some(sy)) = (index(x, w), index(y, h)) {
                let o = (y * width + x) * c;
                data[o..o + c].copy_from_slice(image.pixel(sx, sy));
            }
        }
    }
    Image::new(width, height, c, data).expect("sizes match")
}

/// Moves the content `shift` columns to the left, zero-filling the right strip.
fn shift_left(image: &Image, shift: usize) -> Image {
    let (w, h) = image.size();
    let c = image.channels();
    let mut out = Image::filled(w, h, c, 0.0);
    if shift < w {
        for y in 0..h {
            let src = &image.row(y)[shift * c..];
            out.data_mut()[y * w * c..y * w * c + src.len()].copy_from_slice(src);
        }
    }
    out
}

/// `d += shift`; a target whose match `x − d` leaves the shifted content `[0, W − shift)` becomes
/// unknown (the release clears its validity mask there instead; NaN keeps it per disparity).
fn shift_disparity(d: &mut Image, shift: usize) {
    let (w, _) = d.size();
    let limit = w.saturating_sub(shift) as f32;
    for (i, v) in d.data_mut().iter_mut().enumerate() {
        *v += shift as f32;
        let m = (i % w) as f32 - *v;
        if !(m >= 0.0 && m < limit) {
            *v = f32::NAN;
        }
    }
}

/// One draw of torchvision's `ColorJitter`: factors and the order of the four operations.
struct Jitter {
    order: [usize; 4],
    brightness: f32,
    contrast: f32,
    saturation: f32,
    hue: f32,
}

impl Jitter {
    fn draw(c: &AugmentConfig, rng: &mut SplitMix64) -> Self {
        let mut order = [0, 1, 2, 3];
        rng.shuffle(&mut order);
        let around_one =
            |rng: &mut SplitMix64, v: f64| rng.uniform((1.0 - v).max(0.0), 1.0 + v) as f32;
        Self {
            order,
            brightness: around_one(rng, c.brightness),
            contrast: around_one(rng, c.contrast),
            saturation: rng.uniform(c.saturation_range[0], c.saturation_range[1]) as f32,
            hue: rng.uniform(-c.hue, c.hue) as f32,
        }
    }

    fn apply(&self, image: &Image) -> Image {
        let mut out = image.clone();
        for &op in &self.order {
            match op {
                0 => blend_with(&mut out, self.brightness, |_| 0.0),
                1 => {
                    let mean = mean_gray(&out);
                    blend_with(&mut out, self.contrast, |_| mean);
                }
                2 if out.channels() == 3 => {
                    let gray = out.data().chunks_exact(3).map(gray_of).collect::<Vec<_>>();
                    blend_with(&mut out, self.saturation, |p| gray[p]);
                }
                3 if out.channels() == 3 => shift_hue(&mut out, self.hue),
                _ => {}
            }
        }
        out
    }
}

/// torchvision `rgb_to_grayscale` weights.
fn gray_of(px: &[f32]) -> f32 {
    0.2989 * px[0] + 0.587 * px[1] + 0.114 * px[2]
}

fn mean_gray(image: &Image) -> f32 {
    let n = (image.width() * image.height()).max(1) as f64;
    let sum: f64 = if image.channels() == 3 {
        image
            .data()
            .chunks_exact(3)
            .map(|p| gray_of(p) as f64)
            .sum()
    } else {
        image.data().iter().map(|&v| v as f64).sum::<f64>() / image.channels() as f64
    };
    (sum / n) as f32
}

/// torchvision `_blend`: `(f·img + (1 − f)·other).clamp(0, 1)`, `other(pixel)` one value per pixel.
fn blend_with(image: &mut Image, factor: f32, other: impl Fn(usize) -> f32) {
    let c = image.channels();
    for (p, px) in image.data_mut().chunks_exact_mut(c).enumerate() {
        let o = other(p);
        for v in px {
            *v = (factor * *v + (1.0 - factor) * o).clamp(0.0, 1.0);
        }
    }
}

/// torchvision `adjust_hue` on an RGB image in [0, 1]: rotate the HSV hue by `factor` turns.
fn shift_hue(image: &mut Image, factor: f32) {
    for px in image.data_mut().chunks_exact_mut(3) {
        let (r, g, b) = (px[0], px[1], px[2]);
        let maxc = r.max(g).max(b);
        let minc = r.min(g).min(b);
        let cr = maxc - minc;
        let v = maxc;
        let s = if maxc > 0.0 { cr / maxc } else { 0.0 };
        let h = if cr == 0.0 {
            0.0
        } else {
            let rc = (maxc - r) / cr;
            let gc = (maxc - g) / cr;
            let bc = (maxc - b) / cr;
            let h = if maxc == r {
                bc - gc
            } else if maxc == g {
                2.0 + rc - bc
            } else {
                4.0 + gc - rc
            };
            (h / 6.0 + 1.0).rem_euclid(1.0)
        };
        let h = (h + factor).rem_euclid(1.0);
        let i = (h * 6.0).floor();
        let f = h * 6.0 - i;
        let p = (v * (1.0 - s)).clamp(0.0, 1.0);
        let q = (v * (1.0 - s * f)).clamp(0.0, 1.0);
        let t = (v * (1.0 - s * (1.0 - f))).clamp(0.0, 1.0);
        let (nr, ng, nb) = match (i as i32).rem_euclid(6) {
            0 => (v, t, p),
            1 => (q, v, p),
            2 => (p, v, t),
            3 => (p, q, v),
            4 => (t, p, v),
            _ => (v, p, q),
        };
        px[0] = nr;
        px[1] = ng;
        px[2] = nb;
    }
}

/// torchvision `adjust_gamma`: `gain · img^gamma`, clamped to [0, 1] (as the release).
fn adjust_gamma(mut image: Image, gamma: f32, gain: f32) -> Image {
    if gamma != 1.0 || gain != 1.0 {
        for v in image.data_mut() {
            *v = (gain * v.max(0.0).powf(gamma)).clamp(0.0, 1.0);
        }
    }
    image
}

/// The release's `eraser_aug`: 1..=max boxes at uniform corners (inclusive of the far edge, so a
/// box may be empty), sides uniform in the size range, filled with the image's mean colour.
fn erase(image: &mut Image, c: &AugmentConfig, rng: &mut SplitMix64) {
    let (w, h) = image.size();
    let ch = image.channels();
    let n = (w * h).max(1) as f64;
    let mean: Vec<f32> = (0..ch)
        .map(|k| {
            (image
                .data()
                .iter()
                .skip(k)
                .step_by(ch)
                .map(|&v| v as f64)
                .sum::<f64>()
                / n) as f32
        })
        .collect();
    let boxes = rng.randint(1, c.eraser_max_boxes as i64);
    for _ in 0..boxes {
        let x0 = rng.randint(0, w as i64) as usize;
        let y0 = rng.randint(0, h as i64) as usize;
        let dx = rng.randint(c.eraser_min_size as i64, c.eraser_max_size as i64) as usize;
        let dy = rng.randint(c.eraser_min_size as i64, c.eraser_max_size as i64) as usize;
        for y in y0..(y0 + dy).min(h) {
            for x in x0..(x0 + dx).min(w) {
                let o = (y * w + x) * ch;
                image.data_mut()[o..o + ch].copy_from_slice(&mean);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn release_normalisation() {
        let im = Image::new(3, 1, 1, vec![0.0, 255.0, 51.0]).unwrap();
        assert_eq!(normalize_unit_range(&im).data(), &[0.0, 1.0, 0.2]);
        let im = Image::new(2, 1, 1, vec![10.0, 20.0]).unwrap();
        assert_eq!(normalize_unit_range(&im).data(), &[0.0, 1.0]);
        let flat = Image::filled(2, 2, 1, 7.0);
        assert_eq!(normalize_unit_range(&flat).data(), flat.data());
    }
}
