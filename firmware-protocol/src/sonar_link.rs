//! The PICAXE multiplexer's ASCII commands on the sonar link.
//!
//! ```text
//! select   EyeBot -> master   '@' 'S' <'1'..'4'> CR        40 53 3n 0D
//! ack      master -> EyeBot   '@' 'A' <'1'..'4'> CR LF     40 41 3n 0D 0A
//! nak      master -> EyeBot   '@' 'N' CR LF                40 4E 0D 0A
//! ```
//! `@S` is the `serin` qualifier: a PICAXE master waits with
//! `serin RX, N4800, ("@S"), b0` and reads the transducer digit into `b0`. The acknowledgement
//! repeats the digit once the relays have switched. Depth data then arrives as NMEA sentences
//! (see [`crate::nmea`]).

use bytes::{BufMut, BytesMut};
use nom::{
    IResult, Parser,
    branch::alt,
    bytes::complete::tag,
    combinator::{all_consuming, map, value},
    number::complete::be_u8,
    sequence::{delimited, preceded},
};

use crate::error::{LinkError, SonarCommandError};
use crate::nmea::Transducer;

/// First byte of every sonar command.
pub const START: u8 = b'@';

/// A select, acknowledge or negative acknowledge.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SonarCommand {
    /// EyeBot asks the master to switch the relays to this transducer.
    Select(Transducer),
    /// The master reports that the relays now connect this transducer.
    Ack(Transducer),
    /// The master received a select it could not carry out (digit not 1..4).
    Nak,
}

impl SonarCommand {
    /// Wire length of a command whose letter is `letter`.
    pub fn len_for(letter: u8) -> Option<usize> {
        match letter {
            b'S' | b'N' => Some(4),
            b'A' => Some(5),
            _ => None,
        }
    }

    /// The master's answer to a wire error: `@N` for a select with a bad transducer digit,
    /// nothing for other errors (PROTOCOL.md section 3).
    pub fn nak_for(error: &LinkError) -> Option<Self> {
        matches!(
            error,
            LinkError::SonarCommand(SonarCommandError::BadTransducer { .. })
        )
        .then_some(Self::Nak)
    }

    pub fn encode(&self, dst: &mut BytesMut) {
        match self {
            Self::Select(t) => dst.put_slice(&[b'@', b'S', t.digit(), b'\r']),
            Self::Ack(t) => dst.put_slice(&[b'@', b'A', t.digit(), b'\r', b'\n']),
            Self::Nak => dst.put_slice(b"@N\r\n"),
        }
    }
}

/// Outcome of scanning bytes that start with `@`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandScan {
    NeedMore,
    Complete {
        len: usize,
    },
    Reject {
        error: SonarCommandError,
        consume: usize,
    },
}

/// Delimit a candidate command at `buf[0] == b'@'`.
pub fn scan_command(buf: &[u8]) -> CommandScan {
    debug_assert_eq!(buf.first(), Some(&START));
    let Some(&letter) = buf.get(1) else {
        return CommandScan::NeedMore;
    };
    let Some(len) = SonarCommand::len_for(letter) else {
        return CommandScan::Reject {
            error: SonarCommandError::UnknownCommand { byte: letter },
            consume: 1,
        };
    };
    if buf.len() < len {
        return CommandScan::NeedMore;
    }
    let terminator: &[u8] = if letter == b'S' { b"\r" } else { b"\r\n" };
    let at = len - terminator.len();
    for (k, &want) in terminator.iter().enumerate() {
        if buf[at + k] != want {
            return CommandScan::Reject {
                error: SonarCommandError::BadTerminator {
                    offset: at + k,
                    byte: buf[at + k],
                },
                consume: 1,
            };
        }
    }
    CommandScan::Complete { len }
}

#[derive(Clone)]
enum Shape {
    Select(u8),
    Ack(u8),
    Nak,
}

fn shape(input: &[u8]) -> IResult<&[u8], Shape> {
    alt((
        map(
            delimited(tag(&b"@S"[..]), be_u8, tag(&b"\r"[..])),
            Shape::Select,
        ),
        map(
            delimited(tag(&b"@A"[..]), be_u8, tag(&b"\r\n"[..])),
            Shape::Ack,
        ),
        value(Shape::Nak, preceded(tag(&b"@N"[..]), tag(&b"\r\n"[..]))),
    ))
    .parse(input)
}

/// Decode one whole command as delimited by [`scan_command`].
pub fn parse_command(cmd: &[u8]) -> Result<SonarCommand, SonarCommandError> {
    let (_, s) = all_consuming(shape).parse(cmd).map_err(
        |_: nom::Err<nom::error::Error<&[u8]>>| match cmd.get(1) {
            Some(&b) if SonarCommand::len_for(b).is_none() => {
                SonarCommandError::UnknownCommand { byte: b }
            }
            _ => SonarCommandError::Truncated { have: cmd.len() },
        },
    )?;
    let transducer =
        |d: u8| Transducer::from_digit(d).ok_or(SonarCommandError::BadTransducer { byte: d });
    Ok(match s {
        Shape::Select(d) => SonarCommand::Select(transducer(d)?),
        Shape::Ack(d) => SonarCommand::Ack(transducer(d)?),
        Shape::Nak => SonarCommand::Nak,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn select_two_is_four_bytes() {
        let mut b = BytesMut::new();
        SonarCommand::Select(Transducer::new(2).unwrap()).encode(&mut b);
        assert_eq!(&b[..], &[0x40, 0x53, 0x32, 0x0D]);
        assert_eq!(scan_command(&b), CommandScan::Complete { len: 4 });
        assert_eq!(
            parse_command(&b),
            Ok(SonarCommand::Select(Transducer::new(2).unwrap()))
        );
    }

    #[test]
    fn select_five_is_bad_transducer() {
        assert_eq!(
            parse_command(b"@S5\r"),
            Err(SonarCommandError::BadTransducer { byte: b'5' })
        );
    }

    #[test]
    fn bad_digit_is_answered_with_nak() {
        let e = LinkError::SonarCommand(SonarCommandError::BadTransducer { byte: b'5' });
        assert_eq!(SonarCommand::nak_for(&e), Some(SonarCommand::Nak));
        assert_eq!(
            SonarCommand::nak_for(&LinkError::Skipped { count: 1 }),
            None
        );
    }

    #[test]
    fn missing_cr_is_rejected_one_byte() {
        assert!(matches!(
            scan_command(b"@S1$"),
            CommandScan::Reject { consume: 1, .. }
        ));
    }
}
