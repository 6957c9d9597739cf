//! `eyebot-hil run`: the bridge daemon.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use clap::Args;
use tokio::sync::watch;

use super::CliError;
use crate::cli::output::errln;
use crate::config::{BesideOrEmbedded, ConfigSource, DEFAULT_CONFIG, Document, Embedded};
use crate::daemon::config::{DaemonConfig, Overrides, TimeModeName};
use crate::daemon::course::StartChoice;
use crate::daemon::{self, Readiness, RunOptions};

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
    pub time_mode: Option<TimeModeName>,
    /// Realtime speed factor, >= 0.1 (overrides run.speed).
    #[arg(long, value_name = "X")]
    pub speed: Option<f64>,
    /// Directory for the link symlinks, the status socket (overrides run.run_dir).
    #[arg(long, value_name = "DIR")]
    pub run_dir: Option<PathBuf>,
    /// Write the daemon's PID to FILE (removed at exit).
    #[arg(long, value_name = "FILE")]
    pub pid_file: Option<PathBuf>,
    /// Where the vehicle starts (overrides [start]): a course start named in the world file
    /// (`wall_following`, ...) or NORTH,EAST,HEADING in m, m, deg (depth from [start]).
    #[arg(long, value_name = "NAME|N,E,HEADING")]
    pub start: Option<StartChoice>,
    /// Serve a live page of the run (default 127.0.0.1, a port the system picks); prints
    /// `view: URL` (the URL carries the access token) before `ready`.
    #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1, default_missing_value = crate::view::DEFAULT_ADDR)]
    pub view: Option<std::net::SocketAddr>,
    /// Allow --view on an address other than loopback (anyone with the URL can steer the run).
    #[arg(long, requires = "view")]
    pub view_public: bool,
    /// Publish the run to Foxglove over its WebSocket protocol (default 127.0.0.1:8765):
    /// the 3D scene, the pose, the sonar, the sensors, the thrusters and the link messages.
    /// Prints `foxglove: ws://HOST:PORT` before `ready`.
    #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1, default_missing_value = crate::view::FOXGLOVE_ADDR)]
    pub foxglove: Option<std::net::SocketAddr>,
    /// Allow --foxglove on an address other than loopback (anyone who reaches it can watch).
    #[arg(long, requires = "foxglove")]
    pub foxglove_public: bool,
}

impl RunArgs {
    /// The options that stand in for `[run]` keys.
    pub fn overrides(&self) -> Overrides {
        Overrides {
            seed: self.seed,
            time_mode: self.time_mode,
            speed: self.speed,
            run_dir: self.run_dir.clone(),
        }
    }
}

/// A loaded daemon configuration with where it came from.
pub struct Loaded {
    pub config: DaemonConfig,
    /// Where its model files are read.
    pub source: Box<dyn ConfigSource>,
    /// Its text, verbatim.
    pub text: String,
    /// Its name: the path given, or `<embedded>/default.toml`.
    pub name: String,
}

/// Loads the daemon configuration, `--config FILE` or the embedded default, with
/// `overrides` applied by [`DaemonConfig::resolve_with`].
pub fn load_config(path: Option<&PathBuf>, overrides: &Overrides) -> Result<Loaded, CliError> {
    let (source, file, base_dir): (Box<dyn ConfigSource>, String, Option<PathBuf>) = match path {
        Some(path) => {
            let (source, file) = BesideOrEmbedded::for_file(path);
            let base_dir = source.root().map(Path::to_path_buf);
            (Box::new(source), file, base_dir)
        }
        None => (Box::new(Embedded), DEFAULT_CONFIG.to_string(), None),
    };
    let text = source.read(&file)?.into_owned();
    let config = DaemonConfig::resolve_with(
        &Document::new(source.describe(&file), &text),
        overrides,
        base_dir.as_deref(),
    )?;
    let name = path.map_or_else(
        || format!("<embedded>/{DEFAULT_CONFIG}"),
        |p| p.display().to_string(),
    );
    Ok(Loaded {
        config,
        source,
        text,
        name,
    })
}

pub fn main(args: RunArgs) -> Result<(), CliError> {
    let Loaded {
        config,
        source,
        text,
        name,
    } = load_config(args.config.as_ref(), &args.overrides())?;
    let mut config = config;
    if let Some(choice) = &args.start {
        let world = crate::physics::load_world(source.as_ref(), &config.world)?;
        config.start = choice
            .resolve(&config.start, &world)
            .map_err(CliError::Usage)?;
    }
    let model = crate::daemon::plant::MakoPlant::from_config(source.as_ref(), &config)?;
    let (board, mux) = crate::daemon::plant::devices(&config);
    let leftovers = daemon::shutdown::Leftovers::default();
    let view = if args.view.is_some() || args.foxglove.is_some() {
        Some(crate::view::ViewOptions {
            addr: args.view,
            public: args.view_public,
            foxglove: args.foxglove,
            foxglove_public: args.foxglove_public,
            scene: crate::view::Scene::load(
                source.as_ref(),
                &config.vehicle,
                &config.world,
                &config.sensors,
            )?,
        })
    } else {
        None
    };
    let options = RunOptions {
        record: args.record,
        pid_file: args.pid_file,
        config_toml: text,
        config_name: name,
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
        let mut bridge = daemon::Daemon::start(&config, model, board, mux, options).await?;
        let observers = match view {
            Some(view) => match watch_with_view(&mut bridge, view).await {
                Ok(observers) => observers,
                Err(e) => {
                    // What `start` made is removed before the error is reported.
                    let _ = bridge.finish().await;
                    return Err(CliError::from(e));
                }
            },
            None => Vec::new(),
        };
        let summary = daemon::serve_started(bridge, observers, stop_rx, |event| {
            let mut out = std::io::stdout().lock();
            match event {
                Readiness::Link { name, path } => {
                    let _ = writeln!(out, "link {name}: {path}");
                }
                Readiness::Observer { name, url } => {
                    let _ = writeln!(out, "{name}: {url}");
                }
                Readiness::Ready { status_socket } => {
                    let _ = writeln!(out, "ready (status: {})", status_socket.display());
                    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
                }
            }
            let _ = out.flush();
        })
        .await?;
        Ok::<_, CliError>(summary)
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

/// Connects the live view and Foxglove, as `view` asks, to the daemon's observer; returns
/// where each is reached, to be announced before `ready`.
async fn watch_with_view<M: crate::engine::Model>(
    bridge: &mut daemon::Daemon<M>,
    view: crate::view::ViewOptions,
) -> Result<Vec<Readiness>, crate::view::ViewError> {
    let observation = bridge.observe();
    let started = crate::view::start_live(view, observation, bridge.status_updates()).await?;
    bridge.spawn_service("view", started.service);
    let mut observers = Vec::new();
    if let Some(url) = started.page_url {
        observers.push(Readiness::Observer { name: "view", url });
    }
    if let Some(url) = started.foxglove_url {
        observers.push(Readiness::Observer {
            name: "foxglove",
            url,
        });
    }
    Ok(observers)
}
