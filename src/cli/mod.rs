//! The command-line interface: argument definitions and dispatch. Each subcommand lives in
//! its own module; `main.rs` only parses, installs tracing and calls [`main`].

use std::path::PathBuf;

use clap::{Parser, Subcommand, ValueEnum};

pub mod check;
pub mod export;
pub mod gap;
pub mod gap_bench;
pub mod output;
pub mod probe;
pub mod replay;
pub mod run;
pub mod simulate;
pub mod status;
pub mod validate;
pub mod view;

/// Hardware-in-the-loop bridge for the EyeBot MK4 controller of the Mako AUV.
#[derive(Debug, Parser)]
#[command(name = "eyebot-hil", version, about, long_about = None)]
pub struct Cli {
    /// Log format on stderr. The level comes from EYEBOT_HIL_LOG (tracing env-filter
    /// syntax, default `info`).
    #[arg(long, value_enum, global = true, default_value_t = LogFormat::Text)]
    pub log_format: LogFormat,
    #[command(subcommand)]
    pub command: Command,
}

/// How log events are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LogFormat {
    Text,
    Json,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the bridge daemon on the embedded default configuration (or --config FILE).
    Run(run::RunArgs),
    /// Ask a running daemon for its status.
    Status(status::StatusArgs),
    /// Talk to a running bridge as an EyeBot would (ADC, compass, sonar, thrusters, time).
    Probe(probe::ProbeArgs),
    /// Run one experiment offline as fast as possible and write the state trace as CSV.
    Simulate(simulate::SimulateArgs),
    /// Run the thesis experiments and compare with Mako's measurements and SubSim's.
    Validate(validate::ValidateArgs),
    /// Replay captured NMEA logs onto a pty, a serial device or stdout.
    Replay(replay::ReplayArgs),
    /// Reality gap: compare measured data with a model, name and fit the missing effect.
    Gap(gap::GapArgs),
    /// Benchmark the reality-gap workflow on generated hidden-effect and null cases.
    GapBench(gap_bench::GapBenchArgs),
    /// Run a control program against a private lockstep daemon and judge it by a scenario.
    Check(check::CheckArgs),
    /// Show a recording in the browser: the live view's page with a time slider.
    View(view::ViewArgs),
    /// Write a recording in another format (MCAP for Foxglove).
    Export(export::ExportArgs),
}

/// Errors that end a CLI command.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error(transparent)]
    Daemon(#[from] crate::daemon::DaemonError),
    #[error(transparent)]
    Status(#[from] crate::daemon::status::StatusError),
    #[error(transparent)]
    Probe(#[from] crate::probe::ProbeError),
    #[error("experiment `{experiment}`: {source}")]
    Physics {
        experiment: String,
        source: crate::physics::PhysicsError,
    },
    #[error(transparent)]
    Validate(#[from] crate::thesis::ValidateError),
    #[error(transparent)]
    Replay(#[from] replay::ReplayCliError),
    #[error("check failed: {failed} of {total} criteria")]
    CheckFailed { failed: usize, total: usize },
    #[error("{failed} of {total} validation rows failed")]
    ValidationFailed { failed: usize, total: usize },
    /// A file or program the command needed failed; `doing` is what was tried (`read`,
    /// `write`, `create`, `remove`, `run`, `wait for`, `resolve`).
    #[error("cannot {doing} `{}`: {source}", path.display())]
    Io {
        doing: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("the bridge answered {request} with {reply}")]
    UnexpectedReply {
        request: &'static str,
        reply: String,
    },
    #[error(transparent)]
    Gap(#[from] crate::gap::GapError),
    #[error("{0}")]
    Usage(String),
    #[error("cannot format output: {0}")]
    Output(String),
    #[error(transparent)]
    View(#[from] crate::view::ViewError),
    #[error("cannot start the async runtime: {0}")]
    Runtime(#[source] std::io::Error),
}

/// A single-threaded tokio runtime: the daemon's work is I/O bound and its core is one
/// state machine; the recorder has its own thread.
pub fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(CliError::Runtime)
}

pub fn main(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::Run(args) => run::main(args),
        Command::Status(args) => status::main(args),
        Command::Probe(args) => probe::main(args),
        Command::Simulate(args) => simulate::run(&args),
        Command::Validate(args) => validate::run(&args),
        Command::Replay(args) => Ok(replay::main(args)?),
        Command::Gap(args) => gap::run(&args),
        Command::GapBench(args) => gap_bench::run(&args),
        Command::Check(args) => check::main(args),
        Command::View(args) => view::main(args),
        Command::Export(args) => export::main(args),
    }
}
