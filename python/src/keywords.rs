//! Keyword options (`**options`) read into the library's flag values ([`seasonstereo::flags`]):
//! the same names, defaults and meanings as the command line's flags, underscores for dashes.

use std::path::PathBuf;

use pyo3::exceptions::{PyOverflowError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use seasonstereo::flags::{self, ClassicalFlags};
use seasonstereo::Finishing;

use crate::errors::{exception, value_error};

/// The most worker threads a call may ask for: far beyond any core count, each one a stack.
const MAX_THREADS: usize = 1024;

/// The keywords of one call, taken one by one; any left at the end were misspelt.
pub struct Keywords<'py>(Bound<'py, PyDict>);

impl<'py> Keywords<'py> {
    /// The keywords given (none when `None`), copied so that taking them leaves the caller's dict.
    pub fn new(py: Python<'py>, given: Option<&Bound<'py, PyDict>>) -> PyResult<Self> {
        Ok(Keywords(match given {
            Some(d) => d.copy()?,
            None => PyDict::new(py),
        }))
    }

    /// The value of `key` when given and not `None`.
    pub fn take<T: FromPyObject<'py>>(&self, key: &str) -> PyResult<Option<T>> {
        let Some(value) = self.0.get_item(key)? else {
            return Ok(None);
        };
        self.0.del_item(key)?;
        if value.is_none() {
            return Ok(None);
        }
        value.extract().map(Some).map_err(|e| {
            let py = value.py();
            let message = format!("option {key}: {}", e.value(py));
            // A number out of the option's range (a negative count) is a bad value, not type.
            if e.is_instance_of::<PyOverflowError>(py) {
                value_error(message)
            } else {
                PyTypeError::new_err(message)
            }
        })
    }

    /// A path option (`str` or `os.PathLike`).
    pub fn path(&self, key: &str) -> PyResult<Option<PathBuf>> {
        self.take(key)
    }

    /// Fails naming the keywords nobody took.
    pub fn finish(self) -> PyResult<()> {
        let left: Vec<String> = self.0.keys().iter().map(|k| k.to_string()).collect();
        if left.is_empty() {
            return Ok(());
        }
        Err(PyTypeError::new_err(format!(
            "unexpected option(s): {}",
            left.join(", ")
        )))
    }

    /// The classical matcher's settings: `method` and the keywords `p1`, `p2`, `four_paths`,
    /// `lr_tolerance`, `p2_adaptive`, `census` ("WxH"), `uniqueness`, `speckle`,
    /// `speckle_diff`; absent ones keep the command line's defaults.
    pub fn classical(&self, method: &str) -> PyResult<ClassicalFlags> {
        let d = ClassicalFlags::default();
        let census = match self.take::<String>("census")? {
            Some(c) => flags::census_window(&c)
                .map_err(|e| value_error(format!("census is \"WxH\", e.g. \"5x5\": {e}")))?,
            None => d.census,
        };
        Ok(ClassicalFlags {
            method: flags::method(method).map_err(exception)?,
            p1: self.take("p1")?.unwrap_or(d.p1),
            p2: self.take("p2")?.unwrap_or(d.p2),
            four_paths: self.take("four_paths")?.unwrap_or(d.four_paths),
            lr_tolerance: self.take("lr_tolerance")?.unwrap_or(d.lr_tolerance),
            p2_adaptive: self.take("p2_adaptive")?.unwrap_or(d.p2_adaptive),
            census,
            uniqueness: self.take("uniqueness")?.unwrap_or(d.uniqueness),
            speckle: self.take("speckle")?.unwrap_or(d.speckle),
            speckle_diff: self.take("speckle_diff")?.unwrap_or(d.speckle_diff),
        })
    }

    /// `threads`: the worker threads of this call (default: every core, shared by all calls).
    /// Refused above [`MAX_THREADS`] before any is started.
    pub fn threads(&self) -> PyResult<Option<usize>> {
        let threads = self.take("threads")?;
        match threads {
            Some(n) if n > MAX_THREADS => Err(value_error(format!(
                "threads must be between 1 and {MAX_THREADS}, got {n}"
            ))),
            _ => Ok(threads),
        }
    }

    /// `gridding` ("median" or "max"), `fill_holes` and `median_filter` (cells, 0 = none), and
    /// with `reach` `fill_reach` (cells), over the given defaults: how a DSM is made from its
    /// points, in every command that makes one. Without `reach` the filling has none (its rays'
    /// length).
    pub fn finishing(&self, finishing: &mut Finishing, reach: bool) -> PyResult<()> {
        let mut gridding = finishing.gridding;
        if let Some(g) = self.take::<String>("gridding")? {
            gridding = flags::gridding(&g).map_err(exception)?;
        }
        let fill_holes = match self.take("fill_holes")? {
            Some(cells) => flags::fill_cells(cells),
            None => finishing.fill_holes.map(|f| f.span),
        };
        let fill_reach = match reach {
            true => self
                .take("fill_reach")?
                .or(finishing.fill_holes.map(|f| f.reach)),
            false => None,
        };
        let median_filter = match self.take("median_filter")? {
            Some(cells) => flags::median_cells(cells),
            None => finishing.median_filter,
        };
        *finishing = Finishing::new(gridding, fill_holes, fill_reach, median_filter);
        Ok(())
    }

    /// `ortho`, `ortho_blend` ("nadir" or "median"), `points`, `preview`, `heights`
    /// ("ellipsoid" or "egm96"): the products written beside the DSM and its vertical
    /// reference, as the command line's `--ortho`, `--ortho-blend`, `--points`, `--preview`,
    /// `--heights`.
    pub fn products(&self) -> PyResult<seasonstereo::Products> {
        let mut products = seasonstereo::Products {
            ortho: self.path("ortho")?,
            points: self.path("points")?,
            preview: self.path("preview")?,
            ..Default::default()
        };
        if let Some(blend) = self.take::<String>("ortho_blend")? {
            products.ortho_blend = flags::ortho_blend(&blend).map_err(exception)?;
        }
        if let Some(heights) = self.take::<String>("heights")? {
            products.heights = flags::heights(&heights).map_err(exception)?;
        }
        Ok(products)
    }

    /// `tile`, `collar` (pixels) and `max_memory` (GiB) over the given defaults: the tiling of
    /// every command that runs tiles.
    pub fn tiling(
        &self,
        tile: &mut usize,
        collar: &mut usize,
        max_memory: &mut u64,
    ) -> PyResult<()> {
        *tile = self.take("tile")?.unwrap_or(*tile);
        *collar = self.take("collar")?.unwrap_or(*collar);
        if let Some(gib) = self.take("max_memory")? {
            *max_memory = flags::memory_bytes(gib).map_err(exception)?;
        }
        Ok(())
    }
}
