//! NMEA 0183 on the sonar link: line framing, XOR checksum, and the depth sentences.
//!
//! A sentence is `$` + address + `,` + fields + `*` + two hex digits + CR LF, at most
//! [`SENTENCE_MAX_LEN`] characters. [`scan_line`] finds a candidate line in a stream (it
//! never waits past 82 bytes); [`parse_line`] checks and decodes one whole line with nom.
//! Sentences: `DBT` (default), `DPT`, and the proprietary `$PEBHS` echo report.

use bytes::{BufMut, BytesMut};
use nom::{
    IResult, Parser,
    bytes::complete::{tag, take, take_till, take_while_m_n},
    character::complete::char,
    combinator::{all_consuming, opt},
};

use crate::error::{EncodeError, LinkError, NmeaError, SentenceError};

/// Longest sentence including `$` and CR LF (NMEA 0183).
pub const SENTENCE_MAX_LEN: usize = 82;

/// Manufacturer mnemonic of the proprietary echo report (`$PEBHS`): "EBH" = EyeBot-HIL.
pub const PROPRIETARY_ADDRESS: &[u8] = b"PEBHS";

/// XOR of every byte (the bytes between `$` and `*`).
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |acc, &b| acc ^ b)
}

/// Outcome of scanning bytes that start with `$`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineScan {
    /// No decision yet; resume scanning at `scanned` when more bytes arrive.
    NeedMore { scanned: usize },
    /// `buf[..len]` is a whole line ending in CR LF.
    Complete { len: usize },
    /// Not a valid line: report `error`, drop `consume` bytes, rescan.
    Reject { error: NmeaError, consume: usize },
}

/// Find the end of the line starting at `buf[0] == b'$'`, resuming at `from`.
pub fn scan_line(buf: &[u8], from: usize) -> LineScan {
    debug_assert_eq!(buf.first(), Some(&b'$'));
    let end = buf.len().min(SENTENCE_MAX_LEN);
    let mut i = from.max(1);
    while i < end {
        // Skip eight ordinary bytes at a time; fall back to one byte at a time near a special.
        if let Some(word) = buf.get(i..i + 8).filter(|_| i + 8 <= end) {
            let mut w = [0u8; 8];
            w.copy_from_slice(word);
            if !has_special_byte(u64::from_le_bytes(w)) {
                i += 8;
                continue;
            }
        }
        let b = buf[i];
        if (0x20..=0x7E).contains(&b) && b != b'$' {
            i += 1;
            continue;
        }
        return match b {
            b'\r' => {
                if i + 2 > SENTENCE_MAX_LEN {
                    too_long()
                } else {
                    match buf.get(i + 1) {
                        None => LineScan::NeedMore { scanned: i },
                        Some(b'\n') => LineScan::Complete { len: i + 2 },
                        Some(_) => LineScan::Reject {
                            error: NmeaError::BadTerminator { offset: i },
                            consume: 1,
                        },
                    }
                }
            }
            b'$' => LineScan::Reject {
                error: NmeaError::Interrupted { len: i },
                consume: i,
            },
            byte => LineScan::Reject {
                error: NmeaError::InvalidByte { byte, offset: i },
                consume: 1,
            },
        };
    }
    if buf.len() >= SENTENCE_MAX_LEN {
        too_long()
    } else {
        LineScan::NeedMore { scanned: i }
    }
}

/// True when any byte of `w` is outside `0x20..=0x7E` or is `$` (SWAR: exact for "any",
/// borrows and carries only disturb bytes above a byte that already matched).
fn has_special_byte(w: u64) -> bool {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    let below_space = w.wrapping_sub(LO * 0x20) & !w & HI;
    let del_or_high = (w.wrapping_add(LO) | w) & HI;
    let x = w ^ (LO * u64::from(b'$'));
    let dollar = x.wrapping_sub(LO) & !x & HI;
    below_space | del_or_high | dollar != 0
}

fn too_long() -> LineScan {
    LineScan::Reject {
        error: NmeaError::TooLong {
            max: SENTENCE_MAX_LEN,
        },
        consume: 1,
    }
}

/// Two-letter talker identifier (`SD` sounder, `II` integrated instruments, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Talker([u8; 2]);

impl Talker {
    /// Depth sounder, the default.
    pub const SOUNDER: Talker = Talker(*b"SD");

