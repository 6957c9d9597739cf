//! Moving a link's bytes between its endpoint and the bridge core.
//!
//! One task per line. It owns the endpoint (pty, serial device or TCP listener), forwards
//! what the EyeBot side sends to the core, and writes what the core releases. It never
//! parses anything. Faults stay inside the task: a serial device that vanishes is reopened
//! with back-off, a TCP client that leaves is replaced by the next, and a client that does not
//! read makes the core drop (and count) output instead of growing memory.
//!
//! Bytes the core handed over that never reach the endpoint (the device vanished, a write
//! failed, the daemon stopped before the client took them) are counted in `dropped_tx` and,
//! with `--record`, written to the recording's `drops.tsv` (docs/recording.md).
//!
//! A pty stays open on the bridge side, so the EyeBot side opening and closing it is not
//! visible on the master; the link task watches the slave device with inotify instead and
//! counts every open after the first as a reconnect.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use bytes::{Buf, Bytes};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::{mpsc, watch};

use super::config::{Endpoint, LinkConfig};
use crate::record::{DropReason, RecordHandle};
use crate::transport::pty::{PtyDrain, PtyError, PtyMaster};
use crate::transport::{LineSettings, serial};

/// Back-off between attempts to reopen a vanished serial device.
pub const REOPEN_BACKOFF_MIN: Duration = Duration::from_millis(100);
/// The longest wait between reopen attempts.
pub const REOPEN_BACKOFF_MAX: Duration = Duration::from_secs(2);
/// At shutdown, input is read until the endpoint stays quiet this long (a pty is instead
/// held and read to its last accepted byte, see [`PtyDrain`]).
pub const SHUTDOWN_DRAIN: Duration = Duration::from_millis(10);
/// At shutdown, an endpoint that keeps sending is read for at most this long.
pub const SHUTDOWN_DRAIN_LIMIT: Duration = Duration::from_millis(100);
/// At shutdown, bytes already handed over are still written for at most this long.
pub const SHUTDOWN_FLUSH: Duration = Duration::from_millis(50);
/// Chunks the core may have handed over but the endpoint has not yet written.
pub const TX_CHANNEL_CHUNKS: usize = 64;

/// Counters shared between a link task and the status snapshot.
#[derive(Debug, Default)]
pub struct LinkCounters {
    pub bytes_rx: AtomicU64,
    /// Bytes written to the endpoint.
    pub bytes_tx: AtomicU64,
    /// Serial device reopened, TCP client replaced, or the EyeBot side reopened its pty.
    pub reconnects: AtomicU64,
    pub io_errors: AtomicU64,
    /// Bytes handed over by the core that never reached the endpoint.
    pub dropped_tx: AtomicU64,
}

/// Bytes released by the core, with the simulated time of the hand-over.
#[derive(Debug, Clone)]
pub struct Outbound {
    pub sim_s: f64,
    pub data: Bytes,
}

/// What a link task needs besides its endpoint and channels.
#[derive(Debug, Clone)]
pub struct LineContext {
    pub line: usize,
    pub name: &'static str,
    pub counters: Arc<LinkCounters>,
    /// Where drops are recorded (`--record`).
    pub recorder: Option<RecordHandle>,
}

impl LineContext {
    /// Counts, logs and records (in `drops.tsv`) bytes put on the line at simulated time
    /// `sim_s` that did not reach the endpoint: the one place for every drop, whether the
    /// loop drops them (a client that does not read) or the link task (an endpoint gone).
    pub fn dropped(&self, sim_s: f64, reason: DropReason, data: &[u8]) {
        if data.is_empty() {
            return;
        }
        self.counters
            .dropped_tx
            .fetch_add(data.len() as u64, Ordering::Relaxed);
        let (link, bytes, why) = (self.name, data.len(), reason.as_str());
        match reason {
            // A client that does not read drops at every release: counted, not shouted.
            DropReason::NotRead => tracing::debug!(link, bytes, why, "not read: dropped"),
            DropReason::EndpointGone | DropReason::Shutdown => crate::warn_limited!(
                "bytes did not reach the endpoint",
                link,
                bytes,
                why,
                "bytes put on the line did not reach the endpoint"
            ),
        }
        if let Some(rec) = &self.recorder {
            rec.dropped(sim_s, self.name, reason, data);
        }
    }
}

