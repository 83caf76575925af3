//! Weight import: PyTorch `.pth` state dicts and safetensors, with a key report.
//!
//! Entry points (all take any burn `Module`; keys use the **PyTorch** names of the upstream
//! `Monster.state_dict()`, e.g. `mono_encoder.blocks.0.norm1.weight`):
//!
//! ```text
//! pub fn load_weights<M: Module>(module: &mut M, path: impl AsRef<Path>) -> Result<LoadReport, WeightsError>
//! pub fn load_submodule<M: Module>(module: &mut M, path: impl AsRef<Path>, prefix: &str) -> Result<LoadReport, WeightsError>
//! pub fn load_submodule_with<M: Module>(module: &mut M, path: impl AsRef<Path>, prefix: &str,
//!                                       remap: &[(&str, &str)]) -> Result<LoadReport, WeightsError>
//! pub fn load_weights_mapped<M: Module>(module: &mut M, path: impl AsRef<Path>,
//!                                       map_keys: impl FnOnce(&[String]) -> Vec<Option<String>>) -> Result<LoadReport, WeightsError>
//! pub fn save_checkpoint<M: Module>(module: &M, path: impl AsRef<Path>) -> Result<(), WeightsError>
//! pub fn module_keys<M: Module>(module: &M) -> Vec<(String, Vec<usize>)>   // PyTorch names, lazy shapes
//! pub fn file_keys(path: impl AsRef<Path>) -> Result<Vec<(String, Vec<usize>)>, WeightsError>
//! ```
//!
//! For a sub-module test: `load_submodule(&mut feat_transfer, fixture.join("weights.safetensors"),
//! "feat_transfer.")` loads every key under the prefix (prefix stripped) into the module; an error
//! lists the module parameters that are missing in the file and the shape mismatches; keys under
//! the prefix that the module does not have are reported in `LoadReport::unexpected` (not an
//! error). Keys outside the prefix are ignored.
//!
//! Conventions the modules must follow so that keys match by path:
//! - field names equal the PyTorch attribute names (`patch_embed`, `ls1`, `resConfUnit1` needs
//!   `#[allow(non_snake_case)]`);
//! - `nn.ModuleList` / `nn.Sequential` → `Vec<T>` with **exactly** the PyTorch indices: use
//!   `Vec<Option<T>>` with `None` for parameter-free entries (ReLU, Identity), e.g. DPT
//!   `output_conv2` = `[Some(conv), None, Some(conv), None, None]` (no index compaction is done);
//! - burn `Linear` (weight stored `[in, out]`) is transposed from PyTorch `[out, in]`, and the norms'
//!   `gamma`/`beta` are matched to `weight`/`bias` automatically (burn-store's
//!   `PyTorchToBurnAdapter`); BatchNorm `running_mean`/`running_var` match by name;
//!   `num_batches_tracked` is ignored;
//! - heterogeneous Sequentials (different types at different indices) cannot be a `Vec`: give the
//!   fields names and pass regex `remap` pairs to [`load_submodule_with`], applied to the keys after
//!   the prefix is stripped, e.g. `&[(r"^0\.", "conv0."), (r"^1\.", "bn1.")]`.
//!
//! Float tensors (F16/BF16/F32/F64) are converted to f32. A `.pth` file may be a bare state dict
//! or wrapped in `model` / `state_dict` (other top-level entries such as `optimizer` are dropped),
//! with or without a `module.` prefix (DataParallel). The format is detected from the file's
//! first bytes (zip/pickle → PyTorch, otherwise safetensors).
//!
//! Our own checkpoints ([`save_checkpoint`]) are safetensors in PyTorch naming (so upstream
//! PyTorch can read them too); they load back with [`load_weights`].

use std::collections::BTreeSet;
use std::io::Read;
use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleVisitor, Param};
use burn::store::burn_pack::Tensor as PackTensor;
use burn::store::{
    ApplyError, BurnToPyTorchAdapter, FloatCastAdapter, KeyRemapper, ModuleAdapter, ModuleSnapshot,
    ModuleStore, PyTorchToBurnAdapter, PytorchStore, SafetensorsStore,
};
use burn::tensor::{Bool, DType, Int, Tensor};