    pub fn new(talker: &str) -> Result<Self, EncodeError> {
        match talker.as_bytes() {
            &[a, b] if a.is_ascii_uppercase() && b.is_ascii_uppercase() => Ok(Self([a, b])),
            _ => Err(EncodeError::BadTalker {
                talker: talker.to_owned(),
            }),
        }
    }
    pub fn as_bytes(&self) -> [u8; 2] {
        self.0
    }
}

/// A decimal with exactly one digit after the point, held exactly as tenths (`x.x` fields).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Tenths(i32);

impl Tenths {
    /// Largest magnitude written: 99999.9.
    pub const MAX: i32 = 999_999;

    pub fn from_tenths(tenths: i32) -> Option<Self> {
        (tenths.abs() <= Self::MAX).then_some(Self(tenths))
    }
    /// Round `value` to tenths; `field` names it in the error.
    pub fn from_f64(field: &'static str, value: f64) -> Result<Self, EncodeError> {
        let tenths = (value * 10.0).round();
        if !tenths.is_finite() || tenths.abs() > f64::from(Self::MAX) {
            return Err(EncodeError::NumberOutOfRange { field, value });
        }
        Ok(Self(tenths as i32))
    }
    pub fn tenths(self) -> i32 {
        self.0
    }
    pub fn as_f64(self) -> f64 {
        f64::from(self.0) / 10.0
    }
    fn non_negative(field: &'static str, value: f64) -> Result<Self, EncodeError> {
        if value < 0.0 {
            return Err(EncodeError::Negative { field, value });
        }
        Self::from_f64(field, value)
    }
    fn put(self, dst: &mut BytesMut) {
        if self.0 < 0 {
            dst.put_u8(b'-');
        }
        let abs = self.0.unsigned_abs();
        put_decimal(dst, abs / 10);
        dst.put_u8(b'.');
        dst.put_u8(b'0' + (abs % 10) as u8);
    }
}

fn put_decimal(dst: &mut BytesMut, mut v: u32) {
    let mut digits = [0u8; 10];
    let mut n = 0;
    loop {
        digits[n] = b'0' + (v % 10) as u8;
        n += 1;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    for &d in digits[..n].iter().rev() {
        dst.put_u8(d);
    }
}

/// `$--DBT,<feet>,f,<metres>,M,<fathoms>,F`: depth below transducer. Empty = no data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Dbt {
    pub talker: Talker,
    pub feet: Option<Tenths>,
    pub metres: Option<Tenths>,
    pub fathoms: Option<Tenths>,
}

/// Feet per metre and fathoms per metre used to fill DBT's three units.
pub const FEET_PER_METRE: f64 = 1.0 / 0.3048;
pub const FATHOMS_PER_METRE: f64 = 1.0 / 1.8288;

impl Dbt {
    /// A DBT with all three units filled from one depth in metres.
    pub fn from_depth_m(talker: Talker, depth_m: f64) -> Result<Self, EncodeError> {
        Ok(Self {
            talker,
            feet: Some(Tenths::non_negative("depth_ft", depth_m * FEET_PER_METRE)?),
            metres: Some(Tenths::non_negative("depth_m", depth_m)?),
            fathoms: Some(Tenths::non_negative(
                "depth_fathoms",
                depth_m * FATHOMS_PER_METRE,
            )?),
        })
    }
    /// The "no echo" form with every value field empty.
    pub fn empty(talker: Talker) -> Self {
        Self {
            talker,
            feet: None,
            metres: None,
            fathoms: None,
        }
    }
}

/// `$--DPT,<depth m>,<offset m>[,<max range m>]`: depth of water.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Dpt {
    pub talker: Talker,
    pub depth_m: Option<Tenths>,
    pub offset_m: Option<Tenths>,
    /// `None`: the third field is absent (NMEA 2.x form). `Some(None)`: present but empty.
    pub max_range_m: Option<Option<Tenths>>,
}

impl Dpt {
    /// Depth below the transducer and transducer offset (positive: transducer to waterline).
    pub fn new(talker: Talker, depth_m: f64, offset_m: f64) -> Result<Self, EncodeError> {
        Ok(Self {
            talker,
            depth_m: Some(Tenths::non_negative("depth_m", depth_m)?),
            offset_m: Some(Tenths::from_f64("offset_m", offset_m)?),
            max_range_m: None,
        })
    }
}

/// Transducer number on the PICAXE multiplexer, 1..=4.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Transducer(u8);

