//! The timestamp grammar of NMEA text logs: a seconds or ISO 8601 prefix before the sentence,
//! and the vote of a file's first data lines that decides its form.

use std::path::Path;

use super::{InputError, TimestampForm};

/// Parses a seconds prefix (`12`, `12.250`) into nanoseconds.
pub fn parse_seconds(prefix: &str) -> Option<i64> {
    let ok = !prefix.is_empty()
        && prefix.bytes().all(|b| b.is_ascii_digit() || b == b'.')
        && prefix.bytes().filter(|&b| b == b'.').count() <= 1
        && prefix.bytes().any(|b| b.is_ascii_digit());
    if !ok {
        return None;
    }
    let s: f64 = prefix.parse().ok()?;
    let ns = (s * 1e9).round();
    (ns.is_finite() && ns < i64::MAX as f64).then_some(ns as i64)
}

/// Parses an ISO 8601 date-time prefix into Unix nanoseconds (UTC when it has no offset).
pub fn parse_iso8601(prefix: &str) -> Option<i64> {
    if !prefix.contains('T') {
        return None;
    }
    if let Ok(t) = chrono::DateTime::parse_from_rfc3339(prefix) {
        return t.timestamp_nanos_opt();
    }
    prefix
        .parse::<chrono::NaiveDateTime>()
        .ok()?
        .and_utc()
        .timestamp_nanos_opt()
}

/// Splits `line` into a timestamp prefix and the rest, if a `$` follows the whitespace.
pub(super) fn split_prefix(line: &[u8]) -> Option<(&str, &[u8])> {
    let ws = line.iter().position(|&b| b == b' ' || b == b'\t')?;
    let rest_at = ws + line[ws..].iter().position(|&b| b != b' ' && b != b'\t')?;
    let prefix = std::str::from_utf8(&line[..ws]).ok()?;
    Some((prefix, &line[rest_at..]))
}

/// The form a single data line shows, if any.
pub fn classify(line: &[u8]) -> Option<TimestampForm> {
    if line.first() == Some(&b'$') {
        return Some(TimestampForm::None);
    }
    let (prefix, rest) = split_prefix(line)?;
    if rest.first() != Some(&b'$') {
        return None;
    }
    if parse_seconds(prefix).is_some() {
        Some(TimestampForm::Seconds)
    } else if parse_iso8601(prefix).is_some() {
        Some(TimestampForm::Iso8601)
    } else {
        None
    }
}

/// Decides a file's timestamp form from the votes of its first data lines (rule on
/// [`TimestampForm`]). `votes` holds (line number, form) for lines that showed one.
pub fn decide_form(
    path: &Path,
    votes: &[(u64, TimestampForm)],
) -> Result<TimestampForm, InputError> {
    let forms = [
        TimestampForm::None,
        TimestampForm::Seconds,
        TimestampForm::Iso8601,
    ];
    let count = |f: TimestampForm| votes.iter().filter(|(_, v)| *v == f).count();
    let best = forms.iter().map(|&f| count(f)).max().unwrap_or(0);
    let winners: Vec<TimestampForm> = forms.into_iter().filter(|&f| count(f) == best).collect();
    match winners.as_slice() {
        _ if best == 0 => Ok(TimestampForm::None),
        [one] => Ok(*one),
        [a, b, ..] => {
            let line_of = |f: TimestampForm| {
                votes
                    .iter()
                    .find(|(_, v)| *v == f)
                    .map_or(0, |(line, _)| *line)
            };
            Err(InputError::MixedTimestamps {
                path: path.to_path_buf(),
                first: line_of(*a),
                second: line_of(*b),
                a: *a,
                b: *b,
            })
        }
        [] => Ok(TimestampForm::None),
    }
}
