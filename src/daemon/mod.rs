//! The bridge daemon (`eyebot-hil run`): links, device emulators, the time model, recording
//! and the process life cycle around the simulation.
//!
//! A run has three stages, each a library call: [`Daemon::start`] (the resolved
//! configuration, a model, the devices and the options in; endpoints open, tasks running
//! out), [`Daemon::serve`] (until a shutdown future resolves) and [`Daemon::finish`] (a
//! [`Summary`] out). [`run`] composes them and reports readiness through a callback;
//! `main.rs` (through `cli::run`) only parses arguments, installs tracing and signal handlers
//! and calls it, so tests run the daemon in-process. Time comes from tokio's clock, which
//! tests can pause and advance; the model itself never reads a clock.

pub mod clock;
pub mod config;
pub mod course;
pub mod engine;
pub mod feed;
pub mod link;
pub mod pid_file;
pub mod plant;
pub mod run_dir;
pub mod shutdown;
pub mod socket;
pub mod status;
pub mod warn_limit;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

use self::clock::{RealtimeMap, TimeMode};
use self::config::{DaemonConfig, Endpoint};
use self::engine::{Carries, Engine, LineSpec, Model};
use self::link::{EndpointError, Inbound, LineContext, LinkCounters, OpenEndpoint, Outbound};
use self::pid_file::PidFile;
use self::status::{LinkStatus, Pose, StatusServer, StatusSnapshot};
use crate::record::{DropReason, RecordError, Recorder};

/// How often the realtime loop wakes when nothing is due (bounds the physics lag).
pub const IDLE_WAKE: Duration = Duration::from_millis(20);
/// How often the status snapshot is refreshed.
pub const STATUS_PERIOD: Duration = Duration::from_millis(100);

