//! What a DSM's heights are measured from, and how its file says so.

/// The vertical reference of a DSM's heights.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum Heights {
    /// Above the WGS84 ellipsoid (EPSG:4979), as the cameras give them.
    #[default]
    Ellipsoid,
    /// Above the EGM96 geoid (EPSG:5773, ≈ mean sea level).
    Egm96,
}

impl Heights {
    /// GDAL's metadata (tag 42112) saying what the heights are: `gdalinfo` and QGIS show the
    /// band's description and unit and the vertical reference as a dataset item.
    pub fn gdal_metadata(self) -> String {
        let (reference, description) = match self {
            Heights::Ellipsoid => (
                "ellipsoidal heights, WGS84 (EPSG:4979)",
                "height above the WGS84 ellipsoid",
            ),
            Heights::Egm96 => (
                "EGM96 geoid heights (EPSG:5773)",
                "height above the EGM96 geoid",
            ),
        };
        format!(
            "<GDALMetadata>\n  <Item name=\"VERTICAL_REFERENCE\">{reference}</Item>\n  \
             <Item name=\"VERTICAL_UNIT\">metre</Item>\n  <Item name=\"DESCRIPTION\" \
             sample=\"0\" role=\"description\">{description}</Item>\n  <Item name=\"UNITTYPE\" \
             sample=\"0\" role=\"unittype\">metre</Item>\n</GDALMetadata>"
        )
    }
}
