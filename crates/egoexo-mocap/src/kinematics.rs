//! Forward kinematics of an ASF skeleton with ASF/AMC semantics, in metres.
//!
//! Frames: the capture's global frame (CMU: Y up, metres after conversion). Each bone `b`
//! has a local frame `C_b` (from its `axis X Y Z ORDER`, relative to the global frame); an
//! AMC frame gives the bone's motion `M_b` in that local frame, so its rotation expressed in
//! global axes is `L_b = C_b · M_b · C_b⁻¹`, and the bone's world rotation composes along
//! the chain, `W_b = W_parent · L_b` (`W_root = L_root`). `W_b` maps the rest pose (global
//! axes) to the current pose: a bone ends at `start_b + W_b · (direction_b × length_b)`, and
//! starts where its parent ends (the root "ends" at its position).
//!
//! Euler angles follow the Acclaim/CMU viewer convention: the first listed axis is applied
//! first (`XYZ` → `R_Z · R_Y · R_X`); a bone's DOF rotations compose the same way in their
//! `dof` order.

use egoexo_core::euler::{Axis, EulerOrder};
use egoexo_core::glam::{Quat, Vec3};
use thiserror::Error;

use crate::amc::ChannelLayout;
use crate::asf::{AngleUnit, AsfSkeleton, Dof};

/// Errors turning an ASF into a kinematic skeleton.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum KinematicsError {
    #[error("bone `{bone}` has a `{dof}` DOF; only rotations are supported below the root")]
    UnsupportedDof { bone: String, dof: &'static str },
    #[error("frame has {found} values, the skeleton expects {expected}")]
    FrameLength { expected: usize, found: usize },
}

/// One bone, ready for forward kinematics. Index 0 is the root.
#[derive(Clone, Debug, PartialEq)]
pub struct KinematicBone {
    pub name: String,
    /// Parent bone index (`None` for the root).
    pub parent: Option<usize>,
    /// Rest vector from the bone's start to its end, metres, global frame.
    pub rest_offset: Vec3,
    /// The bone's local frame `C_b` relative to the global frame.
    pub local_frame: Quat,
    /// DOFs in AMC order.
    pub dofs: Vec<Dof>,
    /// Offset of the bone's values in a frame.
    pub channel_offset: usize,
}

/// An ASF skeleton prepared for forward kinematics: bones sorted so that parents come first
/// (index 0 is the root), lengths in metres.
#[derive(Clone, Debug, PartialEq)]
pub struct CmuSkeleton {
    bones: Vec<KinematicBone>,
    /// Root rest position, metres.
    root_position: Vec3,
    metres_per_unit: f32,
    angle_unit: AngleUnit,
    channels_per_frame: usize,
}

/// The pose of every bone for one frame, before forward kinematics (what is interpolated).
#[derive(Clone, Debug, PartialEq)]
pub struct CmuPose {
    /// Root translation, metres, global frame (the AMC root translation; the ASF root
    /// position is added by forward kinematics).
    pub root_translation: Vec3,
    /// `L_b = C_b · M_b · C_b⁻¹` per bone (index 0: the root's rotation).
    pub local_rotations: Vec<Quat>,
}

/// World transforms of every bone after forward kinematics.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct CmuBoneTransforms {
    /// `W_b`: rest (global axes) → current, per bone.
    pub rotations: Vec<Quat>,
    /// Where each bone starts, metres (the root's: its position).
    pub starts: Vec<Vec3>,
    /// Where each bone ends, metres (the root's: its position).
    pub ends: Vec<Vec3>,
}

/// Rotation of Euler angles `angles` (radians, indexed by axis: X, Y, Z, as ASF lists them)
/// in `order` (`egoexo_core::euler`'s convention; an ASF `axis XYZ` is [`EulerOrder::ZYX`]).
pub fn euler_rotation(angles: [f32; 3], order: EulerOrder) -> Quat {
    order.to_quat(order.axes().map(|axis| angles[axis.index()]))
}

