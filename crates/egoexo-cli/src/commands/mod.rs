//! One module per subcommand.

pub mod capture;
pub mod convert;
pub mod detection;
pub mod detector_eval;
pub mod eval;
pub mod eval_group;
pub mod inspect;
pub mod keypoints;
pub mod live;
pub mod mocap;
pub mod models;
pub mod reconstruct;
pub mod register;
pub mod serve;
pub mod session_input;
pub mod share;
pub mod simulation;
pub mod synth;
pub mod tracking;
pub mod walk;
