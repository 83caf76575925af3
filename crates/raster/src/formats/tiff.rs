//! TIFF and GeoTIFF rasters: satellite images with their RPC camera models, and the
//! georeferenced DSMs the pipeline produces.
//!
//! Pixels are read band-interleaved as `f32` in their native units (no rescaling); the geotiff
//! tags are decoded into a GDAL-style geotransform, the EPSG code and the raw key directory.

use std::fs::File;
use std::io::{self, BufReader, Seek, Write};
use std::path::{Path, PathBuf};

use tiff::decoder::{ChunkType, Decoder, DecodingResult, Limits};
use tiff::encoder::colortype::ColorType;
use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, TiffKind};
use tiff::tags::{PhotometricInterpretation, PlanarConfiguration, SampleFormat, Tag};

use super::support::{alloc_samples, checked_samples, no_panic, write_atomically};
use crate::{Image, RasterError, Result};

pub(super) const TAG_RPC: u16 = 50844;
/// GDAL's metadata tag: an XML `<GDALMetadata>` of name/value items (NITF header fields and the
/// like of a converted satellite image).
pub(super) const TAG_GDAL_METADATA: u16 = 42112;
const KEY_MODEL_TYPE: u16 = 1024;
const KEY_RASTER_TYPE: u16 = 1025;
const KEY_GEOGRAPHIC_TYPE: u16 = 2048;
const KEY_PROJECTED_TYPE: u16 = 3072;

/// A raster read from a (Geo)TIFF with what the file says about where it is.
#[derive(Clone, Debug, PartialEq)]
pub struct GeoRaster {
    pub image: Image,
    pub georef: Option<GeoReference>,
    /// The GDAL_NODATA value; NaN when the file says "nan".
    pub nodata: Option<f64>,
    /// The RPC camera model of a satellite image.
    pub rpc: Option<RpcTag>,
}

impl GeoRaster {
    /// The metadata, to write another raster on the same grid with [`write_geotiff`].
    pub fn meta(&self) -> GeoTiffMeta {
        GeoTiffMeta::on_grid_of(&self.georef, self.nodata, &self.rpc)
    }
}

/// What [`write_geotiff`] stores besides the pixels.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GeoTiffMeta {
    pub georef: Option<GeoReference>,
    pub nodata: Option<f64>,
    pub rpc: Option<RpcTag>,
    /// GDAL's metadata (tag 42112, `<GDALMetadata>…</GDALMetadata>`): band descriptions, units
    /// and dataset items that GDAL, QGIS and rasterio show.
    pub gdal_metadata: Option<String>,
}

impl GeoTiffMeta {
    /// The metadata of a new raster on another's grid, nodata and camera; not the other's GDAL
    /// metadata, which describes its content (an acquisition date, what heights are), not the
    /// new one's.
    fn on_grid_of(
        georef: &Option<GeoReference>,
        nodata: Option<f64>,
        rpc: &Option<RpcTag>,
    ) -> Self {
        GeoTiffMeta {
            georef: georef.clone(),
            nodata,
            rpc: rpc.clone(),
            gdal_metadata: None,
        }
    }
}

/// Where a raster lies: GDAL's affine geotransform and the coordinate system.
#[derive(Clone, Debug, PartialEq)]
pub struct GeoReference {
    /// `x = gt[0] + col*gt[1] + row*gt[2]`, `y = gt[3] + col*gt[4] + row*gt[5]`, for the corner of
    /// pixel (0, 0) (the PixelIsArea convention, as GDAL reports it).
    pub geotransform: [f64; 6],
    /// ProjectedCSTypeGeoKey, or else GeographicTypeGeoKey.
    pub epsg: Option<u32>,
    /// The raw GeoKeyDirectory (tag 34735). When present it is written back as is (so a CRS
    /// described by more than an EPSG code survives a round trip); otherwise a minimal one is
    /// built from `epsg`.
    pub geo_keys: Option<Vec<u16>>,
    /// GeoDoubleParams (tag 34736).
    pub geo_doubles: Option<Vec<f64>>,
    /// GeoAsciiParams (tag 34737).
    pub geo_ascii: Option<String>,
}

