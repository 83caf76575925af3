//! TensorBoard event files: the scalars of `metrics.csv` and `validation.csv`, readable by
//! `tensorboard --logdir RUN_DIR`.
//!
//! No well-kept crate writes them (tensorboard-rs is unmaintained and pulls protobuf 2 and an old
//! image crate), and the format is small: a file of TFRecords (`u64` length, masked CRC-32C of
//! the length, the bytes, masked CRC-32C of the bytes), each holding a protobuf `Event`
//! (`tensorflow/core/util/event.proto`): `wall_time` (1, double), `step` (2, int64) and either
//! `file_version` (3, string), a `Summary` (5) of `Value`s with `tag` (1, string) and
//! `simple_value` (2, float), or a `SessionLog` (7) with its `status` (1).
//!
//! A resumed run opens a new file that starts with a `SessionLog` START event at the first step
//! it will log: TensorBoard then drops the events from that step on written by the interrupted
//! run (it keeps those with a smaller step), so the curves read as one run, like the CSV logs.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use crate::TrainError;

/// An open TensorBoard event file.
pub struct EventWriter {
    path: PathBuf,
    file: BufWriter<File>,
}

impl EventWriter {
    /// Creates a new event file in `dir` (`events.out.tfevents.<seconds>.<pid>.seasonstereo`).
    /// With `resumed_at = Some(step)` (the checkpoint's step) it first records a session restart
    /// at `step + 1`, the first step the resumed run logs.
    pub fn create(dir: &Path, resumed_at: Option<usize>) -> Result<Self, TrainError> {
        let now = wall_time();
        let name = format!(
            "events.out.tfevents.{}.{}.seasonstereo",
            now as u64,
            std::process::id()
        );
        let path = dir.join(name);
        let file = File::create(&path).map_err(|e| TrainError::io(&path, e))?;
        let mut writer = Self {
            path,
            file: BufWriter::new(file),
        };
        let mut version = event_header(now, 0);
        put_bytes(&mut version, 3, b"brain.Event:2");
        writer.write_record(&version)?;
        if let Some(step) = resumed_at {
            // SessionLog { status (1) = START (1) } in Event field 7.
            let mut session_log = Vec::new();
            put_varint_field(&mut session_log, 1, 1);
            let mut event = event_header(now, step + 1);
            put_bytes(&mut event, 7, &session_log);
            writer.write_record(&event)?;
        }
        writer.flush()?;
        Ok(writer)
    }

    /// The file written to.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Records `values` (tag, value) at `step` as one event, and flushes it (a run killed
    /// midway keeps every event logged before).
    pub fn scalars(&mut self, step: usize, values: &[(&str, f64)]) -> Result<(), TrainError> {
        let mut summary = Vec::new();
        for (tag, value) in values {
            let mut v = Vec::new();
            put_bytes(&mut v, 1, tag.as_bytes());
            put_key(&mut v, 2, WIRE_FIXED32);
            v.extend_from_slice(&(*value as f32).to_le_bytes());
            put_bytes(&mut summary, 1, &v);
        }
        let mut event = event_header(wall_time(), step);
        put_bytes(&mut event, 5, &summary);
        self.write_record(&event)?;
        self.flush()
    }

    fn write_record(&mut self, data: &[u8]) -> Result<(), TrainError> {
        let framed = tf_record(data);
        self.file
            .write_all(&framed)
            .map_err(|e| TrainError::io(&self.path, e))
    }

    fn flush(&mut self) -> Result<(), TrainError> {
        self.file.flush().map_err(|e| TrainError::io(&self.path, e))
    }
}

fn wall_time() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

const WIRE_VARINT: u8 = 0;
const WIRE_FIXED64: u8 = 1;
const WIRE_BYTES: u8 = 2;
const WIRE_FIXED32: u8 = 5;

/// `Event.wall_time` and `Event.step`.
fn event_header(wall_time: f64, step: usize) -> Vec<u8> {
    let mut e = Vec::new();
    put_key(&mut e, 1, WIRE_FIXED64);
    e.extend_from_slice(&wall_time.to_le_bytes());
    put_varint_field(&mut e, 2, step as u64);
    e
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8 & 0x7f) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn put_key(out: &mut Vec<u8>, field: u32, wire: u8) {
    put_varint(out, (u64::from(field) << 3) | u64::from(wire));
}

fn put_varint_field(out: &mut Vec<u8>, field: u32, v: u64) {
    put_key(out, field, WIRE_VARINT);
    put_varint(out, v);
}

