//! numpy arrays in and out: images as `H×W` or `H×W×C` arrays of float32, uint8 or uint16 (the
//! values kept, as the command line reads them from files; NaN = no data, as `rectify` writes
//! outside the views), disparities and DSMs as float32.
//! The Python layer converts other real numbers (float64, integers) to float32 before they get
//! here.

use numpy::ndarray::{Array2, ArrayViewD};
use numpy::{IntoPyArray, PyArray2, PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use seasonstereo::Image;

use crate::errors::value_error;

/// An image array of one of the pixel types satellite images come in.
pub enum ImageArray<'py> {
    F32(PyReadonlyArrayDyn<'py, f32>),
    U8(PyReadonlyArrayDyn<'py, u8>),
    U16(PyReadonlyArrayDyn<'py, u16>),
}

/// Extracted by hand: a derived extraction's error names the Rust enum and its variants.
impl<'py> FromPyObject<'py> for ImageArray<'py> {
    fn extract_bound(ob: &Bound<'py, PyAny>) -> PyResult<Self> {
        if let Ok(a) = ob.extract() {
            return Ok(ImageArray::F32(a));
        }
        if let Ok(a) = ob.extract() {
            return Ok(ImageArray::U8(a));
        }
        if let Ok(a) = ob.extract() {
            return Ok(ImageArray::U16(a));
        }
        let got = match ob.downcast::<PyUntypedArray>() {
            Ok(a) => format!("a numpy array of {}", a.dtype().str()?),
            Err(_) => ob.get_type().name()?.to_string(),
        };
        Err(PyTypeError::new_err(format!(
            "an image is a numpy array of float32, uint8 or uint16, got {got}"
        )))
    }
}

impl ImageArray<'_> {
    /// The image `name`, pixels interleaved as the library stores them (row-major, channels
    /// last); refused before it is copied when it would take more than `max_bytes` as float32
    /// (a broadcast array takes no memory in numpy, all of it here).
    pub fn to_image(&self, name: &str, max_bytes: u64) -> PyResult<Image> {
        let shape = match self {
            ImageArray::F32(a) => a.shape().to_vec(),
            ImageArray::U8(a) => a.shape().to_vec(),
            ImageArray::U16(a) => a.shape().to_vec(),
        };
        let bytes = shape.iter().fold(4u64, |b, &n| b.saturating_mul(n as u64));
        if bytes > max_bytes {
            let dims: Vec<String> = shape.iter().map(|n| n.to_string()).collect();
            return Err(value_error(format!(
                "{name} is too large: {} pixels take more than max_memory ({} GiB); crop it, \
                 or use reconstruct, which works in tiles",
                dims.join("×"),
                gib(max_bytes)
            )));
        }
        let image = match self {
            ImageArray::F32(a) => image(a.as_array()),
            ImageArray::U8(a) => image(a.as_array()),
            ImageArray::U16(a) => image(a.as_array()),
        };
        image.map_err(|e| value_error(format!("{name}: {e}")))
    }
}

/// `bytes` in GiB, as the `max_memory` option gives them.
pub fn gib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 30) as f64
}

/// An `H×W` or `H×W×C` array as an image, in any memory layout.
fn image<T: Copy + Into<f32>>(a: ArrayViewD<'_, T>) -> Result<Image, String> {
    let (height, width, channels) = match *a.shape() {
        [h, w] => (h, w, 1),
        [h, w, c] => (h, w, c),
        _ => {
            return Err(format!(
                "an image is an H×W or H×W×C array, got {} dimensions",
                a.ndim()
            ))
        }
    };
    if height == 0 || width == 0 || channels == 0 {
        return Err(format!(
            "an empty image ({height}×{width}×{channels}): it needs at least one pixel"
        ));
    }
    if a.iter().any(|&v| v.into().is_infinite()) {
        return Err("infinite values: mark pixels without data with NaN".into());
    }
    let data = a.iter().map(|&v| v.into()).collect();
    Image::new(width, height, channels, data).map_err(|e| e.to_string())
}

/// A one-channel image (a disparity, a DSM) as an `H×W` float32 array.
pub fn to_numpy(py: Python<'_>, image: Image) -> PyResult<Bound<'_, PyArray2<f32>>> {
    let (w, h) = image.size();
    let array = Array2::from_shape_vec((h, w), image.into_data()).map_err(value_error)?;
    Ok(array.into_pyarray(py))
}
