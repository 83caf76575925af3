//! The acquisition date GDAL keeps in a TIFF's metadata tag 42112 when it converts a NITF image:
//! `<GDALMetadata><Item name="NITF_IDATIM">20141214160402</Item>…`, or failing that
//! `NITF_STDIDC_ACQUISITION_DATE` of the STDIDC extension, both `YYYYMMDDhhmmss`.

use std::path::Path;

use super::fields::{metadata_error, nitf_datetime, Acquisition};
use super::xml::leaves;
use crate::Result;

const DATE_ITEMS: [&str; 2] = ["NITF_IDATIM", "NITF_STDIDC_ACQUISITION_DATE"];

/// The acquisition in the GDAL metadata `xml` of the TIFF `image`: its date when an item gives
/// one, no angles. An item that is there but not a
/// date is an error; no item gives `datetime: None`.
pub fn acquisition_from_gdal_metadata(xml: &str, image: &Path) -> Result<Acquisition> {
    let origin = image.display().to_string();
    let items = leaves(xml).map_err(|m| {
        metadata_error(
            &origin,
            "42112",
            format!("malformed GDAL metadata XML: {m}"),
        )
    })?;
    let mut datetime = None;
    for key in DATE_ITEMS {
        let item = items.iter().find(|l| {
            l.name == "Item" && l.name_attr.as_deref() == Some(key) && !l.text.is_empty()
        });
        if let Some(item) = item {
            // NITF writes unknown digits as '-': such a date is no date.
            if item.text.contains('-') {
                continue;
            }
            datetime = Some(nitf_datetime(&item.text).ok_or_else(|| {
                metadata_error(&origin, key, format!("not a date-time: {:?}", item.text))
            })?);
            break;
        }
    }
    Ok(Acquisition {
        datetime,
        source: image.to_path_buf(),
        ..Acquisition::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn date(xml: &str) -> Result<Option<String>> {
        acquisition_from_gdal_metadata(xml, Path::new("x.tif")).map(|a| a.datetime)
    }

    #[test]
    fn nitf_dates() {
        let item = |k: &str, v: &str| {
            format!("<GDALMetadata>\n  <Item name=\"NITF_ABPP\">11</Item>\n  <Item name=\"{k}\">{v}</Item>\n</GDALMetadata>")
        };
        assert_eq!(
            date(&item("NITF_IDATIM", "20141214160402"))
                .unwrap()
                .as_deref(),
            Some("20141214160402")
        );
        assert_eq!(
            date(&item("NITF_STDIDC_ACQUISITION_DATE", "20141214160402"))
                .unwrap()
                .as_deref(),
            Some("20141214160402")
        );
        assert_eq!(date(&item("NITF_IDATIM", "2014121416----")).unwrap(), None);
        assert_eq!(date(&item("NITF_FDT", "20170123150226")).unwrap(), None);
        assert_eq!(date("<GDALMetadata/>").unwrap(), None);
        let err = date(&item("NITF_IDATIM", "20141314160402")).unwrap_err();
        assert!(err.to_string().contains("NITF_IDATIM"), "{err}");
        assert!(date("<GDALMetadata><Item name=\"NITF_IDATIM\">2014").is_err());
    }
}
