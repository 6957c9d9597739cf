//! The daemon under test: the built binary as a child process ([`Daemon`]) or the library's
//! daemon on a thread of the test ([`InProcessDaemon`]).
//!
//! The binary's path is always given by the test: `env!("CARGO_BIN_EXE_eyebot-hil")`, which
//! cargo sets for the root package's integration tests and builds for the same profile first,
//! so a test never runs a stale or guessed binary. Both handles own a [`TempDir`] (run
//! directory, recordings, configurations), wait for readiness with a timeout (never a fixed
//! sleep), and stop and clean up in `Drop`. Both answer [`RunningDaemon`], so one script runs
//! against either.

use std::ffi::OsStr;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use eyebot_hil::config::{Directory, Document};
use eyebot_hil::daemon::config::DaemonConfig;
use eyebot_hil::daemon::status::{LinkStatus, StatusSnapshot};
use eyebot_hil::daemon::{Daemon as Bridge, RunOptions, Summary};
use nix::sys::signal::Signal;
use nix::unistd::Pid;

use crate::dir::TempDir;
use crate::wait::wait_for;

/// How long a daemon may take to come up (a cold start on a loaded 2-core machine).
pub const READY_TIMEOUT: Duration = Duration::from_secs(30);

/// How long a daemon may take to exit after SIGTERM or SIGINT (its bound is 1 s).
pub const EXIT_TIMEOUT: Duration = Duration::from_secs(5);

/// What a test asks of a running daemon, whichever way it runs.
pub trait RunningDaemon {
    /// The run directory, where the link symlinks and the status socket live.
    fn run_dir(&self) -> &Path;

    /// The symlink of link `name` (`sonar`, `sensor`).
    fn link(&self, name: &str) -> PathBuf {
        self.run_dir().join(name)
    }

    fn status_socket(&self) -> PathBuf {
        self.run_dir().join("status.sock")
    }

    /// A status snapshot, read from the status socket (refreshed every 100 ms).
    fn status(&self) -> StatusSnapshot {
        status_at(&self.status_socket())
    }

    /// Polls the status until `pred` holds, or panics after `timeout` naming `what`.
    fn wait_status(
        &self,
        timeout: Duration,
        what: &str,
        pred: impl Fn(&StatusSnapshot) -> bool,
    ) -> StatusSnapshot
    where
        Self: Sized,
    {
        wait_for(what, timeout, || {
            let s = self.status();
            pred(&s).then_some(s)
        })
    }
}

/// The status snapshot served at `socket`, read through the library's client on a thread of
/// its own (so it can be called from inside an async test).
pub fn status_at(socket: &Path) -> StatusSnapshot {
    let path = socket.to_path_buf();
    let result = std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("a runtime for the status query");
        runtime.block_on(eyebot_hil::daemon::status::query(
            &path,
            Duration::from_secs(5),
        ))
    })
    .join()
    .expect("the status query thread");
    result.unwrap_or_else(|e| panic!("status at {}: {e}", socket.display()))
}

/// The counters of link `name` in a status snapshot.
pub fn link_status<'a>(s: &'a StatusSnapshot, name: &str) -> &'a LinkStatus {
    s.links
        .iter()
        .find(|l| l.name == name)
        .unwrap_or_else(|| panic!("no link `{name}` in status: {s:#?}"))
}

/// How to start the binary: `eyebot-hil run` arguments gathered on a fresh [`TempDir`].
#[derive(Debug)]
pub struct DaemonOptions {
    bin: String,
    dir: TempDir,
    args: Vec<String>,
    record: Option<PathBuf>,
}

impl DaemonOptions {
    /// The directory the daemon will run in, to prepare files before [`start`](Self::start).
    pub fn dir(&self) -> &TempDir {
        &self.dir
    }

    /// `--config FILE`: `configs/default.toml` with `edits` (see
    /// [`crate::config::config_text`]), written into the directory.
    pub fn config(mut self, edits: &[(&str, &str)]) -> Self {
        let config = self.dir.write_config("config.toml", edits);
        self.args
            .extend(["--config".into(), config.display().to_string()]);
        self
    }

    /// `--time-mode lockstep`.
    pub fn lockstep(self) -> Self {
        self.args(&["--time-mode", "lockstep"])
    }

    /// `--time-mode realtime`.
    pub fn realtime(self) -> Self {
        self.args(&["--time-mode", "realtime"])
    }

    /// `--record DIR/rec`; [`Daemon::record_dir`] gives the path.
    pub fn record(mut self) -> Self {
        let record = self.dir.join("rec");
        self.args
            .extend(["--record".into(), record.display().to_string()]);
        self.record = Some(record);
        self
    }

    /// The recording directory [`record`](Self::record) asked for.
    pub fn record_dir(&self) -> &Path {
        self.record
            .as_deref()
            .expect("DaemonOptions::record was called")
    }

    /// More arguments, as given.
    pub fn args(mut self, args: &[&str]) -> Self {
        self.args.extend(args.iter().map(|a| a.to_string()));
        self
    }

