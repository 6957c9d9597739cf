//! Reading logs: plain and timestamped NMEA text, our own `--record` output, gzip, comments.
//!
//! Every input is streamed one physical line at a time; nothing holds a whole file. A line
//! longer than [`MAX_PHYSICAL_LINE`] bytes is cut at the input (its length is kept for the
//! report) so binary junk without line feeds cannot grow memory.
//!
//! **Formats, detected per file:**
//! - gzip by its magic bytes `1f 8b` (the extension is not consulted);
//! - a `--record` directory (its `bytes.tsv` or `bytes.tsv.gz`) or a file whose first line is
//!   the `bytes.tsv` header: the `tx` chunks of one link (default `sonar`) are joined and cut
//!   into lines at LF, so sentences split across chunks are reassembled. A sentence takes the
//!   `sim_s` of the chunk holding its first byte and the file:line of that chunk. Lines of the
//!   sonar link's own select/ack protocol (starting with `@`) are skipped and counted;
//! - otherwise an NMEA text log, with or without a timestamp prefix (see [`TimestampForm`]).
//!
//! Lines starting with `#` are gpsfake-style comments. `#Serial: 4800 8N1` (also
//! `# Serial:`) gives the line settings; other comments are handed to the report.

mod open;
mod recording;
mod timestamp;

use std::collections::VecDeque;
use std::fmt;
use std::io::{self, BufRead, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicU64;

use crate::record::BYTES_HEADER;
use crate::transport::LineSettings;

use super::output::Shutdown;

pub use super::line::{Loc, MAX_PHYSICAL_LINE, Terminator, TimestampForm};
use super::problem::{Action, Problem, ProblemKind};
use open::decompressing;
pub use open::{STDIN, is_stdin, open_reader, read_capped, resolve_path};
use timestamp::split_prefix;
pub use timestamp::{classify, decide_form, parse_iso8601, parse_seconds};

/// How many data lines at the start of a file decide its timestamp form.
pub const DETECT_LINES: usize = 8;

/// At most this many comment and data lines are read ahead to find those [`DETECT_LINES`]
/// (blank lines are counted, not held): a head of a million comments decides on what it has.
pub const DETECT_MAX_LOOKAHEAD: usize = 256;

/// What kind of input a file turned out to be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Nmea { timestamps: TimestampForm },
    Recording,
}

impl Format {
    pub fn is_timed(self) -> bool {
        !matches!(
            self,
            Format::Nmea {
                timestamps: TimestampForm::None
            }
        )
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Format::Nmea { timestamps } => write!(f, "NMEA log, {timestamps}"),
            Format::Recording => f.write_str("eyebot-hil recording (bytes.tsv)"),
        }
    }
}

/// Whether a log line is data or a comment passed through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineKind {
    Data,
    /// A `#` comment sent to the output (`--comments send`).
    Comment,
}

/// One line of a log, before validation.
#[derive(Debug, Clone, PartialEq)]
pub struct LogLine {
    pub loc: Loc,
    /// Index of the input on the command line.
    pub input: usize,
    /// Log time in nanoseconds (Unix time for ISO 8601, else as written), if the log has one.
    pub time_ns: Option<i64>,
    /// The line without its terminator (and without the timestamp prefix).
    pub bytes: Vec<u8>,
    pub terminator: Terminator,
    /// The line's real length when it exceeded [`MAX_PHYSICAL_LINE`] and was cut.
    pub overflow: Option<usize>,
    pub kind: LineKind,
}

/// What reading an input yields, in file order.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    Line(LogLine),
    Comment { loc: Loc, text: String },
    Serial { loc: Loc, settings: LineSettings },
    Problem(Problem),
}

/// What to do with `#` comments other than `#Serial:`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum CommentMode {
    /// List them in the report (stderr); do not send them.
    #[default]
    Report,
    /// Send them to the output as lines, as gpsfake does (gpsd ignores them).
    Send,
    /// Skip them (counted in the summary).
    Ignore,
}

/// Why an input cannot be read at all.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error(
        "{path}: a directory without bytes.tsv or bytes.tsv.gz (expected an eyebot-hil --record directory)"
    )]
    NotARecording { path: PathBuf },
    #[error(
        "{path}: cannot tell the timestamp form: lines {first} and {second} disagree ({a} vs {b}) and neither form has a majority in the first {DETECT_LINES} data lines"
    )]
    MixedTimestamps {
        path: PathBuf,
        first: u64,
        second: u64,
        a: TimestampForm,
        b: TimestampForm,
    },
}

/// A physical line read ahead during detection.
struct Physical {
    line_no: u64,
    bytes: Vec<u8>,
    total: usize,
    terminator: Terminator,
}