impl GeoReference {
    /// A north-up grid with square `resolution`-sized pixels whose top-left corner is
    /// `(x_min, y_max)`, e.g. a UTM DSM.
    pub fn from_origin_utm(x_min: f64, y_max: f64, resolution: f64, epsg: u32) -> Self {
        GeoReference {
            geotransform: [x_min, resolution, 0.0, y_max, 0.0, -resolution],
            epsg: Some(epsg),
            geo_keys: None,
            geo_doubles: None,
            geo_ascii: None,
        }
    }

    /// The value of GeoKey `id` when stored inline in the key directory.
    fn key(keys: &[u16], id: u16) -> Option<u16> {
        keys.get(4..)?
            .chunks_exact(4)
            .find(|k| k[0] == id && k[1] == 0)
            .map(|k| k[3])
    }

    fn pixel_is_point(&self) -> bool {
        self.geo_keys
            .as_deref()
            .and_then(|k| Self::key(k, KEY_RASTER_TYPE))
            == Some(2)
    }
}

/// The RPC camera model of tag 50844 (RPCCoefficientTag), in its storage order.
#[derive(Clone, Debug, PartialEq)]
pub struct RpcTag {
    pub err_bias: f64,
    pub err_rand: f64,
    pub line_off: f64,
    pub samp_off: f64,
    pub lat_off: f64,
    pub lon_off: f64,
    pub height_off: f64,
    pub line_scale: f64,
    pub samp_scale: f64,
    pub lat_scale: f64,
    pub lon_scale: f64,
    pub height_scale: f64,
    pub line_num: [f64; 20],
    pub line_den: [f64; 20],
    pub samp_num: [f64; 20],
    pub samp_den: [f64; 20],
}

impl RpcTag {
    /// Number of doubles in the tag.
    pub const LEN: usize = 92;

    /// From the 92 doubles of the tag.
    pub fn from_coefficients(c: &[f64]) -> std::result::Result<Self, String> {
        if c.len() != Self::LEN {
            return Err(format!(
                "RPC tag {TAG_RPC} has {} values, expected {}",
                c.len(),
                Self::LEN
            ));
        }
        let arr = |i: usize| -> [f64; 20] { c[i..i + 20].try_into().expect("20 values") };
        Ok(RpcTag {
            err_bias: c[0],
            err_rand: c[1],
            line_off: c[2],
            samp_off: c[3],
            lat_off: c[4],
            lon_off: c[5],
            height_off: c[6],
            line_scale: c[7],
            samp_scale: c[8],
            lat_scale: c[9],
            lon_scale: c[10],
            height_scale: c[11],
            line_num: arr(12),
            line_den: arr(32),
            samp_num: arr(52),
            samp_den: arr(72),
        })
    }

    /// The 92 doubles in storage order.
    pub fn to_coefficients(&self) -> Vec<f64> {
        let mut c = vec![
            self.err_bias,
            self.err_rand,
            self.line_off,
            self.samp_off,
            self.lat_off,
            self.lon_off,
            self.height_off,
            self.line_scale,
            self.samp_scale,
            self.lat_scale,
            self.lon_scale,
            self.height_scale,
        ];
        for a in [
            &self.line_num,
            &self.line_den,
            &self.samp_num,
            &self.samp_den,
        ] {
            c.extend_from_slice(a);
        }
        c
    }
}

/// Reads the first image of a TIFF or BigTIFF: uint8/16/32, int8/16/32 or float32/64 samples,
/// any number of bands (chunky or planar), striped or tiled, uncompressed, LZW, Deflate or
/// PackBits.
pub fn read_tiff(path: impl AsRef<Path>) -> Result<GeoRaster> {
    let mut reader = TiffReader::open(path)?;
    let (w, h) = reader.size();
    let image = reader.read_window(0, 0, w, h)?;
    Ok(GeoRaster {
        image,
        georef: reader.georef,
        nodata: reader.nodata,
        rpc: reader.rpc,
    })
}

/// A (Geo)TIFF opened for reading windows of its first image: only the strips or tiles a window
/// touches are decoded, so a whole satellite scene (35,000 × 40,000 px and more) is never held in
/// memory. The metadata is read once, at opening.
pub struct TiffReader {
    path: PathBuf,
    dec: Dec,
    file_len: u64,
    layout: Layout,
    pub georef: Option<GeoReference>,
    /// The GDAL_NODATA value; NaN when the file says "nan".
    pub nodata: Option<f64>,
    /// The RPC camera model of a satellite image.
    pub rpc: Option<RpcTag>,
    /// The text of GDAL's metadata tag 42112 (`<GDALMetadata>…`), as stored; the camera crate
    /// reads acquisition dates from it.
    pub gdal_metadata: Option<String>,
}

