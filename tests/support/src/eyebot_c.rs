//! The EyeBot C library (`firmware-protocol/c`) and programs built with make, for the host or
//! for the 68k under qemu-m68k, and run in lockstep against a recording daemon.
//!
//! Builds go to `CARGO_TARGET_TMPDIR/eyebot-c/` (the test passes
//! `env!("CARGO_TARGET_TMPDIR")`), inside the target directory: make rebuilds only what
//! changed, and nothing is written to the source tree or the system's temporary directory.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use nix::sys::signal::Signal;

use crate::config::{as_edits, start_at};
use crate::daemon::Daemon;
use crate::recording::{Recording, TranscriptChunk, first_difference};
use crate::tools::{require_file, require_tool};

/// Which compiler builds the C.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// The host's `cc`.
    Host,
    /// `m68k-linux-gnu-gcc -mcpu=68020 -static`, run under `qemu-m68k`.
    M68k,
}

impl Target {
    fn name(self) -> &'static str {
        match self {
            Target::Host => "host",
            Target::M68k => "m68k",
        }
    }

    /// Checks the tools that build and run for this target are installed.
    pub fn require_tools(self) {
        require_tool("make", "make");
        match self {
            Target::Host => {
                require_tool("cc", "gcc");
            }
            Target::M68k => {
                require_tool("m68k-linux-gnu-gcc", "gcc-m68k-linux-gnu");
                require_file(
                    Path::new("/usr/m68k-linux-gnu/include/stdio.h"),
                    "libc6-dev-m68k-cross",
                );
                require_tool("qemu-m68k", "qemu-user");
            }
        }
    }
}

/// The C library's source directory.
pub fn c_source_dir() -> PathBuf {
    crate::workspace_root().join("firmware-protocol").join("c")
}

/// Runs one `make` of the C library at a time in this test binary: tests run on threads and
/// share output directories (one build of the examples for several runs), and make is not safe
/// to run twice at once on one `OUT` (one run's `rm -f libeyebot.a` under another's link
/// leaves every library call undefined). Every make of a test goes through here.
pub fn run_make(make: &mut Command) -> std::process::Output {
    static MAKE: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one_at_a_time = MAKE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    make.output().expect("run make")
}

/// Builds libeyebot and the examples (plus the `extra` programs) for `target` into
/// `TMP/eyebot-c/<name>-<target>/` and returns that directory; `tmp` is the test's
/// `env!("CARGO_TARGET_TMPDIR")`. `name` keeps tests that build at the same time out of each
/// other's directories. `make_args` (`VAR=value`) come after the target's own: for example
/// `BACKEND=robios` with its `CFLAGS` and `LDLIBS`.
pub fn build(
    tmp: &str,
    name: &str,
    target: Target,
    extra: &[&Path],
    make_args: &[String],
) -> PathBuf {
    target.require_tools();
    let out = Path::new(tmp)
        .join("eyebot-c")
        .join(format!("{name}-{}", target.name()));
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
    let output = run_make(&mut make);
    assert!(
        output.status.success(),
        "make failed for {target:?}:\n{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    out
}

/// Starts `BIN run --time-mode lockstep --seed SEED --record DIR/rec` in a fresh directory
/// named after `tag`, with the vehicle at `start` (position north-east-down in m, heading in
/// deg) if given, else at the default start.
pub fn start_daemon(bin: &str, tag: &str, start: Option<([f64; 3], f64)>, seed: u64) -> Daemon {
    let mut options = Daemon::options(bin, tag)
        .lockstep()
        .args(&["--seed", &seed.to_string()])
        .record();
    if let Some((position_m, heading_deg)) = start {
        options = options.config(&as_edits(&start_at(position_m, heading_deg)));
    }
    options.start()
}

/// Stops a daemon of [`start_daemon`] (SIGINT: the recording is flushed) and reads its
/// recording.
pub fn stop_daemon(daemon: &mut Daemon) -> Recording {
    daemon.stop_with(Signal::SIGINT);
    Recording::read(daemon.record_dir())
}

/// Runs `program` against `daemon` ([`run_program`]), checks it succeeded, stops the daemon
/// ([`stop_daemon`]) and returns the recording and what the program printed.
pub fn run_to_end(
    mut daemon: Daemon,
    target: Target,
    program: &Path,
    env: &[(&str, &str)],
    timeout: Duration,
) -> (Recording, String) {
    let result = run_program(&daemon, target, program, env, timeout);
    assert!(
        result.status.success(),
        "{} ({target:?}): {:?}\n{}\n{}",
        program.display(),
        result.status,
        result.stdout,
        result.stderr
    );
    (stop_daemon(&mut daemon), result.stdout)
}

/// A run's transcript and what the program printed.
pub type RunOutput = (Vec<TranscriptChunk>, String);

/// Checks that two runs of one program (other builds, same seed) sent and received the same
/// bytes at the same simulated times and printed the same text; `what` names them.
pub fn assert_same_run(what: &str, a: &RunOutput, b: &RunOutput) {
    assert!(
        a.0.len() > 100,
        "{what}: short transcript ({} chunks)",
        a.0.len()
    );
    assert!(
        a.0 == b.0,
        "{what}: transcripts differ at {}",
        first_difference(&a.0, &b.0)
    );
    assert_eq!(a.1, b.1, "{what}: LCD output differs");
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
    run_program_args(daemon, target, program, &[], env, timeout)
}

/// [`run_program`] with command-line arguments for the program.
pub fn run_program_args(
    daemon: &Daemon,
    target: Target,
    program: &Path,
    args: &[&str],
    env: &[(&str, &str)],
    timeout: Duration,
) -> ProgramRun {
    let mut cmd = match target {
        Target::Host => Command::new(program),
        Target::M68k => {
            let mut c = Command::new(require_tool("qemu-m68k", "qemu-user"));
            c.arg(program);
            c
        }
    };
    cmd.args(args);
    cmd.env("EYEBOT_RUN_DIR", &daemon.run_dir)
        .env("EYEBOT_TIME_MODE", "lockstep")
        // Generous: in lockstep a retry would change the transcript.
        .env("EYEBOT_TIMEOUT_MS", "3000")
        .env_remove("EYEBOT_LCD")
        .env_remove("EYEBOT_KEYS")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let child = cmd
        .spawn()
        .unwrap_or_else(|e| panic!("start {}: {e}", program.display()));
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
            let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), Signal::SIGKILL);
            panic!("{} ran longer than {timeout:?}", program.display());
        }
    }
}
