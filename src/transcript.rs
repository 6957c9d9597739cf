//! One decoder of a link transcript: the bytes that crossed the links (time, link, direction,
//! bytes, as a recording's `bytes.tsv` holds them or the daemon's tap hands them over) turned
//! into what the EyeBot asked for and what the bridge answered.
//!
//! The live view, `view RECORD_DIR`, `export --mcap` and `gap convert` all read the wire
//! through [`Transcript`], so they agree on what a run said: each link and direction is decoded
//! on its own with the protocol crate's [`LineDecoder`], and every decoded item is handed on
//! as [`Event::Item`] followed by what it means ([`Event`]):
//!
//! - thruster commands: THRUSTER_SET, THRUSTER_SET_ALL and the thrusters of a TIME_STEP, at
//!   the request's time; HELLO switches them all off ([`Event::Thrusters`] carries all four);
//! - ADC values: ADC_VALUE at the reply's time, ADC_SAMPLES and STEP values at the tick they
//!   name (`firmware-protocol/PROTOCOL.md` 2.9: value i of a STEP is the reading the
//!   TIME_STEP's code i asked for). A STEP value counts only once the EyeBot said it used it:
//!   the next TIME_STEP's `used` values of it, or all of them when another request follows;
//!   values taken back, and those of a last reply nobody answered, never happened and are
//!   only counted ([`Transcript::step_values_unused`]);
//! - compass headings (COMPASS_HEADING, its push, and STEP values), decoded in the output
//!   format the EyeBot set (COMPASS_MODE; HELLO resets it to binary);
//! - the sonar: the transducer the master acknowledged, `$PEBHS` echo reports, and plain
//!   depth sentences, which do not say which transducer pinged.
//!
//! A retried request (same seq and payload, answered from the bridge's store) is executed
//! only once. The decoder is sans-IO: it never reads a file or a clock.

use std::collections::{BTreeMap, BTreeSet};

use bytes::BytesMut;
use firmware_protocol::compass_word::HeadingFormat;
use firmware_protocol::sensor_link::{
    CompassOutput, Frame, Message, Reading, Readings, ThrusterCommand, msg_type,
};
use firmware_protocol::sonar_link::SonarCommand;
use firmware_protocol::{HeadingWord, LineDecoder, LineItem, Sentence};

use crate::record::Direction;

/// The tick length the bridge uses until its HELLO_REPLY says otherwise (µs).
const DEFAULT_TICK_US: u32 = 10_000;

/// What one decoded item meant. Times are simulated seconds, as the transcript gives them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event<'a> {
    /// Every decoded item, first, as it came off the wire.
    Item(&'a LineItem),
    /// The thruster commands changed (or were sent again): all four as the EyeBot last set
    /// them; `None` until it sent one (after HELLO: all `None`, the motors are off).
    Thrusters {
        t_s: f64,
        commands: [Option<ThrusterCommand>; 4],
    },
    /// An ADC channel's value.
    Adc { t_s: f64, channel: u8, value: u16 },
    /// A compass heading (degrees).
    Compass { t_s: f64, heading_deg: f64 },
    /// A raw compass reply or push (not a heading).
    CompassRaw,
    /// The sonar master acknowledged transducer `transducer` (1-4).
    SonarSelected { transducer: u8 },
    /// An echo report that names its transducer; `range_m` `None`: no echo.
    Echo {
        t_s: f64,
        transducer: u8,
        range_m: Option<f64>,
    },
    /// A plain depth sentence (DBT, DPT): it does not name its transducer; `selected` is the
    /// one the master last acknowledged.
    Depth {
        t_s: f64,
        selected: Option<u8>,
        range_m: Option<f64>,
    },
    /// A stretch of bytes that did not decode.
    Error,
}

/// The TIME_STEP exchanges of one link (PROTOCOL.md 2.9).
#[derive(Debug, Default)]
struct StepLink {
    /// The last request, to tell a retry (same seq and payload, answered from the bridge's
    /// store, never executed again) from a new request.
    last_request: Option<Frame>,
    /// The TIME_STEP waiting for its STEP: seq, `used`, readings.
    asked: Option<(u8, u8, Readings)>,
    /// The last STEP's values, in request order: time, reading, value, the heading format then.
    open: Vec<(f64, Reading, u16, HeadingFormat)>,
}

