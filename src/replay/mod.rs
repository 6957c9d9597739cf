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
pub mod sentence_check;
pub mod stats;

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
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
    #[error("{what} must be {expected}, got {value}")]
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

    /// Runs the replay into `sink` until the logs end (or, with `--loop`, until `stop`).
    /// A shutdown request ends it early with the summary so far.
    pub fn run(
        &self,
        sink: &mut dyn Sink,
        observer: &mut dyn Observer,
        stop: &Shutdown,
    ) -> Result<Summary, ReplayError> {
        let opts = &self.opts;
        let timed = self.pacing != Pacing::Fast;
        let wake = timed.then(|| {
            crate::transport::WakeGuard::acquire(opts.cpu_latency_us, opts.realtime_priority)
        });
        for refusal in wake.iter().flat_map(|w| w.refusals()) {
            observer.note(refusal);
        }
        let result = self.run_inner(sink, observer, stop);
        let realtime = wake
            .as_ref()
            .is_some_and(|w| w.realtime_priority().is_some());
        let cpu_latency_us = wake.as_ref().and_then(|w| w.cpu_latency_us());
        drop(wake);
        result.map(|mut s| {
            s.realtime = realtime;
            s.cpu_latency_us = cpu_latency_us;
            s
        })
    }

    fn run_inner(
        &self,
        sink: &mut dyn Sink,
        observer: &mut dyn Observer,
        stop: &Shutdown,
    ) -> Result<Summary, ReplayError> {
        let opts = &self.opts;
        let origin = opts.origin.unwrap_or_else(Instant::now);
        sink.begin(origin);
        observer.started(origin);
        let mut summary = Summary::new(opts.gap_threshold_s);
        let mut reporter = Reporter {
            listed: BTreeMap::new(),
            once: HashSet::new(),
            list_all: opts.list_all_problems,
        };
        let mut base_ns = 0u64;
        let char_ns = self.line.char_time_ns();
        let mut pass = 0u64;
        'passes: loop {
            let first = pass == 0;
            let read = Arc::new(AtomicU64::new(0));
            let held = self.opened.lock().ok().and_then(|mut o| o.take());
            let sources = match held {
                // The first pass reads what `open` opened (bytes read then are not in the
                // progress count: only the few lines of format detection).
                Some(sources) => sources,
                None => {
                    let mut sources = Vec::with_capacity(opts.inputs.len());
                    for (i, path) in opts.inputs.iter().enumerate() {
                        sources.push(Source::open_until(
                            path,
                            i,
                            &opts.link,
                            opts.comments,
                            read.clone(),
                            stop,
                        )?);
                    }
                    sources
                }
            };
            let mut merger = Merger::new(sources);
            let mut sched =
                Scheduler::new(self.pacing, opts.speed, opts.start_s, opts.end_s, char_ns);
            let mut sent_this_pass = 0u64;
            let mut last_due: Option<u64> = None;
            let mut stopped = false;
            while let Some(event) = merger.next_event()? {
                if stop.is_triggered() {
                    stopped = true;
                    break;
                }
                match event {
                    Event::Problem(p) => {
                        reporter.report(p, usize::MAX, first, &mut summary, observer)
                    }
                    Event::Comment { loc, text } => {
                        if first {
                            observer.comment(&loc, &text);
                        }
                    }
                    Event::Serial { loc, settings } => {
                        if settings != self.line && first {
                            let why = match self.line_origin {
                                LineOrigin::CommandLine => "--line given",
                                _ => "the first #Serial: applies to the whole replay",
                            };
                            let problem = Problem {
                                loc,
                                kind: ProblemKind::SerialConflict {
                                    found: settings.to_string(),
                                    in_force: self.line.to_string(),
                                    why,
                                },
                                action: Action::Ignored,
                            };
                            reporter.report(problem, usize::MAX, first, &mut summary, observer);
                        }
                    }
                    Event::Line(line) => {
                        if first && line.kind == input::LineKind::Data {
                            summary.lines_read += 1;
                        }
                        let checked = match line.kind {
                            input::LineKind::Data => sentence_check::check_line(
                                &line.bytes,
                                line.terminator,
                                line.overflow,
                                opts.policy,
                            ),
                            input::LineKind::Comment => sentence_check::Checked {
                                out: Some([&line.bytes[..], b"\r\n"].concat()),
                                ..Default::default()
                            },
                        };
                        if first {
                            let mut fixed = false;
                            let mut passed_bad = false;
                            for (kind, action) in &checked.problems {
                                summary.checksum_failures += u64::from(kind.is_checksum());
                                fixed |=
                                    matches!(action, Action::Fixed { .. } | Action::JunkRemoved);
                                passed_bad |= *action == Action::Passed;
                            }
                            if checked.out.is_none() {
                                summary.lines_dropped += 1;
                            } else if fixed {
                                summary.lines_fixed += 1;
                            } else if passed_bad {
                                summary.lines_passed_with_problems += 1;
                            }
                        }
                        for (kind, action) in checked.problems {
                            let problem = Problem {
                                loc: line.loc.clone(),
                                kind,
                                action,
                            };
                            reporter.report(problem, line.input, first, &mut summary, observer);
                        }
                        if let Some(out) = checked.out {
                            let is_comment = line.kind == input::LineKind::Comment;
                            let placement = if is_comment {
                                Placement::Asap
                            } else {
                                sched.place(line.time_ns, out.len())
                            };
                            let due = match placement {
                                Placement::Skip => {
                                    if first {
                                        summary.skipped_before_start += 1;
                                    }
                                    None
                                }
                                Placement::Stop => {
                                    if first {
                                        summary.past_end += 1;
                                    }
                                    break;
                                }
                                Placement::Due { offset_ns } => {
                                    Some(Some(base_ns.saturating_add(offset_ns)))
                                }
                                // Without a deadline of its own, a line follows the one before.
                                Placement::Asap if self.pacing == Pacing::Fast => Some(None),
                                Placement::Asap => Some(Some(last_due.unwrap_or(base_ns))),
                            };
                            if let Some(due) = due {
                                let sent = match sink.send(&out, due, stop) {
                                    Ok(s) => s,
                                    Err(SinkError::Stopped) => {
                                        stopped = true;
                                        break;
                                    }
                                    Err(e) => return Err(e.into()),
                                };
                                last_due = due.or(last_due);
                                sent_this_pass += 1;
                                summary.bytes_sent += out.len() as u64;
                                if is_comment {
                                    summary.comments_sent += 1;
                                } else {
                                    summary.sentences_sent += 1;
                                    if first {
                                        if let Some(address) = checked.address {
                                            summary.count_type(address);
                                        }
                                        if let Some(t) = line.time_ns {
                                            summary.note_time(t, &line.loc);
                                        }
                                    }
                                }
                                if sent.line_wait_ns > 0 {
                                    summary.line_waits += 1;
                                    summary.line_wait_max_ns =
                                        summary.line_wait_max_ns.max(sent.line_wait_ns);
                                }
                                observer.sent(&line.loc, &out, &sent);
                                // Every sentence when paced (a few per second); in batches when fast.
                                if self.pacing != Pacing::Fast || sent_this_pass.is_multiple_of(256)
                                {
                                    observer.progress(
                                        read.load(Ordering::Relaxed),
                                        summary.sentences_sent,
                                    );
                                }
                            }
                        }
                    }
                }
            }
            if first {
                for s in merger.sources() {
                    summary.link_messages_skipped += s.link_messages_skipped;
                    summary.blank_lines += s.blank_lines;
                    summary.comments += s.comment_lines;
                    summary.physical_lines += s.physical_lines();
                    summary.other_chunks += s.other_chunks;
                    summary.lines_read += s.unplaceable_lines;
                    summary.lines_dropped += s.unplaceable_lines;
                    summary.serial_comments += s.serial_lines;
                    summary.inputs_cut_short += u64::from(s.cut_short);
                }
            }
            if stopped {
                break 'passes;
            }
            observer.progress(read.load(Ordering::Relaxed), summary.sentences_sent);
            summary.passes += 1;
            observer.pass_done(pass);
            if !opts.looping || stop.is_triggered() || sent_this_pass == 0 {
                break;
            }
            base_ns = sink.free_at_ns();
            pass += 1;
        }
        summary.elapsed = origin.elapsed();
        Ok(summary)
    }
}