/// Why an endpoint could not be opened at start-up.
#[derive(Debug, thiserror::Error)]
pub enum EndpointError {
    #[error("link `{link}`: {source}")]
    Pty {
        link: &'static str,
        #[source]
        source: PtyError,
    },
    /// The pty link would land outside the run directory, whose owner and mode the daemon
    /// checked; `why` says how.
    #[error(
        "link `{link}`: {path}: {why}; a pty link must stay inside the run directory, the one place whose owner and mode the daemon checks"
    )]
    LinkOutside {
        link: &'static str,
        path: PathBuf,
        why: String,
    },
    #[error("link `{link}`: {source}")]
    Serial {
        link: &'static str,
        #[source]
        source: serial::SerialError,
    },
    #[error("link `{link}`: cannot listen on {addr}: {source}")]
    Tcp {
        link: &'static str,
        addr: std::net::SocketAddr,
        #[source]
        source: std::io::Error,
    },
}

/// An endpoint opened at start-up, before the readiness lines are printed.
pub enum OpenEndpoint {
    /// The pty and the watch on its slave device that sees the EyeBot side open it.
    Pty(PtyMaster, Option<OpenWatch>),
    Serial {
        device: PathBuf,
        line: LineSettings,
        port: Option<tokio_serial::SerialStream>,
    },
    Tcp(tokio::net::TcpListener),
}

impl std::fmt::Debug for OpenEndpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OpenEndpoint::Pty(p, _) => write!(f, "Pty({})", p.client_path().display()),
            OpenEndpoint::Serial { device, .. } => write!(f, "Serial({})", device.display()),
            OpenEndpoint::Tcp(l) => write!(f, "Tcp({:?})", l.local_addr().ok()),
        }
    }
}

/// Why the pty link `link` would not land inside `run_dir`: a `..` or a root in it (the
/// configuration refuses those too), or a directory on the way that is a symlink (its real
/// place could be anywhere, a world-writable directory among them). Directories on the way
/// that do not exist yet are created as real directories inside the run directory.
fn check_link_inside(run_dir: &Path, link: &Path) -> Result<(), String> {
    if !super::config::stays_inside(link) {
        return Err("leaves the run directory (`..`, or an absolute path)".into());
    }
    let mut dir = run_dir.to_path_buf();
    for part in link.parent().into_iter().flat_map(Path::components) {
        dir.push(part);
        match std::fs::symlink_metadata(&dir) {
            Ok(meta) if meta.file_type().is_symlink() => {
                return Err(format!(
                    "the directory {} on its way is a symlink",
                    dir.display()
                ));
            }
            Ok(_) => {}
            Err(_) => break,
        }
    }
    Ok(())
}

impl OpenEndpoint {
    /// Opens `config`'s endpoint. Pty symlinks are placed relative to `run_dir`.
    pub async fn open(
        link: &'static str,
        config: &LinkConfig,
        run_dir: &Path,
    ) -> Result<Self, EndpointError> {
        match &config.endpoint {
            Endpoint::Pty { link: symlink } => {
                let path = run_dir.join(symlink);
                check_link_inside(run_dir, symlink).map_err(|why| EndpointError::LinkOutside {
                    link,
                    path: path.clone(),
                    why,
                })?;
                PtyMaster::open(Some(&path))
                    .map(|pty| {
                        // Watch before anyone can open it, so no early open is missed.
                        let watch = OpenWatch::new(link, pty.slave_path());
                        OpenEndpoint::Pty(pty, watch)
                    })
                    .map_err(|source| EndpointError::Pty { link, source })
            }
            Endpoint::Serial { device } => {
                let port = serial::open(device, &config.line)
                    .map_err(|source| EndpointError::Serial { link, source })?;
                Ok(OpenEndpoint::Serial {
                    device: device.clone(),
                    line: config.line,
                    port: Some(port),
                })
            }
            Endpoint::Tcp { addr } => tokio::net::TcpListener::bind(addr)
                .await
                .map(OpenEndpoint::Tcp)
                .map_err(|source| EndpointError::Tcp {
                    link,
                    addr: *addr,
                    source,
                }),
            Endpoint::SharedWithSonar => unreachable!("a shared link has no endpoint of its own"),
        }
    }

    /// Our symlink and what it points at, for a pty with one.
    pub fn owned_link(&self) -> Option<(&Path, &Path)> {
        match self {
            OpenEndpoint::Pty(p, _) => p.link_path().map(|l| (l, p.slave_path())),
            _ => None,
        }
    }

    /// Where the EyeBot side connects, for the readiness line and the status.
    pub fn describe(&self) -> String {
        match self {
            OpenEndpoint::Pty(p, _) => match p.link_path() {
                Some(link) => format!("{} -> {}", link.display(), p.slave_path().display()),
                None => p.slave_path().display().to_string(),
            },
            OpenEndpoint::Serial { device, line, .. } => format!("{} ({line})", device.display()),
            OpenEndpoint::Tcp(l) => l
                .local_addr()
                .map_or_else(|_| "tcp".to_string(), |a| format!("tcp://{a}")),
        }
    }
}

