//! Shutdown within [`SHUTDOWN_LIMIT`], even when part of the daemon hangs.
//!
//! A clean shutdown (SIGINT/SIGTERM) stops the loop, flushes what is due, stops the link
//! tasks (they write what the engine released, take what the EyeBot side sent, close their
//! endpoints and remove their symlinks), finishes the recording (flush + `fsync`) and removes
//! the sockets and the pid file. Normally that takes a few milliseconds. Two things bound it
//! when something hangs:
//!
//! - inside [`super::Daemon::finish`], link tasks that have not stopped after
//!   [`TASKS_BUDGET`] are aborted (dropping their endpoints), services after
//!   [`SERVICES_BUDGET`], and everything we created is removed through [`Leftovers`];
//! - the process-level guard started by [`spawn_signal_guard`] watches the signals on a
//!   thread of its own, so it fires even when the daemon's runtime is blocked (a recorder
//!   waiting on a disk that stopped taking data, a serial `close` waiting for the line to
//!   drain): [`HARD_EXIT_AFTER`] after the signal it removes our symlinks, sockets and pid
//!   file and exits with [`EXIT_SHUTDOWN_HUNG`]. What the recorder had not written by then
//!   is lost, and the log says so.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::sync::watch;

/// SIGINT/SIGTERM to process exit, at most.
pub const SHUTDOWN_LIMIT: Duration = Duration::from_secs(1);
/// When the process-level guard gives up on a clean shutdown (leaves time to exit).
pub const HARD_EXIT_AFTER: Duration = Duration::from_millis(800);
/// How long link tasks may take to stop before they are aborted.
pub const TASKS_BUDGET: Duration = Duration::from_millis(300);
/// How long the services beside the links (status, feed) get, between them, to stop before
/// they are aborted.
pub const SERVICES_BUDGET: Duration = Duration::from_millis(200);
/// Exit status when shutdown had to be cut short.
pub const EXIT_SHUTDOWN_HUNG: i32 = 3;

/// Where a clean shutdown is, so that the guard can say what it was waiting for when it
/// gives up (one daemon per process).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Phase {
    /// The loop has not yet seen the stop.
    Serving = 0,
    /// Waiting for the link tasks to stop.
    Links = 1,
    /// Waiting for the services beside the links (status, feed, view).
    Services = 2,
    /// Finishing the recording (flush and `fsync`).
    Recording = 3,
    /// Removing the pid file, sockets and symlinks.
    Cleanup = 4,
    /// Finished; the process is exiting.
    Done = 5,
}

static PHASE: AtomicU8 = AtomicU8::new(Phase::Serving as u8);

impl Phase {
    /// Records that shutdown has reached this phase.
    pub fn enter(self) {
        PHASE.store(self as u8, Ordering::Relaxed);
    }

    fn current() -> Self {
        match PHASE.load(Ordering::Relaxed) {
            1 => Self::Links,
            2 => Self::Services,
            3 => Self::Recording,
            4 => Self::Cleanup,
            5 => Self::Done,
            _ => Self::Serving,
        }
    }

    /// What the shutdown waits for in this phase, for the guard's error.
    pub fn waiting_for(self) -> &'static str {
        match self {
            Self::Serving => "the main loop to see the stop (it is busy or not scheduled)",
            Self::Links => "the link tasks to stop",
            Self::Services => "the services (status, feed, view) to stop",
            Self::Recording => "the recording's flush and fsync (the disk)",
            Self::Cleanup => "removing the pid file, sockets and symlinks (the file system)",
            Self::Done => "the process to exit",
        }
    }
}

#[derive(Debug, Clone)]
enum Leftover {
    Symlink { path: PathBuf, target: PathBuf },
    Socket(PathBuf),
    PidFile(PathBuf),
}

/// Everything the daemon created in the file system that must not outlive it.
#[derive(Debug, Clone, Default)]
pub struct Leftovers(Arc<Mutex<Vec<Leftover>>>);

impl Leftovers {
    fn push(&self, item: Leftover) {
        if let Ok(mut items) = self.0.lock() {
            items.push(item);
        }
    }

    /// Our symlink at `path` pointing at `target`.
    pub fn symlink(&self, path: &Path, target: &Path) {
        self.push(Leftover::Symlink {
            path: path.to_path_buf(),
            target: target.to_path_buf(),
        });
    }

