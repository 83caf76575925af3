//! Vendor cameras and metadata beside the images: the DFC2019 RPB sidecars against the benchmark
//! JSONs and the GeoTIFF tags, `_RPC.TXT` and DIMAP round trips, discovery, malformed files.

mod support;

use std::fmt::Write;
use std::fs;
use std::path::{Path, PathBuf};

use camera::vendor::{read_imd, read_rpb};
use camera::{
    camera_beside, find_camera_file, find_metadata_file, metadata_of, read_camera_file,
    read_metadata_file, CameraError, RpcModel,
};
use support::{jax_dev, JAX_DEV};

/// A mildly non-linear synthetic camera with every term of its polynomials set.
fn synthetic() -> RpcModel {
    let mut c = RpcModel::nadir(
        [17170.2054804964, 7278.22441211532, 30.3003, -81.6408, -21.0],
        [22758.0, 21250.0, 0.0703, 0.0729, 501.0],
    );
    for i in 1..20 {
        let t = i as f64;
        c.col_num[i] += 1e-3 / t;
        c.row_num[i] -= 7e-4 / (t * t);
        c.col_den[i] = 1e-5 * t.sin();
        c.row_den[i] = -2e-5 * t.cos();
    }
    c
}

/// Ground points spread over the model's validity domain.
fn ground_points(m: &RpcModel) -> Vec<(f64, f64, f64)> {
    let mut pts = Vec::new();
    for &a in &[-0.8, 0.0, 0.7] {
        for &b in &[-0.6, 0.1, 0.9] {
            for &h in &[-0.5, 0.0, 0.4] {
                pts.push((
                    m.lon_offset + a * m.lon_scale,
                    m.lat_offset + b * m.lat_scale,
                    m.alt_offset + h * m.alt_scale,
                ));
            }
        }
    }
    pts
}

/// Largest projection difference between two cameras, pixels.
fn projection_gap(a: &RpcModel, b: &RpcModel) -> f64 {
    ground_points(a)
        .into_iter()
        .map(|(lon, lat, alt)| {
            let (c1, r1) = a.projection(lon, lat, alt);
            let (c2, r2) = b.projection(lon, lat, alt);
            (c1 - c2).abs().max((r1 - r2).abs())
        })
        .fold(0.0, f64::max)
}

fn without_bounds(m: &RpcModel) -> RpcModel {
    RpcModel {
        min_alt: None,
        max_alt: None,
        ..m.clone()
    }
}

/// The model as an RPB, as DigitalGlobe writes it.
fn rpb_text(m: &RpcModel) -> String {
    let mut s = String::from("satId = \"WV03\";\nSpecId = \"RPC00B\";\nBEGIN_GROUP = IMAGE\n");
    for (k, v) in [
        ("lineOffset", m.row_offset),
        ("sampOffset", m.col_offset),
        ("latOffset", m.lat_offset),
        ("longOffset", m.lon_offset),
        ("heightOffset", m.alt_offset),
        ("lineScale", m.row_scale),
        ("sampScale", m.col_scale),
        ("latScale", m.lat_scale),
        ("longScale", m.lon_scale),
        ("heightScale", m.alt_scale),
    ] {
        let _ = writeln!(s, "\t{k} = {v};");
    }
    for (k, p) in [
        ("lineNumCoef", &m.row_num),
        ("lineDenCoef", &m.row_den),
        ("sampNumCoef", &m.col_num),
        ("sampDenCoef", &m.col_den),
    ] {
        let list: Vec<String> = p.iter().map(|c| format!("\t\t\t{c}")).collect();
        let _ = writeln!(s, "\t{k} = (\n{});", list.join(",\n"));
    }
    s.push_str("END_GROUP = IMAGE\nEND;\n");
    s
}

