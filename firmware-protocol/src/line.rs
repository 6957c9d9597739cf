//! One decoder for a line that may carry NMEA sentences, sonar commands and binary frames.
//!
//! The first byte decides: `$` starts an NMEA sentence, `@` a sonar command, `0xEB` a binary
//! frame. Anything else is garbage, skipped and reported once per run as
//! [`LinkError::Skipped`] (bare CR and LF between messages are dropped silently). A candidate
//! that turns out bad is reported as an error item; when its extent cannot be trusted (bad
//! CRC, impossible length, control byte in a sentence) only its first byte is dropped and the
//! scan restarts at the next byte, so a real message hidden in the junk is still found.
//!
//! The decoder is sans-IO: hand it the bytes received so far; it says how many it used.
//! Decisions depend only on the bytes, never on how they were chunked.

use bytes::{Buf, BytesMut};

use crate::error::{FrameError, LinkError, NmeaError, SonarCommandError};
use crate::frame::{self, Candidate};
use crate::nmea::{self, LineScan, Sentence};
use crate::sensor_link::Frame;
use crate::sonar_link::{self, CommandScan, SonarCommand};

/// One thing found on the line.
#[derive(Debug, Clone, PartialEq)]
pub enum LineItem {
    Nmea(Sentence),
    Sonar(SonarCommand),
    Frame(Frame),
    /// Bad bytes, reported; decoding continues after them.
    Error(LinkError),
}

/// Result of one [`LineDecoder::decode_slice`] call.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    /// Bytes at the front of the buffer that are used up; drop them before the next call.
    pub consumed: usize,
    /// The next item, or `None` when more bytes are needed.
    pub item: Option<LineItem>,
}

/// Stream decoder for a shared line. Keeps the garbage count and, for an unfinished NMEA
/// line, the offset where its scan stopped (like tokio-util's `LinesCodec::next_index`).
#[derive(Debug, Clone, Default)]
pub struct LineDecoder {
    skipped: usize,
    nmea_scanned: usize,
}

fn is_start(b: u8) -> bool {
    b == b'$' || b == sonar_link::START || b == frame::SYNC[0]
}

impl LineDecoder {
    pub fn new() -> Self {
        Self::default()
    }

    /// Decode from `buf`, the bytes received and not yet consumed (the unconsumed tail of the
    /// previous call's buffer plus new bytes).
    pub fn decode_slice(&mut self, buf: &[u8]) -> Decoded {
        let mut pos = 0;
        loop {
            while let Some(&b) = buf.get(pos) {
                if is_start(b) {
                    break;
                }
                if b != b'\r' && b != b'\n' {
                    self.skipped += 1;
                }
                pos += 1;
            }
            let rest = &buf[pos..];
            let Some(&first) = rest.first() else {
                return Decoded {
                    consumed: pos,
                    item: None,
                };
            };
            // (bytes to consume from `rest`, item), or None to wait for more.
            let outcome: Option<(usize, LineItem)> = match first {
                b'$' => match nmea::scan_line(rest, self.nmea_scanned) {
                    LineScan::NeedMore { scanned } => {
                        self.nmea_scanned = scanned;
                        None
                    }
                    LineScan::Complete { len } => Some((
                        len,
                        match nmea::parse_line(&rest[..len]) {
                            Ok(s) => LineItem::Nmea(s),
                            Err(e) => LineItem::Error(e),
                        },
                    )),
                    LineScan::Reject { error, consume } => {
                        Some((consume, LineItem::Error(error.into())))
                    }
                },
                sonar_link::START => match sonar_link::scan_command(rest) {
                    CommandScan::NeedMore => None,
                    CommandScan::Complete { len } => Some((
                        len,
                        match sonar_link::parse_command(&rest[..len]) {
                            Ok(c) => LineItem::Sonar(c),
                            Err(e) => LineItem::Error(e.into()),
                        },
                    )),
                    CommandScan::Reject { error, consume } => {
                        Some((consume, LineItem::Error(error.into())))
                    }
                },
                _ => match frame::candidate(rest) {
                    Candidate::NeedMore => None,
                    Candidate::NotAFrame => {
                        self.skipped += 1;
                        pos += 1;
                        continue;
                    }
                    Candidate::Reject(e) => Some((1, LineItem::Error(e.into()))),
                    Candidate::Complete { len } => match frame::parse(&rest[..len]) {
                        Ok(raw) => Some((
                            len,
                            match Frame::decode(raw) {
                                Ok(f) => LineItem::Frame(f),
                                Err(e) => LineItem::Error(e.into()),
                            },
                        )),
                        Err(e) => Some((1, LineItem::Error(e.into()))),
                    },
                },
            };
            return match outcome {
                None => Decoded {
                    consumed: pos,
                    item: None,
                },
                // Garbage before this item is reported first; the item is found again next call.
                Some(_) if self.skipped > 0 => self.take_skipped(pos),
                Some((used, item)) => {
                    self.nmea_scanned = 0;
                    Decoded {
                        consumed: pos + used,
                        item: Some(item),
                    }
                }
            };
        }
    }

