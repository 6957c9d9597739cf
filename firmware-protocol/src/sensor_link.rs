//! Sensor-link messages (EyeBot <-> bridge): ADC, compass, thrusters, time, service frames.
//!
//! A [`Frame`] is a sequence number plus a typed [`Message`]. Values are validated when they
//! are built ([`AdcChannel::new`], [`AdcValue::new`], ...), so a `Message` always encodes; a
//! payload from the wire that breaks a rule becomes a [`MessageError`] item instead.
//! `PROTOCOL.md` gives the byte layout of each message; the type numbers are in [`msg_type`].

use crate::compass_word::HeadingWord;
use crate::error::{EncodeError, FrameError, LinkError, MessageError};
use crate::frame::{self, RawFrame};
use bytes::BytesMut;

mod decode;

use self::decode::decode_message;

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

#[cfg(test)]
mod tests;
