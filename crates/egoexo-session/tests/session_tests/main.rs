//! egoexo-session's integration tests: one binary, a module per area (docs/style.md).

mod capture_format;
mod fixtures;
mod malformed;
mod placement;
mod real_aria;
mod roundtrip;
mod schema;
#[path = "../support/mod.rs"]
mod support;