/// The model as a DIMAP v2 `RPC_*.XML`, image offsets 1-based; `first_col` writes a DIMAP v3
/// `ImagetoGround_Validity_Domain/FIRST_COL` and offsets based on it instead.
fn dimap_text(m: &RpcModel, first_col: Option<f64>) -> String {
    let base = first_col.unwrap_or(1.0);
    let mut s = String::from(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Dimap_Document name=\"RPC\">\n\
         <Rational_Function_Model>\n<Global_RFM>\n<Direct_Model>\n",
    );
    // A direct model with other values under the same names: it must not be read.
    for n in ["SAMP_NUM_COEFF", "LINE_NUM_COEFF"] {
        for j in 1..=20 {
            let _ = writeln!(s, "<{n}_{j}>9.5</{n}_{j}>");
        }
    }
    s.push_str("</Direct_Model>\n<Inverse_Model>\n");
    for (n, p) in [
        ("SAMP_NUM_COEFF", &m.col_num),
        ("SAMP_DEN_COEFF", &m.col_den),
        ("LINE_NUM_COEFF", &m.row_num),
        ("LINE_DEN_COEFF", &m.row_den),
    ] {
        for (j, c) in p.iter().enumerate() {
            let _ = writeln!(s, "<{n}_{}>{c:e}</{n}_{}>", j + 1, j + 1);
        }
    }
    s.push_str("<ERR_BIAS_ROW>-1</ERR_BIAS_ROW>\n</Inverse_Model>\n<RFM_Validity>\n");
    s.push_str(
        "<Direct_Model_Validity_Domain><FIRST_ROW>1</FIRST_ROW></Direct_Model_Validity_Domain>\n",
    );
    for (k, v) in [
        ("LONG_SCALE", m.lon_scale),
        ("LONG_OFF", m.lon_offset),
        ("LAT_SCALE", m.lat_scale),
        ("LAT_OFF", m.lat_offset),
        ("HEIGHT_SCALE", m.alt_scale),
        ("HEIGHT_OFF", m.alt_offset),
        ("SAMP_SCALE", m.col_scale),
        ("SAMP_OFF", m.col_offset + base),
        ("LINE_SCALE", m.row_scale),
        ("LINE_OFF", m.row_offset + base),
    ] {
        let _ = writeln!(s, "<{k}>{v}</{k}>");
    }
    s.push_str("</RFM_Validity>\n</Global_RFM>\n");
    if let Some(f) = first_col {
        let _ = writeln!(
            s,
            "<ImagetoGround_Validity_Domain><FIRST_COL>{f}</FIRST_COL></ImagetoGround_Validity_Domain>"
        );
    }
    s.push_str("</Rational_Function_Model>\n</Dimap_Document>\n");
    s
}

const DIM_XML: &str = "<?xml version=\"1.0\"?>\n<Dimap_Document>\n<Dataset_Sources>\
<Source_Identification><Strip_Source><MISSION>PLEIADES</MISSION>\
<IMAGING_DATE>2013-01-01</IMAGING_DATE><IMAGING_TIME>10:11:12.5Z</IMAGING_TIME>\
</Strip_Source></Source_Identification></Dataset_Sources>\n<Geometric_Data><Use_Area>\
<Located_Geometric_Values><LOCATION_TYPE>Top Center</LOCATION_TYPE><TIME>2013-01-01T10:11:11.9Z</TIME>\
<Solar_Incidences><SUN_AZIMUTH unit=\"deg\">150.0</SUN_AZIMUTH><SUN_ELEVATION unit=\"deg\">20.0</SUN_ELEVATION></Solar_Incidences>\
</Located_Geometric_Values>\
<Located_Geometric_Values><LOCATION_TYPE>Center</LOCATION_TYPE><TIME>2013-01-01T10:11:12.5Z</TIME>\
<Solar_Incidences><SUN_AZIMUTH unit=\"deg\">151.25</SUN_AZIMUTH><SUN_ELEVATION unit=\"deg\">21.5</SUN_ELEVATION></Solar_Incidences>\
</Located_Geometric_Values></Use_Area></Geometric_Data>\n</Dimap_Document>\n";

const IMD: &str = "version = \"28.3\";\ngenerationTime = 2015-01-01T00:00:00.000000Z;\n\
BEGIN_GROUP = IMAGE_1\n\tsatId = \"WV03\";\n\tfirstLineTime = 2014-12-14T16:04:02.000000Z;\n\
\tmeanSunAz = 158.6;\n\tmeanSunEl = 33.5;\n\tmeanSatAz = 201.2;\n\tmeanSatEl = 71.0;\n\
END_GROUP = IMAGE_1\nEND;\n";

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    fs::write(&p, text).unwrap();
    p
}

