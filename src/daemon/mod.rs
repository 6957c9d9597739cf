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
pub mod feed;
mod lines;
pub mod link;
pub mod observer;
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
use self::lines::{LineRuntime, Spawned, flush_outputs, open_lines, snapshot, spawn_link_tasks};
use self::link::{EndpointError, Inbound, LineContext, LinkCounters, OpenEndpoint, Outbound};
use self::observer::{Control, Observation, ObserverEnd};
use self::pid_file::PidFile;
use self::status::{LinkStatus, Pose, StatusServer, StatusSnapshot};
use crate::engine::{self, Carries, Engine, Journal, LineSpec, Model};
use crate::record::{DropReason, RecordError, RecordHandle, Recorder, StateRow};

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
}

/// What the daemon reports as it comes up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Readiness {
    /// A link is open; the EyeBot side connects at `path`.
    Link { name: &'static str, path: String },
    /// Something the caller connected to the daemon's observer (the live view: `view`,
    /// Foxglove: `foxglove`) is reached at `url`.
    Observer { name: &'static str, url: String },
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
    /// Tasks beside the links (the status socket, the sonar feed, what watches the run),
    /// stopped by `stop`.
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
    /// The recording, when recording (the engine and the link tasks hold handles on it).
    recorder: Option<Recorder>,
    /// The loop's end of the observer, once something asked to watch.
    observer: Option<ObserverEnd>,
}

/// The engine reports to the recording through a handle.
impl Journal for RecordHandle {
    fn bytes(&self, sim_s: f64, line: &'static str, dir: crate::record::Direction, data: &[u8]) {
        RecordHandle::bytes(self, sim_s, line, dir, data);
    }
    fn state(&self, row: StateRow) {
        RecordHandle::state(self, row);
    }
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
        let recorder = match &options.record {
            Some(dir) => {
                let meta = crate::record::Meta::new(
                    config.seed,
                    config.time_mode.name(),
                    config.time_mode.speed(),
                    &options.config_name,
                );
                let recorder = Recorder::start(dir, &meta, &options.config_toml)?;
                engine.set_journal(
                    Box::new(recorder.handle()),
                    (1e9 / config.state_record_hz) as u64,
                );
                Some(recorder)
            }
            None => None,
        };

        let (stop, stop_rx) = watch::channel(false);
        let Spawned {
            lines,
            links,
            link_tasks,
            inbound,
        } = spawn_link_tasks(
            &specs,
            endpoints,
            recorder.as_ref().map(Recorder::handle),
            &stop_rx,
        );

        let (feed_tx, feed) = mpsc::channel(64);
        let (status, status_rx) = watch::channel(StatusSnapshot::default());
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
            recorder,
            observer: None,
        };
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

    /// Starts handing what crosses the links, the vehicle's state and the controls coming
    /// back to a watcher (the live view, Foxglove), through the returned [`Observation`]; a
    /// second call replaces the first watcher. The loop never waits for it
    /// ([`observer`]).
    pub fn observe(&mut self) -> Observation {
        let (end, observation) = observer::observer();
        self.observer = Some(end);
        observation
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
            flush_outputs(&mut self.engine, &mut self.lines, self.observer.as_ref());
            let now = Instant::now();
            if let Some(observer) = self.observer.as_mut()
                && now >= observer.next_state
            {
                let state = self.engine.model().state();
                observer.tap.state(StateRow::from_state(&state));
                observer.next_state = now + observer::OBSERVER_PERIOD;
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
            if let Some(observer) = &self.observer {
                wake_at = wake_at.min(observer.next_state.max(now));
            }
            let control = async {
                match self.observer.as_mut() {
                    Some(observer) => observer.controls.recv().await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                inbound = self.inbound.recv() => match inbound {
                    Some(inbound) => {
                        self.advance_to_wall()?;
                        let moves_time = self
                            .lines
                            .get(inbound.line)
                            .is_some_and(|l| l.carries_sensor);
                        let behind = if self.pacing.map.is_none() && moves_time {
                            self.take_earlier_input()?
                        } else {
                            Vec::new()
                        };
                        self.receive_inbound(&inbound)?;
                        for chunk in &behind {
                            self.receive_inbound(chunk)?;
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

    /// Applies a control from the observer at the current simulated time and records it as
    /// an event; `Err` says why it was refused (nothing changed then).
    fn apply_control(&mut self, control: &Control) -> Result<String, String> {
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
                if let Some(observer) = &self.observer {
                    observer.tap.paused(map.is_paused());
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
                if let Some(observer) = &self.observer {
                    observer.tap.current(*north_mps, *east_mps);
                }
                format!("water current {north_mps} m/s north, {east_mps} m/s east")
            }
            Control::Reset => {
                self.engine.reset_pose()?;
                "vehicle back at its start pose, at rest".to_string()
            }
        };
        let t_s = self.engine.now() as f64 * 1e-9;
        if let Some(recorder) = &self.recorder {
            recorder.event(t_s, control.name(), &control.detail());
        }
        tracing::info!(sim_s = t_s, control = control.name(), "{done}");
        Ok(done)
    }

    /// In realtime: settles the overrun accounting for this wake-up and runs the model up to
    /// the wall clock.
    /// Hands one chunk a line brought to the engine (and to the observer's tap), and notes
    /// when the line last brought bytes.
    fn receive_inbound(&mut self, inbound: &Inbound) -> Result<(), DaemonError> {
        if let Some(observer) = &self.observer {
            let name = self.engine.line_name(inbound.line);
            let t_s = self.engine.now() as f64 * 1e-9;
            observer.tap.bytes(
                t_s,
                name,
                crate::record::Direction::Rx,
                inbound.data.clone(),
            );
        }
        self.engine
            .receive(inbound.line, &inbound.data)
            .map_err(model_error)?;
        if let Some(line) = self.lines.get_mut(inbound.line) {
            line.last_rx_wall = Instant::now();
        }
        Ok(())
    }

    /// In lockstep, before a chunk of the sensor link's line is handled: takes first
    /// everything the EyeBot side wrote on the lines that do not carry the sensor link, which
    /// it wrote before that chunk (a lockstep client waits for each reply, so nothing it
    /// writes later can be there yet; the other way round, a sonar chunk is handled as it
    /// comes, and a request written after it on the sensor line is still unread). The chunks the
    /// link tasks already read come from the queue; what is still in a pty is read from it
    /// directly (the loop runs on the link tasks' one thread, so no link task holds bytes it
    /// read and has not queued). Without this, a select written on the sonar line just before
    /// a TIME_STEP was taken at that step or at a later one, as the host scheduled the two
    /// link tasks. Returns the queued chunks of the sensor link's lines, which come after it.
    fn take_earlier_input(&mut self) -> Result<Vec<Inbound>, DaemonError> {
        let mut behind = Vec::new();
        while let Ok(queued) = self.inbound.try_recv() {
            if self.lines.get(queued.line).is_none_or(|l| l.carries_sensor) {
                behind.push(queued);
            } else {
                self.receive_inbound(&queued)?;
            }
        }
        for other in 0..self.lines.len() {
            if self.lines[other].carries_sensor {
                continue;
            }
            loop {
                let line = &mut self.lines[other];
                let Some(peek) = line.peek.as_mut() else {
                    break;
                };
                let data = match peek.read_now() {
                    Ok([]) => break,
                    Ok(read) => bytes::Bytes::copy_from_slice(read),
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    // WouldBlock: nothing more was written. Anything else is the link
                    // task's to see and report.
                    Err(_) => break,
                };
                line.cx
                    .counters
                    .bytes_rx
                    .fetch_add(data.len() as u64, Ordering::Relaxed);
                self.receive_inbound(&Inbound { line: other, data })?;
            }
        }
        Ok(behind)
    }

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
    /// a partial frame on a line that carries the sensor link is dropped once the line has
    /// been silent for its idle limit of wall time (PROTOCOL.md section 3). A sonar-only
    /// line, and every line in realtime, is flushed by the engine in simulated time.
    fn flush_idle_lockstep(&mut self) -> Result<(), DaemonError> {
        if self.pacing.map.is_some() {
            return Ok(());
        }
        for index in 0..self.lines.len() {
            let Some(limit) = self.engine.lockstep_wall_idle_limit(index) else {
                continue;
            };
            if self.engine.holds_partial(index) && self.lines[index].last_rx_wall.elapsed() >= limit
            {
                self.engine.flush_line(index).map_err(model_error)?;
            }
        }
        Ok(())
    }

    /// In lockstep: when the next line with a partial frame reaches its wall-clock idle limit.
    fn next_idle_flush_lockstep(&self) -> Option<Instant> {
        if self.pacing.map.is_some() {
            return None;
        }
        self.lines
            .iter()
            .enumerate()
            .filter(|(index, _)| self.engine.holds_partial(*index))
            .filter_map(|(index, line)| {
                Some(line.last_rx_wall + self.engine.lockstep_wall_idle_limit(index)?)
            })
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
        flush_outputs(&mut self.engine, &mut self.lines, self.observer.as_ref());
        let sim_time_s = self.engine.now() as f64 * 1e-9;
        let overruns = self.pacing.map.as_ref().map_or(0, RealtimeMap::overruns);
        self.stop.send_replace(true);
        let stopping = Instant::now();
        shutdown::Phase::Links.enter();
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
        // The deadline is polled first: a client that keeps writing keeps `inbound` ready,
        // and polled first it starved the deadline until the process-level guard cut the
        // shutdown short.
        loop {
            tokio::select! {
                biased;
                () = tokio::time::sleep_until(tasks_deadline) => {
                    tracing::warn!("a link task did not stop in time; aborting it");
                    for abort in &aborts {
                        abort.abort();
                    }
                    let _ = tokio::time::timeout(Duration::from_millis(20), &mut joined).await;
                    break;
                }
                () = &mut joined => break,
                Some(inbound) = self.inbound.recv() => {
                    self.engine.record_unprocessed(inbound.line, &inbound.data);
                }
            }
        }
        while let Ok(inbound) = self.inbound.try_recv() {
            self.engine.record_unprocessed(inbound.line, &inbound.data);
        }
        shutdown::Phase::Services.enter();
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
        shutdown::Phase::Recording.enter();
        drop(self.engine.take_journal());
        let records = match self.recorder.take() {
            Some(recorder) => Some(recorder.finish()?),
            None => None,
        };
        shutdown::Phase::Cleanup.enter();
        drop(self.pid_file.take());
        self.leftovers.remove_all();
        drop(self.run_dir_lock.take());
        warn_limit::flush();
        shutdown::Phase::Done.enter();
        tracing::debug!(
            ms = stopping.elapsed().as_millis() as u64,
            "links, services and recording stopped"
        );
        Ok(Summary {
            sim_time_s,
            records,
            overruns,
        })
    }
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
/// then [`serve_started`].
pub async fn run<M>(
    config: &DaemonConfig,
    model: M,
    board: crate::devices::sensor_board::SensorBoard,
    mux: crate::devices::multiplexer::Multiplexer,
    options: RunOptions,
    shutdown: watch::Receiver<bool>,
    on_ready: impl FnMut(Readiness),
) -> Result<Summary, DaemonError>
where
    M: Model,
{
    let daemon = Daemon::start(config, model, board, mux, options).await?;
    serve_started(daemon, Vec::new(), shutdown, on_ready).await
}

/// Serves a started daemon until `shutdown` turns true (or its sender is dropped): readiness
/// reported through `on_ready` (each link, then `observers`, what the caller connected to
/// [`Daemon::observe`], then `Ready`), [`Daemon::serve`], [`Daemon::finish`]. The daemon is
/// finished even when serving failed; the serving error is returned first.
pub async fn serve_started<M>(
    mut daemon: Daemon<M>,
    observers: Vec<Readiness>,
    mut shutdown: watch::Receiver<bool>,
    mut on_ready: impl FnMut(Readiness),
) -> Result<Summary, DaemonError>
where
    M: Model,
{
    for link in daemon.links() {
        on_ready(Readiness::Link {
            name: link.name,
            path: link.path.clone(),
        });
    }
    for observer in observers {
        on_ready(observer);
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

#[cfg(test)]
mod tests;
