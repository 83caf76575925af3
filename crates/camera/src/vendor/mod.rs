//! Cameras and acquisition metadata as vendors deliver them beside an image: Maxar/DigitalGlobe
//! `.RPB` and `.IMD`, GDAL/GeoEye `_RPC.TXT`, Pléiades/SPOT DIMAP `RPC_*.XML` and `DIM_*.XML`,
//! and the NITF acquisition date GDAL keeps in a TIFF's metadata tag.
//!
//! Users get their images this way, not as the benchmark's JSONs, so the product finds these
//! files as GDAL does (same names beside the image, same readings of their keys) and turns them
//! into an [`RpcModel`] and an [`Acquisition`]. A file that is there but cannot be read is an
//! error naming the file and the key; metadata without a date is not (its `datetime` is `None`).

mod digitalglobe;
mod dimap;
mod fields;
mod gdal_metadata;
mod rpc_txt;
mod xml;

use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};

use raster::formats::TiffReader;

use crate::{CameraError, Result, RpcModel};

pub use digitalglobe::{read_imd, read_rpb};
pub use fields::Acquisition;

use self::fields::{metadata_error, rpc_error};
pub use dimap::{read_dimap_metadata, read_dimap_rpc};
pub use gdal_metadata::acquisition_from_gdal_metadata;
pub use rpc_txt::read_rpc_txt;

/// The vendor camera file beside `image`, looked for as GDAL does: `<stem>.RPB`/`.rpb`,
/// `<stem>_RPC.TXT`/`_rpc.txt`, then for a DIMAP tile `IMG_<X>_R<i>C<j>.<ext>` the file
/// `RPC_<X>_R<i>C<j>.XML` or `RPC_<X>.XML`.
pub fn find_camera_file(image: &Path) -> Option<PathBuf> {
    let (dir, stem) = split(image)?;
    let mut names = vec![
        format!("{stem}.RPB"),
        format!("{stem}.rpb"),
        format!("{stem}_RPC.TXT"),
        format!("{stem}_rpc.txt"),
    ];
    names.extend(dimap_names(&stem, "RPC_"));
    first_file(&dir, &names)
}

/// The vendor metadata file beside `image`: `<stem>.IMD`/`.imd`, or for a DIMAP tile
/// `IMG_<X>_R<i>C<j>.<ext>` the file `DIM_<X>_R<i>C<j>.XML` or `DIM_<X>.XML` (GDAL's rule).
pub fn find_metadata_file(image: &Path) -> Option<PathBuf> {
    let (dir, stem) = split(image)?;
    let mut names = vec![format!("{stem}.IMD"), format!("{stem}.imd")];
    names.extend(dimap_names(&stem, "DIM_"));
    first_file(&dir, &names)
}

/// Reads a camera file of any supported kind, recognised by its content: rpcm/SatNeRF JSON
/// (with its `min_alt`/`max_alt`), `.RPB`, `_RPC.TXT`, DIMAP `RPC_*.XML` or a TIFF's tag 50844.
pub fn read_camera_file(path: &Path) -> Result<RpcModel> {
    match sniff(path)? {
        Kind::Tiff => {
            let origin = path.display().to_string();
            let tag = TiffReader::open(path)?
                .rpc
                .ok_or_else(|| rpc_error(&origin, "50844", "the TIFF has no RPC tag"))?;
            RpcModel::from_tiff_tag(&tag).map_err(|e| match e {
                CameraError::Rpc { key, message, .. } => rpc_error(&origin, &key, message),
                e => e,
            })
        }
        Kind::Json => RpcModel::read_rpcm_json(path),
        Kind::Xml => read_dimap_rpc(path),
        Kind::Text(text) => {
            // By content, else by extension (so that a damaged file reports its missing keys).
            let origin = path.display().to_string();
            let ext = Some(raster::formats::extension_of(path));
            if text.contains("lineNumCoef") || text.contains("BEGIN_GROUP") {
                digitalglobe::rpb_from_text(&text, &origin)
            } else if text.to_ascii_uppercase().contains("LINE_NUM_COEFF") {
                rpc_txt::rpc_txt_from_text(&text, &origin)
            } else if ext.as_deref() == Some("rpb") {
                digitalglobe::rpb_from_text(&text, &origin)
            } else if ext.as_deref() == Some("txt") {
                rpc_txt::rpc_txt_from_text(&text, &origin)
            } else {
                Err(rpc_error(
                    &path.display().to_string(),
                    "",
                    "not a camera file this reader knows (JSON, RPB, _RPC.TXT, DIMAP XML, TIFF)",
                ))
            }
        }
    }
}

