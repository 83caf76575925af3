//! What is made from a finished DSM: its heights converted to the geoid when asked, and the
//! products a run asks for beside it (orthoimage, point cloud, quicklook: the `products`
//! crate), written once the DSM is, and said in the log.

use std::path::Path;

use anyhow::{Context, Result};
use camera::{DsmGrid, Heights, RpcModel};
use products::{MeasuredFrom, OrthoView, Products, ProductsWritten};

use crate::progress::Progress;

/// Writes `products` of the DSM at `dsm` (on `grid`), seen by the images `views` with their
/// cameras as the reconstruction used them; the point cloud keeps the cells the sidecar
/// `measured` marks as measured (read as `kind`). `None` when no product is asked for.
pub fn write_products(
    products: &Products,
    dsm: &Path,
    grid: &DsmGrid,
    views: &[(&Path, &RpcModel)],
    measured: (&Path, MeasuredFrom),
    progress: &dyn Progress,
) -> Result<Option<ProductsWritten>> {
    if products.is_empty() {
        return Ok(None);
    }
    if products.heights == Heights::Egm96 {
        progress.note(&format!(
            "converting {} to heights above the EGM96 geoid",
            dsm.display()
        ));
    }
    let names: Vec<String> = products
        .paths()
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    if !names.is_empty() {
        progress.note(&format!(
            "writing {} from the DSM and {} views",
            names.join(", "),
            views.len()
        ));
    }
    let views: Vec<OrthoView> = views
        .iter()
        .map(|(image, rpc)| OrthoView {
            image: image.to_path_buf(),
            rpc: (*rpc).clone(),
        })
        .collect();
    let keep = products::measured_from_sidecar(measured.0, grid, measured.1);
    let written = products
        .write(dsm, &views, keep.as_deref())
        .with_context(|| format!("writing the products of {}", dsm.display()))?;
    Ok(Some(written))
}
