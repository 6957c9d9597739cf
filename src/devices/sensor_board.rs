//! The sensor-link board: what sits behind the EyeBot's binary sensor link.
//!
//! It answers every request frame with exactly one reply carrying the request's sequence
//! number (or a NAK saying what was wrong), and pushes unsolicited frames (ADC streams,
//! continuous compass headings) from its own push sequence. It holds four small devices:
//!
//! - the **ADC board**: polled reads and a stream of chosen channels at a set period;
//! - the **Vector 2X compass**: poll mode (the reply carries the latest completed
//!   measurement; the conversion delay is the sensor model's latency), continuous mode (a
//!   push at the compass's own rate), binary/BCD/raw output, the two-point calibration, reset;
//! - the **motor driver**: PWM duty and direction per thruster, with an optional watchdog that
//!   zeroes the thrusters when the link goes silent;
//! - **time**: simulated time in ticks, and lockstep advances, which the bridge core carries
//!   out (the board only asks for them, see [`Output::Advance`]).
//!
//! Retries are idempotent (PROTOCOL.md 2.2): the board remembers the last request it executed
//! and its reply, and answers an identical request with the stored reply without executing
//! it again, so a retried TIME_ADVANCE or TAKE_POINT is never applied twice.

use firmware_protocol::error::{FrameError, LinkError, MessageError};
use firmware_protocol::sensor_link::{
    self, AdcChannel, AdcSamples, AdcValue, CompassMode, CompassOutput, Counters, ErrorCode,
    Message, ThrusterCommand, TimeMode, capability, msg_type,
};
use firmware_protocol::{Frame, HeadingFormat, HeadingWord};

use super::Plant;
use crate::SimNanos;

/// Fixed settings of the board.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardSettings {
    /// One lockstep tick (MK4's `OSGetCount` tick, 10 ms by default).
    pub tick_ns: u64,
    /// Whether the daemon runs in lockstep (TIME_ADVANCE allowed) or realtime.
    pub lockstep: bool,
    /// Period of the compass's continuous mode (about 400 ms: 2.5 Hz).
    pub compass_period_ns: u64,
    /// Characters per second the line carries (for the ADC stream capacity check).
    pub line_chars_per_s: f64,
    /// Zero the thrusters after this long without a thruster frame.
    pub watchdog_ns: Option<u64>,
    /// Whether the sonar link shares this line (reported in HELLO_REPLY).
    pub sonar_on_this_line: bool,
}

/// What the board wants done after handling an input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// Send this frame now.
    Send(Frame),
    /// Lockstep: advance simulated time to `to`, then call [`SensorBoard::finish_advance`]
    /// to get the TIME reply for `seq`.
    Advance { to: SimNanos, seq: u8 },
}

#[derive(Debug, Clone, Copy)]
struct AdcStream {
    mask: u8,
    period_ns: u64,
    next_ns: SimNanos,
}

/// The last executed request and the reply it got.
#[derive(Debug, Clone, Copy)]
struct LastRequest {
    request: Frame,
    reply: Frame,
}

/// The board's state.
#[derive(Debug)]
pub struct SensorBoard {
    settings: BoardSettings,
    counters: Counters,
    push_seq: u8,
    stream: Option<AdcStream>,
    compass_mode: CompassMode,
    compass_output: CompassOutput,
    next_compass_push_ns: Option<SimNanos>,
    last_request: Option<LastRequest>,
    pending_advance: Option<Frame>,
    duplicates: u64,
    thrusters: [ThrusterCommand; 4],
    last_thruster_ns: Option<SimNanos>,
    watchdog_trips: u64,
}

impl SensorBoard {
    pub fn new(settings: BoardSettings) -> Self {
        Self {
            settings,
            counters: Counters::default(),
            push_seq: 0,
            stream: None,
            compass_mode: CompassMode::Poll,
            compass_output: CompassOutput::Binary,
            next_compass_push_ns: None,
            last_request: None,
            pending_advance: None,
            duplicates: 0,
            thrusters: [ThrusterCommand::OFF; 4],
            last_thruster_ns: None,
            watchdog_trips: 0,
        }
    }

    /// The protocol counters (also what COUNTERS_GET returns).
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Retried requests answered from the stored reply.
    pub fn duplicates(&self) -> u64 {
        self.duplicates
    }

    /// How often the watchdog zeroed the thrusters.
    pub fn watchdog_trips(&self) -> u64 {
        self.watchdog_trips
    }

    /// The motor driver's current outputs.
    pub fn thrusters(&self) -> [ThrusterCommand; 4] {
        self.thrusters
    }

    fn ticks(&self, now: SimNanos) -> u32 {
        // The tick counter wraps like a 32-bit hardware counter.
        (now / self.settings.tick_ns) as u32
    }

