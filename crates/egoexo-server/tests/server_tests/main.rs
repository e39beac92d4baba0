//! egoexo-server's integration tests: one binary, a module per area (docs/style.md).

mod api;
mod live;