impl Transducer {
    pub fn new(transducer: u8) -> Result<Self, EncodeError> {
        if (1..=4).contains(&transducer) {
            Ok(Self(transducer))
        } else {
            Err(EncodeError::TransducerOutOfRange { transducer })
        }
    }
    pub fn get(self) -> u8 {
        self.0
    }
    /// The ASCII digit '1'..='4'.
    pub fn digit(self) -> u8 {
        b'0' + self.0
    }
    pub(crate) fn from_digit(digit: u8) -> Option<Self> {
        (b'1'..=b'4').contains(&digit).then(|| Self(digit - b'0'))
    }
}

/// `$PEBHS,<transducer>,<range m>,<quality %>`: proprietary echo report naming the
/// transducer. Range empty when the echo was invalid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EchoReport {
    pub transducer: Transducer,
    pub range_m: Option<Tenths>,
    /// Echo quality 0..=100 percent (0 when there was no valid echo).
    pub quality_pct: u8,
}

impl EchoReport {
    pub fn new(
        transducer: Transducer,
        range_m: Option<f64>,
        quality_pct: u8,
    ) -> Result<Self, EncodeError> {
        if quality_pct > 100 {
            return Err(EncodeError::QualityOutOfRange {
                quality: quality_pct,
            });
        }
        let range_m = range_m
            .map(|r| Tenths::non_negative("range_m", r))
            .transpose()?;
        Ok(Self {
            transducer,
            range_m,
            quality_pct,
        })
    }
}

/// Every sentence the sonar link carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Sentence {
    Dbt(Dbt),
    Dpt(Dpt),
    Echo(EchoReport),
}

impl Sentence {
    /// Append the sentence with checksum and CR LF. Fails (writing nothing) only if it would
    /// exceed 82 characters, which the value ranges above cannot reach.
    pub fn encode(&self, dst: &mut BytesMut) -> Result<(), EncodeError> {
        let start = dst.len();
        dst.reserve(SENTENCE_MAX_LEN);
        dst.put_u8(b'$');
        let opt = |dst: &mut BytesMut, v: Option<Tenths>| {
            if let Some(v) = v {
                v.put(dst);
            }
        };
        match self {
            Sentence::Dbt(d) => {
                dst.put_slice(&d.talker.0);
                dst.put_slice(b"DBT,");
                opt(dst, d.feet);
                dst.put_slice(b",f,");
                opt(dst, d.metres);
                dst.put_slice(b",M,");
                opt(dst, d.fathoms);
                dst.put_slice(b",F");
            }
            Sentence::Dpt(d) => {
                dst.put_slice(&d.talker.0);
                dst.put_slice(b"DPT,");
                opt(dst, d.depth_m);
                dst.put_u8(b',');
                opt(dst, d.offset_m);
                if let Some(max) = d.max_range_m {
                    dst.put_u8(b',');
                    opt(dst, max);
                }
            }
            Sentence::Echo(e) => {
                dst.put_slice(PROPRIETARY_ADDRESS);
                dst.put_u8(b',');
                dst.put_u8(e.transducer.digit());
                dst.put_u8(b',');
                opt(dst, e.range_m);
                dst.put_u8(b',');
                put_decimal(dst, u32::from(e.quality_pct));
            }
        }
        let sum = checksum(&dst[start + 1..]);
        const HEX: &[u8; 16] = b"0123456789ABCDEF";
        dst.put_slice(&[
            b'*',
            HEX[usize::from(sum >> 4)],
            HEX[usize::from(sum & 0xF)],
            b'\r',
            b'\n',
        ]);
        let len = dst.len() - start;
        if len > SENTENCE_MAX_LEN {
            dst.truncate(start);
            return Err(EncodeError::SentenceTooLong {
                len,
                max: SENTENCE_MAX_LEN,
            });
        }
        Ok(())
    }
}

type Res<'a, O> = IResult<&'a [u8], O>;

fn hex_value(b: u8) -> Option<u8> {
    match b {
        b'0'..=b'9' => Some(b - b'0'),
        b'A'..=b'F' => Some(b - b'A' + 10),
        b'a'..=b'f' => Some(b - b'a' + 10),
        _ => None,
    }
}

/// `$` body `*` h h CR LF, all consuming.
fn line_parts(input: &[u8]) -> Res<'_, (&[u8], &[u8])> {
    let (input, _) = char('$').parse(input)?;
    let (input, body) = take_till(|b| b == b'*' || b == b'\r').parse(input)?;
    let (input, _) = char('*').parse(input)?;
    let (input, digits) = take(2usize).parse(input)?;
    let (input, _) = tag(&b"\r\n"[..]).parse(input)?;
    Ok((input, (body, digits)))
}

