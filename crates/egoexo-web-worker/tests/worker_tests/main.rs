//! egoexo-web-worker's integration tests in one binary, a module per area. Every test binary links
//! the whole dependency tree, so one binary instead of one per file saves those links in a
//! clean build, and the areas' tests run side by side (docs/performance.md).

#[path = "../common/mod.rs"]
mod common;
mod detection;
mod live;
mod native;
mod participants;
