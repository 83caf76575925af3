//! RPC models read from the anchors' SatNeRF JSON and GeoTIFF tags: projection against reference
//! numbers, localisation round trips, malformed inputs.

mod support;

use camera::{CameraError, RpcModel};
use support::{rpcm, s2p, JAX_JSON, RPCM, S2P, S2P_IMG1, S2P_IMG2};

/// Largest |projection(localization(x, alt), alt) − x| over a grid of image points and
/// altitudes, in pixels.
fn round_trip_error(rpc: &RpcModel, width: f64, height: f64, alts: &[f64]) -> f64 {
    let mut worst: f64 = 0.0;
    for i in 0..=8 {
        for j in 0..=8 {
            let (col, row) = (width * i as f64 / 8.0, height * j as f64 / 8.0);
            for &alt in alts {
                let (lon, lat) = rpc.localization(col, row, alt).unwrap();
                let (c, r) = rpc.projection(lon, lat, alt);
                worst = worst.max((c - col).abs()).max((r - row).abs());
                // The warm start converges to the same point from a start 20 pixels away.
                let (lon2, lat2) = rpc
                    .localization_from(col, row, alt, lon + 1e-4, lat - 1e-4)
                    .unwrap();
                assert!(
                    (lon2 - lon).abs() < 1e-9 && (lat2 - lat).abs() < 1e-9,
                    "warm start moved ({col}, {row}, {alt}) by {} / {} deg",
                    lon2 - lon,
                    lat2 - lat
                );
            }
        }
    }
    worst
}

#[test]
fn satnerf_json_projection_matches_reference() {
    testdata::require!(RPCM);
    let rpc = RpcModel::read_rpcm_json(rpcm(JAX_JSON)).unwrap();
    assert_eq!((rpc.min_alt, rpc.max_alt), (Some(-27.0), Some(30.0)));
    assert_eq!(rpc.altitude_range(), (-522.0, 480.0));
    // Reference values: rpcm's `apply_poly`/`apply_rfm` formulas evaluated with numpy in float64
    // on the same JSON (rpcm's own package needs rasterio, which is not installed here).
    for &(lon, lat, alt, col, row) in &[
        (-81.6630, 30.3490, 5.0, 427.302565661, 621.148659939),
        (-81.6650, 30.3470, -20.0, -190.293136775, 73.378690702),
    ] {
        let (c, r) = rpc.projection(lon, lat, alt);
        assert!((c - col).abs() < 1e-6 && (r - row).abs() < 1e-6, "{c} {r}");
    }
}

#[test]
fn satnerf_json_round_trip() {
    testdata::require!(RPCM);
    let rpc = RpcModel::read_rpcm_json(rpcm(JAX_JSON)).unwrap();
    let err = round_trip_error(&rpc, 746.0, 815.0, &[-27.0, 0.0, 30.0, 100.0]);
    println!("JAX_068_001 round trip: max error {err:.3e} px");
    assert!(err < 1e-3, "{err}");
}

#[test]
fn geotiff_tag_projection_matches_reference() {
    testdata::require!(S2P);
    // Reference values: RPC00B formulas in numpy on the tag read with PIL.
    let cases = [
        (
            S2P_IMG1,
            55.6511624439,
            -21.2336041273,
            100.0,
            512.000007872,
            511.999995774,
        ),
        (
            S2P_IMG1,
            55.65,
            -21.23,
            250.0,
            285.340828533,
            -231.435966182,
        ),
        (
            S2P_IMG2,
            55.6511624439,
            -21.2336041273,
            100.0,
            274.923543606,
            1687.549345181,
        ),
        (S2P_IMG2, 55.65, -21.23, 250.0, 65.152715939, 858.378533706),
    ];
    for (file, lon, lat, alt, col, row) in cases {
        let rpc = RpcModel::read_geotiff_rpc(s2p(file)).unwrap();
        let (c, r) = rpc.projection(lon, lat, alt);
        assert!(
            (c - col).abs() < 1e-6 && (r - row).abs() < 1e-6,
            "{file}: {c} {r}"
        );
    }
}

#[test]
fn geotiff_tag_round_trip() {
    testdata::require!(S2P);
    for (file, w, h) in [(S2P_IMG1, 1024.0, 1024.0), (S2P_IMG2, 1031.0, 1102.0)] {
        let rpc = RpcModel::read_geotiff_rpc(s2p(file)).unwrap();
        let err = round_trip_error(&rpc, w, h, &[0.0, 150.0, 400.0, 900.0]);
        println!("{file} round trip: max error {err:.3e} px");
        assert!(err < 1e-3, "{file}: {err}");
    }
}

#[test]
fn bare_rpc_dict_is_accepted() {
    testdata::require!(RPCM);
    let text = std::fs::read_to_string(rpcm(JAX_JSON)).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let full = RpcModel::from_rpcm_json(&v).unwrap();
    let bare = RpcModel::from_rpcm_json(&v["rpc"]).unwrap();
    assert_eq!(bare.min_alt, None);
    assert_eq!(
        full.projection(-81.664, 30.348, 3.0),
        bare.projection(-81.664, 30.348, 3.0)
    );
}

fn rpc_error(v: &serde_json::Value) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.json");
    std::fs::write(&path, serde_json::to_string(v).unwrap()).unwrap();
    let err = RpcModel::read_rpcm_json(&path).unwrap_err();
    assert!(matches!(err, CameraError::Rpc { .. }), "{err}");
    let msg = err.to_string();
    assert!(msg.contains("bad.json"), "{msg}");
    msg
}

#[test]
fn malformed_json_names_file_and_key() {
    testdata::require!(RPCM);
    let text = std::fs::read_to_string(rpcm(JAX_JSON)).unwrap();
    let good: serde_json::Value = serde_json::from_str(&text).unwrap();

    let mut v = good.clone();
    v["rpc"].as_object_mut().unwrap().remove("lat_scale");
    let msg = rpc_error(&v);
    assert!(
        msg.contains("lat_scale") && msg.contains("missing"),
        "{msg}"
    );

    let mut v = good.clone();
    v["rpc"]["col_den"].as_array_mut().unwrap().pop();
    let msg = rpc_error(&v);
    assert!(msg.contains("col_den") && msg.contains("19"), "{msg}");

    let mut v = good.clone();
    v["rpc"]["row_scale"] = serde_json::json!(0.0);
    assert!(rpc_error(&v).contains("row_scale"));

    let mut v = good.clone();
    v["rpc"]["alt_offset"] = serde_json::json!("high");
    assert!(rpc_error(&v).contains("alt_offset"));

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.json");
    std::fs::write(&path, "{\"rpc\": ").unwrap();
    let msg = RpcModel::read_rpcm_json(&path).unwrap_err().to_string();
    assert!(msg.contains("broken.json"), "{msg}");
}

#[test]
fn tiff_without_rpc_is_an_error() {
    testdata::require!(S2P);
    let msg = RpcModel::read_geotiff_rpc(s2p("tests/data/expected_output/pair/dsm.tif"))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("dsm.tif") && msg.contains("RPC"), "{msg}");
}
