//! Camera models: pinhole and Project Aria's Fisheye624 (`FisheyeRadTanThinPrism`).
//!
//! Frames: a camera's optical frame is OpenCV/Aria's (+X right, +Y down, +Z forward).
//! A [`CameraCalibration`] is intrinsics plus `T_device_camera`, which maps points in the
//! camera's optical frame into its device frame; the device pose `T_world_device` comes from
//! the trajectory. Units: metres in 3D, pixels in the image, with the centre of the top-left
//! pixel at (0, 0) — so the image spans `[−0.5, width − 0.5] × [−0.5, height − 0.5]`.
//!
//! Fisheye624 (15 parameters `[f, cu, cv, k0..k5, p0, p1, s0..s3]`), as in projectaria_tools:
//! with `a = x/z`, `b = y/z`, `r = √(a²+b²)`, `θ = atan r`,
//! `θ_d = θ (1 + k0 θ² + k1 θ⁴ + … + k5 θ¹²)`, `x_r = (θ_d / r) (a, b)`; then tangential
//! `u = x_r + 2 (x_r·p) x_r + |x_r|² p` and thin prism `u_x += s0 |x_r|² + s1 |x_r|⁴`,
//! `u_y += s2 |x_r|² + s3 |x_r|⁴`; pixel = `f u + (cu, cv)`. Unprojection inverts the
//! tangential/thin-prism part by 2-D Newton iterations and the radial polynomial by 1-D
//! Newton iterations, in `f64`.