    fn reply(&mut self, seq: u8, message: Message) -> Output {
        self.reply_frame(Frame::new(seq, message))
    }

    /// Counts and sends a reply (a NAK also counts as a NAK sent).
    fn reply_frame(&mut self, frame: Frame) -> Output {
        self.counters.tx_frames = self.counters.tx_frames.wrapping_add(1);
        if matches!(frame.message, Message::Nak { .. }) {
            self.counters.tx_naks = self.counters.tx_naks.wrapping_add(1);
        }
        Output::Send(frame)
    }

    fn push(&mut self, message: Message) -> Frame {
        self.counters.tx_frames = self.counters.tx_frames.wrapping_add(1);
        let seq = self.push_seq;
        self.push_seq = self.push_seq.wrapping_add(1);
        Frame::new(seq, message)
    }

    fn nak(&mut self, seq: u8, rejected_type: u8, code: ErrorCode, detail: u8) -> Output {
        self.reply(
            seq,
            Message::Nak {
                rejected_type,
                code,
                detail,
            },
        )
    }

    /// A wire error on this link: counted, and answered with a NAK as PROTOCOL.md section 3
    /// says (a CRC mismatch gets an advisory BAD_CRC NAK with the type and seq as received).
    pub fn handle_error(&mut self, error: &LinkError) -> Option<Output> {
        match error {
            LinkError::Skipped { count } => {
                self.counters.rx_skipped_bytes =
                    self.counters.rx_skipped_bytes.wrapping_add(*count as u32);
                None
            }
            LinkError::Frame(FrameError::ChecksumMismatch { msg_type, seq, .. }) => {
                self.counters.rx_crc_errors = self.counters.rx_crc_errors.wrapping_add(1);
                // PROTOCOL.md: the bridge never NAKs a NAK.
                (*msg_type != msg_type::NAK)
                    .then(|| self.nak(*seq, *msg_type, ErrorCode::BadCrc, 0))
            }
            LinkError::Frame(_) => {
                self.counters.rx_framing_errors = self.counters.rx_framing_errors.wrapping_add(1);
                None
            }
            LinkError::Message(e) => {
                self.counters.rx_rejected = self.counters.rx_rejected.wrapping_add(1);
                if e.msg_type() == msg_type::NAK {
                    return None; // never NAK a NAK
                }
                let (code, detail) = match e {
                    // A reply or push type is not a request, whatever its length or values.
                    _ if !REQUEST_TYPES.contains(&e.msg_type()) => (ErrorCode::UnknownType, 0),
                    MessageError::UnknownType { .. } => (ErrorCode::UnknownType, 0),
                    MessageError::BadLength { expected, .. } => (ErrorCode::BadLength, *expected),
                    MessageError::BadValue { offset, .. } => (ErrorCode::BadValue, *offset),
                };
                Some(self.nak(e.seq(), e.msg_type(), code, detail))
            }
            // NMEA or sonar-command errors belong to the multiplexer's side of a shared line.
            LinkError::Nmea(_) | LinkError::Sentence(_) | LinkError::SonarCommand(_) => None,
        }
    }

    /// Handles one decoded frame from the EyeBot side at simulated time `now`.
    ///
    /// Counting (PROTOCOL.md 2.4, COUNTERS): a frame whose CRC checks is counted once, as
    /// "received OK" when it is answered with its reply (or starts a lockstep advance), and as
    /// "rejected" when it is answered with a NAK of any code or not answered at all (a NAK
    /// sent to the bridge). A retry answered from the stored reply counts the same way again.
    pub fn handle(&mut self, frame: Frame, now: SimNanos, plant: &mut dyn Plant) -> Option<Output> {
        let out = match self.last_request.filter(|l| l.request == frame) {
            Some(last) => {
                self.duplicates += 1;
                tracing::debug!(
                    seq = frame.seq,
                    "retried request answered from the stored reply"
                );
                Some(self.reply_frame(last.reply))
            }
            None => {
                let out = self.execute(frame, now, plant);
                if let Some(Output::Send(reply)) = out {
                    self.remember(frame, reply);
                }
                out
            }
        };
        let rejected = match &out {
            Some(Output::Send(reply)) => matches!(reply.message, Message::Nak { .. }),
            Some(Output::Advance { .. }) => false,
            None => true,
        };
        if rejected {
            self.counters.rx_rejected = self.counters.rx_rejected.wrapping_add(1);
        } else {
            self.counters.rx_frames = self.counters.rx_frames.wrapping_add(1);
        }
        out
    }

    fn remember(&mut self, request: Frame, reply: Frame) {
        self.last_request = Some(LastRequest { request, reply });
    }

