//! egoexo-mocap's integration tests: one binary, a module per area (docs/style.md).

// First: `require_cmu!` is in scope for the modules below it.
#[macro_use]
mod common;

mod bvh;
mod cmu_data;
mod cmu_extra;
mod malformed;
mod python_reads_library;