use glam::{DMat2, DVec2, Vec2, Vec3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::rigid::RigidTransform;

/// Errors from building or rescaling a camera.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CameraError {
    /// A parameter is NaN or infinite.
    #[error("camera parameter `{name}` is not finite ({value})")]
    NonFiniteParameter { name: &'static str, value: f32 },
    /// Focal lengths must be positive.
    #[error("camera focal length `{name}` must be positive, got {value}")]
    NonPositiveFocal { name: &'static str, value: f32 },
    /// Image sizes must be positive.
    #[error("camera image size must be positive, got {width}×{height}")]
    EmptyImage { width: u32, height: u32 },
    /// The radial polynomial of a fisheye model must increase near the centre.
    #[error("fisheye radial distortion is not monotonic even near the image centre (k = {k:?})")]
    NonMonotonicDistortion { k: [f32; 6] },
    /// Fisheye624 has one focal length, so it can only be rescaled uniformly.
    #[error("a single-focal fisheye camera cannot be rescaled non-uniformly ({sx} × {sy})")]
    NonUniformScale { sx: f32, sy: f32 },
}

/// Ideal pinhole intrinsics (pixels).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pinhole {
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl Pinhole {
    /// Validated constructor.
    pub fn new(fx: f32, fy: f32, cx: f32, cy: f32) -> Result<Self, CameraError> {
        for (name, value) in [("fx", fx), ("fy", fy), ("cx", cx), ("cy", cy)] {
            if !value.is_finite() {
                return Err(CameraError::NonFiniteParameter { name, value });
            }
        }
        for (name, value) in [("fx", fx), ("fy", fy)] {
            if value <= 0.0 {
                return Err(CameraError::NonPositiveFocal { name, value });
            }
        }
        Ok(Self { fx, fy, cx, cy })
    }
}

/// Parameter names of Fisheye624 in storage order.
pub const FISHEYE624_PARAM_NAMES: [&str; 15] =
    ["f", "cu", "cv", "k0", "k1", "k2", "k3", "k4", "k5", "p0", "p1", "s0", "s1", "s2", "s3"];

/// Largest field angle (from the optical axis) considered at all: the model divides by z.
const FISHEYE_FIELD_ANGLE_CAP: f64 = 1.55;

/// Project Aria's `FisheyeRadTanThinPrism` model with one focal length ("Fisheye624").
///
/// Construction computes the largest field angle over which the radial polynomial is
/// strictly increasing (so projection is invertible); points beyond it do not project.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "Fisheye624Params", into = "Fisheye624Params")]
pub struct Fisheye624 {
    params: [f32; 15],
    max_field_angle: f32,
}

/// Serialized form of [`Fisheye624`]: the 15 parameters in Aria's order.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct Fisheye624Params {
    pub params: [f32; 15],
}

impl TryFrom<Fisheye624Params> for Fisheye624 {
    type Error = CameraError;
    fn try_from(raw: Fisheye624Params) -> Result<Self, CameraError> {
        Fisheye624::new(raw.params)
    }
}

impl From<Fisheye624> for Fisheye624Params {
    fn from(f: Fisheye624) -> Self {
        Fisheye624Params { params: f.params }
    }
}

impl Fisheye624 {
    /// Validated constructor from `[f, cu, cv, k0..k5, p0, p1, s0..s3]`.
    pub fn new(params: [f32; 15]) -> Result<Self, CameraError> {
        for (name, &value) in FISHEYE624_PARAM_NAMES.iter().zip(params.iter()) {
            if !value.is_finite() {
                return Err(CameraError::NonFiniteParameter { name, value });
            }
        }
        if params[0] <= 0.0 {
            return Err(CameraError::NonPositiveFocal { name: "f", value: params[0] });
        }
        let mut this = Self { params, max_field_angle: 0.0 };
        this.max_field_angle = this.monotonic_field_angle()?;
        Ok(this)
    }

    /// The 15 parameters in Aria's order.
    pub fn params(&self) -> [f32; 15] {
        self.params
    }

    /// Focal length, pixels.
    pub fn focal(&self) -> f32 {
        self.params[0]
    }

    /// Principal point `(cu, cv)`, pixels.
    pub fn principal_point(&self) -> Vec2 {
        Vec2::new(self.params[1], self.params[2])
    }

    /// Largest angle from the optical axis (radians) that projects.
    pub fn max_field_angle(&self) -> f32 {
        self.max_field_angle
    }

    fn k(&self) -> [f64; 6] {
        std::array::from_fn(|i| f64::from(self.params[3 + i]))
    }

    fn p(&self) -> DVec2 {
        DVec2::new(f64::from(self.params[9]), f64::from(self.params[10]))
    }

    fn s(&self) -> [f64; 4] {
        std::array::from_fn(|i| f64::from(self.params[11 + i]))
    }

    /// `θ_d(θ) = θ (1 + Σ k_i θ^(2i+2))` and its derivative.
    fn radial(&self, theta: f64) -> (f64, f64) {
        let k = self.k();
        let t2 = theta * theta;
        let mut poly = 1.0;
        let mut dpoly = 1.0;
        let mut t2i = t2;
        for (i, ki) in k.iter().enumerate() {
            poly += ki * t2i;
            dpoly += ki * t2i * (2 * i + 3) as f64;
            t2i *= t2;
        }
        (theta * poly, dpoly)
    }

    fn monotonic_field_angle(&self) -> Result<f32, CameraError> {
        const STEP: f64 = 1e-3;
        let mut theta = 0.0;
        let mut last = 0.0;
        while theta + STEP <= FISHEYE_FIELD_ANGLE_CAP {
            let next = theta + STEP;
            let (rd, d) = self.radial(next);
            if d <= 0.0 || rd <= last {
                break;
            }
            last = rd;
            theta = next;
        }
        if theta < 0.1 {
            return Err(CameraError::NonMonotonicDistortion { k: std::array::from_fn(|i| self.params[3 + i]) });
        }
        Ok(theta as f32)
    }

    /// Tangential + thin-prism distortion of radially distorted coordinates, with its Jacobian.
    fn tangential_thin_prism(&self, x: DVec2) -> (DVec2, DMat2) {
        let p = self.p();
        let s = self.s();
        let r2 = x.length_squared();
        let xp = x.dot(p);
        let u = x + 2.0 * xp * x + r2 * p + DVec2::new(s[0] * r2 + s[1] * r2 * r2, s[2] * r2 + s[3] * r2 * r2);
        // d/dx of each term (columns are d/dx0, d/dx1).
        let outer = |a: DVec2, b: DVec2| DMat2::from_cols(a * b.x, a * b.y); // a bᵀ
        let prism_rows = DVec2::new(2.0 * (s[0] + 2.0 * s[1] * r2), 2.0 * (s[2] + 2.0 * s[3] * r2));
        let jac = DMat2::IDENTITY * (1.0 + 2.0 * xp) + outer(2.0 * x, p) + outer(2.0 * p, x) + outer(prism_rows, x);
        (u, jac)
    }

    /// Projects a point in the camera frame; `None` behind the camera or beyond the valid
    /// field angle.
    pub fn project(&self, p_camera: Vec3) -> Option<Vec2> {
        let p = p_camera.as_dvec3();
        if !p.is_finite() || p.z <= 0.0 {
            return None;
        }
        let r_xy = p.truncate().length();
        let theta = r_xy.atan2(p.z);
        if theta > f64::from(self.max_field_angle) {
            return None;
        }
        let ab = p.truncate() / p.z;
        let r = r_xy / p.z;
        let (theta_d, _) = self.radial(theta);
        let scale = if r < f64::EPSILON { 1.0 } else { theta_d / r };
        let (u, _) = self.tangential_thin_prism(ab * scale);
        let f = f64::from(self.params[0]);
        let c = self.principal_point().as_dvec2();
        Some((u * f + c).as_vec2())
    }

    /// Unit ray in the camera frame through `pixel`; `None` if the iterations do not converge
    /// or the ray lies beyond the valid field angle.
    pub fn unproject(&self, pixel: Vec2) -> Option<Vec3> {
        if !pixel.is_finite() {
            return None;
        }
        let f = f64::from(self.params[0]);
        let target = (pixel.as_dvec2() - self.principal_point().as_dvec2()) / f;
        // 1) Invert tangential + thin prism: find x_r with D(x_r) = target.
        let mut x = target;
        let mut converged = false;
        for _ in 0..30 {
            let (u, jac) = self.tangential_thin_prism(x);
            let residual = u - target;
            if residual.length() < 1e-12 {
                converged = true;
                break;
            }
            if jac.determinant().abs() < 1e-12 {
                return None;
            }
            x -= jac.inverse() * residual;
            if !x.is_finite() {
                return None;
            }
        }
        if !converged && (self.tangential_thin_prism(x).0 - target).length() > 1e-9 {
            return None;
        }
        // 2) Invert the radial polynomial: θ with θ_d(θ) = |x_r|.
        let rd = x.length();
        let max_theta = f64::from(self.max_field_angle);
        let (rd_max, _) = self.radial(max_theta);
        if rd > rd_max * (1.0 + 1e-6) {
            return None;
        }
        let mut theta = rd.min(max_theta);
        for _ in 0..50 {
            let (value, slope) = self.radial(theta);
            let step = (value - rd) / slope;
            theta = (theta - step).clamp(0.0, max_theta);
            if step.abs() < 1e-14 {
                break;
            }
        }
        if (self.radial(theta).0 - rd).abs() > 1e-9 {
            return None;
        }
        // 3) Back to a direction.
        let ray = if rd < 1e-12 {
            glam::DVec3::new(x.x, x.y, 1.0)
        } else {
            let r = theta.tan();
            let ab = x * (r / rd);
            glam::DVec3::new(ab.x, ab.y, 1.0)
        };
        Some(ray.normalize().as_vec3())
    }
}

/// Intrinsic projection model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum Projection {
    Pinhole(Pinhole),
    Fisheye624(Fisheye624),
}

