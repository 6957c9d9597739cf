//! Processes and names for end-to-end tests: unique names per test, a child that is killed
//! and reaped in `Drop`, readiness by polling with a timeout (never a fixed sleep), and a
//! loud failure when a system tool the test needs is missing.

use std::net::{Ipv4Addr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// A name no other test in this run (or a concurrent run) uses: `prefix-PID-N`.
pub fn unique_name(prefix: &str) -> String {
    static NEXT: AtomicU32 = AtomicU32::new(0);
    format!(
        "{prefix}-{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    )
}

/// A temporary directory with a unique name, removed (with its contents) on drop.
#[derive(Debug)]
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(prefix: &str) -> Self {
        let path = std::env::temp_dir().join(unique_name(prefix));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path)
            .unwrap_or_else(|e| panic!("cannot create {}: {e}", path.display()));
        Self(path)
    }
    pub fn path(&self) -> &Path {
        &self.0
    }
    pub fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The path of a system tool, or a loud panic naming it and the package that provides it.
pub fn require_tool(tool: &str, package: &str) -> PathBuf {
    let found = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .chain([PathBuf::from("/usr/sbin"), PathBuf::from("/sbin")])
            .map(|dir| dir.join(tool))
            .find(|p| p.is_file())
    });
    found.unwrap_or_else(|| {
        let banner = "!".repeat(72);
        eprintln!(
            "\n{banner}\n!! MISSING TOOL: `{tool}` is not installed (Debian package `{package}`).\n!! This test needs it; install it with `bash .ci/install-deps`.\n{banner}\n"
        );
        panic!("required tool `{tool}` (package `{package}`) is missing");
    })
}

/// Polls `ready` every `every` until it returns `Some`, or panics after `timeout` naming
/// `what`.
pub fn wait_for<T>(
    what: &str,
    timeout: Duration,
    every: Duration,
    mut ready: impl FnMut() -> Option<T>,
) -> T {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(v) = ready() {
            return v;
        }
        assert!(
            Instant::now() < deadline,
            "timed out after {timeout:?} waiting for {what}"
        );
        std::thread::sleep(every);
    }
}

/// A loopback TCP port free at the time of the call.
pub fn free_tcp_port() -> u16 {
    let listener =
        TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).expect("bind an ephemeral loopback port");
    listener.local_addr().expect("local address").port()
}

/// A child process killed (SIGKILL) and reaped on drop; paths in `cleanup` are removed too.
#[derive(Debug)]
pub struct ChildGuard {
    name: String,
    child: Option<Child>,
    cleanup: Vec<PathBuf>,
}

impl ChildGuard {
    /// Spawns `command`, panicking with `name` if it cannot start.
    pub fn spawn(name: &str, command: &mut Command) -> Self {
        let child = command
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
        Self {
            name: name.to_string(),
            child: Some(child),
            cleanup: Vec::new(),
        }
    }

    /// Removes `path` when the guard drops.
    pub fn remove_on_drop(mut self, path: impl Into<PathBuf>) -> Self {
        self.cleanup.push(path.into());
        self
    }

    pub fn id(&self) -> u32 {
        self.child.as_ref().map_or(0, Child::id)
    }

    /// Panics if the process has already exited, showing its status.
    pub fn assert_running(&mut self) {
        if let Some(child) = self.child.as_mut()
            && let Ok(Some(status)) = child.try_wait()
        {
            panic!("{} exited early: {status}", self.name);
        }
    }

    /// Waits up to `timeout` for the process to exit by itself and returns its output
    /// (stdout/stderr must have been piped); kills it and panics on timeout.
    pub fn wait_output(mut self, timeout: Duration) -> Output {
        let deadline = Instant::now() + timeout;
        let mut child = self.child.take().expect("child present");
        loop {
            match child.try_wait() {
                Ok(Some(_)) => break,
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(20))
                }
                _ => {
                    let _ = child.kill();
                    let out = child.wait_with_output();
                    panic!(
                        "{} did not finish within {timeout:?}; output so far: {:?}",
                        self.name,
                        out.map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
                    );
                }
            }
        }
        child
            .wait_with_output()
            .unwrap_or_else(|e| panic!("{}: {e}", self.name))
    }
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
        for path in &self.cleanup {
            let _ = std::fs::remove_file(path);
        }
    }
}