fn dof_name(dof: Dof) -> &'static str {
    match dof {
        Dof::Translation(Axis::X) => "tx",
        Dof::Translation(Axis::Y) => "ty",
        Dof::Translation(Axis::Z) => "tz",
        Dof::Rotation(Axis::X) => "rx",
        Dof::Rotation(Axis::Y) => "ry",
        Dof::Rotation(Axis::Z) => "rz",
        Dof::Length => "l",
    }
}

impl CmuSkeleton {
    /// Prepares an ASF skeleton. Bones below the root may only rotate.
    pub fn from_asf(asf: &AsfSkeleton) -> Result<Self, KinematicsError> {
        let to_rad = asf.units.angle.to_radians();
        let upm = asf.units.metres_per_unit();
        let layout = ChannelLayout::of(asf);
        let euler = |angles: [f64; 3], order| euler_rotation(angles.map(|a| (a * to_rad) as f32), order);

        let root = KinematicBone {
            name: "root".to_owned(),
            parent: None,
            rest_offset: Vec3::ZERO,
            local_frame: euler(asf.root.orientation, asf.root.axis),
            dofs: asf.root.order.clone(),
            channel_offset: 0,
        };
        // Parents first: breadth-first from the root over the hierarchy.
        let mut order: Vec<usize> = Vec::with_capacity(asf.bones.len());
        let mut frontier: Vec<Option<usize>> = vec![None];
        while let Some(parent) = frontier.pop() {
            for (i, bone) in asf.bones.iter().enumerate() {
                if bone.parent == parent {
                    order.push(i);
                    frontier.push(Some(i));
                }
            }
        }
        let mut new_index = vec![usize::MAX; asf.bones.len()];
        for (k, &i) in order.iter().enumerate() {
            new_index[i] = k + 1;
        }
        let mut bones = vec![root];
        for &i in &order {
            let b = &asf.bones[i];
            if let Some(&dof) = b.dofs.iter().find(|d| !matches!(d, Dof::Rotation(_))) {
                return Err(KinematicsError::UnsupportedDof { bone: b.name.clone(), dof: dof_name(dof) });
            }
            let direction = Vec3::new(b.direction[0] as f32, b.direction[1] as f32, b.direction[2] as f32);
            bones.push(KinematicBone {
                name: b.name.clone(),
                parent: Some(b.parent.map_or(0, |p| new_index[p])),
                rest_offset: direction * (b.length * upm) as f32,
                local_frame: euler(b.axis, b.axis_order),
                dofs: b.dofs.clone(),
                channel_offset: layout.bone_offsets[i],
            });
        }
        let p = asf.root.position;
        Ok(Self {
            bones,
            root_position: Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32) * upm as f32,
            metres_per_unit: upm as f32,
            angle_unit: asf.units.angle,
            channels_per_frame: layout.channels_per_frame,
        })
    }

    /// Bones, parents first; index 0 is the root.
    pub fn bones(&self) -> &[KinematicBone] {
        &self.bones
    }

    /// Index of the bone called `name` (`"root"` is 0).
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }

    /// Metres per ASF length unit.
    pub fn metres_per_unit(&self) -> f32 {
        self.metres_per_unit
    }

    /// Values per AMC frame.
    pub fn channels_per_frame(&self) -> usize {
        self.channels_per_frame
    }

    /// The rest pose (every DOF zero, root at the origin).
    pub fn rest_pose(&self) -> CmuPose {
        CmuPose { root_translation: Vec3::ZERO, local_rotations: vec![Quat::IDENTITY; self.bones.len()] }
    }

    /// The pose of one AMC frame (`values` in the skeleton's channel layout; angles in
    /// `angle_unit`, root translation in ASF length units).
    pub fn pose_from_frame(&self, values: &[f32], angle_unit: AngleUnit) -> Result<CmuPose, KinematicsError> {
        if values.len() != self.channels_per_frame {
            return Err(KinematicsError::FrameLength { expected: self.channels_per_frame, found: values.len() });
        }
        let to_rad = angle_unit.to_radians() as f32;
        let mut root_translation = Vec3::ZERO;
        let mut local_rotations = Vec::with_capacity(self.bones.len());
        for bone in &self.bones {
            let mut motion = Quat::IDENTITY;
            for (k, dof) in bone.dofs.iter().enumerate() {
                let v = values[bone.channel_offset + k];
                match *dof {
                    Dof::Rotation(axis) => motion = axis.rotation(v * to_rad) * motion,
                    Dof::Translation(axis) => root_translation[axis.index()] = v * self.metres_per_unit,
                    Dof::Length => {}
                }
            }
            local_rotations.push((bone.local_frame * motion * bone.local_frame.conjugate()).normalize());
        }
        Ok(CmuPose { root_translation, local_rotations })
    }

    /// The angle unit the ASF declares (AMC files may override it).
    pub fn angle_unit(&self) -> AngleUnit {
        self.angle_unit
    }

    /// Forward kinematics into `out` (reused between frames to avoid allocation).
    ///
    /// `pose.local_rotations` must have one entry per bone; missing entries count as
    /// identity.
    pub fn forward_kinematics_into(&self, pose: &CmuPose, out: &mut CmuBoneTransforms) {
        let n = self.bones.len();
        out.rotations.resize(n, Quat::IDENTITY);
        out.starts.resize(n, Vec3::ZERO);
        out.ends.resize(n, Vec3::ZERO);
        let root_position = self.root_position + pose.root_translation;
        for (b, bone) in self.bones.iter().enumerate() {
            let local = pose.local_rotations.get(b).copied().unwrap_or(Quat::IDENTITY);
            match bone.parent {
                None => {
                    out.rotations[b] = local;
                    out.starts[b] = root_position;
                    out.ends[b] = root_position;
                }
                Some(p) => {
                    let w = (out.rotations[p] * local).normalize();
                    out.rotations[b] = w;
                    out.starts[b] = out.ends[p];
                    out.ends[b] = out.ends[p] + w * bone.rest_offset;
                }
            }
        }
    }

    /// Forward kinematics, allocating the result.
    pub fn forward_kinematics(&self, pose: &CmuPose) -> CmuBoneTransforms {
        let mut out = CmuBoneTransforms::default();
        self.forward_kinematics_into(pose, &mut out);
        out
    }
}