impl Projection {
    /// Pixel of a camera-frame point; `None` behind the camera (z ≤ 0) or beyond the model's
    /// field of view. The pixel may lie outside the image.
    pub fn project(&self, p_camera: Vec3) -> Option<Vec2> {
        match self {
            Projection::Pinhole(k) => {
                if !p_camera.is_finite() || p_camera.z <= 0.0 {
                    return None;
                }
                Some(Vec2::new(k.fx * p_camera.x / p_camera.z + k.cx, k.fy * p_camera.y / p_camera.z + k.cy))
            }
            Projection::Fisheye624(f) => f.project(p_camera),
        }
    }

    /// Unit ray (camera frame) through a pixel.
    pub fn unproject(&self, pixel: Vec2) -> Option<Vec3> {
        match self {
            Projection::Pinhole(k) => {
                if !pixel.is_finite() {
                    return None;
                }
                Some(Vec3::new((pixel.x - k.cx) / k.fx, (pixel.y - k.cy) / k.fy, 1.0).normalize())
            }
            Projection::Fisheye624(f) => f.unproject(pixel),
        }
    }

    /// Principal point, pixels.
    pub fn principal_point(&self) -> Vec2 {
        match self {
            Projection::Pinhole(k) => Vec2::new(k.cx, k.cy),
            Projection::Fisheye624(f) => f.principal_point(),
        }
    }

