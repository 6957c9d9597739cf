//! `--record DIR`: every byte on every link, and the ground-truth vehicle state.
//!
//! The files and their serde types are in [`format`](mod@format) (specified in
//! `docs/recording.md`); `replay`, `gap convert` and the test harness read them through its
//! readers. In short:
//!
//! - `meta.toml` ([`Meta`]): what produced the recording (format, version, seed, time mode).
//! - `config.toml`: the daemon configuration of the run, verbatim.
//! - `bytes.tsv` ([`ByteChunk`]): one row per chunk of bytes that crossed a link, in the
//!   order they crossed.
//! - `drops.tsv` ([`DropRow`]): bytes the bridge put on a line (so in `bytes.tsv` as `tx`)
//!   that never reached the endpoint.
//! - `state.csv` ([`StateRow`]): the vehicle's true state at a set rate (the same rows as
//!   `simulate`'s trace).
//!
//! Writes go to a dedicated thread through a bounded channel of [`QUEUE_MESSAGES`] messages
//! (each at most a few KiB: one read from a link, one release of paced bytes, one state
//! row). Nothing handed to the recorder is dropped: when the disk falls behind, the caller
//! waits (back-pressure: the bridge stops reading its links until the recorder catches up,
//! and the EyeBot's own writes block in the kernel), and each such wait is counted
//! ([`Stats::stalls`]). The thread flushes at least every [`FLUSH_INTERVAL`], so `kill -9`
//! loses at most that much; a clean shutdown (SIGINT/SIGTERM, [`Recorder::finish`]) flushes
//! and syncs everything.

pub mod format;

use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub use self::format::{
    BYTES_HEADER, ByteChunk, DROPS_HEADER, Direction, DropReason, DropRow, EVENTS_HEADER, EventRow,
    Meta, ModelFiles, ParseChunkError, ReadError, STATE_HEADER, StateRow, parse_chunk, read_bytes,
    read_config, read_drops, read_events, read_meta, read_model_files, read_state, read_state_file,
};

/// The longest a recorded chunk may wait in memory before it reaches the file.
pub const FLUSH_INTERVAL: Duration = Duration::from_millis(50);

/// Messages the recorder thread may have queued before a caller waits for it.
pub const QUEUE_MESSAGES: usize = 1024;

/// Why a recording could not be started or completed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("recording {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("recording {path}: {source}")]
    Csv {
        path: PathBuf,
        #[source]
        source: csv::Error,
    },
    #[error("recording {path}: {source}")]
    Meta {
        path: PathBuf,
        #[source]
        source: toml::ser::Error,
    },
    /// `--record` names a directory that already holds something: nothing is written there,
    /// so no earlier recording is lost.
    #[error(
        "recording {path}: the directory is not empty (it holds `{first}`{more}); a recording never writes over files: choose a new directory, or move its contents away"
    )]
    NotEmpty {
        path: PathBuf,
        first: String,
        /// `, and N more` when it holds more than one entry.
        more: String,
    },
    #[error("recorder thread stopped unexpectedly")]
    ThreadGone,
}

enum Message {
    Bytes(ByteChunk),
    Dropped(DropRow),
    State(StateRow),
    Event(EventRow),
    Finish,
}

/// Sends to the recorder thread, waiting (and counting the wait) when its queue is full.
#[derive(Debug, Clone)]
pub struct RecordHandle {
    tx: mpsc::SyncSender<Message>,
    stalls: Arc<AtomicU64>,
}

impl RecordHandle {
    fn send(&self, message: Message) -> bool {
        match self.tx.try_send(message) {
            Ok(()) => true,
            Err(mpsc::TrySendError::Full(message)) => {
                let stalls = self.stalls.fetch_add(1, Ordering::Relaxed);
                if stalls.is_power_of_two() || stalls == 0 {
                    tracing::warn!(
                        stalls = stalls + 1,
                        "the recorder is behind (slow disk?): the bridge waits for it"
                    );
                }
                self.tx.send(message).is_ok()
            }
            Err(mpsc::TrySendError::Disconnected(_)) => false,
        }
    }

    /// Records one ground-truth row (`state.csv`).
    pub fn state(&self, row: StateRow) {
        self.send_or_log(Message::State(row), "state");
    }

    /// Records bytes that crossed `link` at simulated time `sim_s` (`bytes.tsv`).
    pub fn bytes(&self, sim_s: f64, link: &'static str, dir: Direction, data: &[u8]) {
        if !data.is_empty() {
            let (wall_unix_s, link, data) = (wall_unix_s(), link.to_string(), data.to_vec());
            self.send_or_log(
                Message::Bytes(ByteChunk {
                    sim_s,
                    wall_unix_s,
                    link,
                    dir,
                    data,
                }),
                "bytes",
            );
        }
    }

