//! [`LossBatch`]: what the loss needs of a batch besides the predictions, collated once per
//! training step from the (augmented) samples.

use burn::tensor::{Bool, Device, Tensor, TensorData};
use raster::{Image, Mask};

use super::config::LossConfig;
use super::LossError;
use crate::mask::{supervision_mask, SupervisionParams};

/// One sample's images and masks, borrowed (the trainer builds these from `dataset::Sample`).
/// All rasters share one size; images in `[0, 1]` (the release normalises every image to `[0, 1]`
/// on load and its loss divides the 0–255 model inputs by 255 again).
#[derive(Clone, Copy, Debug)]
pub struct BatchItem<'a> {
    /// The network's INPUT left image (any season): drives the edge weights of `L_smooth`.
    pub input_left: &'a Image,
    /// The REAL synchronic pair the input derives from: the photometric term compares these.
    pub real_left: &'a Image,
    pub real_right: &'a Image,
    /// Disparity supervising `L_disp` (teacher, or LiDAR for configuration (a)); NaN = unknown.
    pub target: &'a Image,
    /// Rectification ∧ ¬water ∧ ¬tree on the left view.
    pub valid_left: &'a Mask,
    /// Building mask `V_B` on the left view.
    pub building_left: &'a Mask,
}

impl<'a> BatchItem<'a> {
    /// The item of a (normalised, augmented) `dataset::Sample`, supervised by the teacher or, for
    /// [`SupervisionTarget::Lidar`](super::SupervisionTarget::Lidar), by its LiDAR disparity
    /// (an error when the sample has none).
    pub fn from_sample(
        sample: &'a dataset::Sample,
        config: &LossConfig,
    ) -> Result<Self, LossError> {
        let target = match config.target {
            super::SupervisionTarget::Teacher => &sample.teacher,
            super::SupervisionTarget::Lidar => sample.lidar.as_ref().ok_or_else(|| {
                LossError::Input(format!(
                    "{}: the loss is LiDAR-supervised (configuration (a)) but the sample has no \
                     LiDAR disparity: give the layout a LiDAR folder (disparity_maps/GT)",
                    sample.stem
                ))
            })?,
        };
        Ok(Self {
            input_left: &sample.input_left,
            real_left: &sample.real_left,
            real_right: &sample.real_right,
            target,
            valid_left: &sample.valid_left,
            building_left: &sample.building_left,
        })
    }
}

/// The batch as tensors on the training device plus the CPU masks the z-buffer test combines
/// with each prediction.
#[derive(Clone, Debug)]
pub struct LossBatch {
    pub(crate) input_left: Tensor<4>,
    pub(crate) real_left: Tensor<4>,
    pub(crate) real_right: Tensor<4>,
    /// Target with non-finite values replaced by 0 (they are outside the supervision mask).
    pub(crate) target: Tensor<4>,
    pub(crate) supervision_t: Tensor<4, Bool>,
    supervision: Vec<bool>,
    building: Vec<bool>,
    dims: [usize; 3],
}

/// Largest image value accepted as "in [0, 1]" (a little slack for resampling overshoot).
const MAX_UNIT_VALUE: f32 = 1.0 + 1e-3;

