//! Where replayed sentences go, and the byte timing on the way.
//!
//! The replay core hands each sentence to a [`Sink`] with its deadline. Byte outputs (a pty,
//! a serial device, stdout, any writer) are a [`ByteSink`] over a [`Port`]: it sleeps to the
//! deadline, then releases each byte only once its completion time on the line has come, using
//! the same [`WirePacer`] model as the daemon (start bit + data + parity + stop bits per
//! character, at the configured baud). Writes block when the consumer does not read: that
//! blocking is the back-pressure, there are no hand-tuned delays.
//!
//! `--into-sonar` is a [`ByteSink`] too, over [`Port::Writer`] on a running daemon's sonar
//! feed socket (`crate::daemon::feed`): the replay paces the sentences, the daemon's
//! multiplexer forwards each at the simulated time it arrives, through select/ack, and the
//! daemon's own link pacer times the bytes to the EyeBot.

use std::io::{self, Write};
use std::os::fd::{AsRawFd, BorrowedFd};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use bytes::Bytes;
use nix::errno::Errno;
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};

use crate::transport::LineSettings;
use crate::transport::pacer::WirePacer;
use crate::transport::pty::PtyMaster;

/// The longest a blocking wait lasts before the shutdown flag is checked again.
pub const SHUTDOWN_POLL: Duration = Duration::from_millis(100);

/// A shutdown request shared between a signal handler (or a test) and the replay.
#[derive(Debug, Clone, Default)]
pub struct Shutdown(Arc<AtomicBool>);

impl Shutdown {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn trigger(&self) {
        self.0.store(true, Ordering::SeqCst);
    }
    pub fn is_triggered(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// Why a sink failed.
#[derive(Debug, thiserror::Error)]
pub enum SinkError {
    #[error("writing to {to}: {source}")]
    Io {
        to: String,
        #[source]
        source: io::Error,
    },
    #[error("stopped by a shutdown request")]
    Stopped,
}

/// What happened to one sentence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sent {
    /// When its first byte's start bit began on the modelled line (ns after the origin).
    pub start_ns: Option<u64>,
    /// When its last byte was complete on the modelled line (ns after the origin).
    pub end_ns: Option<u64>,
    /// How long it waited for the line to finish the sentence before (ns).
    pub line_wait_ns: u64,
    /// When the last byte was handed to the operating system.
    pub written_at: Instant,
    /// The longest any of its bytes was handed to the operating system after its completion
    /// time on the line (ns): how late this process ran, before any consumer is involved.
    pub write_late_max_ns: u64,
    /// The longest single `write` call for it took (ns): time spent inside the kernel.
    pub write_call_max_ns: u64,
}

/// Somewhere sentences go.
pub trait Sink {
    /// Called once before the first sentence: deadlines count from `origin`.
    fn begin(&mut self, origin: Instant);
    /// Sends one sentence (with CR LF), not before `due_ns` after the origin (`None`: as soon
    /// as the sink takes it). Returns once the sink has taken all of it.
    fn send(
        &mut self,
        sentence: &[u8],
        due_ns: Option<u64>,
        stop: &Shutdown,
    ) -> Result<Sent, SinkError>;
    /// When the line is free again (ns after the origin): where a `--loop` pass restarts.
    fn free_at_ns(&self) -> u64;
}

/// A byte port written with blocking semantics.
pub enum Port {
    /// A pty created for this replay (its symlink is removed on drop).
    Pty(PtyMaster),
    /// A real serial device opened with the line settings.
    Serial(tokio_serial::SerialStream),
    Stdout(io::Stdout),
    /// Any writer: tests, benchmarks.
    Writer(Box<dyn Write + Send>),
}

impl std::fmt::Debug for Port {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

impl Port {
    /// A name for messages: the pty's symlink, the device, `stdout`.
    pub fn describe(&self) -> String {
        match self {
            Port::Pty(p) => match p.link_path() {
                Some(link) => format!("{} -> {}", link.display(), p.slave_path().display()),
                None => p.slave_path().display().to_string(),
            },
            Port::Serial(s) => tokio_serial::SerialPort::name(s).unwrap_or_else(|| "serial".into()),
            Port::Stdout(_) => "stdout".into(),
            Port::Writer(_) => "writer".into(),
        }
    }

