//! Helpers for the EyeBot C library tests: build `firmware-protocol/c` with make (host or
//! m68k), start the bridge daemon in lockstep with a recording, run a C program against it,
//! and read the recording back (`docs/recording.md`).
//!
//! Everything is built under the workspace's `target/eyebot-c/`, never in the source tree.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Which compiler builds the C.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// The host's `cc`.
    Host,
    /// `m68k-linux-gnu-gcc -mcpu=68020 -static`, run under `qemu-m68k`.
    M68k,
}

/// The workspace root (the parent of this crate).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("pty-tests sits inside the workspace")
        .to_path_buf()
}

/// The C library's source directory.
pub fn c_source_dir() -> PathBuf {
    workspace_root().join("firmware-protocol").join("c")
}

/// The cargo target directory this test binary was built into (`.../target`).
pub fn target_dir() -> PathBuf {
    if let Ok(dir) = std::env::var("CARGO_TARGET_DIR") {
        return PathBuf::from(dir);
    }
    // current_exe = target/<profile>/deps/<test>-<hash>
    let exe = std::env::current_exe().expect("current_exe");
    exe.parent()
        .and_then(Path::parent)
        .and_then(Path::parent)
        .map(Path::to_path_buf)
        .unwrap_or_else(|| workspace_root().join("target"))
}

