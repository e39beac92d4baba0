//! The viewer's palette. Colours are display (sRGB-encoded) RGBA in `0..=1`; the shaders light
//! them in that space and the renderer writes them to a non-sRGB target unchanged.

use egoexo_core::skeleton::JOINT_NAMES;

/// An RGBA colour, display-encoded, each channel in `0..=1`.
pub type Rgba = [f32; 4];

/// Which side of the body a joint or bone belongs to (SMPL names: `left_*`, `right_*`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BodySide {
    Left,
    Right,
    Centre,
}

impl BodySide {
    /// Side of SMPL joint `joint` (by its name); out-of-range joints are `Centre`.
    pub fn of_joint(joint: usize) -> Self {
        match JOINT_NAMES.get(joint) {
            Some(name) if name.starts_with("left_") => Self::Left,
            Some(name) if name.starts_with("right_") => Self::Right,
            _ => Self::Centre,
        }
    }

    /// The reconstruction's colour for this side.
    pub fn colour(self) -> Rgba {
        match self {
            Self::Left => LEFT,
            Self::Right => RIGHT,
            Self::Centre => CENTRE,
        }
    }
}

/// Left joints and bones of the reconstruction (blue).
pub const LEFT: Rgba = [0.20, 0.52, 1.00, 1.0];
/// Right joints and bones of the reconstruction (orange).
pub const RIGHT: Rgba = [1.00, 0.45, 0.12, 1.0];
/// Centre joints and bones (spine, neck, head) of the reconstruction (near white).
pub const CENTRE: Rgba = [0.90, 0.90, 0.86, 1.0];
/// The ego-only comparison overlay (violet, translucent).
pub const EGO_ONLY: Rgba = [0.78, 0.42, 1.00, 0.55];
/// The ground-truth ghost (pale cyan, translucent).
pub const GROUND_TRUTH: Rgba = [0.55, 0.95, 0.92, 0.33];
/// Clear colour behind the scene (dark slate).
pub const BACKGROUND: Rgba = [0.075, 0.085, 0.105, 1.0];
/// The floor disc under the grid (a shade above the background, so shadows show on it).
pub const FLOOR: Rgba = [0.15, 0.16, 0.19, 1.0];
/// Contact shadows on the floor (drawn with a per-disc alpha).
pub const SHADOW: Rgba = [0.0, 0.0, 0.0, 1.0];
/// Minor floor grid lines.
pub const GRID_MINOR: Rgba = [0.32, 0.34, 0.38, 0.45];
/// Major floor grid lines (every metre).
pub const GRID_MAJOR: Rgba = [0.45, 0.48, 0.53, 0.8];
/// The head device's trajectory (yellow).
pub const HEAD_DEVICE: Rgba = [1.00, 0.84, 0.20, 1.0];
/// Observer frustum colours, cycled by observer index.
pub const OBSERVERS: [Rgba; 4] =
    [[0.30, 0.90, 0.95, 1.0], [0.95, 0.45, 0.85, 1.0], [0.70, 0.95, 0.35, 1.0], [0.95, 0.75, 0.45, 1.0]];

/// Other participants of a capture, by their colour index (the capture's order, cycled):
/// one colour per body, none of them the wearer's side colours, the overlay's or the ghost's.
pub const PARTICIPANTS: [Rgba; 6] = [
    [0.98, 0.78, 0.28, 1.0],
    [0.36, 0.86, 0.52, 1.0],
    [0.93, 0.40, 0.58, 1.0],
    [0.45, 0.78, 1.00, 1.0],
    [0.80, 0.62, 0.98, 1.0],
    [0.55, 0.92, 0.88, 1.0],
];

/// Participant colour `index` (cycled).
pub fn participant_colour(index: usize) -> Rgba {
    PARTICIPANTS[index % PARTICIPANTS.len()]
}

/// `c` as a CSS colour (`rgb(r g b)`), for the page's legend.
pub fn css(c: Rgba) -> String {
    let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    format!("rgb({} {} {})", byte(c[0]), byte(c[1]), byte(c[2]))
}