/// Bytes from the EyeBot side, tagged with the line they came in on.
#[derive(Debug)]
pub struct Inbound {
    pub line: usize,
    pub data: Bytes,
}

/// Runs the line until `shutdown` turns true.
pub async fn run_line(
    cx: LineContext,
    endpoint: OpenEndpoint,
    to_core: mpsc::Sender<Inbound>,
    mut from_core: mpsc::Receiver<Outbound>,
    mut shutdown: watch::Receiver<bool>,
) {
    let name = cx.name;
    match endpoint {
        OpenEndpoint::Pty(mut pty, watch) => {
            let opens = watch_opens(&cx, watch);
            tokio::pin!(opens);
            let drain = match pty.drain_handle() {
                Ok(drain) => Some(drain),
                Err(error) => {
                    tracing::warn!(link = name, %error, "cannot hold the pty's input at shutdown");
                    None
                }
            };
            let pumped = pump(
                &cx,
                &mut pty,
                drain,
                &to_core,
                &mut from_core,
                &mut shutdown,
            );
            tokio::select! {
                _ = pumped => {}
                () = &mut opens => {}
            }
        }
        OpenEndpoint::Serial {
            device,
            line: settings,
            mut port,
        } => {
            let mut backoff = REOPEN_BACKOFF_MIN;
            loop {
                if let Some(mut open) = port.take() {
                    backoff = REOPEN_BACKOFF_MIN;
                    if pump(
                        &cx,
                        &mut open,
                        None,
                        &to_core,
                        &mut from_core,
                        &mut shutdown,
                    )
                    .await
                        == Pumped::Shutdown
                    {
                        return;
                    }
                    tracing::warn!(link = name, device = %device.display(), "serial device lost; reopening");
                }
                // While the device is gone, drain the core's output so it never blocks; the
                // bytes are lost, and recorded as such.
                let reopen = tokio::time::sleep(backoff);
                tokio::pin!(reopen);
                loop {
                    tokio::select! {
                        _ = &mut reopen => break,
                        chunk = from_core.recv() => match chunk {
                            Some(o) => cx.dropped(o.sim_s, DropReason::EndpointGone, &o.data),
                            None => return,
                        },
                        _ = shutdown.changed() => return,
                    }
                }
                match serial::open(&device, &settings) {
                    Ok(p) => {
                        cx.counters.reconnects.fetch_add(1, Ordering::Relaxed);
                        tracing::info!(link = name, device = %device.display(), "serial device reopened");
                        port = Some(p);
                    }
                    Err(e) => {
                        tracing::debug!(link = name, error = %e, "reopen failed");
                        backoff = (backoff * 2).min(REOPEN_BACKOFF_MAX);
                    }
                }
            }
        }
        OpenEndpoint::Tcp(listener) => loop {
            let accepted = tokio::select! {
                a = listener.accept() => a,
                _ = shutdown.changed() => return,
            };
            match accepted {
                Ok((mut stream, peer)) => {
                    tracing::info!(link = name, %peer, "client connected");
                    let _ = stream.set_nodelay(true);
                    if pump(
                        &cx,
                        &mut stream,
                        None,
                        &to_core,
                        &mut from_core,
                        &mut shutdown,
                    )
                    .await
                        == Pumped::Shutdown
                    {
                        return;
                    }
                    cx.counters.reconnects.fetch_add(1, Ordering::Relaxed);
                    tracing::info!(link = name, %peer, "client left");
                }
                Err(e) => {
                    cx.counters.io_errors.fetch_add(1, Ordering::Relaxed);
                    crate::warn_limited!("accept failed", link = name, error = %e, "accept failed");
                    tokio::time::sleep(REOPEN_BACKOFF_MIN).await;
                }
            }
        },
    }
}

#[derive(Debug, PartialEq, Eq)]
enum Pumped {
    Shutdown,
    EndpointLost,
}

/// An inotify watch for `IN_OPEN`/`IN_CLOSE` on a pty's slave device.
pub struct OpenWatch(tokio::io::unix::AsyncFd<InotifyFd>);

