//! The PICAXE sonar multiplexer master, as the EyeBot's sonar line sees it.
//!
//! The EyeBot sends a select (`@S1\r`); the master switches the relays (the timing is the
//! sonar model's, behind [`Plant::sonar_select`]) and acknowledges with `@A1\r\n` once they
//! have switched; from then on it forwards the active controller's NMEA depth sentences. A
//! sentence does not say which transducer produced it (faithful default); the optional
//! proprietary `$PEBHS` sentence does, for firmware that is extended to read it.
//!
//! **Feeds.** Captured sentences can stand in for the simulated sonar (`eyebot-hil replay
//! --into-sonar`, or `replay = "FILE"` in `[devices.multiplexer]`). While a feed is active the
//! model's readings are not forwarded; the relays and acknowledgements still follow the
//! model's timing. A feed's depth sentence is forwarded as the active controller's output
//! when the feed does not say which transducer produced it, or when it says so with a
//! `$PEBHS` sentence right after it (the order this bridge writes them) and that transducer
//! is the selected one: the EyeBot then reads the captured ranges through the normal
//! select/ack protocol with the log's transducer mapping.

use bytes::{Bytes, BytesMut};
use firmware_protocol::error::{LinkError, SonarCommandError};
use firmware_protocol::nmea::{Dbt, Dpt, EchoReport, Sentence, Talker, Transducer};
use firmware_protocol::sonar_link::SonarCommand;

use super::{Plant, SonarEvent};
use crate::SimNanos;

/// Which depth sentence the sonar controllers emit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DepthSentence {
    /// `DBT`: depth below transducer in feet, metres and fathoms (the default).
    Dbt,
    /// `DPT`: depth and transducer offset.
    Dpt { offset_m: f64 },
}

/// What the controller does when an echo was not valid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InvalidEcho {
    /// Send nothing: a reading is only reported when the echo was valid (thesis 4.4, the
    /// Navman behaviour Mako's programs were written against). The default.
    Omit,
    /// Send the sentence with empty data fields (NMEA's "no data").
    EmptyFields,
}

/// Fixed settings of the multiplexer emulator.
#[derive(Debug, Clone, PartialEq)]
pub struct MultiplexerSettings {
    pub sentence: DepthSentence,
    pub talker: Talker,
    pub invalid_echo: InvalidEcho,
    /// Also send `$PEBHS` with transducer id, range and echo quality after each reading.
    pub proprietary: bool,
}

/// Counters of the sonar line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MultiplexerCounters {
    pub selects: u64,
    pub acks: u64,
    pub naks: u64,
    pub sentences: u64,
    pub invalid_echoes: u64,
    /// Wire errors received (garbage, bad commands, unexpected NMEA from the EyeBot side).
    pub rx_errors: u64,
    /// Feed sentences forwarded, and held back because another transducer is selected.
    pub fed: u64,
    pub fed_withheld: u64,
}

/// The master's state.
#[derive(Debug)]
pub struct Multiplexer {
    settings: MultiplexerSettings,
    counters: MultiplexerCounters,
    events: Vec<(SimNanos, SonarEvent)>,
    /// The transducer the relays connect (after its acknowledgement), 1..=4.
    selected: Option<u8>,
    feed_active: bool,
    /// A fed depth sentence waiting to learn (from a following `$PEBHS`) whose it is.
    pending_feed: Option<(SimNanos, Bytes)>,
}

/// How long a fed depth sentence waits for a `$PEBHS` naming its transducer (simulated time).
pub const FEED_MAPPING_WAIT_NS: u64 = 200_000_000;

impl Multiplexer {
    pub fn new(settings: MultiplexerSettings) -> Self {
        Self {
            settings,
            counters: MultiplexerCounters::default(),
            events: Vec::new(),
            selected: None,
            feed_active: false,
            pending_feed: None,
        }
    }

    /// A feed starts (`true`) or ends: while active, the model's readings are not forwarded.
    pub fn set_feed_active(&mut self, active: bool) {
        self.feed_active = active;
        if !active {
            self.pending_feed = None;
        }
    }

