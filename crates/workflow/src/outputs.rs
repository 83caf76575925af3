//! The one place that decides whether a run may write an output, and how a run that did not
//! produce everything it was asked for ends.
//!
//! Outputs: a path is resolved (symlinks, `..`, relative to the current folder) before it is
//! compared with the run's inputs; an output that is one of the inputs, or a folder holding one
//! of them that the command would clear, is refused naming both paths. An existing final
//! product (a DSM, a disparity, a report) is only replaced when the caller says so
//! (`--overwrite`), and always atomically (the writers of `raster::formats` write beside and
//! rename). Work folders keep their own resume rules and are only checked against the inputs.
//!
//! Outcomes: [`Incomplete`] is the error of a run that did some work but not all of it
//! ([`Incomplete::Partial`], exit code 2) or produced nothing ([`Incomplete::Nothing`], exit
//! code 3); any other error is exit code 1.

use std::fmt;
use std::path::{Component, Path, PathBuf};

use anyhow::{bail, Result};

/// `path` made absolute and normal: the longest existing ancestor is canonicalized (symlinks
/// resolved), the rest appended with `.` and `..` folded.
pub fn resolve(path: &Path) -> PathBuf {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .unwrap_or_else(|_| PathBuf::from("/"))
            .join(path)
    };
    let mut normal = PathBuf::new();
    for c in absolute.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                normal.pop();
            }
            c => normal.push(c),
        }
    }
    // Canonicalize the longest existing prefix, keep the remainder as written.
    let mut existing = normal.clone();
    let mut rest = Vec::new();
    loop {
        if let Ok(c) = existing.canonicalize() {
            let mut out = c;
            for part in rest.iter().rev() {
                out.push(part);
            }
            return out;
        }
        match (
            existing.file_name().map(|n| n.to_os_string()),
            existing.parent(),
        ) {
            (Some(name), Some(parent)) => {
                rest.push(name);
                existing = parent.to_path_buf();
            }
            _ => return normal,
        }
    }
}

/// Whether two paths name the same file (after [`resolve`], or the same inode).
pub fn same_file(a: &Path, b: &Path) -> bool {
    if resolve(a) == resolve(b) {
        return true;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    false
}

/// Refuses an output file that is one of the run's `inputs` (`flag` names the option, e.g.
/// `-o`), a folder, or an existing file when `overwrite` is false.
pub fn check_output_file(
    flag: &str,
    output: &Path,
    inputs: &[&Path],
    overwrite: bool,
) -> Result<()> {
    refuse_inputs(flag, output, inputs)?;
    check_writable(flag, output)?;
    if output.is_dir() {
        bail!(
            "{flag} {} is a folder: give the path of a file",
            output.display()
        );
    }
    if output.exists() && !output.is_file() {
        bail!(
            "{flag} {} exists and is not a regular file (a device, a socket): outputs are \
             written beside and renamed over, which would replace it; choose a file path",
            output.display()
        );
    }
    if !overwrite && output.exists() {
        // An io::Error of its kind, so that callers can tell it from a bad value (the Python
        // package raises `FileExistsError`); its text is the message.
        return Err(std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            format!(
                "{flag} {} already exists: pass --overwrite to replace it (atomically), or \
                 choose another path",
                output.display()
            ),
        )
        .into());
    }
    Ok(())
}

/// The extensions a DSM is written under (any case): the writers make GeoTIFFs only, and a
/// GeoTIFF named `.las` or `.png` misleads every tool that trusts the name.
pub const DSM_EXTENSIONS: [&str; 2] = ["tif", "tiff"];

/// Refuses a DSM path whose extension is not one of [`DSM_EXTENSIONS`].
pub fn check_dsm_extension(flag: &str, output: &Path) -> Result<()> {
    if DSM_EXTENSIONS.contains(&raster::formats::extension_of(output).as_str()) {
        return Ok(());
    }
    bail!(
        "{flag} {}: a DSM is written as a GeoTIFF only; give a path ending in .{} (any case)",
        output.display(),
        DSM_EXTENSIONS.join(" or .")
    )
}

/// Refuses an output (file or folder) that is one of the run's `inputs`, or a folder that holds
/// one of them when `clears` (the command empties or rewrites the folder).
pub fn check_output_folder(
    flag: &str,
    folder: &Path,
    inputs: &[&Path],
    clears: bool,
) -> Result<()> {
    refuse_inputs(flag, folder, inputs)?;
    check_writable(flag, &folder.join("probe"))?;
    if clears {
        let dir = resolve(folder);
        for input in inputs {
            if resolve(input).starts_with(&dir) {
                bail!(
                    "{flag} {} holds the input {}, and this command clears it: choose another \
                     folder",
                    folder.display(),
                    input.display()
                );
            }
        }
    }
    Ok(())
}

