//! Sans-IO codecs for the wire protocols between an EyeBot MK4 and the Mako bridge.
//!
//! `PROTOCOL.md` in this crate is the specification; this crate implements it. Bytes flow:
//!
//! ```text
//! bytes from a port ──► LineDecoder ──► LineItem::{Nmea, Sonar, Frame, Error}
//!                        │ first byte:  '$' nmea::scan_line  → nmea::parse_line
//!                        │              '@' sonar_link::scan_command → parse_command
//!                        │             0xEB frame::candidate → frame::parse → sensor_link::Frame::decode
//!                        └ anything else: skipped, reported as LinkError::Skipped
//! typed message ──► Sentence::encode / SonarCommand::encode / Frame::encode ──► BytesMut
//! ```
//!
//! The EyeBot side is [`client::EyeBotClient`]: the sensor link's sequence counter and
//! request encoding, the decoder over what comes back, each item classified as a reply
//! (type below `0xC0`, matched to its request by seq), a push, NMEA, a sonar command or an
//! error (counted). A client that moves the bytes (an async port, a blocking file) is a thin
//! I/O shell over it that adds its timeouts and retries.
//!
//! The crate opens no port, reads no clock and uses no `std::io`; the daemon moves the bytes.
//! Wire errors come back as [`LineItem::Error`] items and decoding continues; misuse of the
//! API (a value the protocol cannot carry) is an [`EncodeError`]. With the `tokio-codec`
//! feature, [`codec::LineCodec`] adapts the decoder to tokio-util.

pub mod client;
#[cfg(feature = "tokio-codec")]
pub mod codec;
pub mod compass_word;
pub mod crc;
pub mod error;
pub mod frame;
pub mod line;
pub mod nmea;
pub mod sensor_link;
pub mod sonar_link;

pub use client::{EyeBotClient, Incoming};
pub use compass_word::{HeadingFormat, HeadingWord};
pub use error::{
    CompassWordError, EncodeError, FrameError, LinkError, MessageError, NmeaError, SentenceError,
    SonarCommandError,
};
pub use line::{Decoded, LineDecoder, LineItem};
pub use nmea::{Dbt, Dpt, EchoReport, Sentence, Talker, Tenths, Transducer};
pub use sensor_link::{Frame, Message};
pub use sonar_link::SonarCommand;