/// Lists each problem once: first pass only, once per file for once-per-file kinds, and at
/// most [`LISTED_PER_KIND`] per kind unless told to list all. Every one is counted.
struct Reporter {
    listed: BTreeMap<&'static str, u64>,
    once: HashSet<(usize, &'static str)>,
    list_all: bool,
}

impl Reporter {
    fn report(
        &mut self,
        problem: Problem,
        input: usize,
        first_pass: bool,
        summary: &mut Summary,
        observer: &mut dyn Observer,
    ) {
        if !first_pass {
            return;
        }
        let name = problem.kind.name();
        *summary.problems.entry(name).or_default() += 1;
        let shown = self.listed.entry(name).or_default();
        let limited = !self.list_all && *shown >= LISTED_PER_KIND;
        let repeat = problem.kind.once_per_file() && !self.once.insert((input, name));
        if limited || repeat {
            summary.problems_not_listed += 1;
        } else {
            *shown += 1;
            observer.problem(&problem);
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;
    use std::sync::Mutex;

    use super::*;
    use crate::record::{Direction, Recorder};

    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// What the daemon's recorder writes, replay sends back: the sonar link's `tx` sentences,
    /// reassembled across chunk boundaries, without the select/ack traffic or other links.
    #[test]
    fn a_recording_made_by_the_recorder_replays_its_sonar_sentences() {
        let tmp = crate::scratch::dir("replay-rec");
        let dir = tmp.path().join("rec");
        let meta = crate::record::Meta::new(1, "lockstep", 1.0, "test");
        let rec = Recorder::start(&dir, &meta, "").unwrap();
        let a = b"$SDDBT,6.6,f,2.0,M,1.1,F*04\r\n";
        let b = b"$SDDPT,2.0,0.5*50\r\n";
        rec.bytes(0.100, "sonar", Direction::Rx, b"@S1\r");
        rec.bytes(0.101, "sonar", Direction::Tx, b"@A1\r\n$SDDBT,6.6");
        rec.bytes(0.102, "sensor", Direction::Tx, &[0xEB, 0x90, 0x00]);
        rec.bytes(0.103, "sonar", Direction::Tx, b",f,2.0,M,1.1,F*04\r\n$SDD");
        rec.bytes(0.350, "sonar", Direction::Tx, b"PT,2.0,0.5*50\r\n");
        rec.finish().unwrap();

        let mut opts = Options::new(vec![dir.clone()]);
        opts.pacing = Some(Pacing::Fast);
        let replay = Replay::open(opts).unwrap();
        assert_eq!(replay.inputs()[0].format, Format::Recording);
        let out = Shared::default();
        let mut sink = ByteSink::new(Port::Writer(Box::new(out.clone())), &DEFAULT_LINE);
        let summary = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
        assert_eq!(*out.0.lock().unwrap(), [&a[..], &b[..]].concat());
        assert_eq!(summary.link_messages_skipped, 1);
        assert_eq!(summary.problem_count(), 0);
        assert_eq!(summary.first_time_ns, Some(101_000_000));
        assert_eq!(summary.last_time_ns, Some(103_000_000));
    }

    /// `--start`/`--end` and the speed factor act on log time. Checked on the modelled line
    /// times the sink reports.
    #[test]
    fn start_end_speed_and_loop_shape_the_schedule() {
        #[derive(Default)]
        struct Times(Vec<(u64, u64)>);
        impl Observer for Times {
            fn sent(&mut self, loc: &Loc, _b: &[u8], sent: &Sent) {
                self.0.push((loc.line, sent.start_ns.unwrap()));
            }
        }
        let tmp = crate::scratch::dir("replay-se");
        let dir = tmp.path();
        let log = dir.join("t.log");
        let text: String = (0..6)
            .map(|i| format!("{}.000 $SDDPT,1.{i},0.3*00\r\n", 100 + i))
            .collect();
        std::fs::write(&log, text).unwrap();
        let mut opts = Options::new(vec![log]);
        opts.start_s = 1.0;
        opts.end_s = Some(3.0);
        opts.speed = 50.0;
        opts.line = Some(LineSettings::n81(115_200));
        let replay = Replay::open(opts).unwrap();
        assert_eq!(replay.pacing(), Pacing::Timestamps);
        let mut sink = ByteSink::new(
            Port::Writer(Box::new(std::io::sink())),
            &replay.line_settings(),
        );
        let mut times = Times::default();
        let summary = replay.run(&mut sink, &mut times, &Shutdown::new()).unwrap();
        // Lines 2..=4 (log 1 s, 2 s, 3 s) at 20 ms intervals (speed 50).
        assert_eq!(times.0, vec![(2, 0), (3, 20_000_000), (4, 40_000_000)]);
        assert_eq!(summary.skipped_before_start, 1);
    }

    /// `--loop` starts the next pass when the line is free, and keeps the schedule of the
    /// first; problems are listed on the first pass only.
    #[test]
    fn loop_passes_follow_each_other_on_the_line() {
        struct StopAfter(usize, Shutdown, Vec<u64>, usize);
        impl Observer for StopAfter {
            fn sent(&mut self, _loc: &Loc, _b: &[u8], sent: &Sent) {
                self.2.push(sent.start_ns.unwrap());
                if self.2.len() == self.0 {
                    self.1.trigger();
                }
            }
            fn problem(&mut self, _p: &Problem) {
                self.3 += 1;
            }
        }
        let tmp = crate::scratch::dir("replay-loop");
        let dir = tmp.path();
        let log = dir.join("l.log");
        std::fs::write(&log, "0.0 $A*41\r\n0.01 $B*00\r\n").unwrap();
        let mut opts = Options::new(vec![log]);
        opts.looping = true;
        opts.line = Some(LineSettings::n81(115_200));
        let replay = Replay::open(opts).unwrap();
        let stop = Shutdown::new();
        let mut obs = StopAfter(5, stop.clone(), Vec::new(), 0);
        let mut sink = ByteSink::new(
            Port::Writer(Box::new(std::io::sink())),
            &replay.line_settings(),
        );
        let summary = replay.run(&mut sink, &mut obs, &stop).unwrap();
        let char_ns = LineSettings::n81(115_200).char_time_ns();
        let pass_ns = 10_000_000 + 7 * char_ns; // B starts at 10 ms and takes 7 characters
        assert_eq!(
            obs.2,
            vec![0, 10_000_000, pass_ns, pass_ns + 10_000_000, 2 * pass_ns]
        );
        assert_eq!(
            obs.3, 1,
            "the bad checksum of $B is listed once, not every pass"
        );
        assert_eq!(summary.problems.get("checksum mismatch"), Some(&1));
    }

    /// `--comments send` passes comments through as lines, in file order, as gpsfake does;
    /// `#Serial:` is never sent, and a conflicting later one is reported.
    #[test]
    fn comments_are_sent_in_place_when_asked() {
        let tmp = crate::scratch::dir("replay-cm");
        let dir = tmp.path();
        let log = dir.join("c.log");
        std::fs::write(
            &log,
            "#Serial: 9600 8N1\n$A*41\r\n# between\r\n#Serial: 4800 8N1\n$A*41\r\n",
        )
        .unwrap();
        let mut opts = Options::new(vec![log]);
        opts.comments = CommentMode::Send;
        opts.pacing = Some(Pacing::Fast);
        let replay = Replay::open(opts).unwrap();
        assert_eq!(replay.line_settings(), LineSettings::n81(9600));
        let out = Shared::default();
        let mut sink = ByteSink::new(Port::Writer(Box::new(out.clone())), &replay.line_settings());
        let summary = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
        assert_eq!(*out.0.lock().unwrap(), b"$A*41\r\n# between\r\n$A*41\r\n");
        assert_eq!(summary.comments_sent, 1);
        assert_eq!(summary.sentences_sent, 2);
        assert_eq!(summary.problems.get("#Serial conflict"), Some(&1));
    }

    /// Every line of a text log lands in one counter of the summary, bad timestamps among
    /// the dropped, comments counted whatever `--comments` does with them.
    #[test]
    fn the_summary_accounts_for_every_line_once() {
        let tmp = crate::scratch::dir("replay-acct");
        let log = tmp.path().join("a.log");
        std::fs::write(
            &log,
            "#Serial: 9600 8N1\n# c1\n\n0.0 $A*41\r\nbad $A*41\r\n1.0 $B*00\r\n\n# c2\n2.0 $A*41\r3.0 $A*41\r\n9.0 $A*41\r\n",
        )
        .unwrap();
        for mode in [CommentMode::Report, CommentMode::Send, CommentMode::Ignore] {
            let mut opts = Options::new(vec![log.clone()]);
            opts.pacing = Some(Pacing::Fast);
            opts.policy = Policy::Drop;
            opts.comments = mode;
            opts.start_s = 1.0;
            opts.end_s = Some(5.0);
            let replay = Replay::open(opts).unwrap();
            let out = Shared::default();
            let mut sink = ByteSink::new(Port::Writer(Box::new(out.clone())), &DEFAULT_LINE);
            let s = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
            assert_eq!(s.physical_lines, 11, "{mode:?}");
            assert_eq!((s.comments, s.serial_comments, s.blank_lines), (2, 1, 2));
            assert_eq!(s.lines_read, 6, "{mode:?}: 5 timed lines and `bad`");
            assert_eq!(
                s.physical_lines,
                s.lines_read + s.comments + s.serial_comments + s.blank_lines
            );
            // 0.0 skipped, `bad` and the bad checksum dropped, 2.0 and 3.0 sent, 9.0 past --end.
            assert_eq!(
                (
                    s.skipped_before_start,
                    s.lines_dropped,
                    s.sentences_sent,
                    s.past_end
                ),
                (1, 2, 2, 1),
                "{mode:?}"
            );
            let comments_sent = if mode == CommentMode::Send { 2 } else { 0 };
            assert_eq!(s.comments_sent, comments_sent, "{mode:?}");
            assert_eq!(s.problems.get("CR without LF"), Some(&1), "{mode:?}");
        }
    }

    /// `--speed` outside its range is refused; at the ends of the range a schedule is finite.
    #[test]
    fn speed_has_a_range() {
        let tmp = crate::scratch::dir("replay-speed");
        let log = tmp.path().join("a.log");
        std::fs::write(&log, "0 $A*41\r\n").unwrap();
        for bad in [1e-300, 0.0009, 1000.5, f64::INFINITY, f64::NAN, -1.0] {
            let mut opts = Options::new(vec![log.clone()]);
            opts.speed = bad;
            let err = Replay::open(opts).unwrap_err().to_string();
            assert!(
                err.contains("--speed must be from 0.001 to 1000"),
                "{bad}: {err}"
            );
        }
        let mut sched = Scheduler::new(Pacing::Timestamps, 0.001, 0.0, None, 1000);
        assert_eq!(
            sched.place(Some(i64::MIN), 10),
            Placement::Due { offset_ns: 0 }
        );
        assert!(
            matches!(sched.place(Some(i64::MAX), 10), Placement::Due { offset_ns } if offset_ns == u64::MAX)
        );
    }

    /// A pipe or FIFO is opened once and read once: by `open` for the format and `#Serial:`,
    /// then by the first pass. `--loop` over one is refused.
    #[test]
    fn a_fifo_is_read_once() {
        let tmp = crate::scratch::dir("replay-fifo");
        let fifo = tmp.path().join("log.fifo");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let path = fifo.clone();
        let writer = std::thread::spawn(move || {
            let text: String = std::iter::once("#Serial: 9600 8N1\n".to_string())
                .chain((0..500).map(|i| format!("$GPXXX,{i}*00\r\n")))
                .collect();
            std::fs::write(path, text).unwrap();
        });
        let (tx, rx) = std::sync::mpsc::channel();
        let reader_path = fifo.clone();
        std::thread::spawn(move || {
            let mut opts = Options::new(vec![reader_path]);
            opts.pacing = Some(Pacing::Fast);
            let replay = Replay::open(opts).unwrap();
            let line = replay.line_settings();
            let mut sink = ByteSink::new(Port::Writer(Box::new(std::io::sink())), &line);
            let s = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
            let _ = tx.send((line, s.sentences_sent, s.physical_lines));
        });
        let (line, sent, lines) = rx
            .recv_timeout(std::time::Duration::from_secs(10))
            .expect("the replay of a FIFO ended");
        writer.join().unwrap();
        assert_eq!((line, sent, lines), (LineSettings::n81(9600), 500, 501));

        let writer = {
            let path = fifo.clone();
            std::thread::spawn(move || std::fs::write(path, "$A*41\r\n").unwrap())
        };
        let mut opts = Options::new(vec![fifo]);
        opts.looping = true;
        let err = Replay::open(opts).unwrap_err().to_string();
        writer.join().unwrap();
        assert!(err.contains("--loop") && err.contains("log.fifo"), "{err}");
    }

    /// A log of many distinct addresses costs a fixed table of types.
    #[test]
    fn sentence_types_have_a_capped_table() {
        let tmp = crate::scratch::dir("replay-types");
        let log = tmp.path().join("a.log");
        let text: String = (0..1000).map(|i| format!("$X{i:05},1*00\r\n")).collect();
        std::fs::write(&log, text).unwrap();
        let mut opts = Options::new(vec![log]);
        opts.pacing = Some(Pacing::Fast);
        let replay = Replay::open(opts).unwrap();
        let mut sink = ByteSink::new(Port::Writer(Box::new(std::io::sink())), &DEFAULT_LINE);
        let s = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
        assert_eq!(s.by_type.len(), stats::TYPES_LISTED + 1);
        assert_eq!(
            s.by_type.get(stats::OTHER_TYPES),
            Some(&(1000 - stats::TYPES_LISTED as u64))
        );
        assert_eq!(s.by_type.values().sum::<u64>(), 1000);
    }
}