/// The camera error of `text` read as `name`, with the file's name and `key` in its message.
fn camera_error(dir: &Path, name: &str, text: &str, key: &str) -> String {
    let p = write(dir, name, text);
    let err = read_camera_file(&p).expect_err(name);
    let msg = err.to_string();
    assert!(matches!(err, CameraError::Rpc { .. }), "{msg}");
    assert!(msg.contains(name) && msg.contains(key), "{key}: {msg}");
    msg
}

#[test]
fn rpb_of_every_dev_image_is_its_json_and_its_tiff_tag() {
    testdata::require!(JAX_DEV);
    let mut rpbs: Vec<PathBuf> = fs::read_dir(jax_dev("vendor"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "RPB"))
        .collect();
    rpbs.sort();
    assert!(!rpbs.is_empty());
    for rpb in &rpbs {
        let stem = rpb.file_stem().unwrap().to_str().unwrap();
        let model = read_camera_file(rpb).unwrap();
        assert_eq!(model, read_rpb(rpb).unwrap());
        assert_eq!((model.min_alt, model.max_alt), (None, None));
        let json =
            RpcModel::read_rpcm_json(jax_dev(&format!("rpcs/original/{stem}.json"))).unwrap();
        assert_eq!(model, without_bounds(&json), "{stem}");
        let tif = jax_dev(&format!("images/{stem}.tif"));
        let tag = read_camera_file(&tif).unwrap();
        assert_eq!(tag, RpcModel::read_geotiff_rpc(&tif).unwrap());
        let gap = projection_gap(&model, &tag);
        assert!(gap < 1e-6, "{stem}: RPB and TIFF tag differ by {gap} px");
        // Through `_RPC.TXT` and DIMAP and back.
        let dir = tempfile::tempdir().unwrap();
        let txt = write(dir.path(), &format!("{stem}_RPC.TXT"), &model.to_rpc_txt());
        assert_eq!(read_camera_file(&txt).unwrap(), model);
        let xml = write(dir.path(), "RPC_X.XML", &dimap_text(&model, None));
        let gap = projection_gap(&model, &read_camera_file(&xml).unwrap());
        assert!(gap < 1e-6, "{stem}: DIMAP differs by {gap} px");
    }
}

#[test]
fn vendor_delivery_is_found_beside_the_image() {
    testdata::require!(JAX_DEV);
    let tif = jax_dev("vendor/JAX_068_006_RGB.TIF");
    let rpb = jax_dev("vendor/JAX_068_006_RGB.RPB");
    assert_eq!(find_camera_file(&tif), Some(rpb.clone()));
    assert_eq!(
        find_metadata_file(&tif),
        Some(jax_dev("vendor/JAX_068_006_RGB.IMD"))
    );
    let (model, from) = camera_beside(&tif).unwrap().unwrap();
    assert_eq!(from, rpb);
    assert_eq!(model, read_rpb(&rpb).unwrap());
    let acq = metadata_of(&tif).unwrap().unwrap();
    assert_eq!(acq.datetime.as_deref(), Some("20141214160402"));
    assert_eq!(
        (acq.sun_elevation, acq.sun_azimuth),
        (Some(33.5), Some(158.6))
    );
    assert_eq!(
        (acq.satellite_elevation, acq.satellite_azimuth),
        (None, None)
    );
    assert_eq!(acq.source, jax_dev("vendor/JAX_068_006_RGB.IMD"));
}

#[test]
fn dates_and_sun_of_every_dev_image_match_the_json() {
    testdata::require!(JAX_DEV);
    for entry in fs::read_dir(jax_dev("images")).unwrap() {
        let tif = entry.unwrap().path();
        let stem = tif.file_stem().unwrap().to_str().unwrap().to_string();
        let json: serde_json::Value = serde_json::from_str(
            &fs::read_to_string(jax_dev(&format!("rpcs/original/{stem}.json"))).unwrap(),
        )
        .unwrap();
        let date = json["acquisition_date"].as_str().unwrap();
        // The GeoTIFF: its GDAL metadata's NITF_IDATIM, and its own RPC tag as camera.
        let acq = metadata_of(&tif).unwrap().unwrap();
        assert_eq!(acq.datetime.as_deref(), Some(date), "{stem}");
        assert_eq!(acq.source, tif);
        let (_, from) = camera_beside(&tif).unwrap().unwrap();
        assert_eq!(from, tif);
        // The vendor delivery, where there is one: the IMD.
        let imd = jax_dev(&format!("vendor/{stem}.IMD"));
        if imd.is_file() {
            let a = read_imd(&imd).unwrap();
            assert_eq!(a.datetime.as_deref(), Some(date), "{stem}");
            let sun = |k: &str| json[k].as_str().unwrap().parse::<f64>().unwrap();
            assert_eq!(a.sun_elevation, Some(sun("sun_elevation")), "{stem}");
            assert_eq!(a.sun_azimuth, Some(sun("sun_azimuth")), "{stem}");
        }
    }
}

