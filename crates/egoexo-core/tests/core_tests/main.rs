//! egoexo-core's integration tests in one binary, a module per area. Every test binary links
//! the whole dependency tree, so one binary instead of one per file saves those links in a
//! clean build, and the areas' tests run side by side (docs/performance.md).

#[cfg(target_arch = "wasm32")]
wasm_bindgen_test::wasm_bindgen_test_configure!(run_in_browser);

mod cameras;
#[path = "../common/mod.rs"]
mod common;
mod ego_features;
mod fk_parity_fixture;
mod metrics;
mod rays;
mod region;
mod rotations;
mod skeleton;
mod xr;
