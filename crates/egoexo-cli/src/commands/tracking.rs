//! `--tracking 1|3|3-hand-tracking|3-mixed`, shared by the commands that simulate or
//! reconstruct.

use egoexo_core::TrackingMode;
use egoexo_dataset::shards::WristKind;

/// Wearer tracking: `1` (glasses only), `3` (glasses + wrist devices), `3-hand-tracking`
/// (glasses whose own hand tracking gives the wrists while they are in view; alias
/// `3-intermittent`), `3-mixed` (simulations alternate between the two kinds of wrists).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TrackingArg {
    #[value(name = "1")]
    One,
    #[value(name = "3")]
    Three,
    #[value(name = "3-hand-tracking", alias = "3-intermittent")]
    ThreeHandTracking,
    #[value(name = "3-mixed")]
    ThreeMixed,
}

impl TrackingArg {
    /// How simulated wrists are tracked (devices unless asked otherwise).
    pub fn wrists(self) -> WristKind {
        match self {
            TrackingArg::One | TrackingArg::Three => WristKind::Devices,
            TrackingArg::ThreeHandTracking => WristKind::HandTracking,
            TrackingArg::ThreeMixed => WristKind::Mixed,
        }
    }
}

impl From<TrackingArg> for TrackingMode {
    fn from(t: TrackingArg) -> Self {
        match t {
            TrackingArg::One => TrackingMode::OnePoint,
            TrackingArg::Three | TrackingArg::ThreeHandTracking | TrackingArg::ThreeMixed => TrackingMode::ThreePoint,
        }
    }
}