    fn write_all(&mut self, buf: &[u8], stop: &Shutdown) -> io::Result<()> {
        match self {
            Port::Pty(p) => write_fd(p.as_raw_fd(), buf, stop),
            Port::Serial(s) => write_fd(s.as_raw_fd(), buf, stop),
            Port::Stdout(s) => {
                let mut lock = s.lock();
                lock.write_all(buf)?;
                lock.flush()
            }
            Port::Writer(w) => w.write_all(buf),
        }
    }
}

/// Writes all of `buf` to a non-blocking descriptor, waiting in `poll` while it is full.
fn write_fd(raw: std::os::fd::RawFd, mut buf: &[u8], stop: &Shutdown) -> io::Result<()> {
    // SAFETY: `raw` belongs to a `PtyMaster` or `SerialStream` borrowed for this call.
    let fd = unsafe { BorrowedFd::borrow_raw(raw) };
    while !buf.is_empty() {
        match nix::unistd::write(fd, buf) {
            Ok(n) => buf = &buf[n..],
            Err(Errno::EINTR) => {}
            Err(Errno::EAGAIN) => {
                if stop.is_triggered() {
                    return Err(io::Error::new(io::ErrorKind::Interrupted, "shutdown"));
                }
                let mut fds = [PollFd::new(fd, PollFlags::POLLOUT)];
                let ms = u16::try_from(SHUTDOWN_POLL.as_millis()).unwrap_or(100);
                match poll(&mut fds, PollTimeout::from(ms)) {
                    Ok(_) | Err(Errno::EINTR) => {}
                    Err(e) => return Err(e.into()),
                }
            }
            Err(e) => return Err(e.into()),
        }
    }
    Ok(())
}

/// Sleeps until `deadline` in slices, so a shutdown is seen within [`SHUTDOWN_POLL`].
/// Returns `false` if stopped. `std::thread::sleep` is a high-resolution `nanosleep`.
pub fn sleep_until(deadline: Instant, stop: &Shutdown) -> bool {
    loop {
        if stop.is_triggered() {
            return false;
        }
        let now = Instant::now();
        if now >= deadline {
            return true;
        }
        std::thread::sleep((deadline - now).min(SHUTDOWN_POLL));
    }
}

/// Bytes to a [`Port`], each released at its completion time on the line.
#[derive(Debug)]
pub struct ByteSink {
    port: Port,
    pacer: WirePacer,
    char_ns: u64,
    origin: Instant,
    free_at_ns: u64,
    out: Vec<u8>,
    written_bytes: u64,
    trace: Option<Vec<(u64, Instant)>>,
}

impl ByteSink {
    pub fn new(port: Port, line: &LineSettings) -> Self {
        let pacer = WirePacer::new(line, 64 * 1024);
        Self {
            char_ns: pacer.char_ns(),
            port,
            pacer,
            origin: Instant::now(),
            free_at_ns: 0,
            out: Vec::new(),
            written_bytes: 0,
            trace: None,
        }
    }

    /// Also keeps, for every `write`, the number of bytes written so far and when that write
    /// returned: the sender's side of a latency measurement (tests, diagnostics).
    pub fn with_write_trace(mut self) -> Self {
        self.trace = Some(Vec::new());
        self
    }

    /// The write trace, if enabled: `(bytes written so far, when)` per write.
    pub fn write_trace(&self) -> &[(u64, Instant)] {
        self.trace.as_deref().unwrap_or(&[])
    }

    fn traced(&mut self, n: usize, at: Instant) {
        self.written_bytes += n as u64;
        if let Some(trace) = &mut self.trace {
            trace.push((self.written_bytes, at));
        }
    }

    pub fn port(&self) -> &Port {
        &self.port
    }

    fn io(&self, source: io::Error, stop: &Shutdown) -> SinkError {
        if stop.is_triggered() {
            SinkError::Stopped
        } else {
            SinkError::Io {
                to: self.port.describe(),
                source,
            }
        }
    }
}

impl Sink for ByteSink {
    fn begin(&mut self, origin: Instant) {
        self.origin = origin;
    }

