//! What a work folder belongs to: `<work>/run.json`, written when a run starts using the folder,
//! names the command, its inputs (resolved path, size and a hash of the file's head) and every
//! option that changes the result. A rerun that matches resumes and may rewrite its own DSM;
//! anything else (another command, other inputs, other settings, a folder of an earlier version
//! without the record) is refused before any work unless `--overwrite`, which clears the run's
//! entries from the folder (never the user's other files, never an input).
//! The options split in two: those the folder's content (tiles, pairs' DSMs) depends on, and the
//! finishing of the DSM (hole filling, median, fusion rules): a rerun with other finishing reuses
//! the folder but replaces the DSM only with `--overwrite`.

use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::dsm::GridChoice;
use workflow::outputs::resolve;
use workflow::stage::{read_json, write_text};

/// The record's name in the work folder.
pub const RECORD: &str = "run.json";

/// The entries a run writes in its work folder (`reconstruct`'s scene, tiles and kept
/// intermediates, `reconstruct-many`'s pairs): its content, what clearing removes. Anything else
/// is left alone: the job files a cluster submission writes before its first task (`jobs/`), a
/// user's own files in a folder given to `--work`.
const RUN_ENTRIES: [&str; 9] = [
    "scene.json",
    "cameras",
    "tiles",
    "pairs",
    "L",
    "R",
    "homography",
    "rectify",
    "disparity",
];

/// An input of at most this many bytes (a camera JSON) is identified by its whole content.
const WHOLE_BYTES: u64 = 64 << 10;

/// A larger input (an image) by its size and its first bytes (the TIFF header and the start of
/// the first strips): another acquisition differs there, while a damaged tile rewritten after a
/// failed run (a repaired download) or a touched file resumes, as `jobs resubmit` expects.
const HEAD_BYTES: u64 = 4 << 10;

/// One run of a command into a work folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// `reconstruct` or `reconstruct-many`.
    pub command: String,
    /// Every file the result depends on, in the command's order.
    pub inputs: Vec<InputFile>,
    /// The options the folder's content depends on.
    pub work: Value,
    /// The DSM made from the folder, and the options that finish it.
    pub product: Product,
}

/// One input file, as identified when the run started.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InputFile {
    /// What it is to the command (`left`, `camera`, `like`…).
    pub role: String,
    /// Resolved (absolute, links followed).
    pub path: PathBuf,
    /// `None` when it could not be read (the command's own checks name the problem).
    pub size: Option<u64>,
    /// FNV-1a of its content ([`WHOLE_BYTES`]) or first [`HEAD_BYTES`], hexadecimal.
    pub head: Option<String>,
}

/// The DSM of a run and how it is finished.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Product {
    /// Resolved path of the DSM.
    pub output: PathBuf,
    pub finishing: Value,
}

impl InputFile {
    /// The file at `path` as it is now, in the role `role`.
    pub fn of(role: &str, path: &Path) -> InputFile {
        let read = || -> std::io::Result<(u64, String)> {
            let mut f = std::fs::File::open(path)?;
            let size = f.metadata()?.len();
            let read = if size <= WHOLE_BYTES {
                size
            } else {
                HEAD_BYTES
            };
            let mut head = Vec::with_capacity(read as usize);
            f.by_ref().take(read).read_to_end(&mut head)?;
            Ok((size, format!("{:016x}", fnv1a(&head))))
        };
        let (size, head) = read().ok().unzip();
        InputFile {
            role: role.into(),
            path: resolve(path),
            size,
            head,
        }
    }
}

/// FNV-1a, 64 bits: stable across builds and platforms, as a record read back later must be.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h: u64, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The grid as the record keeps it (a `--like` file is an input instead).
pub fn grid_json(grid: &GridChoice) -> Value {
    match grid {
        // The file itself is an input.
        GridChoice::Like(_) => json!("like"),
        GridChoice::Resolution {
            resolution,
            bounds,
            epsg,
        } => json!({ "resolution": resolution, "bounds": bounds, "epsg": epsg }),
        GridChoice::Exact(grid) => json!(grid),
    }
}

