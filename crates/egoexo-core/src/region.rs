//! Region proposals (paper § Ego-Guided Wearer Localization): project the wearer's 3D joints
//! (e.g. EgoNet's coarse pose) into an observer image and take their bounding box, expanded
//! by a margin and clipped to the image.
//!
//! Units: pixels (centre of the top-left pixel at 0, 0); joints are world points (metres).

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

use crate::camera::CameraCalibration;
use crate::rigid::RigidTransform;

/// Default margin: each side grows by this fraction of the box's longer side.
pub const DEFAULT_REGION_MARGIN: f32 = 0.15;

/// An axis-aligned pixel box.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoundingBox {
    pub min: Vec2,
    pub max: Vec2,
}

impl BoundingBox {
    /// The smallest box holding every point (`None` for no points).
    pub fn around(points: impl IntoIterator<Item = Vec2>) -> Option<Self> {
        points.into_iter().fold(None, |acc, p| {
            Some(match acc {
                None => BoundingBox { min: p, max: p },
                Some(b) => BoundingBox { min: b.min.min(p), max: b.max.max(p) },
            })
        })
    }

    /// Width and height, pixels.
    pub fn size(&self) -> Vec2 {
        (self.max - self.min).max(Vec2::ZERO)
    }

    /// The box's diagonal length, pixels (a scale for normalising pixel distances).
    pub fn diagonal(&self) -> f32 {
        self.size().length()
    }

    /// Centre, pixels.
    pub fn center(&self) -> Vec2 {
        0.5 * (self.min + self.max)
    }

    /// Whether `p` lies inside (borders included).
    pub fn contains(&self, p: Vec2) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// Grown on every side by `fraction` of the longer side.
    pub fn expanded(&self, fraction: f32) -> Self {
        let pad = Vec2::splat(self.size().max_element() * fraction);
        Self { min: self.min - pad, max: self.max + pad }
    }

    /// Intersection with another box (`None` when they do not overlap).
    pub fn intersection(&self, other: &Self) -> Option<Self> {
        let b = Self { min: self.min.max(other.min), max: self.max.min(other.max) };
        (b.min.x <= b.max.x && b.min.y <= b.max.y).then_some(b)
    }
}

/// Why a wearer has no region in an observer image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NotVisibleReason {
    /// Every joint is behind the camera.
    BehindCamera,
    /// In front of the camera but no joint lands in the image's valid region.
    OutOfFrame,
}

/// The wearer's region in one observer image at one frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegionProposal {
    Visible {
        /// Box around the projected joints, expanded by the margin, clipped to the image.
        bbox: BoundingBox,
        /// How many of the given joints project inside the image's valid region.
        joints_in_image: usize,
    },
    NotVisible(NotVisibleReason),
}

impl RegionProposal {
    /// The box, if visible.
    pub fn bbox(&self) -> Option<BoundingBox> {
        match self {
            RegionProposal::Visible { bbox, .. } => Some(*bbox),
            RegionProposal::NotVisible(_) => None,
        }
    }
}

/// Projects world-space joints into the image of `camera` on an observer device at
/// `t_world_observer_device`, and boxes them with `margin` (see [`DEFAULT_REGION_MARGIN`]).
pub fn propose_region(
    joints_world: &[Vec3],
    camera: &CameraCalibration,
    t_world_observer_device: &RigidTransform,
    margin: f32,
) -> RegionProposal {
    let t_camera_world = camera.t_world_camera(t_world_observer_device).inverse();
    let in_camera: Vec<Vec3> = joints_world.iter().map(|&p| t_camera_world.transform_point(p)).collect();
    if !in_camera.iter().any(|p| p.is_finite() && p.z > 0.0) {
        return RegionProposal::NotVisible(NotVisibleReason::BehindCamera);
    }
    let projected: Vec<Vec2> = in_camera.iter().filter_map(|&p| camera.project(p)).collect();
    let joints_in_image = projected.iter().filter(|&&px| camera.is_valid_pixel(px)).count();
    let image = BoundingBox { min: Vec2::splat(-0.5), max: camera.image_size() - 0.5 };
    let clipped =
        BoundingBox::around(projected.iter().copied()).map(|b| b.expanded(margin)).and_then(|b| b.intersection(&image));
    match clipped {
        Some(bbox) if joints_in_image > 0 => RegionProposal::Visible { bbox, joints_in_image },
        _ => RegionProposal::NotVisible(NotVisibleReason::OutOfFrame),
    }
}
