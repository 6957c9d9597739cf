//! `eyebot-hil status`: a snapshot of the running daemon over a Unix socket.
//!
//! The daemon listens on `RUN_DIR/status.sock`, created with owner-only permissions (0600)
//! inside a run directory that is itself 0700 where the daemon created it. A client connects
//! and the daemon writes one JSON document ([`StatusSnapshot`]) followed by a newline, then
//! closes. There is no request to parse, so a client cannot confuse the daemon.

use std::io;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{UnixListener, UnixStream};
use tokio::sync::watch;

/// Per-link counters.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LinkStatus {
    pub name: String,
    /// Where the EyeBot side connects (symlink, device or address).
    pub path: String,
    pub bytes_rx: u64,
    pub bytes_tx: u64,
    pub frames_rx: u64,
    pub frames_tx: u64,
    /// Malformed or unknown input: answered where the protocol says so, logged at debug level
    /// (so a flood costs counters, not log lines).
    pub errors: u64,
    /// Bytes put on the line that never reached the endpoint (the EyeBot side did not read,
    /// the endpoint was gone); with `--record` each drop is in `drops.tsv`.
    pub dropped_tx: u64,
    /// Times the endpoint was lost and reopened: a serial device reopened, a TCP client
    /// replaced, or the EyeBot side opening its pty again.
    pub reconnects: u64,
}

/// The vehicle's pose.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub x_m: f64,
    pub y_m: f64,
    pub depth_m: f64,
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub heading_deg: f64,
    pub surge_mps: f64,
}

/// Everything `eyebot-hil status` prints.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StatusSnapshot {
    pub pid: u32,
    pub version: String,
    pub uptime_s: f64,
    pub sim_time_s: f64,
    pub time_mode: String,
    pub speed: f64,
    pub overruns: u64,
    pub links: Vec<LinkStatus>,
    pub pose: Pose,
    pub contacts: u64,
    pub recording: Option<String>,
}

impl StatusSnapshot {
    /// Human-readable form, as `eyebot-hil status` prints it.
    pub fn render(&self) -> String {
        let mut out = format!(
            "eyebot-hil {} (pid {})\nuptime      {:.1} s\nsim time    {:.3} s\ntime mode   {} (speed {}, overruns {})\n",
            self.version,
            self.pid,
            self.uptime_s,
            self.sim_time_s,
            self.time_mode,
            self.speed,
            self.overruns
        );
        out.push_str(&format!(
            "pose        x {:.2} m  y {:.2} m  depth {:.2} m  heading {:.1} deg  roll {:.1}  pitch {:.1}  surge {:.3} m/s\ncontacts    {}\n",
            self.pose.x_m,
            self.pose.y_m,
            self.pose.depth_m,
            self.pose.heading_deg,
            self.pose.roll_deg,
            self.pose.pitch_deg,
            self.pose.surge_mps,
            self.contacts
        ));
        if let Some(dir) = &self.recording {
            out.push_str(&format!("recording   {dir}\n"));
        }
        out.push_str("link      path                          rx bytes   tx bytes  rx frames  tx frames  errors  dropped  reconnects\n");
        for l in &self.links {
            out.push_str(&format!(
                "{:<9} {:<28} {:>9} {:>10} {:>10} {:>10} {:>7} {:>8} {:>11}\n",
                l.name,
                l.path,
                l.bytes_rx,
                l.bytes_tx,
                l.frames_rx,
                l.frames_tx,
                l.errors,
                l.dropped_tx,
                l.reconnects
            ));
        }
        out
    }
}

/// Why the status socket could not be served or read.
#[derive(Debug, thiserror::Error)]
pub enum StatusError {
    #[error("status socket {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error(
        "status socket {path}: the daemon sent something that is not a status document: {source}"
    )]
    Garbled {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    /// Nothing listens on the socket: no daemon runs with this run directory.
    #[error(
        "no daemon runs here: nothing listens on {path} ({source}); start one with `eyebot-hil run`, or name the run directory of the one running with `--run-dir DIR`"
    )]
    NoDaemon {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("status socket {path}: no answer within {timeout:?}")]
    Timeout { path: PathBuf, timeout: Duration },
    #[error(
        "status socket {path}: more than {MAX_STATUS_BYTES} bytes; a status document is a few KiB (is something else serving this socket?)"
    )]
    TooLarge { path: PathBuf },
}

/// The most a status client reads: a snapshot is a few KiB, and a socket that streams
/// without end must cost an error, not memory.
pub const MAX_STATUS_BYTES: u64 = 1 << 20;

/// The listening socket; removes its file on drop.
#[derive(Debug)]
pub struct StatusServer {
    listener: UnixListener,
    path: PathBuf,
}