#[test]
fn rpc_txt_round_trip_and_gdal_text() {
    let dir = tempfile::tempdir().unwrap();
    let m = synthetic();
    let p = write(dir.path(), "a_RPC.TXT", &m.to_rpc_txt());
    assert_eq!(read_camera_file(&p).unwrap(), m);
    assert_eq!(camera::vendor::read_rpc_txt(&p).unwrap(), m);
    // GDAL's layout: signs, zero padding, units, error terms, lower-case keys.
    let mut text = String::from("ERR_BIAS: -1.00\nERR_RAND: -1.00\n");
    for line in m.to_rpc_txt().lines() {
        let (k, v) = line.split_once(": ").unwrap();
        let k = if k.starts_with("LAT_OFF") {
            "lat_off"
        } else {
            k
        };
        let v = if k == "lat_off" {
            "+030.3003 degrees".to_string()
        } else {
            v.to_string()
        };
        let _ = writeln!(text, "{k}:   {v}");
    }
    let p = write(dir.path(), "b_rpc.txt", &text);
    assert_eq!(read_camera_file(&p).unwrap(), m);
}

#[test]
fn dimap_round_trip_is_one_based() {
    let dir = tempfile::tempdir().unwrap();
    let m = synthetic();
    let p = write(dir.path(), "RPC_A.XML", &dimap_text(&m, None));
    let d = read_camera_file(&p).unwrap();
    assert_eq!(d, camera::vendor::read_dimap_rpc(&p).unwrap());
    // The file says LINE_OFF = row_offset + 1: the model is back on 0-based pixels.
    assert!(
        (d.row_offset - m.row_offset).abs() < 1e-9,
        "{}",
        d.row_offset
    );
    assert!(
        (d.col_offset - m.col_offset).abs() < 1e-9,
        "{}",
        d.col_offset
    );
    assert_eq!(
        (d.row_num, d.row_den, d.col_num, d.col_den),
        (m.row_num, m.row_den, m.col_num, m.col_den)
    );
    assert_eq!(
        (
            d.lat_offset,
            d.lon_offset,
            d.alt_offset,
            d.lat_scale,
            d.lon_scale,
            d.alt_scale
        ),
        (
            m.lat_offset,
            m.lon_offset,
            m.alt_offset,
            m.lat_scale,
            m.lon_scale,
            m.alt_scale
        )
    );
    assert!(projection_gap(&m, &d) < 1e-6);
    // DIMAP v3 saying its first pixel is 0.
    let p = write(dir.path(), "RPC_B.XML", &dimap_text(&m, Some(0.0)));
    let d = read_camera_file(&p).unwrap();
    assert_eq!((d.row_offset, d.col_offset), (m.row_offset, m.col_offset));
}