/// Refuses, before any work, an output whose folder (or the nearest existing folder above it,
/// where the run would create the rest) cannot be written: hours of matching are not spent on
/// a result that cannot be saved.
fn check_writable(flag: &str, output: &Path) -> Result<()> {
    let resolved = resolve(output);
    let mut dir = resolved.parent().unwrap_or(Path::new("/"));
    while !dir.exists() {
        dir = dir.parent().unwrap_or(Path::new("/"));
    }
    if !dir.is_dir() {
        bail!(
            "{flag} {}: {} is a file, not a folder: choose another output path",
            output.display(),
            dir.display()
        );
    }
    let probe = dir.join(format!(".seasonstereo-write-probe-{}", std::process::id()));
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => bail!(
            "{flag} {}: the folder {} cannot be written ({e}): choose a writable folder",
            output.display(),
            dir.display()
        ),
    }
}

/// The refusal of an output that is one of the inputs.
fn refuse_inputs(flag: &str, output: &Path, inputs: &[&Path]) -> Result<()> {
    for input in inputs {
        if same_file(output, input) {
            bail!(
                "{flag} {} is the input {}: the run would overwrite it; choose another output path",
                output.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// An error chain as one line: causes joined by `: `, a context already contained in its cause
/// left out, a cause repeated after its own context said once.
pub fn one_line(e: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in e.chain() {
        let mut text = cause.to_string();
        if let Some(last) = parts.last() {
            if last.ends_with(&text) {
                continue;
            }
            // "reading P" then "P: not found": the path once.
            let said = text
                .match_indices(": ")
                .map(|(i, _)| i)
                .filter(|&i| last.ends_with(&text[..i]))
                .last();
            if let Some(i) = said {
                text = text[i + 2..].to_string();
            }
        }
        parts.push(text);
    }
    let mut out = parts.join(": ");
    for p in &parts {
        let twice = format!("{p}: {p}");
        while out.contains(&twice) {
            out = out.replace(&twice, p);
        }
    }
    out
}

/// The first few of `names`, then how many more: `a, b, c and 12 more`.
pub fn first_names(names: &[String]) -> String {
    const SHOWN: usize = 8;
    let shown = names[..names.len().min(SHOWN)].join(", ");
    match names.len().saturating_sub(SHOWN) {
        0 => shown,
        more => format!("{shown} and {more} more"),
    }
}

/// A run that did not produce all it was asked for: the error a command returns so that its
/// exit code tells scripts what happened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Incomplete {
    /// Some items (tiles, pairs) failed; the output was written from the others. Exit code 2.
    Partial {
        /// What was written and what failed, one line.
        message: String,
        /// The names of the failed items.
        failed: Vec<String>,
    },
    /// Nothing was produced. Exit code 3.
    Nothing {
        /// Why, one line, with the fix.
        message: String,
    },
}

impl Incomplete {
    /// The process exit code: 2 partial, 3 nothing.
    pub fn exit_code(&self) -> u8 {
        match self {
            Incomplete::Partial { .. } => 2,
            Incomplete::Nothing { .. } => 3,
        }
    }
}

impl fmt::Display for Incomplete {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Incomplete::Partial { message, .. } | Incomplete::Nothing { message } => {
                f.write_str(message)
            }
        }
    }
}

impl std::error::Error for Incomplete {}

/// Refuses products (`--ortho`, `--points`, `--preview`) of the wrong format, that are inputs,
/// that are the DSM itself, or that exist and are not this run's; adds them to `outputs` (what
/// the run's provenance checks).
pub fn check_products(
    products: &products::Products,
    dsm_path: &Path,
    inputs: &[&Path],
    outputs: &mut Vec<PathBuf>,
) -> Result<()> {
    products.check()?;
    for path in products.paths() {
        if resolve(path) == resolve(dsm_path) {
            bail!(
                "{}: a product cannot be written over the DSM (-o): give another file name",
                path.display()
            );
        }
        check_output_file("a product", path, inputs, true)?;
        outputs.push(path.to_path_buf());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_that_are_inputs_are_refused_through_dots_and_links() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("a.tif");
        std::fs::write(&input, b"x").unwrap();
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        let dotted = sub.join("../a.tif");
        let e = check_output_file("-o", &dotted, &[&input], true).unwrap_err();
        assert!(e.to_string().contains("is the input"), "{e}");
        #[cfg(unix)]
        {
            let link = dir.path().join("link.tif");
            std::os::unix::fs::symlink(&input, &link).unwrap();
            assert!(check_output_file("-o", &link, &[&input], true).is_err());
        }
        let out = dir.path().join("b.tif");
        check_output_file("-o", &out, &[&input], false).unwrap();
        std::fs::write(&out, b"y").unwrap();
        let e = check_output_file("-o", &out, &[&input], false).unwrap_err();
        assert!(e.to_string().contains("--overwrite"), "{e}");
        check_output_file("-o", &out, &[&input], true).unwrap();
        assert!(check_output_folder("--work", dir.path(), &[&input], true).is_err());
        check_output_folder("--work", dir.path(), &[&input], false).unwrap();
    }
}