impl TiffReader {
    /// Opens `path` and reads its header, georeferencing, nodata, RPC and GDAL metadata tags.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|e| RasterError::io(path, e))?;
        let file_len = file.metadata().map(|m| m.len()).unwrap_or(0);
        no_panic(path, "TIFF", || {
            let mut limits = Limits::default();
            limits.ifd_value_size = 64 << 20;
            limits.decoding_buffer_size = 1 << 30;
            limits.intermediate_buffer_size = 1 << 30;
            let mut dec = Decoder::new(BufReader::new(file))
                .map_err(|e| tiff_err(path, e))?
                .with_limits(limits);
            let layout = layout(path, &mut dec)?;
            let georef = read_georef(path, &mut dec)?;
            let nodata = match find(path, &mut dec, Tag::GdalNodata)? {
                Some(v) => Some(parse_nodata(path, v)?),
                None => None,
            };
            let rpc = match find(path, &mut dec, Tag::Unknown(TAG_RPC))? {
                Some(v) => {
                    let c = v.into_f64_vec().map_err(|e| tiff_err(path, e))?;
                    Some(RpcTag::from_coefficients(&c).map_err(|m| RasterError::format(path, m))?)
                }
                None => None,
            };
            let gdal_metadata = match find(path, &mut dec, Tag::Unknown(TAG_GDAL_METADATA))? {
                Some(v) => Some(ascii_tag(path, v)?),
                None => None,
            };
            Ok(TiffReader {
                path: path.to_path_buf(),
                dec,
                file_len,
                layout,
                georef,
                nodata,
                rpc,
                gdal_metadata,
            })
        })
    }

    /// `(width, height)` of the image, pixels.
    pub fn size(&self) -> (usize, usize) {
        (self.layout.width, self.layout.height)
    }

    /// Number of bands.
    pub fn bands(&self) -> usize {
        self.layout.bands
    }

    /// The metadata, to write another raster on the same grid with [`write_geotiff`].
    pub fn meta(&self) -> GeoTiffMeta {
        GeoTiffMeta::on_grid_of(&self.georef, self.nodata, &self.rpc)
    }

    /// The `width × height` window at `(x0, y0)` as `(H, W, C)` f32; it must lie inside the
    /// image.
    pub fn read_window(
        &mut self,
        x0: usize,
        y0: usize,
        width: usize,
        height: usize,
    ) -> Result<Image> {
        let path = self.path.clone();
        let err = |m: String| RasterError::format(&path, m);
        let Layout {
            width: w,
            height: h,
            bands,
            chunk: (cw, ch),
            planar,
        } = self.layout;
        if width == 0 || height == 0 || x0 + width > w || y0 + height > h {
            return Err(err(format!(
                "window {width}x{height} at ({x0}, {y0}) is not inside the {w}x{h} image"
            )));
        }
        // Compression ratios are bounded in practice (LZW/Deflate rarely beat 1000:1 on
        // imagery); a header promising far more samples than the file could hold is corrupt.
        let max = self.file_len.saturating_mul(4096).saturating_add(1 << 28);
        let n = checked_samples(&path, width as u64, height as u64, bands as u64, max)?;
        let mut out = alloc_samples(&path, n, f32::NAN)?;
        let across = w.div_ceil(cw);
        let down = h.div_ceil(ch);
        let (planes, spp) = if planar { (bands, 1) } else { (1, bands) };
        let dec = &mut self.dec;
        no_panic(&path, "TIFF", || {
            for plane in 0..planes {
                for r in y0 / ch..(y0 + height).div_ceil(ch) {
                    for c in x0 / cw..(x0 + width).div_ceil(cw) {
                        let index = (plane * down * across + r * across + c) as u32;
                        let chunk = dec.read_chunk(index).map_err(|e| tiff_err(&path, e))?;
                        let values = to_f32(chunk).ok_or_else(|| {
                            err("unsupported TIFF sample format (need (u)int or float)".into())
                        })?;
                        let (cx, cy) = (c * cw, r * ch);
                        let dw = cw.min(w - cx);
                        let dh = ch.min(h - cy);
                        // Chunks come back `dw` pixels wide (edge tiles cropped); the bottom tiles
                        // of the planes after the first may come back uncropped in height, hence
                        // `<`.
                        if values.len() < dw * dh * spp {
                            return Err(err(format!("TIFF chunk {index} is too short")));
                        }
                        let (xa, xb) = (cx.max(x0), (cx + dw).min(x0 + width));
                        for y in cy.max(y0)..(cy + dh).min(y0 + height) {
                            let src = &values[(y - cy) * dw * spp..(y - cy + 1) * dw * spp];
                            let row = (y - y0) * width;
                            for x in xa..xb {
                                let o = (row + x - x0) * bands + plane;
                                out[o..o + spp]
                                    .copy_from_slice(&src[(x - cx) * spp..(x - cx + 1) * spp]);
                            }
                        }
                    }
                }
            }
            Ok(())
        })?;
        Image::new(width, height, bands, out).map_err(|e| err(e.to_string()))
    }
}