#[test]
fn dimap_files_are_found_and_read() {
    let dir = tempfile::tempdir().unwrap();
    let m = synthetic();
    let img = write(dir.path(), "IMG_PHR1A_P_001_R1C1.JP2", "not an image");
    assert_eq!(find_camera_file(&img), None);
    assert_eq!(metadata_of(&img).unwrap(), None);
    assert_eq!(camera_beside(&img).unwrap(), None);
    let rpc = write(dir.path(), "RPC_PHR1A_P_001.XML", &dimap_text(&m, None));
    let dim = write(dir.path(), "DIM_PHR1A_P_001.XML", DIM_XML);
    assert_eq!(find_camera_file(&img), Some(rpc.clone()));
    assert_eq!(find_metadata_file(&img), Some(dim.clone()));
    let (model, from) = camera_beside(&img).unwrap().unwrap();
    assert_eq!(from, rpc);
    assert!(projection_gap(&m, &model) < 1e-6);
    let acq = metadata_of(&img).unwrap().unwrap();
    assert_eq!(acq.datetime.as_deref(), Some("20130101101112"));
    assert_eq!(
        (acq.sun_elevation, acq.sun_azimuth),
        (Some(21.5), Some(151.25))
    );
    assert_eq!(acq.source, dim);
    // The tile's own name is preferred to the product's.
    let tile = write(
        dir.path(),
        "RPC_PHR1A_P_001_R1C1.XML",
        &dimap_text(&m, None),
    );
    assert_eq!(find_camera_file(&img), Some(tile));
    // No strip date: the centre's TIME.
    let no_strip = DIM_XML.replace("<IMAGING_DATE>2013-01-01</IMAGING_DATE>", "");
    let p = write(dir.path(), "DIM_B.XML", &no_strip);
    assert_eq!(
        read_metadata_file(&p).unwrap().datetime.as_deref(),
        Some("20130101101112")
    );
    // No date at all: no error.
    let undated = no_strip.replace("<TIME>2013-01-01T10:11:12.5Z</TIME>", "");
    let undated = undated.replace("<TIME>2013-01-01T10:11:11.9Z</TIME>", "");
    let p = write(dir.path(), "DIM_C.XML", &undated);
    let acq = read_metadata_file(&p).unwrap();
    assert_eq!(acq.datetime, None);
    assert_eq!(acq.sun_elevation, Some(21.5));
}

#[test]
fn rpb_sidecars_and_imd_without_the_data_set() {
    let dir = tempfile::tempdir().unwrap();
    let m = synthetic();
    let img = write(dir.path(), "scene.NTF", "");
    write(dir.path(), "scene.RPB", &rpb_text(&m));
    write(dir.path(), "scene.IMD", IMD);
    let (model, _) = camera_beside(&img).unwrap().unwrap();
    assert_eq!(model, m);
    let acq = metadata_of(&img).unwrap().unwrap();
    assert_eq!(acq.datetime.as_deref(), Some("20141214160402"));
    assert_eq!(
        (
            acq.sun_elevation,
            acq.sun_azimuth,
            acq.satellite_elevation,
            acq.satellite_azimuth
        ),
        (Some(33.5), Some(158.6), Some(71.0), Some(201.2))
    );
    // An IMD without a date: Ok, no date.
    let p = write(
        dir.path(),
        "undated.IMD",
        &IMD.replace("firstLineTime", "lastLineTime"),
    );
    let acq = read_imd(&p).unwrap();
    assert_eq!(acq.datetime, None);
    assert_eq!(acq.sun_elevation, Some(33.5));
    // Lower-case sidecars.
    let img = write(dir.path(), "other.tif", "");
    write(dir.path(), "other.rpb", &rpb_text(&m));
    write(dir.path(), "other.imd", IMD);
    assert_eq!(find_camera_file(&img), Some(dir.path().join("other.rpb")));
    assert_eq!(find_metadata_file(&img), Some(dir.path().join("other.imd")));
    // No sidecar, not a TIFF: nothing, no error.
    let img = write(dir.path(), "lonely.tif", "");
    assert_eq!(camera_beside(&img).unwrap(), None);
    assert_eq!(metadata_of(&img).unwrap(), None);
}