impl OpenWatch {
    /// `None` (logged) if inotify is unavailable: reopens are then not counted.
    fn new(link: &'static str, slave: &Path) -> Option<Self> {
        use nix::sys::inotify::{AddWatchFlags, InitFlags, Inotify};
        let inotify = Inotify::init(InitFlags::IN_NONBLOCK | InitFlags::IN_CLOEXEC).and_then(|i| {
            i.add_watch(slave, AddWatchFlags::IN_OPEN | AddWatchFlags::IN_CLOSE)
                .map(|_| i)
        });
        let fd = inotify.map_err(std::io::Error::from).and_then(|i| {
            // SAFETY: the inotify descriptor is open and owned by `InotifyFd`, whose
            // `as_raw_fd` returns that same descriptor for as long as the `AsyncFd` owns it.
            unsafe {
                tokio::io::unix::AsyncFd::register_with_interest(
                    InotifyFd(i),
                    tokio::io::Interest::READABLE,
                )
            }
            .map_err(std::io::Error::from)
        });
        match fd {
            Ok(fd) => Some(Self(fd)),
            Err(error) => {
                tracing::warn!(link, %error, "cannot watch the pty for reopens; they are not counted");
                None
            }
        }
    }
}

/// Counts the EyeBot side's opens of the pty slave (inotify `IN_OPEN` on the device): every
/// open after the first is a reconnect. Never returns.
async fn watch_opens(cx: &LineContext, watch: Option<OpenWatch>) {
    use nix::sys::inotify::AddWatchFlags;
    let Some(OpenWatch(fd)) = watch else {
        return std::future::pending().await;
    };
    let mut opens = 0u64;
    loop {
        let Ok(mut guard) = fd.readable().await else {
            return std::future::pending().await;
        };
        let events =
            match guard.try_io(|f| f.get_ref().0.read_events().map_err(std::io::Error::from)) {
                Ok(Ok(events)) => events,
                Ok(Err(error)) => {
                    tracing::debug!(link = cx.name, %error, "inotify read failed");
                    continue;
                }
                Err(_would_block) => continue,
            };
        for event in events {
            if event.mask.contains(AddWatchFlags::IN_OPEN) {
                opens += 1;
                if opens > 1 {
                    cx.counters.reconnects.fetch_add(1, Ordering::Relaxed);
                }
                tracing::info!(
                    link = cx.name,
                    session = opens,
                    "the EyeBot side opened the pty"
                );
            } else {
                tracing::debug!(link = cx.name, "the EyeBot side closed the pty");
            }
        }
    }
}

struct InotifyFd(nix::sys::inotify::Inotify);

impl std::os::fd::AsRawFd for InotifyFd {
    fn as_raw_fd(&self) -> std::os::fd::RawFd {
        use std::os::fd::AsFd;
        self.0.as_fd().as_raw_fd()
    }
}

async fn pump<S: AsyncRead + AsyncWrite + Unpin>(
    cx: &LineContext,
    stream: &mut S,
    pty: Option<PtyDrain>,
    to_core: &mpsc::Sender<Inbound>,
    from_core: &mut mpsc::Receiver<Outbound>,
    shutdown: &mut watch::Receiver<bool>,
) -> Pumped {
    let (line, name, counters) = (cx.line, cx.name, &*cx.counters);
    // Reading and writing run concurrently: a client that never reads blocks the writer
    // only, and shutdown still ends both at once.
    let (mut rd, mut wr) = tokio::io::split(stream);
    // The chunk being written (what is left of it), kept outside the writer so that what
    // never left can be accounted for when the pump stops.
    let mut current: Option<Outbound> = None;
    let reader = async {
        let mut buf = vec![0u8; 4096];
        loop {
            // Room in the channel first, then the read: both waits are cancel-safe, so a
            // shutdown never drops bytes already taken from the endpoint.
            let Ok(permit) = to_core.reserve().await else {
                return Pumped::Shutdown;
            };
            match rd.read(&mut buf).await {
                Ok(0) => return Pumped::EndpointLost,
                Ok(n) => {
                    counters.bytes_rx.fetch_add(n as u64, Ordering::Relaxed);
                    permit.send(Inbound {
                        line,
                        data: Bytes::copy_from_slice(&buf[..n]),
                    });
                }
                Err(e) => {
                    counters.io_errors.fetch_add(1, Ordering::Relaxed);
                    crate::warn_limited!("read failed", link = name, error = %e, "read failed");
                    return Pumped::EndpointLost;
                }
            }
        }
    };
    let writer = write_all_from(&mut wr, &mut current, from_core, counters, name);
    let outcome = tokio::select! {
        r = reader => r,
        w = writer => w,
        _ = shutdown.changed() => Pumped::Shutdown,
    };
    if outcome == Pumped::Shutdown {
        // What the EyeBot side wrote before the shutdown is still taken, so the recording
        // holds it. A pty's input is held first, so every byte its writer was told was
        // accepted is read; other endpoints are read until they are quiet for a moment.
        match &pty {
            Some(pty) => drain_pty(cx, pty, to_core).await,
            None => {
                let mut buf = vec![0u8; 4096];
                let deadline = tokio::time::Instant::now() + SHUTDOWN_DRAIN_LIMIT;
                while let Ok(Ok(n)) = tokio::time::timeout(SHUTDOWN_DRAIN, rd.read(&mut buf)).await
                {
                    if n == 0 || !forward(cx, to_core, &buf[..n]).await {
                        break;
                    }
                    if tokio::time::Instant::now() >= deadline {
                        tracing::warn!(
                            link = name,
                            "input still arriving at shutdown; stopped reading"
                        );
                        break;
                    }
                }
            }
        }
        // What the core released before it stopped is still written, briefly: the core
        // closes the channel once it has handed over its last bytes.
        let _ = tokio::time::timeout(
            SHUTDOWN_FLUSH,
            write_all_from(&mut wr, &mut current, from_core, counters, name),
        )
        .await;
    }
    let reason = match outcome {
        Pumped::Shutdown => DropReason::Shutdown,
        Pumped::EndpointLost => DropReason::EndpointGone,
    };
    if let Some(rest) = current.take() {
        cx.dropped(rest.sim_s, reason, &rest.data);
    }
    if outcome == Pumped::Shutdown {
        while let Ok(rest) = from_core.try_recv() {
            cx.dropped(rest.sim_s, reason, &rest.data);
        }
    }
    outcome
}