/// Check the checksum of a whole line (from `$` to LF) and return the body between `$` and
/// `*`.
pub fn checked_body(line: &[u8]) -> Result<&[u8], NmeaError> {
    let (_, (body, digits)) = all_consuming(line_parts)
        .parse(line)
        .map_err(|_: nom::Err<nom::error::Error<&[u8]>>| NmeaError::MissingChecksum)?;
    let found = match digits {
        &[h, l] => match (hex_value(h), hex_value(l)) {
            (Some(h), Some(l)) => (h << 4) | l,
            _ => return Err(NmeaError::MissingChecksum),
        },
        _ => return Err(NmeaError::MissingChecksum),
    };
    let calculated = checksum(body);
    if calculated != found {
        return Err(NmeaError::ChecksumMismatch { calculated, found });
    }
    Ok(body)
}

/// Decode one whole line (as delimited by [`scan_line`]).
pub fn parse_line(line: &[u8]) -> Result<Sentence, LinkError> {
    let body = checked_body(line)?;
    Ok(parse_body(body)?)
}

fn unsupported(address: &[u8]) -> SentenceError {
    let mut a = [0u8; 8];
    let len = address.len().min(8);
    a[..len].copy_from_slice(&address[..len]);
    SentenceError::Unsupported {
        address: a,
        len: len as u8,
    }
}

/// Decode the body of a sentence whose checksum checked.
pub fn parse_body(body: &[u8]) -> Result<Sentence, SentenceError> {
    let mut fields = body.split(|&b| b == b',');
    let address = fields.next().unwrap_or_default();
    if address == PROPRIETARY_ADDRESS {
        let f = collect::<3>(fields)?;
        let transducer = match f[0] {
            &[d] => Transducer::from_digit(d),
            _ => None,
        }
        .ok_or(SentenceError::BadField {
            index: 0,
            expected: "transducer digit 1..4",
        })?;
        let range_m = opt_tenths(f[1], 1, false)?;
        let quality_pct = parse_quality(f[2])?;
        return Ok(Sentence::Echo(EchoReport {
            transducer,
            range_m,
            quality_pct,
        }));
    }
    let (talker, kind) = match address {
        &[a, b, ref kind @ ..]
            if kind.len() == 3 && a.is_ascii_uppercase() && b.is_ascii_uppercase() =>
        {
            (Talker([a, b]), kind)
        }
        _ if address.first() == Some(&b'P') => return Err(unsupported(address)),
        _ => return Err(SentenceError::BadAddress),
    };
    match kind {
        b"DBT" => {
            let f = collect::<6>(fields)?;
            unit(f[1], b"f", 1)?;
            unit(f[3], b"M", 3)?;
            unit(f[5], b"F", 5)?;
            Ok(Sentence::Dbt(Dbt {
                talker,
                feet: opt_tenths(f[0], 0, false)?,
                metres: opt_tenths(f[2], 2, false)?,
                fathoms: opt_tenths(f[4], 4, false)?,
            }))
        }
        b"DPT" => {
            let f: Vec<&[u8]> = fields.take(4).collect();
            if !(2..=3).contains(&f.len()) {
                return Err(SentenceError::FieldCount {
                    expected: 3,
                    found: f.len() as u8,
                });
            }
            let max_range_m = match f.get(2) {
                None => None,
                Some(field) => Some(opt_tenths(field, 2, false)?),
            };
            Ok(Sentence::Dpt(Dpt {
                talker,
                depth_m: opt_tenths(f[0], 0, false)?,
                offset_m: opt_tenths(f[1], 1, true)?,
                max_range_m,
            }))
        }
        _ => Err(unsupported(address)),
    }
}

fn collect<'a, const N: usize>(
    mut fields: impl Iterator<Item = &'a [u8]>,
) -> Result<[&'a [u8]; N], SentenceError> {
    let mut out: [&[u8]; N] = [&[]; N];
    let mut found = 0u8;
    for slot in &mut out {
        match fields.next() {
            Some(f) => {
                *slot = f;
                found += 1;
            }
            None => {
                return Err(SentenceError::FieldCount {
                    expected: N as u8,
                    found,
                });
            }
        }
    }
    let extra = fields.count();
    if extra > 0 {
        return Err(SentenceError::FieldCount {
            expected: N as u8,
            found: (N + extra).min(255) as u8,
        });
    }
    Ok(out)
}

fn unit(field: &[u8], want: &[u8], index: u8) -> Result<(), SentenceError> {
    if field == want {
        Ok(())
    } else {
        Err(SentenceError::BadField {
            index,
            expected: "unit letter",
        })
    }
}

fn is_digit(b: u8) -> bool {
    b.is_ascii_digit()
}