/// Gate value `0` (ray ignored) → red, `0.5` → yellow, `1` (ray trusted) → green; values
/// outside `0..=1` are clamped and a non-finite gate is drawn as red.
pub fn gate_colour(gate: f32) -> Rgba {
    const RED: [f32; 3] = [0.92, 0.16, 0.12];
    const YELLOW: [f32; 3] = [0.98, 0.85, 0.15];
    const GREEN: [f32; 3] = [0.18, 0.86, 0.32];
    let g = if gate.is_finite() { gate.clamp(0.0, 1.0) } else { 0.0 };
    let (from, to, t) = if g < 0.5 { (RED, YELLOW, g * 2.0) } else { (YELLOW, GREEN, g * 2.0 - 1.0) };
    [from[0] + (to[0] - from[0]) * t, from[1] + (to[1] - from[1]) * t, from[2] + (to[2] - from[2]) * t, 1.0]
}

/// A device trajectory's colour by device name (`head`, `left_wrist`, `right_wrist`, other).
pub fn device_colour(name: &str) -> Rgba {
    match name {
        "head" => HEAD_DEVICE,
        n if n.starts_with("left") => lighten(LEFT, 0.35),
        n if n.starts_with("right") => lighten(RIGHT, 0.35),
        _ => [0.8, 0.8, 0.8, 1.0],
    }
}

/// The colour of a frame without a valid reconstruction: desaturated towards grey and
/// translucent, so it reads as "held pose, not tracked".
pub fn dimmed(c: Rgba) -> Rgba {
    let grey = 0.5 * (c[0] + c[1] + c[2]) / 3.0 + 0.2;
    let mix = |x: f32| 0.3 * x + 0.7 * grey;
    [mix(c[0]), mix(c[1]), mix(c[2]), 0.3 * c[3]]
}

/// `c` moved towards white by `t` (`0..=1`).
pub fn lighten(c: Rgba, t: f32) -> Rgba {
    [c[0] + (1.0 - c[0]) * t, c[1] + (1.0 - c[1]) * t, c[2] + (1.0 - c[2]) * t, c[3]]
}

/// `c` with its alpha multiplied by `a`.
pub fn with_alpha(c: Rgba, a: f32) -> Rgba {
    [c[0], c[1], c[2], c[3] * a]
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn sides_follow_smpl_names() {
        assert_eq!(BodySide::of_joint(0), BodySide::Centre); // pelvis
        assert_eq!(BodySide::of_joint(1), BodySide::Left); // left_hip
        assert_eq!(BodySide::of_joint(2), BodySide::Right); // right_hip
        assert_eq!(BodySide::of_joint(15), BodySide::Centre); // head
        assert_eq!(BodySide::of_joint(20), BodySide::Left); // left_wrist
        assert_eq!(BodySide::of_joint(23), BodySide::Right); // right_hand
        assert_eq!(BodySide::of_joint(99), BodySide::Centre);
        let lefts = (0..24).filter(|&j| BodySide::of_joint(j) == BodySide::Left).count();
        let rights = (0..24).filter(|&j| BodySide::of_joint(j) == BodySide::Right).count();
        assert_eq!((lefts, rights), (9, 9));
    }

    #[test]
    fn gate_ramp_runs_red_to_green_and_tolerates_bad_values() {
        let low = gate_colour(0.0);
        let high = gate_colour(1.0);
        assert!(low[0] > 0.8 && low[1] < 0.3, "{low:?}");
        assert!(high[1] > 0.8 && high[0] < 0.3, "{high:?}");
        assert_eq!(gate_colour(-3.0), low);
        assert_eq!(gate_colour(7.0), high);
        assert_eq!(gate_colour(f32::NAN), low);
        // Green grows monotonically with the gate.
        let greens: Vec<f32> = (0..=10).map(|i| gate_colour(i as f32 / 10.0)[1]).collect();
        assert!(greens.windows(2).all(|w| w[1] >= w[0] - 0.02), "{greens:?}");
    }

    #[test]
    fn dimmed_colours_are_greyer_and_translucent() {
        let d = dimmed(RIGHT);
        assert!(d[3] < 0.5);
        let spread = |c: Rgba| c[0].max(c[1]).max(c[2]) - c[0].min(c[1]).min(c[2]);
        assert!(spread(d) < 0.5 * spread(RIGHT));
    }
}
