//! What the one band of a raster on a DSM grid holds, and how its file says so: the DSM's
//! heights (and from what they are measured), or a sidecar's values (pairs per cell, matching
//! confidence, filled cells). `gdalinfo`, QGIS and rasterio show the band's description and unit
//! and, for heights, the vertical reference as a dataset item (GDAL's metadata, tag 42112).

/// The vertical reference of a DSM's heights.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum Heights {
    /// Above the WGS84 ellipsoid (EPSG:4979), as the cameras give them.
    #[default]
    Ellipsoid,
    /// Above the EGM96 geoid (EPSG:5773, ≈ mean sea level).
    Egm96,
}

/// What a raster on a DSM grid holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Band {
    /// Heights, metres, above a reference.
    Heights(Heights),
    /// Any other value per cell: what it is, and its unit when it has one.
    Values {
        description: &'static str,
        unit: Option<&'static str>,
    },
}

impl Band {
    /// GDAL's metadata saying what the band holds.
    pub fn gdal_metadata(self) -> String {
        let mut items = Vec::new();
        let (description, unit) = match self {
            Band::Heights(heights) => {
                let (reference, description) = match heights {
                    Heights::Ellipsoid => (
                        "ellipsoidal heights, WGS84 (EPSG:4979)",
                        "height above the WGS84 ellipsoid",
                    ),
                    Heights::Egm96 => (
                        "EGM96 geoid heights (EPSG:5773)",
                        "height above the EGM96 geoid",
                    ),
                };
                items.push(format!(
                    "<Item name=\"VERTICAL_REFERENCE\">{reference}</Item>"
                ));
                items.push("<Item name=\"VERTICAL_UNIT\">metre</Item>".to_string());
                (description, Some("metre"))
            }
            Band::Values { description, unit } => (description, unit),
        };
        items.push(format!(
            "<Item name=\"DESCRIPTION\" sample=\"0\" role=\"description\">{description}</Item>"
        ));
        if let Some(unit) = unit {
            items.push(format!(
                "<Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">{unit}</Item>"
            ));
        }
        format!("<GDALMetadata>\n  {}\n</GDALMetadata>", items.join("\n  "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_name_their_reference_and_values_only_what_they_are() {
        let h = Band::Heights(Heights::Egm96).gdal_metadata();
        assert!(h.contains("EGM96 geoid heights (EPSG:5773)") && h.contains(">metre<"));
        let count = Band::Values {
            description: "pairs that measured the cell",
            unit: None,
        }
        .gdal_metadata();
        assert!(count.contains(">pairs that measured the cell<"), "{count}");
        assert!(
            !count.contains("VERTICAL") && !count.contains("unittype"),
            "{count}"
        );
    }
}
