//! Maxar/DigitalGlobe sidecars: the `.RPB` camera and the `.IMD` image metadata, both in the
//! `key = value;` grammar with `BEGIN_GROUP = X` … `END_GROUP = X` blocks and `( a, b, … );`
//! lists.
//!
//! The RPB's coefficient lists are in RPC00B term order; `line` is the row, `samp` the column,
//! `long` the longitude.

use std::path::Path;

use super::fields::{iso_datetime, metadata_error, number, rpc_error, Acquisition, Rpc00b};
use crate::{Result, RpcModel};

/// One `key = value` statement and the groups it sits in (outermost first).
struct Entry {
    groups: Vec<String>,
    key: String,
    value: String,
}

/// The statements of a DigitalGlobe keyword file. Lenient: lines it cannot make sense of are
/// skipped, and what is missing shows when a key is asked for.
fn entries(text: &str) -> Vec<Entry> {
    let mut groups: Vec<String> = Vec::new();
    let mut out = Vec::new();
    let mut pending = String::new();
    let mut finish = |statement: &str, groups: &mut Vec<String>| {
        let statement = statement.trim().trim_end_matches(';').trim();
        let Some((key, value)) = statement.split_once('=') else {
            return;
        };
        let (key, value) = (key.trim(), value.trim());
        if key.eq_ignore_ascii_case("BEGIN_GROUP") {
            groups.push(value.to_string());
        } else if key.eq_ignore_ascii_case("END_GROUP") {
            groups.pop();
        } else {
            out.push(Entry {
                groups: groups.clone(),
                key: key.to_string(),
                value: value.trim_matches('"').to_string(),
            });
        }
    };
    for line in text.lines() {
        let line = line.trim();
        let upper = line.to_ascii_uppercase();
        if pending.is_empty()
            && (upper.starts_with("BEGIN_GROUP") || upper.starts_with("END_GROUP"))
        {
            finish(line, &mut groups);
            continue;
        }
        pending.push_str(line);
        pending.push('\n');
        if line.ends_with(';') {
            finish(&pending, &mut groups);
            pending.clear();
        }
    }
    if !pending.trim().is_empty() {
        // A truncated file: keep its last statement so that the key it names reports it.
        finish(&pending, &mut groups);
    }
    out
}

/// The value of `key` in group `group` (any group when `None`), case-insensitive.
fn lookup<'a>(entries: &'a [Entry], group: Option<&str>, key: &str) -> Option<&'a str> {
    entries
        .iter()
        .find(|e| {
            e.key.eq_ignore_ascii_case(key)
                && group.is_none_or(|g| {
                    e.groups
                        .last()
                        .is_some_and(|last| last.eq_ignore_ascii_case(g))
                })
        })
        .map(|e| e.value.as_str())
}

/// Reads a Maxar/DigitalGlobe `.RPB` camera.
pub fn read_rpb(path: &Path) -> Result<RpcModel> {
    let text = std::fs::read(path).map_err(|e| raster::RasterError::io(path, e))?;
    rpb_from_text(&String::from_utf8_lossy(&text), &path.display().to_string())
}

pub(super) fn rpb_from_text(text: &str, origin: &str) -> Result<RpcModel> {
    let entries = entries(text);
    // Keys are looked for in the IMAGE group, where DigitalGlobe puts them, else anywhere.
    let get = |key: &str| {
        lookup(&entries, Some("IMAGE"), key)
            .or_else(|| lookup(&entries, None, key))
            .ok_or_else(|| rpc_error(origin, key, "missing"))
    };
    let scalar =
        |key: &str| -> Result<f64> { number(get(key)?).map_err(|m| rpc_error(origin, key, m)) };
    let scale = |key: &str| -> Result<f64> {
        let x = scalar(key)?;
        if x == 0.0 {
            return Err(rpc_error(origin, key, "a scale cannot be zero"));
        }
        Ok(x)
    };
    let poly = |key: &str| -> Result<[f64; 20]> {
        let v = get(key)?.trim();
        let inner = v
            .strip_prefix('(')
            .and_then(|v| v.strip_suffix(')'))
            .ok_or_else(|| rpc_error(origin, key, "expected a parenthesised list of 20 numbers"))?;
        let items: Vec<&str> = inner.split(',').map(str::trim).collect();
        if items.len() != 20 {
            return Err(rpc_error(
                origin,
                key,
                format!("expected 20 coefficients, got {}", items.len()),
            ));
        }
        let mut out = [0.0; 20];
        for (i, (o, item)) in out.iter_mut().zip(&items).enumerate() {
            *o =
                number(item).map_err(|m| rpc_error(origin, key, format!("term {}: {m}", i + 1)))?;
        }
        Ok(out)
    };
    Rpc00b {
        offsets: [
            scalar("lineOffset")?,
            scalar("sampOffset")?,
            scalar("latOffset")?,
            scalar("longOffset")?,
            scalar("heightOffset")?,
        ],
        scales: [
            scale("lineScale")?,
            scale("sampScale")?,
            scale("latScale")?,
            scale("longScale")?,
            scale("heightScale")?,
        ],
        polys: [
            poly("lineNumCoef")?,
            poly("lineDenCoef")?,
            poly("sampNumCoef")?,
            poly("sampDenCoef")?,
        ],
    }
    .into_model(origin)
}

/// Reads a Maxar/DigitalGlobe `.IMD`: the acquisition time (`firstLineTime` of group `IMAGE_1`,
/// or of `IMAGE` in older files, as GDAL reads it) and the mean sun and satellite angles
/// (`meanSunEl`, `meanSunAz`, `meanSatEl`, `meanSatAz`).
pub fn read_imd(path: &Path) -> Result<Acquisition> {
    let text = std::fs::read(path).map_err(|e| raster::RasterError::io(path, e))?;
    imd_from_text(&String::from_utf8_lossy(&text), path)
}

pub(super) fn imd_from_text(text: &str, path: &Path) -> Result<Acquisition> {
    let origin = path.display().to_string();
    let entries = entries(text);
    let get = |key: &str| {
        lookup(&entries, Some("IMAGE_1"), key).or_else(|| lookup(&entries, Some("IMAGE"), key))
    };
    let angle = |key: &str| -> Result<Option<f64>> {
        match get(key) {
            None => Ok(None),
            Some(v) => number(v)
                .map(Some)
                .map_err(|m| metadata_error(&origin, key, m)),
        }
    };
    let datetime = match get("firstLineTime") {
        None => None,
        Some(v) => Some(iso_datetime(v).ok_or_else(|| {
            metadata_error(&origin, "firstLineTime", format!("not a date-time: {v:?}"))
        })?),
    };
    Ok(Acquisition {
        datetime,
        sun_elevation: angle("meanSunEl")?,
        sun_azimuth: angle("meanSunAz")?,
        satellite_elevation: angle("meanSatEl")?,
        satellite_azimuth: angle("meanSatAz")?,
        source: path.to_path_buf(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grammar() {
        let e = entries(
            "a = \"x\";\nBEGIN_GROUP = IMAGE\n\tb = 1;\n\tc = (\n1,\n2);\nEND_GROUP = IMAGE\nEND;\n",
        );
        assert_eq!(lookup(&e, None, "A"), Some("x"));
        assert_eq!(lookup(&e, Some("image"), "b"), Some("1"));
        assert_eq!(lookup(&e, Some("image"), "c"), Some("(\n1,\n2)"));
        assert_eq!(lookup(&e, Some("IMAGE_1"), "b"), None);
    }
}