impl CmuPose {
    /// Interpolates between two poses of the same skeleton: slerp of every bone rotation
    /// (shortest arc), lerp of the root translation; `alpha` in `[0, 1]`.
    pub fn interpolate(&self, other: &CmuPose, alpha: f32) -> CmuPose {
        let local_rotations = self
            .local_rotations
            .iter()
            .zip(&other.local_rotations)
            .map(|(a, b)| {
                let b = if a.dot(*b) < 0.0 { -*b } else { *b };
                a.slerp(b, alpha).normalize()
            })
            .collect();
        CmuPose { root_translation: self.root_translation.lerp(other.root_translation, alpha), local_rotations }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn asf_xyz_applies_x_first() {
        let a = [0.3f32, -0.7, 1.1];
        let q = euler_rotation(a, EulerOrder::ZYX);
        let expected = Quat::from_rotation_z(a[2]) * Quat::from_rotation_y(a[1]) * Quat::from_rotation_x(a[0]);
        assert!(q.abs_diff_eq(expected, 1e-6));
    }

    #[test]
    fn femur_axis_rotates_minus_y_to_the_bone_direction() {
        // CMU lfemur: `axis 0 0 20 XYZ`, direction (sin 20°, −cos 20°, 0): the local −Y axis.
        let c = euler_rotation([0.0, 0.0, 20f32.to_radians()], EulerOrder::ZYX);
        let d = c * Vec3::NEG_Y;
        assert!(d.abs_diff_eq(Vec3::new(0.34202, -0.939693, 0.0), 1e-5));
    }
}
