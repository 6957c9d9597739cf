//! Several logs as one stream.
//!
//! When every input has times, lines are merged by time; ties go to the input named first
//! on the command line, and within one input lines keep their file order (each input
//! contributes only its next line, so a time that goes back in one file is sent in file
//! order, never reordered). When any input lacks times, inputs are played one after another
//! in command-line order. Non-line events (comments, problems) pass through as they are read.

use std::collections::VecDeque;

use super::input::{Event, InputError, LogLine, Source};

/// How the inputs are combined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MergeMode {
    ByTime,
    OneAfterAnother,
}

/// The merged stream of several [`Source`]s.
#[derive(Debug)]
pub struct Merger {
    sources: Vec<Source>,
    heads: Vec<Option<LogLine>>,
    exhausted: Vec<bool>,
    queue: VecDeque<Event>,
    mode: MergeMode,
    current: usize,
}

impl Merger {
    pub fn new(sources: Vec<Source>) -> Self {
        let mode = if sources.iter().all(|s| s.format().is_timed()) {
            MergeMode::ByTime
        } else {
            MergeMode::OneAfterAnother
        };
        let n = sources.len();
        Self {
            sources,
            heads: vec![None; n],
            exhausted: vec![false; n],
            queue: VecDeque::new(),
            mode,
            current: 0,
        }
    }

    pub fn mode(&self) -> MergeMode {
        self.mode
    }

    pub fn sources(&self) -> &[Source] {
        &self.sources
    }

    /// Pulls input `i` until it has a head line or ends; other events are queued.
    fn fill(&mut self, i: usize) -> Result<(), InputError> {
        while self.heads[i].is_none() && !self.exhausted[i] {
            match self.sources[i].next_event()? {
                Some(Event::Line(l)) => self.heads[i] = Some(l),
                Some(other) => self.queue.push_back(other),
                None => self.exhausted[i] = true,
            }
        }
        Ok(())
    }

    /// The next event of the merged stream.
    pub fn next_event(&mut self) -> Result<Option<Event>, InputError> {
        loop {
            if let Some(e) = self.queue.pop_front() {
                return Ok(Some(e));
            }
            match self.mode {
                MergeMode::OneAfterAnother => {
                    let Some(source) = self.sources.get_mut(self.current) else {
                        return Ok(None);
                    };
                    match source.next_event()? {
                        Some(e) => return Ok(Some(e)),
                        None => self.current += 1,
                    }
                }
                MergeMode::ByTime => {
                    for i in 0..self.sources.len() {
                        self.fill(i)?;
                    }
                    if !self.queue.is_empty() {
                        continue;
                    }
                    // Earliest time; ties to the lowest input index (strict `<` keeps the first).
                    let mut best: Option<(i64, usize)> = None;
                    for (i, head) in self.heads.iter().enumerate() {
                        if let Some(l) = head {
                            let t = l.time_ns.unwrap_or(i64::MIN);
                            if best.is_none_or(|(bt, _)| t < bt) {
                                best = Some((t, i));
                            }
                        }
                    }
                    let Some((_, i)) = best else {
                        return Ok(None);
                    };
                    return Ok(self.heads[i].take().map(Event::Line));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;
    use std::sync::atomic::AtomicU64;

    use super::*;
    use crate::replay::input::CommentMode;

    fn order(files: &[&str]) -> (MergeMode, Vec<(String, u64)>) {
        let tmp = crate::scratch::dir("merge");
        let dir = tmp.path();
        let sources = files
            .iter()
            .enumerate()
            .map(|(i, text)| {
                let path = dir.join(format!("in{i}.log"));
                std::fs::write(&path, text).unwrap();
                Source::open(
                    &path,
                    i,
                    "sonar",
                    CommentMode::Report,
                    Arc::new(AtomicU64::new(0)),
                )
                .unwrap()
            })
            .collect();
        let mut m = Merger::new(sources);
        let mut out = Vec::new();
        while let Some(e) = m.next_event().unwrap() {
            if let Event::Line(l) = e {
                let name = l
                    .loc
                    .file
                    .file_name()
                    .unwrap()
                    .to_string_lossy()
                    .into_owned();
                out.push((name, l.loc.line));
            }
        }
        (m.mode(), out)
    }

    fn pairs(v: &[(&str, u64)]) -> Vec<(String, u64)> {
        v.iter().map(|(f, l)| (f.to_string(), *l)).collect()
    }

    #[test]
    fn merged_by_time_with_ties_by_file_then_line() {
        let a = "1.0 $A*00\n2.0 $A*00\n2.0 $A*00\n5.0 $A*00\n";
        let b = "0.5 $B*00\n2.0 $B*00\n3.0 $B*00\n";
        let (mode, got) = order(&[a, b]);
        assert_eq!(mode, MergeMode::ByTime);
        assert_eq!(
            got,
            pairs(&[
                ("in1.log", 1),
                ("in0.log", 1),
                ("in0.log", 2),
                ("in0.log", 3),
                ("in1.log", 2),
                ("in1.log", 3),
                ("in0.log", 4),
            ])
        );
    }

    #[test]
    fn a_file_whose_time_goes_back_keeps_its_order() {
        let a = "3.0 $A*00\n1.0 $A*00\n4.0 $A*00\n";
        let b = "2.0 $B*00\n";
        let (_, got) = order(&[a, b]);
        assert_eq!(
            got,
            pairs(&[
                ("in1.log", 1),
                ("in0.log", 1),
                ("in0.log", 2),
                ("in0.log", 3)
            ])
        );
    }

    #[test]
    fn untimed_inputs_play_one_after_another() {
        let (mode, got) = order(&["$A*00\n$A*00\n", "1.0 $B*00\n"]);
        assert_eq!(mode, MergeMode::OneAfterAnother);
        assert_eq!(
            got,
            pairs(&[("in0.log", 1), ("in0.log", 2), ("in1.log", 1)])
        );
    }
}