    fn send(
        &mut self,
        sentence: &[u8],
        due_ns: Option<u64>,
        stop: &Shutdown,
    ) -> Result<Sent, SinkError> {
        let Some(due_ns) = due_ns else {
            // Fast: the consumer sets the pace; a full buffer blocks the write.
            if let Err(e) = self.port.write_all(sentence, stop) {
                return Err(self.io(e, stop));
            }
            let written_at = Instant::now();
            self.traced(sentence.len(), written_at);
            self.free_at_ns = written_at.saturating_duration_since(self.origin).as_nanos() as u64;
            return Ok(Sent {
                start_ns: None,
                end_ns: None,
                line_wait_ns: 0,
                written_at,
                write_late_max_ns: 0,
                write_call_max_ns: 0,
            });
        };
        let start_ns = self.free_at_ns.max(due_ns);
        let end_ns = self
            .pacer
            .push(due_ns, Bytes::copy_from_slice(sentence))
            .map_err(|e| SinkError::Io {
                to: self.port.describe(),
                source: io::Error::other(e),
            })?;
        debug_assert_eq!(end_ns, start_ns + self.char_ns * sentence.len() as u64);
        self.free_at_ns = end_ns;
        let mut written_at = Instant::now();
        let mut write_late_max_ns = 0u64;
        let mut write_call_max_ns = 0u64;
        while let Some(next_ns) = self.pacer.next_release_ns() {
            if !sleep_until(self.origin + Duration::from_nanos(next_ns), stop) {
                return Err(SinkError::Stopped);
            }
            let now_ns = self.origin.elapsed().as_nanos() as u64;
            self.out.clear();
            self.pacer.release(now_ns, &mut self.out);
            let out = std::mem::take(&mut self.out);
            let before_write = Instant::now();
            let result = self.port.write_all(&out, stop);
            self.out = out;
            if let Err(e) = result {
                return Err(self.io(e, stop));
            }
            written_at = Instant::now();
            let n = self.out.len();
            self.traced(n, written_at);
            write_call_max_ns =
                write_call_max_ns.max((written_at - before_write).as_nanos() as u64);
            // The first byte of this batch was due at `next_ns`: it is the latest one.
            let at_ns = written_at.saturating_duration_since(self.origin).as_nanos() as u64;
            write_late_max_ns = write_late_max_ns.max(at_ns.saturating_sub(next_ns));
        }
        Ok(Sent {
            start_ns: Some(start_ns),
            end_ns: Some(end_ns),
            line_wait_ns: start_ns - due_ns,
            written_at,
            write_late_max_ns,
            write_call_max_ns,
        })
    }

    fn free_at_ns(&self) -> u64 {
        self.free_at_ns
    }
}

/// Takes everything at once: `--dry-run`.
#[derive(Debug, Default)]
pub struct NullSink;

impl Sink for NullSink {
    fn begin(&mut self, _origin: Instant) {}
    fn send(&mut self, _s: &[u8], _due: Option<u64>, _stop: &Shutdown) -> Result<Sent, SinkError> {
        Ok(Sent {
            start_ns: None,
            end_ns: None,
            line_wait_ns: 0,
            written_at: Instant::now(),
            write_late_max_ns: 0,
            write_call_max_ns: 0,
        })
    }
    fn free_at_ns(&self) -> u64 {
        0
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use super::*;

    type Writes = Vec<(Instant, Vec<u8>)>;

    /// A writer that timestamps every write.
    #[derive(Clone, Default)]
    struct Recording(Arc<Mutex<Writes>>);

    impl Write for Recording {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            self.0.lock().unwrap().push((Instant::now(), buf.to_vec()));
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    /// No byte is written before its completion time at the line rate.
    #[test]
    fn bytes_never_leave_before_their_wire_time() {
        let rec = Recording::default();
        let line = LineSettings::n81(9600);
        let mut sink = ByteSink::new(Port::Writer(Box::new(rec.clone())), &line);
        let origin = Instant::now();
        sink.begin(origin);
        let stop = Shutdown::new();
        let a = sink.send(b"$AB*00\r\n", Some(5_000_000), &stop).unwrap();
        let b = sink.send(b"$CD*00\r\n", Some(0), &stop).unwrap();
        let char_ns = line.char_time_ns();
        assert_eq!(a.end_ns, Some(5_000_000 + 8 * char_ns));
        assert_eq!(b.start_ns, a.end_ns, "the second waits for the line");
        assert_eq!(b.line_wait_ns, 5_000_000 + 8 * char_ns);
        let writes = rec.0.lock().unwrap();
        let mut sent = 0u64;
        for (at, bytes) in writes.iter() {
            sent += bytes.len() as u64;
            let complete_ns = 5_000_000 + sent * char_ns;
            assert!(
                at.duration_since(origin).as_nanos() as u64 >= complete_ns,
                "byte {sent} written before its completion time"
            );
        }
        assert_eq!(sent, 16);
    }

    #[test]
    fn shutdown_interrupts_a_long_wait() {
        let mut sink = ByteSink::new(Port::Writer(Box::new(io::sink())), &LineSettings::n81(4800));
        sink.begin(Instant::now());
        let stop = Shutdown::new();
        stop.trigger();
        assert!(matches!(
            sink.send(b"$X*00\r\n", Some(3_600_000_000_000), &stop),
            Err(SinkError::Stopped)
        ));
    }
}
