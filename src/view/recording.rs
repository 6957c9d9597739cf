//! `eyebot-hil view RECORD_DIR`: the page over a recording.
//!
//! The recording is read once: every `state.csv` row becomes a [`Sample`], with what the
//! wire had said by then (`bytes.tsv` decoded by the same [`WireWatch`] as a live run), and
//! every decoded message is kept with its time. The page asks for a time ([`RecordingView::at`])
//! and gets the row at or before it, the minute before, and the last messages. Memory grows
//! with the recording: about 1 KiB per state row plus the decoded messages.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::frame::{Frame, HISTORY_S, Sample, StatusView, wire_links};
use super::wire::{LinkMessage, MESSAGES_KEPT, Readings, WireWatch};
use crate::record::{self, Meta, ReadError};

/// Most points of the minute before that one answer carries.
const HISTORY_POINTS: usize = 600;

/// A recording, decoded, ready to be shown at any time.
#[derive(Debug)]
pub struct RecordingView {
    dir: PathBuf,
    meta: Meta,
    samples: Vec<Sample>,
    readings: Vec<Readings>,
    messages: Vec<LinkMessage>,
    events: Vec<record::EventRow>,
}

/// One step of [`RecordingView::replay`].
#[derive(Debug, Clone, Copy)]
pub enum Step<'a> {
    Message(&'a LinkMessage),
    State(&'a Sample, &'a Readings),
}

/// What the page shows of the recording itself.
#[derive(Debug, Clone, Serialize)]
pub struct RecordingInfo {
    pub dir: String,
    pub seed: u64,
    pub time_mode: String,
    pub speed: f64,
    pub config: String,
    pub first_s: f64,
    pub last_s: f64,
    pub events: Vec<record::EventRow>,
}