/// `-?d{1,5}.d` as (negative, integer digits, tenth digit).
fn tenths_parts(input: &[u8]) -> Res<'_, (Option<char>, &[u8], &[u8])> {
    let (input, sign) = opt(char('-')).parse(input)?;
    let (input, int) = take_while_m_n(1, 5, is_digit).parse(input)?;
    let (input, _) = char('.').parse(input)?;
    let (input, frac) = take_while_m_n(1, 1, is_digit).parse(input)?;
    Ok((input, (sign, int, frac)))
}

fn opt_tenths(
    field: &[u8],
    index: u8,
    allow_negative: bool,
) -> Result<Option<Tenths>, SentenceError> {
    if field.is_empty() {
        return Ok(None);
    }
    let err = SentenceError::BadField {
        index,
        expected: if allow_negative {
            "empty or -?d.d"
        } else {
            "empty or d.d"
        },
    };
    let (_, (sign, int, frac)) = all_consuming(tenths_parts)
        .parse(field)
        .map_err(|_: nom::Err<nom::error::Error<&[u8]>>| err)?;
    if sign.is_some() && !allow_negative {
        return Err(err);
    }
    let magnitude = int
        .iter()
        .chain(frac)
        .fold(0i32, |acc, &d| acc * 10 + i32::from(d - b'0'));
    Ok(Some(Tenths(if sign.is_some() {
        -magnitude
    } else {
        magnitude
    })))
}

fn parse_quality(field: &[u8]) -> Result<u8, SentenceError> {
    let err = SentenceError::BadField {
        index: 2,
        expected: "quality 0..100",
    };
    let (_, digits) = all_consuming(take_while_m_n(1, 3, is_digit))
        .parse(field)
        .map_err(|_: nom::Err<nom::error::Error<&[u8]>>| err)?;
    let v = digits
        .iter()
        .fold(0u16, |acc, &d| acc * 10 + u16::from(d - b'0'));
    u8::try_from(v).ok().filter(|&v| v <= 100).ok_or(err)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encode(s: Sentence) -> Vec<u8> {
        let mut b = BytesMut::new();
        s.encode(&mut b).unwrap();
        b.to_vec()
    }

    #[test]
    fn dbt_from_depth_fills_three_units() {
        let s = Sentence::Dbt(Dbt::from_depth_m(Talker::SOUNDER, 3.2).unwrap());
        assert_eq!(encode(s), b"$SDDBT,10.5,f,3.2,M,1.7,F*35\r\n");
    }

    #[test]
    fn checksum_mismatch_names_both_values() {
        let err = parse_line(b"$SDDBT,10.5,f,3.2,M,1.7,F*37\r\n").unwrap_err();
        assert_eq!(
            err,
            LinkError::Nmea(NmeaError::ChecksumMismatch {
                calculated: 0x35,
                found: 0x37
            })
        );
    }

    #[test]
    fn negative_depth_is_api_misuse() {
        assert!(matches!(
            Dbt::from_depth_m(Talker::SOUNDER, -1.0),
            Err(EncodeError::Negative { .. })
        ));
        assert!(Talker::new("sd").is_err());
    }

    #[test]
    fn scan_stops_at_82_characters() {
        let mut line = vec![b'$'];
        line.extend(std::iter::repeat_n(b'A', 90));
        assert!(matches!(
            scan_line(&line, 0),
            LineScan::Reject {
                error: NmeaError::TooLong { .. },
                consume: 1
            }
        ));
    }

    /// The word-at-a-time test must agree with the byte test for every byte in every lane.
    #[test]
    fn swar_special_byte_test_matches_byte_test() {
        let ordinary = |b: u8| (0x20..=0x7E).contains(&b) && b != b'$';
        for lane in 0..8 {
            for b in 0..=255u8 {
                for fill in [b'A', b' ', b'~', b'0'] {
                    let mut w = [fill; 8];
                    w[lane] = b;
                    assert_eq!(
                        has_special_byte(u64::from_le_bytes(w)),
                        !ordinary(b),
                        "byte {b:#04x} in lane {lane} among {fill:#04x}"
                    );
                }
            }
        }
    }

    #[test]
    fn exactly_82_characters_is_accepted_by_the_framer() {
        let mut line = vec![b'$'];
        line.extend(std::iter::repeat_n(b'A', 79));
        line.extend(b"\r\n");
        assert_eq!(line.len(), 82);
        assert_eq!(scan_line(&line, 0), LineScan::Complete { len: 82 });
    }
}