    fn execute(&mut self, frame: Frame, now: SimNanos, plant: &mut dyn Plant) -> Option<Output> {
        let seq = frame.seq;
        let kind = frame.message.msg_type();
        let out = match frame.message {
            Message::Hello { client_version } => {
                if client_version != sensor_link::PROTOCOL_VERSION {
                    return Some(self.nak(
                        seq,
                        kind,
                        ErrorCode::VersionMismatch,
                        sensor_link::PROTOCOL_VERSION,
                    ));
                }
                // A new session: streams stop, compass back to poll/binary, thrusters off.
                self.stream = None;
                self.compass_mode = CompassMode::Poll;
                self.compass_output = CompassOutput::Binary;
                self.next_compass_push_ns = None;
                self.last_request = None;
                if self.thrusters != [ThrusterCommand::OFF; 4] {
                    self.thrusters = [ThrusterCommand::OFF; 4];
                    plant.set_thrusters(self.thrusters, now);
                }
                self.last_thruster_ns = None;
                let mut capabilities = capability::ADC
                    | capability::ADC_STREAM
                    | capability::COMPASS
                    | capability::COMPASS_RAW
                    | capability::COMPASS_CALIBRATION
                    | capability::THRUSTERS;
                if self.settings.lockstep {
                    capabilities |= capability::LOCKSTEP;
                }
                if self.settings.sonar_on_this_line {
                    capabilities |= capability::SONAR_ON_THIS_LINE;
                }
                Message::HelloReply {
                    protocol_version: sensor_link::PROTOCOL_VERSION,
                    capabilities,
                    tick_us: (self.settings.tick_ns / 1000) as u32,
                    max_payload: firmware_protocol::frame::MAX_PAYLOAD as u8,
                }
            }
            Message::CountersGet => Message::Counters(self.counters),
            Message::AdcRead { channel } => Message::AdcValue {
                channel,
                value: adc_value(plant, channel, now),
            },
            Message::AdcStream {
                channels,
                period_ms,
            } => {
                if channels == 0 {
                    self.stream = None;
                } else if period_ms == 0 || self.stream_overloads_line(channels, period_ms) {
                    return Some(self.nak(seq, kind, ErrorCode::BadValue, 1));
                } else {
                    let period_ns = u64::from(period_ms) * 1_000_000;
                    self.stream = Some(AdcStream {
                        mask: channels,
                        period_ns,
                        next_ns: now + period_ns,
                    });
                }
                Message::Ack { acked_type: kind }
            }
            Message::CompassMode { mode, output } => {
                self.compass_mode = mode;
                self.compass_output = output;
                self.next_compass_push_ns = match mode {
                    CompassMode::Continuous => Some(now + self.settings.compass_period_ns),
                    CompassMode::Poll => None,
                };
                Message::Ack { acked_type: kind }
            }
            Message::CompassRead => self.compass_message(plant, now, false),
            Message::CompassCalibrate { action } => match plant.compass_calibrate(action, now) {
                Ok(progress) => Message::CalibrationStatus {
                    state: progress.state,
                    points: progress.points,
                },
                Err(refused) => {
                    tracing::debug!(%refused, "calibration step refused");
                    return Some(self.nak(seq, kind, ErrorCode::BadState, 0));
                }
            },
            Message::CompassReset => {
                plant.compass_reset(now);
                self.compass_mode = CompassMode::Poll;
                self.compass_output = CompassOutput::Binary;
                self.next_compass_push_ns = None;
                Message::Ack { acked_type: kind }
            }
            Message::ThrusterSet { thruster, command } => {
                self.thrusters[thruster as usize] = command;
                self.last_thruster_ns = Some(now);
                plant.set_thrusters(self.thrusters, now);
                Message::Ack { acked_type: kind }
            }
            Message::ThrusterSetAll { commands } => {
                self.thrusters = commands;
                self.last_thruster_ns = Some(now);
                plant.set_thrusters(self.thrusters, now);
                Message::Ack { acked_type: kind }
            }
            Message::TimeGet => Message::Time {
                ticks: self.ticks(now),
                tick_us: (self.settings.tick_ns / 1000) as u32,
            },
            Message::TimeAdvance { ticks } => {
                if !self.settings.lockstep {
                    return Some(self.nak(seq, kind, ErrorCode::BadState, 0));
                }
                self.pending_advance = Some(frame);
                return Some(Output::Advance {
                    to: now + u64::from(ticks) * self.settings.tick_ns,
                    seq,
                });
            }
            Message::TimeMode { mode } => {
                let ours = if self.settings.lockstep {
                    TimeMode::Lockstep
                } else {
                    TimeMode::RealTime
                };
                if mode != ours {
                    // The daemon's time mode is chosen when it starts (--time-mode).
                    return Some(self.nak(seq, kind, ErrorCode::BadState, 0));
                }
                Message::Ack { acked_type: kind }
            }
            // Replies and pushes travel bridge -> EyeBot only.
            Message::Ack { .. }
            | Message::HelloReply { .. }
            | Message::Counters(_)
            | Message::AdcValue { .. }
            | Message::CompassHeading { .. }
            | Message::CompassRaw { .. }
            | Message::CalibrationStatus { .. }
            | Message::Time { .. }
            | Message::AdcSamples { .. }
            | Message::CompassHeadingPush { .. }
            | Message::CompassRawPush { .. } => {
                return Some(self.nak(seq, kind, ErrorCode::UnknownType, 0));
            }
            // Counted (as rejected, in `handle`), never answered: the bridge never NAKs a NAK.
            Message::Nak { .. } => return None,
        };
        Some(self.reply(seq, out))
    }

