//! One module per subcommand.

pub mod convert;
pub mod inspect;
pub mod mocap;
pub mod session_input;
