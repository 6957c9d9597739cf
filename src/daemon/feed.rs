//! Captured NMEA in place of the simulated sonar controllers.
//!
//! Two ways in, one mechanism ([`crate::devices::multiplexer`]'s feed):
//!
//! - **`replay = "FILE"`** in `[devices.multiplexer]`: the daemon reads the log at start-up
//!   with replay's log reader ([`crate::replay::input::Source`]: the same formats, gzip and
//!   timestamps as `eyebot-hil replay`, sentences checked under the `pass` policy), and
//!   forwards each sentence at its log time as simulated time from the start of the run.
//!   Deterministic, so it works in lockstep too.
//! - **`eyebot-hil replay LOG --into-sonar`**: a replay process paces the log itself and
//!   writes the sentences into the running daemon's `RUN_DIR/sonar-feed.sock` (owner-only);
//!   each is forwarded at the simulated time it arrives. One feeder at a time.

use std::path::{Path, PathBuf};

use bytes::Bytes;
use tokio::io::AsyncReadExt;
use tokio::net::UnixListener;
use tokio::sync::{mpsc, watch};

use crate::SimNanos;
use crate::replay::input::{CommentMode, Event, InputError, LineKind, Source};
use crate::replay::sentence_check::{Policy, check_line};

/// The live feed socket's name inside the run directory.
pub const FEED_SOCKET: &str = "sonar-feed.sock";

/// The sentence rate of a log without timestamps: the Navman's 1 Hz.
pub const UNTIMED_PERIOD_NS: SimNanos = 1_000_000_000;

/// Why a feed could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum FeedError {
    #[error("sonar replay {path}: {source}")]
    Log {
        path: PathBuf,
        #[source]
        source: InputError,
    },
    #[error("sonar feed socket {path}: {source}")]
    Socket {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Reads a log into (simulated time, sentence) pairs, the first sentence at time 0: by the
/// log's timestamps when it has them (a time that goes back is due with the sentence before),
/// else one sentence per [`UNTIMED_PERIOD_NS`]. Sentences are checked as `replay --policy
/// pass` does (sent as they are, with CR LF); comments and lines with problems the policy
/// drops are left out.
pub fn load_schedule(path: &Path) -> Result<Vec<(SimNanos, Bytes)>, FeedError> {
    let fail = |source| FeedError::Log {
        path: path.to_path_buf(),
        source,
    };
    let mut source =
        Source::open(path, 0, "sonar", CommentMode::Ignore, Default::default()).map_err(fail)?;
    let timed = source.format().is_timed();
    let mut schedule: Vec<(SimNanos, Bytes)> = Vec::new();
    let mut first_ns = None;
    let mut latest_ns: SimNanos = 0;
    while let Some(event) = source.next_event().map_err(fail)? {
        let Event::Line(line) = event else {
            continue;
        };
        if line.kind != LineKind::Data {
            continue;
        }
        let checked = check_line(&line.bytes, line.terminator, line.overflow, Policy::Pass);
        let Some(out) = checked.out else {
            continue;
        };
        let at = match (timed, line.time_ns) {
            (true, Some(t)) => {
                let since_first = t.saturating_sub(*first_ns.get_or_insert(t));
                latest_ns = latest_ns.max(since_first.max(0) as SimNanos);
                latest_ns
            }
            (true, None) => schedule.last().map_or(0, |(t, _)| *t),
            (false, _) => schedule.len() as SimNanos * UNTIMED_PERIOD_NS,
        };
        schedule.push((at, Bytes::from(out)));
    }
    tracing::info!(log = %path.display(), sentences = schedule.len(), timed, "sonar replay loaded");
    Ok(schedule)
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
    super::socket::bind_owner_only(path).map_err(|source| FeedError::Socket {
        path: path.to_path_buf(),
        source,
    })
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

    /// The schedule's times for a log with this text.
    fn times(dir: &Path, name: &str, text: &str) -> Vec<SimNanos> {
        let log = dir.join(name);
        std::fs::write(&log, text).unwrap();
        load_schedule(&log)
            .unwrap()
            .iter()
            .map(|(t, _)| *t)
            .collect()
    }

    const DBT_A: &str = "$SDDBT,8.2,f,2.5,M,1.4,F*0E";
    const DBT_B: &str = "$SDDBT,9.9,f,3.0,M,1.6,F*02";

    /// A timestamped log plays from time 0 at its log times, and a time that goes back is
    /// due with the sentence before (never reordered); a log without timestamps plays at
    /// 1 Hz; a comment is not a sentence.
    #[test]
    fn a_log_becomes_a_schedule_from_time_zero() {
        let tmp = crate::scratch::dir("feed");
        let dir = tmp.path();
        let second = UNTIMED_PERIOD_NS;
        let cases = [
            (
                "timed.nmea",
                format!("100.000 {DBT_A}\n100.070 $PEBHS,1,2.5,90*71\n101.500 {DBT_B}\n"),
                vec![0, 70_000_000, 1_500_000_000],
            ),
            (
                "back.nmea",
                format!("10.0 {DBT_A}\n12.0 {DBT_B}\n11.0 {DBT_A}\n"),
                vec![0, 2 * second, 2 * second],
            ),
            (
                "plain.nmea",
                format!("{DBT_A}\n# a comment\n{DBT_B}\n{DBT_A}\n"),
                vec![0, second, 2 * second],
            ),
        ];
        for (name, text, expected) in cases {
            assert_eq!(times(dir, name, &text), expected, "{name}");
        }
        let schedule = load_schedule(&dir.join("timed.nmea")).unwrap();
        assert_eq!(&schedule[2].1[..], format!("{DBT_B}\r\n").as_bytes());
        let missing = load_schedule(&dir.join("nope.nmea")).unwrap_err();
        assert!(missing.to_string().contains("nope.nmea"), "{missing}");
    }
}
