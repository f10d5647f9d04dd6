//! Choosing a DoV backend: `auto` takes a wgpu adapter when one exists, else the CPU ray caster.

use serde::{Deserialize, Serialize};

use super::{CpuBackend, DovBackend, GpuBackend};
use crate::error::{Error, Result};
use crate::scene::Scene;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BackendChoice {
    /// GPU when wgpu finds an adapter (a real GPU or Mesa's CPU drivers), else CPU.
    #[default]
    Auto,
    Gpu,
    Cpu,
}

impl std::str::FromStr for BackendChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            "gpu" => Ok(Self::Gpu),
            "cpu" => Ok(Self::Cpu),
            _ => Err(format!("unknown backend '{s}' (expected auto, gpu or cpu)")),
        }
    }
}

/// Builds the chosen backend for `scene` at `resolution`. `auto` falls back to the CPU when the
/// GPU backend cannot start (no adapter, or the scene exceeds the device's limits).
pub fn create_backend(choice: BackendChoice, scene: &Scene, resolution: u32) -> Result<Box<dyn DovBackend>> {
    if !(1..=4096).contains(&resolution) {
        return Err(Error::bad_arg("--resolution", format!("{resolution} is outside 1..=4096 texels per face edge")));
    }
    match choice {
        BackendChoice::Cpu => Ok(Box::new(CpuBackend::new(scene, resolution)?)),
        BackendChoice::Gpu => Ok(Box::new(GpuBackend::new(scene, resolution)?)),
        BackendChoice::Auto => match GpuBackend::new(scene, resolution) {
            Ok(gpu) => Ok(Box::new(gpu)),
            Err(_) => Ok(Box::new(CpuBackend::new(scene, resolution)?)),
        },
    }
}
