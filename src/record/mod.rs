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
mod tests {
    use super::*;

    /// What a `--record` directory holds before the run.
    #[derive(Debug, Clone)]
    enum Before {
        Missing,
        Empty,
        /// Some of a recording's files, with contents.
        Recording(Vec<(&'static str, Vec<u8>)>),
        /// Anything else: files (hidden ones too), a directory, a symlink.
        Other(Vec<(String, u8)>),
    }

    fn before() -> impl proptest::strategy::Strategy<Value = Before> {
        use proptest::prelude::*;
        let recording_file = prop::sample::select(vec![
            format::META_FILE,
            format::CONFIG_FILE,
            format::BYTES_FILE,
            format::DROPS_FILE,
            format::STATE_FILE,
            format::EVENTS_FILE,
            "bytes.tsv.gz",
        ]);
        prop_oneof![
            Just(Before::Missing),
            Just(Before::Empty),
            prop::collection::vec(
                (recording_file, prop::collection::vec(any::<u8>(), 0..64)),
                1..6
            )
            .prop_map(Before::Recording),
            prop::collection::vec(("[.]?[a-z]{1,8}", 0u8..3), 1..4).prop_map(Before::Other),
        ]
    }

    /// Every entry under `dir` with its contents (a symlink by its target), sorted.
    fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
        let mut out = Vec::new();
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            let meta = std::fs::symlink_metadata(&path).unwrap();
            if meta.file_type().is_symlink() {
                let target = std::fs::read_link(&path).unwrap();
                out.push((path, target.into_os_string().into_encoded_bytes()));
            } else if meta.is_dir() {
                out.push((path.clone(), b"<dir>".to_vec()));
                out.extend(snapshot(&path));
            } else {
                out.push((path.clone(), std::fs::read(&path).unwrap()));
            }
        }
        out.sort();
        out
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

        /// A recording starts in a missing or empty directory; a directory holding a
        /// recording, or anything else, is refused by name and left as it was. (A second
        /// `run --record DIR` replaced a recording of 1,260 chunks with an empty one.)
        #[test]
        fn a_recording_never_writes_over_what_a_directory_holds(before in before()) {
            let tmp = crate::scratch::dir("rec-over");
            let dir = tmp.path().join("rec");
            match &before {
                Before::Missing => {}
                Before::Empty => std::fs::create_dir(&dir).unwrap(),
                Before::Recording(files) => {
                    std::fs::create_dir(&dir).unwrap();
                    for (name, data) in files {
                        std::fs::write(dir.join(name), data).unwrap();
                    }
                }
                Before::Other(entries) => {
                    std::fs::create_dir(&dir).unwrap();
                    for (name, kind) in entries {
                        let path = dir.join(name);
                        if std::fs::symlink_metadata(&path).is_ok() {
                            continue;
                        }
                        match kind {
                            0 => std::fs::write(&path, name.as_bytes()).unwrap(),
                            1 => std::fs::create_dir_all(path.join("inner")).unwrap(),
                            _ => std::os::unix::fs::symlink(tmp.path(), &path).unwrap(),
                        }
                    }
                }
            }
            let was = if dir.exists() { snapshot(&dir) } else { Vec::new() };
            let meta = Meta::new(1, "lockstep", 1.0, "test");
            match Recorder::start(&dir, &meta, "") {
                Ok(rec) => {
                    proptest::prop_assert!(was.is_empty(), "started over {was:?}");
                    rec.finish().unwrap();
                }
                Err(e) => {
                    proptest::prop_assert!(!was.is_empty(), "{e}");
                    proptest::prop_assert!(matches!(e, RecordError::NotEmpty { .. }), "{e}");
                    proptest::prop_assert!(e.to_string().contains(&dir.display().to_string()), "{e}");
                    proptest::prop_assert_eq!(snapshot(&dir), was);
                }
            }
        }
    }

