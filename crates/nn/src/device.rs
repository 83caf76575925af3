//! Where a network runs. The command line parses the user's word once into a [`DeviceChoice`];
//! every stage that loads a network takes that typed choice and asks it for burn's device.

use std::fmt;
use std::str::FromStr;

pub use burn::tensor::Device;

/// The backend a network runs on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DeviceChoice {
    /// The best backend compiled in: CUDA, then wgpu, then the CPU.
    #[default]
    Auto,
    /// burn's pure-Rust CPU backend (`flex`).
    Cpu,
    /// wgpu (Vulkan, Metal, DX12); needs the `wgpu` build feature.
    Wgpu,
    /// CUDA; needs the `cuda` build feature.
    Cuda,
}

impl DeviceChoice {
    /// The words [`FromStr`] accepts, for help texts.
    pub const NAMES: [&'static str; 4] = ["auto", "cpu", "wgpu", "cuda"];

    /// The word of this choice.
    pub fn name(self) -> &'static str {
        match self {
            DeviceChoice::Auto => "auto",
            DeviceChoice::Cpu => "cpu",
            DeviceChoice::Wgpu => "wgpu",
            DeviceChoice::Cuda => "cuda",
        }
    }

    /// burn's device, or why this build cannot give it.
    pub fn device(self) -> Result<Device, String> {
        match self {
            DeviceChoice::Auto => Ok(default_device()),
            DeviceChoice::Cpu => Ok(Device::flex()),
            #[cfg(feature = "wgpu")]
            DeviceChoice::Wgpu => Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice)),
            #[cfg(not(feature = "wgpu"))]
            DeviceChoice::Wgpu => Err(not_compiled_in("wgpu")),
            #[cfg(feature = "cuda")]
            DeviceChoice::Cuda => Ok(Device::cuda(0)),
            #[cfg(not(feature = "cuda"))]
            DeviceChoice::Cuda => Err(not_compiled_in("cuda")),
        }
    }
}

impl FromStr for DeviceChoice {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(DeviceChoice::Auto),
            "cpu" | "flex" => Ok(DeviceChoice::Cpu),
            "wgpu" => Ok(DeviceChoice::Wgpu),
            "cuda" => Ok(DeviceChoice::Cuda),
            other => Err(format!(
                "unknown device {other:?} (expected auto, cpu, wgpu or cuda)"
            )),
        }
    }
}

impl fmt::Display for DeviceChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Runs `pass` (a network's forward, a training step) on a thread of rayon's pool when `device`
/// is the CPU; elsewhere, or already on a pool thread, right here.
///
/// Why: every CPU kernel splits its work over the pool. Called from outside it, each of the
/// thousands of operations of a pass hands all its pieces over and puts the calling thread to
/// sleep until they are done (a futex wait and wake every time, a visible share of a training
/// step: BENCHMARKS.md, "SegFormer and the training step against PyTorch");
/// called from a pool thread, the operation runs its first piece right there and the other
/// threads steal the rest.
pub fn on_cpu_pool<R: Send>(device: &Device, pass: impl FnOnce() -> R + Send) -> R {
    if *device == Device::flex() {
        rayon::scope(|_| pass())
    } else {
        pass()
    }
}

/// Why a GPU backend named on the command line cannot be used, and how to get it.
#[allow(dead_code)] // unused when both GPU features are compiled in
fn not_compiled_in(backend: &str) -> String {
    format!("the {backend} backend is not compiled in: rebuild with `--features {backend}`")
}

/// The best compiled device: CUDA, then wgpu, then the CPU.
#[allow(unreachable_code)]
pub fn default_device() -> Device {
    #[cfg(feature = "cuda")]
    return Device::cuda(0);
    #[cfg(feature = "wgpu")]
    return Device::wgpu(burn::tensor::DeviceKind::DefaultDevice);
    Device::flex()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_round_trip_and_unknown_ones_are_refused() {
        for name in DeviceChoice::NAMES {
            assert_eq!(name.parse::<DeviceChoice>().unwrap().name(), name);
        }
        assert_eq!("flex".parse::<DeviceChoice>(), Ok(DeviceChoice::Cpu));
        assert!("tpu".parse::<DeviceChoice>().unwrap_err().contains("tpu"));
        assert!(DeviceChoice::Cpu.device().is_ok());
    }

    #[test]
    fn cpu_passes_run_on_a_pool_thread() {
        let cpu = Device::flex();
        assert!(rayon::current_thread_index().is_none());
        assert!(on_cpu_pool(&cpu, rayon::current_thread_index).is_some());
        assert!(on_cpu_pool(&cpu.clone().autodiff(), rayon::current_thread_index).is_some());
    }
}
