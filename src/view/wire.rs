//! What the page shows of the links: the bytes that crossed them, decoded.
//!
//! [`WireWatch`] takes the same chunks a recording's `bytes.tsv` holds (time, link,
//! direction, bytes), decodes them with the one transcript decoder ([`Transcript`], which
//! `gap convert` uses too), keeps the last [`MESSAGES_KEPT`] messages, and tracks what the
//! page plots from the wire: the thruster commands the EyeBot sent (also inside TIME_STEP),
//! the ADC values and compass headings the bridge answered (also as STEP values), and each
//! transducer's latest echo. A live run and a recording go through the same code, so the page
//! shows the same thing for both.

use std::collections::{BTreeMap, VecDeque};

use firmware_protocol::LineItem;
use firmware_protocol::sensor_link::{Direction as Spin, ThrusterCommand};
use serde::Serialize;

use crate::record::Direction;
use crate::transcript::{Event, Transcript};

/// How many decoded messages the page is given (the newest).
pub const MESSAGES_KEPT: usize = 200;

/// One decoded link message.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LinkMessage {
    /// Counts every message decoded since the start, so a page can ask for the new ones.
    pub seq: u64,
    pub t_s: f64,
    pub link: String,
    /// `rx` (EyeBot to bridge) or `tx`.
    pub dir: &'static str,
    /// The message's kind (`ThrusterSetAll`, `AdcSamples`, `Dbt`, `Select`, `Error`, ...).
    pub kind: String,
    /// The decoded message in full.
    pub text: String,
}

/// A thruster command as the EyeBot last sent it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ThrusterSeen {
    /// The PWM duty byte on the wire (0xFF is off).
    pub duty: u8,
    pub reverse: bool,
}

/// A transducer's latest reading on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EchoSeen {
    pub t_s: f64,
    /// `None`: the reading said "no echo".
    pub range_m: Option<f64>,
}

/// What the wire said most recently.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Readings {
    /// Port, starboard, bow, stern; `None` until the EyeBot sent one.
    pub thrusters: [Option<ThrusterSeen>; 4],
    pub adc: [Option<u16>; 8],
    /// The compass heading the bridge last answered (degrees).
    pub compass_deg: Option<f64>,
    /// The transducer the master last acknowledged (1-4).
    pub selected: Option<u8>,
    /// Index 0 is transducer 1.
    pub echoes: [Option<EchoSeen>; 4],
    /// Stretches of bytes that did not decode (both links, both directions).
    pub errors: u64,
    /// What crossed each link, counted from the wire.
    pub links: BTreeMap<String, WireCounts>,
}

/// Bytes and decoded messages per direction, and undecodable stretches, of one link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct WireCounts {
    pub bytes_rx: u64,
    pub bytes_tx: u64,
    pub messages_rx: u64,
    pub messages_tx: u64,
    pub errors: u64,
}

/// Decodes the links as chunks arrive.
#[derive(Debug)]
pub struct WireWatch {
    transcript: Transcript,
    readings: Readings,
    recent: VecDeque<LinkMessage>,
    seq: u64,
}

impl Default for WireWatch {
    fn default() -> Self {
        Self {
            transcript: Transcript::new(),
            readings: Readings::default(),
            recent: VecDeque::with_capacity(MESSAGES_KEPT),
            seq: 0,
        }
    }
}

impl WireWatch {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn readings(&self) -> &Readings {
        &self.readings
    }

    /// The newest messages, oldest first (at most [`MESSAGES_KEPT`]).
    pub fn recent(&self) -> &VecDeque<LinkMessage> {
        &self.recent
    }

    /// How many messages were decoded so far.
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// Some bytes were not seen (nobody watched, or the view fell behind): partial messages
    /// are dropped, each decoder starts afresh at the next bytes without counting what it
    /// skips to find a message start as an error, and what the wire had said is forgotten
    /// until it says it again.
    pub fn gap(&mut self) {
        self.transcript.gap();
        let r = &mut self.readings;
        r.thrusters = [None; 4];
        r.adc = [None; 8];
        r.compass_deg = None;
        r.selected = None;
        r.echoes = [None; 4];
    }