/// Marker prepended to keys outside the requested prefix (they are never applied or reported).
const OUTSIDE: &str = "\u{1}outside\u{1}.";

/// Errors of weight import/export. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum WeightsError {
    /// The file could not be opened or read.
    #[error("{file}: cannot read: {source}")]
    Io {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a valid safetensors / PyTorch file (truncated, corrupt, unsupported).
    #[error("{file}: {message}")]
    Format {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Required parameters are missing or have the wrong shape/dtype.
    #[error("{}: weights do not fit the model:\n{}", report.file.display(), report.describe())]
    Mismatch {
        /// The full report (missing, mismatched, unexpected keys).
        report: Box<LoadReport>,
    },
    /// Writing a checkpoint failed.
    #[error("{file}: cannot save checkpoint: {message}")]
    Save {
        /// The file.
        file: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// What a load did, in PyTorch key names (with the prefix that was requested).
#[derive(Debug, Clone, Default)]
pub struct LoadReport {
    /// The file that was read.
    pub file: PathBuf,
    /// The key prefix that was loaded ("" for a whole model).
    pub prefix: String,
    /// Number of tensors applied.
    pub applied: usize,
    /// Module parameters with no tensor in the file (an error unless empty).
    pub missing: Vec<String>,
    /// Tensors whose shape or dtype kind does not fit (an error unless empty): one message each.
    pub mismatched: Vec<String>,
    /// Keys in the file (under the prefix) that the module does not have (reported, not an error).
    pub unexpected: Vec<String>,
    /// Keys deliberately ignored (`num_batches_tracked`).
    pub ignored: Vec<String>,
}

impl LoadReport {
    /// True when every module parameter was loaded with the right shape.
    pub fn is_complete(&self) -> bool {
        self.missing.is_empty() && self.mismatched.is_empty()
    }

    /// Human-readable listing of missing / mismatched / unexpected keys.
    pub fn describe(&self) -> String {
        let mut s = format!(
            "  prefix {:?}: {} tensors applied, {} missing, {} mismatched, {} unexpected, {} ignored\n",
            self.prefix,
            self.applied,
            self.missing.len(),
            self.mismatched.len(),
            self.unexpected.len(),
            self.ignored.len()
        );
        let mut list = |title: &str, items: &[String]| {
            if !items.is_empty() {
                s.push_str(&format!("  {title}:\n"));
                for k in items {
                    s.push_str(&format!("    {k}\n"));
                }
            }
        };
        list("missing in the file", &self.missing);
        list("wrong shape/dtype", &self.mismatched);
        list("unexpected (not in the model)", &self.unexpected);
        s
    }
}

impl std::fmt::Display for LoadReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.file.display(), self.describe())
    }
}

/// Loads a whole model (keys without prefix; a `module.` prefix and a `model`/`state_dict`
/// wrapper are removed). Errors when a parameter is missing or mis-shaped.
pub fn load_weights<M: Module>(
    module: &mut M,
    path: impl AsRef<Path>,
) -> Result<LoadReport, WeightsError> {
    load_submodule_with(module, path, "", &[])
}

/// Loads the keys under `prefix` (e.g. `"feat_transfer."`, prefix stripped) into `module`.
pub fn load_submodule<M: Module>(
    module: &mut M,
    path: impl AsRef<Path>,
    prefix: &str,
) -> Result<LoadReport, WeightsError> {
    load_submodule_with(module, path, prefix, &[])
}