    fn take_skipped(&mut self, consumed: usize) -> Decoded {
        let count = std::mem::take(&mut self.skipped);
        Decoded {
            consumed,
            item: Some(LineItem::Error(LinkError::Skipped { count })),
        }
    }

    /// Like [`decode_slice`](Self::decode_slice) at the end of the stream (or when the caller
    /// gives up on a partial message after an idle gap): pending garbage and an unfinished
    /// message become error items, and everything is consumed once this returns `None`.
    pub fn decode_eof_slice(&mut self, buf: &[u8]) -> Decoded {
        let d = self.decode_slice(buf);
        if d.item.is_some() {
            return d;
        }
        if self.skipped > 0 {
            return self.take_skipped(d.consumed);
        }
        let rest = &buf[d.consumed..];
        let Some(&first) = rest.first() else {
            return d;
        };
        self.nmea_scanned = 0;
        let have = rest.len();
        let error: LinkError = match first {
            b'$' => NmeaError::Truncated { have }.into(),
            sonar_link::START => SonarCommandError::Truncated { have }.into(),
            _ => FrameError::Truncated {
                have,
                need: rest
                    .get(4)
                    .map_or(frame::HEADER_LEN + frame::CRC_LEN, |&l| {
                        frame::HEADER_LEN + usize::from(l) + frame::CRC_LEN
                    }),
            }
            .into(),
        };
        Decoded {
            consumed: buf.len(),
            item: Some(LineItem::Error(error)),
        }
    }

    /// Decode from a `BytesMut`, advancing it past what was used.
    pub fn decode(&mut self, buf: &mut BytesMut) -> Option<LineItem> {
        let d = self.decode_slice(buf);
        buf.advance(d.consumed);
        d.item
    }

    /// End-of-stream form of [`decode`](Self::decode).
    pub fn decode_eof(&mut self, buf: &mut BytesMut) -> Option<LineItem> {
        let d = self.decode_eof_slice(buf);
        buf.advance(d.consumed);
        d.item
    }

    /// Decode every item in a complete byte string (logs, tests); ends with EOF handling.
    pub fn decode_all(bytes: &[u8]) -> Vec<LineItem> {
        let mut decoder = Self::new();
        let mut buf = BytesMut::from(bytes);
        let mut out = Vec::new();
        while let Some(item) = decoder.decode(&mut buf) {
            out.push(item);
        }
        while let Some(item) = decoder.decode_eof(&mut buf) {
            out.push(item);
        }
        out
    }
}

impl LineItem {
    /// Re-encode a decoded message. Error items have no bytes; they return `false`.
    pub fn encode(&self, dst: &mut BytesMut) -> Result<bool, crate::error::EncodeError> {
        match self {
            LineItem::Nmea(s) => s.encode(dst)?,
            LineItem::Sonar(c) => c.encode(dst),
            LineItem::Frame(f) => f.encode(dst),
            LineItem::Error(_) => return Ok(false),
        }
        Ok(true)
    }
}