    /// Bytes that crossed `link` in direction `dir` at simulated time `t_s`; `each` sees
    /// every message they completed.
    pub fn feed(
        &mut self,
        t_s: f64,
        link: &str,
        dir: Direction,
        data: &[u8],
        mut each: impl FnMut(&LinkMessage),
    ) {
        let Self {
            transcript,
            readings: r,
            recent,
            seq,
        } = self;
        let counts = r.links.entry(link.to_string()).or_default();
        match dir {
            Direction::Rx => counts.bytes_rx += data.len() as u64,
            Direction::Tx => counts.bytes_tx += data.len() as u64,
        }
        transcript.feed(t_s, link, dir, data, |event| match event {
            Event::Item(item) => {
                let counts = r.links.entry(link.to_string()).or_default();
                match (item, dir) {
                    (LineItem::Error(_), _) => counts.errors += 1,
                    (_, Direction::Rx) => counts.messages_rx += 1,
                    (_, Direction::Tx) => counts.messages_tx += 1,
                }
                let (kind, text) = describe(item);
                let message = LinkMessage {
                    seq: *seq,
                    t_s,
                    link: link.to_string(),
                    dir: dir.as_str(),
                    kind,
                    text,
                };
                *seq += 1;
                each(&message);
                if recent.len() == MESSAGES_KEPT {
                    recent.pop_front();
                }
                recent.push_back(message);
            }
            Event::Error => r.errors += 1,
            Event::Thrusters { commands, .. } => r.thrusters = commands.map(|c| c.map(seen)),
            Event::Adc { channel, value, .. } => {
                if let Some(slot) = r.adc.get_mut(usize::from(channel)) {
                    *slot = Some(value);
                }
            }
            Event::Compass { heading_deg, .. } => r.compass_deg = Some(heading_deg),
            Event::SonarSelected { transducer } => r.selected = Some(transducer),
            Event::Echo {
                t_s,
                transducer,
                range_m,
            } => echo(r, Some(transducer), t_s, range_m),
            // A plain depth sentence does not name its transducer: it is the selected one.
            Event::Depth {
                t_s,
                selected,
                range_m,
            } => echo(r, selected, t_s, range_m),
            Event::CompassRaw => {}
        });
    }
}

fn echo(r: &mut Readings, transducer: Option<u8>, t_s: f64, range_m: Option<f64>) {
    let slot = transducer
        .and_then(|t| usize::from(t).checked_sub(1))
        .and_then(|i| r.echoes.get_mut(i));
    if let Some(slot) = slot {
        *slot = Some(EchoSeen { t_s, range_m });
    }
}

/// An item's kind and text: one `Debug` rendering per message, the kind is its leading
/// variant name.
fn describe(item: &LineItem) -> (String, String) {
    match item {
        LineItem::Frame(f) => {
            let text = format!("#{} {:?}", f.seq, f.message);
            let kind = variant(text.split_once(' ').map_or("", |(_, m)| m));
            (kind, text)
        }
        LineItem::Sonar(c) => {
            let text = format!("{c:?}");
            (variant(&text), text)
        }
        LineItem::Nmea(s) => {
            let text = format!("{s:?}");
            (variant(&text), text)
        }
        LineItem::Error(e) => ("Error".to_string(), e.to_string()),
    }
}

fn seen(command: ThrusterCommand) -> ThrusterSeen {
    ThrusterSeen {
        duty: command.duty,
        reverse: command.direction == Spin::Reverse,
    }
}

/// The variant name at the start of a `Debug` rendering (`AdcSamples { .. }` -> `AdcSamples`).
fn variant(debug: &str) -> String {
    debug
        .split(|c: char| !c.is_ascii_alphanumeric())
        .next()
        .unwrap_or_default()
        .to_string()
}

#[cfg(test)]
mod tests {
    use bytes::BytesMut;
    use firmware_protocol::Frame;
    use firmware_protocol::sensor_link::{Message, ThrusterCommand};

    use super::*;

    fn frame(seq: u8, message: Message) -> Vec<u8> {
        let mut buf = BytesMut::new();
        Frame::new(seq, message).encode(&mut buf);
        buf.to_vec()
    }

    /// Split anywhere, the chunks decode to the same messages and readings; the ring keeps
    /// the newest 200.
    #[test]
    fn chunks_decode_into_messages_and_readings_at_any_split() {
        let command = ThrusterCommand {
            duty: 0x40,
            direction: Spin::Reverse,
        };
        let mut rx = Vec::new();
        rx.extend(frame(
            1,
            Message::ThrusterSetAll {
                commands: [command; 4],
            },
        ));
        rx.extend(b"\x00junk");
        let sonar_tx = b"@A2\r\n$SDDBT,8.2,f,2.5,M,1.4,F*0E\r\n";
        for split in 1..rx.len() {
            let mut w = WireWatch::new();
            let mut kinds = Vec::new();
            for part in rx.chunks(split) {
                w.feed(1.0, "sensor", Direction::Rx, part, |m| {
                    kinds.push(m.kind.clone())
                });
            }
            for part in sonar_tx.chunks(split) {
                w.feed(2.0, "sonar", Direction::Tx, part, |m| {
                    kinds.push(m.kind.clone())
                });
            }
            assert_eq!(kinds[0], "ThrusterSetAll", "split {split}");
            assert!(kinds.contains(&"Ack".to_string()), "{kinds:?}");
            assert_eq!(kinds.last().map(String::as_str), Some("Dbt"));
            let r = w.readings();
            assert_eq!(
                r.thrusters[3].map(|t| (t.duty, t.reverse)),
                Some((0x40, true))
            );
            assert_eq!(r.selected, Some(2));
            assert_eq!(r.echoes[1].and_then(|e| e.range_m), Some(2.5));
            assert_eq!(r.echoes[0], None);
        }
        let mut w = WireWatch::new();
        for i in 0..250u8 {
            w.feed(
                0.0,
                "sensor",
                Direction::Rx,
                &frame(i, Message::TimeGet),
                |_| {},
            );
        }
        assert_eq!(w.recent().len(), MESSAGES_KEPT);
        assert_eq!(w.recent().front().map(|m| m.seq), Some(50));
        assert_eq!(w.seq(), 250);
    }

