//! egoexo-web-worker's integration tests: one binary, a module per area (docs/style.md).

#[path = "../common/mod.rs"]
mod common;
mod detection;
mod live;
mod native;
mod participants;