/// [`load_submodule`] with extra regex key renames `(pattern, replacement)`, applied in order to
/// the keys after the prefix was stripped (regex crate syntax, `${1}` for groups).
pub fn load_submodule_with<M: Module>(
    module: &mut M,
    path: impl AsRef<Path>,
    prefix: &str,
    remap: &[(&str, &str)],
) -> Result<LoadReport, WeightsError> {
    let file = path.as_ref().to_path_buf();
    let mut tensors = read_tensors(&file)?;

    let remapper =
        KeyRemapper::from_patterns(remap.to_vec()).map_err(|e| WeightsError::Format {
            file: file.clone(),
            message: format!("bad remap pattern: {e}"),
        })?;

    let mut ignored = Vec::new();
    let mut inside = Vec::with_capacity(tensors.len());
    let mut outside = Vec::new();
    for mut t in tensors.drain(..) {
        let original = t.name.clone();
        match original.strip_prefix(prefix) {
            Some(rest) => {
                if rest.ends_with("num_batches_tracked") {
                    ignored.push(original);
                    continue;
                }
                t.name = rest.to_string();
                inside.push(t);
            }
            None => {
                t.name = format!("{OUTSIDE}{original}");
                outside.push(t);
            }
        }
    }
    let (mut kept, _) = remapper.remap(inside);
    kept.extend(outside);
    apply_with_report(module, file, prefix, kept, ignored)
}

/// Loads a whole model after renaming the file's keys with `map_keys`, which receives every key
/// of the file (after the `model`/`state_dict` unwrapping and `module.` stripping of [`load_weights`])
/// and returns the model key for each, or `None` for a tensor that does not belong to the model
/// (dropped silently, e.g. optimizer state beside a wrapped state dict). For checkpoints whose
/// naming needs more than regex renames (the SegFormer `.pt` of the release: `model_state_dict`
/// wrapper, `module.`/`model.` substrings deleted). `num_batches_tracked` keys are ignored.
pub fn load_weights_mapped<M: Module>(
    module: &mut M,
    path: impl AsRef<Path>,
    map_keys: impl FnOnce(&[String]) -> Vec<Option<String>>,
) -> Result<LoadReport, WeightsError> {
    let file = path.as_ref().to_path_buf();
    let tensors = read_tensors(&file)?;
    let names: Vec<String> = tensors.iter().map(|t| t.name.clone()).collect();
    let mapped = map_keys(&names);
    if mapped.len() != names.len() {
        return Err(WeightsError::Format {
            file,
            message: format!(
                "key mapping returned {} names for {} tensors",
                mapped.len(),
                names.len()
            ),
        });
    }
    let mut ignored = Vec::new();
    let mut kept = Vec::with_capacity(tensors.len());
    for (mut t, name) in tensors.into_iter().zip(mapped) {
        let Some(name) = name else { continue };
        if name.ends_with("num_batches_tracked") {
            ignored.push(name);
            continue;
        }
        t.name = name;
        kept.push(t);
    }
    apply_with_report(module, file, "", kept, ignored)
}

/// Applies the tensors (PyTorch naming, `OUTSIDE`-marked ones never reported) and builds the
/// report; an error unless every module parameter was loaded with the right shape.
fn apply_with_report<M: Module>(
    module: &mut M,
    file: PathBuf,
    prefix: &str,
    kept: Vec<PackTensor>,
    ignored: Vec<String>,
) -> Result<LoadReport, WeightsError> {
    let adapter: Box<dyn ModuleAdapter> =
        Box::new(PyTorchToBurnAdapter.chain(FloatCastAdapter::to(DType::F32)));
    let result = module.apply(kept, None, Some(adapter), true);

    let missing = result
        .missing
        .iter()
        .map(|(p, containers)| {
            format!(
                "{prefix}{}",
                torch_name(p, containers.rsplit('.').next().unwrap_or(""))
            )
        })
        .collect();
    let mismatched = result
        .errors
        .iter()
        .map(|e| match e {
            ApplyError::ShapeMismatch {
                path,
                expected,
                found,
            } => {
                format!(
                    "{prefix}{path}: model expects shape {:?}, file has {:?} (burn layout)",
                    expected.as_slice(),
                    found.as_slice()
                )
            }
            other => format!("{prefix}{other}"),
        })
        .collect();
    let mut unexpected: Vec<String> = result
        .unused
        .iter()
        .filter(|k| !k.starts_with(OUTSIDE))
        .map(|k| format!("{prefix}{k}"))
        .collect();
    unexpected.sort();

    let report = LoadReport {
        file,
        prefix: prefix.to_string(),
        applied: result.applied.len(),
        missing,
        mismatched,
        unexpected,
        ignored,
    };
    if report.is_complete() {
        Ok(report)
    } else {
        Err(WeightsError::Mismatch {
            report: Box::new(report),
        })
    }
}