    /// After a gap the decoder drops what it held, skips to the next message without an
    /// error, and forgets the readings until the wire says them again; without a gap the
    /// same bytes are an error.
    #[test]
    fn a_gap_resyncs_without_an_error_and_forgets_the_readings() {
        let command = ThrusterCommand {
            duty: 0x40,
            direction: Spin::Forward,
        };
        let set = frame(
            1,
            Message::ThrusterSetAll {
                commands: [command; 4],
            },
        );
        let read = frame(2, Message::TimeGet);
        let kinds = |w: &mut WireWatch, data: &[u8]| {
            let mut k = Vec::new();
            w.feed(0.0, "sensor", Direction::Rx, data, |m| {
                k.push(m.kind.clone())
            });
            k
        };
        let mut tail = set[3..].to_vec();
        tail.extend(&read);

        let mut w = WireWatch::new();
        assert_eq!(kinds(&mut w, &set), ["ThrusterSetAll"]);
        assert!(w.readings().thrusters[0].is_some());
        w.gap();
        assert_eq!(w.readings().thrusters[0], None);
        let after_gap = kinds(&mut w, &tail);
        assert_eq!(
            after_gap.last().map(String::as_str),
            Some("TimeGet"),
            "{after_gap:?}"
        );
        assert!(!after_gap.contains(&"Error".to_string()), "{after_gap:?}");
        assert_eq!(w.readings().errors, 0);
        // Once in step, stray bytes are an error again, as they are without a gap.
        let again = kinds(&mut w, &tail);
        assert!(again.contains(&"Error".to_string()), "{again:?}");
        assert_eq!(
            again.last().map(String::as_str),
            Some("TimeGet"),
            "{again:?}"
        );
        let mut w = WireWatch::new();
        let fresh = kinds(&mut w, &tail);
        assert!(fresh.contains(&"Error".to_string()), "{fresh:?}");
    }
    /// The thrusters of a TIME_STEP show at once; the ADC values and heading of its STEP show
    /// once the EyeBot said it used them (the next TIME_STEP's `used`, counted when its STEP
    /// comes, or any other request); values taken back never show.
    #[test]
    fn time_step_thrusters_and_used_step_values_show() {
        use firmware_protocol::sensor_link::{AdcChannel, Reading, Readings, StepValues};
        let adc = |c: u8| Reading::Adc(AdcChannel::new(c).unwrap());
        let command = ThrusterCommand {
            duty: 0x40,
            direction: Spin::Reverse,
        };
        let time_step = |seq: u8, used: u8, thrusters| {
            frame(
                seq,
                Message::TimeStep {
                    used,
                    stop_on_sonar: false,
                    ticks: 1,
                    thrusters,
                    readings: Readings::new([adc(0), adc(3), Reading::Compass]).unwrap(),
                },
            )
        };
        let word = |deg: u16| {
            firmware_protocol::HeadingWord::encode(deg, firmware_protocol::HeadingFormat::Binary)
                .unwrap()
                .0
        };
        let step = |seq: u8, values: [u16; 3]| {
            frame(
                seq,
                Message::Step {
                    ticks: 7,
                    sonar_bytes: 0,
                    values: StepValues::new(values).unwrap(),
                },
            )
        };
        let mut w = WireWatch::new();
        w.feed(
            0.0,
            "sensor",
            Direction::Rx,
            &time_step(1, 0, Some([command; 4])),
            |_| {},
        );
        assert_eq!(
            w.readings().thrusters[2].map(|t| (t.duty, t.reverse)),
            Some((0x40, true))
        );
        w.feed(
            0.0,
            "sensor",
            Direction::Tx,
            &step(1, [100, 200, word(90)]),
            |_| {},
        );
        assert_eq!(w.readings().adc, [None; 8], "not used yet");
        w.feed(0.0, "sensor", Direction::Rx, &time_step(2, 2, None), |_| {});
        assert_eq!(
            w.readings().adc,
            [None; 8],
            "a TIME_STEP may still be refused"
        );
        w.feed(
            0.0,
            "sensor",
            Direction::Tx,
            &step(2, [101, 201, word(45)]),
            |_| {},
        );
        let r = w.readings();
        assert_eq!((r.adc[0], r.adc[3]), (Some(100), Some(200)));
        assert_eq!(r.compass_deg, None, "the heading was taken back");
        w.feed(
            0.0,
            "sensor",
            Direction::Rx,
            &frame(3, Message::TimeGet),
            |_| {},
        );
        let r = w.readings();
        assert_eq!((r.adc[0], r.adc[3]), (Some(101), Some(201)));
        assert_eq!(r.compass_deg, Some(45.0));
    }
}
