//! Where an observer's poses and clock stand against the session's (the wearer's) world and
//! clock, and what registration found (`docs/registration.md`).
//!
//! A session's observers are fused with the wearer only when their poses are in the wearer's
//! world. Devices mapped together (Aria Multi-SLAM, a simulated scene, a shared XR anchor) are;
//! two Aria glasses through MPS one by one, a Quest and a phone in their own XR spaces, or a
//! static camera with no pose are not: their [`Placement`] says `world: own`, and
//! `egoexo-register` either registers them (and records it here) or leaves them out.

pub use egoexo_solve::registration::{Dof, Registration, RegistrationStatus};
use serde::{Deserialize, Serialize};

/// Which world an observer's poses are in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WorldRef {
    /// The session's (the wearer's) world: fused as given (the default; every file before
    /// registration existed).
    #[default]
    Shared,
    /// Its own world: unknown against the wearer's until registered.
    Own,
}

/// Which clock an observer's timestamps are on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClockRef {
    /// The session's clock (the default).
    #[default]
    Shared,
    /// Its own clock, up to a couple of seconds off the wearer's: registration finds the offset.
    Own,
}

/// How the camera is carried.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mount {
    /// On a moving device (glasses, a headset, a phone) with a pose trajectory (the default).
    #[default]
    Worn,
    /// A static camera (a webcam, a GoPro on a tripod): one pose for the whole recording. In
    /// memory its trajectory holds that pose at the start and the end of the recording.
    Fixed,
}

/// An observer's world, clock and camera against the session's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    #[serde(default, skip_serializing_if = "is_default")]
    pub world: WorldRef,
    /// Its world is gravity-aligned (Y up): a registration has 4 degrees of freedom (yaw and
    /// translation), else 6.
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub gravity: bool,
    #[serde(default, skip_serializing_if = "is_default")]
    pub clock: ClockRef,
    #[serde(default, skip_serializing_if = "is_default")]
    pub mount: Mount,
    /// The camera's focal length is calibrated; `false`: the calibration's focal is a guess
    /// registration estimates (a pinhole camera only).
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub focal_known: bool,
    /// What registration found, and whether it was applied.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub registration: Option<RegistrationRecord>,
}

/// A registration kept with the observer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegistrationRecord {
    /// The solver's result: `T_session_observerworld`, its 1σ, frames used, the verdict.
    #[serde(flatten)]
    pub result: Registration,
    /// The transform (and clock offset, focal length) was applied: the observer's stored
    /// poses and times are now in the session's world and clock. `false`: recorded only (a
    /// world checked and kept, or one that could not be registered).
    pub applied: bool,
}

fn yes() -> bool {
    true
}

fn is_true(b: &bool) -> bool {
    *b
}

fn is_default<T: Default + PartialEq>(v: &T) -> bool {
    *v == T::default()
}

impl Default for Placement {
    /// A worn device in the session's world and clock, gravity-aligned, calibrated.
    fn default() -> Self {
        Self {
            world: WorldRef::Shared,
            gravity: true,
            clock: ClockRef::Shared,
            mount: Mount::Worn,
            focal_known: true,
            registration: None,
        }
    }
}

impl Placement {
    /// The default placement (not written to files).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// A static camera that knows nothing of its pose: its own world (its optical frame), no
    /// gravity, its focal length known or not.
    pub fn fixed_unposed(focal_known: bool) -> Self {
        Self { world: WorldRef::Own, gravity: false, mount: Mount::Fixed, focal_known, ..Self::default() }
    }

    /// Whether the observer's rays may be fused with the wearer: its poses are in the
    /// session's world and clock (as given, or registered and applied), and no registration
    /// said otherwise.
    pub fn fusable(&self) -> bool {
        self.world == WorldRef::Shared
            && self.clock == ClockRef::Shared
            && self.registration.as_ref().is_none_or(|r| r.result.status.fusable())
    }

    /// The registration's verdict, if one was made.
    pub fn status(&self) -> Option<RegistrationStatus> {
        self.registration.as_ref().map(|r| r.result.status)
    }

    /// In words, for `inspect` and warnings.
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        parts.push(match self.world {
            WorldRef::Shared => "session world".to_owned(),
            WorldRef::Own => "own world".to_owned(),
        });
        if !self.gravity {
            parts.push("no gravity".into());
        }
        if self.clock == ClockRef::Own {
            parts.push("own clock".into());
        }
        if self.mount == Mount::Fixed {
            parts.push("static camera".into());
        }
        if !self.focal_known {
            parts.push("focal to estimate".into());
        }
        if let Some(r) = &self.registration {
            parts.push(describe_registration(&r.result, r.applied));
        }
        parts.join("; ")
    }
}

/// A registration in words: the verdict, the transform and its 1σ.
pub fn describe_registration(r: &Registration, applied: bool) -> String {
    let t = r.translation_m();
    let sigma =
        |s: Option<f64>, unit: &str, scale: f64| s.map_or(String::new(), |s| format!(" ± {:.1}{unit}", s * scale));
    let mut text = format!("{}", r.status);
    if r.status == RegistrationStatus::Registered {
        text += &format!(
            " (yaw {:.1}°{}, translation ({:.2}, {:.2}, {:.2}) m{}",
            r.yaw_deg,
            sigma(r.sigma_yaw_deg, "°", 1.0),
            t[0],
            t[1],
            t[2],
            sigma(r.sigma_translation_m, " cm", 100.0),
        );
        if r.clock_offset_s != 0.0 {
            text += &format!(", clock {:+.3} s", r.clock_offset_s);
        }
        if let Some(f) = r.focal_px {
            text += &format!(", focal {f:.0} px");
        }
        text += ")";
    }
    text += &format!(", {} of {} frames fit over {:.1} s", r.inlier_frames, r.frames, r.view_s);
    if !applied && r.status == RegistrationStatus::Registered {
        text += ", not applied";
    }
    text
}
