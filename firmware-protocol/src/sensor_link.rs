//! Sensor-link messages (EyeBot <-> bridge): ADC, compass, thrusters, time, service frames.
//!
//! A [`Frame`] is a sequence number plus a typed [`Message`]. Values are validated when they
//! are built ([`AdcChannel::new`], [`AdcValue::new`], ...), so a `Message` always encodes; a
//! payload from the wire that breaks a rule becomes a [`MessageError`] item instead.
//! `PROTOCOL.md` gives the byte layout of each message; the type numbers are in [`msg_type`].

use bytes::BytesMut;
use nom::{
    IResult, Parser,
    combinator::all_consuming,
    number::complete::{be_i16, be_u8, be_u16, be_u32},
};

use crate::compass_word::HeadingWord;
use crate::error::{EncodeError, FrameError, LinkError, MessageError};
use crate::frame::{self, RawFrame};

/// Protocol version this crate speaks (sent in HELLO and HELLO_REPLY).
pub const PROTOCOL_VERSION: u8 = 1;

/// Message type bytes. Requests 0x01..=0x7F (EyeBot -> bridge), replies 0x80..=0xBF,
/// unsolicited pushes 0xC0..=0xFE (bridge -> EyeBot).
pub mod msg_type {
    pub const HELLO: u8 = 0x01;
    pub const COUNTERS_GET: u8 = 0x02;
    pub const ADC_READ: u8 = 0x10;
    pub const ADC_STREAM: u8 = 0x11;
    pub const COMPASS_MODE: u8 = 0x20;
    pub const COMPASS_READ: u8 = 0x21;
    pub const COMPASS_CALIBRATE: u8 = 0x22;
    pub const COMPASS_RESET: u8 = 0x23;
    pub const THRUSTER_SET: u8 = 0x30;
    pub const THRUSTER_SET_ALL: u8 = 0x31;
    pub const TIME_GET: u8 = 0x40;
    pub const TIME_ADVANCE: u8 = 0x41;
    pub const TIME_MODE: u8 = 0x42;
    pub const TIME_STEP: u8 = 0x43;
    pub const ACK: u8 = 0x80;
    pub const HELLO_REPLY: u8 = 0x81;
    pub const COUNTERS: u8 = 0x82;
    pub const ADC_VALUE: u8 = 0x90;
    pub const COMPASS_HEADING: u8 = 0xA1;
    pub const COMPASS_RAW: u8 = 0xA2;
    pub const CALIBRATION_STATUS: u8 = 0xA3;
    pub const TIME: u8 = 0xB0;
    pub const STEP: u8 = 0xB1;
    pub const NAK: u8 = 0xBF;
    pub const ADC_SAMPLES: u8 = 0xD1;
    pub const COMPASS_HEADING_PUSH: u8 = 0xE1;
    pub const COMPASS_RAW_PUSH: u8 = 0xE2;
}

/// One of the eight 10-bit ADC inputs of the 68332.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct AdcChannel(u8);

impl AdcChannel {
    pub fn new(channel: u8) -> Result<Self, EncodeError> {
        if channel < 8 {
            Ok(Self(channel))
        } else {
            Err(EncodeError::AdcChannelOutOfRange { channel })
        }
    }
    pub fn get(self) -> u8 {
        self.0
    }
}

/// A 10-bit conversion result, 0..=1023; on the wire a big-endian u16 with the top 6 bits 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct AdcValue(u16);

impl AdcValue {
    pub fn new(value: u16) -> Result<Self, EncodeError> {
        if value < 1024 {
            Ok(Self(value))
        } else {
            Err(EncodeError::AdcValueOutOfRange { value })
        }
    }
    pub fn get(self) -> u16 {
        self.0
    }
}

/// One ADC stream sample set: a value for each chosen channel (bit n of the mask = channel n).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct AdcSamples {
    values: [Option<AdcValue>; 8],
}

impl AdcSamples {
    /// Samples from `(channel, value)` pairs; a later pair for the same channel wins.
    pub fn new(pairs: impl IntoIterator<Item = (AdcChannel, AdcValue)>) -> Self {
        let mut values = [None; 8];
        for (channel, value) in pairs {
            values[usize::from(channel.0)] = Some(value);
        }
        Self { values }
    }
    /// Bit n set when channel n is present.
    pub fn mask(&self) -> u8 {
        self.values
            .iter()
            .enumerate()
            .filter(|(_, v)| v.is_some())
            .fold(0, |m, (i, _)| m | (1 << i))
    }
    pub fn get(&self, channel: AdcChannel) -> Option<AdcValue> {
        self.values[usize::from(channel.0)]
    }
    /// Present channels in ascending order (the wire order).
    pub fn iter(&self) -> impl Iterator<Item = (AdcChannel, AdcValue)> + '_ {
        self.values
            .iter()
            .enumerate()
            .filter_map(|(i, v)| v.map(|v| (AdcChannel(i as u8), v)))
    }
}

/// Mako's four thrusters, in wire order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Thruster {
    Port = 0,
    Starboard = 1,
    Bow = 2,
    Stern = 3,
}

impl Thruster {
    pub const ALL: [Thruster; 4] = [Self::Port, Self::Starboard, Self::Bow, Self::Stern];
    pub fn from_index(index: u8) -> Result<Self, EncodeError> {
        Self::ALL
            .get(usize::from(index))
            .copied()
            .ok_or(EncodeError::ThrusterOutOfRange { index })
    }
}

