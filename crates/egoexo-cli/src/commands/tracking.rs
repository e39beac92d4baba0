//! `--tracking 1|3`, shared by the commands that simulate or reconstruct.

use egoexo_core::TrackingMode;

/// Wearer tracking: `1` (glasses only) or `3` (glasses + both wrists).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TrackingArg {
    #[value(name = "1")]
    One,
    #[value(name = "3")]
    Three,
}

impl From<TrackingArg> for TrackingMode {
    fn from(t: TrackingArg) -> Self {
        match t {
            TrackingArg::One => TrackingMode::OnePoint,
            TrackingArg::Three => TrackingMode::ThreePoint,
        }
    }
}
