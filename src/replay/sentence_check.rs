//! The bad-line policy: what replay does with each kind of bad line, and the report of it.
//!
//! Every line is framed and checked with `firmware-protocol`'s NMEA code ([`scan_line`] for
//! the structure, [`checked_body`] for the checksum), exactly as the bridge's own decoder
//! does. Each problem becomes a [`Problem`] naming the file:line, the kind and the action
//! taken; nothing is altered without one. The policy:
//!
//! | problem | `pass` | `drop` | `fix` |
//! |---|---|---|---|
//! | checksum mismatch | sent as is | dropped | checksum recomputed |
//! | no `*hh` checksum | sent as is | dropped | checksum appended |
//! | junk before the `$` | sent as is | dropped | junk removed, the sentence checked |
//! | no `$` in the line | sent as is | dropped | dropped |
//! | over 82 characters, control or non-ASCII byte, second `$` | sent as is | dropped | dropped |
//! | longer than the input cap (4096 bytes) | dropped | dropped | dropped |
//!
//! A line ending in LF alone (or the last line without any) is sent with CR LF under every
//! policy; that is reported once per file and counted per line.

use firmware_protocol::NmeaError;
use firmware_protocol::nmea::{LineScan, SENTENCE_MAX_LEN, checked_body, checksum, scan_line};

use super::line::Terminator;
pub use super::problem::{Action, Problem, ProblemKind};

/// What to do with a bad line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Policy {
    /// Send it unchanged, as the instrument did (reproduces a field failure byte for byte).
    #[default]
    Pass,
    /// Leave it out.
    Drop,
    /// Repair what can be repaired (checksums, leading junk); drop the rest.
    Fix,
}

/// The outcome of checking one line.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Checked {
    /// The bytes to send, with CR LF; `None` when dropped.
    pub out: Option<Vec<u8>>,
    pub problems: Vec<(ProblemKind, Action)>,
    /// The sentence address (`SDDBT`) of a line that framed, for the statistics.
    pub address: Option<String>,
}

fn binary(bytes: &[u8]) -> bool {
    bytes
        .iter()
        .any(|&b| !(0x20..=0x7E).contains(&b) && b != b'\t')
}

fn with_crlf(bytes: &[u8]) -> Vec<u8> {
    let mut v = Vec::with_capacity(bytes.len() + 2);
    v.extend_from_slice(bytes);
    v.extend_from_slice(b"\r\n");
    v
}

fn address_of(body: &[u8]) -> String {
    let end = body.iter().position(|&b| b == b',').unwrap_or(body.len());
    String::from_utf8_lossy(&body[..end.min(8)]).into_owned()
}

/// Checks one line (without terminator) under `policy`.
pub fn check_line(
    bytes: &[u8],
    terminator: Terminator,
    overflow: Option<usize>,
    policy: Policy,
) -> Checked {
    let mut checked = check_body(bytes, overflow, policy);
    if checked.out.is_some() {
        match terminator {
            Terminator::CrLf => {}
            Terminator::Lf => checked
                .problems
                .push((ProblemKind::MissingCr, Action::CrAdded)),
            Terminator::Cr => checked
                .problems
                .push((ProblemKind::MissingLf, Action::LfAdded)),
            Terminator::Eof => checked
                .problems
                .push((ProblemKind::NoLineEnding, Action::CrAdded)),
        }
    }
    checked
}

