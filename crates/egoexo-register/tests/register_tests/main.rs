//! egoexo-register's integration tests: one binary, a module per area (docs/style.md).

mod live;
mod register;
