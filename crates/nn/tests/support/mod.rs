//! Reading the upstream parity fixtures (the `fixtures/*` data sets, see `testdata`) in place.
#![allow(dead_code)]

pub mod tiny;

use std::path::PathBuf;

use std::collections::HashMap;

use burn::tensor::{Device, Tensor, TensorData};
use safetensors::{Dtype, SafeTensors};

/// Folder of a fixture set, e.g. `fixture_dir("fixtures/monsterpp-tiny")`, for a test that
/// started with `testdata::require!` of that set.
pub fn fixture_dir(set: &str) -> PathBuf {
    testdata::checked(set)
}

/// All tensors of a safetensors file as (shape, f32 values); F16/BF16/F32 are converted, integer
/// tensors are skipped.
pub fn read_all(path: &std::path::Path) -> Vec<(String, Vec<usize>, Vec<f32>)> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let st = SafeTensors::deserialize(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = Vec::new();
    for (name, view) in st.tensors() {
        let data = view.data();
        let values: Vec<f32> = match view.dtype() {
            Dtype::F32 => data
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            Dtype::F16 => data
                .chunks_exact(2)
                .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            Dtype::BF16 => data
                .chunks_exact(2)
                .map(|b| half::bf16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            _ => continue,
        };
        out.push((name, view.shape().to_vec(), values));
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// One tensor of a fixture file by name, as (shape, values).
pub fn tensor(fixture: &str, file: &str, name: &str) -> (Vec<usize>, Vec<f32>) {
    let path = fixture_dir(fixture).join(file);
    read_all(&path)
        .into_iter()
        .find(|(n, _, _)| n == name)
        .map(|(_, s, v)| (s, v))
        .unwrap_or_else(|| panic!("{} has no tensor {name}", path.display()))
}

/// Max absolute difference and the max absolute reference value (for relative checks).
pub fn max_abs_diff(got: &[f32], want: &[f32]) -> (f32, f32) {
    assert_eq!(got.len(), want.len(), "lengths differ");
    let diff = got
        .iter()
        .zip(want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    let scale = want.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
    (diff, scale)
}

/// The reference tensors of a fixture set, loaded once, handed out as burn tensors on `device`.
pub struct Fixture {
    pub tensors: HashMap<String, (Vec<usize>, Vec<f32>)>,
    pub device: Device,
}

impl Fixture {
    /// `tensors.safetensors` of fixture set `name`, on the flex CPU device.
    pub fn load(name: &str) -> Self {
        let path = fixture_dir(name).join("tensors.safetensors");
        let tensors = read_all(&path)
            .into_iter()
            .map(|(n, s, v)| (n, (s, v)))
            .collect();
        Self {
            tensors,
            device: Device::flex(),
        }
    }

    pub fn raw(&self, name: &str) -> &(Vec<usize>, Vec<f32>) {
        self.tensors
            .get(name)
            .unwrap_or_else(|| panic!("fixture has no tensor {name}"))
    }

    /// Tensor `name` with its rank checked.
    pub fn t<const N: usize>(&self, name: &str) -> Tensor<N> {
        let (shape, values) = self.raw(name);
        assert_eq!(shape.len(), N, "{name}: rank {} expected {N}", shape.len());
        Tensor::from_data(TensorData::new(values.clone(), shape.clone()), &self.device)
    }

    /// `2·img/255 − 1` of `input.left` / `input.right`, as the network normalises its inputs.
    pub fn image(&self, side: &str) -> Tensor<4> {
        self.t::<4>(&format!("input.{side}"))
            .div_scalar(255.0)
            .mul_scalar(2.0)
            .sub_scalar(1.0)
    }
}

/// Rewrites the `weights.safetensors` of fixture set `fixture` into `path` through `edit`, which
/// may drop a tensor (None) or change its shape and bytes: for load-error tests.
pub fn write_edited_weights(
    fixture: &str,
    path: &std::path::Path,
    edit: impl Fn(&str, Vec<usize>, Vec<u8>) -> Option<(Vec<usize>, Vec<u8>)>,
) {
    let bytes = std::fs::read(fixture_dir(fixture).join("weights.safetensors")).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let mut owned: Vec<(String, Dtype, Vec<usize>, Vec<u8>)> = Vec::new();
    for (name, view) in st.tensors() {
        if let Some((shape, data)) = edit(&name, view.shape().to_vec(), view.data().to_vec()) {
            owned.push((name, view.dtype(), shape, data));
        }
    }
    let views: Vec<(String, safetensors::tensor::TensorView)> = owned
        .iter()
        .map(|(n, d, s, b)| {
            (
                n.clone(),
                safetensors::tensor::TensorView::new(*d, s.clone(), b).unwrap(),
            )
        })
        .collect();
    std::fs::write(path, safetensors::serialize(views, None).unwrap()).unwrap();
}

/// Prints each prediction's max abs error against its slice of `reference` (the fixture's
/// `output.disp_preds`, all predictions stacked), to see where the error grows along the
/// iterations.
pub fn print_prediction_errors(preds: &[Tensor<4>], reference: &[f32]) {
    let per = reference.len() / preds.len();
    for (i, p) in preds.iter().enumerate() {
        let got: Vec<f32> = p.to_data().try_to_vec::<f32>().unwrap();
        let (e, _) = max_abs_diff(&got, &reference[i * per..(i + 1) * per]);
        println!("  disp_preds[{i:2}] max abs err {e:.3e}");
    }
}
