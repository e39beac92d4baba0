//! Euler (Tait–Bryan) angles: the one [`Axis`] and [`EulerOrder`] of the project, with one
//! stated convention. Motion formats (BVH, ASF/AMC) describe joint rotations this way; their
//! readers and writers translate their file's wording into this convention once, here named.
//!
//! # Convention
//! `EulerOrder::new([A, B, C])` with angles `[a, b, c]` (radians, in that order) is the matrix
//! product
//!
//! ```text
//! R = R_A(a) · R_B(b) · R_C(c)        acting on column vectors
//! ```
//!
//! read as *intrinsic* rotations it is A, then B about the moved axes, then C; read as
//! *extrinsic* (fixed-axis) rotations it applies C first, then B, then A.
//! - **BVH** lists rotation channels in this product order: `Zrotation Xrotation Yrotation`
//!   is `ZXY`, `R = Rz · Rx · Ry`.
//! - **ASF/AMC** (`axis XYZ`, CMU's viewer) name the axes in the order they are *applied*, X
//!   first: `R = Rz · Ry · Rx`, which is [`EulerOrder::ZYX`] here
//!   ([`EulerOrder::from_applied_first`]).
//!
//! Right-handed rotations; a positive angle turns counter-clockwise looking down the axis.

use glam::{DMat3, DQuat, Quat};
use serde::{Deserialize, Serialize};

/// A coordinate axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    /// All three, in X, Y, Z order.
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    /// 0, 1, 2 for X, Y, Z.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }

    /// The axis named by `c` (`x`, `Y`, …), ASCII case ignored.
    pub fn from_letter(c: char) -> Option<Axis> {
        match c.to_ascii_uppercase() {
            'X' => Some(Axis::X),
            'Y' => Some(Axis::Y),
            'Z' => Some(Axis::Z),
            _ => None,
        }
    }

    /// The rotation by `radians` about this axis (`f64`).
    pub fn rotation_f64(self, radians: f64) -> DQuat {
        match self {
            Axis::X => DQuat::from_rotation_x(radians),
            Axis::Y => DQuat::from_rotation_y(radians),
            Axis::Z => DQuat::from_rotation_z(radians),
        }
    }

    /// The rotation by `radians` about this axis (`f32`).
    pub fn rotation(self, radians: f32) -> Quat {
        match self {
            Axis::X => Quat::from_rotation_x(radians),
            Axis::Y => Quat::from_rotation_y(radians),
            Axis::Z => Quat::from_rotation_z(radians),
        }
    }
}

/// Three distinct axes in matrix-product order, outermost first (see the module docs):
/// `EulerOrder::ZXY` is `R = Rz · Rx · Ry`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "[Axis; 3]", into = "[Axis; 3]")]
pub struct EulerOrder([Axis; 3]);

impl EulerOrder {
    pub const XYZ: EulerOrder = EulerOrder([Axis::X, Axis::Y, Axis::Z]);
    pub const XZY: EulerOrder = EulerOrder([Axis::X, Axis::Z, Axis::Y]);
    pub const YXZ: EulerOrder = EulerOrder([Axis::Y, Axis::X, Axis::Z]);
    pub const YZX: EulerOrder = EulerOrder([Axis::Y, Axis::Z, Axis::X]);
    pub const ZXY: EulerOrder = EulerOrder([Axis::Z, Axis::X, Axis::Y]);
    pub const ZYX: EulerOrder = EulerOrder([Axis::Z, Axis::Y, Axis::X]);

    /// All six orders.
    pub const ALL: [EulerOrder; 6] =
        [EulerOrder::XYZ, EulerOrder::XZY, EulerOrder::YXZ, EulerOrder::YZX, EulerOrder::ZXY, EulerOrder::ZYX];

    /// The order of `axes` in product order (outermost first); `None` unless they are three
    /// distinct axes.
    pub fn new(axes: [Axis; 3]) -> Option<EulerOrder> {
        let [a, b, c] = axes;
        (a != b && b != c && a != c).then_some(EulerOrder(axes))
    }

    /// The order of `axes` listed as they are *applied* to a vector, first applied first (the
    /// ASF/AMC wording): the reverse product order.
    pub fn from_applied_first(axes: [Axis; 3]) -> Option<EulerOrder> {
        let [a, b, c] = axes;
        EulerOrder::new([c, b, a])
    }

    /// Parses three axis letters in product order (`"ZXY"`), ASCII case ignored.
    pub fn parse(letters: &str) -> Option<EulerOrder> {
        let mut chars = letters.chars();
        let axes = [chars.next()?, chars.next()?, chars.next()?].map(Axis::from_letter);
        if chars.next().is_some() {
            return None;
        }
        EulerOrder::new([axes[0]?, axes[1]?, axes[2]?])
    }

    /// The axes in product order, outermost first.
    pub fn axes(self) -> [Axis; 3] {
        self.0
    }

    /// The axes in the order they are applied to a vector (the reverse of [`Self::axes`]).
    pub fn applied_first(self) -> [Axis; 3] {
        let [a, b, c] = self.0;
        [c, b, a]
    }

    /// The three letters in product order (`"ZXY"`).
    pub fn letters(self) -> String {
        self.0.iter().map(|a| ['X', 'Y', 'Z'][a.index()]).collect()
    }