/// Thrust direction bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Direction {
    Forward = 0,
    Reverse = 1,
}

/// PWM duty (inverted logic: 0 = full thrust, 255 = off) and direction for one thruster.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ThrusterCommand {
    pub duty: u8,
    pub direction: Direction,
}

impl ThrusterCommand {
    /// All thrusters off: duty 0xFF, forward.
    pub const OFF: Self = Self {
        duty: 0xFF,
        direction: Direction::Forward,
    };
}

/// Compass poll (slave) or continuous (master, about 2.5 Hz pushes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum CompassMode {
    Poll = 0,
    Continuous = 1,
}

/// What the compass reports: a heading word (binary or BCD) or raw X/Y words.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum CompassOutput {
    Binary = 0,
    Bcd = 1,
    Raw = 2,
}

/// Calibration steps: start, take a point (twice, 180 deg apart), finish; clear forgets it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum CalibrationAction {
    Start = 0,
    TakePoint = 1,
    Finish = 2,
    Clear = 3,
}

/// Calibration state machine as reported in CALIBRATION_STATUS.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum CalibrationState {
    /// Not calibrating (using the last finished calibration, or none).
    Idle = 0,
    /// Started; `points` points taken so far (0 or 1).
    Collecting = 1,
    /// Two points taken; FINISH will apply them.
    ReadyToFinish = 2,
}

/// Real time (the bridge advances on its own clock) or lockstep (only TIME_ADVANCE moves it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum TimeMode {
    RealTime = 0,
    Lockstep = 1,
}

/// NAK reason codes (table in `PROTOCOL.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorCode {
    BadCrc,
    UnknownType,
    BadLength,
    BadValue,
    BadState,
    Unsupported,
    VersionMismatch,
    /// A code this version does not know; kept so a newer peer's NAK still decodes.
    Other(u8),
}

impl ErrorCode {
    pub fn to_u8(self) -> u8 {
        match self {
            Self::BadCrc => 0x01,
            Self::UnknownType => 0x02,
            Self::BadLength => 0x03,
            Self::BadValue => 0x04,
            Self::BadState => 0x05,
            Self::Unsupported => 0x06,
            Self::VersionMismatch => 0x07,
            Self::Other(code) => code,
        }
    }
    /// Canonical decoding: known codes never come back as `Other`.
    pub fn from_u8(code: u8) -> Self {
        match code {
            0x01 => Self::BadCrc,
            0x02 => Self::UnknownType,
            0x03 => Self::BadLength,
            0x04 => Self::BadValue,
            0x05 => Self::BadState,
            0x06 => Self::Unsupported,
            0x07 => Self::VersionMismatch,
            other => Self::Other(other),
        }
    }
}

/// Capability bits in HELLO_REPLY.
pub mod capability {
    pub const ADC: u16 = 0x0001;
    pub const ADC_STREAM: u16 = 0x0002;
    pub const COMPASS: u16 = 0x0004;
    pub const COMPASS_RAW: u16 = 0x0008;
    pub const COMPASS_CALIBRATION: u16 = 0x0010;
    pub const THRUSTERS: u16 = 0x0020;
    pub const LOCKSTEP: u16 = 0x0040;
    pub const SONAR_ON_THIS_LINE: u16 = 0x0080;
    /// TIME_STEP: thrusters, advance and the new tick's readings in one round trip.
    pub const TIME_STEP: u16 = 0x0100;
}

/// The most readings one TIME_STEP may ask for.
pub const MAX_READINGS: usize = 16;

/// One reading a TIME_STEP asks for at its new tick, as ADC_READ or COMPASS_READ would make it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reading {
    /// A conversion of this ADC channel (wire code = the channel, `0x00..=0x07`).
    Adc(AdcChannel),
    /// The compass's heading word (wire code `0x21`, the COMPASS_READ type).
    Compass,
}

impl Reading {
    /// The wire code of the compass reading.
    pub const COMPASS_CODE: u8 = 0x21;

    pub fn code(self) -> u8 {
        match self {
            Self::Adc(channel) => channel.get(),
            Self::Compass => Self::COMPASS_CODE,
        }
    }

    /// `None` for a code that names no reading.
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            Self::COMPASS_CODE => Some(Self::Compass),
            c => AdcChannel::new(c).ok().map(Self::Adc),
        }
    }
}

/// The ordered readings of a TIME_STEP (at most [`MAX_READINGS`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Readings {
    items: [Reading; MAX_READINGS],
    len: u8,
}

impl Default for Readings {
    fn default() -> Self {
        Self {
            items: [Reading::Compass; MAX_READINGS],
            len: 0,
        }
    }
}

impl Readings {
    pub fn new(readings: impl IntoIterator<Item = Reading>) -> Result<Self, EncodeError> {
        let mut out = Self::default();
        for (i, r) in readings.into_iter().enumerate() {
            if i >= MAX_READINGS {
                return Err(EncodeError::TooManyReadings { max: MAX_READINGS });
            }
            out.items[i] = r;
            out.len = (i + 1) as u8;
        }
        Ok(out)
    }
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    pub fn as_slice(&self) -> &[Reading] {
        &self.items[..self.len()]
    }
}

/// The values a STEP reply carries, one u16 per reading of its request, in the same order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct StepValues {
    values: [u16; MAX_READINGS],
    len: u8,
}

