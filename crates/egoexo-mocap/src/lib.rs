//! CMU motion capture retargeted to the SMPL skeleton: the project's motion library.
//!
//! Pipeline (each step a module, all working on in-memory text/bytes):
//! - [`asf`], [`amc`] — Acclaim skeleton and motion parsers (errors name file and line);
//! - [`kinematics`] — ASF/AMC forward kinematics in metres (`C · M · C⁻¹` per bone);
//! - [`retarget`] — the CMU→SMPL joint map and the fit of SMPL rotations to it;
//! - [`clean`] — corrupt-frame detection and resampling plans;
//! - [`catalog`] — `CMU_data.csv` (descriptions, true capture rates);
//! - [`import`] — one subject/trial from text to library clips;
//! - [`library`] — the `.safetensors` motion library and its loader;
//! - [`fs`] (native only) — finding CMU trees on disk, parallel import, library files.
//!
//! Conventions: metres, seconds, radians; Y-up world (the CMU capture volume, floor near
//! `y = 0`); SMPL's body frame faces +Z with the subject's left on +X, like CMU's rest pose.
//! Library clips are 30 fps on the SMPL mean-shape skeleton scaled to the subject's
//! standing head height.
//!
//! Credit: the CMU data was obtained from mocap.cs.cmu.edu; the database was created with
//! funding from NSF EIA-0196217.

pub mod amc;
pub mod asf;
pub mod bvh;
pub mod catalog;
pub mod clean;
pub mod error;
#[cfg(not(target_arch = "wasm32"))]
pub mod fs;
pub mod import;
pub mod kinematics;
pub mod library;
pub mod retarget;

pub use catalog::{Catalog, CatalogEntry};
pub use error::{ParseError, ParseErrorKind, SourceLocation};
pub use import::{ImportError, ImportOptions, LIBRARY_FPS, SubjectImporter, TrialImport};
pub use library::{ClipInfo, LibraryClip, LibraryError, MotionLibrary, RetargetStats, RetargetSummary};
pub use retarget::Retargeter;
