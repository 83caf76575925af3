//! Batches for training and validation, deterministic from `(seed, step)`.
//!
//! Why deterministic by step: a resumed run must see exactly the batches the uninterrupted run
//! would have seen. The data order of epoch `e` is a shuffle seeded by `(seed, "order/e")`; an
//! epoch has `⌊n / batch⌋` batches (the release's `drop_last=True`); the augmentation of slot `j`
//! of step `s` draws from `(seed, "augment/s/j")`. So the "RNG state and data-order position" of
//! a checkpoint are the seed and the step, nothing else.
//!
//! Images are normalised as the release does ([`dataset::augment::normalize_unit_range`]:
//! `/255` for 0–255 data, min–max otherwise) to `[0, 1]` for the loss, and fed to the network
//! ×255.

use burn::tensor::{Device, Tensor, TensorData};
use dataset::augment::{augment_sample, normalize_sample, normalize_unit_range, AugmentConfig};
use dataset::rng::SplitMix64;
use dataset::sample::centre_crop_or_pad;
use dataset::{DatasetDir, Sample, SampleIndex, TrainLayout};
use raster::{Image, Mask};

use crate::config::TrainConfig;
use crate::loss::{BatchItem, SupervisionTarget};
use crate::TrainError;

/// One sample ready for the network and the loss: every raster cropped to the same size,
/// images in `[0, 1]`.
#[derive(Clone, Debug)]
pub struct PreparedSample {
    pub input_left: Image,
    pub input_right: Image,
    pub real_left: Image,
    pub real_right: Image,
    /// The supervising disparity (teacher, or LiDAR for configuration (a)); NaN = unknown.
    pub target: Image,
    pub valid_left: Mask,
    pub building_left: Mask,
    /// The pair's stem (for messages).
    pub stem: String,
    pub diachronic: bool,
}

impl PreparedSample {
    /// The loss's view of this sample.
    pub fn loss_item(&self) -> BatchItem<'_> {
        BatchItem {
            input_left: &self.input_left,
            real_left: &self.real_left,
            real_right: &self.real_right,
            target: &self.target,
            valid_left: &self.valid_left,
            building_left: &self.building_left,
        }
    }
}

/// The network's inputs for a batch: `B×3×H×W`, RGB 0–255 (grey images repeated on 3 channels).
pub fn network_inputs(batch: &[PreparedSample], device: &Device) -> (Tensor<4>, Tensor<4>) {
    let stack = |pick: fn(&PreparedSample) -> &Image| {
        let (w, h) = pick(&batch[0]).size();
        let mut data = Vec::with_capacity(batch.len() * 3 * w * h);
        for s in batch {
            data.extend(rgb_chw_255(pick(s)));
        }
        Tensor::<4>::from_data(TensorData::new(data, [batch.len(), 3, h, w]), device)
    };
    (stack(|s| &s.input_left), stack(|s| &s.input_right))
}

/// HWC `[0, 1]` → CHW 0–255 with 3 channels (grey repeated; extra channels dropped). NaN → 0.
fn rgb_chw_255(image: &Image) -> Vec<f32> {
    let (w, h) = image.size();
    let c = image.channels();
    let mut out = vec![0.0; 3 * w * h];
    for (p, px) in image.data().chunks_exact(c).enumerate() {
        for ch in 0..3 {
            let v = px[if c >= 3 { ch } else { 0 }];
            out[ch * w * h + p] = if v.is_finite() { v * 255.0 } else { 0.0 };
        }
    }
    out
}

/// The training samples and the deterministic batch schedule.
pub struct TrainData {
    index: SampleIndex,
    batch_size: usize,
    augment: AugmentConfig,
    seed: u64,
    lidar: bool,
}

impl TrainData {
    /// Opens the training split of `config.data` (experiment list, AOI filter) and checks that
    /// every file exists.
    pub fn open(config: &TrainConfig) -> Result<Self, TrainError> {
        let dir = DatasetDir::new(&config.data.root);
        let lidar = config.loss.target == SupervisionTarget::Lidar;
        let layout = dir.train(&config.data.teacher);
        if lidar && layout.lidar_dir.is_none() {
            return Err(TrainError::Data(format!(
                "{}: configuration (a) supervises with LiDAR disparities, but there is no disparity_maps/GT folder",
                dir.root.display()
            )));
        }
        let mut index = match &config.data.experiment {
            Some(name) if !name.is_empty() => {
                SampleIndex::from_experiment(layout, &dir.experiment_csv(name))?
            }
            _ => SampleIndex::from_folder(layout)?,
        };
        let aois = dir.aois_csv("train");
        if config.data.use_aoi_lists && aois.exists() {
            index.retain_aois(&aois)?;
        }
        index.check_files()?;
        if index.len() < config.run.batch_size {
            return Err(TrainError::Data(format!(
                "{}: {} training samples, fewer than run.batch_size ({}); lower the batch size",
                dir.root.display(),
                index.len(),
                config.run.batch_size
            )));
        }
        Ok(Self {
            index,
            batch_size: config.run.batch_size,
            augment: config.augment.clone(),
            seed: config.run.seed,
            lidar,
        })
    }

