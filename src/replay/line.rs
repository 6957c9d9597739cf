//! What a log line is, before any check: where it came from, how it ended, the timestamp
//! form of its file. Shared by the reader ([`super::input`]) and the checks
//! ([`super::sentence_check`]), which depend on this module and not on each other.

use std::fmt;
use std::path::Path;
use std::sync::Arc;

/// The longest physical line kept from an input. Longer lines are cut here and dropped by
/// validation (they are at least 50 times the NMEA limit of 82 characters).
pub const MAX_PHYSICAL_LINE: usize = 4096;

/// Where a line came from.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Loc {
    pub file: Arc<Path>,
    /// 1-based.
    pub line: u64,
}

impl fmt::Display for Loc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.file.display(), self.line)
    }
}

/// How a line ended in the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Terminator {
    CrLf,
    /// LF without CR: normalised to CR LF on output, and reported.
    Lf,
    /// CR not followed by LF (old Mac-style line endings): normalised to CR LF on output, and
    /// reported.
    Cr,
    /// The file ended without a line feed.
    Eof,
}

/// The timestamp prefix of an NMEA text log.
///
/// **Detection rule.** The first [`DETECT_LINES`](super::input::DETECT_LINES) data lines (not blank, not `#`) are
/// classified: a line starting with `$` has no prefix; otherwise the text before the first
/// run of spaces or tabs is the prefix, provided a `$` follows that run. A prefix of digits
/// with at most one `.` is [`Seconds`](Self::Seconds); a prefix that parses as an ISO 8601
/// date-time (`2024-05-01T12:00:00.250Z`, `...+02:00`, or without offset, taken as UTC) is
/// [`Iso8601`](Self::Iso8601). Lines that fit no form (junk) do not vote. The form with most
/// votes wins; a tie between two forms is an error naming the file. A later line that does
/// not carry the file's form is reported and dropped, since it cannot be placed in time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimestampForm {
    None,
    /// Seconds, e.g. `12.250` (relative) or `1714564800.250` (Unix time).
    Seconds,
    /// ISO 8601 date-time, converted to Unix time.
    Iso8601,
}

impl fmt::Display for TimestampForm {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            TimestampForm::None => "no timestamps",
            TimestampForm::Seconds => "timestamps in seconds",
            TimestampForm::Iso8601 => "ISO 8601 timestamps",
        })
    }
}
