//! egoexo-infer's integration tests: one binary, a module per area (docs/style.md).

mod common;
mod cost;
mod detector;
mod engine;
mod live_models;
mod parity;
mod passes;
mod training_python;
