//! `bytes.tsv` inputs: the `tx` chunks of one recorded link joined and cut into lines.

use std::io;

use crate::record::{Direction, parse_chunk};

use super::super::problem::{Action, Problem, ProblemKind};
use super::{Event, MAX_PHYSICAL_LINE, Source, Terminator};

/// A chunk's `sim_s` in whole nanoseconds, or `None` when it is no simulated time: not a
/// number, infinite, negative, or beyond what `i64` nanoseconds hold (about 292 years). The
/// recorder writes times from 0 up; anything else in the file was not written by it.
pub fn sim_time_ns(sim_s: f64) -> Option<i64> {
    let ns = (sim_s * 1e9).round();
    // `i64::MAX as f64` rounds up to 2^63, which is itself out of range: hence `<`.
    (ns >= 0.0 && ns < i64::MAX as f64).then_some(ns as i64)
}

impl Source {
    pub(super) fn step_recording(&mut self) -> io::Result<()> {
        let Some(p) = self.read_physical()? else {
            self.done = true;
            self.flush_pending(Terminator::Eof);
            return Ok(());
        };
        let loc = self.loc(p.line_no);
        let text = String::from_utf8_lossy(&p.bytes).into_owned();
        self.buf = p.bytes;
        if text.trim().is_empty() && p.total <= MAX_PHYSICAL_LINE {
            self.blank_lines += 1;
            return Ok(());
        }
        let chunk = match parse_chunk(&text, loc.line as usize) {
            Ok(c) if p.total <= MAX_PHYSICAL_LINE => c,
            Ok(_) => {
                self.unplaceable_lines += 1;
                self.queue.push_back(Event::Problem(Problem {
                    loc,
                    kind: ProblemKind::BadRecordLine {
                        reason: format!("line of {} bytes is too long", p.total),
                    },
                    action: Action::Dropped,
                }));
                return Ok(());
            }
            Err(e) => {
                self.unplaceable_lines += 1;
                self.queue.push_back(Event::Problem(Problem {
                    loc,
                    kind: ProblemKind::BadRecordLine { reason: e.reason },
                    action: Action::Dropped,
                }));
                return Ok(());
            }
        };
        if chunk.dir != Direction::Tx || chunk.link != self.link {
            self.other_chunks += 1;
            return Ok(());
        }
        let Some(time_ns) = sim_time_ns(chunk.sim_s) else {
            self.unplaceable_lines += 1;
            self.queue.push_back(Event::Problem(Problem {
                loc,
                kind: ProblemKind::BadRecordTime {
                    found_s: chunk.sim_s,
                },
                action: Action::Dropped,
            }));
            return Ok(());
        };
        for &b in &chunk.data {
            if self.pending_start.is_none() {
                self.pending_start = Some((loc.clone(), time_ns));
            }
            if b == b'\n' {
                let terminator = if self.pending.last() == Some(&b'\r') {
                    self.pending.pop();
                    Terminator::CrLf
                } else {
                    Terminator::Lf
                };
                self.flush_pending(terminator);
            } else {
                if self.pending.len() < MAX_PHYSICAL_LINE {
                    self.pending.push(b);
                }
                self.pending_total += 1;
            }
        }
        Ok(())
    }