    /// The same camera for an image resized by `(sx, sy)`, keeping pixel centres consistent:
    /// `c' = (c + 0.5) s − 0.5`, `f' = f s`.
    pub fn scaled(&self, sx: f32, sy: f32) -> Result<Self, CameraError> {
        let shift = |c: f32, s: f32| (c + 0.5) * s - 0.5;
        match self {
            Projection::Pinhole(k) => {
                Ok(Projection::Pinhole(Pinhole::new(k.fx * sx, k.fy * sy, shift(k.cx, sx), shift(k.cy, sy))?))
            }
            Projection::Fisheye624(f) => {
                if (sx - sy).abs() > 1e-4 * sx.abs().max(sy.abs()) {
                    return Err(CameraError::NonUniformScale { sx, sy });
                }
                let mut params = f.params;
                params[0] *= sx;
                params[1] = shift(params[1], sx);
                params[2] = shift(params[2], sy);
                Ok(Projection::Fisheye624(Fisheye624::new(params)?))
            }
        }
    }
}

/// A calibrated camera on a device: intrinsics, image size and `T_device_camera`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraCalibration {
    pub projection: Projection,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Maps camera-frame points into the device frame.
    pub t_device_camera: RigidTransform,
    /// Radius around the principal point (pixels) inside which the calibration is valid
    /// (Aria's image circle). `None`: the whole image is valid.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub valid_radius_px: Option<f32>,
}

impl CameraCalibration {
    /// Validated constructor.
    pub fn new(
        projection: Projection,
        width: u32,
        height: u32,
        t_device_camera: RigidTransform,
    ) -> Result<Self, CameraError> {
        if width == 0 || height == 0 {
            return Err(CameraError::EmptyImage { width, height });
        }
        Ok(Self { projection, width, height, t_device_camera, valid_radius_px: None })
    }

    /// With an explicit valid radius (pixels).
    pub fn with_valid_radius(mut self, radius_px: f32) -> Self {
        self.valid_radius_px = Some(radius_px);
        self
    }

    /// Image size as a vector (pixels).
    pub fn image_size(&self) -> Vec2 {
        Vec2::new(self.width as f32, self.height as f32)
    }

    /// Whether a pixel lies on the image and inside the valid radius.
    pub fn is_valid_pixel(&self, pixel: Vec2) -> bool {
        self.is_near_valid_pixel(pixel, 0.0)
    }

    /// Whether `pixel` lies within `margin_px` pixels of the valid region (the image, and the
    /// valid radius when there is one): where a projection is still meaningful as a guess of
    /// where something just out of view is.
    pub fn is_near_valid_pixel(&self, pixel: Vec2, margin_px: f32) -> bool {
        let lo = -0.5 - margin_px;
        let inside = pixel.x >= lo
            && pixel.y >= lo
            && pixel.x <= self.width as f32 - 0.5 + margin_px
            && pixel.y <= self.height as f32 - 0.5 + margin_px;
        let in_circle =
            self.valid_radius_px.is_none_or(|r| pixel.distance(self.projection.principal_point()) <= r + margin_px);
        inside && in_circle
    }

    /// Projects a camera-frame point (see [`Projection::project`]); the pixel may be off-image.
    pub fn project(&self, p_camera: Vec3) -> Option<Vec2> {
        self.projection.project(p_camera)
    }

    /// Unit ray in the camera frame through a pixel; `None` outside the valid radius.
    pub fn unproject(&self, pixel: Vec2) -> Option<Vec3> {
        if let Some(r) = self.valid_radius_px
            && pixel.distance(self.projection.principal_point()) > r
        {
            return None;
        }
        self.projection.unproject(pixel)
    }

    /// `T_world_camera` for a device pose `T_world_device`.
    pub fn t_world_camera(&self, t_world_device: &RigidTransform) -> RigidTransform {
        *t_world_device * self.t_device_camera
    }

    /// Projects a world point seen from a device at `T_world_device`.
    pub fn project_world(&self, p_world: Vec3, t_world_device: &RigidTransform) -> Option<Vec2> {
        let t_camera_world = self.t_world_camera(t_world_device).inverse();
        self.project(t_camera_world.transform_point(p_world))
    }

