//! `egoexo inspect <session>` (being built for the sessions issue).

use std::path::PathBuf;

use anyhow::{Result, bail};

#[derive(clap::Args)]
pub struct Args {
    /// A `.egoexo` file or folder, an Aria MPS folder, or a Nymeria sequence folder.
    pub session: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    bail!("cannot inspect {}: session import is not implemented yet", args.session.display())
}
