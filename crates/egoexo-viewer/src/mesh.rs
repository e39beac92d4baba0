//! The two meshes every solid is instanced from, and the floor grid's lines.
//!
//! Triangles wind counter-clockwise seen from outside (front faces), matching the
//! renderer's back-face culling.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::colors::{self, Rgba};

/// A mesh vertex in the mesh's own frame.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct MeshVertex {
    pub position: [f32; 3],
    /// Unit outward normal.
    pub normal: [f32; 3],
}

/// An indexed triangle mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<MeshVertex>,
    /// Triangle list, counter-clockwise from outside.
    pub indices: Vec<u16>,
}

/// A vertex of a world-space line (grid, full trajectories), metres.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct LineVertex {
    pub position: [f32; 3],
    pub colour: Rgba,
}

/// The unit sphere (radius 1, centred at the origin) as `rings` latitude bands of
/// `segments` quads each.
pub fn unit_sphere(rings: u16, segments: u16) -> Mesh {
    let (rings, segments) = (rings.max(2), segments.max(3));
    let mut mesh = Mesh::default();
    for r in 0..=rings {
        let polar = std::f32::consts::PI * f32::from(r) / f32::from(rings);
        for s in 0..=segments {
            let azimuth = std::f32::consts::TAU * f32::from(s) / f32::from(segments);
            let n = Vec3::new(polar.sin() * azimuth.cos(), polar.cos(), -polar.sin() * azimuth.sin());
            mesh.vertices.push(MeshVertex { position: n.to_array(), normal: n.to_array() });
        }
    }
    let row = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let (a, b) = (r * row + s, (r + 1) * row + s);
            // Skip the degenerate triangles at the poles.
            if r != 0 {
                mesh.indices.extend_from_slice(&[a, b, a + 1]);
            }
            if r != rings - 1 {
                mesh.indices.extend_from_slice(&[a + 1, b, b + 1]);
            }
        }
    }
    mesh
}

/// The unit cylinder: radius 1 around +Y from `y = 0` to `y = 1`, with flat caps, `segments`
/// sides.
pub fn unit_cylinder(segments: u16) -> Mesh {
    let segments = segments.max(3);
    let mut mesh = Mesh::default();
    let ring = |i: u16| {
        let a = std::f32::consts::TAU * f32::from(i) / f32::from(segments);
        Vec3::new(a.cos(), 0.0, -a.sin())
    };
    // Side: a quad strip with outward radial normals.
    for i in 0..=segments {
        let n = ring(i);
        mesh.vertices.push(MeshVertex { position: n.to_array(), normal: n.to_array() });
        mesh.vertices.push(MeshVertex { position: (n + Vec3::Y).to_array(), normal: n.to_array() });
    }
    for i in 0..segments {
        let (b0, t0, b1, t1) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
        mesh.indices.extend_from_slice(&[b0, b1, t0, t0, b1, t1]);
    }
    // Caps: a centre vertex and a fan, normals ∓Y.
    for (y, normal) in [(0.0f32, -Vec3::Y), (1.0, Vec3::Y)] {
        let centre = mesh.vertices.len() as u16;
        mesh.vertices.push(MeshVertex { position: [0.0, y, 0.0], normal: normal.to_array() });
        for i in 0..segments {
            mesh.vertices.push(MeshVertex { position: (ring(i) + Vec3::Y * y).to_array(), normal: normal.to_array() });
        }
        for i in 0..segments {
            let (p, q) = (centre + 1 + i, centre + 1 + (i + 1) % segments);
            if normal.y > 0.0 {
                mesh.indices.extend_from_slice(&[centre, p, q]);
            } else {
                mesh.indices.extend_from_slice(&[centre, q, p]);
            }
        }
    }
    mesh
}