fn check_body(bytes: &[u8], overflow: Option<usize>, policy: Policy) -> Checked {
    let mut c = Checked::default();
    if let Some(len) = overflow {
        c.problems
            .push((ProblemKind::LineTooLong { len }, Action::Dropped));
        return c;
    }
    let pass_or_drop = |c: &mut Checked, kind: ProblemKind| {
        let action = if policy == Policy::Pass {
            c.out = Some(with_crlf(bytes));
            Action::Passed
        } else {
            Action::Dropped
        };
        c.problems.push((kind, action));
    };
    let Some(start) = bytes.iter().position(|&b| b == b'$') else {
        pass_or_drop(
            &mut c,
            ProblemKind::NoSentence {
                len: bytes.len(),
                binary: binary(bytes),
            },
        );
        return c;
    };
    let mut sentence = bytes;
    if start > 0 {
        let kind = ProblemKind::JunkBeforeSentence {
            len: start,
            binary: binary(&bytes[..start]),
        };
        match policy {
            Policy::Pass => {
                // Sent whole below; the sentence itself is still checked and reported.
                c.problems.push((kind, Action::Passed));
                sentence = &bytes[start..];
            }
            Policy::Drop => {
                c.problems.push((kind, Action::Dropped));
                return c;
            }
            Policy::Fix => {
                c.problems.push((kind, Action::JunkRemoved));
                sentence = &bytes[start..];
            }
        }
    }
    // One buffer: the bytes to send (junk kept only under `pass`) with CR LF; the sentence
    // part of it is what gets framed and checked.
    let prefix_len = if policy == Policy::Pass {
        bytes.len() - sentence.len()
    } else {
        0
    };
    let mut out = Vec::with_capacity(prefix_len + sentence.len() + 2);
    out.extend_from_slice(&bytes[..prefix_len]);
    out.extend_from_slice(sentence);
    out.extend_from_slice(b"\r\n");
    let candidate = &out[prefix_len..];
    let framing = match scan_line(candidate, 0) {
        LineScan::Complete { len } if len == candidate.len() => None,
        LineScan::Reject { error, .. } => Some(error),
        // A CR inside the line ends it early, or no decision within 82 bytes.
        LineScan::Complete { len } => Some(NmeaError::BadTerminator { offset: len - 2 }),
        LineScan::NeedMore { .. } => Some(NmeaError::TooLong {
            max: SENTENCE_MAX_LEN,
        }),
    };
    if let Some(error) = framing {
        let action = if policy == Policy::Pass {
            c.out = Some(out);
            Action::Passed
        } else {
            Action::Dropped
        };
        c.problems.push((ProblemKind::Framing(error), action));
        return c;
    }
    let error = match checked_body(candidate) {
        Ok(body) => {
            c.address = Some(address_of(body));
            c.out = Some(out);
            return c;
        }
        Err(error) => error,
    };
    let body_end = sentence
        .iter()
        .position(|&b| b == b'*')
        .unwrap_or(sentence.len());
    let body = &sentence[1..body_end];
    c.address = Some(address_of(body));
    match policy {
        Policy::Pass => {
            c.out = Some(out);
            c.problems
                .push((ProblemKind::Checksum(error), Action::Passed));
        }
        Policy::Drop => {
            c.problems
                .push((ProblemKind::Checksum(error), Action::Dropped));
        }
        Policy::Fix => {
            let sum = checksum(body);
            let mut fixed = Vec::with_capacity(body.len() + 6);
            fixed.push(b'$');
            fixed.extend_from_slice(body);
            fixed.extend_from_slice(format!("*{sum:02X}\r\n").as_bytes());
            if fixed.len() > SENTENCE_MAX_LEN {
                c.problems
                    .push((ProblemKind::Checksum(error), Action::Dropped));
            } else {
                c.out = Some(fixed);
                c.problems.push((
                    ProblemKind::Checksum(error),
                    Action::Fixed { checksum: sum },
                ));
            }
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &[u8] = b"$SDDBT,6.6,f,2.0,M,1.1,F*04";
    const BAD_SUM: &[u8] = b"$SDDBT,6.6,f,2.0,M,1.1,F*3B";

    fn kinds(c: &Checked) -> Vec<&'static str> {
        c.problems.iter().map(|(k, _)| k.name()).collect()
    }

    #[test]
    fn the_reference_sentence_checks() {
        let c = check_line(GOOD, Terminator::CrLf, None, Policy::Drop);
        assert!(c.problems.is_empty(), "{:?}", c.problems);
        assert_eq!(
            c.out.as_deref(),
            Some(&b"$SDDBT,6.6,f,2.0,M,1.1,F*04\r\n"[..])
        );
        assert_eq!(c.address.as_deref(), Some("SDDBT"));
    }

    #[test]
    fn checksum_policies_pass_drop_fix() {
        let pass = check_line(BAD_SUM, Terminator::CrLf, None, Policy::Pass);
        assert_eq!(pass.out.as_deref(), Some(&[BAD_SUM, b"\r\n"].concat()[..]));
        assert_eq!(
            pass.problems,
            vec![(
                ProblemKind::Checksum(NmeaError::ChecksumMismatch {
                    calculated: 0x04,
                    found: 0x3B
                }),
                Action::Passed
            )]
        );
        let drop = check_line(BAD_SUM, Terminator::CrLf, None, Policy::Drop);
        assert_eq!(drop.out, None);
        assert_eq!(drop.problems[0].1, Action::Dropped);
        let fix = check_line(BAD_SUM, Terminator::CrLf, None, Policy::Fix);
        assert_eq!(fix.out.as_deref(), Some(&[GOOD, b"\r\n"].concat()[..]));
        assert_eq!(fix.problems[0].1, Action::Fixed { checksum: 0x04 });
        // A missing checksum is appended by fix.
        let fix = check_line(
            b"$SDDBT,6.6,f,2.0,M,1.1,F",
            Terminator::CrLf,
            None,
            Policy::Fix,
        );
        assert_eq!(fix.out.as_deref(), Some(&[GOOD, b"\r\n"].concat()[..]));
        assert_eq!(kinds(&fix), vec!["missing checksum"]);
    }

    #[test]
    fn lf_only_lines_gain_cr_and_say_so() {
        let c = check_line(GOOD, Terminator::Lf, None, Policy::Pass);
        assert_eq!(c.out.as_deref(), Some(&[GOOD, b"\r\n"].concat()[..]));
        assert_eq!(c.problems, vec![(ProblemKind::MissingCr, Action::CrAdded)]);
        let c = check_line(GOOD, Terminator::Eof, None, Policy::Pass);
        assert_eq!(kinds(&c), vec!["no line ending at end of file"]);
        // A dropped line is not also reported for its line ending.
        let c = check_line(BAD_SUM, Terminator::Lf, None, Policy::Drop);
        assert_eq!(kinds(&c), vec!["checksum mismatch"]);
    }

    #[test]
    fn junk_before_a_sentence_follows_the_policy() {
        let line = [&b"\x00\xff\x13"[..], GOOD].concat();
        let pass = check_line(&line, Terminator::CrLf, None, Policy::Pass);
        assert_eq!(
            pass.out.as_deref(),
            Some(&[&line[..], b"\r\n"].concat()[..])
        );
        assert_eq!(kinds(&pass), vec!["binary junk before '$'"]);
        let fix = check_line(&line, Terminator::CrLf, None, Policy::Fix);
        assert_eq!(fix.out.as_deref(), Some(&[GOOD, b"\r\n"].concat()[..]));
        assert_eq!(fix.problems[0].1, Action::JunkRemoved);
        assert_eq!(
            check_line(&line, Terminator::CrLf, None, Policy::Drop).out,
            None
        );
        // Junk, then a sentence with a bad checksum: both reported, fix repairs both.
        let line = [&b"xx"[..], BAD_SUM].concat();
        let fix = check_line(&line, Terminator::CrLf, None, Policy::Fix);
        assert_eq!(kinds(&fix), vec!["text before '$'", "checksum mismatch"]);
        assert_eq!(fix.out.as_deref(), Some(&[GOOD, b"\r\n"].concat()[..]));
    }

    #[test]
    fn structural_problems_cannot_be_fixed() {
        let long = [&b"$SDXXX,"[..], &[b'1'; 80][..], b"*00"].concat();
        let non_ascii = b"$SDDBT,6.6,f,2\xc3\xa9,M,1.1,F*3A";
        let control = b"$SDDBT,6.6\x07,f,2.0,M,1.1,F*3A";
        let junk = b"\x00\x01\x02\xfe";
        for (line, name) in [
            (&long[..], "over-long sentence"),
            (&non_ascii[..], "non-ASCII byte"),
            (&control[..], "control byte"),
            (&junk[..], "binary junk line"),
        ] {
            for policy in [Policy::Drop, Policy::Fix] {
                let c = check_line(line, Terminator::CrLf, None, policy);
                assert_eq!(c.out, None, "{name} under {policy:?}");
                assert_eq!(kinds(&c), vec![name]);
            }
            let c = check_line(line, Terminator::CrLf, None, Policy::Pass);
            assert_eq!(
                c.out.as_deref(),
                Some(&[line, b"\r\n"].concat()[..]),
                "{name} passes unchanged"
            );
        }
        let cut = check_line(b"$", Terminator::CrLf, Some(10_000), Policy::Pass);
        assert_eq!(cut.out, None, "a cut line cannot be passed whole");
    }
}
