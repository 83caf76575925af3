//! numpy arrays in and out: images as `H×W` or `H×W×C` arrays of float32, uint8 or uint16 (the
//! values kept, as the command line reads them from files), disparities and DSMs as float32.

use numpy::ndarray::{Array2, ArrayViewD};
use numpy::{IntoPyArray, PyArray2, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use seasonstereo::Image;

use crate::errors::value_error;

/// An image array of one of the pixel types satellite images come in.
#[derive(FromPyObject)]
pub enum ImageArray<'py> {
    F32(PyReadonlyArrayDyn<'py, f32>),
    U8(PyReadonlyArrayDyn<'py, u8>),
    U16(PyReadonlyArrayDyn<'py, u16>),
}

impl ImageArray<'_> {
    /// The image, pixels interleaved as the library stores them (row-major, channels last).
    pub fn to_image(&self) -> PyResult<Image> {
        match self {
            ImageArray::F32(a) => image(a.as_array()),
            ImageArray::U8(a) => image(a.as_array()),
            ImageArray::U16(a) => image(a.as_array()),
        }
    }
}

/// An `H×W` or `H×W×C` array as an image, in any memory layout.
fn image<T: Copy + Into<f32>>(a: ArrayViewD<'_, T>) -> PyResult<Image> {
    let (height, width, channels) = match *a.shape() {
        [h, w] => (h, w, 1),
        [h, w, c] => (h, w, c),
        _ => {
            return Err(value_error(format!(
                "an image is an H×W or H×W×C array, got {} dimensions",
                a.ndim()
            )))
        }
    };
    let data = a.iter().map(|&v| v.into()).collect();
    Image::new(width, height, channels, data).map_err(value_error)
}

/// A one-channel image (a disparity, a DSM) as an `H×W` float32 array.
pub fn to_numpy(py: Python<'_>, image: Image) -> PyResult<Bound<'_, PyArray2<f32>>> {
    let (w, h) = image.size();
    let array = Array2::from_shape_vec((h, w), image.into_data()).map_err(value_error)?;
    Ok(array.into_pyarray(py))
}
