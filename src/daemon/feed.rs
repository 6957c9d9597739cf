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
    #[error(
        "sonar replay {path}: not a regular file (a log is read as the simulation reaches each sentence; copy a pipe's output to a file first)"
    )]
    NotAFile { path: PathBuf },
    #[error("sonar feed socket {path}: {source}")]
    Socket {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// A log as (simulated time, sentence) pairs, the first sentence at time 0: by the log's
/// timestamps when it has them (a time that goes back is due with the sentence before), else
/// one sentence per [`UNTIMED_PERIOD_NS`]. Sentences are checked as `replay --policy pass`
/// does (sent as they are, with CR LF); comments and lines with problems the policy drops are
/// left out.
///
/// The log is streamed: the schedule holds the next sentence only, and reads the one after
/// when it is taken, so a log of any length costs the reader's bounded buffers. Only regular
/// files are accepted: the simulation takes sentences as it reaches their times, and a pipe
/// could stall it.
pub struct Schedule {
    path: PathBuf,
    source: Source,
    timed: bool,
    first_ns: Option<i64>,
    latest_ns: SimNanos,
    /// Sentences taken so far (the untimed clock, and the log line at the end).
    taken: u64,
    next: Option<(SimNanos, Bytes)>,
}

impl std::fmt::Debug for Schedule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Schedule")
            .field("path", &self.path)
            .field("taken", &self.taken)
            .field("next", &self.next.as_ref().map(|(t, _)| *t))
            .finish()
    }
}

impl crate::engine::FeedSchedule for Schedule {
    fn next_time(&self) -> Option<SimNanos> {
        Schedule::next_time(self)
    }
    fn pop(&mut self) -> Option<(SimNanos, Bytes)> {
        Schedule::pop(self)
    }
}

impl Schedule {
    /// Opens the log and reads its first sentence (so a log that cannot be read fails here,
    /// before the daemon reports ready).
    pub fn open(path: &Path) -> Result<Self, FeedError> {
        let fail = |source| FeedError::Log {
            path: path.to_path_buf(),
            source,
        };
        let meta = std::fs::metadata(path).map_err(|source| {
            fail(InputError::Io {
                path: path.to_path_buf(),
                source,
            })
        })?;
        if !meta.is_file() {
            return Err(FeedError::NotAFile {
                path: path.to_path_buf(),
            });
        }
        let source = Source::open(path, 0, "sonar", CommentMode::Ignore, Default::default())
            .map_err(fail)?;
        let timed = source.format().is_timed();
        let mut schedule = Self {
            path: path.to_path_buf(),
            source,
            timed,
            first_ns: None,
            latest_ns: 0,
            taken: 0,
            next: None,
        };
        schedule.next = schedule.read_next().map_err(fail)?;
        tracing::info!(log = %path.display(), timed, "sonar replay opened");
        Ok(schedule)
    }

    /// When the next sentence is due.
    pub fn next_time(&self) -> Option<SimNanos> {
        self.next.as_ref().map(|(t, _)| *t)
    }

    /// Takes the next sentence and reads the one after. A read error part-way ends the
    /// schedule, logged with the file.
    pub fn pop(&mut self) -> Option<(SimNanos, Bytes)> {
        let taken = self.next.take()?;
        self.taken += 1;
        match self.read_next() {
            Ok(next) => self.next = next,
            Err(error) => {
                tracing::warn!(log = %self.path.display(), %error, "sonar replay cut short");
            }
        }
        if self.next.is_none() {
            tracing::info!(log = %self.path.display(), sentences = self.taken, "sonar replay finished");
        }
        Some(taken)
    }

    fn read_next(&mut self) -> Result<Option<(SimNanos, Bytes)>, InputError> {
        while let Some(event) = self.source.next_event()? {
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
            let at = match (self.timed, line.time_ns) {
                (true, Some(t)) => {
                    let since_first = t.saturating_sub(*self.first_ns.get_or_insert(t));
                    self.latest_ns = self.latest_ns.max(since_first.max(0) as SimNanos);
                    self.latest_ns
                }
                (true, None) => self.latest_ns,
                // Called with no sentence held: `taken` sentences come before this one.
                (false, _) => self.taken.saturating_mul(UNTIMED_PERIOD_NS),
            };
            return Ok(Some((at, Bytes::from(out))));
        }
        Ok(None)
    }
}

/// Reads a whole log into a schedule (tests and small logs; the daemon streams through
/// [`Schedule`]).
pub fn load_schedule(path: &Path) -> Result<Vec<(SimNanos, Bytes)>, FeedError> {
    let mut schedule = Schedule::open(path)?;
    Ok(std::iter::from_fn(|| schedule.pop()).collect())
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
