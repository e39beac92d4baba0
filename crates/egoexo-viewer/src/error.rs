//! Everything the viewer can refuse or fail at; on the page each becomes a JS `Error` with this
//! message.

use thiserror::Error;

use crate::playback::PlaybackError;
use crate::scene::SceneError;

/// A viewer error.
#[derive(Debug, Error)]
pub enum ViewerError {
    #[error("backend preference must be \"auto\", \"webgpu\" or \"webgl2\", got {0:?}")]
    BadBackendPreference(String),
    #[error("WebGPU is not available: {0}")]
    NoWebGpu(String),
    #[error("WebGPU cannot present to a canvas here: {0} (use \"webgl2\" or \"auto\")")]
    WebGpuCannotPresent(String),
    #[error("WebGL2 is not available: {0}")]
    NoWebGl2(String),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Playback(#[from] PlaybackError),
    #[error("image size {width}×{height} px is not drawable: each side must be 1..={max} px")]
    BadSize { width: u32, height: u32, max: u32 },
    #[error("{what} must be a finite positive number, got {value}")]
    BadNumber { what: &'static str, value: f64 },
    #[error(
        "there is no observer {index} to look through: the scene has {count} (indices from 0; -1 for the orbit view)"
    )]
    NoSuchObserver { index: usize, count: usize },
    #[error("the GPU reported an error: {0}")]
    Gpu(String),
    #[error("the page refused: {0}")]
    Dom(String),
}

/// Which graphics API to ask for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendPreference {
    /// WebGPU when it really works (it can present to a canvas), else WebGL2.
    Auto,
    /// WebGPU only; an error when it is missing or cannot present.
    WebGpu,
    /// WebGL2 only.
    WebGl2,
    /// WebGPU without the presentation check (`"webgpu-unchecked"`), for tests and diagnosis:
    /// where presenting fails, the viewer's lost-device fallback to WebGL2 takes over.
    WebGpuUnchecked,
}

impl std::str::FromStr for BackendPreference {
    type Err = ViewerError;

    /// `"auto"`, `"webgpu"` or `"webgl2"` (case-insensitive, surrounding blanks ignored; an empty
    /// string means `auto`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" | "" => Ok(Self::Auto),
            "webgpu" => Ok(Self::WebGpu),
            "webgl2" | "webgl" => Ok(Self::WebGl2),
            "webgpu-unchecked" => Ok(Self::WebGpuUnchecked),
            _ => Err(ViewerError::BadBackendPreference(s.to_string())),
        }
    }
}

/// The graphics API a viewer draws with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActiveBackend {
    WebGpu,
    WebGl2,
}

impl ActiveBackend {
    /// `"webgpu"` or `"webgl2"`, as `Viewer.backend()` reports it.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::WebGpu => "webgpu",
            Self::WebGl2 => "webgl2",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn backend_preferences_parse() {
        assert_eq!("auto".parse::<BackendPreference>().unwrap(), BackendPreference::Auto);
        assert_eq!(" WebGPU ".parse::<BackendPreference>().unwrap(), BackendPreference::WebGpu);
        assert_eq!("webgl2".parse::<BackendPreference>().unwrap(), BackendPreference::WebGl2);
        assert_eq!("webgpu-unchecked".parse::<BackendPreference>().unwrap(), BackendPreference::WebGpuUnchecked);
        assert_eq!("".parse::<BackendPreference>().unwrap(), BackendPreference::Auto);
        let err = "vulkan".parse::<BackendPreference>().unwrap_err().to_string();
        assert!(err.contains("\"vulkan\"") && err.contains("\"webgl2\""), "{err}");
        assert_eq!(ActiveBackend::WebGl2.as_str(), "webgl2");
    }
}
