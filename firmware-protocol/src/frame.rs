//! Binary sensor-link framing: find a candidate frame, then parse it whole.
//!
//! ```text
//! +------+------+------+-----+-----+-------------+--------+--------+
//! | 0xEB | 0x90 | type | seq | len | payload     | crc_hi | crc_lo |
//! +------+------+------+-----+-----+-------------+--------+--------+
//!                 \___________ CRC-16/IBM-3740 ___________/
//! ```
//! `len` is the payload length, 0..=[`MAX_PAYLOAD`]. The CRC covers type, seq, len and payload
//! (not the sync bytes) and is sent big-endian.

use bytes::{BufMut, BytesMut};
use nom::{
    IResult, Parser,
    bytes::complete::{tag, take},
    combinator::all_consuming,
    number::complete::{be_u8, be_u16},
};

use crate::crc::crc16_parts;
use crate::error::{EncodeError, FrameError};

/// The two sync bytes. Both are above 0x7F, so neither can occur in an NMEA sentence or an
/// ASCII sonar command.
pub const SYNC: [u8; 2] = [0xEB, 0x90];
/// Sync (2) + type + seq + len.
pub const HEADER_LEN: usize = 5;
/// Two CRC bytes.
pub const CRC_LEN: usize = 2;
/// Largest payload a receiver accepts; a larger `len` byte means the header is garbage.
pub const MAX_PAYLOAD: usize = 64;
/// Longest frame on the wire.
pub const MAX_FRAME: usize = HEADER_LEN + MAX_PAYLOAD + CRC_LEN;

/// A frame whose CRC checked, payload not yet interpreted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawFrame<'a> {
    pub msg_type: u8,
    pub seq: u8,
    pub payload: &'a [u8],
}

/// Result of looking at bytes that start with the first sync byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Candidate {
    /// More bytes are needed before anything can be decided.
    NeedMore,
    /// The first byte is not the start of a frame (second sync byte wrong): garbage.
    NotAFrame,
    /// The header is impossible; reject one byte and rescan.
    Reject(FrameError),
    /// `buf[..len]` is a complete candidate frame (CRC not yet checked).
    Complete { len: usize },
}

/// Split off a candidate frame. `buf[0]` must be `SYNC[0]`.
pub fn candidate(buf: &[u8]) -> Candidate {
    debug_assert_eq!(buf.first(), Some(&SYNC[0]));
    match buf.get(1) {
        None => return Candidate::NeedMore,
        Some(&b) if b != SYNC[1] => return Candidate::NotAFrame,
        Some(_) => {}
    }
    let Some(&len) = buf.get(4) else {
        return Candidate::NeedMore;
    };
    if usize::from(len) > MAX_PAYLOAD {
        return Candidate::Reject(FrameError::LengthTooLong {
            len,
            max: MAX_PAYLOAD as u8,
        });
    }
    let total = HEADER_LEN + usize::from(len) + CRC_LEN;
    if buf.len() < total {
        Candidate::NeedMore
    } else {
        Candidate::Complete { len: total }
    }
}

fn frame_parts(input: &[u8]) -> IResult<&[u8], (u8, u8, &[u8], u16)> {
    let (input, _) = tag(&SYNC[..]).parse(input)?;
    let (input, (msg_type, seq, len)) = (be_u8, be_u8, be_u8).parse(input)?;
    let (input, payload) = take(len).parse(input)?;
    let (input, crc) = be_u16.parse(input)?;
    Ok((input, (msg_type, seq, payload, crc)))
}

/// Parse one whole candidate frame (as returned by [`candidate`]) and check its CRC.
pub fn parse(frame: &[u8]) -> Result<RawFrame<'_>, FrameError> {
    let Ok((_, (msg_type, seq, payload, found))) = all_consuming(frame_parts).parse(frame) else {
        return Err(FrameError::Truncated {
            have: frame.len(),
            need: frame.get(4).map_or(HEADER_LEN + CRC_LEN, |&l| {
                HEADER_LEN + usize::from(l) + CRC_LEN
            }),
        });
    };
    let calculated = crc16_parts(&[&[msg_type, seq, payload.len() as u8], payload]);
    if calculated != found {
        return Err(FrameError::ChecksumMismatch {
            calculated,
            found,
            msg_type,
            seq,
        });
    }
    Ok(RawFrame {
        msg_type,
        seq,
        payload,
    })
}

/// Append one frame to `dst`.
pub fn encode(
    msg_type: u8,
    seq: u8,
    payload: &[u8],
    dst: &mut BytesMut,
) -> Result<(), EncodeError> {
    if payload.len() > MAX_PAYLOAD {
        return Err(EncodeError::PayloadTooLong {
            len: payload.len(),
            max: MAX_PAYLOAD,
        });
    }
    let header = [msg_type, seq, payload.len() as u8];
    dst.reserve(HEADER_LEN + payload.len() + CRC_LEN);
    dst.put_slice(&SYNC);
    dst.put_slice(&header);
    dst.put_slice(payload);
    dst.put_u16(crc16_parts(&[&header, payload]));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encode_then_parse() {
        let mut buf = BytesMut::new();
        encode(0x10, 7, &[3], &mut buf).unwrap();
        assert_eq!(candidate(&buf), Candidate::Complete { len: buf.len() });
        let raw = parse(&buf).unwrap();
        assert_eq!((raw.msg_type, raw.seq, raw.payload), (0x10, 7, &[3u8][..]));
    }

    #[test]
    fn flipped_payload_bit_is_a_checksum_mismatch() {
        let mut buf = BytesMut::new();
        encode(0x10, 7, &[3], &mut buf).unwrap();
        buf[5] ^= 0x01;
        assert!(matches!(
            parse(&buf),
            Err(FrameError::ChecksumMismatch { .. })
        ));
    }

    #[test]
    fn over_long_length_is_rejected_before_waiting_for_it() {
        let buf = [0xEB, 0x90, 0x10, 0x00, 65];
        assert_eq!(
            candidate(&buf),
            Candidate::Reject(FrameError::LengthTooLong { len: 65, max: 64 })
        );
    }

    #[test]
    fn too_long_payload_is_api_misuse() {
        let mut buf = BytesMut::new();
        assert!(matches!(
            encode(0x10, 0, &[0; 65], &mut buf),
            Err(EncodeError::PayloadTooLong { len: 65, max: 64 })
        ));
    }
}
