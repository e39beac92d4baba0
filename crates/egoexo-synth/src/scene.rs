//! Things that stand between observers and the wearer: furniture (oriented boxes on the floor)
//! bystanders (vertical cylinders walking straight lines) and, in group scenes, the other
//! people (cylinders following their recorded paths).
//!
//! World Y-up, metres, seconds.

use egoexo_core::glam::{Quat, Vec2, Vec3};

/// A box standing on the floor, rotated about +Y.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Furniture {
    /// Centre of the box (metres).
    pub center: Vec3,
    /// Half extents along the box's own X, Y, Z (metres).
    pub half_extents: Vec3,
    /// Rotation about world +Y (radians).
    pub yaw: f32,
}

impl Furniture {
    /// Whether the segment `a → b` passes through the box (slab test in the box frame).
    pub fn blocks(&self, a: Vec3, b: Vec3) -> bool {
        let to_box = Quat::from_rotation_y(-self.yaw);
        let a = to_box * (a - self.center);
        let d = to_box * (b - self.center) - a;
        let (mut t0, mut t1) = (0.0f32, 1.0f32);
        for axis in 0..3 {
            let (origin, dir, half) = (a[axis], d[axis], self.half_extents[axis]);
            if dir.abs() < 1e-9 {
                if origin.abs() > half {
                    return false;
                }
                continue;
            }
            let (mut near, mut far) = ((-half - origin) / dir, (half - origin) / dir);
            if near > far {
                std::mem::swap(&mut near, &mut far);
            }
            t0 = t0.max(near);
            t1 = t1.min(far);
            if t0 > t1 {
                return false;
            }
        }
        true
    }
}

/// A person walking a straight line at constant speed, modelled as a vertical cylinder.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bystander {
    /// Floor position at time `t = 0` (y = floor height).
    pub start: Vec3,
    /// Horizontal velocity (m/s).
    pub velocity: Vec3,
    pub radius: f32,
    pub height: f32,
}

impl Bystander {
    /// Floor position at time `t` (seconds from the session start).
    pub fn position(&self, t: f32) -> Vec3 {
        self.start + self.velocity * t
    }

    /// Whether the segment `a → b` passes through the cylinder at time `t`.
    pub fn blocks(&self, t: f32, a: Vec3, b: Vec3) -> bool {
        cylinder_blocks(self.position(t), self.radius, self.height, a, b)
    }
}

/// A person following a recorded path (a participant of a group scene, or a bystander with a
/// body), modelled as a vertical cylinder under their head.
#[derive(Clone, Debug, PartialEq)]
pub struct Walker {
    /// Frames per second of `floor`.
    pub fps: f32,
    /// Floor position under the person per frame (y = floor height).
    pub floor: Vec<Vec3>,
    pub radius: f32,
    pub height: f32,
}

impl Walker {
    /// Whether the segment `a → b` passes through the cylinder at time `t` (the nearest frame;
    /// before the first or after the last frame the person is where they start or end).
    pub fn blocks(&self, t: f32, a: Vec3, b: Vec3) -> bool {
        let Some(last) = self.floor.len().checked_sub(1) else { return false };
        let frame = ((t * self.fps).round().max(0.0) as usize).min(last);
        cylinder_blocks(self.floor[frame], self.radius, self.height, a, b)
    }
}

/// Whether the segment `a → b` passes through the vertical cylinder standing at `base` (on
/// the floor) with `radius` and `height`.
fn cylinder_blocks(base: Vec3, radius: f32, height: f32, a: Vec3, b: Vec3) -> bool {
    let a2 = Vec2::new(a.x - base.x, a.z - base.z);
    let d2 = Vec2::new(b.x - a.x, b.z - a.z);
    // Solve |a2 + s d2| = r for s in [0, 1].
    let qa = d2.length_squared();
    let qb = 2.0 * a2.dot(d2);
    let qc = a2.length_squared() - radius * radius;
    let (s0, s1) = if qa < 1e-12 {
        if qc > 0.0 {
            return false;
        }
        (0.0, 1.0)
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 {
            return false;
        }
        let root = disc.sqrt();
        (((-qb - root) / (2.0 * qa)).max(0.0), ((-qb + root) / (2.0 * qa)).min(1.0))
    };
    if s0 > s1 {
        return false;
    }
    // The segment is inside the cylinder's footprint for s in [s0, s1]; check heights.
    let (y0, y1) = (a.y + (b.y - a.y) * s0, a.y + (b.y - a.y) * s1);
    let (lo, hi) = (base.y, base.y + height);
    y0.min(y1) <= hi && y0.max(y1) >= lo
}

/// Everything that can occlude, for one session.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    pub furniture: Vec<Furniture>,
    pub bystanders: Vec<Bystander>,
    /// People with a recorded path (group scenes).
    pub walkers: Vec<Walker>,
}

impl Scene {
    /// Whether the line of sight `eye → point` is blocked at time `t`.
    pub fn blocks(&self, t: f32, eye: Vec3, point: Vec3) -> bool {
        // Stop just short of the point so a joint touching a surface still counts as seen.
        let end = eye + (point - eye) * 0.98;
        self.furniture.iter().any(|f| f.blocks(eye, end))
            || self.bystanders.iter().any(|b| b.blocks(t, eye, end))
            || self.walkers.iter().any(|w| w.blocks(t, eye, end))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_blocks_only_segments_through_it() {
        let table = Furniture { center: Vec3::new(0.0, 0.4, 0.0), half_extents: Vec3::new(1.0, 0.4, 0.3), yaw: 0.5 };
        assert!(table.blocks(Vec3::new(0.0, 0.3, -3.0), Vec3::new(0.0, 0.3, 3.0)));
        assert!(!table.blocks(Vec3::new(0.0, 1.0, -3.0), Vec3::new(0.0, 1.0, 3.0)), "passes above");
        assert!(!table.blocks(Vec3::new(0.0, 0.3, -3.0), Vec3::new(0.0, 0.3, -2.0)), "stops short");
        assert!(!table.blocks(Vec3::new(3.0, 0.3, -3.0), Vec3::new(3.0, 0.3, 3.0)), "passes beside");
    }

    #[test]
    fn bystander_blocks_while_crossing() {
        let person = Bystander { start: Vec3::new(-2.0, 0.0, 0.0), velocity: Vec3::X, radius: 0.25, height: 1.8 };
        let (eye, target) = (Vec3::new(0.0, 1.6, -4.0), Vec3::new(0.0, 1.0, 4.0));
        assert!(!person.blocks(0.0, eye, target), "still 2 m to the side");
        assert!(person.blocks(2.0, eye, target), "in the middle of the line of sight");
        assert!(!person.blocks(2.0, Vec3::new(0.0, 2.5, -4.0), Vec3::new(0.0, 2.5, 4.0)), "above their head");
    }
}