/// Decodes a transcript chunk by chunk (see the module doc).
#[derive(Debug)]
pub struct Transcript {
    decoders: BTreeMap<(String, &'static str), (LineDecoder, BytesMut)>,
    steps: BTreeMap<String, StepLink>,
    thrusters: [Option<ThrusterCommand>; 4],
    heading_format: HeadingFormat,
    selected: Option<u8>,
    tick_us: u32,
    unused: usize,
    /// After a gap, what a decoder skips before its first message is not reported as an
    /// error; `synced` holds those that have found one since.
    after_gap: bool,
    synced: BTreeSet<(String, &'static str)>,
}

impl Default for Transcript {
    fn default() -> Self {
        Self {
            decoders: BTreeMap::new(),
            steps: BTreeMap::new(),
            thrusters: [None; 4],
            heading_format: HeadingFormat::Binary,
            selected: None,
            tick_us: DEFAULT_TICK_US,
            unused: 0,
            after_gap: false,
            synced: BTreeSet::new(),
        }
    }
}

impl Transcript {
    pub fn new() -> Self {
        Self::default()
    }

    /// STEP values that never counted: taken back unused, or of replies whose use the
    /// transcript has not (yet) told.
    pub fn step_values_unused(&self) -> usize {
        self.unused + self.steps.values().map(|s| s.open.len()).sum::<usize>()
    }

    /// Some bytes were not seen (nobody watched, or a reader fell behind): partial messages
    /// are dropped, each decoder starts afresh at the next bytes without reporting what it
    /// skips to find a message start as an error, and what the wire had said (thrusters,
    /// selected transducer, STEP values waiting for their use) is forgotten until it says it
    /// again.
    pub fn gap(&mut self) {
        for (decoder, buf) in self.decoders.values_mut() {
            *decoder = LineDecoder::default();
            buf.clear();
        }
        self.after_gap = true;
        self.synced.clear();
        self.steps.clear();
        self.thrusters = [None; 4];
        self.selected = None;
    }

    /// Bytes that crossed `link` in direction `dir` at simulated time `t_s`; `each` sees
    /// every item they completed and what it meant.
    pub fn feed(
        &mut self,
        t_s: f64,
        link: &str,
        dir: Direction,
        data: &[u8],
        mut each: impl FnMut(Event<'_>),
    ) {
        let key = (link.to_string(), dir.as_str());
        let (mut decoder, mut buf) = self.decoders.remove(&key).unwrap_or_default();
        buf.extend_from_slice(data);
        while let Some(item) = decoder.decode(&mut buf) {
            if self.after_gap && !self.synced.contains(&key) {
                if matches!(item, LineItem::Error(_)) {
                    continue;
                }
                self.synced.insert(key.clone());
            }
            each(Event::Item(&item));
            self.apply(t_s, link, dir, &item, &mut each);
        }
        self.decoders.insert(key, (decoder, buf));
    }

    fn apply(
        &mut self,
        t_s: f64,
        link: &str,
        dir: Direction,
        item: &LineItem,
        each: &mut impl FnMut(Event<'_>),
    ) {
        match (dir, item) {
            (_, LineItem::Error(_)) => each(Event::Error),
            (_, LineItem::Frame(frame)) => {
                self.track_steps(link, dir, *frame, each);
                self.apply_frame(t_s, dir, frame.message, each);
            }
            (Direction::Tx, LineItem::Sonar(SonarCommand::Ack(t))) => {
                self.selected = Some(t.get());
                each(Event::SonarSelected {
                    transducer: t.get(),
                });
            }
            (Direction::Tx, LineItem::Nmea(sentence)) => {
                let tenths = |r: firmware_protocol::Tenths| f64::from(r.tenths()) / 10.0;
                each(match sentence {
                    Sentence::Echo(e) => Event::Echo {
                        t_s,
                        transducer: e.transducer.get(),
                        range_m: e.range_m.map(tenths),
                    },
                    Sentence::Dbt(d) => Event::Depth {
                        t_s,
                        selected: self.selected,
                        range_m: d.metres.map(tenths),
                    },
                    Sentence::Dpt(d) => Event::Depth {
                        t_s,
                        selected: self.selected,
                        range_m: d.depth_m.map(tenths),
                    },
                });
            }
            _ => {}
        }
    }

    /// Which STEP values count (PROTOCOL.md 2.9): emits those the EyeBot used, when it says so.
    fn track_steps(
        &mut self,
        link: &str,
        dir: Direction,
        frame: Frame,
        each: &mut impl FnMut(Event<'_>),
    ) {
        let link = self.steps.entry(link.to_string()).or_default();
        match (dir, frame.message) {
            (Direction::Rx, _) if link.last_request == Some(frame) => {
                // A retry: the bridge answers it from its store and executes nothing.
            }
            (Direction::Rx, Message::TimeStep { used, readings, .. }) => {
                link.last_request = Some(frame);
                link.asked = Some((frame.seq, used, readings));
            }
            (Direction::Rx, _) => {
                link.last_request = Some(frame);
                let all = link.open.len();
                commit(&mut link.open, all, each);
            }
            (Direction::Tx, Message::Step { ticks, values, .. }) => {
                if let Some((_, used, readings)) = link.asked.take_if(|a| a.0 == frame.seq) {
                    self.unused += commit(&mut link.open, usize::from(used), each);
                    let ts = tick_time(ticks, self.tick_us);
                    let format = self.heading_format;
                    link.open = readings
                        .as_slice()
                        .iter()
                        .zip(values.as_slice())
                        .map(|(&r, &v)| (ts, r, v, format))
                        .collect();
                }
            }
            (Direction::Tx, Message::Nak { rejected_type, .. })
                if rejected_type == msg_type::TIME_STEP =>
            {
                // A rejected TIME_STEP changes nothing.
                link.asked = None;
            }
            _ => {}
        }
    }

    fn apply_frame(
        &mut self,
        t_s: f64,
        dir: Direction,
        message: Message,
        each: &mut impl FnMut(Event<'_>),
    ) {
        match (dir, message) {
            (Direction::Rx, Message::Hello { .. }) => {
                self.thrusters = [None; 4];
                self.heading_format = HeadingFormat::Binary;
                each(Event::Thrusters {
                    t_s,
                    commands: self.thrusters,
                });
            }
            (Direction::Rx, Message::ThrusterSet { thruster, command }) => {
                if let Some(slot) = self.thrusters.get_mut(thruster as usize) {
                    *slot = Some(command);
                    each(Event::Thrusters {
                        t_s,
                        commands: self.thrusters,
                    });
                }
            }
            (Direction::Rx, Message::ThrusterSetAll { commands })
            | (
                Direction::Rx,
                Message::TimeStep {
                    thrusters: Some(commands),
                    ..
                },
            ) => {
                self.thrusters = commands.map(Some);
                each(Event::Thrusters {
                    t_s,
                    commands: self.thrusters,
                });
            }
            (Direction::Rx, Message::CompassMode { output, .. }) => match output {
                CompassOutput::Binary => self.heading_format = HeadingFormat::Binary,
                CompassOutput::Bcd => self.heading_format = HeadingFormat::Bcd,
                CompassOutput::Raw => {}
            },
            (Direction::Tx, Message::HelloReply { tick_us, .. }) => self.tick_us = tick_us,
            (Direction::Tx, Message::AdcValue { channel, value }) => each(Event::Adc {
                t_s,
                channel: channel.get(),
                value: value.get(),
            }),
            (Direction::Tx, Message::AdcSamples { ticks, samples }) => {
                let ts = tick_time(ticks, self.tick_us);
                for (channel, value) in samples.iter() {
                    each(Event::Adc {
                        t_s: ts,
                        channel: channel.get(),
                        value: value.get(),
                    });
                }
            }
            (
                Direction::Tx,
                Message::CompassHeading { word } | Message::CompassHeadingPush { word },
            ) => {
                if let Ok(h) = word.decode(self.heading_format) {
                    each(Event::Compass {
                        t_s,
                        heading_deg: f64::from(h),
                    });
                }
            }
            (Direction::Tx, Message::CompassRaw { .. } | Message::CompassRawPush { .. }) => {
                each(Event::CompassRaw)
            }
            _ => {}
        }
    }
}

/// A tick count as seconds, rounded once (as a recording's decimal times are).
fn tick_time(ticks: u32, tick_us: u32) -> f64 {
    (u64::from(ticks) * u64::from(tick_us)) as f64 / 1e6
}

/// Emits the first `used` values of a STEP reply as the replies they stand for would be;
/// returns how many it dropped.
fn commit(
    open: &mut Vec<(f64, Reading, u16, HeadingFormat)>,
    used: usize,
    each: &mut impl FnMut(Event<'_>),
) -> usize {
    let unused = open.len().saturating_sub(used);
    for (t_s, reading, value, format) in open.drain(..).take(used) {
        match reading {
            Reading::Adc(channel) => each(Event::Adc {
                t_s,
                channel: channel.get(),
                value,
            }),
            Reading::Compass => {
                if let Ok(h) = HeadingWord(value).decode(format) {
                    each(Event::Compass {
                        t_s,
                        heading_deg: f64::from(h),
                    });
                }
            }
        }
    }
    unused
}
