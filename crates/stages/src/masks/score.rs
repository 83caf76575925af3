//! Masks scored against real labels: the DFC2019 classes (`<AOI>_CLS.tif`: 2 ground, 5 high
//! vegetation, 6 building, 65 unlabeled) live on the truth DSM's grid, so they are projected into
//! each image through the truth DSM and the image's RPC ([`super::project`], the highest LiDAR
//! cell per pixel) and compared with the masks pixel by pixel where the truth is 2, 5 or 6.
//! Tree = class 5, building = class 6, ground = class 2 against "neither mask".
//!
//! Registration: the cameras' frame and the truth grid may be offset by a few cells (the
//! benchmark registers every DSM to the truth by an integer shift before scoring it). Given DSMs
//! triangulated through the same cameras on the truth grid (`reconstruct --like <truth>`),
//! [`registration`] finds the benchmark's shift of each ([`eval::align`], the released
//! evaluator's multiscale NCC, ±5 cells) and the truth is moved by the median shift into the
//! cameras' frame before it is projected ([`Shift`]).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use camera::{read_dsm, UtmZone};
use dataset::masks::{from_segmentation, MaskFile};
use dataset::segmentation::MaskKind;
use raster::{Image, Mask};

use super::mask_path;
use super::project::render_into_image;
use eval::{align, AlignParams, Alignment};
use reconstruct::dsm::read_camera;

/// The benchmark's registration of the cameras' frame to the truth grid, cells: a DSM `pred`
/// triangulated through the cameras matches the truth as `pred(x − dx, y − dy) ≈ truth(x, y)`
/// ([`eval::align`]'s convention), so truth cell `(c, r)` is seen where the cameras put
/// cell `(c − dx, r − dy)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Shift {
    pub dx: i32,
    pub dy: i32,
}

/// One registration DSM's shift.
#[derive(Clone, Debug)]
pub struct Registered {
    pub dsm: PathBuf,
    pub alignment: Alignment,
}

/// LAS codes of the DFC2019 classes scored.
pub const GROUND: u8 = 2;
pub const HIGH_VEGETATION: u8 = 5;
pub const BUILDING: u8 = 6;

/// Pixel counts of one class.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Confusion {
    pub tp: u64,
    pub fp: u64,
    pub fn_: u64,
}

impl Confusion {
    pub fn iou(&self) -> f64 {
        self.tp as f64 / (self.tp + self.fp + self.fn_).max(1) as f64
    }
    pub fn precision(&self) -> f64 {
        self.tp as f64 / (self.tp + self.fp).max(1) as f64
    }
    pub fn recall(&self) -> f64 {
        self.tp as f64 / (self.tp + self.fn_).max(1) as f64
    }
    fn add(&mut self, truth: bool, pred: bool) {
        match (truth, pred) {
            (true, true) => self.tp += 1,
            (false, true) => self.fp += 1,
            (true, false) => self.fn_ += 1,
            _ => {}
        }
    }
}

/// Scores of one image: tree, building, ground; share of the image the water mask covers.
#[derive(Clone, Debug)]
pub struct ImageScore {
    pub stem: String,
    pub tree: Confusion,
    pub building: Confusion,
    pub ground: Confusion,
    pub water_share: f64,
    /// Pixels with a scored truth class.
    pub labelled: u64,
}

/// The truth: DSM and classes on one grid.
pub struct ClassTruth {
    pub dsm: Image,
    pub classes: Image,
    pub grid: camera::DsmGrid,
}

impl ClassTruth {
    /// Reads `<AOI>_DSM.tif` and its classes (`classes`, else `<AOI>_CLS.tif` beside it); a DFC2019
    /// plain TIFF takes its grid from the `.txt` beside it in `zone`.
    pub fn read(dsm: &Path, classes: Option<&Path>, zone: UtmZone) -> Result<Self> {
        let cls_path = match classes {
            Some(p) => p.to_path_buf(),
            None => {
                let name = dsm.file_name().and_then(|n| n.to_str()).unwrap_or("");
                let Some(aoi) = name.strip_suffix("_DSM.tif") else {
                    bail!("{}: name the classes file with --classes (or call the DSM <AOI>_DSM.tif, its <AOI>_CLS.tif beside it)", dsm.display());
                };
                dsm.with_file_name(format!("{aoi}_CLS.tif"))
            }
        };
        let raster = read_dsm(dsm, Some(zone))
            .with_context(|| format!("reading the truth DSM {}", dsm.display()))?;
        let classes = raster::read_image(&cls_path)
            .with_context(|| format!("reading the truth classes {}", cls_path.display()))?;
        if classes.size() != raster.image.size() {
            bail!(
                "{} is {:?} but the DSM {} is {:?}: the classes must be on the DSM's grid",
                cls_path.display(),
                classes.size(),
                dsm.display(),
                raster.image.size()
            );
        }
        Ok(ClassTruth {
            dsm: raster.image,
            classes: classes.channel(0),
            grid: raster.grid,
        })
    }