/// Saves the module's parameters as safetensors in PyTorch naming (overwrites `path`).
pub fn save_checkpoint<M: Module>(module: &M, path: impl AsRef<Path>) -> Result<(), WeightsError> {
    let file = path.as_ref().to_path_buf();
    let mut store = SafetensorsStore::from_file(file.clone())
        .with_to_adapter(BurnToPyTorchAdapter)
        .overwrite(true);
    module
        .save_into(&mut store)
        .map_err(|e| WeightsError::Save {
            file,
            message: e.to_string(),
        })
}

/// The (key, shape) list of a weights file (safetensors or `.pth`), after unwrapping
/// `model`/`state_dict` and stripping `module.`; `num_batches_tracked` included.
pub fn file_keys(path: impl AsRef<Path>) -> Result<Vec<(String, Vec<usize>)>, WeightsError> {
    let file = path.as_ref().to_path_buf();
    let mut out: Vec<_> = read_tensors(&file)?
        .into_iter()
        .map(|t| (t.name.clone(), t.shape.as_slice().to_vec()))
        .collect();
    out.sort();
    Ok(out)
}

/// The module's parameters as (PyTorch key, PyTorch shape), sorted, without initialising lazy
/// parameters (cheap even for ViT-L).
pub fn module_keys<M: Module>(module: &M) -> Vec<(String, Vec<usize>)> {
    let mut v = KeyLister::default();
    module.visit(&mut v);
    v.out.sort();
    v.out
}

#[derive(Default)]
struct KeyLister {
    path: Vec<String>,
    containers: Vec<String>,
    out: Vec<(String, Vec<usize>)>,
}

impl KeyLister {
    fn push(&mut self, mut shape: Vec<usize>) {
        let container = self.containers.last().map(String::as_str).unwrap_or("");
        let name = self.path.last().map(String::as_str).unwrap_or("");
        if container == "Struct:Linear" && name == "weight" && shape.len() == 2 {
            shape.reverse();
        }
        let full = self.path.join(".");
        self.out.push((torch_name(&full, container), shape));
    }
}

impl ModuleVisitor for KeyLister {
    fn enter_module(&mut self, name: &str, container_type: &str) {
        self.path.push(name.to_string());
        self.containers.push(container_type.to_string());
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
        self.containers.pop();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.push(param.lazy_shape().as_slice().to_vec());
    }
    fn visit_int<const D: usize>(&mut self, param: &Param<Tensor<D, Int>>) {
        self.push(param.lazy_shape().as_slice().to_vec());
    }
    fn visit_bool<const D: usize>(&mut self, param: &Param<Tensor<D, Bool>>) {
        self.push(param.lazy_shape().as_slice().to_vec());
    }
}

/// burn path → PyTorch key (norm `gamma`/`beta` → `weight`/`bias`).
fn torch_name(path: &str, container: &str) -> String {
    if container.contains("Norm") {
        if let Some(stem) = path.strip_suffix("gamma") {
            if stem.is_empty() || stem.ends_with('.') {
                return format!("{stem}weight");
            }
        }
        if let Some(stem) = path.strip_suffix("beta") {
            if stem.is_empty() || stem.ends_with('.') {
                return format!("{stem}bias");
            }
        }
    }
    path.to_string()
}

