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

use std::collections::VecDeque;
use std::fmt;
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::record::{BYTES_HEADER, Direction, parse_chunk};
use crate::transport::LineSettings;

use super::output::Shutdown;

pub use super::line::{Loc, MAX_PHYSICAL_LINE, Terminator, TimestampForm};
use super::problem::{Action, Problem, ProblemKind};

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

/// Counts bytes read from the file (compressed bytes for gzip), for the progress bar.
struct Counting<R> {
    inner: R,
    count: Arc<AtomicU64>,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }
}

/// The path that means standard input.
pub const STDIN: &str = "-";

/// Whether `path` is [`STDIN`].
pub fn is_stdin(path: &Path) -> bool {
    path.as_os_str() == STDIN
}

/// The file to read for `path`: itself, or the `bytes.tsv` of a recording directory.
pub fn resolve_path(path: &Path) -> Result<PathBuf, InputError> {
    if is_stdin(path) {
        return Ok(path.to_path_buf());
    }
    let meta = std::fs::metadata(path).map_err(|source| InputError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if !meta.is_dir() {
        return Ok(path.to_path_buf());
    }
    ["bytes.tsv", "bytes.tsv.gz"]
        .iter()
        .map(|name| path.join(name))
        .find(|p| p.is_file())
        .ok_or_else(|| InputError::NotARecording {
            path: path.to_path_buf(),
        })
}

/// How long a read of a pipe, FIFO or device waits before it looks at the shutdown flag again.
const POLL_MS: u16 = 100;

/// A pipe, FIFO, terminal or device read without blocking the process: the descriptor is
/// non-blocking and each read waits in `poll` for at most [`POLL_MS`] at a time, so a
/// shutdown request ends a read that would otherwise wait forever (a FIFO whose writer never
/// comes). The descriptor's flags are restored on drop (standard input is shared).
struct PollRead {
    file: File,
    stop: Shutdown,
    old_flags: Option<nix::fcntl::OFlag>,
}

impl PollRead {
    fn new(file: File, stop: Shutdown) -> io::Result<Self> {
        use nix::fcntl::{FcntlArg, OFlag, fcntl};
        let old =
            OFlag::from_bits_truncate(fcntl(&file, FcntlArg::F_GETFL).map_err(io::Error::from)?);
        fcntl(&file, FcntlArg::F_SETFL(old | OFlag::O_NONBLOCK)).map_err(io::Error::from)?;
        Ok(Self {
            file,
            stop,
            old_flags: Some(old),
        })
    }
}

impl Drop for PollRead {
    fn drop(&mut self) {
        if let Some(old) = self.old_flags.take() {
            let _ = nix::fcntl::fcntl(&self.file, nix::fcntl::FcntlArg::F_SETFL(old));
        }
    }
}

impl Read for PollRead {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        use nix::poll::{PollFd, PollFlags, poll};
        use std::os::fd::AsFd;
        loop {
            if self.stop.is_triggered() {
                return Err(io::Error::other("stopped by a shutdown request"));
            }
            // Wait for data or the writer's close first: a FIFO that never had a writer
            // reads as end of file, but polls as not ready until a writer comes and goes.
            let mut fds = [PollFd::new(self.file.as_fd(), PollFlags::POLLIN)];
            match poll(&mut fds, POLL_MS) {
                Ok(0) => continue,
                Ok(_) => {}
                Err(nix::errno::Errno::EINTR) => continue,
                Err(e) => return Err(e.into()),
            }
            match self.file.read(buf) {
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
                    ) => {}
                other => return other,
            }
        }
    }
}