    /// A Unix socket we bound.
    pub fn socket(&self, path: &Path) {
        self.push(Leftover::Socket(path.to_path_buf()));
    }

    /// Our pid file.
    pub fn pid_file(&self, path: &Path) {
        self.push(Leftover::PidFile(path.to_path_buf()));
    }

    /// Removes whatever is still there and still ours; safe to call more than once.
    pub fn remove_all(&self) {
        let items = match self.0.lock() {
            Ok(items) => items.clone(),
            Err(poisoned) => poisoned.into_inner().clone(),
        };
        for item in items {
            match item {
                Leftover::Symlink { path, target } => {
                    crate::transport::symlink::remove_if_ours(&path, &target);
                }
                Leftover::Socket(path) => {
                    use std::os::unix::fs::FileTypeExt;
                    // Only a socket: anything else put there since is not ours.
                    let socket =
                        std::fs::symlink_metadata(&path).is_ok_and(|m| m.file_type().is_socket());
                    if socket {
                        let _ = std::fs::remove_file(path);
                    }
                }
                Leftover::PidFile(path) => {
                    let ours = super::run_dir::read_pid(&path) == Some(std::process::id());
                    if ours {
                        let _ = std::fs::remove_file(path);
                    }
                }
            }
        }
    }
}

/// Waits for SIGINT or SIGTERM on a thread of its own, then sets `stop`; if the process is
/// still running [`HARD_EXIT_AFTER`] later, removes `leftovers` and exits with
/// [`EXIT_SHUTDOWN_HUNG`]. For the binary only: tests running the daemon in-process use a
/// plain shutdown channel.
pub fn spawn_signal_guard(
    stop: watch::Sender<bool>,
    leftovers: Leftovers,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    // Register the handlers now, so a signal right after start-up is not missed.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let signals = runtime.block_on(async {
        use tokio::signal::unix::{SignalKind, signal};
        Ok::<_, std::io::Error>((
            signal(SignalKind::interrupt())?,
            signal(SignalKind::terminate())?,
        ))
    })?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            let (mut int, mut term) = signals;
            runtime.block_on(async {
                tokio::select! {
                    _ = int.recv() => {}
                    _ = term.recv() => {}
                }
            });
            tracing::info!("signal received, shutting down");
            let signalled = Instant::now();
            let _ = stop.send(true);
            std::thread::sleep(HARD_EXIT_AFTER);
            let phase = Phase::current();
            tracing::error!(
                limit_ms = SHUTDOWN_LIMIT.as_millis() as u64,
                after_ms = signalled.elapsed().as_millis() as u64,
                phase = ?phase,
                "shutdown did not finish in time: still waiting for {}; removing our links and sockets and exiting; the recording may be incomplete",
                phase.waiting_for()
            );
            leftovers.remove_all();
            std::process::exit(EXIT_SHUTDOWN_HUNG);
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leftovers_removes_only_what_is_still_ours() {
        let tmp = crate::scratch::dir("left");
        let dir = tmp.path();
        let ours = dir.join("sonar");
        let taken = dir.join("sensor");
        std::os::unix::fs::symlink("/dev/null", &ours).unwrap();
        // Another daemon re-pointed this one since we made it.
        std::os::unix::fs::symlink("/dev/zero", &taken).unwrap();
        let sock = dir.join("status.sock");
        let _listener = std::os::unix::net::UnixListener::bind(&sock).unwrap();
        // A regular file where a socket was: not ours, kept.
        let planted = dir.join("feed.sock");
        std::fs::write(&planted, "user data").unwrap();
        let pid = dir.join("pid");
        std::fs::write(&pid, "1\n").unwrap();
        let left = Leftovers::default();
        left.symlink(&ours, Path::new("/dev/null"));
        left.symlink(&taken, Path::new("/dev/null"));
        left.socket(&sock);
        left.socket(&planted);
        left.pid_file(&pid);
        left.remove_all();
        left.remove_all();
        assert!(std::fs::symlink_metadata(&ours).is_err());
        assert!(
            std::fs::symlink_metadata(&taken).is_ok(),
            "not ours any more"
        );
        assert!(!sock.exists());
        assert!(planted.exists(), "a regular file is not a socket of ours");
        assert!(pid.exists(), "a pid file naming another process is kept");
    }
}
