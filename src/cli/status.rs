//! `eyebot-hil status`: asks a running daemon for its snapshot.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args;

use super::CliError;
use crate::cli::output::{out, outln};
use crate::daemon::status;

/// Print a running daemon's uptime, simulated time, links and vehicle pose.
#[derive(Debug, Args)]
pub struct StatusArgs {
    /// The daemon's run directory (holds `status.sock`).
    #[arg(long, default_value = "run")]
    pub run_dir: PathBuf,
    /// The status socket, if not `RUN_DIR/status.sock`.
    #[arg(long)]
    pub socket: Option<PathBuf>,
    /// Print the snapshot as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn main(args: StatusArgs) -> Result<(), CliError> {
    let socket = args
        .socket
        .unwrap_or_else(|| args.run_dir.join("status.sock"));
    let runtime = super::runtime()?;
    let snapshot = runtime.block_on(status::query(&socket, Duration::from_secs(2)))?;
    if args.json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&snapshot).map_err(|e| CliError::Output(e.to_string()))?
        );
    } else {
        out!("{}", snapshot.render());
    }
    Ok(())
}
