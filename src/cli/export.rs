//! `eyebot-hil export RECORD_DIR --mcap FILE`: a recording for Foxglove.

use std::path::PathBuf;

use clap::Args;

use super::CliError;
use crate::cli::output::errln;

/// Write a recording (`run --record DIR`) as an MCAP file that Foxglove opens: the same
/// channels `run --foxglove` publishes (scene, pose, sonar, sensors, thrusters, link
/// messages), at simulated time.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The recording's directory.
    pub record_dir: PathBuf,
    /// The MCAP file to write (replaced if it exists).
    #[arg(long, value_name = "FILE")]
    pub mcap: PathBuf,
}

pub fn main(args: ExportArgs) -> Result<(), CliError> {
    let done = crate::view::foxglove::export_mcap(&args.record_dir, &args.mcap)?;
    errln!(
        "eyebot-hil: wrote {}: {} state rows, {} link messages, {} scenes",
        args.mcap.display(),
        done.states,
        done.messages,
        done.scenes
    );
    Ok(())
}
