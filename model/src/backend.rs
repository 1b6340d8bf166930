//! Which Burn backend runs the network: the one choice shared by `train` and `infer`.

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

/// Tensor backend that runs the network.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// Burn's pure-Rust CPU backend (default; fastest on CPU).
    #[default]
    Flex,
    /// burn-ndarray (deprecated upstream; slow convolution backward).
    Ndarray,
    /// burn-wgpu (needs the `wgpu` cargo feature and a GPU adapter).
    Wgpu,
}

impl Backend {
    /// Parses `flex`, `ndarray` or `wgpu` (as written in configs and on command lines).
    pub fn parse(name: &str) -> Result<Self, String> {
        match name {
            "flex" => Ok(Backend::Flex),
            "ndarray" => Ok(Backend::Ndarray),
            "wgpu" => Ok(Backend::Wgpu),
            other => Err(format!(
                "unknown backend `{other}` (expected flex, ndarray or wgpu)"
            )),
        }
    }

    /// What a run on `device` of this backend should tell its user, if anything: for wgpu, the
    /// adapter's name, and a warning when it is a software rasterizer (lavapipe, llvmpipe,
    /// WARP), which runs the kernels on the CPU far slower than flex. Opens the device.
    pub fn adapter_note(self, device: &Device) -> Option<String> {
        match self {
            Backend::Flex | Backend::Ndarray => None,
            #[cfg(feature = "wgpu")]
            Backend::Wgpu => device.identity().map(|identity| {
                let software = if identity.physical.is_none() {
                    " (a software rasterizer on the CPU: backend `flex` is far faster)"
                } else {
                    ""
                };
                format!("wgpu adapter: {}{software}", identity.name)
            }),
            #[cfg(not(feature = "wgpu"))]
            Backend::Wgpu => {
                let _ = device;
                None
            }
        }
    }

    /// The device of this backend, or why it is not available in this build.
    pub fn device(self) -> Result<Device, String> {
        match self {
            Backend::Flex => Ok(Device::flex()),
            #[allow(deprecated)]
            Backend::Ndarray => Ok(Device::ndarray()),
            #[cfg(feature = "wgpu")]
            Backend::Wgpu => wgpu_device(),
            #[cfg(not(feature = "wgpu"))]
            Backend::Wgpu => Err("backend `wgpu` needs a build with the `wgpu` feature: \
                                  cargo build --release -p train -p infer --features model/wgpu"
                .into()),
        }
    }
}

/// The wgpu device on the adapter wgpu's heuristics pick (a high-power GPU first), or an error
/// when the machine has no adapter at all: burn opens the device lazily and would otherwise
/// panic at the first tensor operation, after the dataset has been read.
#[cfg(feature = "wgpu")]
fn wgpu_device() -> Result<Device, String> {
    if Device::enumerate(burn::tensor::DeviceType::Wgpu).is_empty() {
        return Err(
            "backend `wgpu` found no graphics adapter (Vulkan, Metal, DirectX 12 or \
                    OpenGL) on this machine: install the GPU's driver, or use backend `flex`"
                .into(),
        );
    }
    Ok(Device::wgpu(Default::default()))
}