    /// The same camera for the image resized to `width × height` pixels (aspect must be
    /// kept for Fisheye624). A valid radius scales with it.
    pub fn scaled_to(&self, width: u32, height: u32) -> Result<Self, CameraError> {
        if width == 0 || height == 0 {
            return Err(CameraError::EmptyImage { width, height });
        }
        let sx = width as f32 / self.width as f32;
        let sy = height as f32 / self.height as f32;
        Ok(Self {
            projection: self.projection.scaled(sx, sy)?,
            width,
            height,
            t_device_camera: self.t_device_camera,
            valid_radius_px: self.valid_radius_px.map(|r| r * sx),
        })
    }
}

pub mod aria_rgb {
    //! Project Aria's RGB camera as a preset: a real factory calibration at 1408×1408 and the
    //! camera's mounting on a CPF head device (+X left, +Y up, +Z forward).

    use glam::{Quat, Vec3};

    use super::{CameraCalibration, CameraError, Fisheye624, Projection};
    use crate::rigid::RigidTransform;

    /// Fisheye624 parameters `[f, cu, cv, k0..k5, p0, p1, s0..s3]` at 1408×1408 (pixels).
    pub const PARAMS_1408: [f32; 15] = [
        610.941,
        715.115,
        716.715,
        0.406036,
        -0.489948,
        0.174565,
        1.13298,
        -1.70164,
        0.651156,
        0.000621147,
        1.9322e-05,
        -1.48553e-05,
        0.000260123,
        -0.000658211,
        3.7614e-05,
    ];

    /// Radius of the image circle at 1408 px (pixels from the principal point).
    pub const VALID_RADIUS_1408: f32 = 700.0;

    /// `T_device_camera` on a CPF device: the RGB camera on the left temple, an OpenCV camera
    /// (+X right, +Y down, the CPF frame turned 180° about Z) facing forward, tilted 11° down
    /// (metres).
    pub fn t_device_camera() -> RigidTransform {
        RigidTransform::new(
            Quat::from_rotation_z(std::f32::consts::PI) * Quat::from_rotation_x(-0.2),
            Vec3::new(0.05, 0.012, 0.006),
        )
    }

    /// The RGB camera at `size × size` pixels (1408 or 2880 on the device), with its valid
    /// radius.
    pub fn camera(size: u32) -> Result<CameraCalibration, CameraError> {
        let base = CameraCalibration::new(
            Projection::Fisheye624(Fisheye624::new(PARAMS_1408)?),
            1408,
            1408,
            t_device_camera(),
        )?
        .with_valid_radius(VALID_RADIUS_1408);
        if size == 1408 { Ok(base) } else { base.scaled_to(size, size) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn pinhole_principal_ray() {
        let p = Projection::Pinhole(Pinhole::new(500.0, 500.0, 320.0, 240.0).unwrap());
        assert_eq!(p.project(Vec3::new(0.0, 0.0, 2.0)), Some(Vec2::new(320.0, 240.0)));
        assert_eq!(p.project(Vec3::new(0.0, 0.0, -2.0)), None);
        assert!(p.unproject(Vec2::new(320.0, 240.0)).unwrap().abs_diff_eq(Vec3::Z, 1e-7));
    }

    #[test]
    fn fisheye_rejects_bad_parameters() {
        let mut params = [0.0; 15];
        params[0] = f32::NAN;
        assert!(matches!(Fisheye624::new(params), Err(CameraError::NonFiniteParameter { name: "f", .. })));
        params[0] = -1.0;
        assert!(matches!(Fisheye624::new(params), Err(CameraError::NonPositiveFocal { .. })));
        params[0] = 500.0;
        params[3] = -50.0;
        assert!(matches!(Fisheye624::new(params), Err(CameraError::NonMonotonicDistortion { .. })));
    }

    #[test]
    fn fisheye_serde_round_trip_keeps_parameters() {
        let mut params = [0.0; 15];
        params[..3].copy_from_slice(&[600.0, 700.0, 700.0]);
        let cam = Projection::Fisheye624(Fisheye624::new(params).unwrap());
        let json = serde_json::to_string(&cam).unwrap();
        let back: Projection = serde_json::from_str(&json).unwrap();
        assert_eq!(cam, back);
    }
}