    fn state_row(t_s: f64, contact: bool) -> StateRow {
        StateRow {
            t_s,
            x_m: 1.0 / 3.0,
            y_m: -2.5,
            z_m: 1e-7,
            roll_rad: 0.1,
            pitch_rad: -0.2,
            yaw_rad: std::f64::consts::PI,
            u_mps: 0.3,
            v_mps: 0.0,
            w_mps: -0.0,
            p_radps: 1e300,
            q_radps: 0.5,
            r_radps: 0.25,
            force_port_n: 3.0,
            force_starboard_n: -3.0,
            force_bow_n: 0.125,
            force_stern_n: 7.0,
            contact,
        }
    }

    /// Everything handed to the recorder reads back through the public readers, bit for bit:
    /// meta, the configuration verbatim, every byte value, drops and state rows.
    #[test]
    fn a_recording_reads_back_exactly() {
        let tmp = crate::scratch::dir("rec");
        let dir = tmp.path();
        let meta = Meta::new(7, "lockstep", 1.0, "<embedded>/default.toml");
        let config = "# a comment survives\nvehicle = \"vehicles/mako.toml\"\n";
        let rec = Recorder::start(dir, &meta, config).unwrap();
        let all: Vec<u8> = (0..=255u8).collect();
        rec.bytes(0.25, "sensor", Direction::Rx, &all);
        rec.bytes(1.5, "sonar", Direction::Tx, b"$SDDBT,,f,2.0,M,,F*00\r\n");
        let rows = [state_row(0.0, false), state_row(0.02, true)];
        for row in rows {
            rec.state(row);
        }
        rec.handle()
            .dropped(1.75, "sensor", DropReason::NotRead, &[0xEB, 0x90]);
        rec.event(1.8, "pose", "x_m=2 y_m=3 depth_m=1 heading_deg=90");
        let stats = rec.finish().unwrap();
        assert_eq!(
            stats,
            Stats {
                chunks: 2,
                bytes: 256 + 23,
                states: 2,
                drops: 1,
                dropped_bytes: 2,
                stalls: 0,
                events: 1,
            }
        );
        let events = read_events(dir).unwrap();
        assert_eq!(events.len(), 1);
        assert_eq!(
            (
                events[0].sim_s,
                events[0].event.as_str(),
                events[0].detail.as_str()
            ),
            (1.8, "pose", "x_m=2 y_m=3 depth_m=1 heading_deg=90")
        );
        assert_eq!(read_meta(dir).unwrap(), meta);
        assert_eq!(read_config(dir).unwrap(), config);
        let chunks = read_bytes(dir).unwrap();
        assert_eq!(chunks.len(), 2);
        assert_eq!(chunks[0].data, all);
        assert_eq!(chunks[0].dir, Direction::Rx);
        assert_eq!(chunks[0].sim_s, 0.25);
        assert_eq!(chunks[1].link, "sonar");
        assert_eq!(chunks[1].dir, Direction::Tx);
        assert_eq!(chunks[1].data, b"$SDDBT,,f,2.0,M,,F*00\r\n");
        let drops = read_drops(dir).unwrap();
        assert_eq!(drops.len(), 1);
        assert_eq!(
            (drops[0].sim_s, drops[0].link.as_str(), drops[0].reason),
            (1.75, "sensor", DropReason::NotRead)
        );
        assert_eq!(drops[0].data, [0xEB, 0x90]);
        let states = read_state(dir).unwrap();
        assert_eq!(states.len(), 2);
        for (got, want) in states.iter().zip(&rows) {
            // Bit for bit, including the sign of -0.0.
            let bits = |r: &StateRow| format!("{r:?}");
            assert_eq!(bits(got), bits(want));
        }
        // The documented text layout: 9 decimals of simulated time, lower-case hex.
        let text = std::fs::read_to_string(dir.join("drops.tsv")).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some(DROPS_HEADER));
        let fields: Vec<&str> = lines.next().unwrap().split('\t').collect();
        assert_eq!(fields[0], "1.750000000");
        assert_eq!(fields[2..], ["sensor", "not-read", "eb90"]);
    }

    /// The header constants are the serde field names, so a renamed field cannot leave the
    /// documented header behind.
    #[test]
    fn the_headers_are_the_field_names_of_the_row_types() {
        fn header_of(row: &impl serde::Serialize, delimiter: u8) -> String {
            let mut w = csv::WriterBuilder::new()
                .delimiter(delimiter)
                .from_writer(Vec::new());
            w.serialize(row).unwrap();
            let text = String::from_utf8(w.into_inner().unwrap()).unwrap();
            text.lines().next().unwrap().to_string()
        }
        let chunk = ByteChunk {
            sim_s: 0.0,
            wall_unix_s: 0.0,
            link: "sonar".into(),
            dir: Direction::Tx,
            data: vec![1],
        };
        let drop = DropRow {
            sim_s: 0.0,
            wall_unix_s: 0.0,
            link: "sonar".into(),
            reason: DropReason::Shutdown,
            data: vec![1],
        };
        assert_eq!(header_of(&chunk, b'\t'), BYTES_HEADER);
        assert_eq!(header_of(&drop, b'\t'), DROPS_HEADER);
        assert_eq!(header_of(&state_row(0.0, false), b','), STATE_HEADER);
    }

    /// A recording made before `config.toml` existed (format 1: the configuration as `#`
    /// comments in `meta.toml`), written by that version's binary, still reads: meta,
    /// configuration, model files, bytes and state.
    #[test]
    fn a_format_1_recording_still_reads() {
        let dir = &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/recording-format-1");
        let meta = read_meta(dir).unwrap();
        assert_eq!(meta.format, format::FORMAT_COMMENTED_CONFIG);
        assert_eq!(meta.time_mode, "lockstep");
        let config = read_config(dir).unwrap();
        // the default configuration of the binary that made it (configs/default.toml then)
        let then = std::fs::read_to_string(dir.join("default-then.toml")).unwrap();
        assert_eq!(
            config, then,
            "the commented copy is the configuration verbatim"
        );
        assert_eq!(
            read_model_files(dir).unwrap(),
            ModelFiles {
                vehicle: "vehicles/mako.toml".into(),
                world: "worlds/pool.toml".into(),
                sensors: "sensors/mako-2008.toml".into(),
            }
        );
        let chunks = read_bytes(dir).unwrap();
        assert!(chunks.iter().any(|c| c.dir == Direction::Rx));
        assert!(chunks.iter().any(|c| c.dir == Direction::Tx));
        assert!(!read_state(dir).unwrap().is_empty());
        assert!(read_drops(dir).unwrap().is_empty());
    }

    /// A `meta.toml` of neither format names the file and says it may be older.
    #[test]
    fn an_unreadable_meta_says_it_may_be_from_an_older_version() {
        let tmp = crate::scratch::dir("rec-oldmeta");
        let dir = tmp.path();
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(dir.join("meta.toml"), "seed = 1\n").unwrap();
        let e = read_meta(dir).unwrap_err().to_string();
        assert!(e.contains("meta.toml"), "{e}");
        assert!(e.contains("recorded by an older version"), "{e}");
        let newer = "format = 99\nversion = \"9.0.0\"\nseed = 1\ntime_mode = \"lockstep\"\n\
                     speed = 1.0\nconfig = \"x\"\n";
        std::fs::write(dir.join("meta.toml"), newer).unwrap();
        let e = read_meta(dir).unwrap_err().to_string();
        assert!(e.contains("newer version"), "{e}");
    }

    /// Table errors name the file, the line and the column or header that was expected.
    #[test]
    fn a_bad_table_names_file_line_and_what_was_expected() {
        let tmp = crate::scratch::dir("rec-bad");
        let dir = tmp.path();
        std::fs::create_dir_all(dir).unwrap();
        // `simulate`'s earlier columns (degrees, thrust_*) are not state rows.
        std::fs::write(
            dir.join("state.csv"),
            "t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,0,0,0,0\n",
        )
        .unwrap();
        let e = read_state(dir).unwrap_err().to_string();
        assert!(e.contains("state.csv line 1: expected the header"), "{e}");
        let good = format!("{STATE_HEADER}\n{}\n", "0,".repeat(17) + "0");
        let bad_cell = good.clone() + &"0,".repeat(17) + "2\n";
        std::fs::write(dir.join("state.csv"), &bad_cell).unwrap();
        let e = read_state(dir).unwrap_err().to_string();
        assert!(e.contains("state.csv line 3"), "{e}");
        assert!(e.contains("column `contact`"), "{e}");
        std::fs::write(
            dir.join("bytes.tsv"),
            format!("{BYTES_HEADER}\n1.0\t2.0\tsonar\tup\t00\n"),
        )
        .unwrap();
        let e = read_bytes(dir).unwrap_err().to_string();
        assert!(e.contains("bytes.tsv line 2: unknown variant `up`"), "{e}");
        std::fs::write(
            dir.join("state.csv"),
            format!("{good}NaN{}\n", ",0".repeat(17)),
        )
        .unwrap();
        let e = read_state(dir).unwrap_err().to_string();
        assert!(
            e.contains("state.csv line 3: column `t_s`: expected a finite"),
            "{e}"
        );
    }

    /// A disk that stops taking data (here a FIFO nobody reads) makes the caller wait once
    /// the queue is full, instead of growing memory or dropping: every chunk arrives once the
    /// reader catches up, and the waits are counted.
    #[test]
    fn a_stalled_disk_blocks_the_caller_and_loses_nothing() {
        use std::io::Read;
        use std::os::unix::fs::OpenOptionsExt;
        let tmp = crate::scratch::dir("rec-fifo");
        let dir = tmp.path();
        let fifo = dir.join("bytes.tsv");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let mut reader = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(nix::libc::O_NONBLOCK)
            .open(&fifo)
            .unwrap();
        // The FIFO stands in for a stalled disk, so the directory is not empty.
        let rec = Recorder::start_in(dir, &Meta::new(1, "lockstep", 1.0, "test"), "").unwrap();
        let chunk = vec![0x5A_u8; 1024];
        let total = 3 * QUEUE_MESSAGES;
        let (done_tx, done_rx) = mpsc::channel();
        let writer = std::thread::spawn(move || {
            for i in 0..total {
                rec.bytes(i as f64, "sensor", Direction::Rx, &chunk);
            }
            let _ = done_tx.send(rec.stalls());
            rec.finish().unwrap()
        });
        // Nobody reads: the pipe (64 KiB) and the queue fill, then the caller waits.
        assert!(
            done_rx.recv_timeout(Duration::from_millis(500)).is_err(),
            "the caller must wait for a stalled recorder"
        );
        let mut got = Vec::new();
        let mut buf = vec![0u8; 1 << 16];
        let stalls = loop {
            match reader.read(&mut buf) {
                Ok(n) => got.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    if let Ok(stalls) = done_rx.try_recv() {
                        break stalls;
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(e) => panic!("{e}"),
            }
        };
        assert!(stalls > 0, "the waits are counted");
        // Drain the rest until the writer closes its end.
        let finishing = std::thread::spawn(move || writer.join().unwrap());
        loop {
            match reader.read(&mut buf) {
                Ok(0) if finishing.is_finished() => break,
                Ok(n) => got.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    std::thread::sleep(Duration::from_millis(1))
                }
                Err(e) => panic!("{e}"),
            }
        }
        let stats = finishing.join().unwrap();
        assert_eq!(stats.chunks, total as u64);
        assert!(stats.stalls > 0);
        let text = String::from_utf8(got).unwrap();
        assert_eq!(text.lines().count(), total + 1, "header + every chunk");
    }

    #[test]
    fn malformed_lines_name_the_line_and_the_problem() {
        let reason = |text| parse_chunk(text, 1).unwrap_err().reason;
        assert_eq!(
            parse_chunk("1.0\t2.0\tsonar\tup\t00", 7).unwrap_err().line,
            7
        );
        assert!(reason("1.0\t2.0\tsonar\tup\t00").contains("expected `rx` or `tx`"));
        assert!(reason("1.0\t2.0\tsonar\ttx\t0").contains("bad hex"));
        assert!(reason("1.0\t2.0\tsonar\ttx\tzz").contains("bad hex"));
        assert!(reason("x\t2.0\tsonar\ttx\t00").contains("column `sim_s`"));
        assert!(reason("1.0").contains("missing"));
    }
}
