//! `eyebot-hil replay`: captured NMEA logs back onto a line, with the log's own timing.
//!
//! ```text
//! LOG... ──► input::Source (format, gzip, timestamps, comments) ──► merge::Merger (by time)
//!        ──► sentence_check::check_line (policy pass/drop/fix, one Problem per fault)
//!        ──► pacing::Scheduler (deadline from one start instant) ──► output::Sink
//!                                    ByteSink: pty | serial | stdout | the daemon's sonar
//!                                    feed socket (`--into-sonar`), bytes at the baud rate
//! ```
//!
//! Build a [`Replay`] from [`Options`] with [`Replay::open`] (it reads each input's head to
//! detect formats and `#Serial:`), open an output with [`Replay::line_settings`], then call
//! [`Replay::run`] with a [`Sink`], an [`Observer`] for the report and a [`Shutdown`].
//! The format rules are in `docs/replay.md`.

pub mod input;
pub mod line;
pub mod merge;
pub mod output;
pub mod pacing;
pub mod problem;
mod run;
pub mod sentence_check;
pub mod stats;

use std::path::PathBuf;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex};
use std::time::Instant;

pub use input::{CommentMode, Event, Format, InputError, Loc, Source, TimestampForm};
pub use merge::{MergeMode, Merger};
pub use output::{ByteSink, NullSink, Port, Sent, Shutdown, Sink, SinkError};
pub use pacing::{Pacing, Placement, Scheduler};
pub use problem::{Action, Problem, ProblemKind};
pub use sentence_check::Policy;
pub use stats::Summary;

use crate::transport::LineSettings;

/// NMEA 0183's line: 4800 baud 8N1, used when neither `--line` nor `#Serial:` says otherwise.
pub const DEFAULT_LINE: LineSettings = LineSettings::n81(4800);

/// Problems of one kind listed individually before the rest are only counted.
pub const LISTED_PER_KIND: u64 = 50;

/// The range of `--speed`. Outside it a schedule is either too slow to be useful (a
/// millisecond of log time per second) or faster than the line's own wire time, which
/// `--pacing fast` expresses directly.
pub const SPEED_RANGE: std::ops::RangeInclusive<f64> = 0.001..=1000.0;

/// Everything a replay is told. [`Options::new`] gives the defaults.
#[derive(Debug, Clone)]
pub struct Options {
    pub inputs: Vec<PathBuf>,
    pub policy: Policy,
    /// `None`: by timestamps when every input has them, else back to back at the baud rate.
    pub pacing: Option<Pacing>,
    /// Speed factor on the schedule (2 = twice as fast). Bytes keep their wire time.
    pub speed: f64,
    /// Log-time offsets in seconds from the first sentence.
    pub start_s: f64,
    pub end_s: Option<f64>,
    pub looping: bool,
    /// Overrides `#Serial:` comments.
    pub line: Option<LineSettings>,
    /// The recorded link replayed from `--record` output.
    pub link: String,
    pub comments: CommentMode,
    /// The instant deadlines count from (default: when `run` starts). Tests inject it.
    pub origin: Option<Instant>,
    /// Gaps longer than this are counted in the statistics.
    pub gap_threshold_s: f64,
    /// List every problem, not only the first [`LISTED_PER_KIND`] of each kind.
    pub list_all_problems: bool,
    /// Run the pacing thread under `SCHED_FIFO` at this priority (timed pacing only); if the
    /// system refuses, the replay goes on without it and says so.
    pub realtime_priority: Option<i32>,
    /// Hold a CPU latency QoS request of this many µs while timed pacing runs
    /// ([`crate::transport::CpuLatencyRequest`]); if the system refuses, the replay goes on and says so.
    pub cpu_latency_us: Option<u32>,
}

impl Options {
    pub fn new(inputs: Vec<PathBuf>) -> Self {
        Self {
            inputs,
            policy: Policy::Pass,
            pacing: None,
            speed: 1.0,
            start_s: 0.0,
            end_s: None,
            looping: false,
            line: None,
            link: "sonar".into(),
            comments: CommentMode::Report,
            origin: None,
            gap_threshold_s: 1.0,
            list_all_problems: false,
            realtime_priority: None,
            cpu_latency_us: None,
        }
    }
}

/// Why a replay could not start or had to stop.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    Sink(#[from] SinkError),
    #[error("no input logs given")]
    NoInputs,
    #[error("{what} must be {expected}, got {value:?}")]
    BadOption {
        what: &'static str,
        expected: &'static str,
        value: f64,
    },
    #[error("pacing by timestamps needs timestamps, but {path} has none ({format})")]
    NoTimestamps { path: PathBuf, format: Format },
    #[error("--loop reads every input again, but {path} is a pipe, FIFO or device, read once")]
    NotRereadable { path: PathBuf },
}

/// Where the line settings came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LineOrigin {
    CommandLine,
    SerialComment(Loc),
    Default,
}

/// What was found about one input when it was opened.
#[derive(Debug, Clone)]
pub struct InputInfo {
    pub path: PathBuf,
    pub format: Format,
    pub gzip: bool,
    pub size_bytes: u64,
}

