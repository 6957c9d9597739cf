//! Child processes killed and reaped in `Drop`, a socat-linked pty pair, free ports, and the
//! `/proc` figures of a process.

use std::net::{Ipv4Addr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::tools::require_tool;
use crate::wait::wait_for;

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

    /// Kills the process now (SIGKILL) and reaps it.
    pub fn kill(mut self) {
        self.kill_and_reap();
    }

    fn kill_and_reap(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
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
        self.kill_and_reap();
        for path in &self.cleanup {
            let _ = std::fs::remove_file(path);
        }
    }
}

/// `socat pty,raw,echo=0,link=A pty,raw,echo=0,link=B`: two linked ptys standing in for a
/// serial adapter and its cable, ready once both links exist; killed in `Drop`.
pub fn socat_pair(a: &Path, b: &Path) -> ChildGuard {
    let socat = require_tool("socat", "socat");
    let guard = ChildGuard::spawn(
        "socat",
        Command::new(socat)
            .arg(format!("pty,raw,echo=0,link={}", a.display()))
            .arg(format!("pty,raw,echo=0,link={}", b.display()))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    );
    wait_for("socat's pty links", Duration::from_secs(10), || {
        (a.exists() && b.exists()).then_some(())
    });
    guard
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
    let fields = stat_fields(&text);
    // utime and stime are fields 14 and 15.
    let ticks: u64 = fields[14 - 3].parse::<u64>().expect("utime")
        + fields[15 - 3].parse::<u64>().expect("stime");
    Duration::from_nanos(ticks * 1_000_000_000 / clock_ticks_per_s())
}

/// The fields of a `/proc/.../stat` line from field 3 (the state) on: they follow the
/// parenthesised command name, which may hold spaces.
pub fn stat_fields(stat: &str) -> Vec<&str> {
    let after = &stat[stat.rfind(')').expect("comm in parentheses") + 2..];
    after.split_whitespace().collect()
}

/// `sysconf(_SC_CLK_TCK)`: the unit of `/proc/PID/stat` times.
pub fn clock_ticks_per_s() -> u64 {
    // SAFETY: sysconf has no preconditions.
    let ticks = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if ticks > 0 { ticks as u64 } else { 100 }
}
