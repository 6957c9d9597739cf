//! What replay reports about a line: a [`Problem`] names where, what ([`ProblemKind`]) and
//! what was done about it ([`Action`]).

use std::fmt;

use firmware_protocol::NmeaError;

use super::line::{Loc, MAX_PHYSICAL_LINE, TimestampForm};

/// What is wrong with a line.
#[derive(Debug, Clone, PartialEq)]
pub enum ProblemKind {
    /// Checksum missing or wrong (the protocol crate's error).
    Checksum(NmeaError),
    /// Framing: over-long, a control or non-ASCII byte, an interrupting `$`.
    Framing(NmeaError),
    /// `len` bytes before the `$`; `binary` when any is not printable ASCII.
    JunkBeforeSentence { len: usize, binary: bool },
    /// No `$` anywhere in the line.
    NoSentence { len: usize, binary: bool },
    /// The physical line exceeded the input cap.
    LineTooLong { len: usize },
    /// LF without CR.
    MissingCr,
    /// CR without LF.
    MissingLf,
    /// Reading the input failed part-way (a truncated gzip, a vanished device).
    ReadFailed { reason: String },
    /// The file's last line has no line ending.
    NoLineEnding,
    /// A line of a timestamped file without a readable timestamp.
    BadTimestamp {
        expected: TimestampForm,
        found: String,
    },
    /// Time earlier than the line before (sent in file order).
    TimeWentBack { by_s: f64 },
    /// A `bytes.tsv` line that does not parse.
    BadRecordLine { reason: String },
    /// A `bytes.tsv` chunk whose `sim_s` is no simulated time (`NaN`, infinite, negative or
    /// out of range), in seconds as read.
    BadRecordTime { found_s: f64 },
    /// `#Serial:` with settings that do not parse.
    BadSerialComment { reason: String },
    /// `#Serial:` that disagrees with the settings in force.
    SerialConflict {
        found: String,
        in_force: String,
        why: &'static str,
    },
}

impl ProblemKind {
    /// A short stable name, for the summary table.
    pub fn name(&self) -> &'static str {
        match self {
            ProblemKind::Checksum(NmeaError::ChecksumMismatch { .. }) => "checksum mismatch",
            ProblemKind::Checksum(_) => "missing checksum",
            ProblemKind::Framing(NmeaError::TooLong { .. }) => "over-long sentence",
            ProblemKind::Framing(NmeaError::InvalidByte { byte, .. }) if *byte >= 0x80 => {
                "non-ASCII byte"
            }
            ProblemKind::Framing(NmeaError::InvalidByte { .. }) => "control byte",
            ProblemKind::Framing(_) => "malformed sentence",
            ProblemKind::JunkBeforeSentence { binary: true, .. } => "binary junk before '$'",
            ProblemKind::JunkBeforeSentence { .. } => "text before '$'",
            ProblemKind::NoSentence { binary: true, .. } => "binary junk line",
            ProblemKind::NoSentence { .. } => "line without '$'",
            ProblemKind::LineTooLong { .. } => "line over input cap",
            ProblemKind::MissingCr => "LF without CR",
            ProblemKind::MissingLf => "CR without LF",
            ProblemKind::ReadFailed { .. } => "input cut short",
            ProblemKind::NoLineEnding => "no line ending at end of file",
            ProblemKind::BadTimestamp { .. } | ProblemKind::BadRecordTime { .. } => "bad timestamp",
            ProblemKind::TimeWentBack { .. } => "time went back",
            ProblemKind::BadRecordLine { .. } => "bad bytes.tsv line",
            ProblemKind::BadSerialComment { .. } => "bad #Serial comment",
            ProblemKind::SerialConflict { .. } => "#Serial conflict",
        }
    }

    /// Reported once per file rather than once per line (still counted per line).
    pub fn once_per_file(&self) -> bool {
        matches!(self, ProblemKind::MissingCr | ProblemKind::MissingLf)
    }

    pub fn is_checksum(&self) -> bool {
        matches!(self, ProblemKind::Checksum(_))
    }
}

impl fmt::Display for ProblemKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ProblemKind::Checksum(e) | ProblemKind::Framing(e) => write!(f, "{e}"),
            ProblemKind::JunkBeforeSentence { len, binary } => write!(
                f,
                "{len} {} bytes before '$'",
                if *binary { "binary" } else { "text" }
            ),
            ProblemKind::NoSentence { len, binary } => write!(
                f,
                "{len} {}bytes and no '$'",
                if *binary { "binary " } else { "" }
            ),
            ProblemKind::LineTooLong { len } => write!(
                f,
                "line of {len} bytes exceeds the input cap of {} bytes",
                MAX_PHYSICAL_LINE
            ),
            ProblemKind::MissingCr => f.write_str("lines end in LF without CR"),
            ProblemKind::MissingLf => f.write_str("lines end in CR without LF"),
            ProblemKind::ReadFailed { reason } => write!(f, "reading failed: {reason}"),
            ProblemKind::NoLineEnding => f.write_str("last line has no line ending"),
            ProblemKind::BadTimestamp { expected, found } => {
                write!(f, "expected a line with {expected}, found \"{found}\"")
            }
            ProblemKind::TimeWentBack { by_s } => {
                write!(f, "time goes back {by_s:.3} s from the line before")
            }
            ProblemKind::BadRecordLine { reason } => write!(f, "bytes.tsv: {reason}"),
            // `{:?}` writes 1e300 as `1e300`, not as 301 digits.
            ProblemKind::BadRecordTime { found_s } => write!(
                f,
                "bytes.tsv: column `sim_s`: expected a simulated time from 0 to {:.0} s, found {found_s:?}",
                i64::MAX as f64 * 1e-9
            ),
            ProblemKind::BadSerialComment { reason } => write!(f, "#Serial: {reason}"),
            ProblemKind::SerialConflict {
                found,
                in_force,
                why,
            } => write!(
                f,
                "#Serial: {found} differs from {in_force} in force ({why})"
            ),
        }
    }
}

/// What replay did about a problem.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Action {
    Passed,
    Dropped,
    /// Checksum recomputed (or appended): the new value.
    Fixed {
        checksum: u8,
    },
    JunkRemoved,
    CrAdded,
    LfAdded,
    SentInFileOrder,
    /// The rest of the input is not read.
    InputEnded,
    Ignored,
}

impl fmt::Display for Action {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Action::Passed => f.write_str("sent unchanged (policy pass)"),
            Action::Dropped => f.write_str("dropped"),
            Action::Fixed { checksum } => write!(f, "fixed: checksum set to {checksum:02X}"),
            Action::JunkRemoved => f.write_str("junk removed (policy fix)"),
            Action::CrAdded => f.write_str("CR added: sent with CR LF"),
            Action::LfAdded => f.write_str("LF added: sent with CR LF"),
            Action::SentInFileOrder => f.write_str("sent in file order"),
            Action::InputEnded => f.write_str("the rest of this input is lost"),
            Action::Ignored => f.write_str("ignored"),
        }
    }
}

/// One problem, reported once.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    pub loc: Loc,
    pub kind: ProblemKind,
    pub action: Action,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}; {}", self.loc, self.kind, self.action)
    }
}