    /// The truth class seen at every pixel of a `size` image of camera `rpc` (NaN: none), the
    /// truth moved by `shift` into the cameras' frame.
    pub fn classes_in_image(
        &self,
        rpc: &camera::RpcModel,
        size: (usize, usize),
        shift: Shift,
    ) -> Image {
        let mut grid = self.grid.clone();
        grid.x0 -= shift.dx as f64 * grid.resolution;
        grid.y0 += shift.dy as f64 * grid.resolution;
        render_into_image(&self.dsm, &[&self.classes], &grid, rpc, size)
    }

    /// The benchmark's shift of a DSM on the truth grid (the released evaluator's NCC search).
    pub fn register(&self, dsm: &Path) -> Result<Alignment> {
        let pred = read_dsm(dsm, self.grid.zone())
            .with_context(|| format!("reading the registration DSM {}", dsm.display()))?;
        if pred.grid != self.grid {
            bail!(
                "{}: not on the truth grid; build it with `reconstruct --like <truth DSM>`",
                dsm.display()
            );
        }
        align(&self.dsm, &pred.image, &AlignParams::default())
            .with_context(|| format!("{}: no cell shared with the truth", dsm.display()))
    }
}

/// The shifts of `dsms` and their median (per axis; `(0, 0)` without DSMs).
pub fn registration(truth: &ClassTruth, dsms: &[PathBuf]) -> Result<(Shift, Vec<Registered>)> {
    let mut found = Vec::new();
    for dsm in dsms {
        found.push(Registered {
            dsm: dsm.clone(),
            alignment: truth.register(dsm)?,
        });
    }
    let median = |f: fn(&Alignment) -> i32| -> i32 {
        let mut v: Vec<i32> = found.iter().map(|r| f(&r.alignment)).collect();
        v.sort_unstable();
        v.get(v.len() / 2).copied().unwrap_or(0)
    };
    Ok((
        Shift {
            dx: median(|a| a.dx),
            dy: median(|a| a.dy),
        },
        found,
    ))
}

/// Scores a tree mask and a building mask (true = the class) against projected truth classes.
pub fn score_masks(
    stem: &str,
    truth: &Image,
    tree: &Mask,
    building: &Mask,
    water: &Mask,
) -> ImageScore {
    let mut s = ImageScore {
        stem: stem.to_string(),
        tree: Confusion::default(),
        building: Confusion::default(),
        ground: Confusion::default(),
        water_share: water.count() as f64 / water.data().len().max(1) as f64,
        labelled: 0,
    };
    for (i, &t) in truth.data().iter().enumerate() {
        if !t.is_finite() {
            continue;
        }
        let t = t as u8;
        if ![GROUND, HIGH_VEGETATION, BUILDING].contains(&t) {
            continue;
        }
        s.labelled += 1;
        let (pt, pb) = (tree.data()[i], building.data()[i]);
        s.tree.add(t == HIGH_VEGETATION, pt);
        s.building.add(t == BUILDING, pb);
        s.ground.add(t == GROUND, !pt && !pb);
    }
    s
}

/// Reads the masks of `stem` from a `masks` output folder: (tree, building, water), true = the
/// class.
pub fn read_masks(masks_dir: &Path, stem: &str) -> Result<[Mask; 3]> {
    let read = |kind: MaskKind| -> Result<Mask> {
        let p = mask_path(masks_dir, kind, stem);
        let im = raster::read_image(&p)
            .with_context(|| format!("reading {} (run `seasonstereo masks` first)", p.display()))?;
        let polarity = if kind == MaskKind::Building {
            MaskFile::Building
        } else {
            MaskFile::Keep
        };
        let m = from_segmentation(&im, polarity);
        // Keep masks are true off the class.
        Ok(if kind == MaskKind::Building {
            m
        } else {
            Mask::new(m.width(), m.height(), m.data().iter().map(|v| !v).collect())?
        })
    };
    Ok([
        read(MaskKind::Tree)?,
        read(MaskKind::Building)?,
        read(MaskKind::Water)?,
    ])
}