    /// The TIME reply that ends a lockstep advance; call once simulated time reached `now`.
    pub fn finish_advance(&mut self, seq: u8, now: SimNanos) -> Frame {
        let message = Message::Time {
            ticks: self.ticks(now),
            tick_us: (self.settings.tick_ns / 1000) as u32,
        };
        let reply = Frame::new(seq, message);
        self.counters.tx_frames = self.counters.tx_frames.wrapping_add(1);
        if let Some(request) = self.pending_advance.take() {
            self.remember(request, reply);
        }
        reply
    }

    /// Whether streaming `channels` every `period_ms` would take more than half the line.
    fn stream_overloads_line(&self, channels: u8, period_ms: u16) -> bool {
        let frame_chars = (firmware_protocol::frame::HEADER_LEN
            + 5
            + 2 * channels.count_ones() as usize
            + firmware_protocol::frame::CRC_LEN) as f64;
        let chars_per_s = frame_chars * 1000.0 / f64::from(period_ms);
        chars_per_s > 0.5 * self.settings.line_chars_per_s
    }

    fn compass_message(&mut self, plant: &mut dyn Plant, now: SimNanos, push: bool) -> Message {
        let sample = plant.compass(now);
        let heading = sample.heading_deg.min(359);
        let word = |format| HeadingWord::encode(heading, format).unwrap_or(HeadingWord(0));
        match (self.compass_output, push) {
            (CompassOutput::Binary, false) => Message::CompassHeading {
                word: word(HeadingFormat::Binary),
            },
            (CompassOutput::Bcd, false) => Message::CompassHeading {
                word: word(HeadingFormat::Bcd),
            },
            (CompassOutput::Raw, false) => Message::CompassRaw {
                x: sample.raw_x,
                y: sample.raw_y,
            },
            (CompassOutput::Binary, true) => Message::CompassHeadingPush {
                word: word(HeadingFormat::Binary),
            },
            (CompassOutput::Bcd, true) => Message::CompassHeadingPush {
                word: word(HeadingFormat::Bcd),
            },
            (CompassOutput::Raw, true) => Message::CompassRawPush {
                x: sample.raw_x,
                y: sample.raw_y,
            },
        }
    }

