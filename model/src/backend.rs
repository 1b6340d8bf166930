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

    /// The device of this backend, or why it is not available in this build.
    pub fn device(self) -> Result<Device, String> {
        match self {
            Backend::Flex => Ok(Device::flex()),
            #[allow(deprecated)]
            Backend::Ndarray => Ok(Device::ndarray()),
            #[cfg(feature = "wgpu")]
            Backend::Wgpu => Ok(Device::wgpu(Default::default())),
            #[cfg(not(feature = "wgpu"))]
            Backend::Wgpu => Err("backend `wgpu` needs a build with `--features wgpu`".into()),
        }
    }
}
