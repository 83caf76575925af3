//! NPY arrays (`.npy`, and the public release's `.iio` files, which are NPY inside).
//!
//! The header is parsed here rather than by a general Python-literal parser: it is a tiny dict,
//! and a hand-written, non-recursive parser cannot be driven into deep recursion by a crafted file.

use std::io::Write;
use std::path::Path;

use super::support::{read_bytes, write_atomically};
use crate::{Image, RasterError, Result};

const MAGIC: &[u8] = b"\x93NUMPY";

/// Reads an NPY array of shape `(H, W)` or `(H, W, C)` as an image. Accepted dtypes: float32,
/// float64, (u)int8, (u)int16, (u)int32, (u)int64, bool, either byte order, C or Fortran order.
/// Values are kept in their native units.
pub fn read_npy(path: impl AsRef<Path>) -> Result<Image> {
    let path = path.as_ref();
    let bytes = read_bytes(path)?;
    let (shape, data) = decode::<f32>(path, &bytes)?;
    let (h, w, c) = match shape[..] {
        [h, w] => (h, w, 1),
        [h, w, c] if c > 0 => (h, w, c),
        _ => {
            return Err(RasterError::format(
                path,
                format!("NPY shape {shape:?} is not an image: expected (H, W) or (H, W, C)"),
            ))
        }
    };
    Image::new(w, h, c, data).map_err(|e| RasterError::format(path, e.to_string()))
}

/// Writes `image` as a float32 little-endian NPY of shape `(H, W, C)` (C kept even when 1), the
/// layout of the public release's `.iio` files.
pub fn write_npy(path: impl AsRef<Path>, image: &Image) -> Result<()> {
    let header = header_bytes("<f4", &[image.height(), image.width(), image.channels()]);
    write_atomically(path, |w| {
        w.write_all(&header)?;
        for chunk in image.data().chunks(1 << 16) {
            let bytes: Vec<u8> = chunk.iter().flat_map(|v| v.to_le_bytes()).collect();
            w.write_all(&bytes)?;
        }
        Ok(())
    })
}

/// A complete NPY header (magic, version, length, dict, padding) for a C-order array.
pub(crate) fn header_bytes(descr: &str, shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    // Version 1.0 has a u16 length; the data must start on a 64-byte boundary.
    let v1 = dict.len() + 11 < 65_000;
    let prefix = if v1 { 10 } else { 12 };
    while (prefix + dict.len() + 1) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let mut out = MAGIC.to_vec();
    if v1 {
        out.extend_from_slice(&[1, 0]);
        out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    } else {
        out.extend_from_slice(&[2, 0]);
        out.extend_from_slice(&(dict.len() as u32).to_le_bytes());
    }
    out.extend_from_slice(dict.as_bytes());
    out
}

/// A sample type NPY data can be converted to.
pub(crate) trait Sample: Copy + Default {
    fn from_f64(v: f64) -> Self;
    fn from_f32(v: f32) -> Self;
}

impl Sample for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn from_f32(v: f32) -> Self {
        v
    }
}

impl Sample for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
    fn from_f32(v: f32) -> Self {
        v as f64
    }
}

/// Decodes an NPY file held in `bytes` into its shape and C-order data.
pub(crate) fn decode<T: Sample>(path: &Path, bytes: &[u8]) -> Result<(Vec<usize>, Vec<T>)> {
    let err = |m: String| RasterError::format(path, m);
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err(err("not an NPY file (bad magic)".into()));
    }
    let (len, start): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(err(format!("unsupported NPY version {v}.{}", bytes[7]))),
    };
    let text = bytes
        .get(start..start.saturating_add(len))
        .ok_or_else(|| err("truncated NPY header".into()))?;
    let text = std::str::from_utf8(text).map_err(|_| err("NPY header is not text".into()))?;
    let header = parse_header(text).map_err(|m| err(format!("bad NPY header: {m}")))?;
    let dtype = Dtype::parse(&header.descr).ok_or_else(|| {
        err(format!(
            "unsupported NPY dtype '{}' (shape {:?})",
            header.descr, header.shape
        ))
    })?;
    let data = &bytes[start + len..];
    let count = header
        .shape
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| err(format!("NPY shape {:?} is too large", header.shape)))?;
    let needed = count.checked_mul(dtype.size);
    if needed != Some(data.len()) {
        return Err(err(format!(
            "header/data size mismatch: shape {:?} of '{}' needs {} bytes of data, the file has {}",
            header.shape,
            header.descr,
            needed.map_or("too many".to_string(), |n| n.to_string()),
            data.len()
        )));
    }
    let mut values: Vec<T> = data
        .chunks_exact(dtype.size)
        .map(|b| dtype.read(b))
        .collect();
    if header.fortran_order && header.shape.len() > 1 {
        values = fortran_to_c(&values, &header.shape);
    }
    Ok((header.shape, values))
}