    pub(super) fn flush_pending(&mut self, terminator: Terminator) {
        let Some((loc, time_ns)) = self.pending_start.take() else {
            return;
        };
        let total = std::mem::take(&mut self.pending_total);
        let bytes = std::mem::take(&mut self.pending);
        if bytes.first() == Some(&b'@') && total <= MAX_PHYSICAL_LINE {
            self.link_messages_skipped += 1;
            return;
        }
        self.check_time(&loc, time_ns);
        let overflow = (total > MAX_PHYSICAL_LINE).then_some(total);
        self.push_data(loc, Some(time_ns), bytes, terminator, overflow);
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use proptest::prelude::*;

    use super::super::CommentMode;
    use super::*;
    use crate::record::BYTES_HEADER;

    /// A numeric cell of a `bytes.tsv` row as text: ordinary times, any `f64` (NaN, the
    /// infinities, subnormals), and the other spellings Rust's float parser accepts.
    fn number_text() -> impl Strategy<Value = String> {
        prop_oneof![
            (0.0f64..1e6).prop_map(|v| format!("{v:.9}")),
            (-1e6f64..0.0).prop_map(|v| format!("{v:.9}")),
            any::<f64>().prop_map(|v| v.to_string()),
            any::<f64>().prop_map(|v| format!("{v:e}")),
            prop::sample::select(vec![
                "NaN",
                "nan",
                "inf",
                "-inf",
                "+infinity",
                "Infinity",
                "1e400",
                "-0",
                "1e-400",
                "-0.000000001",
                "9223372036.854775",
                "9223372037",
            ])
            .prop_map(str::to_string),
        ]
    }

    proptest! {
        /// Every row of a recording whose `sim_s` is no simulated time is reported as a bad
        /// timestamp and dropped; every other row is sent at its own time. `wall_unix_s` is
        /// not read by replay, whatever it holds. (Rows timed `inf`, `NaN` or `-1` were sent,
        /// and an `inf` row stalled a paced replay.)
        #[test]
        fn rows_without_a_simulated_time_are_bad_timestamps(
            rows in prop::collection::vec((number_text(), number_text()), 1..12)
        ) {
            let mut tsv = format!("{BYTES_HEADER}\n");
            for (i, (sim, wall)) in rows.iter().enumerate() {
                let sentence = format!("$GPXXX,{i}*00\r\n");
                tsv += &format!("{sim}\t{wall}\tsonar\ttx\t{}\n", hex::encode(sentence));
            }
            let mut source = Source::from_reader(
                Path::new("bytes.tsv"),
                Box::new(std::io::Cursor::new(tsv.into_bytes())),
                "sonar",
                CommentMode::Report,
            )
            .unwrap();
            let mut sent = Vec::new();
            let mut bad = Vec::new();
            while let Some(event) = source.next_event().unwrap() {
                match event {
                    Event::Line(l) => sent.push((l.loc.line, l.time_ns)),
                    Event::Problem(p) => {
                        if let ProblemKind::BadRecordTime { .. } = p.kind {
                            prop_assert_eq!(&p.action, &Action::Dropped);
                            prop_assert!(p.to_string().contains("column `sim_s`"), "{}", p);
                            bad.push(p.loc.line);
                        } else if !matches!(p.kind, ProblemKind::TimeWentBack { .. }) {
                            prop_assert!(false, "unexpected problem {}", p);
                        }
                    }
                    other => prop_assert!(false, "unexpected event {:?}", other),
                }
            }
            let mut want_sent = Vec::new();
            let mut want_bad = Vec::new();
            for (i, (sim, _)) in rows.iter().enumerate() {
                let line = i as u64 + 2;
                // The rule written out again, not through `sim_time_ns`: a time from 0 up
                // whose nanoseconds fit an `i64`.
                let value: f64 = sim.parse().unwrap();
                let ns = (value * 1e9).round();
                if value.is_finite() && (0.0..9.223_372_036_854_776e18).contains(&ns) {
                    want_sent.push((line, Some(ns as i64)));
                } else {
                    want_bad.push(line);
                }
            }
            prop_assert_eq!(&sent, &want_sent);
            prop_assert_eq!(&bad, &want_bad);
            prop_assert_eq!(source.unplaceable_lines, want_bad.len() as u64);
            for (_, t) in sent {
                prop_assert!(t.is_some_and(|t| t >= 0));
            }
        }
    }

    #[test]
    fn the_edges_of_simulated_time() {
        assert_eq!(sim_time_ns(0.0), Some(0));
        assert_eq!(sim_time_ns(-0.0), Some(0));
        assert_eq!(sim_time_ns(1.5), Some(1_500_000_000));
        assert_eq!(
            sim_time_ns(9_223_372_036.0),
            Some(9_223_372_036_000_000_000)
        );
        for bad in [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -1.0,
            -1e-9,
            9_223_372_037.0,
        ] {
            assert_eq!(sim_time_ns(bad), None, "{bad}");
        }
    }
}