/// Why the daemon could not start or had to stop.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error(transparent)]
    Endpoint(#[from] EndpointError),
    #[error(transparent)]
    Status(#[from] status::StatusError),
    #[error(transparent)]
    Record(#[from] RecordError),
    #[error("run directory {path}: {source}")]
    RunDir {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("pid file {path}: {source}")]
    PidFile {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Feed(#[from] feed::FeedError),
    #[error(transparent)]
    View(#[from] crate::view::ViewError),
    #[error("the simulation stopped: {0}")]
    Model(#[source] Box<dyn std::error::Error + Send + Sync>),
}

/// Per-run options that are not part of the configuration file.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Record every byte and the ground truth here.
    pub record: Option<PathBuf>,
    /// Write the daemon's PID here (removed at exit).
    pub pid_file: Option<PathBuf>,
    /// The daemon configuration's text, copied verbatim into a recording as `config.toml`.
    pub config_toml: String,
    /// The configuration's name for the recording's `meta.toml` (a path, or
    /// `<embedded>/default.toml`).
    pub config_name: String,
    /// Filled with what the run creates (symlinks, sockets, pid file), for the process-level
    /// shutdown guard ([`shutdown::spawn_signal_guard`]).
    pub leftovers: shutdown::Leftovers,
    /// Serve the live view (`run --view`).
    pub view: Option<crate::view::ViewOptions>,
}

/// What the daemon reports as it comes up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Readiness {
    /// A link is open; the EyeBot side connects at `path`.
    Link { name: &'static str, path: String },
    /// The live view is served at `url` (it carries the token).
    View { url: String },
    /// Foxglove connects at `url` (`ws://HOST:PORT`).
    Foxglove { url: String },
    /// Everything is up.
    Ready { status_socket: PathBuf },
}

/// What a finished run did.
#[derive(Debug, Clone, Default)]
pub struct Summary {
    pub sim_time_s: f64,
    pub records: Option<crate::record::Stats>,
    pub overruns: u64,
}

/// The name [`Summary`] had when [`run`] was the only entry point.
pub type RunSummary = Summary;

/// An open link, as [`Daemon::links`] lists it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkInfo {
    pub name: &'static str,
    /// Where the EyeBot side connects (a symlink and its pty, a device, an address).
    pub path: String,
}

struct LineRuntime {
    /// The line's name, counters and recorder, shared with its link task.
    cx: LineContext,
    describe: String,
    to_link: mpsc::Sender<Outbound>,
    /// Released bytes the link task has not taken yet, sent as one chunk when it has room.
    backlog: bytes::BytesMut,
    /// Beyond this many waiting bytes the client is taken for not reading: drop and count.
    backlog_limit: usize,
    /// When bytes last arrived (lockstep's wall-clock idle limit).
    last_rx_wall: Instant,
}

/// The bridge, started: endpoints open, link tasks and services running, recording begun.
///
/// [`Daemon::start`] brings it up, [`Daemon::serve`] runs the simulation loop until a
/// shutdown future resolves, [`Daemon::finish`] flushes, closes and reports. Between them the
/// caller can announce readiness ([`Daemon::links`], [`Daemon::status_socket`]). Services
/// that run beside the links (the status socket, the sonar feed) are tokio tasks added with
/// [`Daemon::spawn_service`], told to stop and joined in `finish`; a new one (a live view,
/// reading [`Daemon::status_updates`]) is added the same way, in `start` or by the caller
/// before `serve`.
pub struct Daemon<M: Model> {
    config: DaemonConfig,
    engine: Engine<M>,
    lines: Vec<LineRuntime>,
    links: Vec<LinkInfo>,
    link_tasks: Vec<tokio::task::JoinHandle<()>>,
    inbound: mpsc::Receiver<Inbound>,
    feed: mpsc::Receiver<feed::FeedEvent>,
    status: watch::Sender<StatusSnapshot>,
    /// Tasks beside the links (the status socket, the sonar feed), stopped by `stop`.
    services: Vec<Service>,
    status_socket: PathBuf,
    /// Tells the link tasks and services to stop (sent by `finish`).
    stop: watch::Sender<bool>,
    pacing: LoopClock,
    record_dir: Option<PathBuf>,
    pid_file: Option<PidFile>,
    leftovers: shutdown::Leftovers,
    /// Held until `finish` has removed what the run made.
    run_dir_lock: Option<run_dir::RunDirLock>,
    view: Option<ViewHook>,
}

/// The loop's side of a live view.
struct ViewHook {
    side: crate::view::DaemonSide,
    url: Option<String>,
    foxglove_url: Option<String>,
    next_state: Instant,
}

/// A task that runs beside the links for the life of the daemon.
struct Service {
    name: &'static str,
    task: tokio::task::JoinHandle<()>,
}

/// The loop's view of wall time in realtime mode, and when it next reports status.
struct LoopClock {
    /// When serving began: wall time since then maps to simulated time.
    started: Instant,
    /// Whether `serve` has run, so a second call keeps the anchor.
    anchored: bool,
    /// `None` in lockstep: simulated time moves only on the client's frames.
    map: Option<RealtimeMap>,
    /// When the loop meant to wake next (wall time since start). Lag is measured against
    /// it: the sleep between wakes is not an overrun, only waking late is.
    planned_wake: Duration,
    next_status: Instant,
    timer: crate::transport::PreciseTimer,
}

impl<M: Model> Daemon<M> {
    /// Opens every endpoint, binds the status and feed sockets, writes the pid file, starts
    /// the recording and the link tasks. Must run inside a tokio runtime with I/O and time.
    pub async fn start(
        config: &DaemonConfig,
        model: M,
        board: crate::devices::sensor_board::SensorBoard,
        mux: crate::devices::multiplexer::Multiplexer,
        options: RunOptions,
    ) -> Result<Self, DaemonError> {
        let run_dir = config.run_dir.clone();
        // Before anything is created or cleaned up: of two daemons on one directory, the
        // second stops here having changed nothing.
        let run_dir_lock = run_dir::acquire(&run_dir).map_err(|source| DaemonError::RunDir {
            path: run_dir.clone(),
            source,
        })?;
        let lockstep = config.time_mode == TimeMode::Lockstep;
        let leftovers = options.leftovers.clone();

        let (specs, endpoints) = open_lines(config, &run_dir, &leftovers).await?;
        let status_socket = run_dir.join("status.sock");
        let status_server = StatusServer::bind(&status_socket)?;
        leftovers.socket(&status_socket);
        let pid_file = options
            .pid_file
            .as_deref()
            .map(PidFile::create)
            .transpose()?;
        if let Some(pid) = &options.pid_file {
            leftovers.pid_file(pid);
        }

        let mut engine = Engine::new(model, board, mux, &specs, lockstep);
        if let Some(log) = &config.sonar_replay {
            engine.set_feed(Box::new(feed::Schedule::open(log)?));
        }
        let feed_path = run_dir.join(feed::FEED_SOCKET);
        let feed_listener = feed::bind(&feed_path)?;
        leftovers.socket(&feed_path);
        if let Some(dir) = &options.record {
            let meta = crate::record::Meta::new(
                config.seed,
                config.time_mode.name(),
                config.time_mode.speed(),
                &options.config_name,
            );
            let recorder = Recorder::start(dir, &meta, &options.config_toml)?;
            engine.set_recorder(recorder, (1e9 / config.state_record_hz) as u64);
        }

        let (stop, stop_rx) = watch::channel(false);
        let Spawned {
            lines,
            links,
            link_tasks,
            inbound,
        } = spawn_link_tasks(&specs, endpoints, engine.recorder_handle(), &stop_rx);

        let (feed_tx, feed) = mpsc::channel(64);
        let (status, status_rx) = watch::channel(StatusSnapshot::default());
        let view = match options.view {
            Some(view) => {
                let started = crate::view::start_live(view, status.subscribe()).await?;
                Some((
                    ViewHook {
                        side: started.side,
                        url: started.page_url,
                        foxglove_url: started.foxglove_url,
                        next_state: Instant::now(),
                    },
                    started.service,
                ))
            }
            None => None,
        };
        let (view, view_service) = match view {
            Some((hook, service)) => (Some(hook), Some(service)),
            None => (None, None),
        };
        let started = Instant::now();
        let mut daemon = Self {
            config: config.clone(),
            engine,
            lines,
            links,
            link_tasks,
            inbound,
            feed,
            status,
            services: Vec::new(),
            status_socket,
            stop,
            pacing: LoopClock {
                started,
                map: match config.time_mode {
                    TimeMode::Realtime { speed } => Some(RealtimeMap::new(speed, config.max_lag)),
                    TimeMode::Lockstep => None,
                },
                anchored: false,
                planned_wake: Duration::ZERO,
                next_status: started,
                timer: crate::transport::PreciseTimer::new(),
            },
            record_dir: options.record,
            pid_file,
            leftovers,
            run_dir_lock: Some(run_dir_lock),
            view,
        };
        if let Some(service) = view_service {
            daemon.spawn_service("view", service);
        }
        daemon.spawn_service("sonar feed", |stop| {
            feed::serve(feed_listener, feed_path, feed_tx, stop)
        });
        daemon.spawn_service("status", |stop| async move {
            status_server.serve(status_rx, stop).await
        });
        Ok(daemon)
    }

    /// Runs a service beside the links: `service` is given the stop signal (it turns true
    /// in [`Daemon::finish`]) and must end soon after; one still running after
    /// [`shutdown::SERVICES_BUDGET`] is aborted. A view of the run subscribes to
    /// [`Daemon::status_updates`].
    pub fn spawn_service<F>(
        &mut self,
        name: &'static str,
        service: impl FnOnce(watch::Receiver<bool>) -> F,
    ) where
        F: Future<Output = ()> + Send + 'static,
    {
        let task = tokio::spawn(service(self.stop.subscribe()));
        self.services.push(Service { name, task });
    }

    /// The latest status snapshot, refreshed every [`STATUS_PERIOD`] while serving: a
    /// latest-wins channel, so a slow reader never holds the simulation up.
    pub fn status_updates(&self) -> watch::Receiver<StatusSnapshot> {
        self.status.subscribe()
    }

    /// The open links, in line order.
    pub fn links(&self) -> &[LinkInfo] {
        &self.links
    }

    /// The status socket (`eyebot-hil status`).
    pub fn status_socket(&self) -> &Path {
        &self.status_socket
    }

    /// The live view's URL (with its token), when serving one.
    pub fn view_url(&self) -> Option<&str> {
        self.view.as_ref().and_then(|v| v.url.as_deref())
    }

    /// Where Foxglove connects (`ws://HOST:PORT`), when serving it.
    pub fn foxglove_url(&self) -> Option<&str> {
        self.view.as_ref().and_then(|v| v.foxglove_url.as_deref())
    }

    /// Runs the simulation until `shutdown` resolves, every link task has ended, or the model
    /// fails. In realtime the calling thread holds the configured wake-up requests
    /// (`run.rt_priority`, `run.cpu_latency_us`) while it serves.
    pub async fn serve(&mut self, shutdown: impl Future<Output = ()>) -> Result<(), DaemonError> {
        // Only this thread is raised: the recorder and signal threads were started before and
        // keep the default scheduler. Lockstep has no wall-clock deadlines to protect.
        let wake = self.pacing.map.is_some().then(|| {
            crate::transport::WakeGuard::acquire(
                self.config.cpu_latency_us,
                self.config.rt_priority,
            )
        });
        if let Some(wake) = &wake {
            for refusal in wake.refusals() {
                tracing::warn!("{refusal}");
            }
            if let Some(latency_us) = wake.cpu_latency_us() {
                tracing::info!(latency_us, "holding a CPU latency request");
            }
            if let Some(priority) = wake.realtime_priority() {
                tracing::info!(priority, "bridge thread runs under SCHED_FIFO");
            }
        }
        if !self.pacing.anchored {
            // Wall time spent between `start` and `serve` (announcing readiness) is not
            // simulated time the model has fallen behind.
            self.pacing.started = Instant::now();
            self.pacing.next_status = self.pacing.started;
            self.pacing.anchored = true;
        }
        let mut shutdown = std::pin::pin!(shutdown);
        loop {
            self.catch_up()?;
            self.flush_idle_lockstep()?;
            flush_outputs(&mut self.engine, &mut self.lines, self.view.as_ref());
            let now = Instant::now();
            if let Some(view) = self.view.as_mut()
                && now >= view.next_state
            {
                let state = self.engine.model().state();
                view.side
                    .tap
                    .state(crate::record::StateRow::from_state(&state));
                view.next_state = now + crate::view::tap::VIEW_PERIOD;
            }
            if now >= self.pacing.next_status {
                self.status.send_replace(snapshot(
                    &self.engine,
                    &self.lines,
                    self.pacing.started,
                    &self.config,
                    self.pacing.map.as_ref(),
                    self.record_dir.as_deref(),
                ));
                self.pacing.next_status = now + STATUS_PERIOD;
            }
            let mut wake_at = self.pacing.next_wake(&self.engine, now);
            if let Some(idle) = self.next_idle_flush_lockstep() {
                wake_at = wake_at.min(idle.max(now));
            }
            if let Some(view) = &self.view {
                wake_at = wake_at.min(view.next_state.max(now));
            }
            let control = async {
                match self.view.as_mut() {
                    Some(view) => view.side.controls.recv().await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                inbound = self.inbound.recv() => match inbound {
                    Some(inbound) => {
                        self.advance_to_wall()?;
                        if let Some(view) = &self.view {
                            let name = self.engine.line_name(inbound.line);
                            let t_s = self.engine.now() as f64 * 1e-9;
                            view.side.tap.bytes(t_s, name, crate::record::Direction::Rx, inbound.data.clone());
                        }
                        self.engine.receive(inbound.line, &inbound.data).map_err(model_error)?;
                        if let Some(line) = self.lines.get_mut(inbound.line) {
                            line.last_rx_wall = Instant::now();
                        }
                    }
                    None => return Ok(()),
                },
                Some(request) = control => {
                    self.advance_to_wall()?;
                    let answer = self.apply_control(&request.control);
                    let _ = request.reply.send(answer);
                }
                Some(event) = self.feed.recv() => {
                    self.advance_to_wall()?;
                    match event {
                        feed::FeedEvent::Connected => self.engine.set_feed_connected(true),
                        feed::FeedEvent::Bytes(data) => self.engine.feed_bytes(&data),
                        feed::FeedEvent::Closed => self.engine.set_feed_connected(false),
                    }
                }
                _ = self.pacing.timer.sleep_until(wake_at) => {}
                _ = &mut shutdown => return Ok(()),
            }
        }
    }

    /// Applies a control from the live view at the current simulated time and records it as
    /// an event; `Err` says why it was refused (nothing changed then).
    fn apply_control(&mut self, control: &crate::view::tap::Control) -> Result<String, String> {
        use crate::view::tap::Control;
        let wall = self.pacing.started.elapsed();
        let lockstep = "lockstep: simulated time moves only on the client's time frames";
        let done = match control {
            Control::Pause | Control::Resume | Control::Speed { .. } => {
                let Some(map) = self.pacing.map.as_mut() else {
                    return Err(format!(
                        "{lockstep}; there is no clock to {}",
                        control.name()
                    ));
                };
                match control {
                    Control::Pause => map.pause(wall),
                    Control::Resume => map.resume(wall),
                    Control::Speed { factor } => {
                        if !(factor.is_finite() && config::SPEED_RANGE.contains(factor)) {
                            return Err(format!(
                                "speed factor {factor}: expected {} to {}",
                                config::SPEED_RANGE.start(),
                                config::SPEED_RANGE.end()
                            ));
                        }
                        map.set_speed(*factor, wall);
                    }
                    _ => {}
                }
                if let Some(view) = &self.view {
                    view.side.tap.paused(map.is_paused());
                }
                format!("{} (speed {})", control.name(), map.speed())
            }
            Control::Pose {
                x_m,
                y_m,
                depth_m,
                heading_deg,
            } => {
                let placement = engine::Placement {
                    x_m: *x_m,
                    y_m: *y_m,
                    depth_m: *depth_m,
                    heading_deg: *heading_deg,
                };
                self.engine.place(&placement)?;
                format!(
                    "vehicle at x {x_m} m, y {y_m} m, depth {depth_m} m, heading {heading_deg} deg, at rest"
                )
            }
            Control::Current {
                north_mps,
                east_mps,
            } => {
                self.engine.set_current(*north_mps, *east_mps)?;
                if let Some(view) = &self.view {
                    view.side.tap.current(*north_mps, *east_mps);
                }
                format!("water current {north_mps} m/s north, {east_mps} m/s east")
            }
            Control::Reset => {
                self.engine.reset_pose()?;
                "vehicle back at its start pose, at rest".to_string()
            }
        };
        let t_s = self.engine.now() as f64 * 1e-9;
        if let Some(recorder) = self.engine.recorder_handle() {
            recorder.event(t_s, control.name(), &control.detail());
        }
        tracing::info!(sim_s = t_s, control = control.name(), "{done}");
        Ok(done)
    }

    /// In realtime: settles the overrun accounting for this wake-up and runs the model up to
    /// the wall clock.
    fn catch_up(&mut self) -> Result<(), DaemonError> {
        let Some(map) = self.pacing.map.as_mut() else {
            return Ok(());
        };
        let wall = self.pacing.started.elapsed();
        let reached = self.engine.now().max(map.target(self.pacing.planned_wake));
        if let Some(slip) = map.settle(reached, wall) {
            // Counted in the status's overruns; a starved loop may slip at every wake-up.
            crate::warn_limited!(
                "overrun",
                slip_ms = slip as f64 * 1e-6,
                "overrun: simulated time slipped behind the wall clock"
            );
        }
        self.engine
            .advance_to(map.target(wall))
            .map_err(model_error)
    }

    /// In lockstep, where simulated time stands still while the bridge waits for a request,
    /// a partial message is dropped once its line has been silent for the idle limit of wall
    /// time (PROTOCOL.md section 3). In realtime the engine does this in simulated time.
    fn flush_idle_lockstep(&mut self) -> Result<(), DaemonError> {
        if self.pacing.map.is_some() {
            return Ok(());
        }
        for index in 0..self.lines.len() {
            if self.engine.holds_partial(index)
                && self.lines[index].last_rx_wall.elapsed() >= self.engine.idle_limit(index)
            {
                self.engine.flush_line(index).map_err(model_error)?;
            }
        }
        Ok(())
    }

    /// In lockstep: when the next line with a partial message reaches its idle limit.
    fn next_idle_flush_lockstep(&self) -> Option<Instant> {
        if self.pacing.map.is_some() {
            return None;
        }
        self.lines
            .iter()
            .enumerate()
            .filter(|(index, _)| self.engine.holds_partial(*index))
            .map(|(index, line)| line.last_rx_wall + self.engine.idle_limit(index))
            .min()
    }

    /// In realtime: runs the model up to the wall clock before an input is applied.
    fn advance_to_wall(&mut self) -> Result<(), DaemonError> {
        match self.pacing.map.as_ref() {
            Some(map) => self
                .engine
                .advance_to(map.target(self.pacing.started.elapsed()))
                .map_err(model_error),
            None => Ok(()),
        }
    }

    /// Flushes what is due, stops the link tasks (they write what was released, close their
    /// endpoints and remove their symlinks) and the services, finishes the recording,
    /// removes the pid file and the sockets.
    pub async fn finish(mut self) -> Result<Summary, DaemonError> {
        flush_outputs(&mut self.engine, &mut self.lines, self.view.as_ref());
        let sim_time_s = self.engine.now() as f64 * 1e-9;
        let overruns = self.pacing.map.as_ref().map_or(0, RealtimeMap::overruns);
        self.stop.send_replace(true);
        drop(std::mem::take(&mut self.lines));
        // Link tasks get `TASKS_BUDGET` between them; one that has not stopped by then is
        // aborted, which drops its endpoint (and symlink). See `shutdown` for the whole bound.
        // Input that arrived before the shutdown but was not processed (the loop may stop
        // with chunks still queued, and the link tasks drain their endpoints as they stop) is
        // recorded, not acted on: the run is over. It is taken while the tasks stop, so a
        // task handing over its endpoint's last bytes never waits for room.
        let tasks_deadline = Instant::now() + shutdown::TASKS_BUDGET;
        let tasks = std::mem::take(&mut self.link_tasks);
        let aborts: Vec<_> = tasks.iter().map(|t| t.abort_handle()).collect();
        let joined = async {
            for task in tasks {
                let _ = task.await;
            }
        };
        tokio::pin!(joined);
        loop {
            tokio::select! {
                biased;
                Some(inbound) = self.inbound.recv() => {
                    self.engine.record_unprocessed(inbound.line, &inbound.data);
                }
                () = &mut joined => break,
                () = tokio::time::sleep_until(tasks_deadline) => {
                    tracing::warn!("a link task did not stop in time; aborting it");
                    for abort in &aborts {
                        abort.abort();
                    }
                    let _ = tokio::time::timeout(Duration::from_millis(20), &mut joined).await;
                    break;
                }
            }
        }
        while let Ok(inbound) = self.inbound.try_recv() {
            self.engine.record_unprocessed(inbound.line, &inbound.data);
        }
        let services_deadline = Instant::now() + shutdown::SERVICES_BUDGET;
        for mut service in std::mem::take(&mut self.services) {
            if tokio::time::timeout_at(services_deadline, &mut service.task)
                .await
                .is_err()
            {
                tracing::warn!(
                    service = service.name,
                    "a service did not stop in time; aborting it"
                );
                service.task.abort();
            }
        }
        let records = match self.engine.take_recorder() {
            Some(recorder) => Some(recorder.finish()?),
            None => None,
        };
        drop(self.pid_file.take());
        self.leftovers.remove_all();
        drop(self.run_dir_lock.take());
        warn_limit::flush();
        Ok(Summary {
            sim_time_s,
            records,
            overruns,
        })
    }
}

/// The lines the configuration asks for, each with its endpoint opened: the sonar line
/// (carrying the sensor link too when it is shared), then the sensor line. Symlinks we own
/// are noted in `leftovers`.
async fn open_lines(
    config: &DaemonConfig,
    run_dir: &Path,
    leftovers: &shutdown::Leftovers,
) -> Result<(Vec<LineSpec>, Vec<OpenEndpoint>), DaemonError> {
    let shared = config.sensor.endpoint == Endpoint::SharedWithSonar;
    let line_spec = |name, carries, link: &config::LinkConfig| LineSpec {
        name,
        carries,
        settings: link.line,
        tx_queue_bytes: link.tx_queue_bytes,
        release_quantum_ns: config.release_quantum.as_nanos() as u64,
    };
    let mut specs = vec![if shared {
        line_spec("shared", Carries::SHARED, &config.sonar)
    } else {
        line_spec("sonar", Carries::SONAR, &config.sonar)
    }];
    let mut endpoints = vec![OpenEndpoint::open("sonar", &config.sonar, run_dir).await?];
    if !shared {
        specs.push(line_spec("sensor", Carries::SENSOR, &config.sensor));
        endpoints.push(OpenEndpoint::open("sensor", &config.sensor, run_dir).await?);
    }
    for endpoint in &endpoints {
        if let Some((path, target)) = endpoint.owned_link() {
            leftovers.symlink(path, target);
        }
    }
    Ok((specs, endpoints))
}

/// What [`spawn_link_tasks`] started.
struct Spawned {
    lines: Vec<LineRuntime>,
    links: Vec<LinkInfo>,
    link_tasks: Vec<tokio::task::JoinHandle<()>>,
    /// Everything the link tasks read, in arrival order.
    inbound: mpsc::Receiver<Inbound>,
}

/// One link task per line, on its endpoint; the loop's side of each in `lines`.
fn spawn_link_tasks(
    specs: &[LineSpec],
    endpoints: Vec<OpenEndpoint>,
    recorder: Option<crate::record::RecordHandle>,
    stop: &watch::Receiver<bool>,
) -> Spawned {
    let (in_tx, inbound) = mpsc::channel::<Inbound>(256);
    let mut spawned = Spawned {
        lines: Vec::new(),
        links: Vec::new(),
        link_tasks: Vec::new(),
        inbound,
    };
    for ((index, endpoint), spec) in endpoints.into_iter().enumerate().zip(specs) {
        let describe = endpoint.describe();
        spawned.links.push(LinkInfo {
            name: spec.name,
            path: describe.clone(),
        });
        let (out_tx, out_rx) = mpsc::channel(link::TX_CHANNEL_CHUNKS);
        let counters = Arc::new(LinkCounters::default());
        let cx = LineContext {
            line: index,
            name: spec.name,
            counters,
            recorder: recorder.clone(),
        };
        spawned.link_tasks.push(tokio::spawn(link::run_line(
            cx.clone(),
            endpoint,
            in_tx.clone(),
            out_rx,
            stop.clone(),
        )));
        spawned.lines.push(LineRuntime {
            cx,
            describe,
            to_link: out_tx,
            backlog: bytes::BytesMut::new(),
            backlog_limit: spec.tx_queue_bytes,
            last_rx_wall: Instant::now(),
        });
    }
    spawned
}

impl LoopClock {
    /// When the loop wakes next: at the engine's next deadline (realtime, at most
    /// [`IDLE_WAKE`] away), or to refresh the status (lockstep).
    fn next_wake<M: Model>(&mut self, engine: &Engine<M>, now: Instant) -> Instant {
        match self.map.as_ref() {
            Some(map) => {
                let due = engine
                    .next_deadline()
                    .map_or(Duration::MAX, |t| map.wall_at(t));
                let due = due.min(self.started.elapsed() + IDLE_WAKE);
                self.planned_wake = due;
                self.started + due
            }
            None => now + STATUS_PERIOD,
        }
    }
}

/// Runs the bridge until `shutdown` turns true (or its sender is dropped): [`Daemon::start`],
/// readiness reported through `on_ready` (each link, then `Ready`), [`Daemon::serve`],
/// [`Daemon::finish`]. The daemon is finished even when serving failed; the serving error is
/// returned first.
pub async fn run<M>(
    config: &DaemonConfig,
    model: M,
    board: crate::devices::sensor_board::SensorBoard,
    mux: crate::devices::multiplexer::Multiplexer,
    options: RunOptions,
    mut shutdown: watch::Receiver<bool>,
    mut on_ready: impl FnMut(Readiness),
) -> Result<Summary, DaemonError>
where
    M: Model,
{
    let mut daemon = Daemon::start(config, model, board, mux, options).await?;
    for link in daemon.links() {
        on_ready(Readiness::Link {
            name: link.name,
            path: link.path.clone(),
        });
    }
    if let Some(url) = daemon.view_url() {
        on_ready(Readiness::View {
            url: url.to_string(),
        });
    }
    if let Some(url) = daemon.foxglove_url() {
        on_ready(Readiness::Foxglove {
            url: url.to_string(),
        });
    }
    on_ready(Readiness::Ready {
        status_socket: daemon.status_socket().to_path_buf(),
    });
    let served = daemon
        .serve(async move {
            // A dropped sender is a shutdown too.
            let _ = shutdown.wait_for(|stop| *stop).await;
        })
        .await;
    let summary = daemon.finish().await;
    served?;
    summary
}

fn model_error<E: std::error::Error + Send + Sync + 'static>(e: E) -> DaemonError {
    DaemonError::Model(Box::new(e))
}

/// Hands released bytes to the link tasks. Paced bytes are released a few at a time, so the
/// hand-over channel (counted in chunks) fills after a short stall of the link task even
/// when the client reads: bytes that do not fit wait in the line's backlog and go as one
/// chunk next time. Only when the channel is full and the backlog would exceed the line's
/// `tx_queue_bytes` (a client that does not read, or is gone) are the newly released bytes
/// dropped, counted and recorded as drops (the older ones keep their place, as in a UART
/// overrun); the daemon never blocks on a client.
fn flush_outputs<M: Model>(
    core: &mut Engine<M>,
    lines: &mut [LineRuntime],
    view: Option<&ViewHook>,
) {
    let sim_s = core.now() as f64 * 1e-9;
    for (index, line) in lines.iter_mut().enumerate() {
        let waiting = line.backlog.len();
        while let Some(data) = core.take_output(index) {
            line.backlog.extend_from_slice(&data);
            if let Some(view) = view {
                view.side
                    .tap
                    .bytes(sim_s, line.cx.name, crate::record::Direction::Tx, data);
            }
        }
        if line.backlog.is_empty() {
            continue;
        }
        let chunk = Outbound {
            sim_s,
            data: line.backlog.split().freeze(),
        };
        match line.to_link.try_send(chunk) {
            Ok(()) => {}
            Err(mpsc::error::TrySendError::Full(chunk))
                if chunk.data.len() <= line.backlog_limit =>
            {
                line.backlog.extend_from_slice(&chunk.data);
            }
            Err(mpsc::error::TrySendError::Full(chunk)) => {
                line.backlog.extend_from_slice(&chunk.data[..waiting]);
                line.cx
                    .dropped(sim_s, DropReason::NotRead, &chunk.data[waiting..]);
            }
            Err(mpsc::error::TrySendError::Closed(chunk)) => {
                line.cx
                    .dropped(sim_s, DropReason::EndpointGone, &chunk.data);
            }
        }
    }
}

fn snapshot<M: Model>(
    core: &Engine<M>,
    lines: &[LineRuntime],
    started: Instant,
    config: &DaemonConfig,
    map: Option<&RealtimeMap>,
    record: Option<&Path>,
) -> StatusSnapshot {
    let state = core.model().state();
    let (roll, pitch, yaw) = state.euler_rad();
    StatusSnapshot {
        pid: std::process::id(),
        version: env!("CARGO_PKG_VERSION").to_string(),
        uptime_s: started.elapsed().as_secs_f64(),
        sim_time_s: core.now() as f64 * 1e-9,
        time_mode: config.time_mode.name().to_string(),
        speed: map.map_or(0.0, RealtimeMap::speed),
        overruns: map.map_or(0, RealtimeMap::overruns),
        links: lines
            .iter()
            .enumerate()
            .map(|(i, l)| {
                let c = core.line_counters(i);
                LinkStatus {
                    name: l.cx.name.to_string(),
                    path: l.describe.clone(),
                    bytes_rx: l.cx.counters.bytes_rx.load(Ordering::Relaxed),
                    bytes_tx: l.cx.counters.bytes_tx.load(Ordering::Relaxed),
                    frames_rx: c.frames_rx,
                    frames_tx: c.frames_tx,
                    errors: c.errors + l.cx.counters.io_errors.load(Ordering::Relaxed),
                    dropped_tx: c.dropped_tx + l.cx.counters.dropped_tx.load(Ordering::Relaxed),
                    reconnects: l.cx.counters.reconnects.load(Ordering::Relaxed),
                }
            })
            .collect(),
        pose: Pose {
            x_m: state.position_m.x,
            y_m: state.position_m.y,
            depth_m: state.position_m.z,
            roll_deg: roll.to_degrees(),
            pitch_deg: pitch.to_degrees(),
            heading_deg: yaw.to_degrees().rem_euclid(360.0),
            surge_mps: state.velocity_body_mps.x,
        },
        contacts: core.model().contacts(),
        recording: record.map(|p| p.display().to_string()),
    }
}

#[cfg(test)]
mod tests {
    use bytes::BytesMut;
    use firmware_protocol::sensor_link::Message;
    use firmware_protocol::sonar_link::SonarCommand;
    use firmware_protocol::{Frame, LineDecoder, LineItem, Talker, Transducer};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    use super::*;
    use crate::config::{ConfigSource, DEFAULT_CONFIG, Document, Embedded};
    use crate::daemon::engine::fake::FakeModel;
    use crate::devices::multiplexer::{
        DepthSentence, InvalidEcho, Multiplexer, MultiplexerSettings,
    };
    use crate::devices::sensor_board::{BoardSettings, SensorBoard};
    use crate::transport::serial;

    fn config(run_dir: &Path) -> DaemonConfig {
        let text = Embedded.read(DEFAULT_CONFIG).unwrap();
        let mut config = DaemonConfig::resolve(&Document::new("default", &text)).unwrap();
        config.time_mode = TimeMode::Lockstep;
        config.run_dir = run_dir.to_path_buf();
        config
    }

    /// A fresh scratch directory (removed when it drops) and the default configuration in
    /// `time_mode` with its run directory inside.
    fn scratch(tag: &str, time_mode: TimeMode) -> (tempfile::TempDir, DaemonConfig) {
        let dir = crate::scratch::dir(tag);
        let mut config = config(&dir.path().join("run"));
        config.time_mode = time_mode;
        (dir, config)
    }

    fn devices() -> (SensorBoard, Multiplexer) {
        let board = SensorBoard::new(BoardSettings {
            tick_ns: 10_000_000,
            lockstep: true,
            compass_period_ns: 400_000_000,
            line_chars_per_s: 11_520.0,
            watchdog_ns: None,
            sonar_on_this_line: false,
        });
        let mux = Multiplexer::new(MultiplexerSettings {
            sentence: DepthSentence::Dbt,
            talker: Talker::SOUNDER,
            invalid_echo: InvalidEcho::Omit,
            proprietary: false,
        });
        (board, mux)
    }

    async fn read_item(
        port: &mut tokio_serial::SerialStream,
        buf: &mut BytesMut,
        decoder: &mut LineDecoder,
    ) -> LineItem {
        loop {
            if let Some(item) = decoder.decode(buf) {
                return item;
            }
            let mut chunk = [0u8; 256];
            let n = tokio::time::timeout(Duration::from_secs(5), port.read(&mut chunk))
                .await
                .expect("reply within 5 s")
                .unwrap();
            buf.extend_from_slice(&chunk[..n]);
        }
    }

    /// `run` on a fake model with the test devices, as a task.
    fn spawn_run(
        config: DaemonConfig,
        options: RunOptions,
        stop: watch::Receiver<bool>,
        on_ready: impl FnMut(Readiness) + Send + 'static,
    ) -> tokio::task::JoinHandle<Result<Summary, DaemonError>> {
        let (board, mux) = devices();
        tokio::spawn(async move {
            run(
                &config,
                FakeModel::default(),
                board,
                mux,
                options,
                stop,
                on_ready,
            )
            .await
        })
    }

    /// Sends `message` as frame `seq` on the sensor link and returns the reply to it.
    async fn ask(
        (port, buf, decoder): &mut (
            &mut tokio_serial::SerialStream,
            &mut BytesMut,
            &mut LineDecoder,
        ),
        seq: u8,
        message: Message,
    ) -> Message {
        let mut frame = BytesMut::new();
        Frame::new(seq, message).encode(&mut frame);
        port.write_all(&frame).await.unwrap();
        match read_item(port, buf, decoder).await {
            LineItem::Frame(reply) if reply.seq == seq => reply.message,
            other => panic!("expected the reply to frame {seq}, got {other:?}"),
        }
    }

    /// The daemon in-process, in lockstep, over ptys: a client says hello, advances time,
    /// selects a transducer; the sonar line delivers the ack and a sentence; status reports
    /// the time; shutdown removes the links and finishes the recording.
    /// Regression: every released chunk went to the link task's channel (64 chunks) and was
    /// dropped when the channel was full. Paced bytes are released a few at a time, so a link
    /// task that stalled for a few ms lost bytes of a client that was reading (33,318 bytes
    /// in the one-hour run at speed 100 of `bench daemon rss`). Now they wait in a backlog.
    #[test]
    fn released_bytes_wait_for_a_busy_link_task_instead_of_being_dropped() {
        let (board, mux) = devices();
        let spec = |name, sonar, baud| LineSpec {
            name,
            carries: Carries {
                sonar,
                sensor: !sonar,
            },
            settings: crate::transport::LineSettings::n81(baud),
            tx_queue_bytes: 4096,
            release_quantum_ns: 1_000_000,
        };
        let specs = [spec("sonar", true, 4800), spec("sensor", false, 115_200)];
        let mut core = Engine::new(FakeModel::default(), board, mux, &specs, false);
        // A link task that takes one chunk and then stalls: a channel with room for one.
        let (sonar_tx, _sonar_rx) = mpsc::channel(1);
        let (sensor_tx, mut sensor_rx) = mpsc::channel(1);
        let runtime = |line, name, to_link| LineRuntime {
            cx: LineContext {
                line,
                name,
                counters: Arc::default(),
                recorder: None,
            },
            describe: String::new(),
            to_link,
            backlog: bytes::BytesMut::new(),
            backlog_limit: 4096,
            last_rx_wall: Instant::now(),
        };
        let mut lines = vec![
            runtime(0, "sonar", sonar_tx),
            runtime(1, "sensor", sensor_tx),
        ];
        let mut stream = BytesMut::new();
        Frame::new(
            1,
            Message::AdcStream {
                channels: 0b1,
                period_ms: 10,
            },
        )
        .encode(&mut stream);
        core.receive(1, &stream).unwrap();
        let mut delivered = 0;
        for step in 1..=100u64 {
            core.advance_to(step * 10_000_000).unwrap();
            flush_outputs(&mut core, &mut lines, None);
            if step % 25 == 0 {
                // The link task catches up now and then.
                while let Ok(chunk) = sensor_rx.try_recv() {
                    delivered += chunk.data.len();
                    flush_outputs(&mut core, &mut lines, None);
                }
            }
        }
        assert_eq!(lines[1].cx.counters.dropped_tx.load(Ordering::Relaxed), 0);
        // The ACK and about 100 samples of 14 bytes, all delivered.
        assert!(delivered > 1300, "{delivered} bytes delivered");
    }

    /// Regression: the overrun check compared the time reached at the last wake with the
    /// target now, so a normal 20 ms idle sleep at speed 10 (200 ms simulated) counted as an
    /// overrun of more than `max_lag` (100 ms); the map re-anchored at the old time on every
    /// wake and simulated time never advanced without client traffic.
    #[tokio::test]
    async fn realtime_at_speed_10_advances_without_a_client() {
        let (_dir, config) = scratch("rt10", TimeMode::Realtime { speed: 10.0 });
        let (stop_tx, stop_rx) = watch::channel(false);
        let daemon = spawn_run(config, RunOptions::default(), stop_rx, |_| {});
        tokio::time::sleep(Duration::from_secs(1)).await;
        stop_tx.send(true).unwrap();
        let summary = daemon.await.unwrap().unwrap();
        // 10 s in an ideal world; a loaded machine may slip a little (counted overruns).
        assert!(summary.sim_time_s >= 5.0, "1 s at speed 10: {summary:?}");
    }

    /// The three stages on their own: after `start` the links exist before anything is
    /// served; a service added with `spawn_service` runs beside them and is told to stop by
    /// `finish`; `serve` returns when its shutdown future resolves, having published status.
    #[tokio::test]
    async fn start_serve_finish_run_a_service_beside_the_links() {
        let (_dir, config) = scratch("stages", TimeMode::Lockstep);
        let run_dir = config.run_dir.clone();
        let (board, mux) = devices();
        let mut daemon = Daemon::start(
            &config,
            FakeModel::default(),
            board,
            mux,
            RunOptions::default(),
        )
        .await
        .unwrap();
        let names: Vec<&str> = daemon.links().iter().map(|l| l.name).collect();
        assert_eq!(names, ["sonar", "sensor"]);
        assert!(std::fs::symlink_metadata(run_dir.join("sensor")).is_ok());
        assert_eq!(daemon.status_socket(), run_dir.join("status.sock"));
        let (told_tx, told_rx) = tokio::sync::oneshot::channel();
        daemon.spawn_service("test", |mut stop| async move {
            let _ = stop.wait_for(|stop| *stop).await;
            let _ = told_tx.send(());
        });
        let mut updates = daemon.status_updates();
        daemon
            .serve(tokio::time::sleep(STATUS_PERIOD * 2))
            .await
            .unwrap();
        assert!(
            updates.has_changed().unwrap(),
            "status published while serving"
        );
        assert_eq!(updates.borrow_and_update().links.len(), 2);
        let summary = daemon.finish().await.unwrap();
        assert_eq!(
            summary.sim_time_s, 0.0,
            "lockstep without a client stays at 0"
        );
        tokio::time::timeout(Duration::from_secs(1), told_rx)
            .await
            .expect("the service stopped within its budget")
            .expect("the service was told to stop");
        for name in ["sonar", "sensor", "status.sock", feed::FEED_SOCKET] {
            assert!(
                std::fs::symlink_metadata(run_dir.join(name)).is_err(),
                "{name} removed"
            );
        }
    }

    /// Realtime counts from `serve`, not from `start`: time the caller spends in between
    /// (announcing readiness) is neither simulated nor an overrun.
    #[tokio::test]
    async fn realtime_starts_counting_when_serving_begins() {
        let (_dir, config) = scratch("anchor", TimeMode::Realtime { speed: 1.0 });
        let (board, mux) = devices();
        let options = RunOptions::default();
        let mut daemon = Daemon::start(&config, FakeModel::default(), board, mux, options)
            .await
            .unwrap();
        tokio::time::sleep(Duration::from_millis(500)).await;
        daemon
            .serve(tokio::time::sleep(Duration::from_millis(100)))
            .await
            .unwrap();
        let summary = daemon.finish().await.unwrap();
        assert_eq!(summary.overruns, 0, "{summary:?}");
        assert!(summary.sim_time_s < 0.4, "{summary:?}");
    }

    #[tokio::test]
    async fn lockstep_daemon_serves_ptys_and_shuts_down_cleanly() {
        let (tmp, config) = scratch("daemon", TimeMode::Lockstep);
        let dir = tmp.path();
        let run_dir = config.run_dir.clone();
        let record = dir.join("rec");
        let (stop_tx, stop_rx) = watch::channel(false);
        let (ready_tx, mut ready_rx) = mpsc::unbounded_channel();
        let options = RunOptions {
            record: Some(record.clone()),
            pid_file: Some(dir.join("pid")),
            config_toml: "seed = 1\n".into(),
            ..RunOptions::default()
        };
        let daemon = spawn_run(config, options, stop_rx, move |r| {
            let _ = ready_tx.send(r);
        });
        let mut links = Vec::new();
        while let Readiness::Link { name, path } =
            ready_rx.recv().await.expect("daemon reports readiness")
        {
            links.push((name, path));
        }
        assert_eq!(
            links.iter().map(|l| l.0).collect::<Vec<_>>(),
            vec!["sonar", "sensor"]
        );
        assert!(dir.join("pid").exists());

        let mut sensor = serial::open(
            &run_dir.join("sensor"),
            &crate::transport::LineSettings::n81(115_200),
        )
        .unwrap();
        let mut sonar = serial::open(
            &run_dir.join("sonar"),
            &crate::transport::LineSettings::n81(4800),
        )
        .unwrap();
        let (mut sbuf, mut sdec) = (BytesMut::new(), LineDecoder::new());
        let mut sensor_link = (&mut sensor, &mut sbuf, &mut sdec);
        assert!(matches!(
            ask(&mut sensor_link, 1, Message::Hello { client_version: 1 }).await,
            Message::HelloReply { .. }
        ));
        let mut select = BytesMut::new();
        SonarCommand::Select(Transducer::new(1).unwrap()).encode(&mut select);
        sonar.write_all(&select).await.unwrap();
        // Give the select time to cross its pty before time moves on.
        tokio::time::sleep(Duration::from_millis(100)).await;
        let time = ask(&mut sensor_link, 2, Message::TimeAdvance { ticks: 150 }).await;
        assert!(matches!(time, Message::Time { ticks: 150, .. }), "{time:?}");
        let (mut nbuf, mut ndec) = (BytesMut::new(), LineDecoder::new());
        assert!(matches!(
            read_item(&mut sonar, &mut nbuf, &mut ndec).await,
            LineItem::Sonar(SonarCommand::Ack(_))
        ));
        assert!(matches!(
            read_item(&mut sonar, &mut nbuf, &mut ndec).await,
            LineItem::Nmea(_)
        ));

        tokio::time::sleep(STATUS_PERIOD * 2).await;
        let status = status::query(&run_dir.join("status.sock"), Duration::from_secs(2))
            .await
            .unwrap();
        assert_eq!(status.sim_time_s, 1.5);
        assert_eq!(status.time_mode, "lockstep");

        // `replay --into-sonar`: captured sentences through the feed socket replace the
        // model's; the log's $PEBHS maps each to its transducer (1 is selected, 2 is not).
        let mut feed = tokio::net::UnixStream::connect(run_dir.join(feed::FEED_SOCKET))
            .await
            .unwrap();
        feed.write_all(
            b"$SDDBT,8.2,f,2.5,M,1.4,F*0E\r\n$PEBHS,1,2.5,90*71\r\n$SDDBT,9.9,f,3.0,M,1.6,F*02\r\n$PEBHS,2,3.0,90*76\r\n",
        )
        .await
        .unwrap();
        tokio::time::sleep(Duration::from_millis(200)).await;
        let time = ask(&mut sensor_link, 3, Message::TimeAdvance { ticks: 50 }).await;
        assert!(matches!(time, Message::Time { ticks: 200, .. }), "{time:?}");
        let fed = read_item(&mut sonar, &mut nbuf, &mut ndec).await;
        let LineItem::Nmea(firmware_protocol::Sentence::Dbt(dbt)) = fed else {
            panic!("expected the fed DBT, got {fed:?}")
        };
        assert_eq!(
            dbt.metres.map(|m| m.tenths()),
            Some(25),
            "transducer 1's logged 2.5 m"
        );
        let mut more = [0u8; 64];
        let late = tokio::time::timeout(Duration::from_millis(300), sonar.read(&mut more)).await;
        assert!(
            nbuf.is_empty() && late.is_err(),
            "transducer 2's 3.0 m was withheld"
        );
        drop(feed);

        stop_tx.send(true).unwrap();
        let summary = tokio::time::timeout(Duration::from_secs(1), daemon)
            .await
            .expect("shutdown within 1 s")
            .unwrap()
            .unwrap();
        assert_eq!(summary.sim_time_s, 2.0);
        let records = summary.records.unwrap();
        assert!(records.chunks >= 6, "{records:?}");
        assert!(records.states > 0);
        for name in ["sonar", "sensor", "status.sock"] {
            assert!(
                std::fs::symlink_metadata(run_dir.join(name)).is_err(),
                "{name} removed"
            );
        }
        assert!(!dir.join("pid").exists());
    }
}