impl StatusServer {
    /// Binds `path` (replacing a stale socket file) with mode 0600.
    pub fn bind(path: &Path) -> Result<Self, StatusError> {
        let listener = super::socket::bind_owner_only(path).map_err(|source| StatusError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(Self {
            listener,
            path: path.to_path_buf(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Answers every connection with the latest snapshot until `shutdown` turns true.
    pub async fn serve(
        &self,
        snapshot: watch::Receiver<StatusSnapshot>,
        mut shutdown: watch::Receiver<bool>,
    ) {
        loop {
            tokio::select! {
                accepted = self.listener.accept() => match accepted {
                    Ok((mut stream, _)) => {
                        let mut doc = match serde_json::to_vec(&*snapshot.borrow()) {
                            Ok(doc) => doc,
                            Err(e) => {
                                tracing::error!(error = %e, "cannot serialise status");
                                continue;
                            }
                        };
                        doc.push(b'\n');
                        // A client that never reads must not stall the daemon.
                        tokio::spawn(async move {
                            let _ = tokio::time::timeout(Duration::from_secs(1), stream.write_all(&doc)).await;
                        });
                    }
                    Err(e) => {
                        crate::warn_limited!("status accept failed", error = %e, "status socket accept failed");
                        tokio::time::sleep(Duration::from_millis(50)).await;
                    }
                },
                changed = shutdown.changed() => {
                    if changed.is_err() || *shutdown.borrow() {
                        return;
                    }
                }
            }
        }
    }
}

impl Drop for StatusServer {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Connects to a daemon's status socket and reads its snapshot.
pub async fn query(path: &Path, timeout: Duration) -> Result<StatusSnapshot, StatusError> {
    let io_err = |source| StatusError::Io {
        path: path.to_path_buf(),
        source,
    };
    let read = async {
        let stream = UnixStream::connect(path).await.map_err(|source| {
            if matches!(
                source.kind(),
                io::ErrorKind::NotFound | io::ErrorKind::ConnectionRefused
            ) {
                StatusError::NoDaemon {
                    path: path.to_path_buf(),
                    source,
                }
            } else {
                io_err(source)
            }
        })?;
        let mut doc = Vec::new();
        stream
            .take(MAX_STATUS_BYTES + 1)
            .read_to_end(&mut doc)
            .await
            .map_err(io_err)?;
        if doc.len() as u64 > MAX_STATUS_BYTES {
            return Err(StatusError::TooLarge {
                path: path.to_path_buf(),
            });
        }
        serde_json::from_slice(&doc).map_err(|source| StatusError::Garbled {
            path: path.to_path_buf(),
            source,
        })
    };
    tokio::time::timeout(timeout, read)
        .await
        .map_err(|_| StatusError::Timeout {
            path: path.to_path_buf(),
            timeout,
        })?
}

#[cfg(test)]
mod tests {
    use std::os::unix::fs::PermissionsExt;

    use super::*;

    #[tokio::test]
    async fn a_client_reads_the_latest_snapshot_from_an_owner_only_socket() {
        let tmp = crate::scratch::dir("status");
        let dir = tmp.path();
        let path = dir.join("status.sock");
        let server = StatusServer::bind(&path).unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);

        let (snap_tx, snap_rx) = watch::channel(StatusSnapshot::default());
        let (stop_tx, stop_rx) = watch::channel(false);
        let serving = tokio::spawn(async move { server.serve(snap_rx, stop_rx).await });
        snap_tx.send_modify(|s| {
            s.sim_time_s = 12.5;
            s.links.push(LinkStatus {
                name: "sonar".into(),
                errors: 3,
                ..LinkStatus::default()
            });
        });
        let got = query(&path, Duration::from_secs(2)).await.unwrap();
        assert_eq!(got.sim_time_s, 12.5);
        assert_eq!(got.links[0].errors, 3);
        assert!(got.render().contains("sonar"));

        stop_tx.send(true).unwrap();
        serving.await.unwrap();
        assert!(!path.exists(), "socket file removed when the server stops");
    }

    #[tokio::test]
    async fn a_stale_socket_file_is_replaced_but_a_live_one_is_not() {
        let tmp = crate::scratch::dir("status2");
        let dir = tmp.path();
        let path = dir.join("status.sock");
        {
            let live = StatusServer::bind(&path).unwrap();
            assert!(
                StatusServer::bind(&path).is_err(),
                "a live daemon's socket is kept"
            );
            drop(live);
        }
        // A crashed daemon leaves its socket file behind with nobody listening.
        drop(std::os::unix::net::UnixListener::bind(&path).unwrap());
        assert!(path.exists());
        let replaced = StatusServer::bind(&path).unwrap();
        drop(replaced);
        let err = query(&dir.join("nothing.sock"), Duration::from_millis(200))
            .await
            .unwrap_err();
        assert!(err.to_string().contains("nothing.sock"));
    }

    /// A socket that streams without end costs the client an error, not memory.
    #[tokio::test]
    async fn a_client_reads_a_bounded_document() {
        let tmp = crate::scratch::dir("status-flood");
        let path = tmp.path().join("status.sock");
        let listener = UnixListener::bind(&path).unwrap();
        let server = tokio::spawn(async move {
            let (mut stream, _) = listener.accept().await.unwrap();
            let block = vec![b'x'; 64 * 1024];
            while stream.write_all(&block).await.is_ok() {}
        });
        let err = query(&path, Duration::from_secs(10)).await.unwrap_err();
        assert!(matches!(err, StatusError::TooLarge { .. }), "{err}");
        server.abort();
    }

    /// `status` where no daemon runs says so and names `--run-dir`, not only the socket.
    #[tokio::test]
    async fn no_daemon_is_named_as_such() {
        let tmp = crate::scratch::dir("status-none");
        let err = query(&tmp.path().join("status.sock"), Duration::from_secs(1))
            .await
            .unwrap_err();
        let text = err.to_string();
        assert!(matches!(err, StatusError::NoDaemon { .. }), "{text}");
        assert!(
            text.starts_with("no daemon runs here") && text.contains("--run-dir"),
            "{text}"
        );
        // A socket file left by a daemon that ended: connection refused, the same answer.
        let stale = tmp.path().join("stale.sock");
        drop(std::os::unix::net::UnixListener::bind(&stale).unwrap());
        let err = query(&stale, Duration::from_secs(1)).await.unwrap_err();
        assert!(matches!(err, StatusError::NoDaemon { .. }), "{err}");
    }
}
