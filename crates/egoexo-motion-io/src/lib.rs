//! SMPL motion files in and out: what the CLI and the browser's worker export, and what the
//! motion library and the tests read back.
//!
//! Every reader and writer works in memory (no paths, no clock, no threads), so the CLI and
//! the browser's worker call the same code: [`write()`] with a [`Format`], usually from a file
//! name's extension ([`Format::from_path`]).
//!
//! | format | module | world axes | units | what it holds |
//! |---|---|---|---|---|
//! | AMASS `.npz` | [`amass`] | **Z up** (AMASS's world) | metres, radians | SMPL `poses` (N,72), `trans`, `betas`, `gender`, `mocap_framerate` |
//! | `.bvh` | [`smpl_bvh`] | Y up (this project's world) | metres (or centimetres by option) | SMPL hierarchy, per-joint Euler channels in degrees |
//! | `.glb` | [`gltf`] | Y up, +Z forward (glTF's) | metres | skinned bone mesh, 24 joint nodes, animation |
//! | `.csv` | [`csv`] | Y up (this project's world) | metres, seconds | 24 joint positions per frame |
//!
//! Below them: [`bvh`], a general BVH reader and writer (any hierarchy; the CMU importer
//! reads BVH trials with it), and [`npz`], the one `.npz` writer (AMASS files, `.egoexo`
//! sessions and training shards all use it). Euler angles follow `egoexo_core::euler`.
//!
//! The project's own world is Y up (gravity along −Y), metres; the SMPL body frame faces +Z
//! with the subject's left on +X (see `egoexo_core::skeleton`). `docs/exports.md` describes
//! each format for users.

pub mod amass;
pub mod bvh;
pub mod csv;
pub mod gltf;
pub mod npz;
pub mod smpl_bvh;

use std::fmt;
use std::str::FromStr;

use egoexo_core::SmplMotion;
use thiserror::Error;

/// A file format the exporters write.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// AMASS-style SMPL parameters, a NumPy `.npz` archive ([`amass`]).
    Npz,
    /// Biovision hierarchy with the SMPL skeleton ([`smpl_bvh`]).
    Bvh,
    /// glTF 2.0 binary: skeleton, bone mesh and animation ([`gltf`]).
    Glb,
    /// Joint positions, one row per frame ([`csv`]).
    Csv,
}

impl Format {
    /// Every format, in the order the CLI lists them.
    pub const ALL: [Format; 4] = [Format::Npz, Format::Bvh, Format::Glb, Format::Csv];

    /// The file extension, without a dot.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Npz => "npz",
            Format::Bvh => "bvh",
            Format::Glb => "glb",
            Format::Csv => "csv",
        }
    }

    /// The media type, for browser downloads.
    pub fn mime_type(self) -> &'static str {
        match self {
            Format::Npz => "application/zip",
            Format::Bvh => "text/plain",
            Format::Glb => "model/gltf-binary",
            Format::Csv => "text/csv",
        }
    }

    /// The format for an extension (`"bvh"`, `".BVH"`, …), ASCII case ignored.
    pub fn from_extension(extension: &str) -> Option<Format> {
        let ext = extension.strip_prefix('.').unwrap_or(extension);
        Format::ALL.into_iter().find(|f| f.extension().eq_ignore_ascii_case(ext))
    }

    /// The format for a file name or path (`/` or `\` separated), from its extension.
    pub fn from_path(path: &str) -> Result<Format, ExportError> {
        let name = path.rsplit(['/', '\\']).next().unwrap_or(path);
        name.rsplit_once('.')
            .filter(|(stem, _)| !stem.is_empty())
            .and_then(|(_, ext)| Format::from_extension(ext))
            .ok_or_else(|| ExportError::UnknownFormat(path.to_string()))
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.extension())
    }
}

impl FromStr for Format {
    type Err = ExportError;

    /// Parses an extension (`"glb"`) or a file name (`"walk.glb"`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Format::from_extension(s).map_or_else(|| Format::from_path(s), Ok)
    }
}

/// Why a motion could not be exported.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ExportError {
    #[error("unknown export format for `{0}`: expected a file ending in .npz, .bvh, .glb or .csv")]
    UnknownFormat(String),
    #[error("the motion has no frames: nothing to export")]
    EmptyMotion,
    #[error("the motion's frame rate must be positive and finite, got {0}")]
    InvalidFps(f32),
    #[error("the motion's pose at frame {frame} is not finite")]
    NonFinitePose { frame: usize },
    #[error("the motion's skeleton has a non-finite rest joint {joint}")]
    NonFiniteSkeleton { joint: usize },
    #[error("the motion's betas must be 1 to 300 finite numbers, got {got} values{}", if *.finite { "" } else { " (not all finite)" })]
    InvalidBetas { got: usize, finite: bool },
    #[error("the motion has {frames} frames; {format} export supports at most {limit}")]
    TooManyFrames { format: Format, frames: usize, limit: usize },
    /// An encoder failed on an in-memory buffer (not expected to happen).
    #[error("encoding {format}: {message}")]
    Encode { format: Format, message: String },
}

/// Writes `motion` in `format`.
pub fn write(format: Format, motion: &SmplMotion) -> Result<Vec<u8>, ExportError> {
    match format {
        Format::Npz => amass::write_npz(motion),
        Format::Bvh => smpl_bvh::write_bvh(motion, &smpl_bvh::BvhOptions::default()),
        Format::Glb => gltf::write_glb(motion),
        Format::Csv => csv::write_csv(motion),
    }
}