    pub fn feed_active(&self) -> bool {
        self.feed_active
    }

    /// One complete sentence from a feed (with CR LF), decoded as `sentence`, at `now`.
    /// Returns the bytes to put on the sonar line now, if any.
    pub fn feed(&mut self, sentence: &Sentence, raw: Bytes, now: SimNanos) -> Option<Bytes> {
        match sentence {
            Sentence::Echo(report) => {
                let pending = self.pending_feed.take()?;
                if Some(report.transducer.get()) == self.selected {
                    self.counters.fed += 1;
                    Some(pending.1)
                } else {
                    self.counters.fed_withheld += 1;
                    None
                }
            }
            Sentence::Dbt(_) | Sentence::Dpt(_) => {
                // A depth sentence with no mapping after it goes out as it is.
                let earlier = self.pending_feed.replace((now, raw)).map(|p| p.1);
                if earlier.is_some() {
                    self.counters.fed += 1;
                }
                earlier
            }
        }
    }

    /// A fed depth sentence whose mapping wait ran out is forwarded.
    pub fn feed_timeout(&self) -> Option<SimNanos> {
        self.pending_feed
            .as_ref()
            .map(|(t, _)| t + FEED_MAPPING_WAIT_NS)
    }

    /// Releases a fed depth sentence whose mapping wait ran out by `now`.
    pub fn poll_feed(&mut self, now: SimNanos) -> Option<Bytes> {
        if self.feed_timeout().is_some_and(|t| t <= now) {
            self.counters.fed += 1;
            return self.pending_feed.take().map(|p| p.1);
        }
        None
    }

    pub fn counters(&self) -> MultiplexerCounters {
        self.counters
    }

    /// A command from the EyeBot side.
    pub fn handle(
        &mut self,
        command: SonarCommand,
        now: SimNanos,
        plant: &mut dyn Plant,
    ) -> Option<Bytes> {
        match command {
            SonarCommand::Select(t) => {
                self.counters.selects += 1;
                plant.sonar_select(t.get(), now);
                None
            }
            // Only the master sends these; one arriving from the EyeBot is line noise.
            SonarCommand::Ack(_) | SonarCommand::Nak => {
                self.counters.rx_errors += 1;
                None
            }
        }
    }

    /// A wire error on the sonar line. A select with a bad transducer digit is answered with
    /// `@N\r\n`, as the PICAXE program does; everything else is counted.
    pub fn handle_error(&mut self, error: &LinkError) -> Option<Bytes> {
        self.counters.rx_errors += 1;
        match error {
            LinkError::SonarCommand(SonarCommandError::BadTransducer { .. }) => {
                self.counters.naks += 1;
                let mut out = BytesMut::new();
                SonarCommand::Nak.encode(&mut out);
                Some(out.freeze())
            }
            _ => None,
        }
    }

    /// When the sonar model next has an event.
    pub fn poll_timeout(&self, plant: &dyn Plant) -> Option<SimNanos> {
        plant.sonar_timeout()
    }

    /// The bytes due by `now`: acknowledgements and forwarded sentences, with their times.
    pub fn poll(&mut self, now: SimNanos, plant: &mut dyn Plant, out: &mut Vec<(SimNanos, Bytes)>) {
        self.events.clear();
        plant.sonar_poll(now, &mut self.events);
        for i in 0..self.events.len() {
            let (at, event) = self.events[i];
            if let Some(bytes) = self.encode_event(event) {
                out.push((at, bytes));
            }
        }
    }

