//! File formats: exact round trips, files written by other tools, corrupt inputs and the real
//! s2p test data (read in place where it is present, see `testdata`).

use std::io::Write;
use std::path::{Path, PathBuf};

use raster::formats::{
    read_homographies, read_image, read_npy, read_pfm, read_png, read_tiff, write_atomically,
    write_geotiff, write_homographies, write_image, write_npy, write_pfm, write_png, GeoReference,
    GeoTiffMeta, PngDepth, RpcTag, TiffReader,
};
use raster::{colormap, Homography, Image, Result};

fn tmp() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

/// Bitwise equality, so NaN positions count.
fn assert_same(a: &Image, b: &Image) {
    assert_eq!(
        (a.width(), a.height(), a.channels()),
        (b.width(), b.height(), b.channels())
    );
    for (i, (x, y)) in a.data().iter().zip(b.data()).enumerate() {
        assert!(
            x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
            "sample {i}: {x} vs {y}"
        );
    }
}

/// A test image with negative, fractional, huge and NaN samples.
fn sample_image(w: usize, h: usize, c: usize) -> Image {
    let data = (0..w * h * c)
        .map(|i| match i % 7 {
            0 => f32::NAN,
            1 => -(i as f32) / 3.0,
            2 => 1e30,
            _ => i as f32 * 0.125,
        })
        .collect();
    Image::new(w, h, c, data).unwrap()
}

// ---------------------------------------------------------------- NPY

fn npy_bytes(descr: &str, fortran: bool, shape: &str, data: &[u8]) -> Vec<u8> {
    let order = if fortran { "True" } else { "False" };
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape}, }}");
    while (dict.len() + 11) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.extend_from_slice(data);
    out
}

#[test]
fn npy_round_trip_1_and_3_channels() {
    let dir = tmp();
    for c in [1, 3] {
        let img = sample_image(5, 4, c);
        let p = dir.path().join(format!("x{c}.iio"));
        write_npy(&p, &img).unwrap();
        assert_same(&read_npy(&p).unwrap(), &img);
        // The release layout: float32 little endian, shape (H, W, C) even for C = 1.
        let bytes = std::fs::read(&p).unwrap();
        let header = String::from_utf8_lossy(&bytes[10..128]);
        assert!(
            header.contains("'<f4'") && header.contains(&format!("(4, 5, {c})")),
            "{header}"
        );
        assert_eq!(bytes.len(), 128 + 5 * 4 * c * 4);
    }
}

