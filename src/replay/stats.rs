//! What a replay did: counts, problems by kind, sentence types, time span and gaps.

use std::collections::BTreeMap;
use std::fmt;
use std::time::Duration;

use super::input::Loc;

/// How many of the largest gaps are listed.
pub const GAPS_LISTED: usize = 5;

/// How many sentence addresses get a row of their own in [`Summary::by_type`]; the rest are
/// counted in the [`OTHER_TYPES`] row, so a log of millions of distinct addresses costs a
/// fixed table.
pub const TYPES_LISTED: usize = 64;

/// The row of [`Summary::by_type`] for addresses beyond [`TYPES_LISTED`].
pub const OTHER_TYPES: &str = "(other)";

/// A gap between two consecutive sentences' log times.
#[derive(Debug, Clone, PartialEq)]
pub struct Gap {
    pub seconds: f64,
    /// The sentence after the gap.
    pub at: Loc,
}

/// The summary printed at the end (and by `--dry-run --stats`). Problem, type and time
/// statistics cover the first pass; sent counts cover every pass.
#[derive(Debug, Clone, Default)]
pub struct Summary {
    pub passes: u64,
    /// Physical lines read from the inputs (first pass). For a text log each is exactly one
    /// of: a data line ([`Self::lines_read`]), a comment ([`Self::comments`],
    /// [`Self::serial_comments`]) or a blank line. For a recording each is a chunk of the
    /// replayed link, another chunk or the header ([`Self::other_chunks`]), a bad line
    /// (counted in [`Self::lines_read`] and [`Self::lines_dropped`]) or a blank line.
    pub physical_lines: u64,
    /// Data lines (sentences) read, first pass. Each is exactly one of: sent (first pass),
    /// dropped, skipped before `--start`, or [`Self::past_end`].
    pub lines_read: u64,
    pub sentences_sent: u64,
    pub comments_sent: u64,
    pub bytes_sent: u64,
    pub lines_dropped: u64,
    pub lines_fixed: u64,
    pub lines_passed_with_problems: u64,
    pub checksum_failures: u64,
    pub skipped_before_start: u64,
    /// The sentence past `--end` that ended the pass (0 or 1 per pass).
    pub past_end: u64,
    /// `#Serial:` comment lines.
    pub serial_comments: u64,
    /// Recordings: chunk lines of other links or directions, and the header.
    pub other_chunks: u64,
    /// Inputs that ended with a read error (reported as `input cut short`).
    pub inputs_cut_short: u64,
    /// Problems by kind name (counted per line, listed once each).
    pub problems: BTreeMap<&'static str, u64>,
    /// Problems counted but not listed (beyond the per-kind listing limit, or once-per-file).
    pub problems_not_listed: u64,
    pub by_type: BTreeMap<String, u64>,
    pub comments: u64,
    pub link_messages_skipped: u64,
    pub blank_lines: u64,
    pub first_time_ns: Option<i64>,
    pub last_time_ns: Option<i64>,
    /// Largest gaps over [`Self::gap_threshold_s`] between consecutive sentences, largest
    /// first.
    pub gaps: Vec<Gap>,
    pub gap_threshold_s: f64,
    pub gaps_over_threshold: u64,
    /// Sentences that waited for the line to finish the one before, and the longest wait.
    pub line_waits: u64,
    pub line_wait_max_ns: u64,
    pub elapsed: Duration,
    /// Whether the pacing thread ran under `SCHED_FIFO`.
    pub realtime: bool,
    /// The CPU latency QoS request held while pacing (µs), if any.
    pub cpu_latency_us: Option<u32>,
    prev_time_ns: Option<i64>,
}

impl Summary {
    pub fn new(gap_threshold_s: f64) -> Self {
        Self {
            gap_threshold_s,
            ..Self::default()
        }
    }

    /// Notes a sentence's log time (first pass), tracking span and gaps.
    pub fn note_time(&mut self, time_ns: i64, loc: &Loc) {
        self.first_time_ns.get_or_insert(time_ns);
        self.last_time_ns = Some(self.last_time_ns.map_or(time_ns, |l| l.max(time_ns)));
        if let Some(prev) = self.prev_time_ns {
            // Two valid times can be further apart than i64 nanoseconds hold.
            let seconds = (i128::from(time_ns) - i128::from(prev)) as f64 * 1e-9;
            // Only gaps over the threshold are counted and listed, so the list never holds
            // more than the count, nor a time that went back.
            if seconds <= self.gap_threshold_s {
                self.prev_time_ns = Some(time_ns);
                return;
            }
            self.gaps_over_threshold += 1;
            let smallest = self.gaps.last().map_or(f64::NEG_INFINITY, |g| g.seconds);
            if self.gaps.len() < GAPS_LISTED || seconds > smallest {
                self.gaps.push(Gap {
                    seconds,
                    at: loc.clone(),
                });
                self.gaps.sort_by(|a, b| b.seconds.total_cmp(&a.seconds));
                self.gaps.truncate(GAPS_LISTED);
            }
        }
        self.prev_time_ns = Some(time_ns);
    }