/// Hears what happens during a replay (the CLI prints it; tests record it).
pub trait Observer {
    /// A problem, reported once (first pass only; at most [`LISTED_PER_KIND`] per kind
    /// unless `list_all_problems`).
    fn problem(&mut self, _problem: &Problem) {}
    /// A `#` comment (first pass, `--comments report`).
    fn comment(&mut self, _loc: &Loc, _text: &str) {}
    /// The instant deadlines count from.
    fn started(&mut self, _origin: Instant) {}
    /// A sentence went to the sink.
    fn sent(&mut self, _loc: &Loc, _bytes: &[u8], _sent: &Sent) {}
    /// Bytes read from the inputs so far in this pass, sentences sent so far.
    fn progress(&mut self, _read_bytes: u64, _sentences: u64) {}
    /// A pass over the inputs ended (before the next `--loop` pass).
    fn pass_done(&mut self, _pass: u64) {}
    /// Something worth telling the user that is not about a line.
    fn note(&mut self, _text: &str) {}
}

/// An observer that ignores everything.
#[derive(Debug, Default)]
pub struct Quiet;
impl Observer for Quiet {}

/// A replay ready to run.
#[derive(Debug)]
pub struct Replay {
    opts: Options,
    line: LineSettings,
    line_origin: LineOrigin,
    pacing: Pacing,
    inputs: Vec<InputInfo>,
    /// The sources opened by [`Replay::open`], read by the first pass: a pipe or FIFO is
    /// opened and read once.
    opened: Mutex<Option<Vec<Source>>>,
}

impl Replay {
    /// Checks the options, opens every input once to detect its format and read the
    /// `#Serial:` comments at its head, and resolves the pacing and line settings.
    pub fn open(opts: Options) -> Result<Self, ReplayError> {
        Self::open_until(opts, &Shutdown::new())
    }

    /// [`Self::open`], with reads of pipes, FIFOs and devices (then, and during
    /// [`Self::run`]) ended by `stop`.
    pub fn open_until(opts: Options, stop: &Shutdown) -> Result<Self, ReplayError> {
        if opts.inputs.is_empty() {
            return Err(ReplayError::NoInputs);
        }
        let positive = |what, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(ReplayError::BadOption {
                    what,
                    expected: "a positive number",
                    value,
                })
            }
        };
        if !SPEED_RANGE.contains(&opts.speed) {
            return Err(ReplayError::BadOption {
                what: "--speed",
                expected: "from 0.001 to 1000",
                value: opts.speed,
            });
        }
        if let Some(Pacing::Rate { per_s }) = opts.pacing {
            positive("--rate", per_s)?;
        }
        if !(opts.start_s.is_finite() && opts.start_s >= 0.0) {
            return Err(ReplayError::BadOption {
                what: "--start",
                expected: "zero or more seconds",
                value: opts.start_s,
            });
        }
        if let Some(end) = opts.end_s
            && !(end.is_finite() && end >= opts.start_s)
        {
            return Err(ReplayError::BadOption {
                what: "--end",
                expected: "at least --start",
                value: end,
            });
        }
        let mut inputs = Vec::new();
        let mut opened = Vec::new();
        let mut serial: Option<(LineSettings, Loc)> = None;
        for (i, path) in opts.inputs.iter().enumerate() {
            let source = Source::open_until(
                path,
                i,
                &opts.link,
                opts.comments,
                Arc::new(AtomicU64::new(0)),
                stop,
            )?;
            if opts.looping && !source.is_regular() {
                return Err(ReplayError::NotRereadable {
                    path: path.to_path_buf(),
                });
            }
            // Header comments come before the first line; `#Serial:` later is checked in run.
            if let Some(found) = source.header_serial() {
                serial.get_or_insert(found);
            }
            let file = source.path().to_path_buf();
            inputs.push(InputInfo {
                size_bytes: if source.is_regular() {
                    std::fs::metadata(&file).map(|m| m.len()).unwrap_or(0)
                } else {
                    0
                },
                path: file,
                format: source.format(),
                gzip: source.is_gzip(),
            });
            opened.push(source);
        }
        let (line, line_origin) = match (opts.line, serial) {
            (Some(line), _) => (line, LineOrigin::CommandLine),
            (None, Some((line, loc))) => (line, LineOrigin::SerialComment(loc)),
            (None, None) => (DEFAULT_LINE, LineOrigin::Default),
        };
        let all_timed = inputs.iter().all(|i| i.format.is_timed());
        let pacing = match opts.pacing {
            Some(Pacing::Timestamps) if !all_timed => {
                let untimed = inputs.iter().find(|i| !i.format.is_timed());
                if let Some(i) = untimed {
                    return Err(ReplayError::NoTimestamps {
                        path: i.path.clone(),
                        format: i.format,
                    });
                }
                Pacing::Timestamps
            }
            Some(p) => p,
            None if all_timed => Pacing::Timestamps,
            None => Pacing::Baud,
        };
        Ok(Self {
            opts,
            line,
            line_origin,
            pacing,
            inputs,
            opened: Mutex::new(Some(opened)),
        })
    }

    pub fn line_settings(&self) -> LineSettings {
        self.line
    }

    pub fn line_origin(&self) -> &LineOrigin {
        &self.line_origin
    }

    pub fn pacing(&self) -> Pacing {
        self.pacing
    }

    pub fn inputs(&self) -> &[InputInfo] {
        &self.inputs
    }

    pub fn options(&self) -> &Options {
        &self.opts
    }

    /// Total size of the inputs on disk (compressed size for gzip), for a progress bar.
    pub fn total_input_bytes(&self) -> u64 {
        self.inputs.iter().map(|i| i.size_bytes).sum()
    }
}

#[cfg(test)]
mod tests;
