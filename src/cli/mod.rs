//! The command-line interface: argument definitions and dispatch. Each subcommand lives in
//! its own module; `main.rs` only parses, installs tracing and calls [`main`].

use std::path::PathBuf;

use clap::{Parser, Subcommand};

pub mod simulate;
pub mod validate;

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
    /// Run one experiment offline as fast as possible and write the state trace as CSV.
    Simulate(simulate::SimulateArgs),
    /// Run the thesis experiments and compare with Mako's measurements and SubSim's.
    Validate(validate::ValidateArgs),
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
    Config(#[from] crate::config::ConfigError),
    #[error("experiment `{experiment}`: {source}")]
    Physics {
        experiment: String,
        source: crate::physics::PhysicsError,
    },
    #[error(transparent)]
    Validate(#[from] crate::validate::ValidateError),
    #[error("{failed} of {total} validation rows failed")]
    ValidationFailed { failed: usize, total: usize },
    #[error("cannot write `{}`: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot format output: {0}")]
    Output(String),
}

pub fn main(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::Run => Err(CliError::NotYet {
            command: "run",
            what: "the daemon (issue 5) is not built yet; the wire protocols live in firmware-protocol",
        }),
        Command::Simulate(args) => simulate::run(&args),
        Command::Validate(args) => validate::run(&args),
    }
}