    /// Starts the daemon and waits for its `ready` line.
    pub fn start(self) -> Daemon {
        let args: Vec<&str> = self.args.iter().map(String::as_str).collect();
        let mut daemon = Daemon::start(&self.bin, self.dir, &args);
        daemon.record = self.record;
        daemon
    }
}

/// The built binary, running as a child process (`eyebot-hil run`).
#[derive(Debug)]
pub struct Daemon {
    bin: PathBuf,
    child: Child,
    exit: Option<ExitStatus>,
    record: Option<PathBuf>,
    pub dir: TempDir,
    pub run_dir: PathBuf,
    /// `(name, path)` of each `link NAME: PATH` line of the announcement.
    pub links: Vec<(String, String)>,
    /// The URL of the `view: URL` line (`run --view`).
    pub view_url: Option<String>,
    /// The address of the `foxglove: URL` line (`run --foxglove`).
    pub foxglove_url: Option<String>,
}

impl Daemon {
    /// Options for `BIN run` in a fresh [`TempDir`] named after `tag`.
    pub fn options(bin: &str, tag: &str) -> DaemonOptions {
        DaemonOptions {
            bin: bin.to_string(),
            dir: TempDir::new(tag),
            args: Vec::new(),
            record: None,
        }
    }

    /// The recording directory of a daemon started with [`DaemonOptions::record`].
    pub fn record_dir(&self) -> &Path {
        self.record
            .as_deref()
            .expect("the daemon was started with DaemonOptions::record")
    }