/// The file a grid is taken from, an input of the run.
pub fn grid_input(grid: &GridChoice) -> Option<&Path> {
    match grid {
        GridChoice::Like(p) => Some(p.as_path()),
        GridChoice::Resolution { .. } | GridChoice::Exact(_) => None,
    }
}

/// The vendor files found beside an image (its camera, its metadata): inputs too.
pub fn delivery_files(image: &Path) -> impl Iterator<Item = InputFile> {
    let camera = camera::find_camera_file(image).map(|p| InputFile::of("camera_sidecar", &p));
    let metadata = camera::find_metadata_file(image).map(|p| InputFile::of("metadata", &p));
    camera.into_iter().chain(metadata)
}

impl RunRecord {
    /// The record as it reads back from its file (numbers and paths normalized by JSON).
    fn normalized(&self) -> Result<RunRecord> {
        Ok(serde_json::from_value(serde_json::to_value(self)?)?)
    }
}

/// How a work folder relates to this run.
#[derive(Debug, PartialEq)]
enum Relation {
    /// Absent, or without a run's content.
    Fresh,
    /// The same run: resume.
    Same,
    /// The same content, another DSM or its finishing (why).
    Refinish(String),
    /// Another run's content (why).
    Other(String),
}

/// The entries of `work` that are a run's content ([`RUN_ENTRIES`]).
fn content(work: &Path) -> Vec<PathBuf> {
    RUN_ENTRIES
        .iter()
        .map(|name| work.join(name))
        .filter(|p| p.exists() || p.is_symlink())
        .collect()
}

fn relation(work: &Path, run: &RunRecord) -> Result<Relation> {
    let theirs: Option<RunRecord> = match read_json(&work.join(RECORD)) {
        Ok(r) => r,
        Err(_) => {
            return Ok(Relation::Other(format!(
                "its {RECORD} cannot be read as a run record"
            )))
        }
    };
    let Some(theirs) = theirs else {
        return Ok(if content(work).is_empty() {
            Relation::Fresh
        } else {
            Relation::Other(format!(
                "made by an earlier version of seasonstereo, which did not record its run in \
                 {RECORD}: whether it is this run's cannot be told"
            ))
        });
    };
    let ours = run.normalized()?;
    if theirs.command != ours.command {
        return Ok(Relation::Other(format!(
            "made by `{}`, not `{}`",
            theirs.command, ours.command
        )));
    }
    if theirs.inputs != ours.inputs {
        let differing = ours
            .inputs
            .iter()
            .zip(&theirs.inputs)
            .find(|(a, b)| a != b)
            .map_or("another number of inputs".to_string(), |(a, b)| {
                if a.path == b.path {
                    format!("{} changed since", a.path.display())
                } else {
                    format!("{} instead of {}", b.path.display(), a.path.display())
                }
            });
        return Ok(Relation::Other(format!(
            "made from other inputs: {differing}"
        )));
    }
    if theirs.work != ours.work {
        return Ok(Relation::Other(format!(
            "made with other settings: {}",
            differing_keys(&theirs.work, &ours.work)
        )));
    }
    if theirs.product.output != ours.product.output {
        return Ok(Relation::Refinish(format!(
            "the folder's DSM is {}",
            theirs.product.output.display()
        )));
    }
    if theirs.product.finishing != ours.product.finishing {
        return Ok(Relation::Refinish(format!(
            "made with other finishing options: {}",
            differing_keys(&theirs.product.finishing, &ours.product.finishing)
        )));
    }
    Ok(Relation::Same)
}

/// The keys whose values differ, with both values: `median_filter 15, now 5`.
fn differing_keys(theirs: &Value, ours: &Value) -> String {
    let (Some(a), Some(b)) = (theirs.as_object(), ours.as_object()) else {
        return "other options".into();
    };
    let keys: Vec<String> = b
        .iter()
        .filter(|(k, v)| a.get(*k) != Some(*v))
        .map(|(k, v)| {
            let was = a.get(k).map_or("unset".into(), Value::to_string);
            format!("{k} {was}, now {v}")
        })
        .collect();
    if keys.is_empty() {
        "other options".into()
    } else {
        keys.join("; ")
    }
}

