//! Pseudo-terminals for tests: a pty created with the bridge's own [`PtyMaster`] (so tests
//! exercise the real transport), and a consumer on the slave side that timestamps every read.

use std::os::fd::AsFd;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use eyebot_hil::transport::pty::PtyMaster;
use nix::fcntl::{OFlag, open};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::stat::Mode;

/// A tokio runtime kept alive beside a pty: `PtyMaster` registers with a reactor.
pub struct PtyFixture {
    pub runtime: tokio::runtime::Runtime,
    pub link: PathBuf,
}

impl PtyFixture {
    /// A runtime and a symlink path `dir/name` for a pty.
    pub fn new(dir: &Path, name: &str) -> Self {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("tokio runtime");
        Self {
            runtime,
            link: dir.join(name),
        }
    }

    /// Opens a pty in raw mode with its symlink at `self.link`.
    pub fn open(&self) -> PtyMaster {
        let _enter = self.runtime.enter();
        PtyMaster::open(Some(&self.link)).expect("open a pty")
    }
}

/// One read on the consumer side: when it returned and what it held.
#[derive(Debug, Clone)]
pub struct TimedRead {
    pub at: Instant,
    pub bytes: Vec<u8>,
}

/// A thread reading a tty path until stopped, timestamping each read.
pub struct TimedReader {
    stop: Arc<AtomicBool>,
    received: Arc<AtomicUsize>,
    /// Whether the reading thread runs under `SCHED_FIFO`.
    pub realtime: bool,
    thread: Option<JoinHandle<Vec<TimedRead>>>,
}

impl TimedReader {
    /// Opens `path` (non-blocking, polled every 20 ms for the stop flag) and reads.
    pub fn spawn(path: &Path) -> Self {
        Self::spawn_with(path, None)
    }

    /// Like [`spawn`](Self::spawn); with `Some(priority)` the reading thread first asks for
    /// `SCHED_FIFO` at that priority, so that on a loaded machine its wake-ups measure the
    /// pty rather than the CPU queue. Whether that was granted is in [`Self::realtime`].
    pub fn spawn_with(path: &Path, fifo_priority: Option<i32>) -> Self {
        let fd = open(
            path,
            OFlag::O_RDONLY | OFlag::O_NOCTTY | OFlag::O_NONBLOCK,
            Mode::empty(),
        )
        .unwrap_or_else(|e| panic!("open {}: {e}", path.display()));
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let received = Arc::new(AtomicUsize::new(0));
        let count = received.clone();
        let (granted_tx, granted_rx) = std::sync::mpsc::channel();
        let thread = std::thread::spawn(move || {
            let granted = fifo_priority.is_some_and(|priority| {
                let param = libc::sched_param {
                    sched_priority: priority,
                };
                // SAFETY: plain syscall on the calling thread with a valid parameter struct.
                unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) == 0 }
            });
            let _ = granted_tx.send(granted);
            let mut reads = Vec::new();
            let mut buf = [0u8; 4096];
            loop {
                let mut fds = [PollFd::new(fd.as_fd(), PollFlags::POLLIN)];
                let _ = poll(&mut fds, PollTimeout::from(20u8));
                match nix::unistd::read(&fd, &mut buf) {
                    Ok(n) if n > 0 => {
                        reads.push(TimedRead {
                            at: Instant::now(),
                            bytes: buf[..n].to_vec(),
                        });
                        count.fetch_add(n, Ordering::SeqCst);
                    }
                    _ => {
                        if flag.load(Ordering::SeqCst) {
                            return reads;
                        }
                    }
                }
            }
        });
        let realtime = granted_rx.recv().unwrap_or(false);
        Self {
            stop,
            received,
            realtime,
            thread: Some(thread),
        }
    }

    /// Bytes read so far.
    pub fn received(&self) -> usize {
        self.received.load(Ordering::SeqCst)
    }

    /// Waits (polling, up to `timeout`) until `want` bytes have arrived: bytes written to a
    /// pty master reach the slave through the kernel's flip buffer a little later. Then stops
    /// and returns every read.
    pub fn finish_when(self, want: usize, timeout: Duration) -> Vec<TimedRead> {
        let deadline = Instant::now() + timeout;
        while self.received() < want && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        self.finish()
    }

    /// Stops reading once nothing more arrives and returns every read.
    pub fn finish(mut self) -> Vec<TimedRead> {
        self.stop.store(true, Ordering::SeqCst);
        self.thread
            .take()
            .expect("thread present")
            .join()
            .expect("reader thread")
    }
}

impl Drop for TimedReader {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// All bytes of `reads`, concatenated.
pub fn concat(reads: &[TimedRead]) -> Vec<u8> {
    reads.iter().flat_map(|r| r.bytes.iter().copied()).collect()
}
