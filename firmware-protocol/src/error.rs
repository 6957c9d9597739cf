//! Error types, one per layer.
//!
//! Errors about bytes that came from a wire are *stream items* ([`LinkError`] inside
//! [`crate::LineItem::Error`]): the decoder reports them and keeps going. Misuse of this
//! crate's own API (asking to encode ADC channel 9, a 90-character sentence) is an
//! [`EncodeError`], a different type, so the two can never be confused.

use thiserror::Error;

/// Binary sensor-link framing errors (sync, length, CRC).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum FrameError {
    /// The CRC over type, seq, len and payload did not match the two CRC bytes.
    #[error(
        "frame CRC mismatch: calculated {calculated:#06x}, found {found:#06x} (type {msg_type:#04x}, seq {seq})"
    )]
    ChecksumMismatch {
        calculated: u16,
        found: u16,
        msg_type: u8,
        seq: u8,
    },
    /// The length byte exceeds the protocol maximum; the header is garbage.
    #[error("frame length {len} exceeds the maximum payload of {max} bytes")]
    LengthTooLong { len: u8, max: u8 },
    /// The stream ended (or the caller flushed it) inside a frame.
    #[error("truncated frame: have {have} of {need} bytes")]
    Truncated { have: usize, need: usize },
}

/// NMEA 0183 line framing and checksum errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum NmeaError {
    /// XOR checksum of the bytes between `$` and `*` differs from the two hex digits.
    #[error("NMEA checksum mismatch: calculated {calculated:#04x}, found {found:#04x}")]
    ChecksumMismatch { calculated: u8, found: u8 },
    /// The line has no `*hh` checksum (two hex digits) right before CR LF.
    #[error("NMEA sentence has no valid '*hh' checksum before CR LF")]
    MissingChecksum,
    /// The line exceeds 82 characters including `$` and CR LF.
    #[error("NMEA line longer than {max} characters without CR LF")]
    TooLong { max: usize },
    /// A byte that may not appear in a sentence (control byte, non-ASCII).
    #[error("byte {byte:#04x} at offset {offset} is not allowed in an NMEA sentence")]
    InvalidByte { byte: u8, offset: usize },
    /// CR not followed by LF.
    #[error("CR at offset {offset} not followed by LF")]
    BadTerminator { offset: usize },
    /// A new `$` arrived before the current line ended; the partial line is dropped.
    #[error("NMEA line of {len} bytes interrupted by a new '$'")]
    Interrupted { len: usize },
    /// The stream ended (or the caller flushed it) inside a sentence.
    #[error("truncated NMEA line: {have} bytes without CR LF")]
    Truncated { have: usize },
}

/// Errors in the fields of a sentence whose framing and checksum were fine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum SentenceError {
    /// Sentence address (e.g. `GPGGA`) this crate does not decode. `len` bytes are valid.
    #[error("unsupported NMEA sentence {:?}", String::from_utf8_lossy(&address[..usize::from(*len)]))]
    Unsupported { address: [u8; 8], len: u8 },
    /// The address is not `$` + two upper-case letters + three upper-case letters.
    #[error("malformed NMEA address field")]
    BadAddress,
    /// Wrong number of comma-separated data fields.
    #[error("expected {expected} data fields, found {found}")]
    FieldCount { expected: u8, found: u8 },
    /// Field `index` (0 = first data field) is malformed.
    #[error("data field {index} is malformed: expected {expected}")]
    BadField { index: u8, expected: &'static str },
}

/// Errors in the payload of a sensor-link frame whose CRC was fine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum MessageError {
    /// The type byte names no message.
    #[error("unknown message type {msg_type:#04x} (seq {seq})")]
    UnknownType { msg_type: u8, seq: u8 },
    /// The payload length does not fit the type.
    #[error(
        "message type {msg_type:#04x} (seq {seq}): payload of {found} bytes, expected {expected}"
    )]
    BadLength {
        msg_type: u8,
        seq: u8,
        expected: u8,
        found: u8,
    },
    /// Payload byte `offset` holds a value outside the allowed range.
    #[error(
        "message type {msg_type:#04x} (seq {seq}): payload byte {offset} has invalid value {value:#04x}"
    )]
    BadValue {
        msg_type: u8,
        seq: u8,
        offset: u8,
        value: u8,
    },
}

