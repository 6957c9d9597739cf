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

use firmware_protocol::Frame;
use firmware_protocol::error::{FrameError, LinkError, MessageError};
use firmware_protocol::sensor_link::{
    self, AdcChannel, AdcSamples, CompassMode, CompassOutput, Counters, ErrorCode, Message,
    Readings, ThrusterCommand, capability, msg_type,
};

use super::Plant;
use crate::SimNanos;

mod adc;
mod compass;
mod motors;
mod time;

use self::adc::adc_value;

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
    /// Lockstep TIME_STEP: advance simulated time to `to` (with `stop_on_sonar`, only until
    /// the end of the first tick in which bytes went out on the sonar line), then call
    /// [`SensorBoard::finish_step`] for the STEP reply.
    Step {
        to: SimNanos,
        seq: u8,
        stop_on_sonar: bool,
    },
}

/// The readings of the last STEP reply, which the next TIME_STEP may partly take back
/// (PROTOCOL.md 2.9). The plant saved its reading state just before they were made.
#[derive(Debug, Clone, Copy)]
struct OpenStep {
    readings: Readings,
    at: SimNanos,
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
    /// The readings the TIME_STEP being carried out asks for.
    pending_readings: Readings,
    open_step: Option<OpenStep>,
    /// Readings taken back (made for a STEP reply, never used by the client).
    taken_back: u64,
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
            pending_readings: Readings::default(),
            open_step: None,
            taken_back: 0,
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

    /// Readings made for STEP replies that the client took back unused.
    pub fn taken_back(&self) -> u64 {
        self.taken_back
    }

    /// How often the watchdog zeroed the thrusters.
    pub fn watchdog_trips(&self) -> u64 {
        self.watchdog_trips
    }

    /// The motor driver's current outputs.
    pub fn thrusters(&self) -> [ThrusterCommand; 4] {
        self.thrusters
    }

    /// One tick of simulated time.
    pub fn tick_ns(&self) -> u64 {
        self.settings.tick_ns
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
                if !matches!(frame.message, Message::TimeStep { .. }) {
                    // Any other request: the client used every value of the last STEP.
                    self.open_step = None;
                }
                let out = self.execute(frame, now, plant);
                if let Some(Output::Send(reply)) = out {
                    self.remember(frame, reply);
                }
                out
            }
        };
        let rejected = match &out {
            Some(Output::Send(reply)) => matches!(reply.message, Message::Nak { .. }),
            Some(Output::Advance { .. } | Output::Step { .. }) => false,
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
        match frame.message {
            Message::Hello { .. } => self.execute_hello(frame, now, plant),
            Message::CountersGet => Some(self.reply(seq, Message::Counters(self.counters))),
            Message::AdcRead { .. } | Message::AdcStream { .. } => {
                self.execute_adc(frame, now, plant)
            }
            Message::CompassMode { .. }
            | Message::CompassRead
            | Message::CompassCalibrate { .. }
            | Message::CompassReset => self.execute_compass(frame, now, plant),
            Message::ThrusterSet { .. } | Message::ThrusterSetAll { .. } => {
                self.execute_motors(frame, now, plant)
            }
            Message::TimeGet
            | Message::TimeAdvance { .. }
            | Message::TimeStep { .. }
            | Message::TimeMode { .. } => self.execute_time(frame, now, plant),
            // Replies and pushes travel bridge -> EyeBot only.
            Message::Ack { .. }
            | Message::HelloReply { .. }
            | Message::Counters(_)
            | Message::AdcValue { .. }
            | Message::CompassHeading { .. }
            | Message::CompassRaw { .. }
            | Message::CalibrationStatus { .. }
            | Message::Time { .. }
            | Message::Step { .. }
            | Message::AdcSamples { .. }
            | Message::CompassHeadingPush { .. }
            | Message::CompassRawPush { .. } => {
                Some(self.nak(seq, kind, ErrorCode::UnknownType, 0))
            }
            // Counted (as rejected, in `handle`), never answered: the bridge never NAKs a NAK.
            Message::Nak { .. } => None,
        }
    }

    /// HELLO: a new session.
    pub(super) fn execute_hello(
        &mut self,
        frame: Frame,
        now: SimNanos,
        plant: &mut dyn Plant,
    ) -> Option<Output> {
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
                    capabilities |= capability::LOCKSTEP | capability::TIME_STEP;
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
            _ => return None,
        };
        Some(self.reply(seq, out))
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
    msg_type::TIME_STEP,
];

#[cfg(test)]
mod tests;