/// `tool --version` runs.
pub fn have_tool(tool: &str) -> bool {
    Command::new(tool)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// For tests that need the m68k tool chain: `true` when both tools are there. Without them,
/// prints a notice naming the missing tool and returns `false` (skip) on a developer machine,
/// or panics when the environment variable `CI` is set (CI installs them: `.ci/install-deps`).
pub fn m68k_tools_or_skip(test: &str) -> bool {
    let missing: Vec<&str> = ["m68k-linux-gnu-gcc", "qemu-m68k"]
        .into_iter()
        .filter(|t| !have_tool(t))
        .collect();
    if missing.is_empty() {
        return true;
    }
    let notice = format!(
        "{test}: SKIPPED: {} not installed (Debian: gcc-m68k-linux-gnu libc6-dev-m68k-cross \
         qemu-user; `bash .ci/install-deps` installs them)",
        missing.join(" and ")
    );
    if std::env::var_os("CI").is_some() {
        panic!("{notice}; CI must run this test");
    }
    eprintln!("{notice}");
    false
}

/// Builds libeyebot and the examples (plus `extra` programs) for `target` into
/// `target/eyebot-c/<name>-<target>/`; returns that directory. `name` keeps test binaries
/// that run at the same time out of each other's build directories.
pub fn build(name: &str, target: Target, extra: &[&Path]) -> PathBuf {
    build_with(name, target, extra, &[])
}

/// [`build`] with more `make` arguments (`VAR=value`), given after the target's own: for
/// example `BACKEND=robios` with its `CFLAGS` and `LDLIBS`.
pub fn build_with(name: &str, target: Target, extra: &[&Path], make_args: &[String]) -> PathBuf {
    let out = target_dir().join("eyebot-c").join(format!(
        "{name}-{}",
        match target {
            Target::Host => "host",
            Target::M68k => "m68k",
        }
    ));
    std::fs::create_dir_all(&out).expect("create the build directory");
    let mut make = Command::new("make");
    make.arg("-C")
        .arg(c_source_dir())
        .arg(format!("OUT={}", out.display()));
    match target {
        Target::Host => {
            make.arg("CC=cc").arg("CFLAGS=-O2");
        }
        Target::M68k => {
            make.arg("CC=m68k-linux-gnu-gcc")
                .arg("CFLAGS=-O2 -mcpu=68020")
                .arg("LDFLAGS=-static");
        }
    }
    if !extra.is_empty() {
        let progs: Vec<String> = extra.iter().map(|p| p.display().to_string()).collect();
        make.arg(format!("PROG={}", progs.join(" ")));
    }
    make.args(make_args);
    let output = make.output().expect("run make (is it installed?)");
    assert!(
        output.status.success(),
        "make failed for {target:?}:\n{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    out
}

/// The `eyebot-hil` binary of this build. `cargo test --workspace` builds it (the root
/// package's integration tests need it); with `cargo test -p pty-tests` alone it may be
/// missing, and then this builds it with the same cargo.
pub fn daemon_binary() -> PathBuf {
    let profile_dir = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().and_then(Path::parent).map(Path::to_path_buf))
        .expect("test binary directory");
    let bin = profile_dir.join(format!("eyebot-hil{}", std::env::consts::EXE_SUFFIX));
    if !bin.exists() {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let status = Command::new(cargo)
            .args(["build", "-p", "eyebot-hil", "--bin", "eyebot-hil"])
            .current_dir(workspace_root())
            .status()
            .expect("run cargo build for eyebot-hil");
        assert!(status.success(), "cargo build of eyebot-hil failed");
    }
    assert!(
        bin.exists(),
        "eyebot-hil binary not found at {}",
        bin.display()
    );
    bin
}

/// A fresh scratch directory under `target/eyebot-c/runs/`, removed on drop.
pub struct Scratch(pub PathBuf);

impl Scratch {
    pub fn new(name: &str) -> Self {
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        let dir = target_dir().join("eyebot-c").join("runs").join(format!(
            "{name}-{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create scratch directory");
        Self(dir)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if std::env::var_os("EYEBOT_C_KEEP").is_none() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Writes a daemon configuration into `dir` with the vehicle starting at `position_m`,
/// heading `heading_deg`, next to copies of the model files it names (a config's model files
/// are read from its own directory). Returns the config file.
pub fn config_with_start(dir: &Path, position_m: [f64; 3], heading_deg: f64) -> PathBuf {
    let configs = workspace_root().join("configs");
    for sub in ["vehicles", "worlds", "sensors"] {
        let to = dir.join(sub);
        std::fs::create_dir_all(&to).expect("create config dir");
        for entry in std::fs::read_dir(configs.join(sub)).expect("read configs") {
            let entry = entry.expect("dir entry");
            std::fs::copy(entry.path(), to.join(entry.file_name())).expect("copy config");
        }
    }
    let text = std::fs::read_to_string(configs.join("default.toml")).expect("default.toml");
    let mut out = String::new();
    let mut in_start = false;
    for line in text.lines() {
        if line.starts_with('[') {
            in_start = line.trim() == "[start]";
        }
        if in_start && line.starts_with("position_m") {
            out.push_str(&format!(
                "position_m = [{}, {}, {}]\n",
                position_m[0], position_m[1], position_m[2]
            ));
        } else if in_start && line.starts_with("heading_deg") {
            out.push_str(&format!("heading_deg = {heading_deg}\n"));
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    let path = dir.join("test.toml");
    std::fs::write(&path, out).expect("write test config");
    path
}

/// A running daemon (lockstep, recording); SIGINT and wait on drop.
pub struct Daemon {
    child: Child,
    pub run_dir: PathBuf,
    pub record_dir: PathBuf,
}

impl Daemon {
    /// Starts `eyebot-hil run --time-mode lockstep` in `dir` and waits until it prints
    /// `ready`.
    pub fn start(dir: &Path, config: Option<&Path>, seed: u64) -> Self {
        let run_dir = dir.join("run");
        let record_dir = dir.join("rec");
        let mut cmd = Command::new(daemon_binary());
        cmd.arg("run")
            .arg("--time-mode")
            .arg("lockstep")
            .arg("--seed")
            .arg(seed.to_string())
            .arg("--record")
            .arg(&record_dir)
            .arg("--run-dir")
            .arg(&run_dir);
        if let Some(config) = config {
            cmd.arg("--config").arg(config);
        }
        let mut child = cmd
            .current_dir(dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start eyebot-hil");
        let stdout = child.stdout.take().expect("stdout");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                let ready = line.starts_with("ready");
                if tx.send(line).is_err() || ready {
                    break;
                }
            }
        });
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut daemon = Self {
            child,
            run_dir,
            record_dir,
        };
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match rx.recv_timeout(left) {
                Ok(line) if line.starts_with("ready") => return daemon,
                Ok(_) => {}
                Err(_) => {
                    let status = daemon.child.try_wait();
                    panic!("eyebot-hil did not become ready (status {status:?})");
                }
            }
        }
    }

    /// Stops the daemon (SIGINT: the recording is flushed) and returns the recording.
    pub fn stop(mut self) -> Recording {
        self.shutdown();
        Recording::read(&self.record_dir)
    }

    fn shutdown(&mut self) {
        if let Ok(Some(_)) = self.child.try_wait() {
            return;
        }
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT);
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// What a program printed and how it ended.
#[derive(Debug)]
pub struct ProgramRun {
    pub status: std::process::ExitStatus,
    pub stdout: String,
    pub stderr: String,
}

/// Runs `program` (under qemu-m68k for [`Target::M68k`]) against the daemon's links in
/// lockstep, with `env` added; panics when it runs longer than `timeout`.
pub fn run_program(
    daemon: &Daemon,
    target: Target,
    program: &Path,
    env: &[(&str, &str)],
    timeout: Duration,
) -> ProgramRun {
    let mut cmd = match target {
        Target::Host => Command::new(program),
        Target::M68k => {
            let mut c = Command::new("qemu-m68k");
            c.arg(program);
            c
        }
    };
    cmd.env("EYEBOT_RUN_DIR", &daemon.run_dir)
        .env("EYEBOT_TIME_MODE", "lockstep")
        // generous: a retry would change the transcript (2 cores shared by many builds)
        .env("EYEBOT_TIMEOUT_MS", "3000")
        .env_remove("EYEBOT_LCD")
        .env_remove("EYEBOT_KEYS")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let child = cmd.spawn().expect("start the C program");
    let (tx, rx) = mpsc::channel();
    let pid = child.id();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    match rx.recv_timeout(timeout) {
        Ok(Ok(out)) => ProgramRun {
            status: out.status,
            stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        },
        Ok(Err(e)) => panic!("waiting for {}: {e}", program.display()),
        Err(_) => {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(pid as i32),
                nix::sys::signal::Signal::SIGKILL,
            );
            panic!("{} ran longer than {timeout:?}", program.display());
        }
    }
}

/// One row of `state.csv`.
#[derive(Debug, Clone, Copy)]
pub struct StateRow {
    pub t_s: f64,
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: f64,
    pub roll_rad: f64,
    pub pitch_rad: f64,
    pub yaw_rad: f64,
    pub contact: bool,
}

/// One chunk of `bytes.tsv`, without the wall-clock column.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Chunk {
    pub sim_s: String,
    pub link: String,
    pub dir: String,
    pub hex: String,
}

/// A recording read back.
#[derive(Debug)]
pub struct Recording {
    pub states: Vec<StateRow>,
    pub chunks: Vec<Chunk>,
}

impl Recording {
    pub fn read(dir: &Path) -> Self {
        let state = std::fs::read_to_string(dir.join("state.csv")).expect("state.csv");
        let mut lines = state.lines();
        let header: Vec<&str> = lines.next().expect("state.csv header").split(',').collect();
        let col: HashMap<&str, usize> = header.iter().enumerate().map(|(i, h)| (*h, i)).collect();
        let get = |f: &[&str], name: &str| -> f64 {
            f[col[name]]
                .parse()
                .unwrap_or_else(|_| panic!("state.csv {name}"))
        };
        let states = lines
            .filter(|l| !l.is_empty())
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                StateRow {
                    t_s: get(&f, "t_s"),
                    x_m: get(&f, "x_m"),
                    y_m: get(&f, "y_m"),
                    z_m: get(&f, "z_m"),
                    roll_rad: get(&f, "roll_rad"),
                    pitch_rad: get(&f, "pitch_rad"),
                    yaw_rad: get(&f, "yaw_rad"),
                    contact: get(&f, "contact") != 0.0,
                }
            })
            .collect();
        let bytes = std::fs::read_to_string(dir.join("bytes.tsv")).expect("bytes.tsv");
        let chunks = bytes
            .lines()
            .skip(1)
            .filter(|l| !l.is_empty())
            .map(|l| {
                let f: Vec<&str> = l.split('\t').collect();
                assert_eq!(f.len(), 5, "bytes.tsv row {l:?}");
                Chunk {
                    sim_s: f[0].into(),
                    link: f[2].into(),
                    dir: f[3].into(),
                    hex: f[4].into(),
                }
            })
            .collect();
        Self { states, chunks }
    }

    /// The transcript (sim_s, link, dir, hex), link by link (sonar first, then sensor), with
    /// adjacent chunks of the same time and direction joined. Two things are not part of the
    /// protocol and are normalised away: how the OS splits a write into reads (a select
    /// written byte by byte may be read as one chunk or four), and the order in which the
    /// bridge reads two different lines at the same simulated instant.
    pub fn transcript(&self) -> Vec<Chunk> {
        let mut out: Vec<Chunk> = Vec::new();
        let mut links: Vec<&str> = self.chunks.iter().map(|c| c.link.as_str()).collect();
        links.sort_unstable();
        links.dedup();
        let ordered = links
            .iter()
            .flat_map(|l| self.chunks.iter().filter(move |c| c.link == *l));
        for c in ordered {
            match out.last_mut() {
                Some(last) if last.sim_s == c.sim_s && last.link == c.link && last.dir == c.dir => {
                    last.hex.push_str(&c.hex)
                }
                _ => out.push(c.clone()),
            }
        }
        out
    }
}

/// Depth of a body-frame point (m, forward-starboard-down from the centre of mass).
pub fn point_depth_m(s: &StateRow, body_m: [f64; 3]) -> f64 {
    let (sr, cr) = s.roll_rad.sin_cos();
    let (sp, cp) = s.pitch_rad.sin_cos();
    s.z_m - sp * body_m[0] + cp * sr * body_m[1] + cp * cr * body_m[2]
}

/// North/east position of a body-frame point (yaw only; roll and pitch stay small).
pub fn point_north_east_m(s: &StateRow, body_m: [f64; 2]) -> (f64, f64) {
    let (sy, cy) = s.yaw_rad.sin_cos();
    (
        s.x_m + cy * body_m[0] - sy * body_m[1],
        s.y_m + sy * body_m[0] + cy * body_m[1],
    )
}