/// The settings of a `#Serial:` comment (`None` when `text` is another comment).
fn serial_comment(text: &str) -> Option<Result<LineSettings, String>> {
    let payload = text.trim_start_matches('#').trim_start();
    let rest = payload
        .get(..7)
        .filter(|head| head.eq_ignore_ascii_case("serial:"))
        .and_then(|_| payload.get(7..))?;
    Some(
        rest.trim()
            .parse::<LineSettings>()
            .map_err(|e| e.to_string()),
    )
}

/// One opened input, yielding [`Event`]s in file order.
///
/// Every physical line read ends up in exactly one of its counters or events: a blank line
/// ([`Self::blank_lines`]), a `#` comment ([`Self::comment_lines`], [`Self::serial_lines`]), a
/// line that cannot be placed (an [`Event::Problem`] with [`Action::Dropped`], counted in
/// [`Self::unplaceable_lines`]), or an [`Event::Line`]; for recordings, a skipped select/ack
/// line ([`Self::link_messages_skipped`]) and the chunks of other links or directions
/// ([`Self::other_chunks`]).
pub struct Source {
    reader: Box<dyn BufRead + Send>,
    file: Arc<Path>,
    input: usize,
    format: Format,
    gzip: bool,
    regular: bool,
    comments: CommentMode,
    line_no: u64,
    lookahead: VecDeque<Physical>,
    last_time_ns: Option<i64>,
    /// Recording inputs: the link whose `tx` bytes are replayed, and the pending partial line.
    link: String,
    pending: Vec<u8>,
    pending_start: Option<(Loc, i64)>,
    pending_total: usize,
    done: bool,
    buf: Vec<u8>,
    queue: VecDeque<Event>,
    /// Recording inputs: select/ack lines of the sonar link skipped.
    pub link_messages_skipped: u64,
    /// Recording inputs: chunk lines of other links or of the `rx` direction, and the header.
    pub other_chunks: u64,
    /// Blank lines skipped.
    pub blank_lines: u64,
    /// `#` comment lines other than `#Serial:`, whatever `--comments` does with them.
    pub comment_lines: u64,
    /// `#Serial:` comment lines, valid or not.
    pub serial_lines: u64,
    /// Lines dropped before validation: a bad timestamp, a bad `bytes.tsv` line.
    pub unplaceable_lines: u64,
    /// The input ended with a read error (a truncated gzip, a vanished device): reported as a
    /// [`ProblemKind::ReadFailed`] problem at the line where it happened.
    pub cut_short: bool,
}

impl fmt::Debug for Source {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Source")
            .field("file", &self.file)
            .field("format", &self.format)
            .field("line_no", &self.line_no)
            .finish_non_exhaustive()
    }
}

impl Source {
    /// Opens input number `input` and detects its format. `link` names the recorded link
    /// replayed from recordings. `count` accumulates bytes read from disk.
    pub fn open(
        path: &Path,
        input: usize,
        link: &str,
        comments: CommentMode,
        count: Arc<AtomicU64>,
    ) -> Result<Self, InputError> {
        Self::open_until(path, input, link, comments, count, &Shutdown::new())
    }

    /// [`Self::open`], with reads of pipes, FIFOs and devices ended by `stop`.
    pub fn open_until(
        path: &Path,
        input: usize,
        link: &str,
        comments: CommentMode,
        count: Arc<AtomicU64>,
        stop: &Shutdown,
    ) -> Result<Self, InputError> {
        let file_path = resolve_path(path)?;
        let (reader, gzip, regular) = open_reader(&file_path, count, stop)?;
        Self::with_reader(&file_path, reader, gzip, regular, input, link, comments)
    }

    /// An input read from `raw` (decompressed when it is gzip), named `name` in reports:
    /// what fuzzing and tests feed without a file.
    pub fn from_reader(
        name: &Path,
        raw: Box<dyn Read + Send>,
        link: &str,
        comments: CommentMode,
    ) -> Result<Self, InputError> {
        let (reader, gzip) =
            decompressing(raw, Arc::default()).map_err(|source| InputError::Io {
                path: name.to_path_buf(),
                source,
            })?;
        Self::with_reader(name, reader, gzip, false, 0, link, comments)
    }

