//! From ASF/AMC text to library clips: parse, CMU forward kinematics, corrupt-frame
//! trimming, resampling to the library rate, retargeting, error statistics. No I/O.

use egoexo_core::glam::Vec3;
use egoexo_core::skeleton::{NUM_JOINTS, SmplPose};
use thiserror::Error;

use crate::amc::AmcMotion;
use crate::asf::AsfSkeleton;
use crate::catalog::CatalogEntry;
use crate::clean::{DEFAULT_MAX_JOINT_SPEED_MPS, clean_segments, resample_plan};
use crate::error::ParseError;
use crate::kinematics::{CmuBoneTransforms, CmuPose, CmuSkeleton, KinematicsError};
use crate::library::{ClipInfo, LibraryClip, LibraryError, retarget_stats};
use crate::retarget::{RetargetError, Retargeter};

/// Frame rate of the motion library, frames per second.
pub const LIBRARY_FPS: f32 = 30.0;

/// Credit line stored in every library built from CMU data.
pub const CMU_SOURCE: &str = "The data used in this project was obtained from mocap.cs.cmu.edu. \
     The database was created with funding from NSF EIA-0196217.";

pub use crate::library::ASF_AMC_FORMAT;

/// Settings of an import.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportOptions {
    /// Output rate, frames per second.
    pub fps: f32,
    /// A frame-to-frame joint step faster than this (m/s) is a glitch.
    pub max_joint_speed_mps: f32,
    /// Clean stretches shorter than this (seconds) are dropped.
    pub min_segment_s: f32,
    /// Metres per BVH length unit; `None` infers it from the skeleton's head height.
    pub bvh_metres_per_unit: Option<f64>,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            fps: LIBRARY_FPS,
            max_joint_speed_mps: DEFAULT_MAX_JOINT_SPEED_MPS,
            min_segment_s: 1.0,
            bvh_metres_per_unit: None,
        }
    }
}

/// Errors importing CMU data.
#[derive(Debug, Error)]
pub enum ImportError {
    #[error(transparent)]
    Parse(#[from] ParseError),
    #[error("{file}: {source}")]
    Kinematics { file: String, source: KinematicsError },
    #[error("{file}: {source}")]
    Retarget { file: String, source: RetargetError },
    #[error("{file}: trial {subject:02}_{trial:02} is not in CMU_data.csv, so its capture rate is unknown")]
    NotInCatalog { file: String, subject: u32, trial: u32 },
    #[error("{file}: expected a file named SUBJECT_TRIAL.amc/.bvh (e.g. 05_06.amc) or SUBJECT.asf")]
    FileName { file: String },
    #[error("{file}: no clean stretch of at least {min_s} s in {frames} frames ({glitches} glitches)")]
    NoCleanFrames { file: String, frames: usize, glitches: usize, min_s: f32 },
    #[error("{file}: {source}")]
    Library { file: String, source: LibraryError },
    #[error("{file}: {source}")]
    Bvh { file: String, source: egoexo_motion_io::bvh::BvhError },
    #[error("{file}: cannot use the BVH's length unit: {detail}; give the metres per unit")]
    BvhUnit { file: String, detail: String },
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{0}: no CMU subject folders (NN/NN.asf with NN_TT.amc) found")]
    EmptyTree(String),
    #[error("{0}: no CMU_data.csv found in the tree; pass the catalogue's path")]
    NoCatalog(String),
}

/// `"05_06"` → `(5, 6)`.
pub fn parse_trial_name(stem: &str) -> Option<(u32, u32)> {
    let (subject, trial) = stem.split_once('_')?;
    Some((subject.parse().ok()?, trial.parse().ok()?))
}

/// The result of importing one trial.
#[derive(Clone, Debug)]
pub struct TrialImport {
    /// One clip per clean stretch, in time order.
    pub clips: Vec<LibraryClip>,
    /// Frames in the source.
    pub source_frames: usize,
    /// Source frames in no clip (glitches and stretches too short).
    pub dropped_frames: usize,
    /// Number of glitch steps found.
    pub glitches: usize,
    /// Leading rows that held a reference pose, not motion (cgspeed's prepended T-pose),
    /// left out before everything else (not counted in `source_frames`).
    pub reference_rows_skipped: usize,
    /// Thorax length put back into a BVH conversion that had collapsed it, metres
    /// ([`crate::bvh::restore_collapsed_thorax`]).
    pub restored_thorax_m: Option<f32>,
}

/// Imports the trials of one CMU subject (one ASF skeleton).
#[derive(Clone, Debug)]
pub struct SubjectImporter {
    subject: u32,
    asf: AsfSkeleton,
    skeleton: CmuSkeleton,
    retargeter: Retargeter,
}

impl SubjectImporter {
    /// Parses and prepares a subject's skeleton. `file` names the ASF in errors.
    pub fn new(subject: u32, asf_text: &str, file: &str) -> Result<Self, ImportError> {
        let asf = AsfSkeleton::parse(asf_text, file)?;
        let skeleton =
            CmuSkeleton::from_asf(&asf).map_err(|source| ImportError::Kinematics { file: file.to_owned(), source })?;
        let retargeter =
            Retargeter::new(&skeleton).map_err(|source| ImportError::Retarget { file: file.to_owned(), source })?;
        Ok(Self { subject, asf, skeleton, retargeter })
    }

    /// The CMU subject number.
    pub fn subject(&self) -> u32 {
        self.subject
    }

    /// The parsed ASF.
    pub fn asf(&self) -> &AsfSkeleton {
        &self.asf
    }

    /// The kinematic CMU skeleton.
    pub fn cmu_skeleton(&self) -> &CmuSkeleton {
        &self.skeleton
    }

