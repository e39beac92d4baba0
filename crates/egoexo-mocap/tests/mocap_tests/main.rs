//! egoexo-mocap's integration tests in one binary, a module per area. Every test binary links
//! the whole dependency tree, so one binary instead of one per file saves those links in a
//! clean build, and the areas' tests run side by side (docs/performance.md).

// First: `require_cmu!` is in scope for the modules below it.
#[macro_use]
mod common;

mod bvh;
mod cmu_data;
mod cmu_extra;
mod malformed;
mod python_reads_library;