impl RecordingView {
    /// Reads and decodes the recording in `dir`.
    pub fn load(dir: &Path) -> Result<Self, ReadError> {
        let meta = record::read_meta(dir)?;
        let states = record::read_state(dir)?;
        if states.is_empty() {
            return Err(ReadError::Line {
                path: dir.join(record::format::STATE_FILE),
                line: 2,
                problem: "expected at least one ground-truth row: nothing to show".into(),
            });
        }
        let chunks = record::read_bytes(dir)?;
        let events = record::read_events(dir)?;
        let mut wire = WireWatch::new();
        let mut messages = Vec::new();
        let mut samples = Vec::with_capacity(states.len());
        let mut readings = Vec::with_capacity(states.len());
        let mut next_chunk = chunks.iter().peekable();
        for row in &states {
            while let Some(c) = next_chunk.next_if(|c| c.sim_s <= row.t_s) {
                wire.feed(c.sim_s, &c.link, c.dir, &c.data, |m| {
                    messages.push(m.clone())
                });
            }
            samples.push(Sample::new(row, wire.readings()));
            readings.push(wire.readings().clone());
        }
        for c in next_chunk {
            wire.feed(c.sim_s, &c.link, c.dir, &c.data, |m| {
                messages.push(m.clone())
            });
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            meta,
            samples,
            readings,
            messages,
            events,
        })
    }

    /// Goes through the recording in time order: each state row (with what the wire had said
    /// by then) after the link messages decoded up to its time, then the messages after the
    /// last row. `export --mcap` writes what it is given.
    pub fn replay(&self, mut each: impl FnMut(Step<'_>)) {
        let mut messages = self.messages.iter().peekable();
        for (sample, readings) in self.samples.iter().zip(&self.readings) {
            while let Some(m) = messages.next_if(|m| m.t_s <= sample.t_s) {
                each(Step::Message(m));
            }
            each(Step::State(sample, readings));
        }
        for m in messages {
            each(Step::Message(m));
        }
    }

    /// The first and last state rows' times.
    pub fn span_s(&self) -> (f64, f64) {
        (
            self.samples.first().map_or(0.0, |s| s.t_s),
            self.samples.last().map_or(0.0, |s| s.t_s),
        )
    }

    pub fn describe(&self) -> RecordingInfo {
        let (first_s, last_s) = self.span_s();
        RecordingInfo {
            dir: self.dir.display().to_string(),
            seed: self.meta.seed,
            time_mode: self.meta.time_mode.clone(),
            speed: self.meta.speed,
            config: self.meta.config.clone(),
            first_s,
            last_s,
            events: self.events.clone(),
        }
    }

    /// The index of the state row at or before `t_s` (the first row before the start).
    pub fn index_at(&self, t_s: f64) -> usize {
        self.samples
            .partition_point(|s| s.t_s <= t_s)
            .saturating_sub(1)
    }

    /// The sample at or before `t_s`.
    pub fn sample_at(&self, t_s: f64) -> Option<&Sample> {
        self.samples.get(self.index_at(t_s))
    }

    /// The page's answer for time `t_s`: `{"frame", "history", "messages"}` as JSON.
    pub fn at(&self, t_s: f64) -> String {
        let i = self.index_at(t_s);
        let (Some(sample), Some(readings)) = (self.samples.get(i), self.readings.get(i)) else {
            return "{}".into();
        };
        let status = StatusView {
            sim_time_s: sample.t_s,
            time_mode: self.meta.time_mode.clone(),
            speed: self.meta.speed,
            paused: false,
            overruns: 0,
            links: wire_links(readings),
            view_dropped: 0,
            current_mps: None,
        };
        let from = self.samples[..=i].partition_point(|s| s.t_s < sample.t_s - HISTORY_S);
        let window = &self.samples[from..=i];
        let step = window.len().div_ceil(HISTORY_POINTS).max(1);
        let mut history: Vec<&Sample> = window.iter().step_by(step).collect();
        if history.last().is_none_or(|s| s.t_s != sample.t_s) {
            history.push(sample);
        }
        let upto = self.messages.partition_point(|m| m.t_s <= sample.t_s);
        let messages = &self.messages[upto.saturating_sub(MESSAGES_KEPT)..upto];
        let answer = serde_json::json!({
            "frame": Frame { sample, readings, status: &status },
            "history": history,
            "messages": messages,
        });
        answer.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{Direction, Recorder, StateRow};

    /// The answer at a time is the state row at or before it, with the minute before it and
    /// the messages decoded up to it; a recording with a control holds its event.
    #[test]
    fn a_recording_answers_with_the_row_at_or_before_the_time() {
        let tmp = crate::scratch::dir("viewrec");
        let dir = tmp.path();
        let meta = Meta::new(3, "lockstep", 1.0, "<embedded>/default.toml");
        let rec = Recorder::start(
            dir,
            &meta,
            "vehicle = \"vehicles/mako.toml\"\nworld = \"worlds/pool.toml\"\nsensors = \"sensors/mako-2008.toml\"\n",
        )
        .unwrap();
        for i in 0..100 {
            rec.state(StateRow {
                t_s: f64::from(i) * 0.02,
                x_m: f64::from(i),
                ..StateRow::default()
            });
        }
        rec.bytes(
            0.5,
            "sonar",
            Direction::Tx,
            b"@A2\r\n$SDDBT,8.2,f,2.5,M,1.4,F*0E\r\n",
        );
        rec.event(1.0, "pose", "x_m=1 y_m=1 depth_m=1 heading_deg=0");
        rec.finish().unwrap();
        let view = RecordingView::load(dir).unwrap();
        assert_eq!(view.span_s(), (0.0, 1.98));
        assert_eq!(view.sample_at(0.05).map(|s| s.x_m), Some(2.0));
        assert_eq!(view.sample_at(0.06).map(|s| s.x_m), Some(3.0));
        assert_eq!(view.sample_at(-1.0).map(|s| s.x_m), Some(0.0));
        assert_eq!(view.sample_at(99.0).map(|s| s.x_m), Some(99.0));
        let early: serde_json::Value = serde_json::from_str(&view.at(0.4)).unwrap();
        assert_eq!(early["messages"].as_array().unwrap().len(), 0);
        assert_eq!(
            early["frame"]["readings"]["echoes"][1],
            serde_json::Value::Null
        );
        let late: serde_json::Value = serde_json::from_str(&view.at(0.6)).unwrap();
        assert_eq!(late["messages"].as_array().unwrap().len(), 2);
        assert_eq!(late["frame"]["readings"]["echoes"][1]["range_m"], 2.5);
        assert_eq!(late["history"].as_array().unwrap().len(), 31);
        assert_eq!(view.describe().events.len(), 1);
    }
}
