//! Shared test motion (the crate's procedural walk).
#![allow(dead_code)]

pub use egoexo_synth::procedural::{FPS, walking_circle};