/// The stems of a `masks` folder (its tree masks), sorted.
pub fn mask_stems(masks_dir: &Path) -> Result<Vec<String>> {
    let dir = super::class_dir(masks_dir, MaskKind::Tree).join("masks");
    let mut stems: Vec<String> = std::fs::read_dir(&dir)
        .with_context(|| {
            format!(
                "{}: no tree masks (is this a `seasonstereo masks` folder?)",
                dir.display()
            )
        })?
        .filter_map(|e| {
            e.ok()?
                .file_name()
                .to_str()?
                .strip_suffix("_mask.png")
                .map(str::to_string)
        })
        .collect();
    stems.sort();
    Ok(stems)
}

/// The scores of a folder and the registration they used.
#[derive(Clone, Debug)]
pub struct FolderScore {
    pub scores: Vec<ImageScore>,
    pub shift: Shift,
    pub registered: Vec<Registered>,
}

/// Scores every image of a `masks` folder whose camera `<rpc_dir>/<stem>.json` exists, the truth
/// registered by `register` (DSMs through the same cameras on the truth grid; none: no shift).
pub fn score_folder(
    masks_dir: &Path,
    rpc_dir: &Path,
    truth_dsm: &Path,
    classes: Option<&Path>,
    register: &[PathBuf],
) -> Result<FolderScore> {
    let stems = mask_stems(masks_dir)?;
    let camera = |stem: &str| -> PathBuf { rpc_dir.join(format!("{stem}.json")) };
    let with_camera: Vec<&String> = stems.iter().filter(|s| camera(s).is_file()).collect();
    let Some(first) = with_camera.first() else {
        bail!(
            "none of the {} images of {} has a camera <stem>.json in {}",
            stems.len(),
            masks_dir.display(),
            rpc_dir.display()
        );
    };
    let rpc0 = read_camera(&camera(first))?;
    let truth = ClassTruth::read(
        truth_dsm,
        classes,
        UtmZone::from_lonlat(rpc0.lon_offset, rpc0.lat_offset),
    )?;
    let (shift, registered) = registration(&truth, register)?;
    let mut scores = Vec::new();
    for stem in with_camera {
        let rpc = read_camera(&camera(stem))?;
        let [tree, building, water] = read_masks(masks_dir, stem)?;
        let projected = truth.classes_in_image(&rpc, tree.size(), shift);
        scores.push(score_masks(stem, &projected, &tree, &building, &water));
    }
    Ok(FolderScore {
        scores,
        shift,
        registered,
    })
}

/// The table of [`score_folder`]: one row per image, then the mean over images and the pooled
/// pixels, IoU / precision / recall per class.
pub fn table(scores: &[ImageScore]) -> String {
    let cells =
        |c: &Confusion| format!("{:.3} | {:.3} | {:.3}", c.iou(), c.precision(), c.recall());
    let mut t = String::from("| image | tree IoU | tree P | tree R | building IoU | building P | building R | ground IoU | ground P | ground R | water % |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    for s in scores {
        t += &format!(
            "| {} | {} | {} | {} | {:.2} |\n",
            s.stem,
            cells(&s.tree),
            cells(&s.building),
            cells(&s.ground),
            100.0 * s.water_share
        );
    }
    let n = scores.len().max(1) as f64;
    let mean = |f: &dyn Fn(&ImageScore) -> f64| scores.iter().map(f).sum::<f64>() / n;
    let m = |g: fn(&ImageScore) -> &Confusion| {
        format!(
            "{:.3} | {:.3} | {:.3}",
            mean(&|s| g(s).iou()),
            mean(&|s| g(s).precision()),
            mean(&|s| g(s).recall())
        )
    };
    t += &format!(
        "| **mean of {} images** | {} | {} | {} | {:.2} |\n",
        scores.len(),
        m(|s| &s.tree),
        m(|s| &s.building),
        m(|s| &s.ground),
        100.0 * mean(&|s| s.water_share)
    );
    let pool = |g: fn(&ImageScore) -> &Confusion| {
        scores.iter().fold(Confusion::default(), |a, s| {
            let c = g(s);
            Confusion {
                tp: a.tp + c.tp,
                fp: a.fp + c.fp,
                fn_: a.fn_ + c.fn_,
            }
        })
    };
    t += &format!(
        "| pooled pixels | {} | {} | {} | |\n",
        cells(&pool(|s| &s.tree)),
        cells(&pool(|s| &s.building)),
        cells(&pool(|s| &s.ground))
    );
    t
}
