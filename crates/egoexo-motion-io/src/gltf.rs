//! glTF 2.0 binary (`.glb`): the SMPL skeleton as joint nodes, a skinned bone mesh to see it,
//! and the motion as an animation.
//!
//! # The asset
//! - **World**: glTF's, which is this project's: **Y up**, metres, the body's front facing
//!   +Z in the rest pose. No axis conversion is needed.
//! - **Nodes** 0–23 are the SMPL joints in SMPL order, named as SMPL names them, in SMPL's
//!   tree. In the node's own (bind) transform, `pelvis` sits at `rest[0]` and every other
//!   joint at its rest bone offset `rest[j] − rest[parent]`, with identity rotations: the
//!   rest (T-) pose.
//! - **Skin** `smpl` lists the 24 joint nodes (skeleton root `pelvis`); inverse bind matrices
//!   are `Translate(−rest[j])`.
//! - **Mesh** `bones` (node 24, a scene root, as glTF wants for skinned meshes): one
//!   octahedral bone from every joint to each of its children (plus one up from the head),
//!   each rigidly bound (weight 1) to the bone's parent joint, so it moves exactly like the
//!   skeleton. No normals (viewers shade it flat), a double-sided grey material.
//! - **Animation** `motion`: keyframe times `i / fps` seconds from 0 (the session clock's
//!   start time is not stored); LINEAR samplers; `pelvis` translation = `rest[0] +
//!   translation` (the pelvis joint's world position); rotation of joints 0–21 = the SMPL
//!   root orientation and local body rotations (the hands stay at rest). Quaternion signs
//!   are made continuous so that interpolation takes the short way.

use egoexo_core::SmplMotion;
use egoexo_core::glam::{Quat, Vec3};
use egoexo_core::skeleton::{JOINT_NAMES, NUM_BODY_JOINTS, NUM_JOINTS, PARENTS, SmplJoint, SmplSkeleton};
use gltf_json as json;
use json::validation::{Checked::Valid, USize64};
use json::{Index, Root};

use crate::{ExportError, Format, frame_time_s, validate};

/// The asset's `generator` string.
pub const GENERATOR: &str = concat!("egoexo ", env!("CARGO_PKG_VERSION"));

/// Index of the bone mesh's node (after the 24 joint nodes).
pub const MESH_NODE: usize = NUM_JOINTS;

/// Joints whose rotation is animated (root and the 21 body joints; hands stay at rest).
pub const ANIMATED_JOINTS: usize = 1 + NUM_BODY_JOINTS;

/// Bytes of binary data per frame: time, pelvis translation, one quaternion per animated joint.
const BYTES_PER_FRAME: usize = 4 + 12 + 16 * ANIMATED_JOINTS;

/// Most frames a `.glb` can hold (its lengths are 32-bit).
pub const MAX_FRAMES: usize = (u32::MAX as usize - (1 << 20)) / BYTES_PER_FRAME;

/// GLB container constants (glTF 2.0 § 4.4).
const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const GLB_VERSION: u32 = 2;
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"

/// Writes `motion` as a `.glb` (see the module docs).
pub fn write_glb(motion: &SmplMotion) -> Result<Vec<u8>, ExportError> {
    validate(motion)?;
    if motion.len() > MAX_FRAMES {
        return Err(ExportError::TooManyFrames { format: Format::Glb, frames: motion.len(), limit: MAX_FRAMES });
    }
    let encode = |message: String| ExportError::Encode { format: Format::Glb, message };
    let (root, bin) = build(motion);
    let json = json::serialize::to_vec(&root).map_err(|e| encode(e.to_string()))?;
    glb(json, bin).ok_or_else(|| encode("the asset is larger than a GLB can hold".into()))
}

