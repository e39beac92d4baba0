//! egoexo-cli's integration tests: one binary, a module per area (docs/style.md).

mod common;
mod detect;
mod docs_flags;
mod live;
mod mocap;
mod participants;
mod pipeline;
mod register;
mod serve;
mod sessions;