/// Opens `path` (or standard input for [`STDIN`]) for reading, once. Regular files are read
/// as they are; anything else (pipe, FIFO, terminal, device) through [`PollRead`], so neither
/// the open nor a read ignores `stop`. Returns the reader and whether it is a regular file.
fn open_raw(path: &Path, stop: &Shutdown) -> io::Result<(Box<dyn Read + Send>, bool)> {
    use std::os::unix::fs::OpenOptionsExt;
    let file = if is_stdin(path) {
        use std::os::fd::AsFd;
        File::from(io::stdin().as_fd().try_clone_to_owned()?)
    } else {
        // Non-blocking so that opening a FIFO does not wait for its writer.
        std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path)?
    };
    let kind = file.metadata()?.file_type();
    if kind.is_file() {
        return Ok((Box::new(file), true));
    }
    if kind.is_dir() {
        return Err(io::Error::other("a directory, expected a log file"));
    }
    Ok((Box::new(PollRead::new(file, stop.clone())?), false))
}

/// Opens `path` for reading, decompressing when it starts with the gzip magic `1f 8b`.
/// Returns the reader, whether it was gzip and whether it is a regular file (which can be
/// opened again for another pass; a pipe or FIFO is read once).
pub fn open_reader(
    path: &Path,
    count: Arc<AtomicU64>,
    stop: &Shutdown,
) -> Result<(Box<dyn BufRead + Send>, bool, bool), InputError> {
    let io_err = |source| InputError::Io {
        path: path.to_path_buf(),
        source,
    };
    let (inner, regular) = open_raw(path, stop).map_err(io_err)?;
    let (reader, gzip) = decompressing(inner, count).map_err(io_err)?;
    Ok((reader, gzip, regular))
}

/// `inner` as a buffered reader, decompressed when it starts with the gzip magic `1f 8b`;
/// `count` accumulates the bytes read from `inner`. Returns the reader and whether it is gzip.
fn decompressing(
    inner: Box<dyn Read + Send>,
    count: Arc<AtomicU64>,
) -> io::Result<(Box<dyn BufRead + Send>, bool)> {
    let mut reader = BufReader::with_capacity(64 * 1024, Counting { inner, count });
    let magic = reader.fill_buf()?;
    if magic.starts_with(&[0x1f, 0x8b]) {
        let gz = flate2::bufread::MultiGzDecoder::new(reader);
        Ok((Box::new(BufReader::with_capacity(64 * 1024, gz)), true))
    } else {
        Ok((Box::new(reader), false))
    }
}