    /// Starts `BIN run --run-dir DIR/run ARGS` in `dir` (stderr to `DIR/daemon.log`) and
    /// waits for its `ready` line.
    pub fn start(bin: &str, dir: TempDir, args: &[&str]) -> Self {
        let bin = PathBuf::from(bin);
        let run_dir = dir.join("run");
        let log = std::fs::File::create(dir.join("daemon.log")).expect("create daemon.log");
        let mut child = Command::new(&bin)
            .current_dir(dir.path())
            .arg("run")
            .arg("--run-dir")
            .arg(&run_dir)
            .args(args)
            .env(
                "EYEBOT_HIL_LOG",
                std::env::var("EYEBOT_HIL_LOG").unwrap_or_else(|_| "info".into()),
            )
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .unwrap_or_else(|e| panic!("spawn {} run: {e}", bin.display()));
        let stdout = child.stdout.take().expect("piped stdout");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut daemon = Self {
            bin,
            child,
            exit: None,
            record: None,
            dir,
            run_dir,
            links: Vec::new(),
            view_url: None,
            foxglove_url: None,
        };
        let deadline = Instant::now() + READY_TIMEOUT;
        loop {
            match rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(line) => {
                    if let Some(rest) = line.strip_prefix("link ") {
                        let (name, path) = rest.split_once(": ").expect("`link NAME: PATH`");
                        daemon.links.push((name.into(), path.into()));
                    } else if let Some(url) = line.strip_prefix("view: ") {
                        daemon.view_url = Some(url.to_string());
                    } else if let Some(url) = line.strip_prefix("foxglove: ") {
                        daemon.foxglove_url = Some(url.to_string());
                    } else if line.starts_with("ready") {
                        return daemon;
                    }
                }
                Err(_) => panic!(
                    "eyebot-hil run announced no `ready` within {READY_TIMEOUT:?} (links {:?}); \
                     exit {:?}; log:\n{}",
                    daemon.links,
                    daemon.child.try_wait(),
                    daemon.log()
                ),
            }
        }
    }

    /// The symlink of link `name` (as [`RunningDaemon::link`], without the trait in scope).
    pub fn link(&self, name: &str) -> PathBuf {
        RunningDaemon::link(self, name)
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The daemon's stderr so far (its tracing output).
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("daemon.log")).unwrap_or_default()
    }

    pub fn signal(&self, signal: Signal) {
        nix::sys::signal::kill(Pid::from_raw(self.pid() as i32), signal).expect("signal daemon");
    }

    /// Waits up to `timeout` for the process to exit; `None` if it is still running.
    pub fn wait(&mut self, timeout: Duration) -> Option<ExitStatus> {
        if self.exit.is_none() {
            let deadline = Instant::now() + timeout;
            loop {
                if let Some(status) = self.child.try_wait().expect("try_wait") {
                    self.exit = Some(status);
                    break;
                }
                if Instant::now() >= deadline {
                    break;
                }
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        self.exit
    }

    /// Sends `signal` (SIGTERM or SIGINT) and checks the daemon exits with status 0 within
    /// [`EXIT_TIMEOUT`]: the recording is then complete.
    pub fn stop_with(&mut self, signal: Signal) {
        self.signal(signal);
        let exit = self.wait(EXIT_TIMEOUT).unwrap_or_else(|| {
            panic!("the daemon did not exit within {EXIT_TIMEOUT:?} of {signal}")
        });
        assert!(exit.success(), "{signal}: exit {exit:?}\n{}", self.log());
    }

    /// [`stop_with`](Self::stop_with) SIGTERM.
    pub fn stop(&mut self) {
        self.stop_with(Signal::SIGTERM);
    }

    /// Runs `BIN SUBCOMMAND ARGS` (another subcommand of the same binary, such as `status` or
    /// `probe`), checks it succeeds, and returns its stdout.
    pub fn cli(&self, args: &[&OsStr]) -> String {
        let out = Command::new(&self.bin)
            .args(args)
            .output()
            .unwrap_or_else(|e| panic!("run {} {args:?}: {e}", self.bin.display()));
        assert!(
            out.status.success(),
            "eyebot-hil {args:?} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).expect("the CLI prints UTF-8")
    }

    /// `eyebot-hil status --run-dir RUN EXTRA`: its stdout.
    pub fn status_command(&self, extra: &[&str]) -> String {
        let mut args: Vec<&OsStr> = vec![
            OsStr::new("status"),
            OsStr::new("--run-dir"),
            self.run_dir.as_os_str(),
        ];
        args.extend(extra.iter().map(OsStr::new));
        self.cli(&args)
    }

    /// Resident set size (kB), from `/proc/PID/status`.
    pub fn rss_kb(&self) -> u64 {
        crate::process::rss_kb(self.pid())
    }

    /// User + system CPU time consumed so far, from `/proc/PID/stat`.
    pub fn cpu_time(&self) -> Duration {
        crate::process::cpu_time(self.pid())
    }
}

impl RunningDaemon for Daemon {
    fn run_dir(&self) -> &Path {
        &self.run_dir
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if self.exit.is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
        if std::thread::panicking() {
            eprintln!(
                "daemon log ({}):\n{}",
                self.dir.path().display(),
                self.log()
            );
        }
    }
}

/// The daemon run in-process on its own thread and tokio runtime, through the library's
/// [`Bridge::start`], [`Bridge::serve`] (until [`stop`](InProcessDaemon::stop) or `Drop`)
/// and [`Bridge::finish`].
pub struct InProcessDaemon {
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<Result<Summary, String>>>,
    pub dir: TempDir,
    pub run_dir: PathBuf,
    pub status_socket: PathBuf,
}

impl InProcessDaemon {
    /// Runs with the configuration text `config_text` (see [`crate::config::config_text`]),
    /// adjusted by `adjust`, recording into `record` if given.
    pub fn start(
        dir: TempDir,
        config_text: &str,
        record: Option<PathBuf>,
        adjust: impl FnOnce(&mut DaemonConfig),
    ) -> Self {
        let run_dir = dir.join("run");
        let source = Directory::new(dir.path().to_path_buf());
        let mut config = DaemonConfig::resolve(&Document::new("test config", config_text))
            .expect("test config resolves");
        config.run_dir = run_dir.clone();
        adjust(&mut config);
        let model = eyebot_hil::daemon::plant::MakoPlant::from_config(&source, &config)
            .expect("the model loads");
        let (board, mux) = eyebot_hil::daemon::plant::devices(&config);
        let options = RunOptions {
            record,
            pid_file: None,
            config_toml: config_text.to_string(),
            config_name: "test config".into(),
            ..RunOptions::default()
        };
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let (ready_tx, ready_rx) = mpsc::channel();
        let thread = std::thread::spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .map_err(|e| e.to_string())?;
            runtime.block_on(async move {
                let mut bridge = Bridge::start(&config, model, board, mux, options)
                    .await
                    .map_err(|e| e.to_string())?;
                let _ = ready_tx.send(bridge.status_socket().to_path_buf());
                // A dropped sender stops the daemon too.
                let served = bridge
                    .serve(async move {
                        let _ = stopped.await;
                    })
                    .await;
                let summary = bridge.finish().await.map_err(|e| e.to_string());
                served.map_err(|e| e.to_string())?;
                summary
            })
        });
        let status_socket = match ready_rx.recv_timeout(READY_TIMEOUT) {
            Ok(socket) => socket,
            Err(_) => {
                let outcome = thread.join();
                panic!("in-process daemon never became ready: {outcome:?}");
            }
        };
        Self {
            stop: Some(stop),
            thread: Some(thread),
            dir,
            run_dir,
            status_socket,
        }
    }

    /// The symlink of link `name` (as [`RunningDaemon::link`], without the trait in scope).
    pub fn link(&self, name: &str) -> PathBuf {
        RunningDaemon::link(self, name)
    }

    /// Stops the daemon and returns its summary (the directory stays until `Drop`).
    pub fn stop(&mut self) -> Summary {
        let thread = self.thread.take().expect("the daemon is running");
        drop(self.stop.take());
        thread
            .join()
            .expect("daemon thread panicked")
            .expect("daemon run failed")
    }
}

impl RunningDaemon for InProcessDaemon {
    fn run_dir(&self) -> &Path {
        &self.run_dir
    }

    fn status_socket(&self) -> PathBuf {
        self.status_socket.clone()
    }
}

impl Drop for InProcessDaemon {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