fn put_bytes(out: &mut Vec<u8>, field: u32, bytes: &[u8]) {
    put_key(out, field, WIRE_BYTES);
    put_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

/// TFRecord framing of one record.
fn tf_record(data: &[u8]) -> Vec<u8> {
    let len = (data.len() as u64).to_le_bytes();
    let mut out = Vec::with_capacity(data.len() + 16);
    out.extend_from_slice(&len);
    out.extend_from_slice(&masked_crc(&len).to_le_bytes());
    out.extend_from_slice(data);
    out.extend_from_slice(&masked_crc(data).to_le_bytes());
    out
}

/// TFRecord's masked CRC-32C.
fn masked_crc(data: &[u8]) -> u32 {
    let crc = crc32c::crc32c(data);
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One protobuf field: (number, wire type, varint value or payload bytes).
    type Field = (u32, u8, u64, Vec<u8>);

    fn varint(b: &[u8], i: &mut usize) -> u64 {
        let (mut v, mut shift) = (0u64, 0);
        loop {
            let byte = b[*i];
            *i += 1;
            v |= u64::from(byte & 0x7f) << shift;
            if byte < 0x80 {
                return v;
            }
            shift += 7;
        }
    }

    /// A reader written from the protobuf encoding rules, independent of the writer's helpers.
    fn fields(b: &[u8]) -> Vec<Field> {
        let mut i = 0;
        let mut out = Vec::new();
        while i < b.len() {
            let key = varint(b, &mut i);
            let (field, wire) = ((key >> 3) as u32, (key & 7) as u8);
            let (v, bytes) = match wire {
                0 => (varint(b, &mut i), Vec::new()),
                1 => (0, b[i..i + 8].to_vec()),
                2 => {
                    let n = varint(b, &mut i) as usize;
                    (0, b[i..i + n].to_vec())
                }
                5 => (0, b[i..i + 4].to_vec()),
                w => panic!("wire type {w}"),
            };
            i += match wire {
                1 => 8,
                2 => bytes.len(),
                5 => 4,
                _ => 0,
            };
            out.push((field, wire, v, bytes));
        }
        out
    }

    fn records(file: &[u8]) -> Vec<Vec<u8>> {
        let mut i = 0;
        let mut out = Vec::new();
        while i < file.len() {
            let len_bytes = &file[i..i + 8];
            let n = u64::from_le_bytes(len_bytes.try_into().unwrap()) as usize;
            let crc = u32::from_le_bytes(file[i + 8..i + 12].try_into().unwrap());
            assert_eq!(crc, masked_crc(len_bytes));
            let data = file[i + 12..i + 12 + n].to_vec();
            let crc = u32::from_le_bytes(file[i + 12 + n..i + 16 + n].try_into().unwrap());
            assert_eq!(crc, masked_crc(&data));
            out.push(data);
            i += 16 + n;
        }
        out
    }

    #[test]
    fn crc32c_and_mask_match_tensorflow() {
        // CRC-32C check value (RFC 3720) and TensorBoard's `masked_crc32c` of the same bytes.
        assert_eq!(crc32c::crc32c(b"123456789"), 0xe306_9283);
        assert_eq!(masked_crc(b"123456789"), 0xc78a_b0e5);
    }

    #[test]
    fn events_decode_as_tensorboard_reads_them() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = EventWriter::create(dir.path(), Some(7)).unwrap();
        w.scalars(8, &[("train/total", 0.25), ("train/lr", 5e-4)])
            .unwrap();
        let bytes = std::fs::read(w.path()).unwrap();
        assert!(w
            .path()
            .file_name()
            .unwrap()
            .to_str()
            .unwrap()
            .contains("tfevents"));
        let recs = records(&bytes);
        assert_eq!(recs.len(), 3);

        let version = fields(&recs[0]);
        assert_eq!(version[0].0, 1); // wall_time
        assert_eq!(version[1].0, 2); // step
        assert_eq!(version[2], (3, 2, 0, b"brain.Event:2".to_vec()));

        // Resumed after step 7: TensorBoard drops the old events of steps ≥ 8.
        let restart = fields(&recs[1]);
        assert_eq!((restart[1].0, restart[1].2), (2, 8));
        assert_eq!(restart[2].0, 7);
        assert_eq!(fields(&restart[2].3), vec![(1, 0, 1, Vec::new())]);

        let event = fields(&recs[2]);
        assert_eq!((event[1].0, event[1].2), (2, 8));
        assert_eq!(event[2].0, 5);
        let values: Vec<(String, f32)> = fields(&event[2].3)
            .into_iter()
            .map(|(field, _, _, v)| {
                assert_eq!(field, 1);
                let f = fields(&v);
                (
                    String::from_utf8(f[0].3.clone()).unwrap(),
                    f32::from_le_bytes(f[1].3.clone().try_into().unwrap()),
                )
            })
            .collect();
        assert_eq!(
            values,
            vec![("train/total".into(), 0.25), ("train/lr".into(), 5e-4)]
        );
    }
}