/// A GLB container of a JSON chunk and a BIN chunk; `None` past 4 GiB.
fn glb(mut json: Vec<u8>, mut bin: Vec<u8>) -> Option<Vec<u8>> {
    pad(&mut json, b' ');
    pad(&mut bin, 0);
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    for word in [GLB_MAGIC, GLB_VERSION, u32::try_from(total).ok()?, u32::try_from(json.len()).ok()?, CHUNK_JSON] {
        out.extend(word.to_le_bytes());
    }
    out.extend(json);
    out.extend(u32::try_from(bin.len()).ok()?.to_le_bytes());
    out.extend(CHUNK_BIN.to_le_bytes());
    out.extend(bin);
    Some(out)
}

/// Pads to a multiple of 4 bytes.
fn pad(bytes: &mut Vec<u8>, with: u8) {
    while !bytes.len().is_multiple_of(4) {
        bytes.push(with);
    }
}

fn f32_bytes(values: impl IntoIterator<Item = f32>) -> Vec<u8> {
    values.into_iter().flat_map(f32::to_le_bytes).collect()
}

/// The binary buffer under construction and the JSON that describes it.
struct Builder {
    root: Root,
    bin: Vec<u8>,
}

impl Builder {
    /// Appends `data` as a buffer view (4-byte aligned).
    fn view(&mut self, data: &[u8], target: Option<json::buffer::Target>) -> Index<json::buffer::View> {
        pad(&mut self.bin, 0);
        let offset = self.bin.len();
        self.bin.extend_from_slice(data);
        self.root.push(json::buffer::View {
            buffer: Index::new(0),
            byte_length: USize64::from(data.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        })
    }

    /// Appends `data` as a tightly packed accessor of `count` elements.
    #[allow(clippy::too_many_arguments)]
    fn accessor(
        &mut self,
        data: &[u8],
        target: Option<json::buffer::Target>,
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        min_max: Option<(Vec<f32>, Vec<f32>)>,
        name: &str,
    ) -> Index<json::Accessor> {
        let view = self.view(data, target);
        let (min, max) = match min_max {
            Some((min, max)) => (Some(json::Value::from(min)), Some(json::Value::from(max))),
            None => (None, None),
        };
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min,
            max,
            name: Some(name.to_string()),
            normalized: false,
            sparse: None,
        })
    }
}

/// A bone's vertices (6) and triangles (8, CCW from outside): a ring of 4 points 15% of the
/// way from `from` to `to`, joined to both ends.
fn octahedral_bone(from: Vec3, to: Vec3) -> ([Vec3; 6], [[u16; 3]; 8]) {
    let along = to - from;
    let length = along.length();
    let d = along / length.max(1e-9);
    let u = d.any_orthonormal_vector();
    let v = d.cross(u);
    let m = from + 0.15 * along;
    let w = 0.08 * length;
    let vertices = [from, m + w * u, m + w * v, m - w * u, m - w * v, to];
    let mut triangles = [[0u16; 3]; 8];
    for i in 0..4u16 {
        let (a, b) = (1 + i, 1 + (i + 1) % 4);
        triangles[i as usize] = [a, b, 5];
        triangles[4 + i as usize] = [b, a, 0];
    }
    (vertices, triangles)
}

/// The bones of the mesh: (joint the bone is bound to, start, end), rest pose, metres.
fn bones(skeleton: &SmplSkeleton) -> Vec<(usize, Vec3, Vec3)> {
    let rest = skeleton.rest_joints();
    let mut bones: Vec<_> =
        (1..NUM_JOINTS).map(|j| (PARENTS[j] as usize, rest[PARENTS[j] as usize], rest[j])).collect();
    let head = SmplJoint::Head.index();
    let head_top = rest[head] + Vec3::Y * 0.12 * (skeleton.head_height() / SmplSkeleton::mean_shape().head_height());
    bones.push((head, rest[head], head_top));
    bones
}

