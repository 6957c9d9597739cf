//! When each sentence is due: sans-IO, told the log time, never reads a clock.
//!
//! Every mode maps a sentence to a *log time* (nanoseconds from the first sentence of the
//! pass), then to a deadline `(log_time - start) / speed` counted from one start instant, so
//! sleep errors never accumulate. The deadline is when the sentence is handed to the line;
//! its bytes then take their real wire time at the configured baud (see
//! [`super::output::ByteSink`]), so a sentence due while the line is still busy waits for it,
//! and that wait is counted.
//!
//! | mode | log time of sentence *i* |
//! |---|---|
//! | `timestamps` | its timestamp minus the first timestamp |
//! | `rate` | *i* / rate |
//! | `baud` | the wire time of sentences 0..*i* back to back |
//! | `fast` | no deadline: as fast as the consumer reads (`--start`/`--end` use timestamps if the log has them, else the `baud` log time) |

use std::fmt;

/// How sentences are paced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// By the log's own timestamps.
    Timestamps,
    /// A fixed number of sentences per second.
    Rate { per_s: f64 },
    /// Back to back at the line's baud rate.
    Baud,
    /// No schedule: each write blocks until the consumer has room (back-pressure).
    Fast,
}

impl fmt::Display for Pacing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Pacing::Timestamps => f.write_str("by the log's timestamps"),
            Pacing::Rate { per_s } => write!(f, "{per_s} sentences/s"),
            Pacing::Baud => f.write_str("back to back at the line rate"),
            Pacing::Fast => f.write_str("as fast as the consumer reads"),
        }
    }
}

/// Where a sentence goes in the schedule.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placement {
    /// Before `--start`: not sent.
    Skip,
    /// After `--end`: the pass is over.
    Stop,
    /// Hand it to the line this many nanoseconds after the pass's start.
    Due { offset_ns: u64 },
    /// No deadline (fast mode, or a comment without a time of its own).
    Asap,
}

/// The schedule of one pass over the logs.
#[derive(Debug, Clone)]
pub struct Scheduler {
    pacing: Pacing,
    speed: f64,
    start_ns: i64,
    end_ns: Option<i64>,
    char_ns: u64,
    first_time_ns: Option<i64>,
    index: u64,
    wire_ns: i64,
    /// Latest timestamp log time so far: a time that goes back is due with the one before.
    latest_stamp_ns: i64,
}

impl Scheduler {
    /// `char_ns` is one character's wire time; `start_s`/`end_s` are log-time offsets.
    pub fn new(pacing: Pacing, speed: f64, start_s: f64, end_s: Option<f64>, char_ns: u64) -> Self {
        Self {
            pacing,
            speed,
            start_ns: (start_s * 1e9).round() as i64,
            end_ns: end_s.map(|e| (e * 1e9).round() as i64),
            char_ns,
            first_time_ns: None,
            index: 0,
            wire_ns: 0,
            latest_stamp_ns: 0,
        }
    }

    /// Places a data sentence of `len` bytes (with CR LF) whose log timestamp is `time_ns`.
    pub fn place(&mut self, time_ns: Option<i64>, len: usize) -> Placement {
        let stamped = time_ns.map(|t| {
            let since_first = t.saturating_sub(*self.first_time_ns.get_or_insert(t));
            self.latest_stamp_ns = self.latest_stamp_ns.max(since_first);
            self.latest_stamp_ns
        });
        let log_ns = match (self.pacing, stamped) {
            (Pacing::Timestamps, Some(t)) => t,
            (Pacing::Timestamps, None) => return Placement::Asap,
            (Pacing::Rate { per_s }, _) => (self.index as f64 * 1e9 / per_s).round() as i64,
            (Pacing::Baud, _) | (Pacing::Fast, None) => self.wire_ns,
            (Pacing::Fast, Some(t)) => t,
        };
        self.index += 1;
        self.wire_ns = self.wire_ns.saturating_add(
            i64::try_from(self.char_ns.saturating_mul(len as u64)).unwrap_or(i64::MAX),
        );
        if log_ns < self.start_ns {
            return Placement::Skip;
        }
        if self.end_ns.is_some_and(|end| log_ns > end) {
            return Placement::Stop;
        }
        if self.pacing == Pacing::Fast {
            return Placement::Asap;
        }
        let offset = ((log_ns - self.start_ns) as f64 / self.speed).round();
        Placement::Due {
            offset_ns: offset.max(0.0) as u64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CHAR: u64 = 2_083_334; // 4800 8N1

    fn due(p: Placement) -> u64 {
        match p {
            Placement::Due { offset_ns } => offset_ns,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn timestamps_count_from_the_first_and_scale_with_speed() {
        let mut s = Scheduler::new(Pacing::Timestamps, 2.0, 0.0, None, CHAR);
        assert_eq!(due(s.place(Some(10_000_000_000), 30)), 0);
        assert_eq!(due(s.place(Some(11_000_000_000), 30)), 500_000_000);
        // A time that goes back is due with the sentence before, never reordered or skipped.
        assert_eq!(due(s.place(Some(9_000_000_000), 30)), 500_000_000);
        assert_eq!(due(s.place(Some(12_000_000_000), 30)), 1_000_000_000);
    }

    #[test]
    fn rate_and_baud_ignore_timestamps() {
        let mut r = Scheduler::new(Pacing::Rate { per_s: 4.0 }, 1.0, 0.0, None, CHAR);
        let got: Vec<u64> = (0..3).map(|_| due(r.place(Some(0), 30))).collect();
        assert_eq!(got, vec![0, 250_000_000, 500_000_000]);
        let mut b = Scheduler::new(Pacing::Baud, 1.0, 0.0, None, CHAR);
        assert_eq!(due(b.place(None, 30)), 0);
        assert_eq!(due(b.place(None, 10)), 30 * CHAR);
        assert_eq!(due(b.place(None, 10)), 40 * CHAR);
    }

    #[test]
    fn start_and_end_cut_by_log_time() {
        let mut s = Scheduler::new(Pacing::Timestamps, 1.0, 1.0, Some(2.0), CHAR);
        let t = |s_: f64| Some((s_ * 1e9) as i64);
        assert_eq!(s.place(t(100.0), 30), Placement::Skip);
        assert_eq!(s.place(t(100.5), 30), Placement::Skip);
        assert_eq!(due(s.place(t(101.0), 30)), 0);
        assert_eq!(due(s.place(t(102.0), 30)), 1_000_000_000);
        assert_eq!(s.place(t(102.5), 30), Placement::Stop);
        let mut f = Scheduler::new(Pacing::Fast, 1.0, 0.0, Some(1.0), CHAR);
        assert_eq!(f.place(t(0.0), 30), Placement::Asap);
        assert_eq!(f.place(t(2.0), 30), Placement::Stop);
    }
}