impl MessageError {
    /// Type byte of the offending frame (for the NAK).
    pub fn msg_type(&self) -> u8 {
        match *self {
            Self::UnknownType { msg_type, .. }
            | Self::BadLength { msg_type, .. }
            | Self::BadValue { msg_type, .. } => msg_type,
        }
    }
    /// Sequence number of the offending frame (for the NAK).
    pub fn seq(&self) -> u8 {
        match *self {
            Self::UnknownType { seq, .. }
            | Self::BadLength { seq, .. }
            | Self::BadValue { seq, .. } => seq,
        }
    }
}

/// Errors in the ASCII sonar select / acknowledge messages (`@S1\r`, `@A1\r\n`, `@N\r\n`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum SonarCommandError {
    /// `@` followed by a letter that names no command.
    #[error("unknown sonar command letter {byte:#04x} after '@'")]
    UnknownCommand { byte: u8 },
    /// Well-formed select or acknowledge with a transducer digit outside '1'..='4'.
    #[error("transducer {byte:#04x} is not '1'..='4'")]
    BadTransducer { byte: u8 },
    /// The terminator was not where the command's fixed length puts it.
    #[error("sonar command terminator expected at offset {offset}, found {byte:#04x}")]
    BadTerminator { offset: usize, byte: u8 },
    /// The stream ended (or the caller flushed it) inside a command.
    #[error("truncated sonar command: {have} bytes")]
    Truncated { have: usize },
}

/// Errors decoding a Vector 2X heading word.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum CompassWordError {
    /// Bits outside the format's field are set.
    #[error("heading word {word:#06x} has bits set outside {mask:#06x}")]
    StrayBits { word: u16, mask: u16 },
    /// A BCD digit above 9.
    #[error("heading word {word:#06x} has a BCD digit above 9")]
    BadBcdDigit { word: u16 },
    /// A heading of 360 or more.
    #[error("heading word {word:#06x} is 360 degrees or more")]
    OutOfRange { word: u16 },
}

/// Any wire error on a (possibly shared) line, yielded as a stream item.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum LinkError {
    /// Bytes that started no message were discarded (reported once per run of garbage).
    #[error("skipped {count} bytes that start no message")]
    Skipped { count: usize },
    #[error(transparent)]
    Frame(#[from] FrameError),
    #[error(transparent)]
    Nmea(#[from] NmeaError),
    #[error(transparent)]
    Sentence(#[from] SentenceError),
    #[error(transparent)]
    Message(#[from] MessageError),
    #[error(transparent)]
    SonarCommand(#[from] SonarCommandError),
}

/// Misuse of this crate's API: a value the protocol cannot carry.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EncodeError {
    #[error("ADC channel {channel} is not 0..=7")]
    AdcChannelOutOfRange { channel: u8 },
    #[error("ADC value {value} does not fit 10 bits (0..=1023)")]
    AdcValueOutOfRange { value: u16 },
    #[error("heading {heading_deg} deg is not 0..=359")]
    HeadingOutOfRange { heading_deg: u16 },
    #[error("transducer {transducer} is not 1..=4")]
    TransducerOutOfRange { transducer: u8 },
    #[error("thruster index {index} is not 0..=3")]
    ThrusterOutOfRange { index: u8 },
    #[error("echo quality {quality} is not 0..=100")]
    QualityOutOfRange { quality: u8 },
    #[error("talker {talker:?} is not two upper-case ASCII letters")]
    BadTalker { talker: String },
    #[error("{field} = {value} cannot be written as x.x (|value| must be below 100000)")]
    NumberOutOfRange { field: &'static str, value: f64 },
    #[error("{field} must not be negative, got {value}")]
    Negative { field: &'static str, value: f64 },
    #[error("payload of {len} bytes exceeds the maximum of {max}")]
    PayloadTooLong { len: usize, max: usize },
    #[error("sentence of {len} characters exceeds the NMEA limit of {max}")]
    SentenceTooLong { len: usize, max: usize },
    #[error("ADC stream period must be at least 1 ms")]
    ZeroPeriod,
    #[error("a TIME_STEP asks for at most {max} readings")]
    TooManyReadings { max: usize },
}
