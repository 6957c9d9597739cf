//! Opening an input: a file, a `--record` directory, standard input, a pipe or FIFO read
//! without blocking shutdown, gzip by its magic bytes; and reading it one capped physical line
//! at a time.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use super::super::output::Shutdown;
use super::{InputError, Terminator};

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
pub(super) fn decompressing(
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
