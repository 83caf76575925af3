//! UTM against pyproj, both directions, both hemispheres, inside and at the edge of zones.

use camera::UtmZone;

/// (EPSG, lon, lat, easting, northing). Produced with pyproj 3.7.2 (PROJ's exact transverse
/// Mercator):
/// `Transformer.from_crs(4326, epsg, always_xy=True).transform(lon, lat)`, printed to 1e-6 m.
const REFERENCE: &[(u32, f64, f64, f64, f64)] = &[
    (32617, -81.66, 30.35, 436568.395077, 3357753.826764), // Jacksonville
    (32617, -83.97, 30.35, 214497.865926, 3361310.248858), // zone 17 west edge
    (32740, 55.71, -21.23, 366129.888877, 7651851.509572), // Réunion
    (32740, 54.02, -21.9, 192085.806427, 7575253.040644),  // zone 40 west edge
    (32721, -58.59, -34.49, 354008.634497, 6182364.377651), // Buenos Aires
    (32721, -60.01, -34.9, 224954.746125, 6133910.647261), // just outside zone 21
    (32615, -95.9, 41.2, 256830.370987, 4565014.753848),   // Omaha
    (32615, -92.05, 41.3, 579533.568622, 4572495.976648),  // zone 15, east
];

#[test]
fn forward_matches_pyproj_to_ten_micrometres() {
    for &(epsg, lon, lat, e, n) in REFERENCE {
        let zone = UtmZone::from_epsg(epsg).unwrap();
        let (ee, nn) = zone.forward(lon, lat);
        assert!(
            (ee - e).abs() < 1e-5 && (nn - n).abs() < 1e-5,
            "EPSG:{epsg} ({lon}, {lat}): ({ee:.6}, {nn:.6}) vs ({e}, {n})"
        );
    }
}

#[test]
fn inverse_matches_pyproj_to_ten_micrometres() {
    for &(epsg, lon, lat, e, n) in REFERENCE {
        let zone = UtmZone::from_epsg(epsg).unwrap();
        let (lo, la) = zone.inverse(e, n);
        // 1e-10 degree is about 10 µm (the references are printed to 1e-6 m).
        assert!(
            (lo - lon).abs() < 1e-10 && (la - lat).abs() < 1e-10,
            "EPSG:{epsg} ({e}, {n}): ({lo}, {la}) vs ({lon}, {lat})"
        );
    }
}

#[test]
fn zone_from_lonlat_matches_epsg() {
    assert_eq!(UtmZone::from_lonlat(-81.66, 30.35).epsg(), 32617);
    assert_eq!(UtmZone::from_lonlat(55.71, -21.23).epsg(), 32740);
    assert_eq!(UtmZone::from_lonlat(-58.59, -34.49).epsg(), 32721);
    assert_eq!(UtmZone::from_lonlat(-95.9, 41.2).epsg(), 32615);
    assert_eq!(UtmZone::from_lonlat(180.0, 1.0).epsg(), 32601);
    assert!(UtmZone::from_epsg(32661).is_err() && UtmZone::from_epsg(32700).is_err());
}