    /// Records bytes put on `link` at simulated time `sim_s` that never reached the endpoint
    /// (`drops.tsv`).
    pub fn dropped(&self, sim_s: f64, link: &'static str, reason: DropReason, data: &[u8]) {
        if !data.is_empty() {
            let (wall_unix_s, link, data) = (wall_unix_s(), link.to_string(), data.to_vec());
            self.send_or_log(
                Message::Dropped(DropRow {
                    sim_s,
                    wall_unix_s,
                    link,
                    reason,
                    data,
                }),
                "drop",
            );
        }
    }

    /// Records a change made to the run at simulated time `sim_s` (`events.tsv`).
    pub fn event(&self, sim_s: f64, event: &str, detail: &str) {
        let row = EventRow {
            sim_s,
            wall_unix_s: wall_unix_s(),
            event: event.to_string(),
            detail: detail.to_string(),
        };
        self.send_or_log(Message::Event(row), "event");
    }

    fn send_or_log(&self, message: Message, what: &str) {
        if !self.send(message) {
            tracing::error!("recorder thread is gone; {what} not recorded");
        }
    }
}

/// Wall time for the `wall_unix_s` column only: it is recorded beside the simulated time,
/// never fed to the model.
fn wall_unix_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Handle to the recorder thread. Cheap to call from the simulation loop.
#[derive(Debug)]
pub struct Recorder {
    handle: RecordHandle,
    thread: Option<JoinHandle<Result<Stats, RecordError>>>,
    dir: PathBuf,
}

/// What a finished recording holds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    pub chunks: u64,
    pub bytes: u64,
    pub states: u64,
    /// Rows of `drops.tsv` and the bytes they hold.
    pub drops: u64,
    pub dropped_bytes: u64,
    /// How often a caller had to wait for the recorder (its queue was full).
    pub stalls: u64,
    /// Rows of `events.tsv`.
    pub events: u64,
}

/// One table of the recording and where it lives (for errors).
struct Table {
    writer: csv::Writer<File>,
    path: PathBuf,
}

impl Table {
    fn create(path: PathBuf, delimiter: u8, header: &str) -> Result<Self, RecordError> {
        let file = File::create(&path).map_err(|source| RecordError::Io {
            path: path.clone(),
            source,
        })?;
        let writer =
            format::table_writer(file, delimiter, header).map_err(|source| RecordError::Csv {
                path: path.clone(),
                source,
            })?;
        Ok(Self { writer, path })
    }

    fn write(&mut self, row: &impl serde::Serialize) -> Result<(), RecordError> {
        self.writer
            .serialize(row)
            .map_err(|source| RecordError::Csv {
                path: self.path.clone(),
                source,
            })
    }

    fn flush(&mut self) -> Result<(), RecordError> {
        self.writer.flush().map_err(|source| RecordError::Io {
            path: self.path.clone(),
            source,
        })
    }

    fn sync(&mut self) -> Result<(), RecordError> {
        self.flush()?;
        // A pipe or a character device (a live consumer) cannot be synced.
        match self.writer.get_ref().sync_all() {
            Err(e) if e.kind() == io::ErrorKind::InvalidInput => Ok(()),
            other => other.map_err(|source| RecordError::Io {
                path: self.path.clone(),
                source,
            }),
        }
    }
}

struct Files {
    bytes: Table,
    drops: Table,
    state: Table,
    events: Table,
}

impl Files {
    fn each(&mut self) -> [&mut Table; 4] {
        [
            &mut self.bytes,
            &mut self.drops,
            &mut self.state,
            &mut self.events,
        ]
    }
}

/// [`RecordError::NotEmpty`] when `dir` holds any entry (hidden ones too) but a named pipe:
/// a FIFO a reader made for one of the recording's files (`mkfifo DIR/bytes.tsv`, to follow
/// the bytes live) holds nothing that writing could lose.
fn refuse_non_empty(dir: &Path) -> Result<(), RecordError> {
    use std::os::unix::fs::FileTypeExt;
    let io_err = |source| RecordError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io_err)? {
        let entry = entry.map_err(io_err)?;
        if entry.file_type().map_err(io_err)?.is_fifo() {
            continue;
        }
        names.push(entry.file_name());
    }
    names.sort();
    let Some(first) = names.first() else {
        return Ok(());
    };
    Err(RecordError::NotEmpty {
        path: dir.to_path_buf(),
        first: first.to_string_lossy().into_owned(),
        more: match names.len() {
            1 => String::new(),
            n => format!(", and {} more", n - 1),
        },
    })
}