/// The camera of `image`: its vendor sidecar ([`find_camera_file`]) when there is one, else the
/// RPC tag of the image itself when it is a TIFF that has one. Returns the model and the file it
/// came from; `None` when neither exists. A sidecar that does not parse is an error.
pub fn camera_beside(image: &Path) -> Result<Option<(RpcModel, PathBuf)>> {
    if let Some(file) = find_camera_file(image) {
        return Ok(Some((read_camera_file(&file)?, file)));
    }
    if is_tiff(image) {
        let origin = image.display().to_string();
        if let Some(tag) = TiffReader::open(image)?.rpc {
            let model = RpcModel::from_tiff_tag(&tag).map_err(|e| match e {
                CameraError::Rpc { key, message, .. } => rpc_error(&origin, &key, message),
                e => e,
            })?;
            return Ok(Some((model, image.to_path_buf())));
        }
    }
    Ok(None)
}

/// The acquisition of `image`: its metadata sidecar ([`find_metadata_file`]) when there is one,
/// else the NITF date in the GDAL metadata of the image when it is a TIFF; a sidecar without a
/// date takes the TIFF's. `None` when there is neither.
pub fn metadata_of(image: &Path) -> Result<Option<Acquisition>> {
    let sidecar = match find_metadata_file(image) {
        Some(file) => Some(read_metadata_file(&file)?),
        None => None,
    };
    if sidecar.as_ref().is_some_and(|a| a.datetime.is_some()) {
        return Ok(sidecar);
    }
    let from_tiff = if is_tiff(image) {
        match TiffReader::open(image)?.gdal_metadata {
            Some(xml) => Some(acquisition_from_gdal_metadata(&xml, image)?),
            None => None,
        }
    } else {
        None
    };
    Ok(match (sidecar, from_tiff) {
        (Some(mut a), Some(t)) => {
            a.datetime = t.datetime;
            Some(a)
        }
        (a, t) => a.or(t),
    })
}

/// Reads a metadata sidecar, `.IMD` or DIMAP `DIM_*.XML`, recognised by its content.
pub fn read_metadata_file(path: &Path) -> Result<Acquisition> {
    match sniff(path)? {
        Kind::Xml => read_dimap_metadata(path),
        Kind::Text(text) => digitalglobe::imd_from_text(&text, path),
        Kind::Tiff | Kind::Json => Err(metadata_error(
            &path.display().to_string(),
            "",
            "not a metadata file this reader knows (IMD, DIMAP XML)",
        )),
    }
}

impl RpcModel {
    /// The model as a GDAL `_RPC.TXT` file (RPC00B keys, one `KEY: value unit` a line), each
    /// number written so that it reads back exactly.
    pub fn to_rpc_txt(&self) -> String {
        rpc_txt::write(self)
    }
}

/// What a file holds, from its first bytes.
enum Kind {
    Tiff,
    Json,
    Xml,
    Text(String),
}

fn sniff(path: &Path) -> Result<Kind> {
    let mut head = [0u8; 4];
    let mut file = fs::File::open(path).map_err(|e| raster::RasterError::io(path, e))?;
    let n = read_up_to(&mut file, &mut head).map_err(|e| raster::RasterError::io(path, e))?;
    if is_tiff_magic(&head[..n]) {
        return Ok(Kind::Tiff);
    }
    let bytes = fs::read(path).map_err(|e| raster::RasterError::io(path, e))?;
    let text = String::from_utf8_lossy(&bytes);
    let text = text.trim_start_matches('\u{feff}');
    Ok(match text.trim_start().chars().next() {
        Some('{') => Kind::Json,
        Some('<') => Kind::Xml,
        _ => Kind::Text(text.to_string()),
    })
}

