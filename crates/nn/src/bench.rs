//! Workloads of `seasonstereo bench`: one forward pass of a network with random weights on
//! random inputs, built once and run many times. Reading the output back forces the (possibly
//! lazy or asynchronous) computation, so a run's time is the pass's.

use burn::tensor::{Device, Distribution, Tensor};

use crate::config::MonsterConfig;
use crate::dinov3::{Dinov3Config, Dinov3Vit};
use crate::monster::Monster;
use crate::segformer::{Segformer, SegformerConfig};

/// One run of a workload.
pub type Workload = Box<dyn FnMut() -> Result<(), String>>;

fn force(t: Tensor<4>) -> Result<(), String> {
    t.into_data()
        .try_into_vec_as::<f32>()
        .map(|_| ())
        .map_err(|e| format!("reading the output: {e:?}"))
}

/// MonSter++ `preset` on an `height × width` pair, `iters` refinement iterations (inference).
pub fn monster(
    preset: &str,
    height: usize,
    width: usize,
    iters: usize,
    max_disp: Option<usize>,
    device: &Device,
) -> Result<Workload, String> {
    let mut config = MonsterConfig::preset(preset).map_err(|e| e.to_string())?;
    if let Some(d) = max_disp {
        config.max_disp = d;
    }
    config.validate().map_err(|e| e.to_string())?;
    if iters < 7 {
        return Err(format!(
            "MonSter++ needs at least 7 iterations (its last 7 are dual-branch), got {iters}"
        ));
    }
    let model = Monster::new(&config, device);
    let input = || {
        Tensor::<4>::random(
            [1, 3, height, width],
            Distribution::Uniform(0.0, 255.0),
            device,
        )
    };
    let (l, r) = (input(), input());
    Ok(Box::new(move || {
        force(model.forward(l.clone(), r.clone(), iters, true).disp)
    }))
}

/// SegFormer `preset` (`mit-b2`, the release's OpenEarthMap model, or `tiny`) on one
/// `size × size` image.
pub fn segformer(preset: &str, size: usize, device: &Device) -> Result<Workload, String> {
    let config = match preset {
        "mit-b2" | "mit_b2" => SegformerConfig::mit_b2(9),
        "tiny" => SegformerConfig::tiny(),
        other => return Err(format!("unknown SegFormer preset {other:?} (mit-b2, tiny)")),
    };
    let model = Segformer::new(&config, device);
    let x = Tensor::<4>::random([1, 3, size, size], Distribution::Normal(0.0, 1.0), device);
    Ok(Box::new(move || force(model.forward(x.clone()))))
}

/// DINOv3 ViT `preset` (`vits16`, `vitb16`, `vitl16`, `tiny`) on a `batch` of `size × size`
/// crops (curation's descriptor).
pub fn dinov3(
    preset: &str,
    size: usize,
    batch: usize,
    device: &Device,
) -> Result<Workload, String> {
    let config = Dinov3Config::preset(preset).ok_or_else(|| {
        format!("unknown DINOv3 preset {preset:?} (vits16, vitb16, vitl16, tiny)")
    })?;
    config.validate().map_err(|e| e.to_string())?;
    let model = Dinov3Vit::new(&config, device);
    let x = Tensor::<4>::random(
        [batch, 3, size, size],
        Distribution::Normal(0.0, 1.0),
        device,
    );
    Ok(Box::new(move || {
        let pooled = Dinov3Vit::pooler(model.forward(x.clone()));
        pooled
            .into_data()
            .try_into_vec_as::<f32>()
            .map(|_| ())
            .map_err(|e| format!("reading the output: {e:?}"))
    }))
}