/// Hands bytes read at shutdown to the core (which records them); `false` if it is gone.
async fn forward(cx: &LineContext, to_core: &mpsc::Sender<Inbound>, data: &[u8]) -> bool {
    cx.counters
        .bytes_rx
        .fetch_add(data.len() as u64, Ordering::Relaxed);
    let inbound = Inbound {
        line: cx.line,
        data: Bytes::copy_from_slice(data),
    };
    match tokio::time::timeout(SHUTDOWN_DRAIN_LIMIT, to_core.send(inbound)).await {
        Ok(Ok(())) => true,
        _ => {
            tracing::warn!(
                link = cx.name,
                bytes = data.len(),
                "input read at shutdown could not be handed over"
            );
            false
        }
    }
}

/// Holds the pty's input and reads what it already accepted, to the last byte.
async fn drain_pty(cx: &LineContext, pty: &PtyDrain, to_core: &mpsc::Sender<Inbound>) {
    if let Err(error) = pty.hold_input() {
        tracing::warn!(link = cx.name, %error, "cannot hold the pty's input at shutdown");
    }
    let mut buf = vec![0u8; 4096];
    loop {
        match pty.read_now(&mut buf) {
            Ok(0) => return,
            Ok(n) => {
                if !forward(cx, to_core, &buf[..n]).await {
                    return;
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            // WouldBlock: nothing left. Anything else: the pty is gone.
            Err(_) => return,
        }
    }
}

/// Writes `current` and then each chunk from the core until the channel closes
/// ([`Pumped::Shutdown`]) or a write fails ([`Pumped::EndpointLost`], with the unwritten rest
/// left in `current`).
async fn write_all_from<W: AsyncWrite + Unpin>(
    wr: &mut W,
    current: &mut Option<Outbound>,
    from_core: &mut mpsc::Receiver<Outbound>,
    counters: &LinkCounters,
    name: &'static str,
) -> Pumped {
    loop {
        let chunk = match current {
            Some(chunk) if !chunk.data.is_empty() => chunk,
            _ => match from_core.recv().await {
                Some(next) => current.insert(next),
                None => {
                    *current = None;
                    return Pumped::Shutdown;
                }
            },
        };
        match wr.write(&chunk.data).await {
            Ok(0) => {
                counters.io_errors.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(link = name, "write returned 0 bytes");
                return Pumped::EndpointLost;
            }
            Ok(n) => {
                counters.bytes_tx.fetch_add(n as u64, Ordering::Relaxed);
                chunk.data.advance(n);
                if chunk.data.is_empty() {
                    *current = None;
                }
            }
            Err(e) => {
                counters.io_errors.fetch_add(1, Ordering::Relaxed);
                crate::warn_limited!("write failed", link = name, error = %e, "write failed");
                return Pumped::EndpointLost;
            }
        }
    }
}

#[cfg(test)]
mod tests;
