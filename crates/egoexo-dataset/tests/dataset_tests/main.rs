//! egoexo-dataset's integration tests: one binary, a module per area (docs/style.md).

mod dataset;
mod group;
