//! Fixtures that run the bridge daemon for end-to-end tests: as the built `eyebot-hil` binary
//! ([`DaemonProcess`]) and in-process through `eyebot_hil::daemon::run` ([`InProcessDaemon`]).
//!
//! Every fixture gets its own [`TestDir`] (run directory, recordings, configs), waits for
//! readiness by reading the daemon's `ready` line with a timeout (never a fixed sleep), and
//! kills and cleans up in `Drop`. Set `EYEBOT_HIL_KEEP=1` to keep the directories of a failed
//! run, and `EYEBOT_HIL_BIN` to test a binary other than the workspace's own.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use eyebot_hil::config::{DEFAULT_CONFIG, Directory, Document};
use eyebot_hil::daemon::config::DaemonConfig;
use eyebot_hil::daemon::status::StatusSnapshot;
use eyebot_hil::daemon::{Readiness, RunOptions, RunSummary};
use eyebot_hil::record::{ByteChunk, Direction};
use nix::sys::signal::Signal;
use nix::unistd::Pid;

/// How long a daemon may take to print `ready` (a cold start on a loaded 2-core machine).
pub const READY_TIMEOUT: Duration = Duration::from_secs(30);

/// The repository's `configs/` directory.
pub fn configs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("configs")
}

/// The `eyebot-hil` binary under test.
///
/// `CARGO_BIN_EXE_*` only exists for the binary's own package, so this finds the target
/// directory from the test executable's path (`<target>/<profile>/deps/<test>`), which also
/// covers `CARGO_TARGET_DIR`, and runs `cargo build --bin eyebot-hil` for the same profile
/// once per test process, so the binary is never older than the library the test linked.
/// `EYEBOT_HIL_BIN` overrides all of this.
pub fn binary() -> &'static Path {
    static BINARY: OnceLock<PathBuf> = OnceLock::new();
    BINARY.get_or_init(|| {
        if let Some(bin) = std::env::var_os("EYEBOT_HIL_BIN") {
            return PathBuf::from(bin);
        }
        let exe = std::env::current_exe().expect("the test executable's path");
        let deps = exe
            .parent()
            .expect("the test executable lives in <profile>/deps");
        let profile_dir = if deps.file_name().is_some_and(|n| n == "deps") {
            deps.parent().expect("<profile>/deps has a parent")
        } else {
            deps
        };
        let target_dir = profile_dir.parent().expect("<target>/<profile>");
        let profile = match profile_dir.file_name().and_then(|n| n.to_str()) {
            Some("debug") => "dev".to_string(),
            Some(other) => other.to_string(),
            None => panic!("cannot tell the profile from {}", exe.display()),
        };
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let status = Command::new(cargo)
            .current_dir(&workspace)
            .args([
                "build",
                "--quiet",
                "-p",
                "eyebot-hil",
                "--bin",
                "eyebot-hil",
            ])
            .arg("--profile")
            .arg(&profile)
            .arg("--target-dir")
            .arg(target_dir)
            .status()
            .expect("run cargo to build the eyebot-hil binary");
        assert!(status.success(), "cargo build --bin eyebot-hil failed");
        let bin = profile_dir.join("eyebot-hil");
        assert!(bin.is_file(), "{} was not built", bin.display());
        bin
    })
}

/// A unique, private directory for one test, removed in `Drop` (unless `EYEBOT_HIL_KEEP`).
#[derive(Debug)]
pub struct TestDir {
    path: PathBuf,
}