fn tiff_err(path: &Path, e: tiff::TiffError) -> RasterError {
    match e {
        tiff::TiffError::IoError(e) if e.kind() == io::ErrorKind::UnexpectedEof => {
            RasterError::format(path, "truncated TIFF file")
        }
        e => RasterError::format(path, format!("TIFF: {e}")),
    }
}

type Dec = Decoder<BufReader<File>>;

fn find(path: &Path, dec: &mut Dec, tag: Tag) -> Result<Option<tiff::decoder::ifd::Value>> {
    dec.find_tag(tag).map_err(|e| tiff_err(path, e))
}

/// An ASCII tag's text without its NUL terminator(s).
fn ascii_tag(path: &Path, v: tiff::decoder::ifd::Value) -> Result<String> {
    let s = v.into_string().map_err(|e| tiff_err(path, e))?;
    Ok(s.trim_end_matches('\0').to_string())
}

fn parse_nodata(path: &Path, v: tiff::decoder::ifd::Value) -> Result<f64> {
    let s = ascii_tag(path, v)?;
    let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    s.parse::<f64>()
        .map_err(|_| RasterError::format(path, format!("unreadable GDAL_NODATA value '{s}'")))
}

/// How the first image's samples are stored.
#[derive(Clone, Copy)]
struct Layout {
    width: usize,
    height: usize,
    bands: usize,
    /// Strip or tile size, pixels.
    chunk: (usize, usize),
    planar: bool,
}

/// The checked layout of the first image.
fn layout(path: &Path, dec: &mut Dec) -> Result<Layout> {
    let err = |m: String| RasterError::format(path, m);
    let (w, h) = dec.dimensions().map_err(|e| tiff_err(path, e))?;
    let bands = dec
        .find_tag_unsigned::<u16>(Tag::SamplesPerPixel)
        .map_err(|e| tiff_err(path, e))?
        .unwrap_or(1) as usize;
    let bits = dec
        .find_tag_unsigned_vec::<u16>(Tag::BitsPerSample)
        .map_err(|e| tiff_err(path, e))?
        .unwrap_or_else(|| vec![1]);
    if bits.iter().any(|&b| !matches!(b, 8 | 16 | 32 | 64)) {
        return Err(err(format!(
            "unsupported TIFF bits per sample {bits:?} (8, 16, 32 or 64 supported)"
        )));
    }
    let planar = dec
        .find_tag_unsigned::<u16>(Tag::PlanarConfiguration)
        .map_err(|e| tiff_err(path, e))?
        == Some(PlanarConfiguration::Planar.to_u16());
    if w == 0 || h == 0 || bands == 0 {
        return Err(err(format!("empty TIFF image ({w}x{h}x{bands})")));
    }
    let (cw, ch) = chunk_dims(path, dec)?;
    Ok(Layout {
        width: w as usize,
        height: h as usize,
        bands,
        chunk: (cw as usize, ch as usize),
        planar,
    })
}

fn chunk_dims(path: &Path, dec: &mut Dec) -> Result<(u32, u32)> {
    let (w, h) = dec.dimensions().map_err(|e| tiff_err(path, e))?;
    let dims = match dec.get_chunk_type() {
        ChunkType::Strip => {
            let rows = dec
                .find_tag_unsigned::<u32>(Tag::RowsPerStrip)
                .map_err(|e| tiff_err(path, e))?
                .unwrap_or(h);
            (w, rows.min(h))
        }
        ChunkType::Tile => dec.chunk_dimensions(),
    };
    if dims.0 == 0 || dims.1 == 0 {
        return Err(RasterError::format(path, "TIFF with empty strips or tiles"));
    }
    Ok(dims)
}