    /// When [`SensorBoard::poll`] next has something to do.
    pub fn poll_timeout(&self) -> Option<SimNanos> {
        let watchdog = match (self.settings.watchdog_ns, self.last_thruster_ns) {
            (Some(limit), Some(last)) => Some(last + limit),
            _ => None,
        };
        [
            self.stream.map(|s| s.next_ns),
            self.next_compass_push_ns,
            watchdog,
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// Emits what is due by `now` (stream samples, compass pushes) in time order, and runs
    /// the watchdog.
    pub fn poll(&mut self, now: SimNanos, plant: &mut dyn Plant, out: &mut Vec<(SimNanos, Frame)>) {
        while let Some(due) = self.poll_timeout().filter(|&t| t <= now) {
            if self.next_compass_push_ns == Some(due) {
                self.next_compass_push_ns = Some(due + self.settings.compass_period_ns);
                let message = self.compass_message(plant, due, true);
                out.push((due, self.push(message)));
            } else if let Some(stream) = self.stream.filter(|s| s.next_ns == due) {
                self.stream = Some(AdcStream {
                    next_ns: due + stream.period_ns,
                    ..stream
                });
                let samples =
                    AdcSamples::new((0..8u8).filter(|c| stream.mask & (1 << c) != 0).filter_map(
                        |c| {
                            let channel = AdcChannel::new(c).ok()?;
                            Some((channel, adc_value(plant, channel, due)))
                        },
                    ));
                let message = Message::AdcSamples {
                    ticks: self.ticks(due),
                    samples,
                };
                out.push((due, self.push(message)));
            } else {
                // The watchdog: silence on the thruster commands for too long.
                self.last_thruster_ns = None;
                if self.thrusters != [ThrusterCommand::OFF; 4] {
                    self.thrusters = [ThrusterCommand::OFF; 4];
                    self.watchdog_trips += 1;
                    tracing::warn!(
                        at_s = due as f64 * 1e-9,
                        "motor watchdog: no thruster frame, thrusters zeroed"
                    );
                    plant.set_thrusters(self.thrusters, due);
                }
            }
        }
    }
}

fn adc_value(plant: &mut dyn Plant, channel: AdcChannel, now: SimNanos) -> AdcValue {
    let raw = plant.adc(channel.get(), now).min(1023);
    AdcValue::new(raw).unwrap_or_else(|_| unreachable!("clamped to 10 bits"))
}

/// Message types a sensor board answers, for documentation and tests.
pub const REQUEST_TYPES: &[u8] = &[
    msg_type::HELLO,
    msg_type::COUNTERS_GET,
    msg_type::ADC_READ,
    msg_type::ADC_STREAM,
    msg_type::COMPASS_MODE,
    msg_type::COMPASS_READ,
    msg_type::COMPASS_CALIBRATE,
    msg_type::COMPASS_RESET,
    msg_type::THRUSTER_SET,
    msg_type::THRUSTER_SET_ALL,
    msg_type::TIME_GET,
    msg_type::TIME_ADVANCE,
    msg_type::TIME_MODE,
];

#[cfg(test)]
mod tests {
    use firmware_protocol::sensor_link::{
        CalibrationAction, CalibrationState, Direction, Thruster,
    };

    use super::*;
    use crate::devices::fake::FakePlant;

    const MS: u64 = 1_000_000;

    fn board(lockstep: bool, watchdog_ms: Option<u64>) -> SensorBoard {
        SensorBoard::new(BoardSettings {
            tick_ns: 10 * MS,
            lockstep,
            compass_period_ns: 400 * MS,
            line_chars_per_s: 11_520.0,
            watchdog_ns: watchdog_ms.map(|m| m * MS),
            sonar_on_this_line: false,
        })
    }

    fn sent(out: Option<Output>) -> Frame {
        match out {
            Some(Output::Send(frame)) => frame,
            other => panic!("expected a frame, got {other:?}"),
        }
    }

    #[test]
    fn adc_read_answers_with_the_plant_code_and_the_request_seq() {
        let mut plant = FakePlant {
            adc: [0, 0, 0, 0x2AB, 0, 0, 0, 0],
            ..FakePlant::default()
        };
        let mut b = board(false, None);
        let channel = AdcChannel::new(3).unwrap();
        let reply = sent(b.handle(Frame::new(7, Message::AdcRead { channel }), 0, &mut plant));
        assert_eq!(reply.seq, 7);
        assert_eq!(
            reply.message,
            Message::AdcValue {
                channel,
                value: AdcValue::new(0x2AB).unwrap()
            }
        );
    }

    #[test]
    fn adc_stream_pushes_chosen_channels_every_period_until_stopped() {
        let mut plant = FakePlant {
            adc: [1, 2, 3, 4, 5, 6, 7, 8],
            ..FakePlant::default()
        };
        let mut b = board(false, None);
        let ack = sent(b.handle(
            Frame::new(
                1,
                Message::AdcStream {
                    channels: 0b0000_0101,
                    period_ms: 10,
                },
            ),
            0,
            &mut plant,
        ));
        assert_eq!(
            ack.message,
            Message::Ack {
                acked_type: msg_type::ADC_STREAM
            }
        );
        let mut out = Vec::new();
        b.poll(35 * MS, &mut plant, &mut out);
        let times: Vec<_> = out.iter().map(|(t, _)| *t).collect();
        assert_eq!(times, vec![10 * MS, 20 * MS, 30 * MS]);
        let Message::AdcSamples { ticks, samples } = out[0].1.message else {
            panic!("not samples")
        };
        assert_eq!(ticks, 1);
        assert_eq!(samples.mask(), 0b101);
        assert_eq!(
            samples.get(AdcChannel::new(2).unwrap()),
            Some(AdcValue::new(3).unwrap())
        );
        assert_ne!(
            out[0].1.seq, out[1].1.seq,
            "pushes carry their own sequence"
        );
        b.handle(
            Frame::new(
                2,
                Message::AdcStream {
                    channels: 0,
                    period_ms: 0,
                },
            ),
            35 * MS,
            &mut plant,
        );
        assert_eq!(b.poll_timeout(), None);
    }

    #[test]
    fn compass_read_answers_at_once_with_the_latest_measurement() {
        let mut plant = FakePlant {
            heading_deg: 271,
            ..FakePlant::default()
        };
        let mut b = board(false, None);
        let reply = sent(b.handle(Frame::new(9, Message::CompassRead), 100 * MS, &mut plant));
        assert_eq!(reply.seq, 9);
        assert_eq!(
            reply.message,
            Message::CompassHeading {
                word: HeadingWord::encode(271, HeadingFormat::Binary).unwrap()
            }
        );
        assert_eq!(plant.compass_reads, vec![100 * MS]);
    }

    /// A retried request (same seq, type and payload) is answered again but not executed
    /// again: a lost TIME reply must not make the client's OSWait advance time twice.
    #[test]
    fn retried_requests_are_not_executed_twice() {
        let mut plant = FakePlant::default();
        let mut b = board(true, None);
        let cal = |seq, action| Frame::new(seq, Message::CompassCalibrate { action });
        sent(b.handle(cal(1, CalibrationAction::Start), 0, &mut plant));
        let first = sent(b.handle(cal(2, CalibrationAction::TakePoint), 0, &mut plant));
        let retry = sent(b.handle(cal(2, CalibrationAction::TakePoint), 0, &mut plant));
        assert_eq!(first, retry);
        assert_eq!(
            plant.calibration_points, 1,
            "the retry took no second point"
        );
        assert_eq!(b.duplicates(), 1);
        // A new seq is a new request, even with the same payload.
        sent(b.handle(cal(3, CalibrationAction::TakePoint), 0, &mut plant));
        assert_eq!(plant.calibration_points, 2);

        let advance = Frame::new(4, Message::TimeAdvance { ticks: 5 });
        assert!(matches!(
            b.handle(advance, 0, &mut plant),
            Some(Output::Advance { .. })
        ));
        let time = b.finish_advance(4, 50 * MS);
        assert_eq!(
            b.handle(advance, 50 * MS, &mut plant),
            Some(Output::Send(time)),
            "no second advance"
        );
    }

    #[test]
    fn hello_starts_a_clean_session() {
        let mut plant = FakePlant::default();
        let mut b = board(false, None);
        let full = ThrusterCommand {
            duty: 0,
            direction: Direction::Forward,
        };
        sent(b.handle(
            Frame::new(
                1,
                Message::ThrusterSetAll {
                    commands: [full; 4],
                },
            ),
            0,
            &mut plant,
        ));
        sent(b.handle(
            Frame::new(
                2,
                Message::AdcStream {
                    channels: 1,
                    period_ms: 10,
                },
            ),
            0,
            &mut plant,
        ));
        let reply = sent(b.handle(
            Frame::new(3, Message::Hello { client_version: 1 }),
            5 * MS,
            &mut plant,
        ));
        assert!(matches!(
            reply.message,
            Message::HelloReply {
                protocol_version: 1,
                ..
            }
        ));
        assert_eq!(b.thrusters(), [ThrusterCommand::OFF; 4]);
        assert_eq!(plant.thrusters.last().unwrap().1, [ThrusterCommand::OFF; 4]);
        assert_eq!(b.poll_timeout(), None, "the stream stopped");
        let old = sent(b.handle(
            Frame::new(3, Message::Hello { client_version: 9 }),
            5 * MS,
            &mut plant,
        ));
        assert!(matches!(
            old.message,
            Message::Nak {
                code: ErrorCode::VersionMismatch,
                detail: 1,
                ..
            }
        ));
    }

    #[test]
    fn a_stream_that_would_fill_the_line_is_refused() {
        let mut plant = FakePlant::default();
        let mut slow = SensorBoard::new(BoardSettings {
            line_chars_per_s: 480.0,
            ..board(false, None).settings
        });
        let nak = sent(slow.handle(
            Frame::new(
                1,
                Message::AdcStream {
                    channels: 0xFF,
                    period_ms: 10,
                },
            ),
            0,
            &mut plant,
        ));
        assert!(matches!(
            nak.message,
            Message::Nak {
                code: ErrorCode::BadValue,
                detail: 1,
                ..
            }
        ));
    }

    #[test]
    fn continuous_bcd_compass_pushes_at_its_rate() {
        let mut plant = FakePlant {
            heading_deg: 123,
            ..FakePlant::default()
        };
        let mut b = board(false, None);
        b.handle(
            Frame::new(
                1,
                Message::CompassMode {
                    mode: CompassMode::Continuous,
                    output: CompassOutput::Bcd,
                },
            ),
            0,
            &mut plant,
        );
        let mut out = Vec::new();
        b.poll(1000 * MS, &mut plant, &mut out);
        assert_eq!(out.len(), 2, "2.5 Hz: pushes at 400 and 800 ms");
        assert_eq!(
            out[0].1.message,
            Message::CompassHeadingPush {
                word: HeadingWord(0x0123)
            }
        );
    }

    #[test]
    fn calibration_steps_follow_the_plant_and_bad_steps_are_naked() {
        let mut plant = FakePlant::default();
        let mut b = board(false, None);
        let mut seq = 0u8;
        let mut cal = |action| {
            seq += 1;
            Frame::new(seq, Message::CompassCalibrate { action })
        };
        let finish_early = sent(b.handle(cal(CalibrationAction::Finish), 0, &mut plant));
        assert!(matches!(
            finish_early.message,
            Message::Nak {
                code: ErrorCode::BadState,
                ..
            }
        ));
        sent(b.handle(cal(CalibrationAction::Start), 0, &mut plant));
        sent(b.handle(cal(CalibrationAction::TakePoint), 0, &mut plant));
        let ready = sent(b.handle(cal(CalibrationAction::TakePoint), 0, &mut plant));
        assert_eq!(
            ready.message,
            Message::CalibrationStatus {
                state: CalibrationState::ReadyToFinish,
                points: 2
            }
        );
        let done = sent(b.handle(cal(CalibrationAction::Finish), 0, &mut plant));
        assert_eq!(
            done.message,
            Message::CalibrationStatus {
                state: CalibrationState::Idle,
                points: 0
            }
        );
    }

    #[test]
    fn thruster_frames_reach_the_plant_and_the_watchdog_zeroes_them() {
        let mut plant = FakePlant::default();
        let mut b = board(false, Some(500));
        let full = ThrusterCommand {
            duty: 0,
            direction: Direction::Forward,
        };
        sent(b.handle(
            Frame::new(
                1,
                Message::ThrusterSet {
                    thruster: Thruster::Stern,
                    command: full,
                },
            ),
            100 * MS,
            &mut plant,
        ));
        assert_eq!(plant.thrusters.last().unwrap().1[3], full);
        assert_eq!(b.poll_timeout(), Some(600 * MS));
        let mut out = Vec::new();
        b.poll(599 * MS, &mut plant, &mut out);
        assert_eq!(b.watchdog_trips(), 0);
        b.poll(600 * MS, &mut plant, &mut out);
        assert_eq!(b.watchdog_trips(), 1);
        assert_eq!(
            plant.thrusters.last().unwrap(),
            &(600 * MS, [ThrusterCommand::OFF; 4])
        );
        assert!(out.is_empty(), "the watchdog sends nothing on the wire");
    }

    #[test]
    fn lockstep_advance_is_carried_out_by_the_core_and_answered_with_time() {
        let mut plant = FakePlant::default();
        let mut realtime = board(false, None);
        let refused = sent(realtime.handle(
            Frame::new(3, Message::TimeAdvance { ticks: 5 }),
            0,
            &mut plant,
        ));
        assert!(matches!(
            refused.message,
            Message::Nak {
                code: ErrorCode::BadState,
                ..
            }
        ));

        let mut b = board(true, None);
        let out = b.handle(
            Frame::new(3, Message::TimeAdvance { ticks: 5 }),
            20 * MS,
            &mut plant,
        );
        assert_eq!(
            out,
            Some(Output::Advance {
                to: 70 * MS,
                seq: 3
            })
        );
        let time = b.finish_advance(3, 70 * MS);
        assert_eq!(time.seq, 3);
        assert_eq!(
            time.message,
            Message::Time {
                ticks: 7,
                tick_us: 10_000
            }
        );
    }

    #[test]
    fn wire_errors_are_counted_and_naked_when_the_header_is_trustworthy() {
        let mut b = board(false, None);
        let bad_len = LinkError::Message(MessageError::BadLength {
            msg_type: msg_type::ADC_READ,
            seq: 12,
            expected: 1,
            found: 3,
        });
        let nak = sent(b.handle_error(&bad_len));
        assert_eq!(nak.seq, 12);
        assert_eq!(
            nak.message,
            Message::Nak {
                rejected_type: msg_type::ADC_READ,
                code: ErrorCode::BadLength,
                detail: 1
            }
        );
        let crc = LinkError::Frame(FrameError::ChecksumMismatch {
            calculated: 1,
            found: 2,
            msg_type: 0x10,
            seq: 1,
        });
        let advisory = sent(b.handle_error(&crc));
        assert!(matches!(
            advisory.message,
            Message::Nak {
                code: ErrorCode::BadCrc,
                rejected_type: 0x10,
                ..
            }
        ));
        assert_eq!(advisory.seq, 1);
        assert_eq!(b.counters().rx_crc_errors, 1);
        assert_eq!(b.counters().rx_rejected, 1);
        assert_eq!(b.counters().tx_naks, 2);
    }

    /// PROTOCOL.md: the bridge never NAKs a NAK (whole, damaged or mis-sized), and a reply or
    /// push type sent to it gets UNKNOWN_TYPE whatever its size.
    #[test]
    fn naks_are_never_naked_and_reply_types_are_unknown() {
        let mut b = board(false, None);
        let nak_len = LinkError::Message(MessageError::BadLength {
            msg_type: msg_type::NAK,
            seq: 3,
            expected: 3,
            found: 1,
        });
        assert!(b.handle_error(&nak_len).is_none());
        let nak_crc = LinkError::Frame(FrameError::ChecksumMismatch {
            calculated: 1,
            found: 2,
            msg_type: msg_type::NAK,
            seq: 4,
        });
        assert!(b.handle_error(&nak_crc).is_none());
        let nak = Frame::new(
            5,
            Message::Nak {
                rejected_type: msg_type::HELLO,
                code: ErrorCode::BadCrc,
                detail: 0,
            },
        );
        assert!(b.handle(nak, 0, &mut FakePlant::default()).is_none());
        assert_eq!(b.counters().tx_naks, 0);
        assert_eq!(b.counters().rx_rejected, 2);
        for (reply_type, error) in [
            (
                msg_type::COUNTERS,
                MessageError::BadLength {
                    msg_type: msg_type::COUNTERS,
                    seq: 6,
                    expected: 40,
                    found: 0,
                },
            ),
            (
                msg_type::ADC_VALUE,
                MessageError::BadValue {
                    msg_type: msg_type::ADC_VALUE,
                    seq: 6,
                    offset: 0,
                    value: 0xFF,
                },
            ),
        ] {
            let out = sent(b.handle_error(&LinkError::Message(error)));
            assert_eq!(
                out.message,
                Message::Nak {
                    rejected_type: reply_type,
                    code: ErrorCode::UnknownType,
                    detail: 0
                }
            );
        }
    }

    /// PROTOCOL.md 2.4: a frame with a good CRC is "received OK" only when it gets its reply;
    /// one answered with any NAK (BAD_STATE and VERSION_MISMATCH included), or a NAK sent to
    /// the bridge, is "rejected". A retry answered from the stored reply counts again.
    #[test]
    fn a_nak_counts_the_frame_as_rejected_not_received() {
        let mut plant = FakePlant::default();
        let mut b = board(false, None);
        let counts = |b: &SensorBoard| {
            let c = b.counters();
            (c.rx_frames, c.rx_rejected, c.tx_frames, c.tx_naks)
        };
        sent(b.handle(Frame::new(1, Message::TimeGet), 0, &mut plant));
        assert_eq!(counts(&b), (1, 0, 1, 0), "a TIME_GET is received OK");
        let advance = Frame::new(2, Message::TimeAdvance { ticks: 5 });
        let nak = sent(b.handle(advance, 0, &mut plant));
        assert!(matches!(
            nak.message,
            Message::Nak {
                code: ErrorCode::BadState,
                ..
            }
        ));
        assert_eq!(counts(&b), (1, 1, 2, 1), "BAD_STATE is a rejection");
        let again = sent(b.handle(advance, 0, &mut plant));
        assert_eq!(again, nak, "the retry gets the stored NAK");
        assert_eq!(counts(&b), (1, 2, 3, 2), "and counts as a rejection again");
        let hello = Frame::new(3, Message::Hello { client_version: 2 });
        let mismatch = sent(b.handle(hello, 0, &mut plant));
        assert!(matches!(
            mismatch.message,
            Message::Nak {
                code: ErrorCode::VersionMismatch,
                detail: 1,
                ..
            }
        ));
        assert_eq!(counts(&b), (1, 3, 4, 3), "VERSION_MISMATCH is a rejection");
        let stray_reply = Frame::new(4, Message::Ack { acked_type: 0x10 });
        sent(b.handle(stray_reply, 0, &mut plant));
        assert_eq!(counts(&b), (1, 4, 5, 4), "a reply type is a rejection");
        let stray_nak = Frame::new(
            5,
            Message::Nak {
                rejected_type: 0x10,
                code: ErrorCode::BadValue,
                detail: 0,
            },
        );
        assert!(b.handle(stray_nak, 0, &mut plant).is_none());
        assert_eq!(counts(&b), (1, 5, 5, 4), "a NAK is rejected, not answered");
        let stream = Frame::new(
            6,
            Message::AdcStream {
                channels: 1,
                period_ms: 0,
            },
        );
        sent(b.handle(stream, 0, &mut plant));
        assert_eq!(
            counts(&b),
            (1, 6, 6, 5),
            "BAD_VALUE from the board is a rejection"
        );
    }
}