impl StepValues {
    pub fn new(values: impl IntoIterator<Item = u16>) -> Result<Self, EncodeError> {
        let mut out = Self::default();
        for (i, v) in values.into_iter().enumerate() {
            if i >= MAX_READINGS {
                return Err(EncodeError::TooManyReadings { max: MAX_READINGS });
            }
            out.values[i] = v;
            out.len = (i + 1) as u8;
        }
        Ok(out)
    }
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    pub fn as_slice(&self) -> &[u16] {
        &self.values[..self.len()]
    }
}

/// TIME_STEP flag bits.
pub mod step_flag {
    /// Four thruster commands (8 bytes) follow `ticks`.
    pub const THRUSTERS: u8 = 0x01;
    /// Stop early, at the end of the first tick in which bytes went out on the sonar line.
    pub const STOP_ON_SONAR: u8 = 0x02;
}

/// Link statistics, each a wrapping u32 counted since the bridge started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Counters {
    pub rx_frames: u32,
    pub rx_crc_errors: u32,
    pub rx_framing_errors: u32,
    pub rx_skipped_bytes: u32,
    pub rx_rejected: u32,
    pub tx_frames: u32,
    pub tx_naks: u32,
}

/// Every sensor-link message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Message {
    Hello {
        client_version: u8,
    },
    CountersGet,
    AdcRead {
        channel: AdcChannel,
    },
    /// Stream `channels` (mask, bit n = channel n) every `period_ms`; mask 0 stops the stream.
    AdcStream {
        channels: u8,
        period_ms: u16,
    },
    CompassMode {
        mode: CompassMode,
        output: CompassOutput,
    },
    CompassRead,
    CompassCalibrate {
        action: CalibrationAction,
    },
    CompassReset,
    ThrusterSet {
        thruster: Thruster,
        command: ThrusterCommand,
    },
    /// Port, starboard, bow, stern.
    ThrusterSetAll {
        commands: [ThrusterCommand; 4],
    },
    TimeGet,
    TimeAdvance {
        ticks: u32,
    },
    TimeMode {
        mode: TimeMode,
    },
    /// Lockstep in one round trip: take back the previous step's readings beyond `used`, set
    /// the thrusters (when given), advance `ticks` (at most, with `stop_on_sonar`), then make
    /// `readings` at the new tick (PROTOCOL.md 2.9).
    TimeStep {
        used: u8,
        stop_on_sonar: bool,
        ticks: u32,
        thrusters: Option<[ThrusterCommand; 4]>,
        readings: Readings,
    },
    Ack {
        acked_type: u8,
    },
    HelloReply {
        protocol_version: u8,
        capabilities: u16,
        tick_us: u32,
        max_payload: u8,
    },
    Counters(Counters),
    AdcValue {
        channel: AdcChannel,
        value: AdcValue,
    },
    CompassHeading {
        word: HeadingWord,
    },
    CompassRaw {
        x: i16,
        y: i16,
    },
    CalibrationStatus {
        state: CalibrationState,
        points: u8,
    },
    Time {
        ticks: u32,
        tick_us: u32,
    },
    /// The reply to TIME_STEP: the tick reached, the bytes that went out on the sonar line
    /// during the advance, and one value per reading.
    Step {
        ticks: u32,
        sonar_bytes: u16,
        values: StepValues,
    },
    Nak {
        rejected_type: u8,
        code: ErrorCode,
        detail: u8,
    },
    AdcSamples {
        ticks: u32,
        samples: AdcSamples,
    },
    CompassHeadingPush {
        word: HeadingWord,
    },
    CompassRawPush {
        x: i16,
        y: i16,
    },
}

/// A sensor-link frame: sequence number and message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Frame {
    pub seq: u8,
    pub message: Message,
}

/// Small fixed buffer for building payloads without allocating.
struct Payload {
    bytes: [u8; frame::MAX_PAYLOAD],
    len: usize,
}