/// Before any work: may the run `run` use `work` and write `outputs` (the DSM and its
/// sidecars)? The same run resumes; a new one needs `overwrite` to replace existing outputs;
/// another run's folder is refused, or cleared with `overwrite` (never when it holds one of
/// `inputs`).
pub fn check(
    work: &Path,
    run: &RunRecord,
    outputs: &[PathBuf],
    inputs: &[&Path],
    overwrite: bool,
) -> Result<()> {
    let existing: Vec<&PathBuf> = outputs.iter().filter(|p| p.exists()).collect();
    let why = match relation(work, run)? {
        Relation::Same => return Ok(()),
        Relation::Fresh => None,
        Relation::Refinish(why) => Some(why),
        Relation::Other(why) => {
            if !overwrite {
                return Err(refusal(&existing, Some(work), &why));
            }
            return clear(work, inputs);
        }
    };
    if existing.is_empty() || overwrite {
        return Ok(());
    }
    Err(refusal(&existing, None, why.as_deref().unwrap_or("")))
}

/// The existing-output message: the files, why they are not this run's, the choices. An
/// `AlreadyExists` error (the Python package raises `FileExistsError`).
fn refusal(existing: &[&PathBuf], work: Option<&Path>, why: &str) -> anyhow::Error {
    let names: Vec<String> = existing.iter().map(|p| p.display().to_string()).collect();
    let message = match (names.split_first(), work) {
        (Some((dsm, others)), Some(work)) => format!(
            "-o {dsm} already exists{}, and its work folder {} holds another run ({why}): pass \
             --overwrite to replace them (the work folder is cleared), choose another -o, or \
             delete the work folder",
            also(others),
            work.display()
        ),
        (None, Some(work)) => format!(
            "the work folder {} holds another run ({why}): pass --overwrite to clear it, choose \
             another -o (or --work), or delete the folder",
            work.display()
        ),
        (Some((dsm, others)), None) => {
            let why = if why.is_empty() {
                String::new()
            } else {
                format!(" ({why})")
            };
            format!(
                "-o {dsm} already exists{}{why}: pass --overwrite to replace it (atomically), or \
                 choose another path",
                also(others)
            )
        }
        (None, None) => why.to_string(),
    };
    std::io::Error::new(std::io::ErrorKind::AlreadyExists, message).into()
}

fn also(others: &[String]) -> String {
    if others.is_empty() {
        String::new()
    } else {
        format!(" (with {})", others.join(", "))
    }
}

/// Removes another run's content from `work` ([`RUN_ENTRIES`] and the record; other files
/// stay), refusing when the folder holds one of `inputs`.
fn clear(work: &Path, inputs: &[&Path]) -> Result<()> {
    workflow::outputs::check_output_folder("--work", work, inputs, true)?;
    let record = work.join(RECORD);
    for path in content(work).into_iter().chain([record]) {
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else if path.exists() || path.is_symlink() {
            std::fs::remove_file(&path)
        } else {
            Ok(())
        };
        removed
            .with_context(|| format!("clearing the work folder: removing {}", path.display()))?;
    }
    Ok(())
}

