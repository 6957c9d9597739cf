//! `eyebot-hil run`: the bridge daemon.

use std::io::Write as _;
use std::path::PathBuf;

use clap::{Args, ValueEnum};
use tokio::sync::watch;

use super::CliError;
use crate::cli::output::errln;
use crate::config::{ConfigSource, DEFAULT_CONFIG, Directory, Document, Embedded};
use crate::daemon::clock::TimeMode;
use crate::daemon::config::DaemonConfig;
use crate::daemon::{self, Readiness, RunOptions};

/// Time mode on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TimeModeArg {
    /// Follow the wall clock (times --speed): for a real EyeBot.
    Realtime,
    /// Advance only on the client's time frames: deterministic, as fast as the client.
    Lockstep,
}

/// Run the bridge: simulate Mako and serve its devices on the sonar and sensor links.
///
/// Prints one line per link (`link NAME: PATH`) and then `ready`. SIGINT or SIGTERM shut it
/// down cleanly (links closed, recordings flushed, symlinks removed).
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Daemon configuration (default: the embedded copy of configs/default.toml). Model files
    /// it names are read from the same directory.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Record every byte on every link and the ground-truth state into DIR.
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
    /// Master seed for every random stream (overrides run.seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Time mode (overrides run.time_mode).
    #[arg(long, value_enum)]
    pub time_mode: Option<TimeModeArg>,
    /// Realtime speed factor, >= 0.1 (overrides run.speed).
    #[arg(long, value_name = "X")]
    pub speed: Option<f64>,
    /// Directory for the link symlinks, the status socket (overrides run.run_dir).
    #[arg(long, value_name = "DIR")]
    pub run_dir: Option<PathBuf>,
    /// Write the daemon's PID to FILE (removed at exit).
    #[arg(long, value_name = "FILE")]
    pub pid_file: Option<PathBuf>,
}

/// Loads the daemon configuration: `--config FILE`, or the embedded default.
pub fn load_config(
    path: Option<&PathBuf>,
) -> Result<(DaemonConfig, Box<dyn ConfigSource>, String), CliError> {
    let (source, name): (Box<dyn ConfigSource>, String) = match path {
        Some(path) => {
            let (dir, name) = Directory::for_file(path);
            (Box::new(dir), name)
        }
        None => (Box::new(Embedded), DEFAULT_CONFIG.to_string()),
    };
    let text = source.read(&name)?;
    let config = DaemonConfig::resolve(&Document::new(source.describe(&name), &text))?;
    Ok((config, source, text.into_owned()))
}

pub fn main(args: RunArgs) -> Result<(), CliError> {
    let (mut config, source, text) = load_config(args.config.as_ref())?;
    if let Some(seed) = args.seed {
        config.seed = seed;
    }
    let speed = match config.time_mode {
        TimeMode::Realtime { speed } => speed,
        TimeMode::Lockstep => 1.0,
    };
    let speed = match args.speed {
        Some(s) if !(0.1..=1000.0).contains(&s) || !s.is_finite() => {
            return Err(CliError::Usage(format!(
                "--speed {s}: must be between 0.1 and 1000"
            )));
        }
        Some(s) => s,
        None => speed,
    };
    config.time_mode = match args.time_mode {
        Some(TimeModeArg::Lockstep) => TimeMode::Lockstep,
        Some(TimeModeArg::Realtime) => TimeMode::Realtime { speed },
        None => match config.time_mode {
            TimeMode::Realtime { .. } => TimeMode::Realtime { speed },
            TimeMode::Lockstep => TimeMode::Lockstep,
        },
    };
    if let Some(dir) = args.run_dir {
        config.run_dir = dir;
    }
    // A sonar replay log named in a config file is relative to that file.
    if let (Some(log), Some(file)) = (config.sonar_replay.as_mut(), args.config.as_ref())
        && log.is_relative()
        && let Some(dir) = file.parent()
    {
        *log = dir.join(&*log);
    }
    let model = crate::daemon::plant::MakoPlant::from_config(source.as_ref(), &config)?;
    let (board, mux) = crate::daemon::plant::devices(&config);
    let leftovers = daemon::shutdown::Leftovers::default();
    let options = RunOptions {
        record: args.record,
        pid_file: args.pid_file,
        config_toml: text,
        config_name: args.config.as_ref().map_or_else(
            || format!("<embedded>/{DEFAULT_CONFIG}"),
            |p| p.display().to_string(),
        ),
        leftovers: leftovers.clone(),
    };

    let runtime = super::runtime()?;
    // Signals are watched on a thread of their own, which also enforces the shutdown limit
    // (`daemon::shutdown`): it works even if this runtime is blocked.
    let (stop_tx, stop_rx) = watch::channel(false);
    if let Err(e) = daemon::shutdown::spawn_signal_guard(stop_tx, leftovers) {
        tracing::error!(error = %e, "cannot install signal handlers; stop with kill -9");
    }
    let summary = runtime.block_on(async move {
        daemon::run(&config, model, board, mux, options, stop_rx, |event| {
            let mut out = std::io::stdout().lock();
            match event {
                Readiness::Link { name, path } => {
                    let _ = writeln!(out, "link {name}: {path}");
                }
                Readiness::Ready { status_socket } => {
                    let _ = writeln!(out, "ready (status: {})", status_socket.display());
                    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
                }
            }
            let _ = out.flush();
        })
        .await
    })?;
    errln!(
        "eyebot-hil: stopped at simulated time {:.3} s ({} overruns){}",
        summary.sim_time_s,
        summary.overruns,
        summary
            .records
            .map(|r| format!(
                "; recorded {} chunks, {} bytes, {} state rows",
                r.chunks, r.bytes, r.states
            ))
            .unwrap_or_default()
    );
    Ok(())
}