fn to_f32(chunk: DecodingResult) -> Option<Vec<f32>> {
    Some(match chunk {
        DecodingResult::U8(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::U16(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::U32(v) => v.into_iter().map(|x| x as f32).collect(),
        DecodingResult::I8(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::I16(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::I32(v) => v.into_iter().map(|x| x as f32).collect(),
        DecodingResult::F32(v) => v,
        DecodingResult::F64(v) => v.into_iter().map(|x| x as f32).collect(),
        _ => return None,
    })
}

fn read_georef(path: &Path, dec: &mut Dec) -> Result<Option<GeoReference>> {
    let err = |m: &str| RasterError::format(path, m.to_string());
    let f64s = |dec: &mut Dec, tag| -> Result<Option<Vec<f64>>> {
        match find(path, dec, tag)? {
            Some(v) => Ok(Some(v.into_f64_vec().map_err(|e| tiff_err(path, e))?)),
            None => Ok(None),
        }
    };
    let transform = f64s(dec, Tag::ModelTransformationTag)?;
    let scale = f64s(dec, Tag::ModelPixelScaleTag)?;
    let tie = f64s(dec, Tag::ModelTiepointTag)?;
    let geo_keys = dec
        .find_tag_unsigned_vec::<u16>(Tag::GeoKeyDirectoryTag)
        .map_err(|e| tiff_err(path, e))?;
    let geo_doubles = f64s(dec, Tag::GeoDoubleParamsTag)?;
    let geo_ascii = match find(path, dec, Tag::GeoAsciiParamsTag)? {
        Some(v) => Some(v.into_string().map_err(|e| tiff_err(path, e))?),
        None => None,
    };
    let mut gt = match (transform, scale, tie) {
        (Some(m), _, _) => {
            if m.len() < 16 {
                return Err(err("ModelTransformationTag needs 16 values"));
            }
            [m[3], m[0], m[1], m[7], m[4], m[5]]
        }
        (None, Some(s), Some(t)) => {
            if s.len() < 2 || t.len() < 6 {
                return Err(err("ModelPixelScaleTag/ModelTiepointTag too short"));
            }
            [
                t[3] - t[0] * s[0],
                s[0],
                0.0,
                t[4] + t[1] * s[1],
                0.0,
                -s[1],
            ]
        }
        _ => return Ok(None),
    };
    let keys = geo_keys.as_deref().unwrap_or(&[]);
    let epsg = GeoReference::key(keys, KEY_PROJECTED_TYPE)
        .filter(|&v| v != 0 && v != 32767)
        .or_else(|| GeoReference::key(keys, KEY_GEOGRAPHIC_TYPE).filter(|&v| v != 0 && v != 32767))
        .map(u32::from);
    if GeoReference::key(keys, KEY_RASTER_TYPE) == Some(2) {
        // PixelIsPoint: the tie point is a pixel centre; report the corner, as GDAL does.
        gt[0] -= 0.5 * (gt[1] + gt[2]);
        gt[3] -= 0.5 * (gt[4] + gt[5]);
    }
    Ok(Some(GeoReference {
        geotransform: gt,
        epsg,
        geo_keys,
        geo_doubles,
        geo_ascii,
    }))
}

/// Writes `image` as a Deflate-compressed float32 (Geo)TIFF, bands interleaved, with the
/// georeferencing, GDAL_NODATA and RPC tags of `meta`. BigTIFF is used when the data would
/// exceed 4 GiB.
pub fn write_geotiff(path: impl AsRef<Path>, image: &Image, meta: &GeoTiffMeta) -> Result<()> {
    let path = path.as_ref();
    let shape = |m: String| RasterError::Shape(format!("{}: {m}", path.display()));
    let (Ok(w), Ok(h)) = (u32::try_from(image.width()), u32::try_from(image.height())) else {
        return Err(shape("image too large for TIFF".into()));
    };
    if w == 0 || h == 0 {
        return Err(shape("cannot write an empty image".into()));
    }
    let tags = geo_tags(meta).map_err(shape)?;
    let big = (image.data().len() as u64) * 4 > (u32::MAX as u64) - (1 << 28);
    write_atomically(path, |file| {
        let r = if big {
            TiffEncoder::new_big(file).and_then(|e| encode(e, image, &tags))
        } else {
            TiffEncoder::new(file).and_then(|e| encode(e, image, &tags))
        };
        r.map_err(|e| match e {
            tiff::TiffError::IoError(e) => e,
            e => io::Error::other(e),
        })
    })
}

/// The extra tags of a GeoTIFF, computed before anything is written.
pub(super) struct GeoTags {
    pub scale: Option<[f64; 3]>,
    pub tiepoint: Option<[f64; 6]>,
    pub transform: Option<[f64; 16]>,
    pub keys: Option<Vec<u16>>,
    pub doubles: Option<Vec<f64>>,
    pub ascii: Option<String>,
    pub nodata: Option<String>,
    pub rpc: Option<Vec<f64>>,
    pub gdal_metadata: Option<String>,
}

pub(super) fn geo_tags(meta: &GeoTiffMeta) -> std::result::Result<GeoTags, String> {
    let mut t = GeoTags {
        scale: None,
        tiepoint: None,
        transform: None,
        keys: None,
        doubles: None,
        ascii: None,
        nodata: meta.nodata.map(|v| {
            if v.is_nan() {
                "nan".to_string()
            } else {
                format!("{v}")
            }
        }),
        rpc: meta.rpc.as_ref().map(RpcTag::to_coefficients),
        gdal_metadata: meta.gdal_metadata.clone(),
    };
    if let Some(g) = &meta.georef {
        let mut gt = g.geotransform;
        if gt.iter().any(|v| !v.is_finite()) {
            return Err(format!("non-finite geotransform {gt:?}"));
        }
        if g.pixel_is_point() {
            // The raw keys say PixelIsPoint: store the centre of pixel (0, 0).
            gt[0] += 0.5 * (gt[1] + gt[2]);
            gt[3] += 0.5 * (gt[4] + gt[5]);
        }
        if gt[2] == 0.0 && gt[4] == 0.0 && gt[1] > 0.0 && gt[5] < 0.0 {
            t.scale = Some([gt[1], -gt[5], 0.0]);
            t.tiepoint = Some([0.0, 0.0, 0.0, gt[0], gt[3], 0.0]);
        } else {
            t.transform = Some([
                gt[1], gt[2], 0.0, gt[0], gt[4], gt[5], 0.0, gt[3], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, 1.0,
            ]);
        }
        t.keys = Some(match &g.geo_keys {
            Some(k) => k.clone(),
            None => minimal_keys(g.epsg)?,
        });
        if g.geo_keys.is_some() {
            t.doubles = g.geo_doubles.clone();
            t.ascii = g.geo_ascii.clone();
        }
    }
    Ok(t)
}

/// A GeoKeyDirectory saying "PixelIsArea, in this EPSG coordinate system".
fn minimal_keys(epsg: Option<u32>) -> std::result::Result<Vec<u16>, String> {
    let mut keys = vec![1, 1, 0, 0];
    let mut add = |id: u16, v: u16| keys.extend_from_slice(&[id, 0, 1, v]);
    match epsg {
        Some(code) => {
            let code = u16::try_from(code).map_err(|_| format!("EPSG code {code} out of range"))?;
            let geographic = (4000..5000).contains(&code);
            add(KEY_MODEL_TYPE, if geographic { 2 } else { 1 });
            add(KEY_RASTER_TYPE, 1);
            add(
                if geographic {
                    KEY_GEOGRAPHIC_TYPE
                } else {
                    KEY_PROJECTED_TYPE
                },
                code,
            );
        }
        None => add(KEY_RASTER_TYPE, 1),
    }
    keys[3] = ((keys.len() - 4) / 4) as u16;
    Ok(keys)
}

/// `N` float32 bands, "BlackIsZero" with the extra bands unspecified, as GDAL writes them.
struct FloatBands<const N: usize>;

impl<const N: usize> ColorType for FloatBands<N> {
    type Inner = f32;
    const TIFF_VALUE: PhotometricInterpretation = PhotometricInterpretation::BlackIsZero;
    const BITS_PER_SAMPLE: &'static [u16] = &[32; N];
    const SAMPLE_FORMAT: &'static [SampleFormat] = &[SampleFormat::IEEEFP; N];

    fn horizontal_predict(row: &[f32], result: &mut Vec<f32>) {
        result.extend_from_slice(row);
    }
}

fn encode<W: Write + Seek, K: TiffKind>(
    enc: TiffEncoder<W, K>,
    image: &Image,
    tags: &GeoTags,
) -> tiff::TiffResult<()> {
    macro_rules! bands {
        ($($n:literal)*) => {
            match image.channels() {
                $($n => encode_n::<W, K, $n>(enc, image, tags),)*
                c => Err(io::Error::other(format!("cannot write {c} bands (1 to 16)")).into()),
            }
        };
    }
    bands!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16)
}

fn encode_n<W: Write + Seek, K: TiffKind, const N: usize>(
    mut enc: TiffEncoder<W, K>,
    image: &Image,
    tags: &GeoTags,
) -> tiff::TiffResult<()> {
    enc = enc.with_compression(Compression::Deflate(DeflateLevel::Fast));
    let mut im = enc.new_image::<FloatBands<N>>(image.width() as u32, image.height() as u32)?;
    let d = im.encoder();
    if N > 1 {
        d.write_tag(Tag::ExtraSamples, &vec![0u16; N - 1][..])?;
    }
    if let Some(s) = &tags.scale {
        d.write_tag(Tag::ModelPixelScaleTag, &s[..])?;
    }
    if let Some(t) = &tags.tiepoint {
        d.write_tag(Tag::ModelTiepointTag, &t[..])?;
    }
    if let Some(m) = &tags.transform {
        d.write_tag(Tag::ModelTransformationTag, &m[..])?;
    }
    if let Some(k) = &tags.keys {
        d.write_tag(Tag::GeoKeyDirectoryTag, &k[..])?;
    }
    if let Some(v) = &tags.doubles {
        d.write_tag(Tag::GeoDoubleParamsTag, &v[..])?;
    }
    if let Some(a) = &tags.ascii {
        d.write_tag(Tag::GeoAsciiParamsTag, a.as_str())?;
    }
    if let Some(n) = &tags.nodata {
        d.write_tag(Tag::GdalNodata, n.as_str())?;
    }
    if let Some(r) = &tags.rpc {
        d.write_tag(Tag::Unknown(TAG_RPC), &r[..])?;
    }
    if let Some(m) = &tags.gdal_metadata {
        d.write_tag(Tag::Unknown(TAG_GDAL_METADATA), m.as_str())?;
    }
    im.write_data(image.data())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpc_round_trip_order() {
        let c: Vec<f64> = (0..92).map(|i| i as f64).collect();
        let r = RpcTag::from_coefficients(&c).unwrap();
        assert_eq!(r.line_off, 2.0);
        assert_eq!(r.height_scale, 11.0);
        assert_eq!(r.line_den[0], 32.0);
        assert_eq!(r.samp_den[19], 91.0);
        assert_eq!(r.to_coefficients(), c);
        assert!(RpcTag::from_coefficients(&c[..90]).is_err());
    }

    #[test]
    fn gdal_metadata_tag_is_kept() {
        use tiff::encoder::colortype::Gray8;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("md.tif");
        let xml =
            "<GDALMetadata>\n  <Item name=\"NITF_IDATIM\">20141214160402</Item>\n</GDALMetadata>";
        {
            let file = File::create(&path).unwrap();
            let mut enc = TiffEncoder::new(file).unwrap();
            let mut im = enc.new_image::<Gray8>(2, 2).unwrap();
            im.encoder()
                .write_tag(Tag::Unknown(TAG_GDAL_METADATA), xml)
                .unwrap();
            im.write_data(&[1u8, 2, 3, 4]).unwrap();
        }
        let reader = TiffReader::open(&path).unwrap();
        assert_eq!(reader.gdal_metadata.as_deref(), Some(xml));
        assert!(reader.rpc.is_none());
        // The files written here carry none.
        let out = dir.path().join("out.tif");
        let mut reader = reader;
        let img = reader.read_window(0, 0, 2, 2).unwrap();
        write_geotiff(&out, &img, &reader.meta()).unwrap();
        assert_eq!(TiffReader::open(&out).unwrap().gdal_metadata, None);
    }

    #[test]
    fn minimal_key_directory() {
        assert_eq!(
            minimal_keys(Some(32740)).unwrap(),
            vec![1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32740]
        );
        assert_eq!(minimal_keys(Some(4326)).unwrap()[12..], [2048, 0, 1, 4326]);
        assert!(minimal_keys(Some(100_000)).is_err());
    }
}