impl LossBatch {
    /// Collates `items` on `device` (the model's device, e.g. `Device::flex().autodiff()`) and
    /// builds each supervision mask `V` with `config`'s `max_disp` and `ignore_border`.
    pub fn new(
        items: &[BatchItem<'_>],
        config: &LossConfig,
        device: &Device,
    ) -> Result<Self, LossError> {
        let first = items
            .first()
            .ok_or_else(|| LossError::Input("LossBatch::new: the batch is empty".into()))?;
        let (w, h) = first.target.size();
        let channels = first.real_left.channels();
        let params = SupervisionParams {
            max_disp: config.max_disp,
            ignore_border: config.ignore_border,
        };
        let mut supervision = Vec::with_capacity(items.len() * w * h);
        let mut building = Vec::with_capacity(items.len() * w * h);
        let mut target = Vec::with_capacity(items.len() * w * h);
        let mut images = [Vec::new(), Vec::new(), Vec::new()];
        for (i, item) in items.iter().enumerate() {
            for (name, image) in [
                ("input_left", item.input_left),
                ("real_left", item.real_left),
                ("real_right", item.real_right),
            ] {
                check_image(i, name, image, (w, h), channels)?;
            }
            if item.target.size() != (w, h) || item.target.channels() != 1 {
                return Err(LossError::Input(format!(
                    "LossBatch::new: sample {i}: target is {:?}×{}, expected {w}×{h}×1 (all samples of a batch share one size)",
                    item.target.size(),
                    item.target.channels()
                )));
            }
            if item.building_left.size() != (w, h) {
                return Err(LossError::Input(format!(
                    "LossBatch::new: sample {i}: building mask is {:?}, expected {w}×{h}",
                    item.building_left.size()
                )));
            }
            let v = supervision_mask(item.valid_left, item.target, &params)
                .map_err(|e| LossError::Input(format!("LossBatch::new: sample {i}: {e}")))?;
            supervision.extend_from_slice(v.data());
            building.extend_from_slice(item.building_left.data());
            target.extend(
                item.target
                    .data()
                    .iter()
                    .map(|&d| if d.is_finite() { d } else { 0.0 }),
            );
            images[0].extend(to_chw(item.input_left));
            images[1].extend(to_chw(item.real_left));
            images[2].extend(to_chw(item.real_right));
        }
        let b = items.len();
        let [input_left, real_left, real_right] = images
            .map(|data| Tensor::from_data(TensorData::new(data, [b, channels, h, w]), device));
        Ok(Self {
            input_left,
            real_left,
            real_right,
            target: Tensor::from_data(TensorData::new(target, [b, 1, h, w]), device),
            supervision_t: bool_tensor(&supervision, [b, 1, h, w], device),
            supervision,
            building,
            dims: [b, h, w],
        })
    }

    /// `[batch, height, width]`.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// The supervision masks `V`, row-major `[B, H, W]`.
    pub fn supervision(&self) -> &[bool] {
        &self.supervision
    }

    /// The building masks `V_B`, row-major `[B, H, W]`.
    pub fn building(&self) -> &[bool] {
        &self.building
    }

    /// The target disparity `[B, 1, H, W]` (0 where unknown).
    pub fn target(&self) -> Tensor<4> {
        self.target.clone()
    }
}

fn check_image(
    i: usize,
    name: &str,
    image: &Image,
    size: (usize, usize),
    channels: usize,
) -> Result<(), LossError> {
    if image.size() != size || image.channels() != channels {
        return Err(LossError::Input(format!(
            "LossBatch::new: sample {i}: {name} is {:?}×{}, expected {}×{}×{channels}",
            image.size(),
            image.channels(),
            size.0,
            size.1
        )));
    }
    match image.finite_range() {
        None if !image.data().is_empty() => Err(LossError::Input(format!(
            "LossBatch::new: sample {i}: {name} has no finite value"
        ))),
        Some((lo, hi)) if lo < -1e-3 || hi > MAX_UNIT_VALUE => Err(LossError::Input(format!(
            "LossBatch::new: sample {i}: {name} spans [{lo}, {hi}]; the loss expects images in [0, 1] \
             (normalise as the release does: dataset::augment::normalize_unit_range)"
        ))),
        _ if image.data().iter().any(|v| !v.is_finite()) => Err(LossError::Input(format!(
            "LossBatch::new: sample {i}: {name} contains NaN or infinite values"
        ))),
        _ => Ok(()),
    }
}

/// HWC → CHW.
fn to_chw(image: &Image) -> Vec<f32> {
    let (w, h) = image.size();
    let c = image.channels();
    let data = image.data();
    let mut out = vec![0.0; data.len()];
    for (p, px) in data.chunks_exact(c).enumerate() {
        for (ch, &v) in px.iter().enumerate() {
            out[ch * w * h + p] = v;
        }
    }
    out
}

/// A boolean tensor from a row-major slice.
pub(crate) fn bool_tensor(data: &[bool], shape: [usize; 4], device: &Device) -> Tensor<4, Bool> {
    Tensor::<4, Bool>::from_data(TensorData::new(data.to_vec(), shape), device)
}
