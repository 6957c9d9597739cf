//! Captured NMEA in place of the simulated sonar controllers.
//!
//! Two ways in, one mechanism ([`crate::devices::multiplexer`]'s feed):
//!
//! - **`replay = "FILE"`** in `[devices.multiplexer]`: the daemon reads the log at start-up
//!   through the replay module (formats, gzip, timestamps, checksum policy as `eyebot-hil
//!   replay`), and forwards each sentence at its log time as simulated time from the start of
//!   the run. Deterministic, so it works in lockstep too.
//! - **`eyebot-hil replay LOG --into-sonar`**: a replay process paces the log itself and
//!   writes the sentences into the running daemon's `RUN_DIR/sonar-feed.sock` (owner-only);
//!   each is forwarded at the simulated time it arrives. One feeder at a time.

use std::path::{Path, PathBuf};
use std::time::Instant;

use bytes::Bytes;
use tokio::io::AsyncReadExt;
use tokio::net::UnixListener;
use tokio::sync::{mpsc, watch};

use crate::SimNanos;
use crate::replay::{self, Options, Pacing, Sent, Shutdown, Sink, SinkError};

/// The live feed socket's name inside the run directory.
pub const FEED_SOCKET: &str = "sonar-feed.sock";

/// Why a feed could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum FeedError {
    #[error("sonar replay {path}: {source}")]
    Replay {
        path: PathBuf,
        #[source]
        source: replay::ReplayError,
    },
    #[error("sonar feed socket {path}: {source}")]
    Socket {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Collects the replay's schedule instead of sending it.
#[derive(Debug, Default)]
struct Collect {
    schedule: Vec<(SimNanos, Bytes)>,
}

impl Sink for Collect {
    fn begin(&mut self, _origin: Instant) {}

    fn send(
        &mut self,
        sentence: &[u8],
        due_ns: Option<u64>,
        _stop: &Shutdown,
    ) -> Result<Sent, SinkError> {
        let at = due_ns.unwrap_or_else(|| self.schedule.last().map_or(0, |(t, _)| *t));
        self.schedule.push((at, Bytes::copy_from_slice(sentence)));
        Ok(Sent {
            start_ns: due_ns,
            end_ns: due_ns,
            line_wait_ns: 0,
            written_at: Instant::now(),
            write_late_max_ns: 0,
            write_call_max_ns: 0,
        })
    }

    fn free_at_ns(&self) -> u64 {
        self.schedule.last().map_or(0, |(t, _)| *t)
    }
}

/// Reads a log into (simulated time, sentence) pairs, the first sentence at time 0. Logs
/// without timestamps are paced at the Navman's 1 Hz.
pub fn load_schedule(path: &Path) -> Result<Vec<(SimNanos, Bytes)>, FeedError> {
    let fail = |source| FeedError::Replay {
        path: path.to_path_buf(),
        source,
    };
    let probe = replay::Replay::open(Options::new(vec![path.to_path_buf()])).map_err(fail)?;
    let mut opts = Options::new(vec![path.to_path_buf()]);
    opts.pacing = Some(if probe.pacing() == Pacing::Timestamps {
        Pacing::Timestamps
    } else {
        Pacing::Rate { per_s: 1.0 }
    });
    let replay = replay::Replay::open(opts).map_err(fail)?;
    let mut sink = Collect::default();
    let summary = replay
        .run(&mut sink, &mut replay::Quiet, &Shutdown::new())
        .map_err(fail)?;
    tracing::info!(log = %path.display(), sentences = sink.schedule.len(), ?summary, "sonar replay loaded");
    Ok(sink.schedule)
}

/// What a live feeder does.
#[derive(Debug)]
pub enum FeedEvent {
    Connected,
    Bytes(Bytes),
    Closed,
}

/// Binds `path` with owner-only permissions (replacing a stale socket).
pub fn bind(path: &Path) -> Result<UnixListener, FeedError> {
    use std::os::unix::fs::PermissionsExt;
    let fail = |source| FeedError::Socket {
        path: path.to_path_buf(),
        source,
    };
    if std::fs::symlink_metadata(path).is_ok() {
        if std::os::unix::net::UnixStream::connect(path).is_ok() {
            return Err(fail(std::io::Error::new(
                std::io::ErrorKind::AddrInUse,
                "another daemon is serving this socket",
            )));
        }
        std::fs::remove_file(path).map_err(fail)?;
    }
    let listener = UnixListener::bind(path).map_err(fail)?;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600)).map_err(fail)?;
    Ok(listener)
}

/// Serves feeders one at a time until `shutdown`; the socket file is removed at the end.
pub async fn serve(
    listener: UnixListener,
    path: PathBuf,
    to_core: mpsc::Sender<FeedEvent>,
    mut shutdown: watch::Receiver<bool>,
) {
    loop {
        let accepted = tokio::select! {
            a = listener.accept() => a,
            _ = shutdown.changed() => break,
        };
        let Ok((mut stream, _)) = accepted else {
            continue;
        };
        tracing::info!("sonar feed connected");
        if to_core.send(FeedEvent::Connected).await.is_err() {
            break;
        }
        let mut buf = vec![0u8; 4096];
        loop {
            let read = tokio::select! {
                r = stream.read(&mut buf) => r,
                _ = shutdown.changed() => {
                    let _ = std::fs::remove_file(&path);
                    return;
                }
            };
            match read {
                Ok(n) if n > 0 => {
                    if to_core
                        .send(FeedEvent::Bytes(Bytes::copy_from_slice(&buf[..n])))
                        .await
                        .is_err()
                    {
                        break;
                    }
                }
                _ => break,
            }
        }
        tracing::info!("sonar feed closed");
        if to_core.send(FeedEvent::Closed).await.is_err() {
            break;
        }
    }
    let _ = std::fs::remove_file(&path);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_timestamped_log_becomes_a_schedule_from_time_zero() {
        let dir = std::env::temp_dir().join(format!("eyebot-hil-feed-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let log = dir.join("log.nmea");
        std::fs::write(
            &log,
            "100.000 $SDDBT,8.2,f,2.5,M,1.4,F*0E\n100.070 $PEBHS,1,2.5,90*71\n101.500 $SDDBT,9.9,f,3.0,M,1.6,F*02\n",
        )
        .unwrap();
        let schedule = load_schedule(&log).unwrap();
        let times: Vec<SimNanos> = schedule.iter().map(|(t, _)| *t).collect();
        assert_eq!(times, vec![0, 70_000_000, 1_500_000_000]);
        assert_eq!(&schedule[2].1[..], b"$SDDBT,9.9,f,3.0,M,1.6,F*02\r\n");
        let missing = load_schedule(&dir.join("nope.nmea")).unwrap_err();
        assert!(missing.to_string().contains("nope.nmea"), "{missing}");
        std::fs::remove_dir_all(dir).unwrap();
    }
}