/// Reads one physical line into `buf` (cleared first, terminator not stored), keeping at most
/// `cap` bytes. A line ends at LF, at CR LF, or at a CR not followed by LF (old Mac-style
/// logs). Returns `None` at end of input, else the line's full length (without terminator) and
/// how it ended.
pub fn read_capped(
    reader: &mut dyn BufRead,
    buf: &mut Vec<u8>,
    cap: usize,
) -> io::Result<Option<(usize, Terminator)>> {
    fn fill(reader: &mut dyn BufRead) -> io::Result<&[u8]> {
        while let Err(e) = reader.fill_buf() {
            if e.kind() != io::ErrorKind::Interrupted {
                return Err(e);
            }
        }
        reader.fill_buf()
    }
    buf.clear();
    let mut total = 0usize;
    loop {
        let available = fill(reader)?;
        if available.is_empty() {
            return Ok((total > 0).then_some((total, Terminator::Eof)));
        }
        let end = available.iter().position(|&b| b == b'\n' || b == b'\r');
        let take = end.unwrap_or(available.len());
        let keep = take.min(cap.saturating_sub(buf.len()));
        buf.extend_from_slice(&available[..keep]);
        total += take;
        let Some(at) = end else {
            reader.consume(take);
            continue;
        };
        let was_cr = available[at] == b'\r';
        reader.consume(take + 1);
        if !was_cr {
            return Ok(Some((total, Terminator::Lf)));
        }
        // A CR: the line ends here; a LF right after it belongs to the same ending.
        let next = fill(reader)?;
        if next.first() == Some(&b'\n') {
            reader.consume(1);
            return Ok(Some((total, Terminator::CrLf)));
        }
        return Ok(Some((total, Terminator::Cr)));
    }
}

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
fn split_prefix(line: &[u8]) -> Option<(&str, &[u8])> {
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

    fn step_recording(&mut self) -> io::Result<()> {
        let Some(p) = self.read_physical()? else {
            self.done = true;
            self.flush_pending(Terminator::Eof);
            return Ok(());
        };
        let loc = self.loc(p.line_no);
        let text = String::from_utf8_lossy(&p.bytes).into_owned();
        self.buf = p.bytes;
        if text.trim().is_empty() && p.total <= MAX_PHYSICAL_LINE {
            self.blank_lines += 1;
            return Ok(());
        }
        let chunk = match parse_chunk(&text, loc.line as usize) {
            Ok(c) if p.total <= MAX_PHYSICAL_LINE => c,
            Ok(_) => {
                self.unplaceable_lines += 1;
                self.queue.push_back(Event::Problem(Problem {
                    loc,
                    kind: ProblemKind::BadRecordLine {
                        reason: format!("line of {} bytes is too long", p.total),
                    },
                    action: Action::Dropped,
                }));
                return Ok(());
            }
            Err(e) => {
                self.unplaceable_lines += 1;
                self.queue.push_back(Event::Problem(Problem {
                    loc,
                    kind: ProblemKind::BadRecordLine { reason: e.reason },
                    action: Action::Dropped,
                }));
                return Ok(());
            }
        };
        if chunk.dir != Direction::Tx || chunk.link != self.link {
            self.other_chunks += 1;
            return Ok(());
        }
        let time_ns = (chunk.sim_s * 1e9).round() as i64;
        for &b in &chunk.data {
            if self.pending_start.is_none() {
                self.pending_start = Some((loc.clone(), time_ns));
            }
            if b == b'\n' {
                let terminator = if self.pending.last() == Some(&b'\r') {
                    self.pending.pop();
                    Terminator::CrLf
                } else {
                    Terminator::Lf
                };
                self.flush_pending(terminator);
            } else {
                if self.pending.len() < MAX_PHYSICAL_LINE {
                    self.pending.push(b);
                }
                self.pending_total += 1;
            }
        }
        Ok(())
    }

    fn flush_pending(&mut self, terminator: Terminator) {
        let Some((loc, time_ns)) = self.pending_start.take() else {
            return;
        };
        let total = std::mem::take(&mut self.pending_total);
        let bytes = std::mem::take(&mut self.pending);
        if bytes.first() == Some(&b'@') && total <= MAX_PHYSICAL_LINE {
            self.link_messages_skipped += 1;
            return;
        }
        self.check_time(&loc, time_ns);
        let overflow = (total > MAX_PHYSICAL_LINE).then_some(total);
        self.push_data(loc, Some(time_ns), bytes, terminator, overflow);
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use super::*;

    fn events(path: &Path) -> (Format, Vec<Event>) {
        let mut s = Source::open(
            path,
            0,
            "sonar",
            CommentMode::Report,
            Arc::new(AtomicU64::new(0)),
        )
        .unwrap();
        let mut out = Vec::new();
        while let Some(e) = s.next_event().unwrap() {
            out.push(e);
        }
        (s.format(), out)
    }

    fn lines(events: &[Event]) -> Vec<(Option<i64>, Vec<u8>, Terminator)> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Line(l) => Some((l.time_ns, l.bytes.clone(), l.terminator)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn seconds_iso_and_plain_forms_are_told_apart() {
        assert_eq!(classify(b"$SDDBT,1*00"), Some(TimestampForm::None));
        assert_eq!(
            classify(b"12.250 $SDDBT,1*00"),
            Some(TimestampForm::Seconds)
        );
        assert_eq!(
            classify(b"1714564800\t$SDDBT"),
            Some(TimestampForm::Seconds)
        );
        assert_eq!(
            classify(b"2024-05-01T12:00:00.250Z $SDDBT"),
            Some(TimestampForm::Iso8601)
        );
        assert_eq!(
            classify(b"2024-05-01T12:00:00+02:00  $SDDBT"),
            Some(TimestampForm::Iso8601)
        );
        assert_eq!(
            classify(b"2024-05-01T12:00:00.5 $SDDBT"),
            Some(TimestampForm::Iso8601)
        );
        // Junk does not vote; a prefix without a following sentence is not a timestamp.
        assert_eq!(classify(b"\x00\x01garbage"), None);
        assert_eq!(classify(b"12.5 hello"), None);
        assert_eq!(classify(b"1.2.3 $SDDBT"), None);
        assert_eq!(classify(b"-5 $SDDBT"), None);
    }

    #[test]
    fn iso_times_become_unix_nanoseconds() {
        assert_eq!(parse_iso8601("1970-01-01T00:00:01.5Z"), Some(1_500_000_000));
        assert_eq!(parse_iso8601("1970-01-01T01:00:00+01:00"), Some(0));
        assert_eq!(parse_iso8601("1970-01-01T00:00:02"), Some(2_000_000_000));
        assert_eq!(parse_iso8601("1970-01-01"), None);
        assert_eq!(parse_seconds("0.001"), Some(1_000_000));
    }

    #[test]
    fn majority_of_first_lines_decides_and_ties_are_errors() {
        let p = Path::new("log");
        let s = TimestampForm::Seconds;
        let n = TimestampForm::None;
        assert_eq!(decide_form(p, &[(1, s), (2, n), (3, s)]).unwrap(), s);
        assert_eq!(decide_form(p, &[]).unwrap(), n);
        let err = decide_form(p, &[(4, s), (9, n)]).unwrap_err();
        assert!(err.to_string().contains("lines 9 and 4"), "{err}");
    }

    #[test]
    fn timestamped_log_with_comments_lf_and_junk() {
        let tmp = crate::scratch::dir("timed");
        let dir = tmp.path();
        let path = dir.join("a.log");
        std::fs::write(
            &path,
            b"#Serial: 9600 8N1\n# a note\n0.5 $SDDBT,1*00\r\n\n1.25\t$SDDBT,2*00\nnot-a-time $SDDBT,3*00\n\x01\x02junk\n2 $SDDBT,4*00",
        )
        .unwrap();
        let (format, ev) = events(&path);
        assert_eq!(
            format,
            Format::Nmea {
                timestamps: TimestampForm::Seconds
            }
        );
        assert!(
            matches!(&ev[0], Event::Serial { settings, loc } if settings.baud == 9600 && loc.line == 1)
        );
        assert!(matches!(&ev[1], Event::Comment { text, .. } if text == "# a note"));
        let l = lines(&ev);
        assert_eq!(
            l,
            vec![
                (Some(500_000_000), b"$SDDBT,1*00".to_vec(), Terminator::CrLf),
                (Some(1_250_000_000), b"$SDDBT,2*00".to_vec(), Terminator::Lf),
                (
                    Some(2_000_000_000),
                    b"$SDDBT,4*00".to_vec(),
                    Terminator::Eof
                ),
            ]
        );
        let bad: Vec<u64> = ev
            .iter()
            .filter_map(|e| match e {
                Event::Problem(p) => Some(p.loc.line),
                _ => None,
            })
            .collect();
        assert_eq!(bad, vec![6, 7], "the untimed line and the junk line");
    }

    #[test]
    fn gzip_is_detected_by_magic_not_extension() {
        let tmp = crate::scratch::dir("gzip");
        let dir = tmp.path();
        let plain = b"$SDDBT,1*00\r\n$SDDBT,2*00\r\n";
        let path = dir.join("log.txt"); // no .gz extension
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(plain).unwrap();
        std::fs::write(&path, enc.finish().unwrap()).unwrap();
        let count = Arc::new(AtomicU64::new(0));
        let mut s = Source::open(&path, 0, "sonar", CommentMode::Report, count.clone()).unwrap();
        assert!(s.is_gzip());
        let mut got = Vec::new();
        while let Some(Event::Line(l)) = s.next_event().unwrap() {
            got.push(l.bytes);
        }
        assert_eq!(got, vec![b"$SDDBT,1*00".to_vec(), b"$SDDBT,2*00".to_vec()]);
        assert_eq!(
            count.load(Ordering::Relaxed),
            std::fs::metadata(&path).unwrap().len(),
            "progress counts compressed bytes read from disk"
        );
        // A .gz name on a plain file is read as plain text.
        let fake = dir.join("plain.gz");
        std::fs::write(&fake, plain).unwrap();
        let (_, ev) = events(&fake);
        assert_eq!(lines(&ev).len(), 2);
    }

    #[test]
    fn recorded_sentences_are_reassembled_across_chunks() {
        let tmp = crate::scratch::dir("record");
        let dir = tmp.path();
        let rec = dir.join("run1");
        std::fs::create_dir_all(&rec).unwrap();
        let sentence = b"$SDDBT,6.6,f,2.0,M,1.1,F*3A\r\n";
        let mut tsv = format!("{BYTES_HEADER}\n");
        // Split the first sentence over three chunks, interleave other traffic.
        let parts: [&[u8]; 3] = [&sentence[..5], &sentence[5..20], &sentence[20..]];
        tsv += &format!("1.000000000\t0\tsonar\ttx\t{}\n", hex::encode(parts[0]));
        tsv += &format!("1.001000000\t0\tsonar\trx\t{}\n", hex::encode(b"@S1\r"));
        tsv += &format!("1.002000000\t0\tsensor\ttx\t{}\n", hex::encode([0xEB, 1]));
        tsv += &format!("1.003000000\t0\tsonar\ttx\t{}\n", hex::encode(parts[1]));
        tsv += &format!(
            "1.004000000\t0\tsonar\ttx\t{}{}\n",
            hex::encode(parts[2]),
            hex::encode(b"@A1\r\n$SD")
        );
        tsv += "garbage line\n";
        tsv += &format!("2.5\t0\tsonar\ttx\t{}\n", hex::encode(&sentence[3..]));
        std::fs::write(rec.join("bytes.tsv"), tsv).unwrap();
        let mut s = Source::open(
            &rec,
            0,
            "sonar",
            CommentMode::Report,
            Arc::new(AtomicU64::new(0)),
        )
        .unwrap();
        assert_eq!(s.format(), Format::Recording);
        let mut ev = Vec::new();
        while let Some(e) = s.next_event().unwrap() {
            ev.push(e);
        }
        let l = lines(&ev);
        assert_eq!(l.len(), 2);
        assert_eq!(l[0].0, Some(1_000_000_000), "time of the first byte");
        assert_eq!(l[0].1, &sentence[..sentence.len() - 2]);
        assert_eq!(l[0].2, Terminator::CrLf);
        assert_eq!(l[1].1, &sentence[..sentence.len() - 2], "split at $SD");
        assert_eq!(l[1].0, Some(1_004_000_000));
        assert_eq!(s.link_messages_skipped, 1, "the @A1 ack");
        assert!(ev.iter().any(
            |e| matches!(e, Event::Problem(p) if p.loc.line == 7 && matches!(p.kind, ProblemKind::BadRecordLine { .. }))
        ));
    }

    #[test]
    fn a_line_without_line_feeds_is_cut_at_the_cap() {
        let tmp = crate::scratch::dir("cap");
        let dir = tmp.path();
        let path = dir.join("junk.log");
        let mut data = vec![0xFFu8; 3 * MAX_PHYSICAL_LINE];
        data.extend_from_slice(b"\n$SDDBT,1*00\r\n");
        std::fs::write(&path, data).unwrap();
        let (_, ev) = events(&path);
        match &ev[0] {
            Event::Line(l) => {
                assert_eq!(l.bytes.len(), MAX_PHYSICAL_LINE);
                assert_eq!(l.overflow, Some(3 * MAX_PHYSICAL_LINE));
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(&ev[1], Event::Line(l) if l.bytes == b"$SDDBT,1*00" && l.loc.line == 2));
    }
}

/// Hostile inputs: each case here once cost unbounded memory, lost lines or overflowed.
#[cfg(test)]
mod hostile {
    use std::io::Write;

    use super::*;

    fn from_bytes(data: Vec<u8>) -> Source {
        Source::from_reader(
            Path::new("mem.log"),
            Box::new(io::Cursor::new(data)),
            "sonar",
            CommentMode::Report,
        )
        .unwrap()
    }

    fn drain(s: &mut Source) -> Vec<Event> {
        let mut out = Vec::new();
        while let Some(e) = s.next_event().unwrap() {
            out.push(e);
        }
        out
    }

    /// Format detection holds at most [`DETECT_MAX_LOOKAHEAD`] lines, whatever precedes the
    /// first data lines: blank lines are counted, not held; comments stop being held at the cap.
    #[test]
    fn blank_and_comment_bombs_do_not_fill_the_lookahead() {
        let mut data = b"\n".repeat(200_000);
        data.extend(b"  \r\n".repeat(1000));
        let mut s = from_bytes(data.clone());
        assert!(s.lookahead.is_empty(), "blank lines are not held");
        assert_eq!(s.blank_lines, 201_000);
        let ev = drain(&mut s);
        assert!(ev.is_empty());

        let mut data = b"# note\n".repeat(50_000);
        data.extend_from_slice(b"1.0 $A*41\r\n");
        let mut s = from_bytes(data);
        assert_eq!(s.lookahead.len(), DETECT_MAX_LOOKAHEAD);
        let ev = drain(&mut s);
        assert_eq!(s.comment_lines, 50_000);
        assert_eq!(s.physical_lines(), 50_001);
        // Detection saw no data line; the form is decided on what it had (none).
        assert!(matches!(ev.last(), Some(Event::Line(l)) if l.bytes == b"1.0 $A*41"));
    }

    /// A CR alone ends a line (old Mac-style logs); CR LF stays one ending; a CR at the end of
    /// a read buffer is paired with the LF at the start of the next.
    #[test]
    fn cr_only_line_endings_split_lines() {
        let mut s = from_bytes(b"$A*41\r$B*42\r\r\n$C*43\r".to_vec());
        let got: Vec<(Vec<u8>, Terminator)> = drain(&mut s)
            .into_iter()
            .filter_map(|e| match e {
                Event::Line(l) => Some((l.bytes, l.terminator)),
                _ => None,
            })
            .collect();
        assert_eq!(
            got,
            vec![
                (b"$A*41".to_vec(), Terminator::Cr),
                (b"$B*42".to_vec(), Terminator::Cr),
                (b"$C*43".to_vec(), Terminator::Cr),
            ]
        );
        assert_eq!(s.blank_lines, 1, "the CR LF after $B's CR is an empty line");
        // CR and LF in separate reads.
        let data = [&b"$A*41\r"[..], &b"\n$B*42\r\n"[..]].concat();
        let mut r = io::BufReader::with_capacity(6, &data[..]);
        let mut buf = Vec::new();
        assert_eq!(
            read_capped(&mut r, &mut buf, 100).unwrap(),
            Some((5, Terminator::CrLf))
        );
        assert_eq!(
            read_capped(&mut r, &mut buf, 100).unwrap(),
            Some((5, Terminator::CrLf))
        );
        assert_eq!(read_capped(&mut r, &mut buf, 100).unwrap(), None);
    }

    /// A truncated gzip yields every line before the cut, then an `input cut short` problem at
    /// the line being read, and no error: the replay goes on to its summary.
    #[test]
    fn a_truncated_gzip_reports_where_it_ended() {
        let text: String = (0..2000).map(|i| format!("$GPXXX,{i}*00\r\n")).collect();
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(text.as_bytes()).unwrap();
        let mut gz = enc.finish().unwrap();
        gz.truncate(gz.len() / 2);
        let mut s = from_bytes(gz);
        assert!(s.is_gzip());
        let ev = drain(&mut s);
        assert!(s.cut_short);
        let lines = ev.iter().filter(|e| matches!(e, Event::Line(_))).count() as u64;
        assert!(lines > 100 && lines < 2000, "{lines}");
        match ev.last() {
            Some(Event::Problem(p)) => {
                assert!(matches!(p.kind, ProblemKind::ReadFailed { .. }), "{p}");
                assert_eq!(p.action, Action::InputEnded);
                assert!(p.loc.line > lines, "{} after {lines} lines", p.loc);
                assert!(p.to_string().starts_with("mem.log:"), "{p}");
            }
            other => panic!("{other:?}"),
        }
    }

    /// ISO 8601 times centuries apart differ by more than i64 nanoseconds hold.
    #[test]
    fn times_far_apart_do_not_overflow() {
        let mut s =
            from_bytes(b"2262-04-11T00:00:00Z $A*41\r\n1677-09-22T00:00:00Z $A*41\r\n".to_vec());
        let ev = drain(&mut s);
        let back = ev
            .iter()
            .find_map(|e| match e {
                Event::Problem(Problem {
                    kind: ProblemKind::TimeWentBack { by_s },
                    ..
                }) => Some(*by_s),
                _ => None,
            })
            .expect("time went back");
        let years = back / (365.25 * 86400.0);
        assert!((584.0..585.0).contains(&years), "{back} s = {years} years");
    }

    /// Every physical line lands in exactly one counter or event.
    #[test]
    fn every_line_is_accounted_for_once() {
        let data =
            b"#Serial: 9600 8N1\n# c\n\n1.0 $A*41\r\nbad $A*41\r\n2.0 $B*42\r\n\n#x\nxx\n3 $C"
                .to_vec();
        let mut s = from_bytes(data);
        let ev = drain(&mut s);
        let lines = ev.iter().filter(|e| matches!(e, Event::Line(_))).count() as u64;
        assert_eq!(s.unplaceable_lines, 2, "`bad` and `xx` have no timestamp");
        assert_eq!(s.comment_lines, 2);
        assert_eq!(s.serial_lines, 1);
        assert_eq!(s.blank_lines, 2);
        assert_eq!(lines, 3);
        assert_eq!(
            s.physical_lines(),
            lines + s.unplaceable_lines + s.comment_lines + s.serial_lines + s.blank_lines
        );
    }

    /// A FIFO is opened without waiting for its writer and read once; a read waiting for a
    /// writer that never comes ends on the shutdown flag.
    #[test]
    fn a_fifo_without_writer_gives_way_to_shutdown() {
        let tmp = crate::scratch::dir("fifo");
        let fifo = tmp.path().join("log.fifo");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let stop = Shutdown::new();
        let (tx, rx) = std::sync::mpsc::channel();
        let (path, s2) = (fifo.clone(), stop.clone());
        std::thread::spawn(move || {
            let r = Source::open_until(&path, 0, "sonar", CommentMode::Report, Arc::default(), &s2);
            let _ = tx.send(r.map(|_| ()).map_err(|e| e.to_string()));
        });
        std::thread::sleep(std::time::Duration::from_millis(300));
        assert!(rx.try_recv().is_err(), "still waiting for the writer");
        stop.trigger();
        let r = rx
            .recv_timeout(std::time::Duration::from_secs(2))
            .expect("open gave way to the shutdown flag");
        let err = r.unwrap_err();
        assert!(
            err.contains("log.fifo") && err.contains("shutdown"),
            "{err}"
        );
    }
}