/// Reads all tensors of a file as burn-store tensors (lazy data), keys normalised.
fn read_tensors(file: &Path) -> Result<Vec<PackTensor>, WeightsError> {
    let io = |source| WeightsError::Io {
        file: file.to_path_buf(),
        source,
    };
    let fmt = |message: String| WeightsError::Format {
        file: file.to_path_buf(),
        message,
    };
    let mut f = std::fs::File::open(file).map_err(io)?;
    let len = f.metadata().map_err(io)?.len();
    let mut magic = [0u8; 8];
    let got = read_up_to(&mut f, &mut magic).map_err(io)?;
    let mut first = [0u8; 1];
    let plausible_safetensors = got == 8 && {
        // u64 LE header length, then the JSON header. Its low byte may well be 0x80, so a
        // leading 0x80 alone does not mean pickle.
        let n = u64::from_le_bytes(magic);
        n <= 100_000_000
            && 8 + n <= len
            && read_up_to(&mut f, &mut first).map_err(io)? == 1
            && first[0] == b'{'
    };
    drop(f);
    if got < 8 {
        return Err(fmt(format!(
            "file is truncated or empty ({len} bytes): not a safetensors or PyTorch file"
        )));
    }
    let is_zip = &magic[..2] == b"PK";
    // torch.save(_use_new_zipfile_serialization=False) starts with a pickle (0x80, protocol).
    let is_legacy_pickle = magic[0] == 0x80 && !plausible_safetensors;
    let tensors: Vec<PackTensor> = if is_zip || is_legacy_pickle {
        let mut store = PytorchStore::from_file(file).map_indices_contiguous(false);
        store
            .get_all_tensors()
            .map_err(|e| {
                fmt(format!(
                    "cannot read PyTorch checkpoint (truncated or corrupt?): {e}"
                ))
            })?
            .values()
            .cloned()
            .collect()
    } else {
        check_safetensors_header(file, magic, len).map_err(fmt)?;
        let mut store = SafetensorsStore::from_file(file);
        store
            .get_all_tensors()
            .map_err(|e| {
                fmt(format!(
                    "cannot read safetensors file (truncated or corrupt?): {e}"
                ))
            })?
            .values()
            .cloned()
            .collect()
    };
    Ok(normalise_keys(tensors))
}

fn read_up_to(f: &mut std::fs::File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        let k = f.read(&mut buf[n..])?;
        if k == 0 {
            break;
        }
        n += k;
    }
    Ok(n)
}

/// Checks that the header fits and that the data section is as long as the header says.
fn check_safetensors_header(file: &Path, magic: [u8; 8], len: u64) -> Result<(), String> {
    let n = u64::from_le_bytes(magic);
    if n > 100_000_000 || 8 + n > len {
        return Err(format!(
            "not a safetensors file or truncated: header length {n} does not fit in the file ({len} bytes)"
        ));
    }
    let mut f = std::fs::File::open(file).map_err(|e| e.to_string())?;
    let mut buf = vec![0u8; 8 + n as usize];
    f.read_exact(&mut buf).map_err(|e| e.to_string())?;
    let header: serde_json::Value =
        serde_json::from_slice(&buf[8..]).map_err(|e| format!("bad safetensors header: {e}"))?;
    let end = header
        .as_object()
        .map(|o| {
            o.iter()
                .filter(|(k, _)| k.as_str() != "__metadata__")
                .filter_map(|(_, v)| v.get("data_offsets")?.as_array()?.get(1)?.as_u64())
                .max()
                .unwrap_or(0)
        })
        .unwrap_or(0);
    let have = len - 8 - n;
    if have < end {
        return Err(format!(
            "safetensors file is truncated: the header needs {end} data bytes, the file has {have}"
        ));
    }
    Ok(())
}

/// Unwraps `model.` / `state_dict.` (dropping other top-level entries) and strips `module.`.
fn normalise_keys(tensors: Vec<PackTensor>) -> Vec<PackTensor> {
    let names: BTreeSet<&str> = tensors.iter().map(|t| t.name.as_str()).collect();
    // MonSter has no top-level child called `model`/`state_dict`, so such keys mean a wrapper
    // (`{'model': state_dict, 'optimizer': ...}` flattens to `model.*`, `optimizer.*`).
    let wrapper = ["state_dict.", "model."]
        .into_iter()
        .find(|w| names.iter().any(|n| n.starts_with(w)));
    tensors
        .into_iter()
        .filter_map(|mut t| {
            if let Some(w) = wrapper {
                let rest = t.name.strip_prefix(w)?.to_string();
                t.name = rest;
            }
            if let Some(rest) = t.name.strip_prefix("module.") {
                t.name = rest.to_string();
            }
            Some(t)
        })
        .collect()
}
