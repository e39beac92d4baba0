//! The motion library: retargeted SMPL clips in one compact file.
//!
//! # Format (`.safetensors`, version 1)
//! One [safetensors](https://github.com/huggingface/safetensors) file — an 8-byte header
//! length, a JSON header, then raw little-endian arrays — readable as it is by Python
//! (`safetensors.numpy.load_file`, `safe_open(...).metadata()`). All clips' frames are
//! concatenated; a clip owns frames `frame_offset .. frame_offset + frames`.
//!
//! | tensor | dtype | shape | meaning |
//! |---|---|---|---|
//! | `root_translation` | F32 | `[F, 3]` | SMPL `transl`, metres, world (Y up): pelvis = `rest_joints[0] + transl` |
//! | `root_orientation` | F32 | `[F, 4]` | `R_world_pelvis` as a unit quaternion `(x, y, z, w)` |
//! | `body_rotations` | F32 | `[F, 21, 4]` | SMPL joints 1..=21, local to the parent, `(x, y, z, w)` |
//! | `retarget_error_histogram` | U32 | `[C, 501]` | per clip: joint-error counts in 1 mm bins, last bin ≥ 500 mm |
//!
//! The header's `__metadata__` holds one key, `egoexo_motion_library`, whose value is the
//! JSON of [`LibraryHeader`]: the rate (30 fps), and per clip its subject, trial, CMU name,
//! description, source rate and frames, skeleton scale and retarget error.
//!
//! Skeleton: each clip's poses drive the SMPL mean-shape skeleton scaled uniformly by
//! `skeleton_scale` ([`SmplSkeleton::mean_shape`]`.scaled(skeleton_scale)`), which makes its
//! head height equal the subject's standing head height. World frame: the CMU capture
//! volume, Y up, metres, floor near `y = 0`; SMPL's body frame faces +Z.

use std::collections::{BTreeMap, HashMap};

use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::motion::{MotionError, SmplMotion};
use egoexo_core::skeleton::{NUM_BODY_JOINTS, NUM_JOINTS, SmplPose, SmplSkeleton};
use safetensors::{Dtype, SafeTensors, View};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Format name stored in the header.
pub const FORMAT_NAME: &str = "egoexo-motion-library";
/// Format version this code reads and writes.
pub const FORMAT_VERSION: u32 = 1;
/// Metadata key holding the JSON header.
pub const METADATA_KEY: &str = "egoexo_motion_library";
/// Width of a retarget-error histogram bin, millimetres.
pub const HISTOGRAM_BIN_MM: f32 = 1.0;
/// Bins per histogram (the last collects errors of 500 mm and more).
pub const HISTOGRAM_BINS: usize = 501;

/// Retarget error of a clip: distances between the mapped CMU joint positions and the SMPL
/// joints after forward kinematics, over all 24 joints of every output frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RetargetStats {
    /// Mean distance, centimetres.
    pub mean_cm: f32,
    /// 95th percentile, centimetres (to the histogram's 1 mm resolution).
    pub p95_cm: f32,
    /// Largest distance, centimetres.
    pub max_cm: f32,
    /// Mean distance per SMPL joint, centimetres (SMPL joint order).
    pub per_joint_mean_cm: Vec<f32>,
}