impl Recorder {
    /// Creates `dir` and its files, writes `meta.toml`, `config.toml` (the daemon
    /// configuration `config_toml`, verbatim) and the table headers, starts the thread.
    /// A `dir` that exists must be empty ([`RecordError::NotEmpty`] otherwise, with nothing
    /// written).
    pub fn start(dir: &Path, meta: &Meta, config_toml: &str) -> Result<Self, RecordError> {
        std::fs::create_dir_all(dir).map_err(|source| RecordError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        refuse_non_empty(dir)?;
        Self::start_in(dir, meta, config_toml)
    }

    /// [`Self::start`] in a directory that exists, whatever it holds: its files are
    /// created or truncated.
    fn start_in(dir: &Path, meta: &Meta, config_toml: &str) -> Result<Self, RecordError> {
        let io_err = |path: &Path| {
            let path = path.to_path_buf();
            move |source| RecordError::Io { path, source }
        };
        let meta_path = dir.join(format::META_FILE);
        let meta_text = toml::to_string(meta).map_err(|source| RecordError::Meta {
            path: meta_path.clone(),
            source,
        })?;
        std::fs::write(&meta_path, meta_text).map_err(io_err(&meta_path))?;
        let config_path = dir.join(format::CONFIG_FILE);
        std::fs::write(&config_path, config_toml).map_err(io_err(&config_path))?;
        let mut files = Files {
            bytes: Table::create(dir.join(format::BYTES_FILE), b'\t', BYTES_HEADER)?,
            drops: Table::create(dir.join(format::DROPS_FILE), b'\t', DROPS_HEADER)?,
            state: Table::create(dir.join(format::STATE_FILE), b',', STATE_HEADER)?,
            events: Table::create(dir.join(format::EVENTS_FILE), b'\t', EVENTS_HEADER)?,
        };
        for table in files.each() {
            table.flush()?;
        }
        let (tx, rx) = mpsc::sync_channel(QUEUE_MESSAGES);
        let stalls = Arc::new(AtomicU64::new(0));
        let thread_stalls = stalls.clone();
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || {
                write_loop(rx, files).map(|stats| Stats {
                    stalls: thread_stalls.load(Ordering::Relaxed),
                    ..stats
                })
            })
            .map_err(io_err(dir))?;
        Ok(Self {
            handle: RecordHandle { tx, stalls },
            thread: Some(thread),
            dir: dir.to_path_buf(),
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// A handle for other tasks (the link tasks record drops through it).
    pub fn handle(&self) -> RecordHandle {
        self.handle.clone()
    }

    /// How often a caller has waited for the recorder so far.
    pub fn stalls(&self) -> u64 {
        self.handle.stalls.load(Ordering::Relaxed)
    }

    /// Records bytes that crossed `link` at simulated time `sim_s`.
    pub fn bytes(&self, sim_s: f64, link: &'static str, dir: Direction, data: &[u8]) {
        self.handle.bytes(sim_s, link, dir, data);
    }

    /// Records bytes put on `link` that never reached the endpoint (`drops.tsv`).
    pub fn dropped(&self, sim_s: f64, link: &'static str, reason: DropReason, data: &[u8]) {
        self.handle.dropped(sim_s, link, reason, data);
    }

    /// Records a change made to the run (`events.tsv`).
    pub fn event(&self, sim_s: f64, event: &str, detail: &str) {
        self.handle.event(sim_s, event, detail);
    }

    /// Records one ground-truth row.
    pub fn state(&self, row: StateRow) {
        self.handle.state(row);
    }

    /// Flushes and syncs everything, stops the thread and returns what was written.
    pub fn finish(mut self) -> Result<Stats, RecordError> {
        self.finish_inner()
    }

    fn finish_inner(&mut self) -> Result<Stats, RecordError> {
        let Some(thread) = self.thread.take() else {
            return Ok(Stats::default());
        };
        let _ = self.handle.tx.send(Message::Finish);
        thread.join().map_err(|_| RecordError::ThreadGone)?
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if let Err(e) = self.finish_inner() {
            tracing::error!(error = %e, "recording did not finish cleanly");
        }
    }
}

fn write_loop(rx: mpsc::Receiver<Message>, mut files: Files) -> Result<Stats, RecordError> {
    let mut stats = Stats::default();
    let mut last_flush = Instant::now();
    loop {
        let message = match rx.recv_timeout(FLUSH_INTERVAL) {
            Ok(m) => Some(m),
            Err(mpsc::RecvTimeoutError::Timeout) => None,
            // Every sender dropped without `finish`: flush what we have and stop.
            Err(mpsc::RecvTimeoutError::Disconnected) => Some(Message::Finish),
        };
        match message {
            Some(Message::Bytes(chunk)) => {
                files.bytes.write(&chunk)?;
                stats.chunks += 1;
                stats.bytes += chunk.data.len() as u64;
            }
            Some(Message::Dropped(drop)) => {
                files.drops.write(&drop)?;
                stats.drops += 1;
                stats.dropped_bytes += drop.data.len() as u64;
            }
            Some(Message::State(row)) => {
                files.state.write(&row)?;
                stats.states += 1;
            }
            Some(Message::Event(row)) => {
                files.events.write(&row)?;
                stats.events += 1;
            }
            Some(Message::Finish) => {
                for table in files.each() {
                    table.sync()?;
                }
                return Ok(stats);
            }
            None => {}
        }
        if last_flush.elapsed() >= FLUSH_INTERVAL {
            for table in files.each() {
                table.flush()?;
            }
            last_flush = Instant::now();
        }
    }
}

#[cfg(test)]
mod tests;
