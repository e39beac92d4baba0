//! AMASS-style SMPL parameters in a NumPy `.npz` archive.
//!
//! # The file
//! A zip (deflate) of `.npy` arrays, as `numpy.savez_compressed` writes it; it loads with
//! `numpy.load(path)` without pickles:
//!
//! | key | dtype, shape | content |
//! |---|---|---|
//! | `poses` | `<f8`, (N, 72) | axis-angle (radians) of the 24 SMPL joints: root orientation, 21 body joints, then the two hands, which are zero |
//! | `trans` | `<f8`, (N, 3) | SMPL `transl`, metres, Z-up world (see below) |
//! | `betas` | `<f8`, (B,) | the motion's betas, or `zeros(10)` (the mean shape) when it has none |
//! | `gender` | `<U7`, () | `"neutral"` |
//! | `mocap_framerate` | `<f8`, () | frames per second |
//! | `rest_joints` | `<f8`, (24, 3) | the skeleton the motion was made with (rest joints, metres, SMPL body frame) — an egoexo addition AMASS tools ignore |
//!
//! # World: Z up, as AMASS
//! AMASS data lives in a **Z-up** world (its mocap floor is the XY plane), so that AMASS
//! tooling (body-visualiser scripts, the many loaders built on them) shows the motion upright.
//! This project's world is Y up; the export rotates the whole motion rigidly by
//! [`Y_UP_TO_Z_UP`] = +90° about X, `(x, y, z) ↦ (x, −z, y)`: every joint position becomes
//! `p_zup = C · p_yup`. SMPL's own body frame (its rest pose: Y up, facing +Z) is unchanged,
//! so only the root changes:
//! - root orientation: `R_zup = C · R_yup` (a subject standing upright gets `C`, as in AMASS);
//! - translation: SMPL places the pelvis at `J₀ + trans` where `J₀` is the pelvis rest joint
//!   of the SMPL model for the written betas, so `trans = C · (rest[0] + translation) − J₀`.
//!   `J₀` is the mean shape's pelvis when the motion has no betas (the betas written are then
//!   zero, and a uniformly scaled mean-shape skeleton cannot be expressed in SMPL betas: the
//!   pelvis still lands where the motion has it, limb lengths are the mean shape's), and the
//!   skeleton's own pelvis when it has betas (its skeleton was regressed from them).
//!
//! Body-joint rotations are local and so are the same in either world.
//! [`motion_from_amass`] undoes all of this.

use egoexo_core::SmplMotion;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::rotation::{axis_angle_from_quat, quat_from_axis_angle};
use egoexo_core::skeleton::{MEAN_SHAPE_REST_JOINTS, NUM_BODY_JOINTS, NUM_JOINTS, SmplPose, SmplSkeleton};
use thiserror::Error;

use crate::npz::{NpzWriteError, NpzWriter};
use crate::{ExportError, Format, validate};

/// Rotation from this project's Y-up world to AMASS's Z-up world: +90° about X.
pub const Y_UP_TO_Z_UP: Quat =
    Quat::from_xyzw(std::f32::consts::FRAC_1_SQRT_2, 0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2);

/// Numbers of an axis-angle pose row: 24 joints × 3.
pub const POSE_WIDTH: usize = 3 * NUM_JOINTS;

/// Number of betas written when the motion has none.
pub const DEFAULT_NUM_BETAS: usize = 10;

/// The arrays of an AMASS-style file, flat and row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct AmassArrays {
    /// (N, 72) axis-angle, radians.
    pub poses: Vec<f64>,
    /// (N, 3) SMPL `transl`, metres, Z-up world.
    pub trans: Vec<f64>,
    /// (B,) shape coefficients.
    pub betas: Vec<f64>,
    /// Frames per second.
    pub mocap_framerate: f64,
    /// (24, 3) rest joints, metres, SMPL body frame; `None` when a file lacks them (then the
    /// mean shape is assumed).
    pub rest_joints: Option<Vec<f64>>,
}

impl AmassArrays {
    /// Number of frames.
    pub fn num_frames(&self) -> usize {
        self.poses.len() / POSE_WIDTH
    }
}

/// The pelvis rest joint of the SMPL model the betas describe (see the module docs).
fn model_pelvis(betas_known: bool, skeleton: &SmplSkeleton) -> Vec3 {
    if betas_known { skeleton.rest_joints()[0] } else { Vec3::from_array(MEAN_SHAPE_REST_JOINTS[0]) }
}