    fn with_reader(
        file_path: &Path,
        reader: Box<dyn BufRead + Send>,
        gzip: bool,
        regular: bool,
        input: usize,
        link: &str,
        comments: CommentMode,
    ) -> Result<Self, InputError> {
        let mut source = Source {
            reader,
            file: Arc::from(file_path),
            input,
            format: Format::Nmea {
                timestamps: TimestampForm::None,
            },
            gzip,
            regular,
            comments,
            line_no: 0,
            lookahead: VecDeque::new(),
            last_time_ns: None,
            link: link.to_string(),
            pending: Vec::new(),
            pending_start: None,
            pending_total: 0,
            done: false,
            buf: Vec::new(),
            queue: VecDeque::new(),
            link_messages_skipped: 0,
            other_chunks: 0,
            blank_lines: 0,
            comment_lines: 0,
            serial_lines: 0,
            unplaceable_lines: 0,
            cut_short: false,
        };
        source.detect()?;
        Ok(source)
    }

    pub fn format(&self) -> Format {
        self.format
    }

    pub fn is_gzip(&self) -> bool {
        self.gzip
    }

    /// Whether the input is a regular file, which another pass can open again (a pipe, FIFO
    /// or standard input is read once).
    pub fn is_regular(&self) -> bool {
        self.regular
    }

    pub fn path(&self) -> &Path {
        &self.file
    }

    /// Physical lines read from the input so far (those read ahead for detection included).
    pub fn physical_lines(&self) -> u64 {
        self.line_no
    }

    /// The first `#Serial:` comment with valid settings before the first data line, among
    /// the lines read ahead for detection.
    pub fn header_serial(&self) -> Option<(LineSettings, Loc)> {
        for p in &self.lookahead {
            let trimmed = p.bytes.trim_ascii();
            if trimmed.first() != Some(&b'#') || p.total > MAX_PHYSICAL_LINE {
                return None;
            }
            if let Some(Ok(settings)) = serial_comment(&String::from_utf8_lossy(trimmed)) {
                return Some((settings, self.loc(p.line_no)));
            }
        }
        None
    }

    fn read_physical(&mut self) -> Result<Option<Physical>, io::Error> {
        if let Some(p) = self.lookahead.pop_front() {
            return Ok(Some(p));
        }
        self.read_fresh()
    }

    /// The next physical line from the reader itself (not the lookahead).
    fn read_fresh(&mut self) -> Result<Option<Physical>, io::Error> {
        let mut buf = std::mem::take(&mut self.buf);
        let got = read_capped(self.reader.as_mut(), &mut buf, MAX_PHYSICAL_LINE)?;
        let Some((total, terminator)) = got else {
            self.buf = buf;
            return Ok(None);
        };
        self.line_no += 1;
        Ok(Some(Physical {
            line_no: self.line_no,
            bytes: buf,
            total,
            terminator,
        }))
    }

    /// Reads ahead until [`DETECT_LINES`] data lines have voted on the timestamp form, or
    /// [`DETECT_MAX_LOOKAHEAD`] comment and data lines are held, whichever comes first, so
    /// memory stays bounded whatever the head of the file holds. Blank lines are counted as
    /// they are read and not held.
    fn detect(&mut self) -> Result<(), InputError> {
        let mut votes = Vec::new();
        let mut data_lines = 0;
        while data_lines < DETECT_LINES && self.lookahead.len() < DETECT_MAX_LOOKAHEAD {
            let p = match self.read_fresh() {
                Ok(Some(p)) => p,
                Ok(None) => break,
                // Detection reads what it can; the error is reported where it happened.
                Err(e) => {
                    self.fail(e);
                    break;
                }
            };
            if p.line_no == 1 && p.bytes == BYTES_HEADER.as_bytes() {
                self.format = Format::Recording;
                self.other_chunks += 1;
                return Ok(());
            }
            let trimmed = p.bytes.trim_ascii();
            if trimmed.is_empty() && p.total <= MAX_PHYSICAL_LINE {
                self.blank_lines += 1;
                self.buf = p.bytes;
                continue;
            }
            if trimmed[0] != b'#' {
                data_lines += 1;
                if let Some(form) = classify(trimmed) {
                    votes.push((p.line_no, form));
                }
            }
            self.lookahead.push_back(p);
        }
        self.format = Format::Nmea {
            timestamps: decide_form(&self.file, &votes)?,
        };
        Ok(())
    }

    /// Ends the input after a read error, reporting it at the line being read.
    fn fail(&mut self, e: io::Error) {
        self.cut_short = true;
        self.done = true;
        let loc = self.loc(self.line_no + 1);
        self.queue.push_back(Event::Problem(Problem {
            loc,
            kind: ProblemKind::ReadFailed {
                reason: e.to_string(),
            },
            action: Action::InputEnded,
        }));
    }

    fn loc(&self, line: u64) -> Loc {
        Loc {
            file: self.file.clone(),
            line,
        }
    }