    /// `R_A(a) · R_B(b) · R_C(c)` for `radians = [a, b, c]` in product order (`f64`).
    pub fn to_quat_f64(self, radians: [f64; 3]) -> DQuat {
        let [a, b, c] = self.0;
        a.rotation_f64(radians[0]) * (b.rotation_f64(radians[1]) * c.rotation_f64(radians[2]))
    }

    /// `R_A(a) · R_B(b) · R_C(c)` for `radians = [a, b, c]` in product order (`f32`).
    pub fn to_quat(self, radians: [f32; 3]) -> Quat {
        let [a, b, c] = self.0;
        a.rotation(radians[0]) * (b.rotation(radians[1]) * c.rotation(radians[2]))
    }

    /// Angles in radians (product order) with `self.to_quat_f64(angles) == q`. The middle
    /// angle is in `[-π/2, π/2]`, the others in `(-π, π]`; at the middle angle's ±π/2 (gimbal
    /// lock) the innermost angle is set to 0.
    pub fn angles_f64(self, q: DQuat) -> [f64; 3] {
        let [i, j, k] = self.0.map(Axis::index);
        // +1 for a cyclic (even) permutation of XYZ, −1 otherwise.
        let sign = if (j + 3 - i) % 3 == 1 { 1.0 } else { -1.0 };
        let m = DMat3::from_quat(q.normalize());
        let r = |row: usize, col: usize| m.col(col)[row];
        let cos_middle = r(i, i).hypot(r(i, j));
        let middle = (sign * r(i, k)).atan2(cos_middle);
        let (outer, inner) = if cos_middle > 1e-9 {
            ((-sign * r(j, k)).atan2(r(k, k)), (-sign * r(i, j)).atan2(r(i, i)))
        } else {
            ((sign * r(k, j)).atan2(r(j, j)), 0.0)
        };
        [outer, middle, inner]
    }
}

impl TryFrom<[Axis; 3]> for EulerOrder {
    type Error = String;

    fn try_from(axes: [Axis; 3]) -> Result<Self, Self::Error> {
        EulerOrder::new(axes).ok_or_else(|| format!("Euler axes must be three distinct axes, got {axes:?}"))
    }
}

impl From<EulerOrder> for [Axis; 3] {
    fn from(order: EulerOrder) -> Self {
        order.0
    }
}

impl std::fmt::Display for EulerOrder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.letters())
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    #[test]
    fn product_order_is_outermost_first() {
        let (a, b, c) = (0.3, -0.7, 1.1);
        let expected = DQuat::from_rotation_z(a) * DQuat::from_rotation_x(b) * DQuat::from_rotation_y(c);
        assert!(EulerOrder::ZXY.to_quat_f64([a, b, c]).abs_diff_eq(expected, 1e-12));
        // Extrinsic reading: Ry is applied to a vector first.
        let v = DVec3::new(0.2, 0.5, -0.4);
        let stepwise = DQuat::from_rotation_z(a) * (DQuat::from_rotation_x(b) * (DQuat::from_rotation_y(c) * v));
        assert!((EulerOrder::ZXY.to_quat_f64([a, b, c]) * v).abs_diff_eq(stepwise, 1e-12));
    }

    #[test]
    fn applied_first_is_the_reverse() {
        let asf_xyz = EulerOrder::from_applied_first([Axis::X, Axis::Y, Axis::Z]).unwrap();
        assert_eq!(asf_xyz, EulerOrder::ZYX);
        assert_eq!(asf_xyz.applied_first(), [Axis::X, Axis::Y, Axis::Z]);
        assert_eq!(EulerOrder::parse("zxy"), Some(EulerOrder::ZXY));
        assert_eq!(EulerOrder::parse("XXY"), None);
        assert_eq!(EulerOrder::parse("XY"), None);
        assert_eq!(EulerOrder::parse("XYZW"), None);
        assert_eq!(EulerOrder::ZXY.to_string(), "ZXY");
    }

    #[test]
    fn angles_round_trip_in_every_order_and_at_gimbal_lock() {
        let angles = [[0.4, -0.3, 1.2], [-2.9, 1.4, 0.1], [3.0, -1.5, -3.0], [0.0, 0.0, 0.0]];
        for order in EulerOrder::ALL {
            for a in angles {
                let q = order.to_quat_f64(a);
                let back = order.to_quat_f64(order.angles_f64(q));
                assert!(back.dot(q).abs() > 1.0 - 1e-12, "{order} {a:?}");
            }
            let locked = order.to_quat_f64([0.5, std::f64::consts::FRAC_PI_2, 0.3]);
            let back = order.angles_f64(locked);
            assert_eq!(back[2], 0.0, "{order}");
            assert!(order.to_quat_f64(back).dot(locked).abs() > 1.0 - 1e-9, "{order}");
        }
    }

    #[test]
    fn f32_and_f64_agree() {
        for order in EulerOrder::ALL {
            let q = order.to_quat([0.3, -0.2, 0.9]);
            let d = order.to_quat_f64([0.3, -0.2, 0.9]);
            assert!(q.as_dquat().abs_diff_eq(d, 1e-6), "{order}");
        }
    }

    #[test]
    fn serde_refuses_repeated_axes() {
        let json = serde_json::to_string(&EulerOrder::YXZ).unwrap();
        assert_eq!(json, r#"["Y","X","Z"]"#);
        assert_eq!(serde_json::from_str::<EulerOrder>(&json).unwrap(), EulerOrder::YXZ);
        assert!(serde_json::from_str::<EulerOrder>(r#"["X","X","Z"]"#).is_err());
    }
}