#[test]
fn npy_fortran_order_float64_is_transposed() {
    // numpy: np.save(f, np.asfortranarray(np.arange(6.).reshape(2, 3)))
    let f: Vec<u8> = [0.0f64, 3.0, 1.0, 4.0, 2.0, 5.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let dir = tmp();
    let p = dir.path().join("f.npy");
    std::fs::write(&p, npy_bytes("<f8", true, "(2, 3)", &f)).unwrap();
    let img = read_npy(&p).unwrap();
    assert_eq!((img.width(), img.height(), img.channels()), (3, 2, 1));
    assert_eq!(img.data(), &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);

    // (H, W, C) = (2, 2, 2) Fortran: element (i, j, k) at i + 2j + 4k.
    let f: Vec<u8> = (0..8)
        .map(|n| (n % 2) * 100 + ((n / 2) % 2) * 10 + n / 4)
        .flat_map(|v: i32| (v as f32).to_le_bytes())
        .collect();
    std::fs::write(&p, npy_bytes("<f4", true, "(2, 2, 2)", &f)).unwrap();
    let img = read_npy(&p).unwrap();
    for (x, y, c) in [(0, 0, 0), (1, 0, 1), (0, 1, 0), (1, 1, 1), (1, 0, 0)] {
        assert_eq!(img.get(x, y, c), (y * 100 + x * 10 + c) as f32);
    }
}

#[test]
fn npy_integer_and_big_endian_dtypes() {
    let dir = tmp();
    let p = dir.path().join("i.npy");
    let cases: Vec<(&str, Vec<u8>, Vec<f32>)> = vec![
        ("|u1", vec![0, 7, 255, 1], vec![0., 7., 255., 1.]),
        (
            ">i2",
            [-2i16, 300, -32768, 5]
                .iter()
                .flat_map(|v| v.to_be_bytes())
                .collect(),
            vec![-2., 300., -32768., 5.],
        ),
        (
            "<u2",
            [65535u16, 1, 2, 3]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
            vec![65535., 1., 2., 3.],
        ),
        (
            "<i4",
            [-100000i32, 0, 1, 2]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
            vec![-100000., 0., 1., 2.],
        ),
        (
            ">f4",
            [1.5f32, -0.25, 3.0, 4.0]
                .iter()
                .flat_map(|v| v.to_be_bytes())
                .collect(),
            vec![1.5, -0.25, 3.0, 4.0],
        ),
        (
            ">f8",
            [1.5f64, -0.25, 3.0, 4.0]
                .iter()
                .flat_map(|v| v.to_be_bytes())
                .collect(),
            vec![1.5, -0.25, 3.0, 4.0],
        ),
    ];
    for (descr, bytes, want) in cases {
        std::fs::write(&p, npy_bytes(descr, false, "(2, 2)", &bytes)).unwrap();
        let img = read_npy(&p).unwrap_or_else(|e| panic!("{descr}: {e}"));
        assert_eq!(img.data(), &want[..], "{descr}");
    }
}

#[test]
fn npy_rejects_unsupported_shapes_and_dtypes() {
    let dir = tmp();
    let p = dir.path().join("bad.npy");
    for (descr, shape, n) in [
        ("<f4", "(4,)", 4),
        ("<f4", "(1, 2, 2, 1)", 4),
        ("<c8", "(2, 2)", 8),
    ] {
        std::fs::write(&p, npy_bytes(descr, false, shape, &vec![0u8; n * 4])).unwrap();
        let e = read_npy(&p).unwrap_err().to_string();
        assert!(e.contains("bad.npy"), "{e}");
        assert!(
            e.contains(descr) || e.contains(&shape.replace(['(', ')'], "")[..1]),
            "{e}"
        );
    }
}

// ---------------------------------------------------------------- NPZ

fn sample_homographies() -> (Homography, Homography) {
    (
        Homography([
            [1.01, 0.02, -30.5],
            [-0.003, 0.98, 12.25],
            [1e-6, -2e-7, 1.0],
        ]),
        Homography([[0.99, -0.01, 3.0], [0.004, 1.02, -7.5], [-3e-6, 4e-7, 1.0]]),
    )
}

#[test]
fn npz_round_trip() {
    let dir = tmp();
    let p = dir.path().join("deep/er/H.npz");
    let (l, r) = sample_homographies();
    write_homographies(&p, &l, &r).unwrap();
    assert_eq!(read_homographies(&p).unwrap(), (l, r));
    // Member names and storage as np.savez writes them.
    let mut zip = zip::ZipArchive::new(std::fs::File::open(&p).unwrap()).unwrap();
    let mut names: Vec<String> = zip.file_names().map(String::from).collect();
    names.sort();
    assert_eq!(names, ["Hleft.npy", "Hright.npy"]);
    assert_eq!(
        zip.by_name("Hleft.npy").unwrap().compression(),
        zip::CompressionMethod::Stored
    );
}

/// An NPZ written member by member with the zip crate, as another tool would.
fn write_npz(path: &Path, members: &[(&str, Vec<u8>)], method: zip::CompressionMethod) {
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    let options = zip::write::SimpleFileOptions::default().compression_method(method);
    for (name, bytes) in members {
        zip.start_file(*name, options).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap();
}

fn h_npy_f32(h: &Homography) -> Vec<u8> {
    let data: Vec<u8> =
        h.0.iter()
            .flatten()
            .flat_map(|v| (*v as f32).to_le_bytes())
            .collect();
    npy_bytes("<f4", false, "(3, 3)", &data)
}

fn h_npy_f64(h: &Homography) -> Vec<u8> {
    let data: Vec<u8> = h.0.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    npy_bytes("<f8", false, "(3, 3)", &data)
}

#[test]
fn npz_from_other_writers_float32_and_compressed() {
    let dir = tmp();
    let p = dir.path().join("H.npz");
    let (l, r) = sample_homographies();
    write_npz(
        &p,
        &[("Hright.npy", h_npy_f64(&r)), ("Hleft.npy", h_npy_f32(&l))],
        zip::CompressionMethod::Deflated,
    );
    let (gl, gr) = read_homographies(&p).unwrap();
    assert_eq!(gr, r);
    for (a, b) in gl.0.iter().flatten().zip(l.0.iter().flatten()) {
        assert_eq!(*a, *b as f32 as f64);
    }
}

#[test]
fn npz_errors_name_file_and_keys() {
    let dir = tmp();
    let p = dir.path().join("only_left.npz");
    let (l, _) = sample_homographies();
    write_npz(
        &p,
        &[("Hleft.npy", h_npy_f64(&l)), ("disp.npy", h_npy_f64(&l))],
        zip::CompressionMethod::Stored,
    );
    let e = read_homographies(&p).unwrap_err().to_string();
    assert!(
        e.contains("only_left.npz") && e.contains("Hright") && e.contains("disp"),
        "{e}"
    );

    let p = dir.path().join("nan.npz");
    let bad = Homography([[f64::NAN, 0., 0.], [0., 1., 0.], [0., 0., 1.]]);
    write_npz(
        &p,
        &[
            ("Hleft.npy", h_npy_f64(&l)),
            ("Hright.npy", h_npy_f64(&bad)),
        ],
        zip::CompressionMethod::Stored,
    );
    let e = read_homographies(&p).unwrap_err().to_string();
    assert!(e.contains("nan.npz") && e.contains("non-finite"), "{e}");

    let p = dir.path().join("shape.npz");
    write_npz(
        &p,
        &[
            ("Hleft.npy", h_npy_f64(&l)),
            ("Hright.npy", npy_bytes("<f8", false, "(2, 3)", &[0u8; 48])),
        ],
        zip::CompressionMethod::Stored,
    );
    let e = read_homographies(&p).unwrap_err().to_string();
    assert!(e.contains("shape.npz") && e.contains("[2, 3]"), "{e}");
}

// ---------------------------------------------------------------- TIFF

fn utm_meta() -> GeoTiffMeta {
    GeoTiffMeta {
        georef: Some(GeoReference::from_origin_utm(
            355_000.25,
            7_660_100.5,
            0.5,
            32740,
        )),
        nodata: Some(f64::NAN),
        rpc: None,
        gdal_metadata: None,
    }
}

#[test]
fn geotiff_round_trip_1_and_3_bands() {
    let dir = tmp();
    for c in [1, 3] {
        let img = sample_image(37, 23, c);
        let p = dir.path().join(format!("g{c}.tif"));
        let meta = utm_meta();
        write_geotiff(&p, &img, &meta).unwrap();
        let back = read_tiff(&p).unwrap();
        assert_same(&back.image, &img);
        let g = back.georef.unwrap();
        assert_eq!(
            g.geotransform,
            [355_000.25, 0.5, 0.0, 7_660_100.5, 0.0, -0.5]
        );
        assert_eq!(g.epsg, Some(32740));
        assert!(back.nodata.unwrap().is_nan());
        assert!(back.rpc.is_none());
    }
}

#[test]
fn geotiff_keeps_rpc_rotation_geographic_and_numeric_nodata() {
    let dir = tmp();
    let p = dir.path().join("rot.tiff");
    let coeffs: Vec<f64> = (0..92).map(|i| i as f64 * 0.5 - 3.0).collect();
    let mut georef = GeoReference::from_origin_utm(55.1, -21.0, 1e-5, 4326);
    georef.geotransform[2] = 2e-6;
    let meta = GeoTiffMeta {
        georef: Some(georef.clone()),
        nodata: Some(-9999.0),
        rpc: Some(RpcTag::from_coefficients(&coeffs).unwrap()),
        gdal_metadata: None,
    };
    let img = Image::from_fn(9, 4, |x, y| (x * 10 + y) as f32);
    write_geotiff(&p, &img, &meta).unwrap();
    let back = read_tiff(&p).unwrap();
    assert_same(&back.image, &img);
    assert_eq!(back.nodata, Some(-9999.0));
    assert_eq!(back.rpc.unwrap().to_coefficients(), coeffs);
    let g = back.georef.unwrap();
    assert_eq!(g.geotransform, georef.geotransform);
    assert_eq!(g.epsg, Some(4326));
    // Geographic model type in the minimal key directory.
    assert_eq!(g.geo_keys.clone().unwrap()[4..8], [1024, 0, 1, 2]);
    // Written again from what was read (raw keys path): unchanged.
    let p2 = dir.path().join("again.tif");
    write_geotiff(
        &p2,
        &back.image,
        &GeoTiffMeta {
            georef: Some(g.clone()),
            ..meta
        },
    )
    .unwrap();
    assert_eq!(read_tiff(&p2).unwrap().georef.unwrap(), g);
}

#[test]
fn geotiff_pixel_is_point_is_shifted_like_gdal() {
    let dir = tmp();
    let p = dir.path().join("point.tif");
    let georef = GeoReference {
        geotransform: [100.0, 2.0, 0.0, 500.0, 0.0, -2.0],
        epsg: Some(32631),
        geo_keys: Some(vec![
            1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 2, 3072, 0, 1, 32631,
        ]),
        geo_doubles: None,
        geo_ascii: None,
    };
    write_geotiff(
        &p,
        &Image::filled(3, 3, 1, 1.0),
        &GeoTiffMeta {
            georef: Some(georef.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    // The file stores the centre of pixel (0, 0): (101, 499); reading reports the corner again.
    let back = read_tiff(&p).unwrap().georef.unwrap();
    assert_eq!(back.geotransform, georef.geotransform);
    assert_eq!(back.epsg, Some(32631));
}

/// TIFFs written by the tiff crate's own encoder (other sample types, LZW, PackBits).
#[test]
fn tiff_integer_samples_lzw_and_packbits() {
    use tiff::encoder::{colortype, Compression, TiffEncoder};
    let dir = tmp();
    let p = dir.path().join("u16.tif");
    let (w, h) = (50u32, 31u32);
    let u16s: Vec<u16> = (0..w * h).map(|i| (i * 37 % 65536) as u16).collect();
    let f = std::fs::File::create(&p).unwrap();
    TiffEncoder::new(f)
        .unwrap()
        .with_compression(Compression::Lzw)
        .write_image::<colortype::Gray16>(w, h, &u16s)
        .unwrap();
    let img = read_tiff(&p).unwrap().image;
    assert_eq!(img.size(), (50, 31));
    assert!(img.data().iter().zip(&u16s).all(|(a, b)| *a == *b as f32));

    let p = dir.path().join("i16.tif");
    let i16s: Vec<i16> = (0..w * h).map(|i| (i as i32 - 700) as i16).collect();
    let f = std::fs::File::create(&p).unwrap();
    TiffEncoder::new(f)
        .unwrap()
        .with_compression(Compression::Packbits)
        .write_image::<colortype::GrayI16>(w, h, &i16s)
        .unwrap();
    let img = read_tiff(&p).unwrap().image;
    assert!(img.data().iter().zip(&i16s).all(|(a, b)| *a == *b as f32));

    let p = dir.path().join("rgb8.tif");
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i % 251) as u8).collect();
    let f = std::fs::File::create(&p).unwrap();
    TiffEncoder::new_big(f)
        .unwrap()
        .write_image::<colortype::RGB8>(w, h, &rgb)
        .unwrap();
    let img = read_tiff(&p).unwrap().image;
    assert_eq!(img.channels(), 3);
    assert!(img.data().iter().zip(&rgb).all(|(a, b)| *a == *b as f32));

    let p = dir.path().join("f64.tif");
    let f64s: Vec<f64> = (0..w * h).map(|i| i as f64 / 8.0 - 3.0).collect();
    let f = std::fs::File::create(&p).unwrap();
    TiffEncoder::new(f)
        .unwrap()
        .with_compression(Compression::Deflate(Default::default()))
        .write_image::<colortype::Gray64Float>(w, h, &f64s)
        .unwrap();
    let img = read_tiff(&p).unwrap().image;
    assert!(img.data().iter().zip(&f64s).all(|(a, b)| *a == *b as f32));
}

/// A 20×18, 3-band int16 GeoTIFF written by GDAL (rasterio) with planar configuration 2 and
/// 16×16 Deflate tiles (so the right and bottom tiles are partial), embedded as hex:
/// band b, row y, column x holds b*1000 + y*20 + x - 100; UTM 31N, origin (500000, 4600000), 10 m.
const PLANAR_TILED_I16: &str = "\
    49492a000800000012000001030001000000140000000101030001000000120000000201030003000000e60000000301\
    030001000000080000000601030001000000010000001501030001000000030000001c01030001000000020000003d01\
    03000100000001000000420103000100000010000000430103000100000010000000440104000c000000040100004501\
    03000c000000ec0000005201030002000000000000005301030003000000340100000e830c00030000003a0100008284\
    0c000600000052010000af8703002000000082010000b18702001e000000c20100000000000010001000100084018500\
    3a001e0084018c003e002000840189003e002000e001000064030000e90300002304000041040000c505000051060000\
    8f060000af06000033080000bc080000fa08000002000200020000000000000024400000000000002440000000000000\
    00000000000000000000000000000000000000000000000000000000000080841e4100000000308c5141000000000000\
    00000100010000000700000400000100010001040000010001000204b187160000000108b18707001600060800000100\
    8e23000c00000100777f040c000001002923574753203834202f2055544d207a6f6e652033314e7c5747532038347c00\
    789c05c1338010000040d19f5d4b36966c2cd958b2b16463c9c692edcecc9d993b33db2dd9187eef1df784273d658081\
    06196c88a186196e84914619ed792f78d14bc6186b9cf126986892c9a6986a9ae95ef78637bd65869966996d8eb9e699\
    6f81851659ec7d1ff8d0473ef6894f7de6735ff8d257bef68d6f7de77b3ff8d14f7ef68b5ffde6777ff8d35ffef68f7f\
    fd2794a024a5284d19ca528ef254a02295a84c15aa528dead4a026b5a84d1dea528ffa34a0218d684c139ad28ce6b4a0\
    25ad684d1bdad28ef674a0239de84c17bad28deef4a027bde84d1ffad28ffe0c60208318cc1086328ce18c6024a318cd\
    18c6328ef14c60229398cc14a6328de9cc6026b398cd1ce6328ff92c60218b58cc1296b28ce5ac6025ab58cd1ad6b28e\
    f56c60239bd8cc16b6b28dedec6027bbd8cd1ef6b28ffd1ce0208738cc118e728c0002092298104209239c082289229a\
    d39ce12ce788219638e2492091249249219534d2b9cc15ae728d0c32c9229b1c72c9239f020a29a298dbdce12ef7f80f\
    4a0ed931789c75c9570101000045d11bc1a86054302a18158c0a4605a38251c056c056c056c0a88027c13bbf67a0a146\
    1a0b63a1a5565adb3fe8a893cef61f7aeaa5b7fd8fbefa49f603040911c689102546dc7e822429d2f63364c991b75fa0\
    4889b2fd0a556ad4ed3768d2a26dbf43971e7dfb13a6cc98dbdfb065c7defe852b37eef6ffca5738cd789cedc1c50d84\
    000000b0ee3fe3292e1fdc6d0e12da97b78faf9fbf4028124ba432b942a9526bb43abdc168325bac36bbc3e9716f17b3\
    991db1789c7bc3f096e11dc37b069c809191918991999161140c4b000075d103c1789c05c1338010000040d1eaffbc64\
    63c9c6928d251b4b36966c7766eeccdc99d96ec9c6928d25dc7b5bd8ca36b6134020410413422861841341245144b387\
    bdec633f31c412473c092492443229a492463a4738ca318e934126596493432e79e453402145147386b39ce33c17b8c8\
    252e7385ab5ce33a37b8c92d6e7387bbdce33e0f78c8231ef384a73ce3392f78c92b5ef386b7bce33d1ff8c8273ef385\
    af7ce33b3ff8c92f7ef387bffce33fa52c6d1951cb5acef256b0a295ac6c15ab5acdead6b0a6b5ac6d1deb5acffa36b0\
    a18d6c6c139bdacce6b6b0a5ad6c6d1bdbdacef676b0a39dec6c17bbdacdeef6b0a7bdec6d1ffbdacffe0e70a0831cec\
    10873acce18e70a4a31ced18c73acef14e70a2939cec14a73acde9ce70a6b39ced1ce73acff92e70a18b5cec1297bacc\
    e5ae70a5ab5ced1ad7bacef56e70a39bdc6c808106196c88a186196e84914619ed0e77bacbddc6186b9cf126986892c9\
    a6986a9ae91ef0a0873c6c869966996d8eb9e6996f81851659ec094f7acad39600148f891d789c75c9459502000045d1\
    39e7bfe5cc5001a98054402a2015900a48019c023805700a2015900ac88604ff6e6f532db5d5d18f31d448634dec2fb5\
    d25a1bfb479d74d6c5fe5537ddf5b0ffd44b6f7decfff2c73f01dc07091126623f4a8c3809fb4952a4c9d8cf92234fc1\
    7e9112652af6abd4a8d3b0dfa5479f81fd2933e62cec6fd9b1e760ff0b44e923c9789cedc1b51184000000b02fb2ff54\
    ef3834b8cb1accc11dc9d3cbdbc7d7cf5f2014892552995ca154a9355a9dde6034992d569bdde171bbb413005d1b3178\
    9cbbc27295e51acb7516061ce005cb4b96572caf71ca8f82a10d00ae7b071d789c05c1338010000040d1fcff908d251b\
    4b36966c2cd9eeccdc99b933b3dd928d251b4b36965cefcd67010b5944008104114c08a184114e04914411cd7256b092\
    55c4104b1cf124904812c9a4904a1ae9ac67031bd944069964914d0eb9e4914f01851451cc7676b0935dec660f7bd9c7\
    7e0e7090431ce6084739c6714e7092539ce60c6739c7792e70914b5ce60a57b9c6756e70935bdce60e77b9c77d1ef090\
    473ce6094f79c6735ef09257bce60d6f79c77b3ef0914f7ce60b5ff9c6777ef0935ffce60f7ff947094b5acad296b1ac\
    e5c4f256b0a295ac6c15ab5acdead6b0a6b5ac6d1deb5acffa36b0a18d6c6c139bdacce6b6b0a5ad6c6d1bdbdacef676\
    b0a39dec6c17bbdacdeef6b0a7bdec6d1ffbdacffe0e70a0831cec10873acce18e70a4a31ced18c73acef14e70a2939c\
    ec14a73acde9ce70a6b39ced1ce73acf00030d32d810430d33dc08238d32dac52e71a9cb8c31d638e34d30d124934d31\
    d534d35ded1ad7bace0c33cd32db1c73cd33df020b2db2d8cd6e71abdbfc0fc9dd8909789c75c9458102000044d1bdcd\
    5fa88054402a2015900a48019c023805700a2015900a4805e44a8279d757535d0d35f567f4d4d74043fb33cdb5d0d2fe\
    4e7b1d74b47fd259175deddf74d7434ffb2fbdf5d1d73efc132088fb10612244edc7889320693f459a0c59fb39f21428\
    da2f51a642d57e8b361dbaf6478c9930b5bf62cd86adfd1ff1ea22c5789cedc1b51184000000b02fb3ff1cef3834b8cb\
    4accc11dc9d3cbdbc7d7cf5f2014892552995ca154a9355a9dde6034992d569bdde171bbb4134d1218b1789cdbc3b197\
    631fc77e0e061ce002c7458e4b1c9771ca8f82a10d007a2c067d";

#[test]
fn tiff_planar_tiled_from_gdal() {
    let bytes: Vec<u8> = (0..PLANAR_TILED_I16.len() / 2)
        .map(|i| u8::from_str_radix(&PLANAR_TILED_I16[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    let dir = tmp();
    let p = dir.path().join("planar.tif");
    std::fs::write(&p, bytes).unwrap();
    let r = read_tiff(&p).unwrap();
    assert_eq!(
        (r.image.width(), r.image.height(), r.image.channels()),
        (20, 18, 3)
    );
    for y in 0..18 {
        for x in 0..20 {
            for b in 0..3 {
                assert_eq!(r.image.get(x, y, b), (b * 1000 + y * 20 + x) as f32 - 100.0);
            }
        }
    }
    let g = r.georef.unwrap();
    assert_eq!(
        g.geotransform,
        [500_000.0, 10.0, 0.0, 4_600_000.0, 0.0, -10.0]
    );
    assert_eq!(g.epsg, Some(32631));
}

/// Windows read from striped (our writer), tiled chunky (COG) and tiled planar (GDAL) files equal
/// the same crop of the whole image, at the edges too; a window outside the image is refused.
#[test]
fn tiff_windows_decode_only_what_they_cover_and_match_the_whole_image() {
    let dir = tmp();
    let img = sample_image(300, 270, 3);
    let striped = dir.path().join("striped.tif");
    write_geotiff(&striped, &img, &GeoTiffMeta::default()).unwrap();
    let cog = dir.path().join("cog.tif");
    raster::formats::write_cog(&cog, &img, &utm_meta()).unwrap();
    let planar = dir.path().join("planar.tif");
    let bytes: Vec<u8> = (0..PLANAR_TILED_I16.len() / 2)
        .map(|i| u8::from_str_radix(&PLANAR_TILED_I16[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    std::fs::write(&planar, bytes).unwrap();
    for path in [&striped, &cog, &planar] {
        let whole = read_tiff(path).unwrap().image;
        let mut reader = TiffReader::open(path).unwrap();
        assert_eq!(reader.size(), whole.size());
        assert_eq!(reader.bands(), whole.channels());
        let (w, h) = whole.size();
        for (x, y, ww, hh) in [
            (0, 0, w, h),
            (3, 5, 7, 4),
            (w - 9, h - 2, 9, 2),
            (w / 2, 1, w / 3, h - 1),
        ] {
            let win = reader.read_window(x, y, ww, hh).unwrap();
            assert_same(&win, &raster::geometry::crop(&whole, x, y, ww, hh).unwrap());
        }
        let msg = reader.read_window(w - 1, 0, 2, 1).unwrap_err().to_string();
        assert!(msg.contains("not inside"), "{msg}");
    }
}

// ---------------------------------------------------------------- PNG

#[test]
fn png_round_trips_8_and_16_bit() {
    let dir = tmp();
    for c in 1..=4 {
        let p = dir.path().join(format!("a{c}.png"));
        let img = Image::new(
            7,
            5,
            c,
            (0..7 * 5 * c).map(|i| (i * 7 % 256) as f32).collect(),
        )
        .unwrap();
        write_png(&p, &img, PngDepth::Eight).unwrap();
        assert_same(&read_png(&p).unwrap(), &img);

        let img16 = Image::new(
            7,
            5,
            c,
            (0..7 * 5 * c).map(|i| (i * 1999 % 65536) as f32).collect(),
        )
        .unwrap();
        write_png(&p, &img16, PngDepth::Sixteen).unwrap();
        assert_same(&read_png(&p).unwrap(), &img16);
    }
}

#[test]
fn png_clamps_rounds_and_zeroes_nan() {
    let dir = tmp();
    let p = dir.path().join("clamp.png");
    let img = Image::new(5, 1, 1, vec![-5.0, 1.4, 1.6, 300.0, f32::NAN]).unwrap();
    write_png(&p, &img, PngDepth::Eight).unwrap();
    assert_eq!(read_png(&p).unwrap().data(), &[0.0, 1.0, 2.0, 255.0, 0.0]);
    let img = Image::new(2, 1, 1, vec![70000.0, 1234.5]).unwrap();
    write_png(&p, &img, PngDepth::Sixteen).unwrap();
    assert_eq!(read_png(&p).unwrap().data(), &[65535.0, 1235.0]);
    assert!(write_png(&p, &Image::filled(2, 2, 5, 0.0), PngDepth::Eight).is_err());
}

#[test]
fn png_palette_is_expanded() {
    let dir = tmp();
    let p = dir.path().join("pal.png");
    let f = std::fs::File::create(&p).unwrap();
    let mut enc = png::Encoder::new(f, 2, 1);
    enc.set_color(png::ColorType::Indexed);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_palette(vec![10, 20, 30, 200, 100, 0]);
    let mut w = enc.write_header().unwrap();
    w.write_image_data(&[1, 0]).unwrap();
    w.finish().unwrap();
    let img = read_png(&p).unwrap();
    assert_eq!(img.channels(), 3);
    assert_eq!(img.data(), &[200.0, 100.0, 0.0, 10.0, 20.0, 30.0]);
}

// ---------------------------------------------------------------- PFM

#[test]
fn pfm_round_trips_1_and_3_channels() {
    let dir = tmp();
    for c in [1, 3] {
        let p = dir.path().join(format!("d{c}.pfm"));
        let img = sample_image(6, 4, c);
        write_pfm(&p, &img).unwrap();
        assert_same(&read_pfm(&p).unwrap(), &img);
    }
    assert!(write_pfm(dir.path().join("x.pfm"), &Image::filled(2, 2, 2, 0.0)).is_err());
}

#[test]
fn pfm_big_endian_bottom_to_top() {
    let dir = tmp();
    let p = dir.path().join("be.pfm");
    let mut bytes = b"Pf\n2 2\n1.0\n".to_vec();
    // Bottom row (y = 1) first.
    for v in [3.0f32, 4.0, 1.0, 2.0] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    std::fs::write(&p, bytes).unwrap();
    assert_eq!(read_pfm(&p).unwrap().data(), &[1.0, 2.0, 3.0, 4.0]);
}

// ---------------------------------------------------------------- dispatch and atomicity

#[test]
fn read_and_write_image_dispatch_by_extension() {
    let dir = tmp();
    let img = Image::from_fn(4, 3, |x, y| (x + 4 * y) as f32);
    for name in ["a.npy", "b.IIO", "c.tif", "d.TIFF", "e.png", "f.pfm"] {
        let p = dir.path().join(name);
        write_image(&p, &img).unwrap();
        assert_same(&read_image(&p).unwrap(), &img);
    }
    // Really the formats the extensions name.
    assert!(read_npy(dir.path().join("b.IIO")).is_ok());
    assert!(read_png(dir.path().join("e.png")).is_ok());
    assert!(read_tiff(dir.path().join("d.TIFF"))
        .unwrap()
        .georef
        .is_none());
    let e = write_image(dir.path().join("g.jpg"), &img)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("g.jpg") && e.contains("npy") && e.contains("tif"),
        "{e}"
    );
    assert!(read_image(dir.path().join("h")).is_err());
}

#[test]
fn writers_replace_atomically() {
    let dir = tmp();
    let p = dir.path().join("out.npy");
    write_npy(&p, &Image::filled(2, 2, 1, 1.0)).unwrap();
    // A failing write keeps the old file and leaves no temporary behind.
    let r = write_atomically(&p, |w| {
        w.write_all(b"garbage")?;
        Err(std::io::Error::other("killed"))
    });
    assert!(r.is_err());
    assert_eq!(read_npy(&p).unwrap().data(), &[1.0; 4]);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

// ---------------------------------------------------------------- corrupt inputs

type Reader = fn(&Path) -> Result<()>;

fn npy_reader(p: &Path) -> Result<()> {
    read_npy(p).map(drop)
}
fn npz_reader(p: &Path) -> Result<()> {
    read_homographies(p).map(drop)
}
fn tiff_reader(p: &Path) -> Result<()> {
    read_tiff(p).map(drop)
}
fn png_reader(p: &Path) -> Result<()> {
    read_png(p).map(drop)
}
fn pfm_reader(p: &Path) -> Result<()> {
    read_pfm(p).map(drop)
}

/// Deterministic pseudo-random numbers (Knuth's MMIX LCG).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
}

fn expect_error(dir: &Path, name: &str, bytes: &[u8], read: Reader, what: &str) {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    match read(&p) {
        Ok(()) => panic!("{what}: {name} was accepted"),
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.contains(name),
                "{what}: error does not name the file: {msg}"
            );
        }
    }
}

/// Empty, wrong magic, truncated, garbage, oversized claims and random byte flips.
fn corrupt_suite(ext: &str, valid: &[u8], claims_more: &[u8], read: Reader) {
    let dir = tmp();
    let d = dir.path();
    let p = d.join(format!("valid.{ext}"));
    std::fs::write(&p, valid).unwrap();
    read(&p).expect("the valid file reads");

    expect_error(d, &format!("empty.{ext}"), &[], read, "empty");
    let mut magic = valid.to_vec();
    magic[..4].copy_from_slice(b"JUNK");
    expect_error(d, &format!("magic.{ext}"), &magic, read, "wrong magic");
    expect_error(
        d,
        &format!("half.{ext}"),
        &valid[..valid.len() / 2],
        read,
        "truncated",
    );
    expect_error(
        d,
        &format!("claims.{ext}"),
        claims_more,
        read,
        "claims more data",
    );
    let mut rng = Lcg(42);
    let garbage: Vec<u8> = (0..4096).map(|_| rng.next() as u8).collect();
    expect_error(d, &format!("garbage.{ext}"), &garbage, read, "garbage");

    let flipped = d.join(format!("flipped.{ext}"));
    for _ in 0..300 {
        let mut bytes = valid.to_vec();
        for _ in 0..1 + rng.next() % 8 {
            let i = (rng.next() as usize) % bytes.len();
            bytes[i] ^= 1 << (rng.next() % 8);
        }
        std::fs::write(&flipped, &bytes).unwrap();
        if let Err(e) = read(&flipped) {
            let msg = e.to_string();
            assert!(msg.contains("flipped"), "{msg}");
        }
    }
}

#[test]
fn npy_corrupt_files() {
    let dir = tmp();
    let p = dir.path().join("v.npy");
    write_npy(&p, &sample_image(8, 6, 2)).unwrap();
    let valid = std::fs::read(&p).unwrap();
    let claims = npy_bytes("<f4", false, "(1000000, 1000000, 1)", &[0u8; 64]);
    corrupt_suite("npy", &valid, &claims, npy_reader);
    // Overflowing shapes too.
    let huge = npy_bytes("<f8", false, "(99999999999, 99999999999, 9999)", &[0u8; 8]);
    expect_error(dir.path(), "huge.npy", &huge, npy_reader, "overflow");
}

#[test]
fn npz_corrupt_files() {
    let dir = tmp();
    let p = dir.path().join("v.npz");
    let (l, r) = sample_homographies();
    write_homographies(&p, &l, &r).unwrap();
    let valid = std::fs::read(&p).unwrap();
    let claims_path = dir.path().join("c.npz");
    let short = npy_bytes("<f8", false, "(3, 3)", &[0u8; 16]);
    write_npz(
        &claims_path,
        &[("Hleft.npy", short.clone()), ("Hright.npy", short)],
        zip::CompressionMethod::Stored,
    );
    let claims = std::fs::read(&claims_path).unwrap();
    corrupt_suite("npz", &valid, &claims, npz_reader);
}

/// Sets the value of a LONG/SHORT tag in the first IFD of a little-endian classic TIFF.
fn patch_tiff_tag(bytes: &mut [u8], tag: u16, value: u32) {
    let ifd = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
    let n = u16::from_le_bytes([bytes[ifd], bytes[ifd + 1]]) as usize;
    for e in 0..n {
        let at = ifd + 2 + 12 * e;
        if u16::from_le_bytes([bytes[at], bytes[at + 1]]) == tag {
            let ty = u16::from_le_bytes([bytes[at + 2], bytes[at + 3]]);
            let v = if ty == 3 { value.min(65535) } else { value };
            bytes[at + 8..at + 12].copy_from_slice(&v.to_le_bytes());
            return;
        }
    }
    panic!("tag {tag} not found");
}

#[test]
fn tiff_corrupt_files() {
    let dir = tmp();
    let p = dir.path().join("v.tif");
    write_geotiff(&p, &sample_image(20, 10, 1), &utm_meta()).unwrap();
    let valid = std::fs::read(&p).unwrap();
    let mut claims = valid.clone();
    patch_tiff_tag(&mut claims, 256, 1_000_000);
    patch_tiff_tag(&mut claims, 257, 1_000_000);
    corrupt_suite("tif", &valid, &claims, tiff_reader);
    // A header promising more rows than the strips hold.
    let mut taller = valid.clone();
    patch_tiff_tag(&mut taller, 257, 5000);
    expect_error(dir.path(), "taller.tif", &taller, tiff_reader, "taller");
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[test]
fn png_corrupt_files() {
    let dir = tmp();
    let p = dir.path().join("v.png");
    write_png(
        &p,
        &Image::from_fn(30, 20, |x, y| (x * y % 256) as f32),
        PngDepth::Eight,
    )
    .unwrap();
    let valid = std::fs::read(&p).unwrap();
    // IHDR at byte 8: length, "IHDR", width, height, ..., CRC over type + data.
    let mut claims = valid.clone();
    claims[16..20].copy_from_slice(&100_000u32.to_be_bytes());
    claims[20..24].copy_from_slice(&100_000u32.to_be_bytes());
    let crc = crc32(&claims[12..29]);
    claims[29..33].copy_from_slice(&crc.to_be_bytes());
    corrupt_suite("png", &valid, &claims, png_reader);
}

#[test]
fn pfm_corrupt_files() {
    let dir = tmp();
    let p = dir.path().join("v.pfm");
    write_pfm(&p, &sample_image(9, 7, 3)).unwrap();
    let valid = std::fs::read(&p).unwrap();
    let mut claims = b"PF\n100000 100000\n-1.0\n".to_vec();
    claims.extend_from_slice(&[0u8; 400]);
    corrupt_suite("pfm", &valid, &claims, pfm_reader);
    expect_error(
        dir.path(),
        "scale.pfm",
        b"Pf\n1 1\n0\n\0\0\0\0",
        pfm_reader,
        "zero scale",
    );
}

// ---------------------------------------------------------------- colormap

#[test]
fn colorized_png_is_rgb_with_black_nan() {
    let dir = tmp();
    let p = dir.path().join("c.png");
    let mut img = Image::from_fn(10, 10, |x, y| (x + y) as f32);
    img.set(3, 3, 0, f32::NAN);
    colormap::write_colorized_png(&p, &img, None).unwrap();
    let c = read_png(&p).unwrap();
    assert_eq!((c.channels(), c.width()), (3, 10));
    assert_eq!(c.pixel(3, 3), &[0.0; 3]);
    assert_ne!(c.pixel(0, 0), c.pixel(9, 9));
}

// ---------------------------------------------------------------- the s2p test data

/// Sum of the finite samples, in f64 (as numpy's nansum of the float64 cast).
fn sum(img: &Image) -> f64 {
    img.data()
        .iter()
        .filter(|v| v.is_finite())
        .map(|&v| v as f64)
        .sum()
}

/// `<s2p's test data>/tests/data/<rel>`, or None (the test skips) where the set is absent.
fn anchor(rel: &str) -> Option<PathBuf> {
    testdata::dataset("anchors/data/s2p").map(|dir| dir.join("tests/data").join(rel))
}

#[test]
fn s2p_satellite_image_with_rpc() {
    let Some(p) = anchor("input_pair/img_01.tif") else {
        return;
    };
    let r = read_tiff(&p).unwrap();
    assert_eq!(
        (r.image.width(), r.image.height(), r.image.channels()),
        (1024, 1024, 1)
    );
    // uint16 digital numbers, kept as they are.
    // Values GDAL reports for this file: uint16 digital numbers, kept as they are.
    assert_eq!(r.image.finite_range(), Some((94.0, 1883.0)));
    assert_eq!(
        (r.image.get(200, 100, 0), r.image.get(300, 400, 0)),
        (385.0, 211.0)
    );
    assert_eq!(sum(&r.image), 279_380_690.0);
    let rpc = r.rpc.expect("RPC tag");
    let c = rpc.to_coefficients();
    assert!(c.iter().all(|v| v.is_finite()));
    assert!((rpc.lat_off + 21.0).abs() < 1.0, "lat_off {}", rpc.lat_off);
    assert!((rpc.lon_off - 55.0).abs() < 1.5, "lon_off {}", rpc.lon_off);
    assert_eq!((rpc.lat_off, rpc.lon_off), (-21.2316081288, 55.7119698801));
    assert_eq!((rpc.line_off, rpc.samp_off), (19403.5, 19999.5));
    assert_eq!(rpc.line_num[..2], [-37.284870906, -0.389307964671]);
    assert!(rpc.line_off > 0.0 && rpc.samp_off > 0.0 && rpc.line_scale > 0.0);
    assert!(rpc.line_den[0] != 0.0 && rpc.samp_den[0] != 0.0);
}

#[test]
fn s2p_dsm_reads_and_round_trips() {
    let Some(p) = anchor("expected_output/pair/dsm.tif") else {
        return;
    };
    let r = read_tiff(&p).unwrap();
    assert_eq!(
        (r.image.width(), r.image.height(), r.image.channels()),
        (721, 739, 1)
    );
    let g = r.georef.clone().expect("georeferenced");
    assert_eq!(g.epsg, Some(32740));
    assert_eq!(g.geotransform[1], 0.5);
    assert_eq!(g.geotransform[5], -0.5);
    assert_eq!((g.geotransform[2], g.geotransform[4]), (0.0, 0.0));
    // What GDAL reports for this (256×256-tiled) file.
    assert_eq!(
        g.geotransform,
        [359_746.0, 0.5, 0.0, 7_651_923.0, 0.0, -0.5]
    );
    assert!(r.nodata.unwrap().is_nan());
    let nans = r.image.data().iter().filter(|v| v.is_nan()).count();
    assert_eq!(nans, 60_101);
    assert_eq!(r.image.get(200, 100, 0), 2_356.838_9);
    assert_eq!(r.image.get(300, 400, 0), 2_341.394_3);
    assert!((sum(&r.image) - 1_100_418_635.667_480_5).abs() < 1e-3);

    let dir = tmp();
    let out = dir.path().join("dsm_copy.tif");
    write_geotiff(&out, &r.image, &r.meta()).unwrap();
    let back = read_tiff(&out).unwrap();
    assert_same(&back.image, &r.image);
    let bg = back.georef.unwrap();
    assert_eq!(bg.geotransform, g.geotransform);
    assert_eq!(bg.epsg, Some(32740));
    assert!(back.nodata.unwrap().is_nan());

    // A fresh minimal georeference gives the same grid.
    let fresh = GeoReference::from_origin_utm(g.geotransform[0], g.geotransform[3], 0.5, 32740);
    let out2 = dir.path().join("dsm_fresh.tif");
    write_geotiff(
        &out2,
        &r.image,
        &GeoTiffMeta {
            georef: Some(fresh),
            nodata: Some(f64::NAN),
            rpc: None,
            gdal_metadata: None,
        },
    )
    .unwrap();
    let back2 = read_tiff(&out2).unwrap().georef.unwrap();
    assert_eq!(back2.geotransform, g.geotransform);
    assert_eq!(back2.epsg, Some(32740));
}

#[test]
fn s2p_bigtiff_disparity() {
    let Some(p) = anchor("input_triangulation/pair_1/rectified_disp.tif") else {
        return;
    };
    let r = read_tiff(&p).unwrap();
    assert_eq!(
        (r.image.width(), r.image.height(), r.image.channels()),
        (503, 425, 1)
    );
    // LZW-compressed strips; values as GDAL reads them.
    let nans = r.image.data().iter().filter(|v| v.is_nan()).count();
    assert_eq!(nans, 10_736);
    assert_eq!(r.image.finite_range(), Some((-40.856_354, 29.792_543)));
    assert_eq!(r.image.get(200, 100, 0), 14.922_277);
    assert_eq!(r.image.get(300, 400, 0), -26.946_672);
    assert!((sum(&r.image) + 1_325_387.179_741_629_4).abs() < 1e-3);
}