    /// The retargeter (scaled SMPL skeleton, head height, joint map).
    pub fn retargeter(&self) -> &Retargeter {
        &self.retargeter
    }

    /// Parses an AMC and returns its per-frame CMU poses.
    pub fn parse_motion(&self, amc_text: &str, file: &str) -> Result<Vec<CmuPose>, ImportError> {
        let amc = AmcMotion::parse(amc_text, file, &self.asf)?;
        (0..amc.frame_count())
            .map(|f| self.skeleton.pose_from_frame(amc.frame(f), amc.angle_unit))
            .collect::<Result<_, _>>()
            .map_err(|source| ImportError::Kinematics { file: file.to_owned(), source })
    }

    /// Mapped SMPL joint positions (metres) of each CMU pose.
    pub fn joint_positions(&self, poses: &[CmuPose]) -> Vec<[Vec3; NUM_JOINTS]> {
        let mut fk = CmuBoneTransforms::default();
        poses
            .iter()
            .map(|p| {
                self.skeleton.forward_kinematics_into(p, &mut fk);
                self.retargeter.joint_map().positions(&fk)
            })
            .collect()
    }

    /// Imports one trial: `amc_text` is the AMC, `file` its name in errors, `entry` its
    /// catalogue entry (description, true capture rate).
    pub fn import_trial(
        &self,
        trial: u32,
        amc_text: &str,
        file: &str,
        entry: &CatalogEntry,
        options: &ImportOptions,
    ) -> Result<TrialImport, ImportError> {
        let poses = self.parse_motion(amc_text, file)?;
        let source =
            TrialSource { subject: self.subject, trial, file, entry, format: ASF_AMC_FORMAT, first_source_frame: 0 };
        clips_from_source(&self.retargeter, &source, options, poses.len(), |i, alpha, out| {
            if alpha == 0.0 {
                self.skeleton.forward_kinematics_into(&poses[i], out);
            } else {
                self.skeleton.forward_kinematics_into(&poses[i].interpolate(&poses[i + 1], alpha), out);
            }
        })
    }
}

/// Which trial a source is, for clip metadata and errors.
pub(crate) struct TrialSource<'a> {
    pub subject: u32,
    pub trial: u32,
    pub file: &'a str,
    pub entry: &'a CatalogEntry,
    /// The data source's kind ([`ClipInfo::source_format`]).
    pub format: &'static str,
    /// Source frame index of the first frame handed to [`clips_from_source`] (for
    /// [`ClipInfo::source_range`]).
    pub first_source_frame: usize,
}

/// Corrupt-frame trimming, resampling, retargeting and error statistics for one trial of
/// `frames` source frames, whatever its format. `fk_at(i, alpha, out)` writes the bone
/// transforms of source time `i + alpha` (frames; `alpha` in `[0, 1)`, and `alpha = 0` for the
/// last frame) in the retargeter's bone indexing.
pub(crate) fn clips_from_source(
    retargeter: &Retargeter,
    source: &TrialSource<'_>,
    options: &ImportOptions,
    frames: usize,
    mut fk_at: impl FnMut(usize, f32, &mut CmuBoneTransforms),
) -> Result<TrialImport, ImportError> {
    let source_fps = source.entry.framerate;
    let mut fk = CmuBoneTransforms::default();
    let positions: Vec<[Vec3; NUM_JOINTS]> = (0..frames)
        .map(|i| {
            fk_at(i, 0.0, &mut fk);
            retargeter.joint_map().positions(&fk)
        })
        .collect();
    let min_frames = (options.min_segment_s * source_fps).ceil().max(2.0) as usize;
    let segments = clean_segments(&positions, source_fps, options.max_joint_speed_mps, min_frames);
    let limit = options.max_joint_speed_mps / source_fps;
    let glitches = crate::clean::frame_steps(&positions).iter().filter(|&&s| s > limit).count();
    if segments.is_empty() {
        return Err(ImportError::NoCleanFrames {
            file: source.file.to_owned(),
            frames,
            glitches,
            min_s: options.min_segment_s,
        });
    }
    let kept: usize = segments.iter().map(|r| r.len()).sum();
    let mut clips = Vec::with_capacity(segments.len());
    for (segment, range) in segments.iter().enumerate() {
        let plan = resample_plan(range.len(), source_fps, options.fps);
        let mut smpl_poses: Vec<SmplPose> = Vec::with_capacity(plan.len());
        let mut errors = Vec::with_capacity(plan.len());
        for (i, alpha) in plan {
            fk_at(range.start + i, alpha, &mut fk);
            let frame = retargeter.retarget(&fk);
            smpl_poses.push(frame.pose);
            errors.push(frame.errors);
        }
        let (retarget, error_histogram) = retarget_stats(&errors);
        let info = ClipInfo {
            subject: source.subject,
            trial: source.trial,
            name: format!("{:02}_{:02}", source.subject, source.trial),
            segment: segment as u32,
            description: source.entry.description.clone(),
            source_fps,
            source_format: source.format.to_owned(),
            source_frames: (frames + source.first_source_frame) as u32,
            source_range: [
                (range.start + source.first_source_frame) as u32,
                (range.end + source.first_source_frame) as u32,
            ],
            frames: smpl_poses.len() as u32,
            frame_offset: 0,
            head_height_m: retargeter.head_height(),
            skeleton_scale: retargeter.scale(),
            retarget,
        };
        clips.push(LibraryClip { info, poses: smpl_poses, error_histogram });
    }
    Ok(TrialImport {
        clips,
        source_frames: frames,
        dropped_frames: frames - kept,
        glitches,
        reference_rows_skipped: 0,
        restored_thorax_m: None,
    })
}
