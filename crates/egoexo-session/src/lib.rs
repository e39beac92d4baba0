//! Sessions in, motion out.
//!
//! - [`model`] — the in-memory session (wearer, observers, keypoints, subject, ground truth).
//! - [`align`] — every stream resampled onto one timeline.
//!
//! Everything works on in-memory bytes so the browser's worker can use it; path helpers are
//! native-only.

pub mod align;
pub mod model;