/// When the run starts using `work`: refuses another run's content (a caller that skipped
/// [`check`]), then records this run.
pub fn claim(work: &Path, run: &RunRecord) -> Result<()> {
    if let Relation::Other(why) = relation(work, run)? {
        bail!(
            "the work folder {} holds another run ({why}): pass --overwrite to clear it, or give \
             another --work folder",
            work.display()
        );
    }
    std::fs::create_dir_all(work).with_context(|| format!("creating {}", work.display()))?;
    // One line: the record stays small beside the tiles.
    write_text(&work.join(RECORD), &serde_json::to_string(run)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run on two images of `dir` (written), its DSM `dsm.tif` finished with a median of
    /// `median` cells, its work folder `dsm_work`.
    struct Run {
        right: PathBuf,
        output: PathBuf,
        work: PathBuf,
        camera: Option<PathBuf>,
        median: usize,
    }

    impl Run {
        fn new(dir: &Path) -> Run {
            let (l, r) = (dir.join("l.tif"), dir.join("r.tif"));
            std::fs::write(&l, b"left").unwrap();
            std::fs::write(&r, b"right").unwrap();
            Run {
                right: r,
                output: dir.join("dsm.tif"),
                work: dir.join("dsm_work"),
                camera: None,
                median: 15,
            }
        }

        fn record(&self) -> RunRecord {
            let left = self.right.with_file_name("l.tif");
            let mut inputs = vec![
                InputFile::of("left", &left),
                InputFile::of("right", &self.right),
            ];
            inputs.extend(self.camera.as_ref().map(|c| InputFile::of("rpc_left", c)));
            RunRecord {
                command: "reconstruct".into(),
                inputs,
                work: json!({ "tile": 1024 }),
                product: Product {
                    output: resolve(&self.output),
                    finishing: json!({ "median_filter": self.median }),
                },
            }
        }
    }

    #[test]
    fn the_same_run_resumes_and_any_other_is_refused_or_cleared() {
        let dir = tempfile::tempdir().unwrap();
        let o = Run::new(dir.path());
        let work = o.work.clone();
        let outputs = vec![o.output.clone()];
        let run = o.record();
        check(&work, &run, &outputs, &[], false).unwrap();
        claim(&work, &run).unwrap();
        std::fs::write(work.join("tile"), b"t").unwrap();
        std::fs::write(&o.output, b"dsm").unwrap();
        check(&work, &run, &outputs, &[], false).unwrap();

        // Other finishing: the DSM is replaced only with --overwrite, the content kept.
        let refinished = Run {
            median: 5,
            ..Run::new(dir.path())
        };
        let run2 = refinished.record();
        let e = check(&work, &run2, &outputs, &[], false).unwrap_err();
        assert!(e.to_string().contains("median_filter"), "{e}");
        check(&work, &run2, &outputs, &[], true).unwrap();
        assert!(work.join("tile").is_file());

        // Another input: refused naming the DSM, cleared with --overwrite.
        std::fs::write(&o.right, b"other right").unwrap();
        let run3 = o.record();
        let e = check(&work, &run3, &outputs, &[], false).unwrap_err();
        assert!(
            e.to_string().contains("dsm.tif already exists") && e.to_string().contains("r.tif"),
            "{e}"
        );
        assert!(claim(&work, &run3).is_err());
        check(&work, &run3, &outputs, &[], true).unwrap();
        assert!(content(&work).is_empty() && !work.join(RECORD).exists());
    }

    #[test]
    fn a_folder_without_a_record_is_an_earlier_version_and_inputs_are_never_cleared() {
        let dir = tempfile::tempdir().unwrap();
        let mut o = Run::new(dir.path());
        let work = o.work.clone();
        std::fs::create_dir_all(work.join("jobs")).unwrap();
        std::fs::write(work.join("notes.txt"), b"mine").unwrap();
        let run = o.record();
        check(&work, &run, &[], &[], false).unwrap();
        std::fs::write(work.join("scene.json"), b"{}").unwrap();
        let e = check(&work, &run, &[], &[], false).unwrap_err();
        assert!(e.to_string().contains("earlier version"), "{e}");
        let camera = work.join("camera.json");
        std::fs::write(&camera, b"{}").unwrap();
        o.camera = Some(camera.clone());
        let run = o.record();
        assert!(check(&work, &run, &[], &[&camera], true).is_err());
        assert!(camera.is_file());
        std::fs::remove_file(&camera).unwrap();
        check(&work, &run, &[], &[], true).unwrap();
        assert!(work.join("jobs").is_dir() && !work.join("scene.json").exists());
        assert!(
            work.join("notes.txt").is_file(),
            "a user's file is not a run's"
        );
    }
}