impl Payload {
    fn new() -> Self {
        Self {
            bytes: [0; frame::MAX_PAYLOAD],
            len: 0,
        }
    }
    fn u8(&mut self, v: u8) -> &mut Self {
        self.bytes[self.len] = v;
        self.len += 1;
        self
    }
    fn u16(&mut self, v: u16) -> &mut Self {
        self.slice(&v.to_be_bytes())
    }
    fn u32(&mut self, v: u32) -> &mut Self {
        self.slice(&v.to_be_bytes())
    }
    fn slice(&mut self, v: &[u8]) -> &mut Self {
        self.bytes[self.len..self.len + v.len()].copy_from_slice(v);
        self.len += v.len();
        self
    }
    fn as_slice(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

impl Message {
    /// The type byte of this message.
    pub fn msg_type(&self) -> u8 {
        use msg_type as t;
        match self {
            Self::Hello { .. } => t::HELLO,
            Self::CountersGet => t::COUNTERS_GET,
            Self::AdcRead { .. } => t::ADC_READ,
            Self::AdcStream { .. } => t::ADC_STREAM,
            Self::CompassMode { .. } => t::COMPASS_MODE,
            Self::CompassRead => t::COMPASS_READ,
            Self::CompassCalibrate { .. } => t::COMPASS_CALIBRATE,
            Self::CompassReset => t::COMPASS_RESET,
            Self::ThrusterSet { .. } => t::THRUSTER_SET,
            Self::ThrusterSetAll { .. } => t::THRUSTER_SET_ALL,
            Self::TimeGet => t::TIME_GET,
            Self::TimeAdvance { .. } => t::TIME_ADVANCE,
            Self::TimeMode { .. } => t::TIME_MODE,
            Self::TimeStep { .. } => t::TIME_STEP,
            Self::Ack { .. } => t::ACK,
            Self::HelloReply { .. } => t::HELLO_REPLY,
            Self::Counters(_) => t::COUNTERS,
            Self::AdcValue { .. } => t::ADC_VALUE,
            Self::CompassHeading { .. } => t::COMPASS_HEADING,
            Self::CompassRaw { .. } => t::COMPASS_RAW,
            Self::CalibrationStatus { .. } => t::CALIBRATION_STATUS,
            Self::Time { .. } => t::TIME,
            Self::Step { .. } => t::STEP,
            Self::Nak { .. } => t::NAK,
            Self::AdcSamples { .. } => t::ADC_SAMPLES,
            Self::CompassHeadingPush { .. } => t::COMPASS_HEADING_PUSH,
            Self::CompassRawPush { .. } => t::COMPASS_RAW_PUSH,
        }
    }

    fn payload(&self) -> Payload {
        let mut p = Payload::new();
        match *self {
            Self::Hello { client_version } => {
                p.u8(client_version);
            }
            Self::CountersGet | Self::CompassRead | Self::CompassReset | Self::TimeGet => {}
            Self::AdcRead { channel } => {
                p.u8(channel.0);
            }
            Self::AdcStream {
                channels,
                period_ms,
            } => {
                p.u8(channels).u16(period_ms);
            }
            Self::CompassMode { mode, output } => {
                p.u8(mode as u8).u8(output as u8);
            }
            Self::CompassCalibrate { action } => {
                p.u8(action as u8);
            }
            Self::ThrusterSet { thruster, command } => {
                p.u8(thruster as u8)
                    .u8(command.duty)
                    .u8(command.direction as u8);
            }
            Self::ThrusterSetAll { commands } => {
                for c in commands {
                    p.u8(c.duty).u8(c.direction as u8);
                }
            }
            Self::TimeAdvance { ticks } => {
                p.u32(ticks);
            }
            Self::TimeMode { mode } => {
                p.u8(mode as u8);
            }
            Self::TimeStep {
                used,
                stop_on_sonar,
                ticks,
                thrusters,
                readings,
            } => {
                let mut flags = 0;
                if thrusters.is_some() {
                    flags |= step_flag::THRUSTERS;
                }
                if stop_on_sonar {
                    flags |= step_flag::STOP_ON_SONAR;
                }
                p.u8(used).u8(flags).u32(ticks);
                for c in thrusters.iter().flatten() {
                    p.u8(c.duty).u8(c.direction as u8);
                }
                for r in readings.as_slice() {
                    p.u8(r.code());
                }
            }
            Self::Step {
                ticks,
                sonar_bytes,
                values,
            } => {
                p.u32(ticks).u16(sonar_bytes);
                for v in values.as_slice() {
                    p.u16(*v);
                }
            }
            Self::Ack { acked_type } => {
                p.u8(acked_type);
            }
            Self::HelloReply {
                protocol_version,
                capabilities,
                tick_us,
                max_payload,
            } => {
                p.u8(protocol_version)
                    .u16(capabilities)
                    .u32(tick_us)
                    .u8(max_payload);
            }
            Self::Counters(c) => {
                p.u32(c.rx_frames)
                    .u32(c.rx_crc_errors)
                    .u32(c.rx_framing_errors)
                    .u32(c.rx_skipped_bytes)
                    .u32(c.rx_rejected)
                    .u32(c.tx_frames)
                    .u32(c.tx_naks);
            }
            Self::AdcValue { channel, value } => {
                p.u8(channel.0).u16(value.0);
            }
            Self::CompassHeading { word } | Self::CompassHeadingPush { word } => {
                p.u16(word.0);
            }
            Self::CompassRaw { x, y } | Self::CompassRawPush { x, y } => {
                p.slice(&x.to_be_bytes()).slice(&y.to_be_bytes());
            }
            Self::CalibrationStatus { state, points } => {
                p.u8(state as u8).u8(points);
            }
            Self::Time { ticks, tick_us } => {
                p.u32(ticks).u32(tick_us);
            }
            Self::Nak {
                rejected_type,
                code,
                detail,
            } => {
                p.u8(rejected_type).u8(code.to_u8()).u8(detail);
            }
            Self::AdcSamples { ticks, samples } => {
                p.u32(ticks).u8(samples.mask());
                for (_, v) in samples.iter() {
                    p.u16(v.0);
                }
            }
        }
        p
    }
}

impl Frame {
    pub fn new(seq: u8, message: Message) -> Self {
        Self { seq, message }
    }

    /// The NAK the bridge sends for a wire error (PROTOCOL.md section 3), or `None` when the
    /// error gets no answer (garbage, impossible length, truncation, non-frame errors).
    pub fn nak_for(error: &LinkError) -> Option<Self> {
        let (seq, rejected_type, code, detail) = match *error {
            LinkError::Frame(FrameError::ChecksumMismatch { msg_type, seq, .. }) => {
                (seq, msg_type, ErrorCode::BadCrc, 0)
            }
            LinkError::Message(MessageError::UnknownType { msg_type, seq }) => {
                (seq, msg_type, ErrorCode::UnknownType, 0)
            }
            LinkError::Message(MessageError::BadLength {
                msg_type,
                seq,
                expected,
                ..
            }) => (seq, msg_type, ErrorCode::BadLength, expected),
            LinkError::Message(MessageError::BadValue {
                msg_type,
                seq,
                offset,
                ..
            }) => (seq, msg_type, ErrorCode::BadValue, offset),
            _ => return None,
        };
        Some(Self::new(
            seq,
            Message::Nak {
                rejected_type,
                code,
                detail,
            },
        ))
    }

    /// Append the frame (sync, header, payload, CRC) to `dst`. Cannot fail: every message's
    /// payload is at most 38 bytes.
    pub fn encode(&self, dst: &mut BytesMut) {
        let payload = self.message.payload();
        // Every payload built above is at most 38 bytes (a STEP with 16 values), below
        // MAX_PAYLOAD.
        if let Err(e) = frame::encode(self.message.msg_type(), self.seq, payload.as_slice(), dst) {
            unreachable!("message payload exceeds MAX_PAYLOAD: {e}");
        }
    }

    /// Interpret a frame whose CRC checked.
    pub fn decode(raw: RawFrame<'_>) -> Result<Self, MessageError> {
        let message = decode_message(raw)?;
        Ok(Self {
            seq: raw.seq,
            message,
        })
    }
}

/// Payload length for each fixed-size type; `None` for an unknown type.
fn fixed_len(t: u8) -> Option<u8> {
    use msg_type as m;
    Some(match t {
        m::HELLO => 1,
        m::COUNTERS_GET | m::COMPASS_READ | m::COMPASS_RESET | m::TIME_GET => 0,
        m::ADC_READ => 1,
        m::ADC_STREAM => 3,
        m::COMPASS_MODE => 2,
        m::COMPASS_CALIBRATE => 1,
        m::THRUSTER_SET => 3,
        m::THRUSTER_SET_ALL => 8,
        m::TIME_ADVANCE => 4,
        m::TIME_MODE => 1,
        m::ACK => 1,
        m::HELLO_REPLY => 8,
        m::COUNTERS => 28,
        m::ADC_VALUE => 3,
        m::COMPASS_HEADING | m::COMPASS_HEADING_PUSH => 2,
        m::COMPASS_RAW | m::COMPASS_RAW_PUSH => 4,
        m::CALIBRATION_STATUS => 2,
        m::TIME => 8,
        m::NAK => 3,
        // Variable: 5 + 2 * popcount(mask); checked separately.
        m::ADC_SAMPLES => 5,
        // Variable, at least this long; checked separately.
        m::TIME_STEP | m::STEP => 6,
        _ => return None,
    })
}

type Res<'a, O> = IResult<&'a [u8], O>;
type NomErr<'a> = nom::Err<nom::error::Error<&'a [u8]>>;

fn u8s<const N: usize>(input: &[u8]) -> Res<'_, [u8; N]> {
    let mut out = [0u8; N];
    let mut rest = input;
    for slot in &mut out {
        let (r, b) = be_u8(rest)?;
        *slot = b;
        rest = r;
    }
    Ok((rest, out))
}

fn decode_message(raw: RawFrame<'_>) -> Result<Message, MessageError> {
    use msg_type as m;
    let RawFrame {
        msg_type: t,
        seq,
        payload,
    } = raw;
    let Some(expected) = fixed_len(t) else {
        return Err(MessageError::UnknownType { msg_type: t, seq });
    };
    let found = payload.len() as u8;
    let bad_len = |expected: u8| MessageError::BadLength {
        msg_type: t,
        seq,
        expected,
        found,
    };
    let bad = |offset: u8, value: u8| MessageError::BadValue {
        msg_type: t,
        seq,
        offset,
        value,
    };
    if t == m::ADC_SAMPLES {
        let Some(&mask) = payload.get(4) else {
            return Err(bad_len(expected));
        };
        let want = 5 + 2 * mask.count_ones() as u8;
        if found != want {
            return Err(bad_len(want));
        }
        if mask == 0 {
            return Err(bad(4, 0));
        }
    } else if t == m::TIME_STEP {
        let Some(&flags) = payload.get(1) else {
            return Err(bad_len(expected));
        };
        let head = if flags & step_flag::THRUSTERS != 0 {
            14
        } else {
            6
        };
        if found < head {
            return Err(bad_len(head));
        }
        if usize::from(found - head) > MAX_READINGS {
            return Err(bad_len(head + MAX_READINGS as u8));
        }
    } else if t == m::STEP {
        if found < expected || !(found - expected).is_multiple_of(2) {
            return Err(bad_len(expected));
        }
        if usize::from(found - expected) / 2 > MAX_READINGS {
            return Err(bad_len(expected + 2 * MAX_READINGS as u8));
        }
    } else if found != expected {
        return Err(bad_len(expected));
    }
    // The length is right, so the nom parsers below cannot run out of input; a failure would
    // still be reported as a length error rather than a panic.
    let parse = |r: Res<'_, Message>| r.map(|(_, msg)| msg).map_err(|_| bad_len(expected));
    let direction = |offset: u8, v: u8| match v {
        0 => Ok(Direction::Forward),
        1 => Ok(Direction::Reverse),
        _ => Err(bad(offset, v)),
    };
    let adc_value = |offset: u8, v: u16| AdcValue::new(v).map_err(|_| bad(offset, (v >> 8) as u8));
    let message = match t {
        m::HELLO => parse(
            all_consuming(be_u8)
                .map(|v| Message::Hello { client_version: v })
                .parse(payload),
        )?,
        m::COUNTERS_GET => Message::CountersGet,
        m::COMPASS_READ => Message::CompassRead,
        m::COMPASS_RESET => Message::CompassReset,
        m::TIME_GET => Message::TimeGet,
        m::ADC_READ => {
            let [c] = payload_array::<1>(payload).map_err(|_| bad_len(expected))?;
            Message::AdcRead {
                channel: AdcChannel::new(c).map_err(|_| bad(0, c))?,
            }
        }
        m::ADC_STREAM => parse(
            all_consuming((be_u8, be_u16))
                .map(|(channels, period_ms)| Message::AdcStream {
                    channels,
                    period_ms,
                })
                .parse(payload),
        )
        .and_then(|msg| match msg {
            Message::AdcStream {
                channels,
                period_ms: 0,
            } if channels != 0 => Err(bad(1, 0)),
            msg => Ok(msg),
        })?,
        m::COMPASS_MODE => {
            let [mode, output] = payload_array::<2>(payload).map_err(|_| bad_len(expected))?;
            let mode = match mode {
                0 => CompassMode::Poll,
                1 => CompassMode::Continuous,
                v => return Err(bad(0, v)),
            };
            let output = match output {
                0 => CompassOutput::Binary,
                1 => CompassOutput::Bcd,
                2 => CompassOutput::Raw,
                v => return Err(bad(1, v)),
            };
            Message::CompassMode { mode, output }
        }
        m::COMPASS_CALIBRATE => {
            let [a] = payload_array::<1>(payload).map_err(|_| bad_len(expected))?;
            let action = match a {
                0 => CalibrationAction::Start,
                1 => CalibrationAction::TakePoint,
                2 => CalibrationAction::Finish,
                3 => CalibrationAction::Clear,
                v => return Err(bad(0, v)),
            };
            Message::CompassCalibrate { action }
        }
        m::THRUSTER_SET => {
            let [i, duty, dir] = payload_array::<3>(payload).map_err(|_| bad_len(expected))?;
            let thruster = Thruster::from_index(i).map_err(|_| bad(0, i))?;
            Message::ThrusterSet {
                thruster,
                command: ThrusterCommand {
                    duty,
                    direction: direction(2, dir)?,
                },
            }
        }
        m::THRUSTER_SET_ALL => {
            let b = payload_array::<8>(payload).map_err(|_| bad_len(expected))?;
            let mut commands = [ThrusterCommand::OFF; 4];
            for (i, c) in commands.iter_mut().enumerate() {
                let off = 2 * i;
                *c = ThrusterCommand {
                    duty: b[off],
                    direction: direction(off as u8 + 1, b[off + 1])?,
                };
            }
            Message::ThrusterSetAll { commands }
        }
        m::TIME_ADVANCE => parse(
            all_consuming(be_u32)
                .map(|ticks| Message::TimeAdvance { ticks })
                .parse(payload),
        )?,
        m::TIME_MODE => {
            let [v] = payload_array::<1>(payload).map_err(|_| bad_len(expected))?;
            let mode = match v {
                0 => TimeMode::RealTime,
                1 => TimeMode::Lockstep,
                v => return Err(bad(0, v)),
            };
            Message::TimeMode { mode }
        }
        m::TIME_STEP => {
            let (rest, (used, flags, ticks)) = (be_u8, be_u8, be_u32)
                .parse(payload)
                .map_err(|_: NomErr<'_>| bad_len(expected))?;
            if flags & !(step_flag::THRUSTERS | step_flag::STOP_ON_SONAR) != 0 {
                return Err(bad(1, flags));
            }
            let (rest, thrusters) = if flags & step_flag::THRUSTERS != 0 {
                let Some((b, rest)) = rest.split_first_chunk::<8>() else {
                    return Err(bad_len(14));
                };
                let mut commands = [ThrusterCommand::OFF; 4];
                for (i, c) in commands.iter_mut().enumerate() {
                    let off = 2 * i;
                    *c = ThrusterCommand {
                        duty: b[off],
                        direction: direction(6 + off as u8 + 1, b[off + 1])?,
                    };
                }
                (rest, Some(commands))
            } else {
                (rest, None)
            };
            let first = (payload.len() - rest.len()) as u8;
            let mut items = Vec::with_capacity(rest.len());
            for (i, &code) in rest.iter().enumerate() {
                items.push(Reading::from_code(code).ok_or_else(|| bad(first + i as u8, code))?);
            }
            Message::TimeStep {
                used,
                stop_on_sonar: flags & step_flag::STOP_ON_SONAR != 0,
                ticks,
                thrusters,
                readings: Readings::new(items).map_err(|_| bad_len(first))?,
            }
        }
        m::STEP => {
            let (mut rest, (ticks, sonar_bytes)) = (be_u32, be_u16)
                .parse(payload)
                .map_err(|_: NomErr<'_>| bad_len(expected))?;
            let mut values = Vec::with_capacity(rest.len() / 2);
            while !rest.is_empty() {
                let (r, v) = be_u16(rest).map_err(|_: NomErr<'_>| bad_len(expected))?;
                values.push(v);
                rest = r;
            }
            Message::Step {
                ticks,
                sonar_bytes,
                values: StepValues::new(values).map_err(|_| bad_len(expected))?,
            }
        }
        m::ACK => parse(
            all_consuming(be_u8)
                .map(|acked_type| Message::Ack { acked_type })
                .parse(payload),
        )?,
        m::HELLO_REPLY => parse(
            all_consuming((be_u8, be_u16, be_u32, be_u8))
                .map(
                    |(protocol_version, capabilities, tick_us, max_payload)| Message::HelloReply {
                        protocol_version,
                        capabilities,
                        tick_us,
                        max_payload,
                    },
                )
                .parse(payload),
        )?,
        m::COUNTERS => parse(
            all_consuming((be_u32, be_u32, be_u32, be_u32, be_u32, be_u32, be_u32))
                .map(|(a, b, c, d, e, f, g)| {
                    Message::Counters(Counters {
                        rx_frames: a,
                        rx_crc_errors: b,
                        rx_framing_errors: c,
                        rx_skipped_bytes: d,
                        rx_rejected: e,
                        tx_frames: f,
                        tx_naks: g,
                    })
                })
                .parse(payload),
        )?,
        m::ADC_VALUE => {
            let (_, (c, v)) = all_consuming((be_u8, be_u16))
                .parse(payload)
                .map_err(|_: NomErr<'_>| bad_len(expected))?;
            let channel = AdcChannel::new(c).map_err(|_| bad(0, c))?;
            Message::AdcValue {
                channel,
                value: adc_value(1, v)?,
            }
        }
        m::COMPASS_HEADING | m::COMPASS_HEADING_PUSH => {
            let (_, w) = all_consuming(be_u16)
                .parse(payload)
                .map_err(|_: NomErr<'_>| bad_len(expected))?;
            if w & 0xFC00 != 0 {
                return Err(bad(0, (w >> 8) as u8));
            }
            let word = HeadingWord(w);
            if t == m::COMPASS_HEADING {
                Message::CompassHeading { word }
            } else {
                Message::CompassHeadingPush { word }
            }
        }
        m::COMPASS_RAW | m::COMPASS_RAW_PUSH => {
            let (_, (x, y)) = all_consuming((be_i16, be_i16))
                .parse(payload)
                .map_err(|_: NomErr<'_>| bad_len(expected))?;
            if t == m::COMPASS_RAW {
                Message::CompassRaw { x, y }
            } else {
                Message::CompassRawPush { x, y }
            }
        }
        m::CALIBRATION_STATUS => {
            let [s, points] = payload_array::<2>(payload).map_err(|_| bad_len(expected))?;
            let state = match s {
                0 => CalibrationState::Idle,
                1 => CalibrationState::Collecting,
                2 => CalibrationState::ReadyToFinish,
                v => return Err(bad(0, v)),
            };
            if points > 2 {
                return Err(bad(1, points));
            }
            Message::CalibrationStatus { state, points }
        }
        m::TIME => parse(
            all_consuming((be_u32, be_u32))
                .map(|(ticks, tick_us)| Message::Time { ticks, tick_us })
                .parse(payload),
        )?,
        m::NAK => {
            let [rejected_type, code, detail] =
                payload_array::<3>(payload).map_err(|_| bad_len(expected))?;
            Message::Nak {
                rejected_type,
                code: ErrorCode::from_u8(code),
                detail,
            }
        }
        m::ADC_SAMPLES => {
            let (mut rest, (ticks, mask)) = (be_u32, be_u8)
                .parse(payload)
                .map_err(|_: NomErr<'_>| bad_len(expected))?;
            let mut values = [None; 8];
            for (ch, slot) in values.iter_mut().enumerate() {
                if mask & (1 << ch) != 0 {
                    let offset = (payload.len() - rest.len()) as u8;
                    let (r, v) = be_u16(rest).map_err(|_: NomErr<'_>| bad_len(expected))?;
                    rest = r;
                    *slot = Some(adc_value(offset, v)?);
                }
            }
            Message::AdcSamples {
                ticks,
                samples: AdcSamples { values },
            }
        }
        _ => return Err(MessageError::UnknownType { msg_type: t, seq }),
    };
    Ok(message)
}

fn payload_array<const N: usize>(payload: &[u8]) -> Result<[u8; N], ()> {
    all_consuming(u8s::<N>)
        .parse(payload)
        .map(|(_, a)| a)
        .map_err(|_: NomErr<'_>| ())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip(message: Message) -> Frame {
        let mut buf = BytesMut::new();
        Frame::new(0x42, message).encode(&mut buf);
        let raw = frame::parse(&buf).unwrap();
        Frame::decode(raw).unwrap()
    }

    #[test]
    fn adc_value_is_big_endian_with_top_bits_zero() {
        let msg = Message::AdcValue {
            channel: AdcChannel::new(3).unwrap(),
            value: AdcValue::new(0x03FF).unwrap(),
        };
        let mut buf = BytesMut::new();
        Frame::new(1, msg).encode(&mut buf);
        assert_eq!(&buf[5..8], &[0x03, 0x03, 0xFF]);
        assert_eq!(roundtrip(msg).message, msg);
    }

    #[test]
    fn channel_nine_is_api_misuse() {
        assert_eq!(
            AdcChannel::new(9),
            Err(EncodeError::AdcChannelOutOfRange { channel: 9 })
        );
        assert_eq!(
            AdcValue::new(1024),
            Err(EncodeError::AdcValueOutOfRange { value: 1024 })
        );
    }

    #[test]
    fn wire_channel_nine_is_bad_value_item() {
        let mut buf = BytesMut::new();
        frame::encode(msg_type::ADC_READ, 5, &[9], &mut buf).unwrap();
        let raw = frame::parse(&buf).unwrap();
        assert_eq!(
            Frame::decode(raw),
            Err(MessageError::BadValue {
                msg_type: msg_type::ADC_READ,
                seq: 5,
                offset: 0,
                value: 9
            })
        );
    }

    /// NAK mapping of PROTOCOL.md section 3: channel 9 gives BAD_VALUE at offset 0 with the
    /// request's seq (the `nak` example), garbage gives no answer.
    #[test]
    fn nak_for_wire_errors_follows_the_table() {
        let e = LinkError::Message(MessageError::BadValue {
            msg_type: 0x10,
            seq: 0x11,
            offset: 0,
            value: 9,
        });
        assert_eq!(
            Frame::nak_for(&e),
            Some(Frame::new(
                0x11,
                Message::Nak {
                    rejected_type: 0x10,
                    code: ErrorCode::BadValue,
                    detail: 0
                }
            ))
        );
        let e = LinkError::Message(MessageError::BadLength {
            msg_type: 0x10,
            seq: 1,
            expected: 1,
            found: 2,
        });
        assert!(matches!(
            Frame::nak_for(&e),
            Some(Frame {
                message: Message::Nak {
                    code: ErrorCode::BadLength,
                    detail: 1,
                    ..
                },
                ..
            })
        ));
        let e = LinkError::Frame(FrameError::ChecksumMismatch {
            calculated: 1,
            found: 2,
            msg_type: 0x41,
            seq: 3,
        });
        assert!(matches!(
            Frame::nak_for(&e),
            Some(Frame {
                seq: 3,
                message: Message::Nak {
                    code: ErrorCode::BadCrc,
                    ..
                }
            })
        ));
        assert_eq!(Frame::nak_for(&LinkError::Skipped { count: 3 }), None);
        assert_eq!(
            Frame::nak_for(&LinkError::Frame(FrameError::LengthTooLong {
                len: 99,
                max: 64
            })),
            None
        );
    }

    #[test]
    fn adc_samples_length_follows_mask() {
        let mut buf = BytesMut::new();
        // mask 0b101 needs 2 values (4 bytes) but only one is present.
        frame::encode(
            msg_type::ADC_SAMPLES,
            0,
            &[0, 0, 0, 1, 0b101, 0x01, 0x00],
            &mut buf,
        )
        .unwrap();
        let raw = frame::parse(&buf).unwrap();
        assert!(matches!(
            Frame::decode(raw),
            Err(MessageError::BadLength {
                expected: 9,
                found: 7,
                ..
            })
        ));
    }

    fn decode_raw(t: u8, payload: &[u8]) -> Result<Frame, MessageError> {
        let mut buf = BytesMut::new();
        frame::encode(t, 7, payload, &mut buf).unwrap();
        Frame::decode(frame::parse(&buf).unwrap())
    }

    /// TIME_STEP's length depends on its flags and its readings (PROTOCOL.md 2.9); bad flag
    /// bits, directions and reading codes are BAD_VALUE at their offsets.
    #[test]
    fn time_step_lengths_and_values_are_checked() {
        let bad_len = |expected| move |r: Result<Frame, MessageError>| matches!(r, Err(MessageError::BadLength { expected: e, .. }) if e == expected);
        let bad_value = |offset| move |r: Result<Frame, MessageError>| matches!(r, Err(MessageError::BadValue { offset: o, .. }) if o == offset);
        let t = msg_type::TIME_STEP;
        assert!(bad_len(6)(decode_raw(t, &[0])));
        assert!(bad_len(6)(decode_raw(t, &[0, 0, 0, 0, 1])));
        // thrusters announced but missing
        assert!(bad_len(14)(decode_raw(t, &[0, 1, 0, 0, 0, 1, 0xFF, 0])));
        // 17 readings
        let mut long = vec![0, 0, 0, 0, 0, 1];
        long.extend([0u8; 17]);
        assert!(bad_len(22)(decode_raw(t, &long)));
        assert!(bad_value(1)(decode_raw(t, &[0, 0x04, 0, 0, 0, 1])));
        assert!(bad_value(6)(decode_raw(t, &[0, 0, 0, 0, 0, 1, 0x08])));
        // starboard's direction byte (payload offset 9) is 2
        assert!(bad_value(9)(decode_raw(
            t,
            &[0, 1, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 0]
        )));
        let ok = decode_raw(t, &[2, 0, 0, 0, 0, 1, 0x21, 0x07]).unwrap();
        assert_eq!(
            ok.message,
            Message::TimeStep {
                used: 2,
                stop_on_sonar: false,
                ticks: 1,
                thrusters: None,
                readings: Readings::new([
                    Reading::Compass,
                    Reading::Adc(AdcChannel::new(7).unwrap())
                ])
                .unwrap(),
            }
        );
        // STEP: 6 bytes, then whole u16 values
        assert!(bad_len(6)(decode_raw(
            msg_type::STEP,
            &[0, 0, 0, 1, 0, 0, 1]
        )));
        assert!(Readings::new([Reading::Compass; 17]).is_err());
    }
}