    /// The next event, or `None` at the end of the input. A read error after the input was
    /// opened ends it with a [`ProblemKind::ReadFailed`] problem (and [`Self::cut_short`]).
    pub fn next_event(&mut self) -> Result<Option<Event>, InputError> {
        loop {
            if let Some(e) = self.queue.pop_front() {
                return Ok(Some(e));
            }
            if self.done {
                return Ok(None);
            }
            let step = match self.format {
                Format::Recording => self.step_recording(),
                Format::Nmea { timestamps } => self.step_nmea(timestamps),
            };
            if let Err(e) = step {
                if self.format == Format::Recording {
                    self.flush_pending(Terminator::Eof);
                }
                self.fail(e);
            }
        }
    }

    fn comment(&mut self, loc: Loc, text: &[u8], terminator: Terminator) {
        let text = String::from_utf8_lossy(text).trim().to_string();
        if let Some(serial) = serial_comment(&text) {
            self.serial_lines += 1;
            match serial {
                Ok(settings) => self.queue.push_back(Event::Serial { loc, settings }),
                Err(reason) => self.queue.push_back(Event::Problem(Problem {
                    loc,
                    kind: ProblemKind::BadSerialComment { reason },
                    action: Action::Ignored,
                })),
            }
            return;
        }
        self.comment_lines += 1;
        match self.comments {
            CommentMode::Report => self.queue.push_back(Event::Comment { loc, text }),
            CommentMode::Ignore => {}
            CommentMode::Send => self.queue.push_back(Event::Line(LogLine {
                loc,
                input: self.input,
                time_ns: self.last_time_ns,
                bytes: text.into_bytes(),
                terminator,
                overflow: None,
                kind: LineKind::Comment,
            })),
        }
    }

    fn step_nmea(&mut self, form: TimestampForm) -> io::Result<()> {
        let Some(mut p) = self.read_physical()? else {
            self.done = true;
            return Ok(());
        };
        let terminator = p.terminator;
        let loc = self.loc(p.line_no);
        let overflow = (p.total > MAX_PHYSICAL_LINE).then_some(p.total);
        let trimmed = p.bytes.trim_ascii();
        if trimmed.is_empty() && overflow.is_none() {
            self.blank_lines += 1;
        } else if trimmed.first() == Some(&b'#') && overflow.is_none() {
            let text = trimmed.to_vec();
            self.comment(loc, &text, terminator);
        } else if form == TimestampForm::None {
            let bytes = std::mem::take(&mut p.bytes);
            self.push_data(loc, None, bytes, terminator, overflow);
        } else {
            let parsed = split_prefix(&p.bytes).and_then(|(prefix, rest)| {
                let t = match form {
                    TimestampForm::Seconds => parse_seconds(prefix),
                    _ => parse_iso8601(prefix),
                }?;
                Some((t, rest.to_vec()))
            });
            match parsed {
                Some((time_ns, bytes)) => {
                    self.check_time(&loc, time_ns);
                    self.push_data(loc, Some(time_ns), bytes, terminator, overflow);
                }
                None => {
                    let shown = p.bytes.iter().take(24).copied().collect::<Vec<u8>>();
                    self.unplaceable_lines += 1;
                    self.queue.push_back(Event::Problem(Problem {
                        loc,
                        kind: ProblemKind::BadTimestamp {
                            expected: form,
                            found: String::from_utf8_lossy(&shown).escape_debug().to_string(),
                        },
                        action: Action::Dropped,
                    }));
                }
            }
        }
        self.buf = p.bytes;
        Ok(())
    }

    /// Queues a data line of this input.
    fn push_data(
        &mut self,
        loc: Loc,
        time_ns: Option<i64>,
        bytes: Vec<u8>,
        terminator: Terminator,
        overflow: Option<usize>,
    ) {
        self.queue.push_back(Event::Line(LogLine {
            loc,
            input: self.input,
            time_ns,
            bytes,
            terminator,
            overflow,
            kind: LineKind::Data,
        }));
    }

    /// Notes a line's time; a time earlier than the latest so far is reported. The difference
    /// of two valid times can exceed `i64` nanoseconds (ISO dates centuries apart), so it is
    /// taken as an unsigned distance.
    fn check_time(&mut self, loc: &Loc, time_ns: i64) {
        if let Some(last) = self.last_time_ns
            && time_ns < last
        {
            self.queue.push_back(Event::Problem(Problem {
                loc: loc.clone(),
                kind: ProblemKind::TimeWentBack {
                    by_s: last.abs_diff(time_ns) as f64 * 1e-9,
                },
                action: Action::SentInFileOrder,
            }));
        }
        self.last_time_ns = Some(self.last_time_ns.map_or(time_ns, |l| l.max(time_ns)));
    }
}

#[cfg(test)]
mod tests;

/// Hostile inputs: each case here once cost unbounded memory, lost lines or overflowed.
#[cfg(test)]
mod hostile;