/// The AMASS arrays of a motion (Z-up world; see the module docs).
pub fn amass_arrays(motion: &SmplMotion) -> Result<AmassArrays, ExportError> {
    validate(motion)?;
    let skeleton = &motion.skeleton;
    let j0 = model_pelvis(motion.betas.is_some(), skeleton);
    let mut poses = Vec::with_capacity(motion.len() * POSE_WIDTH);
    let mut trans = Vec::with_capacity(motion.len() * 3);
    for pose in &motion.poses {
        let root = Y_UP_TO_Z_UP * pose.root_orientation.normalize();
        poses.extend(axis_angle_from_quat(root).to_array().map(f64::from));
        for q in &pose.body {
            poses.extend(axis_angle_from_quat(*q).to_array().map(f64::from));
        }
        poses.extend([0.0; 6]); // left_hand, right_hand
        let pelvis = Y_UP_TO_Z_UP * (skeleton.rest_joints()[0] + pose.translation);
        trans.extend((pelvis - j0).to_array().map(f64::from));
    }
    let betas = match &motion.betas {
        Some(b) => b.iter().map(|&v| f64::from(v)).collect(),
        None => vec![0.0; DEFAULT_NUM_BETAS],
    };
    let rest_joints = skeleton.rest_joints().iter().flat_map(|p| p.to_array().map(f64::from)).collect();
    Ok(AmassArrays { poses, trans, betas, mocap_framerate: f64::from(motion.fps), rest_joints: Some(rest_joints) })
}

/// Writes `motion` as an AMASS-style `.npz` (see the module docs).
pub fn write_npz(motion: &SmplMotion) -> Result<Vec<u8>, ExportError> {
    let a = amass_arrays(motion)?;
    let n = a.num_frames() as u64;
    let encode = |e: NpzWriteError| ExportError::Encode { format: Format::Npz, message: e.to_string() };
    let mut npz = NpzWriter::new();
    npz.add("poses", &[n, POSE_WIDTH as u64], &a.poses).map_err(encode)?;
    npz.add("trans", &[n, 3], &a.trans).map_err(encode)?;
    npz.add("betas", &[a.betas.len() as u64], &a.betas).map_err(encode)?;
    npz.add_str("gender", "neutral").map_err(encode)?;
    npz.add("mocap_framerate", &[], &[a.mocap_framerate]).map_err(encode)?;
    if let Some(rest) = &a.rest_joints {
        npz.add("rest_joints", &[NUM_JOINTS as u64, 3], rest).map_err(encode)?;
    }
    npz.finish().map_err(encode)
}

/// Why AMASS arrays do not make a motion.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AmassReadError {
    #[error("`{array}` has {got} values, expected {expected}")]
    Shape { array: &'static str, got: usize, expected: String },
    #[error("`{array}` has a non-finite value at index {index}")]
    NonFinite { array: &'static str, index: usize },
    #[error("invalid motion: {0}")]
    Motion(String),
}

/// The motion of AMASS arrays in this project's Y-up world: the inverse of [`amass_arrays`]
/// (the hands' rotations are ignored, SMPL keeps them at identity). The skeleton is
/// `rest_joints` when present, else the mean shape; betas are kept unless all zero.
pub fn motion_from_amass(a: &AmassArrays, start_ns: i64) -> Result<SmplMotion, AmassReadError> {
    let n = a.num_frames();
    let shape = |array: &'static str, got: usize, expected: String| Err(AmassReadError::Shape { array, got, expected });
    if a.poses.is_empty() || !a.poses.len().is_multiple_of(POSE_WIDTH) {
        return shape("poses", a.poses.len(), format!("a positive multiple of {POSE_WIDTH}"));
    }
    if a.trans.len() != 3 * n {
        return shape("trans", a.trans.len(), format!("3 per frame ({})", 3 * n));
    }
    let finite = |array: &'static str, v: &[f64]| match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(AmassReadError::NonFinite { array, index }),
        None => Ok(()),
    };
    finite("poses", &a.poses)?;
    finite("trans", &a.trans)?;
    finite("betas", &a.betas)?;
    let skeleton = match &a.rest_joints {
        None => SmplSkeleton::mean_shape(),
        Some(r) if r.len() == 3 * NUM_JOINTS => {
            finite("rest_joints", r)?;
            let mut joints = [Vec3::ZERO; NUM_JOINTS];
            for (j, p) in joints.iter_mut().enumerate() {
                *p = Vec3::new(r[3 * j] as f32, r[3 * j + 1] as f32, r[3 * j + 2] as f32);
            }
            SmplSkeleton::from_rest_joints(joints).map_err(|e| AmassReadError::Motion(e.to_string()))?
        }
        Some(r) => return shape("rest_joints", r.len(), format!("{}", 3 * NUM_JOINTS)),
    };
    let betas_known = a.betas.iter().any(|&b| b != 0.0);
    let j0 = model_pelvis(betas_known, &skeleton);
    let z_up_to_y_up = Y_UP_TO_Z_UP.inverse();
    let aa = |v: &[f64]| quat_from_axis_angle(Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32));
    let poses = a
        .poses
        .chunks_exact(POSE_WIDTH)
        .zip(a.trans.chunks_exact(3))
        .map(|(row, t)| {
            let mut body = [Quat::IDENTITY; NUM_BODY_JOINTS];
            for (i, q) in body.iter_mut().enumerate() {
                *q = aa(&row[3 * (i + 1)..3 * (i + 2)]);
            }
            let pelvis_zup = j0 + Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32);
            SmplPose {
                root_orientation: (z_up_to_y_up * aa(&row[0..3])).normalize(),
                body,
                translation: z_up_to_y_up * pelvis_zup - skeleton.rest_joints()[0],
            }
        })
        .collect();
    let betas = betas_known.then(|| a.betas.iter().map(|&b| b as f32).collect());
    SmplMotion::new(a.mocap_framerate as f32, start_ns, skeleton, betas, poses)
        .map_err(|e| AmassReadError::Motion(e.to_string()))
}