fn read_up_to(file: &mut fs::File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

/// Classic or Big TIFF, either byte order.
fn is_tiff_magic(head: &[u8]) -> bool {
    matches!(
        head,
        [b'I', b'I', 42, 0] | [b'M', b'M', 0, 42] | [b'I', b'I', 43, 0] | [b'M', b'M', 0, 43]
    )
}

fn is_tiff(path: &Path) -> bool {
    let mut head = [0u8; 4];
    fs::File::open(path)
        .and_then(|mut f| read_up_to(&mut f, &mut head))
        .is_ok_and(|n| is_tiff_magic(&head[..n]))
}

/// The folder and file stem of `image`.
fn split(image: &Path) -> Option<(PathBuf, String)> {
    let stem = image.file_stem()?.to_str()?.to_string();
    let dir = match image.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Some((dir, stem))
}

/// GDAL's DIMAP sidecar names for the image stem `IMG_<X>_R<i>C<j>`: `<prefix><X>_R<i>C<j>.XML`
/// then `<prefix><X>.XML` (each also in lower-case `.xml`); none unless the stem ends in a tile
/// index `_R<i>C<j>`.
fn dimap_names(stem: &str, prefix: &str) -> Vec<String> {
    let Some(rest) = stem.get(4..) else {
        return Vec::new();
    };
    let Some(underscore) = rest.rfind('_') else {
        return Vec::new();
    };
    if !is_tile_index(&rest[underscore + 1..]) {
        return Vec::new();
    }
    let base = &rest[..underscore];
    let mut names = Vec::new();
    for name in [rest, base] {
        names.push(format!("{prefix}{name}.XML"));
        names.push(format!("{prefix}{name}.xml"));
    }
    names
}

/// `R<digits>C<digits>`.
fn is_tile_index(s: &str) -> bool {
    let Some(s) = s.strip_prefix('R') else {
        return false;
    };
    let Some((r, c)) = s.split_once('C') else {
        return false;
    };
    let digits = |t: &str| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit());
    digits(r) && digits(c)
}

fn first_file(dir: &Path, names: &[String]) -> Option<PathBuf> {
    names.iter().map(|n| dir.join(n)).find(|p| p.is_file())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vendor::fields::{compact_datetime, iso_datetime, nitf_datetime, number};

    #[test]
    fn dates() {
        assert_eq!(
            iso_datetime("2014-12-14T16:04:02.000000Z").as_deref(),
            Some("20141214160402")
        );
        assert_eq!(
            compact_datetime("2013-01-01", Some("10:11:12.5Z")).as_deref(),
            Some("20130101101112")
        );
        assert_eq!(
            compact_datetime("2013-01-01", None).as_deref(),
            Some("20130101000000")
        );
        for bad in [
            "",
            "2014-13-01T00:00:00Z",
            "2014-12-14T25:00:00",
            "2014-1-1",
            "x",
        ] {
            assert_eq!(iso_datetime(bad), None, "{bad}");
        }
        assert_eq!(
            nitf_datetime("20141214160402").as_deref(),
            Some("20141214160402")
        );
        assert_eq!(nitf_datetime("2014121416----"), None);
        assert_eq!(nitf_datetime("2014121416040"), None);
    }

    #[test]
    fn numbers_with_units() {
        assert_eq!(number("+030.3003 degrees"), Ok(30.3003));
        assert_eq!(number(" -21 meters"), Ok(-21.0));
        assert!(number("").is_err());
        assert!(number("nan").is_err());
        assert!(number("1e999").is_err());
        assert!(number("abc").is_err());
    }

    #[test]
    fn dimap_sidecar_names() {
        assert_eq!(
            dimap_names("IMG_PHR1A_P_001_R1C1", "RPC_"),
            [
                "RPC_PHR1A_P_001_R1C1.XML",
                "RPC_PHR1A_P_001_R1C1.xml",
                "RPC_PHR1A_P_001.XML",
                "RPC_PHR1A_P_001.xml"
            ]
        );
        assert!(dimap_names("JAX_068_006_RGB", "RPC_").is_empty());
        assert!(dimap_names("IMG", "RPC_").is_empty());
        assert!(dimap_names("IMG_X_R1", "DIM_").is_empty());
        assert!(is_tile_index("R12C3") && !is_tile_index("RC3") && !is_tile_index("R1C"));
    }
}
