//! Moving a link's bytes between its endpoint and the bridge core.
//!
//! One task per line. It owns the endpoint (pty, serial device or TCP listener), forwards
//! what the EyeBot side sends to the core, and writes what the core releases. It never
//! parses anything. Faults stay inside the task: a serial device that vanishes is reopened
//! with back-off, a TCP client that leaves is replaced by the next, and a client that does not
//! read makes the core drop (and count) output instead of growing memory.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use bytes::Bytes;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::{mpsc, watch};

use super::config::{Endpoint, LinkConfig};
use crate::transport::pty::{PtyError, PtyMaster};
use crate::transport::{LineSettings, serial};

/// Back-off between attempts to reopen a vanished serial device.
pub const REOPEN_BACKOFF_MIN: Duration = Duration::from_millis(100);
/// The longest wait between reopen attempts.
pub const REOPEN_BACKOFF_MAX: Duration = Duration::from_secs(2);
/// At shutdown, input is read until the endpoint stays quiet this long.
pub const SHUTDOWN_DRAIN: Duration = Duration::from_millis(10);
/// Chunks the core may have handed over but the endpoint has not yet written.
pub const TX_CHANNEL_CHUNKS: usize = 64;

/// Counters shared between a link task and the status snapshot.
#[derive(Debug, Default)]
pub struct LinkCounters {
    pub bytes_rx: AtomicU64,
    pub bytes_tx: AtomicU64,
    pub reconnects: AtomicU64,
    pub io_errors: AtomicU64,
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
    Pty(PtyMaster),
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
            OpenEndpoint::Pty(p) => write!(f, "Pty({})", p.client_path().display()),
            OpenEndpoint::Serial { device, .. } => write!(f, "Serial({})", device.display()),
            OpenEndpoint::Tcp(l) => write!(f, "Tcp({:?})", l.local_addr().ok()),
        }
    }
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
                PtyMaster::open(Some(&path))
                    .map(OpenEndpoint::Pty)
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

    /// Where the EyeBot side connects, for the readiness line and the status.
    pub fn describe(&self) -> String {
        match self {
            OpenEndpoint::Pty(p) => match p.link_path() {
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
    line: usize,
    name: &'static str,
    endpoint: OpenEndpoint,
    to_core: mpsc::Sender<Inbound>,
    mut from_core: mpsc::Receiver<Bytes>,
    counters: Arc<LinkCounters>,
    mut shutdown: watch::Receiver<bool>,
) {
    match endpoint {
        OpenEndpoint::Pty(mut pty) => {
            let _ = pump(
                line,
                name,
                &mut pty,
                &to_core,
                &mut from_core,
                &counters,
                &mut shutdown,
            )
            .await;
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
                        line,
                        name,
                        &mut open,
                        &to_core,
                        &mut from_core,
                        &counters,
                        &mut shutdown,
                    )
                    .await
                        == Pumped::Shutdown
                    {
                        return;
                    }
                    tracing::warn!(link = name, device = %device.display(), "serial device lost; reopening");
                }
                // While the device is gone, drain the core's output so it never blocks.
                let reopen = tokio::time::sleep(backoff);
                tokio::pin!(reopen);
                loop {
                    tokio::select! {
                        _ = &mut reopen => break,
                        chunk = from_core.recv() => if chunk.is_none() { return },
                        _ = shutdown.changed() => return,
                    }
                }
                match serial::open(&device, &settings) {
                    Ok(p) => {
                        counters.reconnects.fetch_add(1, Ordering::Relaxed);
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
                        line,
                        name,
                        &mut stream,
                        &to_core,
                        &mut from_core,
                        &counters,
                        &mut shutdown,
                    )
                    .await
                        == Pumped::Shutdown
                    {
                        return;
                    }
                    counters.reconnects.fetch_add(1, Ordering::Relaxed);
                    tracing::info!(link = name, %peer, "client left");
                }
                Err(e) => {
                    counters.io_errors.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!(link = name, error = %e, "accept failed");
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

async fn pump<S: AsyncRead + AsyncWrite + Unpin>(
    line: usize,
    name: &'static str,
    stream: &mut S,
    to_core: &mpsc::Sender<Inbound>,
    from_core: &mut mpsc::Receiver<Bytes>,
    counters: &LinkCounters,
    shutdown: &mut watch::Receiver<bool>,
) -> Pumped {
    // Reading and writing run concurrently: a client that never reads blocks the writer
    // only, and shutdown still ends both at once.
    let (mut rd, mut wr) = tokio::io::split(stream);
    let reader = async {
        let mut buf = vec![0u8; 4096];
        loop {
            match rd.read(&mut buf).await {
                Ok(0) => return Pumped::EndpointLost,
                Ok(n) => {
                    counters.bytes_rx.fetch_add(n as u64, Ordering::Relaxed);
                    let inbound = Inbound {
                        line,
                        data: Bytes::copy_from_slice(&buf[..n]),
                    };
                    if to_core.send(inbound).await.is_err() {
                        return Pumped::Shutdown;
                    }
                }
                Err(e) => {
                    counters.io_errors.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!(link = name, error = %e, "read failed");
                    return Pumped::EndpointLost;
                }
            }
        }
    };
    let writer = async {
        while let Some(chunk) = from_core.recv().await {
            if let Err(e) = wr.write_all(&chunk).await {
                counters.io_errors.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(link = name, error = %e, "write failed");
                return Pumped::EndpointLost;
            }
            counters
                .bytes_tx
                .fetch_add(chunk.len() as u64, Ordering::Relaxed);
        }
        Pumped::Shutdown
    };
    let outcome = tokio::select! {
        r = reader => r,
        w = writer => w,
        _ = shutdown.changed() => Pumped::Shutdown,
    };
    if outcome == Pumped::Shutdown {
        // What the EyeBot side wrote before the shutdown is still taken, so the recording
        // holds it: read until the endpoint has nothing more for a moment.
        let mut buf = vec![0u8; 4096];
        while let Ok(Ok(n)) = tokio::time::timeout(SHUTDOWN_DRAIN, rd.read(&mut buf)).await {
            if n == 0 {
                break;
            }
            counters.bytes_rx.fetch_add(n as u64, Ordering::Relaxed);
            let inbound = Inbound {
                line,
                data: Bytes::copy_from_slice(&buf[..n]),
            };
            if to_core.try_send(inbound).is_err() {
                break;
            }
        }
    }
    outcome
}

#[cfg(test)]
mod tests {
    use std::io::{Read, Write};

    use super::*;

    fn pty_config() -> LinkConfig {
        LinkConfig {
            endpoint: Endpoint::Pty {
                link: "sonar".into(),
            },
            line: LineSettings::n81(4800),
            tx_queue_bytes: 4096,
        }
    }

    struct Running {
        to_core: mpsc::Receiver<Inbound>,
        from_core: mpsc::Sender<Bytes>,
        stop: watch::Sender<bool>,
        task: tokio::task::JoinHandle<()>,
        client_path: PathBuf,
        _dir: PathBuf,
    }

    async fn start(tag: &str) -> Running {
        let dir =
            std::env::temp_dir().join(format!("eyebot-hil-link-{}-{tag}", std::process::id()));
        let endpoint = OpenEndpoint::open("sonar", &pty_config(), &dir)
            .await
            .unwrap();
        let client_path = dir.join("sonar");
        assert!(
            endpoint
                .describe()
                .starts_with(&client_path.display().to_string())
        );
        let (in_tx, in_rx) = mpsc::channel(16);
        let (out_tx, out_rx) = mpsc::channel(TX_CHANNEL_CHUNKS);
        let (stop, stop_rx) = watch::channel(false);
        let counters = Arc::new(LinkCounters::default());
        let task = tokio::spawn(run_line(
            0, "sonar", endpoint, in_tx, out_rx, counters, stop_rx,
        ));
        Running {
            to_core: in_rx,
            from_core: out_tx,
            stop,
            task,
            client_path,
            _dir: dir,
        }
    }

    #[tokio::test]
    async fn bytes_cross_a_pty_link_both_ways() {
        let mut run = start("both").await;
        let path = run.client_path.clone();
        let mut client = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
            .unwrap();
        client.write_all(b"#S1\r").unwrap();
        let got = run.to_core.recv().await.unwrap();
        assert_eq!(&got.data[..], b"#S1\r");
        run.from_core
            .send(Bytes::from_static(b"$SDDBT,,f,2.0,M,,F*00\r\n"))
            .await
            .unwrap();
        let mut back = [0u8; 23];
        tokio::task::spawn_blocking(move || {
            client.read_exact(&mut back).unwrap();
            back
        })
        .await
        .map(|b| assert_eq!(&b, b"$SDDBT,,f,2.0,M,,F*00\r\n"))
        .unwrap();
        run.stop.send(true).unwrap();
        run.task.await.unwrap();
        assert!(
            std::fs::symlink_metadata(&path).is_err(),
            "symlink removed at shutdown"
        );
    }

    /// Regression: bytes the EyeBot wrote just before shutdown were lost when the task's
    /// select picked the shutdown over the pending read (and so never reached the
    /// recording). The task now drains its endpoint as it stops.
    #[tokio::test]
    async fn bytes_written_just_before_shutdown_still_reach_the_core() {
        for round in 0..20 {
            let mut run = start(&format!("drain{round}")).await;
            let mut client = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(&run.client_path)
                .unwrap();
            // The shutdown is signalled before the link task has run at all.
            client.write_all(b"#S2\r").unwrap();
            run.stop.send(true).unwrap();
            tokio::time::timeout(Duration::from_secs(1), run.task)
                .await
                .expect("link task ends")
                .unwrap();
            let got = run.to_core.try_recv().map(|i| i.data.to_vec());
            assert_eq!(got.as_deref(), Ok(&b"#S2\r"[..]), "round {round}");
        }
    }

    /// A client that opens the line but never reads must not wedge the daemon: the hand-over
    /// channel fills (the core then drops and counts), and shutdown still ends the task.
    #[tokio::test]
    async fn a_client_that_never_reads_cannot_block_shutdown() {
        let run = start("noread").await;
        let _client = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&run.client_path)
            .unwrap();
        let chunk = Bytes::from(vec![b'x'; 4096]);
        let mut refused = 0;
        for _ in 0..1000 {
            if run.from_core.try_send(chunk.clone()).is_err() {
                refused += 1;
            }
            tokio::task::yield_now().await;
        }
        assert!(
            refused > 0,
            "a bounded hand-over refuses chunks once the client stops reading"
        );
        run.stop.send(true).unwrap();
        tokio::time::timeout(Duration::from_secs(1), run.task)
            .await
            .expect("link task ends within 1 s of shutdown")
            .unwrap();
    }
}