/// Everything known about one library clip besides its poses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClipInfo {
    /// CMU subject number (e.g. 5 for `05`).
    pub subject: u32,
    /// CMU trial number (e.g. 6 for `05_06`).
    pub trial: u32,
    /// CMU trial name, e.g. `05_06`.
    pub name: String,
    /// Index of this clean stretch within the trial (0 unless glitches split it).
    pub segment: u32,
    /// Motion description from `CMU_data.csv`.
    pub description: String,
    /// True capture rate of the source, frames per second (from `CMU_data.csv`).
    pub source_fps: f32,
    /// The kind of source file: `ASF/AMC` or which BVH conversion
    /// ([`crate::bvh::CmuBvhNaming::source_format`]). Libraries written before it was
    /// recorded were all ASF/AMC.
    #[serde(default = "asf_amc_format")]
    pub source_format: String,
    /// Frames in the source trial.
    pub source_frames: u32,
    /// Source frames `[start, end)` (0-based) this clip was made from.
    pub source_range: [u32; 2],
    /// Frames of the clip at the library rate.
    pub frames: u32,
    /// First frame of the clip in the library's frame arrays.
    pub frame_offset: u64,
    /// The subject's standing head height, metres (head joint above the lowest foot joint).
    pub head_height_m: f32,
    /// Uniform scale of the SMPL mean shape for this subject.
    pub skeleton_scale: f32,
    /// Retarget error.
    pub retarget: RetargetStats,
}

/// [`ClipInfo::source_format`] of clips imported from ASF/AMC (libraries written before the
/// field existed hold only such clips).
pub const ASF_AMC_FORMAT: &str = "ASF/AMC";

fn asf_amc_format() -> String {
    ASF_AMC_FORMAT.to_owned()
}

impl ClipInfo {
    /// `05_06`, or `05_06/1` for a trial's later clean stretches.
    pub fn label(&self) -> String {
        if self.segment == 0 { self.name.clone() } else { format!("{}/{}", self.name, self.segment) }
    }

    /// Duration at the library rate, seconds.
    pub fn duration_s(&self, fps: f32) -> f32 {
        if self.frames == 0 { 0.0 } else { (self.frames - 1) as f32 / fps }
    }

    /// The SMPL skeleton this clip's poses drive.
    pub fn skeleton(&self) -> SmplSkeleton {
        SmplSkeleton::mean_shape().scaled(self.skeleton_scale)
    }
}

/// The JSON header of a library file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LibraryHeader {
    pub format: String,
    pub version: u32,
    /// Frame rate of every clip.
    pub fps: f32,
    /// Where the motion came from (credit).
    pub source: String,
    pub clips: Vec<ClipInfo>,
}

/// A clip ready to be added to a library.
#[derive(Clone, Debug, PartialEq)]
pub struct LibraryClip {
    /// Metadata (`frames` and `frame_offset` are set when the library is built).
    pub info: ClipInfo,
    /// Poses at the library rate.
    pub poses: Vec<SmplPose>,
    /// Retarget-error histogram ([`HISTOGRAM_BINS`] bins of [`HISTOGRAM_BIN_MM`]).
    pub error_histogram: Vec<u32>,
}

