//! egoexo-session's integration tests in one binary, a module per area. Every test binary links
//! the whole dependency tree, so one binary instead of one per file saves those links in a
//! clean build, and the areas' tests run side by side (docs/performance.md).

mod capture_format;
mod fixtures;
mod malformed;
mod placement;
mod real_aria;
mod roundtrip;
mod schema;
#[path = "../support/mod.rs"]
mod support;