#[test]
fn malformed_cameras_are_errors_naming_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let m = synthetic();
    let rpb = rpb_text(&m);
    camera_error(d, "empty.RPB", "", "");
    camera_error(
        d,
        "missing.RPB",
        &rpb.replace("\tlatScale = 0.0703;\n", ""),
        "latScale",
    );
    camera_error(
        d,
        "nan.RPB",
        &rpb.replace("latScale = 0.0703", "latScale = nan"),
        "latScale",
    );
    camera_error(
        d,
        "word.RPB",
        &rpb.replace("latScale = 0.0703", "latScale = abc"),
        "latScale",
    );
    camera_error(
        d,
        "zero.RPB",
        &rpb.replace("lineScale = 22758", "lineScale = 0"),
        "lineScale",
    );
    let short = rpb.replacen("\t\t\t1,\n", "", 1);
    let msg = camera_error(d, "short.RPB", &short, "lineDenCoef");
    assert!(msg.contains("expected 20 coefficients, got 19"), "{msg}");
    let open = rpb.replacen(");\n\tlineDenCoef", ";\n\tlineDenCoef", 1);
    camera_error(d, "open.RPB", &open, "lineNumCoef");

    let txt = m.to_rpc_txt();
    camera_error(
        d,
        "missing_RPC.TXT",
        &txt.replace("SAMP_DEN_COEFF_7:", "X:"),
        "SAMP_DEN_COEFF_7",
    );
    camera_error(
        d,
        "extra_RPC.TXT",
        &format!("{txt}LINE_NUM_COEFF_21: 1\n"),
        "LINE_NUM_COEFF_21",
    );
    camera_error(
        d,
        "bad_RPC.TXT",
        &txt.replace("HEIGHT_OFF: -21", "HEIGHT_OFF: inf"),
        "HEIGHT_OFF",
    );

    let xml = dimap_text(&m, None);
    camera_error(
        d,
        "RPC_missing.XML",
        &xml.replace("<LAT_OFF>", "<LAT_OFFX>")
            .replace("</LAT_OFF>", "</LAT_OFFX>"),
        "LAT_OFF",
    );
    let cut = xml
        .replace("<LINE_DEN_COEFF_20>", "<X>")
        .replace("</LINE_DEN_COEFF_20>", "</X>");
    camera_error(d, "RPC_short.XML", &cut, "LINE_DEN_COEFF_20");
    camera_error(
        d,
        "RPC_other.XML",
        "<Dimap_Document><A>1</A></Dimap_Document>",
        "Global_RFM",
    );
    camera_error(
        d,
        "RPC_bad.XML",
        &xml.replace("<LAT_OFF>30.3003", "<LAT_OFF>north"),
        "LAT_OFF",
    );
    camera_error(d, "what.dat", "hello", "");
    camera_error(d, "notes.TXT", "LINE_OFF: 1\n", "LINE_SCALE");
}

/// Every prefix of a good file, and the file with bytes flipped, read without a panic; a prefix
/// cut before its last coefficient is an error.
#[test]
fn truncated_and_garbled_files_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let m = synthetic();
    let cases: [(&str, String, &str); 4] = [
        ("t.RPB", rpb_text(&m), "sampDenCoef"),
        ("t_RPC.TXT", m.to_rpc_txt(), "SAMP_DEN_COEFF_20"),
        ("RPC_t.XML", dimap_text(&m, None), "</Dimap_Document>"),
        ("t.IMD", IMD.to_string(), ""),
    ];
    for (name, text, last) in cases {
        let bytes = text.as_bytes();
        let needed = text.rfind(last).unwrap();
        for n in (0..bytes.len()).step_by(5) {
            let p = dir.path().join(name);
            fs::write(&p, &bytes[..n]).unwrap();
            let r = if name.ends_with(".IMD") {
                read_metadata_file(&p).map(|_| ())
            } else {
                read_camera_file(&p).map(|_| ())
            };
            if n < needed && !last.is_empty() {
                assert!(r.is_err(), "{name} cut at {n} read");
            }
            let mut garbled = bytes.to_vec();
            garbled[n] = [b'(', b'<', b';', 0xff, b'='][n % 5];
            fs::write(&p, &garbled).unwrap();
            let _ = read_camera_file(&p);
            let _ = read_metadata_file(&p);
        }
    }
}

#[test]
fn malformed_metadata_is_an_error_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    for (name, text, key) in [
        (
            "a.IMD",
            IMD.replace("meanSunEl = 33.5", "meanSunEl = high"),
            "meanSunEl",
        ),
        (
            "b.IMD",
            IMD.replace("2014-12-14T16:04:02", "2014-14-14T16:04:02"),
            "firstLineTime",
        ),
        (
            "DIM_a.XML",
            DIM_XML.replace("2013-01-01<", "yesterday<"),
            "IMAGING_DATE",
        ),
        (
            "DIM_b.XML",
            DIM_XML.replace(">21.5<", ">NaN<"),
            "SUN_ELEVATION",
        ),
        ("DIM_c.XML", DIM_XML.replace("</Dimap_Document>", ""), ""),
    ] {
        let p = write(dir.path(), name, &text);
        let err = read_metadata_file(&p).expect_err(name);
        let msg = err.to_string();
        assert!(matches!(err, CameraError::Metadata { .. }), "{msg}");
        assert!(msg.contains(name) && msg.contains(key), "{msg}");
    }
    // An empty IMD is a file without a date.
    let p = write(dir.path(), "empty.IMD", "");
    assert_eq!(read_metadata_file(&p).unwrap().datetime, None);
}