impl TestDir {
    pub fn new(tag: &str) -> Self {
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let path =
            std::env::temp_dir().join(format!("eyebot-hil-pty-{tag}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).expect("create the test directory");
        Self { path }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn join(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }

    /// Writes a daemon configuration: `configs/default.toml` with the model files pointing
    /// back at the repository's `configs/` (so `--config FILE` resolves them) and each
    /// `(line, replacement)` applied to a line that must exist verbatim.
    pub fn write_config(&self, name: &str, edits: &[(&str, &str)]) -> PathBuf {
        let text = config_text(edits);
        let path = self.path.join(name);
        std::fs::write(&path, text).expect("write the test configuration");
        path
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        if std::env::var_os("EYEBOT_HIL_KEEP").is_some() {
            eprintln!("kept {}", self.path.display());
            return;
        }
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

/// `configs/default.toml` with absolute model paths and `edits` applied (see
/// [`TestDir::write_config`]).
pub fn config_text(edits: &[(&str, &str)]) -> String {
    let configs = configs_dir();
    let mut text =
        std::fs::read_to_string(configs.join(DEFAULT_CONFIG)).expect("read configs/default.toml");
    for key in ["vehicle", "world", "sensors"] {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{key} = ")))
            .expect("the default config names its model files")
            .to_string();
        let name = line
            .split('"')
            .nth(1)
            .expect("a quoted model file name")
            .to_string();
        let absolute = format!("{key} = \"{}\"", configs.join(&name).display());
        text = text.replace(&line, &absolute);
    }
    for (from, to) in edits {
        assert!(
            text.lines().any(|l| l == *from),
            "config line `{from}` not found in configs/default.toml"
        );
        text = text.replace(from, to);
    }
    text
}

/// A started daemon's link paths.
#[derive(Debug, Clone, Default)]
pub struct Links {
    /// `(name, path the readiness line gave)`.
    pub lines: Vec<(String, String)>,
}

/// The built binary, running as a child process (`eyebot-hil run`).
#[derive(Debug)]
pub struct DaemonProcess {
    child: Child,
    exit: Option<ExitStatus>,
    pub dir: TestDir,
    pub run_dir: PathBuf,
    pub links: Links,
    /// The readiness lines, as printed.
    pub stdout: Vec<String>,
}

impl DaemonProcess {
    /// Starts `eyebot-hil run --run-dir <dir>/run ARGS` in `dir` and waits for `ready`.
    pub fn start(dir: TestDir, args: &[&str]) -> Self {
        let run_dir = dir.join("run");
        let log = std::fs::File::create(dir.join("daemon.log")).expect("create daemon.log");
        let mut child = Command::new(binary())
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
            .expect("spawn eyebot-hil run");
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
        let mut process = Self {
            child,
            exit: None,
            dir,
            run_dir,
            links: Links::default(),
            stdout: Vec::new(),
        };
        let deadline = Instant::now() + READY_TIMEOUT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match rx.recv_timeout(left) {
                Ok(line) => {
                    process.stdout.push(line.clone());
                    if let Some(rest) = line.strip_prefix("link ") {
                        let (name, path) = rest.split_once(": ").expect("`link NAME: PATH`");
                        process.links.lines.push((name.into(), path.into()));
                    } else if line.starts_with("ready") {
                        return process;
                    }
                }
                Err(_) => panic!(
                    "eyebot-hil run printed no `ready` within {READY_TIMEOUT:?}; stdout {:?}; log:\n{}",
                    process.stdout,
                    process.log()
                ),
            }
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The symlink of link `name` inside the run directory.
    pub fn link(&self, name: &str) -> PathBuf {
        self.run_dir.join(name)
    }

    /// The daemon's stderr so far (tracing output).
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("daemon.log")).unwrap_or_default()
    }

    pub fn signal(&self, signal: Signal) {
        nix::sys::signal::kill(Pid::from_raw(self.pid() as i32), signal).expect("signal daemon");
    }

    /// Waits up to `timeout` for the process to exit.
    pub fn wait(&mut self, timeout: Duration) -> Option<ExitStatus> {
        if self.exit.is_some() {
            return self.exit;
        }
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                self.exit = Some(status);
                return self.exit;
            }
            if Instant::now() >= deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// `eyebot-hil status --json` against this daemon, parsed.
    pub fn status(&self) -> StatusSnapshot {
        let out = self.status_command(&["--json"]);
        serde_json::from_str(&out).unwrap_or_else(|e| panic!("status --json: {e}\n{out}"))
    }

    pub fn status_socket(&self) -> PathBuf {
        self.run_dir.join("status.sock")
    }

    /// Runs `eyebot-hil status --run-dir RUN EXTRA` and returns its stdout.
    pub fn status_command(&self, extra: &[&str]) -> String {
        let out = Command::new(binary())
            .arg("status")
            .arg("--run-dir")
            .arg(&self.run_dir)
            .args(extra)
            .output()
            .expect("run eyebot-hil status");
        assert!(
            out.status.success(),
            "eyebot-hil status failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).expect("status prints UTF-8")
    }

    /// Polls the status until `pred` holds (the snapshot refreshes every 100 ms).
    pub fn wait_status(
        &self,
        timeout: Duration,
        what: &str,
        pred: impl Fn(&StatusSnapshot) -> bool,
    ) -> StatusSnapshot {
        let deadline = Instant::now() + timeout;
        loop {
            let s = self.status();
            if pred(&s) {
                return s;
            }
            assert!(
                Instant::now() < deadline,
                "status never showed {what} within {timeout:?}; last: {s:#?}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Resident set size (kB), from `/proc/PID/status`.
    pub fn rss_kb(&self) -> u64 {
        rss_kb(self.pid())
    }

    /// User + system CPU time consumed so far, from `/proc/PID/stat`.
    pub fn cpu_time(&self) -> Duration {
        cpu_time(self.pid())
    }
}

impl Drop for DaemonProcess {
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

/// `eyebot-hil status --socket SOCKET --json`, parsed: works for in-process daemons too.
pub fn status_at(socket: &Path) -> StatusSnapshot {
    let out = Command::new(binary())
        .arg("status")
        .arg("--socket")
        .arg(socket)
        .arg("--json")
        .output()
        .expect("run eyebot-hil status");
    assert!(
        out.status.success(),
        "eyebot-hil status --socket {} failed: {}",
        socket.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("status --json parses")
}

/// `VmRSS` of process `pid` in kB.
pub fn rss_kb(pid: u32) -> u64 {
    let text =
        std::fs::read_to_string(format!("/proc/{pid}/status")).expect("read /proc/PID/status");
    text.lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmRSS in /proc/PID/status")
}

/// utime + stime of process `pid` (all its threads).
pub fn cpu_time(pid: u32) -> Duration {
    let text = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("read /proc/PID/stat");
    // Fields after the command name (which may contain spaces) start at state = field 3.
    let after = &text[text.rfind(')').expect("comm in parentheses") + 2..];
    let fields: Vec<&str> = after.split_whitespace().collect();
    let ticks: u64 =
        fields[11].parse::<u64>().expect("utime") + fields[12].parse::<u64>().expect("stime");
    let per_s = clock_ticks_per_s();
    Duration::from_nanos(ticks * 1_000_000_000 / per_s)
}

/// `sysconf(_SC_CLK_TCK)`: the unit of `/proc/PID/stat` times.
pub fn clock_ticks_per_s() -> u64 {
    // SAFETY: sysconf has no preconditions.
    let ticks = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if ticks > 0 { ticks as u64 } else { 100 }
}

/// The daemon run in-process through `eyebot_hil::daemon::run`, on its own thread and tokio
/// runtime, stopped through its shutdown watch channel.
pub struct InProcessDaemon {
    stop: tokio::sync::watch::Sender<bool>,
    thread: Option<std::thread::JoinHandle<Result<RunSummary, String>>>,
    pub dir: TestDir,
    pub run_dir: PathBuf,
    pub status_socket: PathBuf,
}

impl InProcessDaemon {
    /// Runs with the configuration text `config_text` (model files resolved from
    /// `configs/`, see [`config_text`]), adjusted by `adjust`.
    pub fn start(
        dir: TestDir,
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
        let (stop, stop_rx) = tokio::sync::watch::channel(false);
        let (ready_tx, ready_rx) = mpsc::channel();
        let thread = std::thread::spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .map_err(|e| e.to_string())?;
            runtime
                .block_on(eyebot_hil::daemon::run(
                    &config,
                    model,
                    board,
                    mux,
                    options,
                    stop_rx,
                    move |r| {
                        let _ = ready_tx.send(r);
                    },
                ))
                .map_err(|e| e.to_string())
        });
        let deadline = Instant::now() + READY_TIMEOUT;
        let status_socket = loop {
            match ready_rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(Readiness::Ready { status_socket }) => break status_socket,
                Ok(Readiness::Link { .. }) => {}
                Err(_) => {
                    let outcome = thread.join();
                    panic!("in-process daemon never became ready: {outcome:?}");
                }
            }
        };
        Self {
            stop,
            thread: Some(thread),
            dir,
            run_dir,
            status_socket,
        }
    }

    pub fn link(&self, name: &str) -> PathBuf {
        self.run_dir.join(name)
    }

    /// Stops the daemon and returns its summary (the test directory stays until `Drop`).
    pub fn stop(&mut self) -> RunSummary {
        self.stop_inner().expect("daemon was running")
    }

    fn stop_inner(&mut self) -> Option<RunSummary> {
        let thread = self.thread.take()?;
        let _ = self.stop.send(true);
        Some(
            thread
                .join()
                .expect("daemon thread panicked")
                .expect("daemon run failed"),
        )
    }
}

impl Drop for InProcessDaemon {
    fn drop(&mut self) {
        if let Some(thread) = self.thread.take() {
            let _ = self.stop.send(true);
            let _ = thread.join();
        }
    }
}

/// Reads `bytes.tsv` of a recording.
pub fn read_chunks(record_dir: &Path) -> Vec<ByteChunk> {
    let text = std::fs::read_to_string(record_dir.join("bytes.tsv")).expect("read bytes.tsv");
    let mut lines = text.lines().enumerate();
    let (_, header) = lines.next().expect("bytes.tsv has a header");
    assert_eq!(header, eyebot_hil::record::BYTES_HEADER);
    lines
        .map(|(i, l)| eyebot_hil::record::parse_chunk(l, i + 1).expect("a valid bytes.tsv line"))
        .collect()
}

/// Reads `drops.tsv` of a recording: (link, reason, bytes) per row.
pub fn read_drops(record_dir: &Path) -> Vec<(String, String, Vec<u8>)> {
    let text = std::fs::read_to_string(record_dir.join("drops.tsv")).expect("read drops.tsv");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(eyebot_hil::record::DROPS_HEADER));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            assert_eq!(f.len(), 5, "drops.tsv row {l:?}");
            (
                f[2].to_string(),
                f[3].to_string(),
                hex::decode(f[4]).expect("drops.tsv hex"),
            )
        })
        .collect()
}

/// Every byte recorded on `link` in direction `dir`, concatenated in order.
pub fn stream(chunks: &[ByteChunk], link: &str, dir: Direction) -> Vec<u8> {
    chunks
        .iter()
        .filter(|c| c.link == link && c.dir == dir)
        .flat_map(|c| c.data.iter().copied())
        .collect()
}

/// A transcript without wall times, with adjacent chunks of the same simulated time, link
/// and direction merged (how the OS splits or joins reads is not part of the behaviour).
pub fn transcript(chunks: &[ByteChunk]) -> Vec<(String, String, &'static str, String)> {
    let mut out: Vec<(String, String, &'static str, String)> = Vec::new();
    for c in chunks {
        let sim = format!("{:.9}", c.sim_s);
        let hex = hex::encode(&c.data);
        match out.last_mut() {
            Some(last) if last.0 == sim && last.1 == c.link && last.2 == c.dir.as_str() => {
                last.3.push_str(&hex)
            }
            _ => out.push((sim, c.link.clone(), c.dir.as_str(), hex)),
        }
    }
    out
}

/// Opens a pty/serial device with `line` as the EyeBot side does (termios applied).
/// Must be called inside a tokio runtime.
pub fn open_line(path: &Path, line: &str) -> tokio_serial::SerialStream {
    let settings: eyebot_hil::transport::LineSettings = line.parse().expect("line settings");
    eyebot_hil::transport::serial::open(path, &settings)
        .unwrap_or_else(|e| panic!("open {}: {e}", path.display()))
}

/// A sensor-link client with one attempt and a long timeout: in lockstep a retry would
/// change the transcript, and a loaded machine may be slow.
pub fn sensor_client(path: &Path) -> eyebot_hil::probe::SensorClient {
    let mut client =
        eyebot_hil::probe::SensorClient::open(path, &"115200 8N1".parse().expect("line"))
            .expect("open the sensor link");
    client.set_policy(eyebot_hil::probe::RetryPolicy {
        timeout: Duration::from_secs(10),
        retries: 0,
    });
    client
}

/// Sends HELLO on the sensor link at `path` and checks the reply; `context` says what the
/// answer shows (in the panic message).
pub async fn expect_hello(path: &Path, context: &str) {
    let mut client = sensor_client(path);
    let reply = client
        .request(
            "hello",
            firmware_protocol::sensor_link::Message::Hello { client_version: 1 },
            Duration::ZERO,
        )
        .await
        .unwrap_or_else(|e| panic!("{context}: {e}"));
    assert!(
        matches!(
            reply,
            firmware_protocol::sensor_link::Message::HelloReply { .. }
        ),
        "{context}: {reply:?}"
    );
}

/// Opens a link as a raw file (blocking), as a plain C program would.
pub fn open_raw(path: &Path) -> std::fs::File {
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .unwrap_or_else(|e| panic!("open {}: {e}", path.display()))
}

/// A sonar-link client at 4800 8N1.
pub fn sonar_client(path: &Path) -> eyebot_hil::probe::SonarClient {
    eyebot_hil::probe::SonarClient::open(path, &"4800 8N1".parse().expect("line"))
        .expect("open the sonar link")
}

/// Which tool a test needs; panics naming it when it is not installed.
pub fn require_tool(name: &str, why: &str) -> PathBuf {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|p| p.is_file())
        .unwrap_or_else(|| {
            panic!("`{name}` is not installed (needed for {why}); run .ci/install-deps or apt-get install {name}")
        })
}

/// Polls `f` until it returns `Some`, or panics after `timeout` naming `what`.
pub fn poll_until<T>(timeout: Duration, what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(
            Instant::now() < deadline,
            "timed out after {timeout:?} waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The link path a status snapshot lists for `name`, with its counters.
pub fn link_status<'a>(
    s: &'a StatusSnapshot,
    name: &str,
) -> &'a eyebot_hil::daemon::status::LinkStatus {
    s.links
        .iter()
        .find(|l| l.name == name)
        .unwrap_or_else(|| panic!("no link `{name}` in status: {s:#?}"))
}