/// Reorders Fortran-order (first index fastest) data into C order (last index fastest).
fn fortran_to_c<T: Copy + Default>(values: &[T], shape: &[usize]) -> Vec<T> {
    let n = shape.len();
    let mut out = vec![T::default(); values.len()];
    // Fortran strides: stride[0] = 1, stride[k] = stride[k-1] * shape[k-1].
    let mut fstride = vec![1usize; n];
    for k in 1..n {
        fstride[k] = fstride[k - 1] * shape[k - 1];
    }
    let mut index = vec![0usize; n];
    for slot in out.iter_mut() {
        let src: usize = index.iter().zip(&fstride).map(|(i, s)| i * s).sum();
        *slot = values[src];
        // Advance the C-order multi-index (last axis fastest).
        for k in (0..n).rev() {
            index[k] += 1;
            if index[k] < shape[k] {
                break;
            }
            index[k] = 0;
        }
    }
    out
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Float,
    Int,
    Uint,
    Bool,
}

/// A plain numeric NPY dtype.
#[derive(Clone, Copy, Debug)]
struct Dtype {
    kind: Kind,
    size: usize,
    big_endian: bool,
}

impl Dtype {
    fn parse(descr: &str) -> Option<Self> {
        let mut chars = descr.chars();
        let (big_endian, rest) = match chars.next()? {
            '<' | '|' | '=' => (false, chars.as_str()),
            '>' => (true, chars.as_str()),
            _ => (false, descr),
        };
        let kind = match rest.chars().next()? {
            'f' => Kind::Float,
            'i' => Kind::Int,
            'u' => Kind::Uint,
            'b' => Kind::Bool,
            _ => return None,
        };
        let size: usize = rest[1..].parse().ok()?;
        let ok = match kind {
            Kind::Float => size == 4 || size == 8,
            Kind::Int | Kind::Uint => matches!(size, 1 | 2 | 4 | 8),
            Kind::Bool => size == 1,
        };
        ok.then_some(Dtype {
            kind,
            size,
            big_endian,
        })
    }

    /// Converts one element's bytes.
    fn read<T: Sample>(&self, b: &[u8]) -> T {
        let mut buf = [0u8; 8];
        buf[..self.size].copy_from_slice(b);
        if self.big_endian {
            buf[..self.size].reverse();
        }
        let u = u64::from_le_bytes(buf);
        match (self.kind, self.size) {
            (Kind::Float, 4) => T::from_f32(f32::from_bits(u as u32)),
            (Kind::Float, _) => T::from_f64(f64::from_bits(u)),
            (Kind::Uint | Kind::Bool, _) => T::from_f64(u as f64),
            (Kind::Int, s) => {
                let shift = 64 - 8 * s as u32;
                T::from_f64((((u << shift) as i64) >> shift) as f64)
            }
        }
    }
}

/// The three keys of an NPY header dict.
#[derive(Debug)]
struct Header {
    descr: String,
    fortran_order: bool,
    shape: Vec<usize>,
}

/// Parses `{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }`.
fn parse_header(text: &str) -> std::result::Result<Header, String> {
    let mut p = Parser {
        s: text.trim_end().as_bytes(),
        i: 0,
    };
    let (mut descr, mut fortran, mut shape) = (None, None, None);
    p.expect(b'{')?;
    loop {
        if p.eat(b'}') {
            break;
        }
        let key = p.string()?;
        p.expect(b':')?;
        match key.as_str() {
            "descr" => {
                if p.peek() == Some(b'[') {
                    return Err("structured dtypes are not supported".into());
                }
                descr = Some(p.string()?)
            }
            "fortran_order" => fortran = Some(p.boolean()?),
            "shape" => shape = Some(p.tuple()?),
            other => return Err(format!("unexpected key '{other}'")),
        }
        if !p.eat(b',') {
            p.expect(b'}')?;
            break;
        }
    }
    Ok(Header {
        descr: descr.ok_or("missing 'descr'")?,
        fortran_order: fortran.ok_or("missing 'fortran_order'")?,
        shape: shape.ok_or("missing 'shape'")?,
    })
}