/// Floor grid lines at height `y`, centred on the grid point nearest `(centre_x, centre_z)`,
/// `half_extent` metres each way, a line every `step` metres; lines on whole metres are major.
pub fn floor_grid(centre_x: f32, centre_z: f32, y: f32, half_extent: f32, step: f32) -> Vec<LineVertex> {
    let step = if step.is_finite() && step > 0.0 { step } else { 0.5 };
    let half = if half_extent.is_finite() { half_extent.clamp(step, 1000.0) } else { 10.0 };
    let snap = |v: f32| if v.is_finite() { (v / step).round() * step } else { 0.0 };
    let (cx, cz) = (snap(centre_x), snap(centre_z));
    let y = if y.is_finite() { y } else { 0.0 };
    let n = (half / step).ceil() as i32;
    let mut lines = Vec::with_capacity(8 * n as usize + 4);
    for i in -n..=n {
        let offset = i as f32 * step;
        let (x, z) = (cx + offset, cz + offset);
        let major = |v: f32| (v - v.round()).abs() < 1e-3;
        let colour = |v: f32| if major(v) { colors::GRID_MAJOR } else { colors::GRID_MINOR };
        let extent = n as f32 * step;
        lines.push(LineVertex { position: [x, y, cz - extent], colour: colour(x) });
        lines.push(LineVertex { position: [x, y, cz + extent], colour: colour(x) });
        lines.push(LineVertex { position: [cx - extent, y, z], colour: colour(z) });
        lines.push(LineVertex { position: [cx + extent, y, z], colour: colour(z) });
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    /// Every triangle is non-degenerate, indexes the mesh, and faces along its vertices'
    /// normals (counter-clockwise from outside).
    fn assert_well_formed(mesh: &Mesh) {
        assert_eq!(mesh.indices.len() % 3, 0);
        for tri in mesh.indices.chunks(3) {
            let v: Vec<&MeshVertex> = tri.iter().map(|&i| &mesh.vertices[usize::from(i)]).collect();
            let p: Vec<Vec3> = v.iter().map(|v| Vec3::from(v.position)).collect();
            let face = (p[1] - p[0]).cross(p[2] - p[0]);
            assert!(face.length() > 1e-6, "degenerate triangle {tri:?}");
            let normal: Vec3 = v.iter().map(|v| Vec3::from(v.normal)).sum();
            assert!(face.dot(normal) > 0.0, "triangle {tri:?} winds inward");
        }
        for v in &mesh.vertices {
            assert!((Vec3::from(v.normal).length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn sphere_is_closed_unit_and_outward() {
        let mesh = unit_sphere(8, 12);
        assert_well_formed(&mesh);
        for v in &mesh.vertices {
            assert!((Vec3::from(v.position).length() - 1.0).abs() < 1e-5);
        }
        // Triangles: 2 per quad minus one at each pole per segment.
        assert_eq!(mesh.indices.len() / 3, 2 * 8 * 12 - 2 * 12);
        let area: f32 = mesh
            .indices
            .chunks(3)
            .map(|t| {
                let p = |i: u16| Vec3::from(mesh.vertices[usize::from(i)].position);
                0.5 * (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).length()
            })
            .sum();
        let sphere = 4.0 * std::f32::consts::PI;
        assert!(area < sphere && area > 0.9 * sphere, "{area}");
    }

    #[test]
    fn cylinder_spans_zero_to_one_along_y() {
        let mesh = unit_cylinder(10);
        assert_well_formed(&mesh);
        for v in &mesh.vertices {
            let p = Vec3::from(v.position);
            assert!((0.0..=1.0).contains(&p.y));
            assert!(Vec3::new(p.x, 0.0, p.z).length() <= 1.0 + 1e-5);
        }
        assert_eq!(mesh.indices.len() / 3, 2 * 10 + 2 * 10);
    }

    #[test]
    fn grid_is_centred_snapped_and_has_major_lines() {
        let lines = floor_grid(0.26, -1.1, 0.05, 2.0, 0.5);
        assert_eq!(lines.len() % 2, 0);
        assert!(lines.iter().all(|v| v.position[1] == 0.05));
        let xs: Vec<f32> = lines.iter().map(|v| v.position[0]).collect();
        let (min, max) = xs.iter().fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        assert!((min + 1.5).abs() < 1e-5 && (max - 2.5).abs() < 1e-5, "{min} {max}");
        assert!(lines.iter().any(|v| v.colour == colors::GRID_MAJOR));
        assert!(lines.iter().any(|v| v.colour == colors::GRID_MINOR));
        // Garbage in, a sane grid out.
        let fallback = floor_grid(f32::NAN, 0.0, f32::INFINITY, f32::NAN, -1.0);
        assert!(!fallback.is_empty() && fallback.iter().all(|v| v.position.iter().all(|c| c.is_finite())));
    }
}
