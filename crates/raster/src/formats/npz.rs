//! Rectifying homography archives, as numpy writes them with
//! `np.savez(path, Hleft=..., Hright=...)` (or `np.savez_compressed`).

use std::fs::File;
use std::io::{BufReader, Read, Write};
use std::path::Path;

use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, ZipArchive, ZipWriter};

use super::npy;
use super::support::{no_panic, write_atomically};
use crate::{Homography, RasterError, Result};

/// Largest member we are willing to read: a 3×3 array is about 200 bytes.
const MAX_MEMBER_BYTES: u64 = 1 << 20;

/// Reads the `Hleft` and `Hright` 3×3 homographies (float64 or float32) of an NPZ archive.
pub fn read_homographies(path: impl AsRef<Path>) -> Result<(Homography, Homography)> {
    let path = path.as_ref();
    let file = File::open(path).map_err(|e| RasterError::io(path, e))?;
    no_panic(path, "NPZ", || {
        let mut zip = ZipArchive::new(BufReader::new(file))
            .map_err(|e| RasterError::format(path, format!("not a readable NPZ archive: {e}")))?;
        let left = read_matrix(path, &mut zip, "Hleft")?;
        let right = read_matrix(path, &mut zip, "Hright")?;
        Ok((left, right))
    })
}

fn read_matrix(
    path: &Path,
    zip: &mut ZipArchive<BufReader<File>>,
    key: &str,
) -> Result<Homography> {
    let member = format!("{key}.npy");
    if zip.index_for_name(&member).is_none() {
        let keys: Vec<&str> = zip
            .file_names()
            .filter_map(|n| n.strip_suffix(".npy"))
            .collect();
        return Err(RasterError::format(
            path,
            format!("no array '{key}' in the archive (arrays present: {keys:?})"),
        ));
    }
    let mut entry = zip
        .by_name(&member)
        .map_err(|e| RasterError::format(path, format!("cannot open '{member}': {e}")))?;
    if entry.size() > MAX_MEMBER_BYTES {
        return Err(RasterError::format(
            path,
            format!(
                "'{member}' is {} bytes, too large for a 3x3 matrix",
                entry.size()
            ),
        ));
    }
    let mut bytes = Vec::new();
    entry
        .by_ref()
        .take(MAX_MEMBER_BYTES)
        .read_to_end(&mut bytes)
        .map_err(|e| RasterError::format(path, format!("cannot read '{member}': {e}")))?;
    let (shape, v) = npy::decode::<f64>(path, &bytes)
        .map_err(|e| RasterError::format(path, format!("'{member}': {}", strip_path(&e))))?;
    if shape != [3, 3] {
        return Err(RasterError::format(
            path,
            format!("'{key}' has shape {shape:?}, expected (3, 3)"),
        ));
    }
    let h = Homography([[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]]);
    if !h.is_finite() {
        return Err(RasterError::format(
            path,
            format!("'{key}' has non-finite entries: {:?}", h.0),
        ));
    }
    Ok(h)
}

/// The message of an error without its leading path (it is added again by the caller).
fn strip_path(e: &RasterError) -> String {
    match e {
        RasterError::Format { message, .. } => message.clone(),
        other => other.to_string(),
    }
}

/// Writes `Hleft`/`Hright` as float64 arrays in an uncompressed archive, as `np.savez` does.
pub fn write_homographies(
    path: impl AsRef<Path>,
    left: &Homography,
    right: &Homography,
) -> Result<()> {
    write_atomically(path, |w| {
        let mut zip = ZipWriter::new(w);
        let options = SimpleFileOptions::default().compression_method(CompressionMethod::Stored);
        for (key, h) in [("Hleft", left), ("Hright", right)] {
            zip.start_file(format!("{key}.npy"), options)?;
            zip.write_all(&npy::header_bytes("<f8", &[3, 3]))?;
            for v in h.0.iter().flatten() {
                zip.write_all(&v.to_le_bytes())?;
            }
        }
        zip.finish()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("H.npz");
        let l = Homography([[1.0, 0.5, -3.25], [0.0, 2.0, 7.0], [1e-5, -2e-6, 1.0]]);
        let r = Homography::translation(-12.5, 4.0);
        write_homographies(&p, &l, &r).unwrap();
        assert_eq!(read_homographies(&p).unwrap(), (l, r));
    }
}