struct Parser<'a> {
    s: &'a [u8],
    i: usize,
}

impl Parser<'_> {
    fn peek(&mut self) -> Option<u8> {
        while self.i < self.s.len() && self.s[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
        self.s.get(self.i).copied()
    }

    fn eat(&mut self, c: u8) -> bool {
        let hit = self.peek() == Some(c);
        if hit {
            self.i += 1;
        }
        hit
    }

    fn expect(&mut self, c: u8) -> std::result::Result<(), String> {
        if self.eat(c) {
            Ok(())
        } else {
            Err(format!("expected '{}' at byte {}", c as char, self.i))
        }
    }

    fn string(&mut self) -> std::result::Result<String, String> {
        let quote = match self.peek() {
            Some(q @ (b'\'' | b'"')) => q,
            _ => return Err(format!("expected a string at byte {}", self.i)),
        };
        let start = self.i + 1;
        let len = self.s[start..]
            .iter()
            .position(|&c| c == quote)
            .ok_or("unterminated string")?;
        self.i = start + len + 1;
        Ok(String::from_utf8_lossy(&self.s[start..start + len]).into_owned())
    }

    fn boolean(&mut self) -> std::result::Result<bool, String> {
        self.peek();
        for (word, value) in [(&b"True"[..], true), (&b"False"[..], false)] {
            if self.s[self.i..].starts_with(word) {
                self.i += word.len();
                return Ok(value);
            }
        }
        Err(format!("expected True or False at byte {}", self.i))
    }

    fn tuple(&mut self) -> std::result::Result<Vec<usize>, String> {
        self.expect(b'(')?;
        let mut dims = Vec::new();
        loop {
            if self.eat(b')') {
                return Ok(dims);
            }
            self.peek();
            let start = self.i;
            while self.i < self.s.len() && self.s[self.i].is_ascii_digit() {
                self.i += 1;
            }
            let digits = std::str::from_utf8(&self.s[start..self.i]).unwrap_or("");
            dims.push(
                digits
                    .parse()
                    .map_err(|_| format!("expected a dimension at byte {start}"))?,
            );
            self.eat(b'L'); // Python 2 long suffix
            if !self.eat(b',') {
                self.expect(b')')?;
                return Ok(dims);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_parses_common_forms() {
        let h =
            parse_header("{'descr': '<f8', 'fortran_order': True, 'shape': (2, 3), }  \n").unwrap();
        assert_eq!(h.descr, "<f8");
        assert!(h.fortran_order);
        assert_eq!(h.shape, vec![2, 3]);
        let h = parse_header("{\"shape\":(5,),\"fortran_order\":False,\"descr\":\"|u1\"}").unwrap();
        assert_eq!(h.shape, vec![5]);
        assert!(
            parse_header("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': ()}").is_err()
        );
        assert!(parse_header("{'descr': '<f4', 'shape': (1,)}").is_err());
    }

    #[test]
    fn header_is_aligned() {
        for shape in [&[1usize, 2, 3][..], &[100000, 100000, 1]] {
            let h = header_bytes("<f4", shape);
            assert_eq!(h.len() % 64, 0);
            assert_eq!(*h.last().unwrap(), b'\n');
        }
    }

    #[test]
    fn dtypes_convert() {
        let d = Dtype::parse(">i2").unwrap();
        assert_eq!(d.read::<f64>(&[0xff, 0xfe]), -2.0);
        let d = Dtype::parse("<u2").unwrap();
        assert_eq!(d.read::<f64>(&[0x01, 0x02]), 513.0);
        let d = Dtype::parse("<i4").unwrap();
        assert_eq!(d.read::<f32>(&(-7i32).to_le_bytes()), -7.0);
        assert!(Dtype::parse("<c8").is_none());
        assert!(Dtype::parse("<f2").is_none());
    }

    #[test]
    fn fortran_transpose() {
        // shape (2, 3): Fortran data lists column by column.
        let f = [0, 3, 1, 4, 2, 5];
        assert_eq!(fortran_to_c(&f, &[2, 3]), vec![0, 1, 2, 3, 4, 5]);
    }
}