    /// Counts one sentence of type `address` (at most [`TYPES_LISTED`] rows, then
    /// [`OTHER_TYPES`]).
    pub fn count_type(&mut self, address: String) {
        if let Some(n) = self.by_type.get_mut(&address) {
            *n += 1;
        } else if self.by_type.len() < TYPES_LISTED {
            self.by_type.insert(address, 1);
        } else {
            *self.by_type.entry(OTHER_TYPES.to_string()).or_default() += 1;
        }
    }

    pub fn problem_count(&self) -> u64 {
        self.problems.values().sum()
    }

    /// Bytes per second and sentences per second over the elapsed time.
    pub fn rates(&self) -> (f64, f64) {
        let s = self.elapsed.as_secs_f64().max(1e-9);
        (self.bytes_sent as f64 / s, self.sentences_sent as f64 / s)
    }

    /// The `--stats` block: sentence types, time span, gaps, checksum failures.
    pub fn stats_text(&self) -> String {
        let mut s = String::new();
        use fmt::Write as _;
        let _ = writeln!(s, "sentences by type:");
        for (address, n) in &self.by_type {
            let _ = writeln!(s, "  {address:<8} {n}");
        }
        match (self.first_time_ns, self.last_time_ns) {
            (Some(a), Some(b)) => {
                let _ = writeln!(
                    s,
                    "time span: {:.3} s ({:.3} .. {:.3})",
                    (i128::from(b) - i128::from(a)) as f64 * 1e-9,
                    a as f64 * 1e-9,
                    b as f64 * 1e-9
                );
                let _ = writeln!(
                    s,
                    "gaps over {} s: {}; largest:",
                    self.gap_threshold_s, self.gaps_over_threshold
                );
                for g in &self.gaps {
                    let _ = writeln!(s, "  {:.3} s before {}", g.seconds, g.at);
                }
            }
            _ => {
                let _ = writeln!(s, "time span: the logs have no timestamps");
            }
        }
        let _ = writeln!(s, "checksum failures: {}", self.checksum_failures);
        s
    }
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (bps, sps) = self.rates();
        writeln!(
            f,
            "replay summary: {} pass(es), {} lines in, {} sentence lines read, {} sentences sent ({} bytes) in {:.3} s ({:.0} B/s, {:.1} sentences/s)",
            self.passes,
            self.physical_lines,
            self.lines_read,
            self.sentences_sent,
            self.bytes_sent,
            self.elapsed.as_secs_f64(),
            bps,
            sps
        )?;
        writeln!(
            f,
            "  dropped {}, fixed {}, sent with problems {}, skipped before --start {}, past --end {}, comments {} ({} sent), #Serial comments {}, blank lines {}, link select/ack lines skipped {}, other recorded chunks {}",
            self.lines_dropped,
            self.lines_fixed,
            self.lines_passed_with_problems,
            self.skipped_before_start,
            self.past_end,
            self.comments,
            self.comments_sent,
            self.serial_comments,
            self.blank_lines,
            self.link_messages_skipped,
            self.other_chunks
        )?;
        if self.inputs_cut_short > 0 {
            writeln!(
                f,
                "  {} input(s) cut short by a read error (see \"input cut short\" above)",
                self.inputs_cut_short
            )?;
        }
        if self.line_waits > 0 {
            writeln!(
                f,
                "  {} sentences waited for a busy line (longest {:.3} ms)",
                self.line_waits,
                self.line_wait_max_ns as f64 * 1e-6
            )?;
        }
        if self.problems.is_empty() {
            writeln!(f, "  problems: none")?;
        } else {
            writeln!(
                f,
                "  problems: {} ({} counted but not listed above)",
                self.problem_count(),
                self.problems_not_listed
            )?;
            for (kind, n) in &self.problems {
                writeln!(f, "    {kind:<32} {n}")?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;
    use std::sync::Arc;

    use super::*;

    /// The gaps listed are gaps over the threshold, never more than counted: a time that went
    /// back, or a gap under the threshold, was listed under "largest".
    #[test]
    fn only_gaps_over_the_threshold_are_listed() {
        let mut s = Summary::new(1.0);
        let file: Arc<Path> = Arc::from(Path::new("a.log"));
        for (line, t_s) in [(1, 0.0), (2, 5.0), (3, 1.0), (4, 2.0), (5, 2.5)] {
            let loc = Loc {
                file: file.clone(),
                line,
            };
            s.note_time((t_s * 1e9) as i64, &loc);
        }
        assert_eq!(s.gaps_over_threshold, 1);
        let listed: Vec<(f64, u64)> = s.gaps.iter().map(|g| (g.seconds, g.at.line)).collect();
        assert_eq!(listed, vec![(5.0, 2)]);
        let text = s.stats_text();
        assert!(
            text.contains("gaps over 1 s: 1; largest:\n  5.000 s before a.log:2\n"),
            "{text}"
        );
    }
}