/// Errors reading or building a library.
#[derive(Debug, Error)]
pub enum LibraryError {
    #[error("not a motion library: {0}")]
    Safetensors(#[from] safetensors::SafeTensorError),
    #[error("not a motion library: the header has no `{METADATA_KEY}` entry")]
    MissingHeader,
    #[error("the library header is malformed: {0}")]
    Header(#[from] serde_json::Error),
    #[error("library format `{format}` version {version} is not `{FORMAT_NAME}` version {FORMAT_VERSION}")]
    Version { format: String, version: u32 },
    #[error("tensor `{name}`: expected {expected}, found {found}")]
    Tensor { name: &'static str, expected: String, found: String },
    #[error("clip {clip} (`{label}`) claims frames {start}..{end}, but the library has {frames}")]
    ClipRange { clip: usize, label: String, start: u64, end: u64, frames: usize },
    #[error("no clip {0}")]
    NoSuchClip(usize),
    #[error("clip `{label}`: {source}")]
    Motion { label: String, source: MotionError },
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("clip `{label}` has {poses} poses but a histogram of {bins} bins (expected {HISTOGRAM_BINS})")]
    Histogram { label: String, poses: usize, bins: usize },
}

/// A loaded motion library. Poses are decoded per clip on demand from the file's bytes.
#[derive(Debug)]
pub struct MotionLibrary {
    header: LibraryHeader,
    bytes: Vec<u8>,
    /// Byte ranges of the three pose tensors and the histogram within `bytes`.
    translation: std::ops::Range<usize>,
    orientation: std::ops::Range<usize>,
    body: std::ops::Range<usize>,
    histogram: std::ops::Range<usize>,
    frames: usize,
}

/// Summary of retarget errors over a set of clips.
#[derive(Clone, Debug, PartialEq)]
pub struct RetargetSummary {
    /// Joint distances counted (frames × 24).
    pub samples: u64,
    pub mean_cm: f32,
    pub p95_cm: f32,
    pub max_cm: f32,
}

/// An owned array to serialise.
struct RawTensor {
    dtype: Dtype,
    shape: Vec<usize>,
    bytes: Vec<u8>,
}

impl View for &RawTensor {
    fn dtype(&self) -> Dtype {
        self.dtype
    }
    fn shape(&self) -> &[usize] {
        &self.shape
    }
    fn data(&self) -> std::borrow::Cow<'_, [u8]> {
        (&self.bytes[..]).into()
    }
    fn data_len(&self) -> usize {
        self.bytes.len()
    }
}

fn push_quat(out: &mut Vec<u8>, q: Quat) {
    for v in q.to_array() {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

fn read_f32(bytes: &[u8], index: usize) -> f32 {
    let at = index * 4;
    bytes.get(at..at + 4).map_or(f32::NAN, |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

fn read_u32(bytes: &[u8], index: usize) -> u32 {
    let at = index * 4;
    bytes.get(at..at + 4).map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// Statistics from a histogram plus exact sums.
pub(crate) fn summarize(histogram: &[u32], sum_m: f64, max_m: f32) -> (u64, f32, f32, f32) {
    let samples: u64 = histogram.iter().map(|&c| u64::from(c)).sum();
    if samples == 0 {
        return (0, 0.0, 0.0, 0.0);
    }
    let mean_cm = (sum_m / samples as f64 * 100.0) as f32;
    (samples, mean_cm, histogram_percentile_cm(histogram, 0.95), max_m * 100.0)
}

/// The `q` quantile of a histogram, centimetres, at the centre of its bin.
pub fn histogram_percentile_cm(histogram: &[u32], q: f64) -> f32 {
    let total: u64 = histogram.iter().map(|&c| u64::from(c)).sum();
    if total == 0 {
        return 0.0;
    }
    let wanted = (q * total as f64).ceil().max(1.0) as u64;
    let mut seen = 0u64;
    for (bin, &count) in histogram.iter().enumerate() {
        seen += u64::from(count);
        if seen >= wanted {
            return (bin as f32 + 0.5) * HISTOGRAM_BIN_MM / 10.0;
        }
    }
    histogram.len() as f32 * HISTOGRAM_BIN_MM / 10.0
}

/// Adds one joint error (metres) to a histogram.
pub fn histogram_add(histogram: &mut [u32], error_m: f32) {
    if histogram.is_empty() {
        return;
    }
    let bin = if error_m.is_finite() { (error_m * 1000.0 / HISTOGRAM_BIN_MM).max(0.0) as usize } else { usize::MAX };
    let last = histogram.len() - 1;
    histogram[bin.min(last)] += 1;
}

impl MotionLibrary {
    /// Builds a library from clips (in the given order).
    pub fn build(fps: f32, source: &str, clips: Vec<LibraryClip>) -> Result<Self, LibraryError> {
        let frames: usize = clips.iter().map(|c| c.poses.len()).sum();
        let mut translation = Vec::with_capacity(frames * 12);
        let mut orientation = Vec::with_capacity(frames * 16);
        let mut body = Vec::with_capacity(frames * NUM_BODY_JOINTS * 16);
        let mut histogram = Vec::with_capacity(clips.len() * HISTOGRAM_BINS * 4);
        let mut infos = Vec::with_capacity(clips.len());
        let mut offset = 0u64;
        for clip in clips {
            let mut info = clip.info;
            if clip.error_histogram.len() != HISTOGRAM_BINS {
                return Err(LibraryError::Histogram {
                    label: info.label(),
                    poses: clip.poses.len(),
                    bins: clip.error_histogram.len(),
                });
            }
            if let Some(frame) = clip.poses.iter().position(|p| !p.is_finite()) {
                return Err(LibraryError::Motion { label: info.label(), source: MotionError::NonFinitePose(frame) });
            }
            for pose in &clip.poses {
                for v in pose.translation.to_array() {
                    translation.extend_from_slice(&v.to_le_bytes());
                }
                push_quat(&mut orientation, pose.root_orientation);
                for q in pose.body {
                    push_quat(&mut body, q);
                }
            }
            for count in &clip.error_histogram {
                histogram.extend_from_slice(&count.to_le_bytes());
            }
            info.frames = clip.poses.len() as u32;
            info.frame_offset = offset;
            offset += clip.poses.len() as u64;
            infos.push(info);
        }
        let header = LibraryHeader {
            format: FORMAT_NAME.to_owned(),
            version: FORMAT_VERSION,
            fps,
            source: source.to_owned(),
            clips: infos,
        };
        let translation = RawTensor { dtype: Dtype::F32, shape: vec![frames, 3], bytes: translation };
        let orientation = RawTensor { dtype: Dtype::F32, shape: vec![frames, 4], bytes: orientation };
        let body = RawTensor { dtype: Dtype::F32, shape: vec![frames, NUM_BODY_JOINTS, 4], bytes: body };
        let histogram =
            RawTensor { dtype: Dtype::U32, shape: vec![header.clips.len(), HISTOGRAM_BINS], bytes: histogram };
        let metadata = HashMap::from([(METADATA_KEY.to_owned(), serde_json::to_string(&header)?)]);
        let bytes = safetensors::serialize(
            [
                ("root_translation", &translation),
                ("root_orientation", &orientation),
                ("body_rotations", &body),
                ("retarget_error_histogram", &histogram),
            ],
            Some(metadata),
        )?;
        Self::from_bytes(bytes)
    }

    /// Reads a library from the bytes of a library file (validating shapes and ranges).
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Self, LibraryError> {
        let (header_len, metadata) = SafeTensors::read_metadata(&bytes)?;
        let json = metadata.metadata().as_ref().and_then(|m| m.get(METADATA_KEY)).ok_or(LibraryError::MissingHeader)?;
        let header: LibraryHeader = serde_json::from_str(json)?;
        if header.format != FORMAT_NAME || header.version != FORMAT_VERSION {
            return Err(LibraryError::Version { format: header.format, version: header.version });
        }
        let tensors = SafeTensors::deserialize(&bytes)?;
        let data_start = 8 + header_len;
        let locate = |name: &'static str,
                      dtype: Dtype,
                      tail: &[usize]|
         -> Result<(std::ops::Range<usize>, usize), LibraryError> {
            let info = metadata.info(name).ok_or_else(|| LibraryError::Tensor {
                name,
                expected: "a tensor".to_owned(),
                found: "nothing".to_owned(),
            })?;
            let view = tensors.tensor(name)?;
            let shape = view.shape();
            if view.dtype() != dtype || shape.len() != tail.len() + 1 || shape[1..] != *tail {
                return Err(LibraryError::Tensor {
                    name,
                    expected: format!("{dtype:?} [n, {tail:?}]"),
                    found: format!("{:?} {:?}", view.dtype(), shape),
                });
            }
            let (start, end) = info.data_offsets;
            Ok((data_start + start..data_start + end, shape[0]))
        };
        let (translation, frames) = locate("root_translation", Dtype::F32, &[3])?;
        let (orientation, n_orientation) = locate("root_orientation", Dtype::F32, &[4])?;
        let (body, n_body) = locate("body_rotations", Dtype::F32, &[NUM_BODY_JOINTS, 4])?;
        let (histogram, n_clips) = locate("retarget_error_histogram", Dtype::U32, &[HISTOGRAM_BINS])?;
        if n_orientation != frames || n_body != frames {
            return Err(LibraryError::Tensor {
                name: "root_orientation/body_rotations",
                expected: format!("{frames} frames like root_translation"),
                found: format!("{n_orientation} and {n_body}"),
            });
        }
        if n_clips != header.clips.len() {
            return Err(LibraryError::Tensor {
                name: "retarget_error_histogram",
                expected: format!("{} rows (one per clip)", header.clips.len()),
                found: n_clips.to_string(),
            });
        }
        for (clip, info) in header.clips.iter().enumerate() {
            let end = info.frame_offset.saturating_add(u64::from(info.frames));
            if end > frames as u64 || !(info.skeleton_scale.is_finite() && info.skeleton_scale > 0.0) {
                return Err(LibraryError::ClipRange {
                    clip,
                    label: info.label(),
                    start: info.frame_offset,
                    end,
                    frames,
                });
            }
        }
        Ok(Self { header, bytes, translation, orientation, body, histogram, frames })
    }

    /// The library file's bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The header (rate, source, clips).
    pub fn header(&self) -> &LibraryHeader {
        &self.header
    }

    /// Frame rate of every clip, frames per second.
    pub fn fps(&self) -> f32 {
        self.header.fps
    }

    /// All clips, in library order (by subject, trial, segment when imported).
    pub fn clips(&self) -> &[ClipInfo] {
        &self.header.clips
    }

    /// Total frames over all clips.
    pub fn total_frames(&self) -> usize {
        self.frames
    }

    /// Total duration, hours (frames / fps).
    pub fn hours(&self) -> f64 {
        self.frames as f64 / f64::from(self.header.fps) / 3600.0
    }

    /// The distinct subjects, ascending.
    pub fn subjects(&self) -> Vec<u32> {
        let mut s: Vec<u32> = self.header.clips.iter().map(|c| c.subject).collect();
        s.sort_unstable();
        s.dedup();
        s
    }

    /// Indices of the clips of the given subjects (for train/validation splits by subject).
    pub fn clips_of_subjects(&self, subjects: &[u32]) -> Vec<usize> {
        (0..self.header.clips.len()).filter(|&i| subjects.contains(&self.header.clips[i].subject)).collect()
    }

    /// Index of the clip with this label (`05_06` or `05_06/1`).
    pub fn find(&self, label: &str) -> Option<usize> {
        self.header.clips.iter().position(|c| c.label() == label)
    }

    /// The poses of clip `clip`, decoded.
    pub fn poses(&self, clip: usize) -> Result<Vec<SmplPose>, LibraryError> {
        let info = self.header.clips.get(clip).ok_or(LibraryError::NoSuchClip(clip))?;
        let t = &self.bytes[self.translation.clone()];
        let o = &self.bytes[self.orientation.clone()];
        let b = &self.bytes[self.body.clone()];
        let start = info.frame_offset as usize;
        let quat = |bytes: &[u8], at: usize| {
            Quat::from_xyzw(
                read_f32(bytes, at),
                read_f32(bytes, at + 1),
                read_f32(bytes, at + 2),
                read_f32(bytes, at + 3),
            )
        };
        Ok((start..start + info.frames as usize)
            .map(|f| SmplPose {
                root_orientation: quat(o, f * 4),
                body: std::array::from_fn(|k| quat(b, (f * NUM_BODY_JOINTS + k) * 4)),
                translation: Vec3::new(read_f32(t, f * 3), read_f32(t, f * 3 + 1), read_f32(t, f * 3 + 2)),
            })
            .collect())
    }

    /// Clip `clip` as an [`SmplMotion`] (library rate, starting at time 0, on the clip's
    /// scaled mean-shape skeleton).
    pub fn motion(&self, clip: usize) -> Result<SmplMotion, LibraryError> {
        let poses = self.poses(clip)?;
        let info = &self.header.clips[clip];
        SmplMotion::new(self.header.fps, 0, info.skeleton(), None, poses)
            .map_err(|source| LibraryError::Motion { label: info.label(), source })
    }

    /// The retarget-error histogram of clip `clip` (1 mm bins).
    pub fn error_histogram(&self, clip: usize) -> Vec<u32> {
        let h = &self.bytes[self.histogram.clone()];
        (0..HISTOGRAM_BINS).map(|k| read_u32(h, clip * HISTOGRAM_BINS + k)).collect()
    }

    /// Retarget error over a set of clips (mean and max exact, p95 from the merged
    /// histograms).
    pub fn retarget_summary(&self, clips: &[usize]) -> RetargetSummary {
        let mut merged = vec![0u32; HISTOGRAM_BINS];
        let mut sum_cm = 0.0f64;
        let mut max_cm = 0.0f32;
        let mut samples = 0u64;
        for &c in clips {
            let Some(info) = self.header.clips.get(c) else { continue };
            let h = self.error_histogram(c);
            let n: u64 = h.iter().map(|&x| u64::from(x)).sum();
            for (m, x) in merged.iter_mut().zip(&h) {
                *m = m.saturating_add(*x);
            }
            samples += n;
            sum_cm += f64::from(info.retarget.mean_cm) * n as f64;
            max_cm = max_cm.max(info.retarget.max_cm);
        }
        let mean_cm = if samples == 0 { 0.0 } else { (sum_cm / samples as f64) as f32 };
        RetargetSummary { samples, mean_cm, p95_cm: histogram_percentile_cm(&merged, 0.95), max_cm }
    }

    /// Clip indices grouped by [`ClipInfo::source_format`] (ascending by name).
    pub fn clips_by_source_format(&self) -> BTreeMap<String, Vec<usize>> {
        let mut out: BTreeMap<String, Vec<usize>> = BTreeMap::new();
        for (i, c) in self.header.clips.iter().enumerate() {
            out.entry(c.source_format.clone()).or_default().push(i);
        }
        out
    }

    /// Clip indices grouped by subject, subjects ascending.
    pub fn clips_by_subject(&self) -> BTreeMap<u32, Vec<usize>> {
        let mut map: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
        for (i, c) in self.header.clips.iter().enumerate() {
            map.entry(c.subject).or_default().push(i);
        }
        map
    }
}

/// Retarget statistics of a clip from per-frame joint errors (metres).
pub fn retarget_stats(errors: &[[f32; NUM_JOINTS]]) -> (RetargetStats, Vec<u32>) {
    let mut histogram = vec![0u32; HISTOGRAM_BINS];
    let mut sum = 0.0f64;
    let mut max = 0.0f32;
    let mut per_joint = [0.0f64; NUM_JOINTS];
    for frame in errors {
        for (j, &e) in frame.iter().enumerate() {
            histogram_add(&mut histogram, e);
            sum += f64::from(e);
            per_joint[j] += f64::from(e);
            max = max.max(e);
        }
    }
    let (_, mean_cm, p95_cm, max_cm) = summarize(&histogram, sum, max);
    let n = errors.len().max(1) as f64;
    let per_joint_mean_cm = per_joint.iter().map(|s| (s / n * 100.0) as f32).collect();
    (RetargetStats { mean_cm, p95_cm, max_cm, per_joint_mean_cm }, histogram)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_of_a_histogram() {
        let mut h = vec![0u32; HISTOGRAM_BINS];
        for mm in 0..100 {
            histogram_add(&mut h, mm as f32 / 1000.0 + 0.0004);
        }
        assert!((histogram_percentile_cm(&h, 0.95) - 9.45).abs() < 1e-4);
        histogram_add(&mut h, 3.0);
        histogram_add(&mut h, f32::NAN);
        assert_eq!(h[HISTOGRAM_BINS - 1], 2);
    }
}
