//! What the page shows of the links: the bytes that crossed them, decoded.
//!
//! [`WireWatch`] takes the same chunks a recording's `bytes.tsv` holds (time, link,
//! direction, bytes), decodes each link and direction on its own with the protocol crate's
//! [`LineDecoder`], keeps the last [`MESSAGES_KEPT`] messages, and tracks what the page
//! plots from the wire: the thruster commands the EyeBot sent, the ADC values and compass
//! headings the bridge answered, and each transducer's latest echo. A live run and a
//! recording go through the same code, so the page shows the same thing for both.

use std::collections::{BTreeMap, VecDeque};

use bytes::BytesMut;
use firmware_protocol::compass_word::HeadingFormat;
use firmware_protocol::sensor_link::{CompassOutput, Direction as Spin, Message};
use firmware_protocol::sonar_link::SonarCommand;
use firmware_protocol::{LineDecoder, LineItem, Sentence};
use serde::Serialize;

use crate::record::Direction;

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
pub struct WireWatch {
    decoders: BTreeMap<(String, &'static str), (LineDecoder, BytesMut)>,
    heading_format: HeadingFormat,
    readings: Readings,
    recent: VecDeque<LinkMessage>,
    seq: u64,
    /// After a gap, what a decoder skips before its first message is not counted or shown
    /// as an error; `synced` holds those that have found one since.
    after_gap: bool,
    synced: std::collections::BTreeSet<(String, &'static str)>,
}

impl Default for WireWatch {
    fn default() -> Self {
        Self {
            decoders: BTreeMap::new(),
            heading_format: HeadingFormat::Binary,
            readings: Readings::default(),
            recent: VecDeque::with_capacity(MESSAGES_KEPT),
            seq: 0,
            after_gap: false,
            synced: std::collections::BTreeSet::new(),
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
        for (decoder, buf) in self.decoders.values_mut() {
            *decoder = LineDecoder::default();
            buf.clear();
        }
        self.after_gap = true;
        self.synced.clear();
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
        let counts = self.readings.links.entry(link.to_string()).or_default();
        match dir {
            Direction::Rx => counts.bytes_rx += data.len() as u64,
            Direction::Tx => counts.bytes_tx += data.len() as u64,
        }
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
            let counts = self.readings.links.entry(link.to_string()).or_default();
            match (&item, dir) {
                (LineItem::Error(_), _) => counts.errors += 1,
                (_, Direction::Rx) => counts.messages_rx += 1,
                (_, Direction::Tx) => counts.messages_tx += 1,
            }
            let message = self.apply(t_s, dir, item);
            let message = LinkMessage {
                seq: self.seq,
                t_s,
                link: link.to_string(),
                dir: dir.as_str(),
                kind: message.0,
                text: message.1,
            };
            self.seq += 1;
            each(&message);
            if self.recent.len() == MESSAGES_KEPT {
                self.recent.pop_front();
            }
            self.recent.push_back(message);
        }
        self.decoders.insert(key, (decoder, buf));
    }

    /// Updates the readings with one item; returns its kind and text.
    fn apply(&mut self, t_s: f64, dir: Direction, item: LineItem) -> (String, String) {
        // One `Debug` rendering per message: the kind is its leading variant name.
        let (text, kind) = match &item {
            LineItem::Frame(f) => {
                let text = format!("#{} {:?}", f.seq, f.message);
                let kind = variant(text.split_once(' ').map_or("", |(_, m)| m));
                (text, kind)
            }
            LineItem::Sonar(c) => {
                let text = format!("{c:?}");
                let kind = variant(&text);
                (text, kind)
            }
            LineItem::Nmea(s) => {
                let text = format!("{s:?}");
                let kind = variant(&text);
                (text, kind)
            }
            LineItem::Error(e) => (e.to_string(), "Error".to_string()),
        };
        let r = &mut self.readings;
        match (dir, item) {
            (_, LineItem::Error(_)) => r.errors += 1,
            (Direction::Rx, LineItem::Frame(f)) => match f.message {
                Message::Hello { .. } => {
                    r.thrusters = [None; 4];
                    self.heading_format = HeadingFormat::Binary;
                }
                Message::ThrusterSet { thruster, command } => {
                    if let Some(slot) = r.thrusters.get_mut(thruster as usize) {
                        *slot = Some(seen(command));
                    }
                }
                Message::ThrusterSetAll { commands } => {
                    r.thrusters = commands.map(|c| Some(seen(c)));
                }
                Message::CompassMode { output, .. } => match output {
                    CompassOutput::Binary => self.heading_format = HeadingFormat::Binary,
                    CompassOutput::Bcd => self.heading_format = HeadingFormat::Bcd,
                    CompassOutput::Raw => {}
                },
                _ => {}
            },
            (Direction::Tx, LineItem::Frame(f)) => match f.message {
                Message::AdcValue { channel, value } => {
                    if let Some(slot) = r.adc.get_mut(usize::from(channel.get())) {
                        *slot = Some(value.get());
                    }
                }
                Message::AdcSamples { samples, .. } => {
                    for (channel, value) in samples.iter() {
                        if let Some(slot) = r.adc.get_mut(usize::from(channel.get())) {
                            *slot = Some(value.get());
                        }
                    }
                }
                Message::CompassHeading { word } | Message::CompassHeadingPush { word } => {
                    if let Ok(h) = word.decode(self.heading_format) {
                        r.compass_deg = Some(f64::from(h));
                    }
                }
                _ => {}
            },
            (Direction::Tx, LineItem::Sonar(SonarCommand::Ack(t))) => r.selected = Some(t.get()),
            (Direction::Tx, LineItem::Nmea(sentence)) => {
                // A plain depth sentence does not name its transducer: it is the selected one.
                let (transducer, range) = match sentence {
                    Sentence::Echo(e) => (Some(e.transducer.get()), e.range_m),
                    Sentence::Dbt(d) => (r.selected, d.metres),
                    Sentence::Dpt(d) => (r.selected, d.depth_m),
                };
                let slot = transducer
                    .and_then(|t| usize::from(t).checked_sub(1))
                    .and_then(|i| r.echoes.get_mut(i));
                if let Some(slot) = slot {
                    *slot = Some(EchoSeen {
                        t_s,
                        range_m: range.map(|m| f64::from(m.tenths()) / 10.0),
                    });
                }
            }
            _ => {}
        }
        (kind, text)
    }
}

fn seen(command: firmware_protocol::sensor_link::ThrusterCommand) -> ThrusterSeen {
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
    use firmware_protocol::sensor_link::ThrusterCommand;

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
}
