//! egoexo-core's integration tests: one binary, a module per area (docs/style.md).

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