#[cfg(test)]
mod tests {
    use std::io::{Cursor, Read};

    use super::*;
    use crate::test_motion;

    #[test]
    fn y_up_to_z_up_maps_up_to_up() {
        assert!((Y_UP_TO_Z_UP * Vec3::Y).abs_diff_eq(Vec3::Z, 1e-6));
        assert!((Y_UP_TO_Z_UP * Vec3::Z).abs_diff_eq(-Vec3::Y, 1e-6));
        assert!((Y_UP_TO_Z_UP * Vec3::X).abs_diff_eq(Vec3::X, 1e-6));
    }

    #[test]
    fn arrays_have_amass_shapes_and_upright_z() {
        let motion = test_motion::motion(5, SmplSkeleton::mean_shape(), None);
        let a = amass_arrays(&motion).unwrap();
        assert_eq!(a.poses.len(), 5 * 72);
        assert_eq!(a.trans.len(), 15);
        assert_eq!(a.betas, vec![0.0; 10]);
        assert!(a.poses.chunks(72).all(|row| row[66..].iter().all(|&v| v == 0.0)));
        // A rest pose standing in the Y-up world has root orientation C (+90° about X) in AMASS.
        let mut standing = motion.clone();
        standing.poses = vec![SmplPose::rest()];
        let s = amass_arrays(&standing).unwrap();
        let expected = std::f64::consts::FRAC_PI_2;
        assert!((s.poses[0] - expected).abs() < 1e-6 && s.poses[1].abs() < 1e-6 && s.poses[2].abs() < 1e-6);
        // Its trans puts the pelvis at C·rest[0]; the pelvis's height (Z) is rest[0].y.
        let z = s.trans[2] + f64::from(MEAN_SHAPE_REST_JOINTS[0][2]);
        assert!((z - f64::from(MEAN_SHAPE_REST_JOINTS[0][1])).abs() < 1e-6, "{z}");
    }

    #[test]
    fn arrays_round_trip_to_the_same_joint_positions() {
        let cases = [
            (SmplSkeleton::mean_shape(), None),
            (SmplSkeleton::mean_shape().scaled(0.9), None),
            (SmplSkeleton::mean_shape().scaled(1.07), Some(vec![0.5, -1.0, 0.25])),
        ];
        for (skeleton, betas) in cases {
            let motion = test_motion::motion(30, skeleton, betas.clone());
            let back = motion_from_amass(&amass_arrays(&motion).unwrap(), motion.start_ns).unwrap();
            assert_eq!(back.betas, betas);
            for (pa, pb) in motion.joint_positions().iter().zip(back.joint_positions()) {
                for (x, y) in pa.iter().zip(pb) {
                    assert!(x.distance(y) < 1e-5, "{x} vs {y}");
                }
            }
        }
    }

    #[test]
    fn npz_is_a_zip_of_npy_arrays() {
        let motion = test_motion::motion(4, SmplSkeleton::mean_shape(), None);
        let bytes = write_npz(&motion).unwrap();
        let mut zip = zip::ZipArchive::new(Cursor::new(bytes)).unwrap();
        let mut names: Vec<String> = zip.file_names().map(|n| n.unwrap().to_string()).collect();
        names.sort();
        assert_eq!(
            names,
            ["betas.npy", "gender.npy", "mocap_framerate.npy", "poses.npy", "rest_joints.npy", "trans.npy"]
        );
        let mut poses = Vec::new();
        zip.by_name("poses.npy").unwrap().read_to_end(&mut poses).unwrap();
        let npy = npyz::NpyFile::new(&poses[..]).unwrap();
        assert_eq!(npy.shape(), &[4, 72]);
        let values: Vec<f64> = npy.into_vec().unwrap();
        assert_eq!(values, amass_arrays(&motion).unwrap().poses);
    }

    #[test]
    fn rejects_malformed_arrays() {
        let motion = test_motion::motion(2, SmplSkeleton::mean_shape(), None);
        let good = amass_arrays(&motion).unwrap();
        let mut a = good.clone();
        a.poses.pop();
        assert!(matches!(motion_from_amass(&a, 0), Err(AmassReadError::Shape { array: "poses", .. })));
        let mut a = good.clone();
        a.trans.push(0.0);
        assert!(matches!(motion_from_amass(&a, 0), Err(AmassReadError::Shape { array: "trans", .. })));
        let mut a = good.clone();
        a.poses[7] = f64::NAN;
        assert_eq!(motion_from_amass(&a, 0), Err(AmassReadError::NonFinite { array: "poses", index: 7 }));
        let mut a = good;
        a.mocap_framerate = 0.0;
        assert!(matches!(motion_from_amass(&a, 0), Err(AmassReadError::Motion(_))));
    }
}
