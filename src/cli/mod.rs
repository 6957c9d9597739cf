//! The command-line interface: argument definitions and dispatch. Each subcommand lives in
//! its own module; `main.rs` only parses, installs tracing and calls [`main`].

pub mod replay;

use clap::{Parser, Subcommand};

/// Hardware-in-the-loop bridge for the EyeBot MK4 controller of the Mako AUV.
#[derive(Debug, Parser)]
#[command(name = "eyebot-hil", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the bridge daemon on the embedded default configuration (or --config FILE).
    Run,
    /// Replay captured NMEA logs onto a pty, a serial device or stdout.
    Replay(replay::ReplayArgs),
}

/// Errors that end a CLI command.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    #[error("`{command}` is not implemented yet: {what}")]
    NotYet {
        command: &'static str,
        what: &'static str,
    },
    #[error(transparent)]
    Replay(#[from] replay::ReplayCliError),
}

pub fn main(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::Run => Err(CliError::NotYet {
            command: "run",
            what: "the daemon (issue 5) is not built yet; the wire protocols live in firmware-protocol",
        }),
        Command::Replay(args) => Ok(replay::main(args)?),
    }
}