    fn encode_event(&mut self, event: SonarEvent) -> Option<Bytes> {
        let mut buf = BytesMut::new();
        match event {
            SonarEvent::Switched { transducer } => {
                let t = Transducer::new(transducer).ok()?;
                self.selected = Some(transducer);
                self.counters.acks += 1;
                SonarCommand::Ack(t).encode(&mut buf);
            }
            SonarEvent::Reading { .. } if self.feed_active => return None,
            SonarEvent::Reading {
                transducer,
                range_m,
                quality_pct,
            } => {
                let talker = self.settings.talker;
                let depth = match (range_m, self.settings.invalid_echo) {
                    (Some(range_m), _) => Some(match self.settings.sentence {
                        DepthSentence::Dbt => {
                            Sentence::Dbt(Dbt::from_depth_m(talker, range_m).ok()?)
                        }
                        DepthSentence::Dpt { offset_m } => {
                            Sentence::Dpt(Dpt::new(talker, range_m, offset_m).ok()?)
                        }
                    }),
                    (None, InvalidEcho::Omit) => None,
                    (None, InvalidEcho::EmptyFields) => Some(match self.settings.sentence {
                        DepthSentence::Dbt => Sentence::Dbt(Dbt::empty(talker)),
                        DepthSentence::Dpt { offset_m } => Sentence::Dpt(Dpt {
                            depth_m: None,
                            ..Dpt::new(talker, 0.0, offset_m).ok()?
                        }),
                    }),
                };
                if range_m.is_none() {
                    self.counters.invalid_echoes += 1;
                }
                if let Some(sentence) = depth {
                    if let Err(e) = sentence.encode(&mut buf) {
                        tracing::error!(error = %e, "cannot encode depth sentence");
                        return None;
                    }
                    self.counters.sentences += 1;
                }
                if self.settings.proprietary {
                    let report = Transducer::new(transducer)
                        .ok()
                        .and_then(|t| EchoReport::new(t, range_m, quality_pct.min(100)).ok());
                    if let Some(report) = report
                        && Sentence::Echo(report).encode(&mut buf).is_ok()
                    {
                        self.counters.sentences += 1;
                    }
                }
            }
        }
        (!buf.is_empty()).then(|| buf.freeze())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::fake::FakePlant;

    const MS: u64 = 1_000_000;

    fn mux(invalid_echo: InvalidEcho, proprietary: bool) -> Multiplexer {
        Multiplexer::new(MultiplexerSettings {
            sentence: DepthSentence::Dbt,
            talker: Talker::SOUNDER,
            invalid_echo,
            proprietary,
        })
    }

    #[test]
    fn select_then_ack_then_sentences() {
        let mut plant = FakePlant::default();
        let mut m = mux(InvalidEcho::Omit, false);
        let select = SonarCommand::Select(Transducer::new(2).unwrap());
        assert_eq!(m.handle(select, 5 * MS, &mut plant), None);
        assert_eq!(plant.selects, vec![(5 * MS, 2)]);
        plant.sonar = vec![
            (60 * MS, SonarEvent::Switched { transducer: 2 }),
            (
                1_000 * MS,
                SonarEvent::Reading {
                    transducer: 2,
                    range_m: Some(2.3),
                    quality_pct: 90,
                },
            ),
        ];
        assert_eq!(m.poll_timeout(&plant), Some(60 * MS));
        let mut out = Vec::new();
        m.poll(2_000 * MS, &mut plant, &mut out);
        assert_eq!(out[0], (60 * MS, Bytes::from_static(b"@A2\r\n")));
        let sentence = std::str::from_utf8(&out[1].1).unwrap();
        assert!(
            sentence.starts_with("$SDDBT,7.5,f,2.3,M,1.3,F*"),
            "{sentence}"
        );
        assert!(sentence.ends_with("\r\n"));
    }

    #[test]
    fn invalid_echo_is_omitted_by_default_or_sent_with_empty_fields() {
        let reading = SonarEvent::Reading {
            transducer: 1,
            range_m: None,
            quality_pct: 0,
        };
        let mut plant = FakePlant {
            sonar: vec![(MS, reading)],
            ..FakePlant::default()
        };
        let mut omit = mux(InvalidEcho::Omit, false);
        let mut out = Vec::new();
        omit.poll(MS, &mut plant, &mut out);
        assert!(out.is_empty());
        assert_eq!(omit.counters().invalid_echoes, 1);

        plant.sonar = vec![(MS, reading)];
        let mut empty = mux(InvalidEcho::EmptyFields, false);
        empty.poll(MS, &mut plant, &mut out);
        assert!(
            std::str::from_utf8(&out[0].1)
                .unwrap()
                .starts_with("$SDDBT,,f,,M,,F*")
        );
    }

    #[test]
    fn proprietary_sentence_names_the_real_transducer() {
        let mut plant = FakePlant {
            sonar: vec![(
                MS,
                SonarEvent::Reading {
                    transducer: 3,
                    range_m: Some(3.1),
                    quality_pct: 75,
                },
            )],
            ..FakePlant::default()
        };
        let mut m = mux(InvalidEcho::Omit, true);
        let mut out = Vec::new();
        m.poll(MS, &mut plant, &mut out);
        let text = std::str::from_utf8(&out[0].1).unwrap();
        let lines: Vec<&str> = text.split_inclusive("\r\n").collect();
        assert_eq!(lines.len(), 2);
        assert!(lines[1].starts_with("$PEBHS,3,"), "{text}");
    }

    fn parsed(line: &[u8]) -> Sentence {
        firmware_protocol::nmea::parse_line(line).unwrap()
    }

    fn echo(t: u8, range_m: f64) -> Bytes {
        let mut b = BytesMut::new();
        Sentence::Echo(EchoReport::new(Transducer::new(t).unwrap(), Some(range_m), 90).unwrap())
            .encode(&mut b)
            .unwrap();
        b.freeze()
    }

    fn dbt(range_m: f64) -> Bytes {
        let mut b = BytesMut::new();
        Sentence::Dbt(Dbt::from_depth_m(Talker::SOUNDER, range_m).unwrap())
            .encode(&mut b)
            .unwrap();
        b.freeze()
    }

    /// With a feed, the log's ranges replace the model's, and a `$PEBHS` after a depth
    /// sentence decides whether it belongs to the selected transducer.
    #[test]
    fn a_feed_replaces_the_model_and_follows_the_logged_transducer() {
        let mut plant = FakePlant {
            sonar: vec![
                (10 * MS, SonarEvent::Switched { transducer: 2 }),
                (
                    500 * MS,
                    SonarEvent::Reading {
                        transducer: 2,
                        range_m: Some(9.9),
                        quality_pct: 90,
                    },
                ),
            ],
            ..FakePlant::default()
        };
        let mut m = mux(InvalidEcho::Omit, false);
        m.set_feed_active(true);
        let mut out = Vec::new();
        m.poll(1_000 * MS, &mut plant, &mut out);
        assert_eq!(
            out.len(),
            1,
            "the ack only; the model's 9.9 m reading is not forwarded"
        );
        // Transducer 2's range is forwarded once its $PEBHS arrives...
        let d = dbt(2.1);
        assert_eq!(m.feed(&parsed(&d), d.clone(), 1_100 * MS), None);
        let e = echo(2, 2.1);
        assert_eq!(m.feed(&parsed(&e), e, 1_140 * MS), Some(d));
        // ...transducer 1's is withheld...
        let d = dbt(3.3);
        m.feed(&parsed(&d), d, 2_100 * MS);
        let e = echo(1, 3.3);
        assert_eq!(m.feed(&parsed(&e), e, 2_140 * MS), None);
        // ...and one without mapping goes out after the wait.
        let d = dbt(4.0);
        m.feed(&parsed(&d), d.clone(), 3_000 * MS);
        assert_eq!(m.poll_feed(3_100 * MS), None);
        assert_eq!(m.feed_timeout(), Some(3_200 * MS));
        assert_eq!(m.poll_feed(3_200 * MS), Some(d));
        assert_eq!((m.counters().fed, m.counters().fed_withheld), (2, 1));
    }

    #[test]
    fn a_select_with_a_bad_digit_is_naked_and_counted() {
        let mut m = mux(InvalidEcho::Omit, false);
        let err = LinkError::SonarCommand(SonarCommandError::BadTransducer { byte: b'7' });
        assert_eq!(m.handle_error(&err), Some(Bytes::from_static(b"@N\r\n")));
        let other = LinkError::Skipped { count: 3 };
        assert_eq!(m.handle_error(&other), None);
        assert_eq!(m.counters().rx_errors, 2);
        assert_eq!(m.counters().naks, 1);
    }
}