/// Checks what every exporter relies on: frames, a valid rate, finite poses and skeleton,
/// sensible betas. (`SmplMotion`'s fields are public, so a motion may not have come through
/// `SmplMotion::new`.)
pub fn validate(motion: &SmplMotion) -> Result<(), ExportError> {
    if motion.poses.is_empty() {
        return Err(ExportError::EmptyMotion);
    }
    if !(motion.fps.is_finite() && motion.fps > 0.0) {
        return Err(ExportError::InvalidFps(motion.fps));
    }
    if let Some(joint) = motion.skeleton.rest_joints().iter().position(|p| !p.is_finite()) {
        return Err(ExportError::NonFiniteSkeleton { joint });
    }
    if let Some(frame) = motion.poses.iter().position(|p| !p.is_finite()) {
        return Err(ExportError::NonFinitePose { frame });
    }
    if let Some(b) = &motion.betas {
        let finite = b.iter().all(|v| v.is_finite());
        if b.is_empty() || b.len() > 300 || !finite {
            return Err(ExportError::InvalidBetas { got: b.len(), finite });
        }
    }
    Ok(())
}

/// Seconds of frame `i` after the motion's first frame.
pub(crate) fn frame_time_s(motion: &SmplMotion, i: usize) -> f64 {
    i as f64 / f64::from(motion.fps)
}

#[cfg(test)]
mod test_motion {
    //! A deterministic, varied test motion: every joint moves, the root walks and turns.

    use egoexo_core::SmplMotion;
    use egoexo_core::glam::{Quat, Vec3};
    use egoexo_core::rotation::quat_from_axis_angle;
    use egoexo_core::skeleton::{NUM_BODY_JOINTS, SmplPose, SmplSkeleton};

    /// `frames` frames at 30 fps on `skeleton`, with large rotations (up to ~150°) on every
    /// body joint, including angles that put Euler decompositions near gimbal lock.
    pub fn motion(frames: usize, skeleton: SmplSkeleton, betas: Option<Vec<f32>>) -> SmplMotion {
        let poses = (0..frames)
            .map(|f| {
                let t = f as f32 * 0.37;
                let mut body = [Quat::IDENTITY; NUM_BODY_JOINTS];
                for (j, q) in body.iter_mut().enumerate() {
                    let k = j as f32 + 1.0;
                    let v = Vec3::new((t + k).sin(), (0.7 * t + 2.0 * k).cos(), (1.3 * t - k).sin()) * (0.4 + 0.06 * k);
                    *q = quat_from_axis_angle(v);
                }
                // Exactly 90° about the arm axis (middle axis for the elbows' ZXY) on one frame.
                if f == 1 {
                    body[17] = Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
                    body[3] = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
                }
                SmplPose {
                    root_orientation: Quat::from_rotation_y(0.9 * t) * Quat::from_rotation_x(0.3 * t.sin()),
                    body,
                    translation: Vec3::new(0.5 * t, 0.9 + 0.05 * t.cos(), -0.2 * t),
                }
            })
            .collect();
        SmplMotion::new(30.0, 1_000_000_000, skeleton, betas, poses).expect("valid test motion")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_from_extensions_and_paths() {
        assert_eq!(Format::from_extension("NPZ"), Some(Format::Npz));
        assert_eq!(Format::from_extension(".bvh"), Some(Format::Bvh));
        assert_eq!(Format::from_path("out/walk.v2.glb"), Ok(Format::Glb));
        assert_eq!(Format::from_path(r"C:\tmp\joints.CSV"), Ok(Format::Csv));
        assert!(Format::from_path("walk").is_err());
        assert!(Format::from_path(".glb").is_err());
        assert!(Format::from_path("dir.glb/walk").is_err());
        assert!(Format::from_path("walk.fbx").is_err());
        assert_eq!("glb".parse::<Format>(), Ok(Format::Glb));
        assert_eq!("a.npz".parse::<Format>(), Ok(Format::Npz));
        for f in Format::ALL {
            assert_eq!(Format::from_extension(&f.to_string()), Some(f));
        }
    }

    #[test]
    fn invalid_motions_are_errors_in_every_format() {
        use egoexo_core::skeleton::SmplSkeleton;
        let good = test_motion::motion(3, SmplSkeleton::mean_shape(), None);
        let mut empty = good.clone();
        empty.poses.clear();
        let mut bad_fps = good.clone();
        bad_fps.fps = f32::NAN;
        let mut nan_pose = good.clone();
        nan_pose.poses[2].translation.y = f32::INFINITY;
        let mut bad_betas = good.clone();
        bad_betas.betas = Some(vec![f32::NAN; 10]);
        for format in Format::ALL {
            assert!(write(format, &good).is_ok(), "{format}");
            assert_eq!(write(format, &empty), Err(ExportError::EmptyMotion));
            assert!(matches!(write(format, &bad_fps), Err(ExportError::InvalidFps(_))));
            assert_eq!(write(format, &nan_pose), Err(ExportError::NonFinitePose { frame: 2 }));
            assert!(matches!(write(format, &bad_betas), Err(ExportError::InvalidBetas { got: 10, finite: false })));
        }
    }
}