    /// Number of training samples.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// Always false (opening fails on an empty list).
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Full batches per epoch (the last partial batch is dropped, as the release does).
    pub fn batches_per_epoch(&self) -> usize {
        self.index.len() / self.batch_size
    }

    /// Sample indices of 0-based step `step`.
    pub fn batch_indices(&self, step: usize) -> Vec<usize> {
        let per_epoch = self.batches_per_epoch();
        let epoch = step / per_epoch;
        let k = step % per_epoch;
        let mut order: Vec<usize> = (0..self.index.len()).collect();
        SplitMix64::for_key(self.seed, &format!("order/{epoch}")).shuffle(&mut order);
        order[k * self.batch_size..(k + 1) * self.batch_size].to_vec()
    }

    /// Loads, normalises and randomly crops the samples of step `step`.
    pub fn batch(&self, step: usize) -> Result<Vec<PreparedSample>, TrainError> {
        self.batch_indices(step)
            .into_iter()
            .enumerate()
            .map(|(slot, i)| {
                let sample = self.index.load(i)?;
                let mut rng = SplitMix64::for_key(self.seed, &format!("augment/{step}/{slot}"));
                prepare_train(sample, &self.augment, self.lidar, &mut rng)
            })
            .collect()
    }
}

fn target_of(sample: &Sample, lidar: bool) -> Result<Image, TrainError> {
    match (lidar, &sample.lidar) {
        (true, Some(l)) => Ok(l.clone()),
        (true, None) => Err(TrainError::Data(format!(
            "{}: no LiDAR disparity for this pair (configuration (a) needs one per pair)",
            sample.stem
        ))),
        (false, _) => Ok(sample.teacher.clone()),
    }
}

/// The release's preparation: normalisation to `[0, 1]`, then the augmentation (scale/stretch,
/// random crop, overlap shift, colour jitter and eraser of the input pair).
fn prepare_train(
    mut sample: Sample,
    augment: &AugmentConfig,
    lidar: bool,
    rng: &mut SplitMix64,
) -> Result<PreparedSample, TrainError> {
    normalize_sample(&mut sample);
    let s = augment_sample(&sample, augment, rng)
        .map_err(|e| TrainError::Data(format!("{}: augmentation: {e}", sample.stem)))?;
    let target = target_of(&s, lidar)?;
    Ok(PreparedSample {
        target,
        stem: s.stem.to_string(),
        diachronic: s.diachronic,
        input_left: s.input_left,
        input_right: s.input_right,
        real_left: s.real_left,
        real_right: s.real_right,
        valid_left: s.valid_left,
        building_left: s.building_left,
    })
}

/// One validation pair: centre-cropped network inputs, the scoring disparity and its mask.
#[derive(Clone, Debug)]
pub struct ValidSample {
    pub left: Image,
    pub right: Image,
    /// Ground truth (LiDAR / exact) when the split has it, else the teacher.
    pub truth: Image,
    pub valid: Mask,
    pub stem: String,
    pub diachronic: bool,
}

/// The validation split (`val/` of the dataset), read lazily pair by pair.
pub struct ValidData {
    index: SampleIndex,
    limit: usize,
    crop: usize,
}

impl ValidData {
    /// The validation split, or `None` when the dataset has no `val/L` folder.
    pub fn open(config: &TrainConfig) -> Result<Option<Self>, TrainError> {
        let dir = DatasetDir::new(&config.data.root);
        let layout: TrainLayout = dir.val();
        if !layout.root.join("L").is_dir() {
            return Ok(None);
        }
        let csv = dir.experiment_csv(&config.data.valid_experiment);
        let mut index = if csv.exists() {
            SampleIndex::from_experiment(layout, &csv)?
        } else {
            SampleIndex::from_folder(layout)?
        };
        let aois = dir.aois_csv("val");
        if config.data.use_aoi_lists && aois.exists() {
            index.retain_aois(&aois)?;
        }
        Ok(Some(Self {
            index,
            limit: config.data.valid_limit,
            crop: config.run.valid_crop,
        }))
    }

    /// Number of pairs scored.
    pub fn len(&self) -> usize {
        match self.limit {
            0 => self.index.len(),
            n => n.min(self.index.len()),
        }
    }

    /// True when there is nothing to score.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Pair `i`, centre-cropped (or edge-padded) to `run.valid_crop` as the release does.
    pub fn get(&self, i: usize) -> Result<ValidSample, TrainError> {
        let s = self.index.load(i)?;
        let truth_is_lidar = s.lidar.is_some();
        let valid = s.supervision_mask(truth_is_lidar);
        let truth = s.lidar.clone().unwrap_or_else(|| s.teacher.clone());
        let c = |im: &Image| centre_crop_or_pad(im, self.crop);
        Ok(ValidSample {
            left: c(&normalize_unit_range(&s.input_left)),
            right: c(&normalize_unit_range(&s.input_right)),
            truth: c(&truth),
            valid: Mask::from_image(&c(&valid.to_image())),
            stem: s.stem.to_string(),
            diachronic: s.diachronic,
        })
    }
}