/// The glTF JSON and its binary buffer.
fn build(motion: &SmplMotion) -> (Root, Vec<u8>) {
    use json::accessor::{ComponentType as C, Type as T};
    use json::buffer::Target;

    let skeleton = &motion.skeleton;
    let rest = skeleton.rest_joints();
    let mut b = Builder {
        root: Root {
            asset: json::Asset {
                generator: Some(GENERATOR.to_string()),
                version: "2.0".to_string(),
                copyright: None,
                extensions: None,
                extras: Default::default(),
                min_version: None,
            },
            ..Default::default()
        },
        bin: Vec::new(),
    };

    // Joint nodes 0..24, then the mesh node.
    for j in 0..NUM_JOINTS {
        let children: Vec<Index<json::Node>> =
            (j + 1..NUM_JOINTS).filter(|&c| PARENTS[c] as usize == j).map(|c| Index::new(c as u32)).collect();
        let translation = if j == 0 { rest[0] } else { skeleton.bone_offset(j) };
        b.root.push(json::Node {
            name: Some(JOINT_NAMES[j].to_string()),
            translation: Some(translation.to_array()),
            children: (!children.is_empty()).then_some(children),
            ..Default::default()
        });
    }

    // The bone mesh, skinned rigidly.
    let mut positions = Vec::new();
    let mut joints = Vec::new();
    let mut indices = Vec::new();
    for (joint, from, to) in bones(skeleton) {
        let (vertices, triangles) = octahedral_bone(from, to);
        let base = positions.len() as u16;
        positions.extend(vertices);
        joints.extend(std::iter::repeat_n([joint as u8, 0, 0, 0], vertices.len()));
        indices.extend(triangles.iter().flatten().map(|i| base + i));
    }
    let (min, max) =
        positions.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    let n_vertices = positions.len();
    let position = b.accessor(
        &f32_bytes(positions.iter().flat_map(|p| p.to_array())),
        Some(Target::ArrayBuffer),
        n_vertices,
        C::F32,
        T::Vec3,
        Some((min.to_array().to_vec(), max.to_array().to_vec())),
        "bone positions",
    );
    let joints_0 =
        b.accessor(&joints.concat(), Some(Target::ArrayBuffer), n_vertices, C::U8, T::Vec4, None, "bone joints");
    let weights_0 = b.accessor(
        &f32_bytes(std::iter::repeat_n([1.0, 0.0, 0.0, 0.0], n_vertices).flatten()),
        Some(Target::ArrayBuffer),
        n_vertices,
        C::F32,
        T::Vec4,
        None,
        "bone weights",
    );
    let index_bytes: Vec<u8> = indices.iter().flat_map(|i: &u16| i.to_le_bytes()).collect();
    let index_accessor = b.accessor(
        &index_bytes,
        Some(Target::ElementArrayBuffer),
        indices.len(),
        C::U16,
        T::Scalar,
        None,
        "bone triangles",
    );
    let material = b.root.push(json::Material {
        name: Some("bone".to_string()),
        double_sided: true,
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            base_color_factor: json::material::PbrBaseColorFactor([0.72, 0.74, 0.78, 1.0]),
            metallic_factor: json::material::StrengthFactor(0.0),
            roughness_factor: json::material::StrengthFactor(0.8),
            ..Default::default()
        },
        ..Default::default()
    });
    let mut attributes = std::collections::BTreeMap::new();
    attributes.insert(Valid(json::mesh::Semantic::Positions), position);
    attributes.insert(Valid(json::mesh::Semantic::Joints(0)), joints_0);
    attributes.insert(Valid(json::mesh::Semantic::Weights(0)), weights_0);
    let mesh = b.root.push(json::Mesh {
        name: Some("bones".to_string()),
        primitives: vec![json::mesh::Primitive {
            attributes,
            indices: Some(index_accessor),
            material: Some(material),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
            extensions: None,
            extras: Default::default(),
        }],
        weights: None,
        extensions: None,
        extras: Default::default(),
    });
    // Column-major Translate(−rest[j]).
    let inverse_bind: Vec<f32> = rest
        .iter()
        .flat_map(|p| [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -p.x, -p.y, -p.z, 1.0])
        .collect();
    let ibm = b.accessor(&f32_bytes(inverse_bind), None, NUM_JOINTS, C::F32, T::Mat4, None, "inverse bind matrices");
    let skin = b.root.push(json::Skin {
        name: Some("smpl".to_string()),
        inverse_bind_matrices: Some(ibm),
        joints: (0..NUM_JOINTS as u32).map(Index::new).collect(),
        skeleton: Some(Index::new(0)),
        extensions: None,
        extras: Default::default(),
    });
    let mesh_node = b.root.push(json::Node {
        name: Some("bones".to_string()),
        mesh: Some(mesh),
        skin: Some(skin),
        ..Default::default()
    });
    debug_assert_eq!(mesh_node.value(), MESH_NODE);
    let scene = b.root.push(json::Scene {
        name: Some("egoexo motion".to_string()),
        nodes: vec![Index::new(0), mesh_node],
        extensions: None,
        extras: Default::default(),
    });
    b.root.scene = Some(scene);

    // The animation.
    let n = motion.len();
    let times: Vec<f32> = (0..n).map(|i| frame_time_s(motion, i) as f32).collect();
    let (t0, t1) = (times[0], times[n - 1]);
    let input = b.accessor(&f32_bytes(times), None, n, C::F32, T::Scalar, Some((vec![t0], vec![t1])), "time");
    let pelvis = f32_bytes(motion.poses.iter().flat_map(|p| (rest[0] + p.translation).to_array()));
    let translation = b.accessor(&pelvis, None, n, C::F32, T::Vec3, None, "pelvis translation");
    let mut samplers = Vec::new();
    let mut channels = Vec::new();
    let mut add_channel = |output, node: usize, path| {
        let sampler = Index::push(
            &mut samplers,
            json::animation::Sampler {
                input,
                interpolation: Valid(json::animation::Interpolation::Linear),
                output,
                extensions: None,
                extras: Default::default(),
            },
        );
        channels.push(json::animation::Channel {
            sampler,
            target: json::animation::Target {
                node: Index::new(node as u32),
                path: Valid(path),
                extensions: None,
                extras: Default::default(),
            },
            extensions: None,
            extras: Default::default(),
        });
    };
    add_channel(translation, 0, json::animation::Property::Translation);
    for j in 0..ANIMATED_JOINTS {
        let mut previous = Quat::IDENTITY;
        let rotations: Vec<f32> = motion
            .poses
            .iter()
            .flat_map(|p| {
                let mut q = p.local_rotation(j).normalize();
                if q.dot(previous) < 0.0 {
                    q = -q;
                }
                previous = q;
                q.to_array()
            })
            .collect();
        let output =
            b.accessor(&f32_bytes(rotations), None, n, C::F32, T::Vec4, None, &format!("{} rotation", JOINT_NAMES[j]));
        add_channel(output, j, json::animation::Property::Rotation);
    }
    b.root.push(json::Animation {
        name: Some("motion".to_string()),
        channels,
        samplers,
        extensions: None,
        extras: Default::default(),
    });

    pad(&mut b.bin, 0);
    b.root.push(json::Buffer {
        byte_length: USize64::from(b.bin.len()),
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    (b.root, b.bin)
}

#[cfg(test)]
mod tests {
    use egoexo_core::glam::Mat4;

    use super::*;
    use crate::test_motion;

    /// Reads a GLB back (JSON + BIN) with the same JSON types.
    fn read_glb(bytes: &[u8]) -> (Root, Vec<u8>) {
        let word = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap()) as usize;
        assert_eq!(word(0) as u32, GLB_MAGIC);
        assert_eq!(word(4), 2);
        assert_eq!(word(8), bytes.len());
        let json_len = word(12);
        assert_eq!(word(16) as u32, CHUNK_JSON);
        let root = Root::from_slice(&bytes[20..20 + json_len]).unwrap();
        let bin_start = 20 + json_len;
        assert_eq!(word(bin_start + 4) as u32, CHUNK_BIN);
        let bin = bytes[bin_start + 8..bin_start + 8 + word(bin_start)].to_vec();
        (root, bin)
    }

    fn floats(root: &Root, bin: &[u8], accessor: Index<json::Accessor>) -> Vec<f32> {
        let a = root.get(accessor).unwrap();
        let view = root.get(a.buffer_view.unwrap()).unwrap();
        let start = view.byte_offset.unwrap().0 as usize;
        bin[start..start + view.byte_length.0 as usize]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    /// Plays the animation back by walking the node tree (as a viewer would) and compares
    /// with the project's forward kinematics, at every keyframe.
    #[test]
    fn animation_reproduces_forward_kinematics() {
        let motion = test_motion::motion(25, SmplSkeleton::mean_shape().scaled(1.05), None);
        let (root, bin) = read_glb(&write_glb(&motion).unwrap());
        assert_eq!(root.nodes.len(), NUM_JOINTS + 1);
        let animation = &root.animations[0];
        assert_eq!(animation.channels.len(), 1 + ANIMATED_JOINTS);
        let fk = motion.joint_positions();
        let times = floats(&root, &bin, animation.samplers[0].input);
        assert_eq!(times.len(), 25);
        assert!((times[24] - 24.0 / 30.0).abs() < 1e-6);
        // Node-local transforms per frame, starting from the nodes' own (bind) transforms.
        let mut local: Vec<Vec<(Vec3, Quat)>> = vec![
            root.nodes
                .iter()
                .map(|n| (Vec3::from_array(n.translation.unwrap_or_default()), Quat::IDENTITY))
                .collect();
            25
        ];
        for channel in &animation.channels {
            let values = floats(&root, &bin, animation.samplers[channel.sampler.value()].output);
            let node = channel.target.node.value();
            for (f, frame) in local.iter_mut().enumerate() {
                match channel.target.path {
                    Valid(json::animation::Property::Translation) => {
                        frame[node].0 = Vec3::from_slice(&values[3 * f..3 * f + 3]);
                    }
                    Valid(json::animation::Property::Rotation) => {
                        frame[node].1 = Quat::from_slice(&values[4 * f..4 * f + 4]);
                    }
                    _ => panic!("unexpected channel"),
                }
            }
        }
        for (f, frame) in local.iter().enumerate() {
            let mut world = vec![Mat4::IDENTITY; NUM_JOINTS];
            for j in 0..NUM_JOINTS {
                let m = Mat4::from_rotation_translation(frame[j].1, frame[j].0);
                world[j] = if j == 0 { m } else { world[PARENTS[j] as usize] * m };
                let p = world[j].w_axis.truncate();
                assert!(p.distance(fk[f][j]) < 1e-5, "frame {f} joint {j}: {p} vs {}", fk[f][j]);
            }
        }
    }

    #[test]
    fn skin_binds_the_mesh_at_the_rest_pose() {
        let motion = test_motion::motion(2, SmplSkeleton::mean_shape(), None);
        let (root, bin) = read_glb(&write_glb(&motion).unwrap());
        let skin = &root.skins[0];
        assert_eq!(skin.joints.len(), NUM_JOINTS);
        let ibm = floats(&root, &bin, skin.inverse_bind_matrices.unwrap());
        for j in 0..NUM_JOINTS {
            let m = Mat4::from_cols_slice(&ibm[16 * j..16 * j + 16]);
            let p = m.transform_point3(motion.skeleton.rest_joints()[j]);
            assert!(p.length() < 1e-6, "joint {j}");
        }
        let mesh_node = &root.nodes[MESH_NODE];
        assert!(mesh_node.translation.is_none() && mesh_node.rotation.is_none());
        assert!(root.scenes[0].nodes.iter().any(|n| n.value() == MESH_NODE));
    }

    #[test]
    fn quaternions_are_sign_continuous() {
        let mut motion = test_motion::motion(3, SmplSkeleton::mean_shape(), None);
        motion.poses[1].body[0] = -motion.poses[1].body[0];
        let (root, bin) = read_glb(&write_glb(&motion).unwrap());
        let animation = &root.animations[0];
        let hip = animation.channels.iter().find(|c| c.target.node.value() == 1).unwrap();
        let q = floats(&root, &bin, animation.samplers[hip.sampler.value()].output);
        let dot = |a: usize, b: usize| (0..4).map(|k| q[4 * a + k] * q[4 * b + k]).sum::<f32>();
        assert!(dot(0, 1) > 0.0 && dot(1, 2) > 0.0);
    }
}
