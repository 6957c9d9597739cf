//! One replay run: passes over the inputs, each line checked, placed in time and sent, every
//! line and problem counted in the [`Summary`].

use std::collections::{BTreeMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use super::input::{self, LogLine};
use super::{
    Action, Event, LISTED_PER_KIND, LineOrigin, Merger, Observer, Pacing, Placement, Problem,
    ProblemKind, Replay, ReplayError, Scheduler, Shutdown, Sink, SinkError, Source, Summary,
    sentence_check,
};
use crate::transport::LineSettings;

/// What handling one event asks of the pass.
enum Flow {
    Go,
    /// The line is past `--end`: the pass ends.
    PastEnd,
    /// A shutdown request ended the send: the replay ends.
    Stopped,
}

/// The state of one pass over the inputs.
struct Pass {
    first: bool,
    /// Bytes read from disk in this pass, for the progress report.
    read: Arc<AtomicU64>,
    sched: Scheduler,
    /// Where this pass starts on the output's timeline, ns from the replay's origin.
    base_ns: u64,
    sent: u64,
    last_due: Option<u64>,
}

impl Replay {
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
        let mut pass_no = 0u64;
        'passes: loop {
            let mut pass = Pass {
                first: pass_no == 0,
                read: Arc::new(AtomicU64::new(0)),
                sched: Scheduler::new(self.pacing, opts.speed, opts.start_s, opts.end_s, char_ns),
                base_ns,
                sent: 0,
                last_due: None,
            };
            let mut merger = Merger::new(self.pass_sources(&pass.read, stop)?);
            let mut stopped = false;
            while let Some(event) = merger.next_event()? {
                if stop.is_triggered() {
                    stopped = true;
                    break;
                }
                let flow = match event {
                    Event::Problem(p) => {
                        reporter.report(p, usize::MAX, pass.first, &mut summary, observer);
                        Flow::Go
                    }
                    Event::Comment { loc, text } => {
                        if pass.first {
                            observer.comment(&loc, &text);
                        }
                        Flow::Go
                    }
                    Event::Serial { loc, settings } => {
                        if settings != self.line && pass.first {
                            let problem = self.serial_conflict(loc, settings);
                            reporter.report(problem, usize::MAX, true, &mut summary, observer);
                        }
                        Flow::Go
                    }
                    Event::Line(line) => self.line(
                        line,
                        &mut pass,
                        &mut summary,
                        &mut reporter,
                        sink,
                        observer,
                        stop,
                    )?,
                };
                match flow {
                    Flow::Go => {}
                    Flow::PastEnd => break,
                    Flow::Stopped => {
                        stopped = true;
                        break;
                    }
                }
            }
            if pass.first {
                add_source_counts(&mut summary, merger.sources());
            }
            if stopped {
                break 'passes;
            }
            observer.progress(pass.read.load(Ordering::Relaxed), summary.sentences_sent);
            summary.passes += 1;
            observer.pass_done(pass_no);
            if !opts.looping || stop.is_triggered() || pass.sent == 0 {
                break;
            }
            base_ns = sink.free_at_ns();
            pass_no += 1;
        }
        summary.elapsed = origin.elapsed();
        Ok(summary)
    }

    /// The inputs of a pass: those [`Replay::open`] opened for the first (bytes read then are
    /// not in the progress count: only the few lines of format detection), opened again for
    /// each later one.
    fn pass_sources(
        &self,
        read: &Arc<AtomicU64>,
        stop: &Shutdown,
    ) -> Result<Vec<Source>, ReplayError> {
        let opts = &self.opts;
        if let Some(sources) = self.opened.lock().ok().and_then(|mut o| o.take()) {
            return Ok(sources);
        }
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
        Ok(sources)
    }

    /// The problem of a `#Serial:` comment that disagrees with the line settings in force.
    fn serial_conflict(&self, loc: input::Loc, settings: LineSettings) -> Problem {
        let why = match self.line_origin {
            LineOrigin::CommandLine => "--line given",
            _ => "the first #Serial: applies to the whole replay",
        };
        Problem {
            loc,
            kind: ProblemKind::SerialConflict {
                found: settings.to_string(),
                in_force: self.line.to_string(),
                why,
            },
            action: Action::Ignored,
        }
    }

    /// Checks one line, counts and reports what the check found, and sends what it kept.
    #[allow(clippy::too_many_arguments)]
    fn line(
        &self,
        line: LogLine,
        pass: &mut Pass,
        summary: &mut Summary,
        reporter: &mut Reporter,
        sink: &mut dyn Sink,
        observer: &mut dyn Observer,
        stop: &Shutdown,
    ) -> Result<Flow, ReplayError> {
        let first = pass.first;
        if first && line.kind == input::LineKind::Data {
            summary.lines_read += 1;
        }
        let checked = match line.kind {
            input::LineKind::Data => sentence_check::check_line(
                &line.bytes,
                line.terminator,
                line.overflow,
                self.opts.policy,
            ),
            input::LineKind::Comment => sentence_check::Checked {
                out: Some([&line.bytes[..], b"\r\n"].concat()),
                ..Default::default()
            },
        };
        if first {
            count_check(summary, &checked);
        }
        for (kind, action) in checked.problems {
            let problem = Problem {
                loc: line.loc.clone(),
                kind,
                action,
            };
            reporter.report(problem, line.input, first, summary, observer);
        }
        let Some(out) = checked.out else {
            return Ok(Flow::Go);
        };
        let is_comment = line.kind == input::LineKind::Comment;
        let placement = if is_comment {
            Placement::Asap
        } else {
            pass.sched.place(line.time_ns, out.len())
        };
        let due = match placement {
            Placement::Skip => {
                if first {
                    summary.skipped_before_start += 1;
                }
                return Ok(Flow::Go);
            }
            Placement::Stop => {
                if first {
                    summary.past_end += 1;
                }
                return Ok(Flow::PastEnd);
            }
            Placement::Due { offset_ns } => Some(pass.base_ns.saturating_add(offset_ns)),
            // Without a deadline of its own, a line follows the one before.
            Placement::Asap if self.pacing == Pacing::Fast => None,
            Placement::Asap => Some(pass.last_due.unwrap_or(pass.base_ns)),
        };
        let sent = match sink.send(&out, due, stop) {
            Ok(s) => s,
            Err(SinkError::Stopped) => return Ok(Flow::Stopped),
            Err(e) => return Err(e.into()),
        };
        pass.last_due = due.or(pass.last_due);
        pass.sent += 1;
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
            summary.line_wait_max_ns = summary.line_wait_max_ns.max(sent.line_wait_ns);
        }
        observer.sent(&line.loc, &out, &sent);
        // Every sentence when paced (a few per second); in batches when fast.
        if self.pacing != Pacing::Fast || pass.sent.is_multiple_of(256) {
            observer.progress(pass.read.load(Ordering::Relaxed), summary.sentences_sent);
        }
        Ok(Flow::Go)
    }
}

/// Counts a checked line of the first pass as dropped, fixed or passed with problems.
fn count_check(summary: &mut Summary, checked: &sentence_check::Checked) {
    let mut fixed = false;
    let mut passed_bad = false;
    for (kind, action) in &checked.problems {
        summary.checksum_failures += u64::from(kind.is_checksum());
        fixed |= matches!(action, Action::Fixed { .. } | Action::JunkRemoved);
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

/// Adds the inputs' own counts (lines that never became events) to the first pass's summary.
fn add_source_counts(summary: &mut Summary, sources: &[Source]) {
    for s in sources {
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
