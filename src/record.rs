//! `--record DIR`: every byte on every link, and the ground-truth vehicle state.
//!
//! The formats are specified in `docs/recording.md`; `replay` and `gap` read them. In short:
//!
//! - `bytes.tsv`: one line per chunk of bytes that crossed a link, in the order they crossed:
//!   `sim_s <TAB> wall_unix_s <TAB> link <TAB> dir <TAB> hex`, where `dir` is `rx` (EyeBot to
//!   bridge) or `tx` (bridge to EyeBot) and `hex` is the bytes in lower-case hex.
//! - `state.csv`: the vehicle's true state at a set rate (same columns as `simulate`).
//! - `drops.tsv`: bytes the bridge put on a line (so in `bytes.tsv` as `tx`) that never
//!   reached the endpoint: `sim_s <TAB> wall_unix_s <TAB> link <TAB> reason <TAB> hex`.
//! - `state.csv`: the vehicle's true state at a set rate (same columns as `simulate`).
//! - `meta.toml`: what produced the recording (version, seed, time mode, links).
//!
//! Writes go to a dedicated thread through a bounded channel of [`QUEUE_MESSAGES`] messages
//! (each at most a few KiB: one read from a link, one release of paced bytes, one state
//! row). Nothing handed to the recorder is dropped: when the disk falls behind, the caller
//! waits (back-pressure: the bridge stops reading its links until the recorder catches up,
//! and the EyeBot's own writes block in the kernel), and each such wait is counted
//! ([`Stats::stalls`]). The thread flushes at least every [`FLUSH_INTERVAL`], so `kill -9`
//! loses at most that much; a clean shutdown (SIGINT/SIGTERM, [`Recorder::finish`]) flushes
//! and syncs everything.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The longest a recorded chunk may wait in memory before it reaches the file.
pub const FLUSH_INTERVAL: Duration = Duration::from_millis(50);

/// Header line of `bytes.tsv`.
pub const BYTES_HEADER: &str = "sim_s\twall_unix_s\tlink\tdir\thex";

/// Header line of `drops.tsv`.
pub const DROPS_HEADER: &str = "sim_s\twall_unix_s\tlink\treason\thex";

/// Messages the recorder thread may have queued before a caller waits for it.
pub const QUEUE_MESSAGES: usize = 1024;

/// Why bytes the bridge put on a line never reached the endpoint (`drops.tsv`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DropReason {
    /// The client did not read: more than the line's `tx_queue_bytes` waited.
    NotRead,
    /// The endpoint was gone or a write to it failed (a vanished serial device, a TCP
    /// client that left).
    EndpointGone,
    /// Still waiting for the endpoint when the daemon stopped.
    Shutdown,
}

impl DropReason {
    pub fn as_str(self) -> &'static str {
        match self {
            DropReason::NotRead => "not-read",
            DropReason::EndpointGone => "endpoint-gone",
            DropReason::Shutdown => "shutdown",
        }
    }
}

/// Which way bytes crossed a link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// From the EyeBot side into the bridge.
    Rx,
    /// From the bridge out to the EyeBot side.
    Tx,
}

impl Direction {
    pub fn as_str(self) -> &'static str {
        match self {
            Direction::Rx => "rx",
            Direction::Tx => "tx",
        }
    }
}

/// Why a recording could not be started or completed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("recording {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("recorder thread stopped unexpectedly")]
    ThreadGone,
}

enum Message {
    Bytes {
        sim_s: f64,
        wall_unix_s: f64,
        link: &'static str,
        dir: Direction,
        data: Vec<u8>,
    },
    Dropped {
        sim_s: f64,
        wall_unix_s: f64,
        link: &'static str,
        reason: DropReason,
        data: Vec<u8>,
    },
    State(String),
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

    /// Records bytes put on `link` at simulated time `sim_s` that never reached the endpoint.
    pub fn dropped(&self, sim_s: f64, link: &'static str, reason: DropReason, data: &[u8]) {
        if data.is_empty() {
            return;
        }
        let sent = self.send(Message::Dropped {
            sim_s,
            wall_unix_s: wall_unix_s(),
            link,
            reason,
            data: data.to_vec(),
        });
        if !sent {
            tracing::error!("recorder thread is gone; drop not recorded");
        }
    }
}

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
}

struct Files {
    bytes: BufWriter<File>,
    drops: BufWriter<File>,
    state: BufWriter<File>,
    bytes_path: PathBuf,
    drops_path: PathBuf,
    state_path: PathBuf,
}

impl Files {
    fn flush(&mut self) -> Result<(), RecordError> {
        for (file, path) in [
            (&mut self.bytes, &self.bytes_path),
            (&mut self.drops, &self.drops_path),
            (&mut self.state, &self.state_path),
        ] {
            file.flush().map_err(|source| RecordError::Io {
                path: path.clone(),
                source,
            })?;
        }
        Ok(())
    }
}

impl Recorder {
    /// Creates `dir` and its files, writes `meta.toml` and the headers, starts the thread.
    /// `state_header` is the CSV header of the ground-truth rows passed to [`Recorder::state`].
    pub fn start(dir: &Path, meta_toml: &str, state_header: &str) -> Result<Self, RecordError> {
        let io_err = |path: &Path| {
            let path = path.to_path_buf();
            move |source| RecordError::Io { path, source }
        };
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        let meta_path = dir.join("meta.toml");
        std::fs::write(&meta_path, meta_toml).map_err(io_err(&meta_path))?;
        let bytes_path = dir.join("bytes.tsv");
        let drops_path = dir.join("drops.tsv");
        let state_path = dir.join("state.csv");
        let mut files = Files {
            bytes: BufWriter::new(File::create(&bytes_path).map_err(io_err(&bytes_path))?),
            drops: BufWriter::new(File::create(&drops_path).map_err(io_err(&drops_path))?),
            state: BufWriter::new(File::create(&state_path).map_err(io_err(&state_path))?),
            bytes_path,
            drops_path,
            state_path,
        };
        writeln!(files.bytes, "{BYTES_HEADER}").map_err(io_err(&files.bytes_path))?;
        writeln!(files.drops, "{DROPS_HEADER}").map_err(io_err(&files.drops_path))?;
        writeln!(files.state, "{state_header}").map_err(io_err(&files.state_path))?;
        files.flush()?;
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
        if data.is_empty() {
            return;
        }
        let sent = self.handle.send(Message::Bytes {
            sim_s,
            wall_unix_s: wall_unix_s(),
            link,
            dir,
            data: data.to_vec(),
        });
        if !sent {
            tracing::error!("recorder thread is gone; bytes not recorded");
        }
    }

    /// Records bytes put on `link` that never reached the endpoint (`drops.tsv`).
    pub fn dropped(&self, sim_s: f64, link: &'static str, reason: DropReason, data: &[u8]) {
        self.handle.dropped(sim_s, link, reason, data);
    }

    /// Records one ground-truth CSV row (without the newline).
    pub fn state(&self, csv_row: String) {
        if !self.handle.send(Message::State(csv_row)) {
            tracing::error!("recorder thread is gone; state not recorded");
        }
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

/// One row of `bytes.tsv` or `drops.tsv` (the two share their layout, `docs/recording.md`):
/// simulated time, wall time, link, direction or drop reason, hex bytes.
fn write_chunk_row(
    line: &mut String,
    (sim_s, wall_unix_s, link, what, data): (f64, f64, &str, &str, &[u8]),
    file: &mut impl Write,
    path: &Path,
) -> Result<(), RecordError> {
    line.clear();
    let _ = writeln!(
        line,
        "{sim_s:.9}\t{wall_unix_s:.6}\t{link}\t{what}\t{}",
        hex::encode(data)
    );
    file.write_all(line.as_bytes())
        .map_err(|source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        })
}

fn write_loop(rx: mpsc::Receiver<Message>, mut files: Files) -> Result<Stats, RecordError> {
    let mut stats = Stats::default();
    let mut last_flush = Instant::now();
    let mut line = String::new();
    loop {
        let message = match rx.recv_timeout(FLUSH_INTERVAL) {
            Ok(m) => Some(m),
            Err(mpsc::RecvTimeoutError::Timeout) => None,
            // Every sender dropped without `finish`: flush what we have and stop.
            Err(mpsc::RecvTimeoutError::Disconnected) => Some(Message::Finish),
        };
        match message {
            Some(Message::Bytes {
                sim_s,
                wall_unix_s,
                link,
                dir,
                data,
            }) => {
                write_chunk_row(
                    &mut line,
                    (sim_s, wall_unix_s, link, dir.as_str(), &data),
                    &mut files.bytes,
                    &files.bytes_path,
                )?;
                stats.chunks += 1;
                stats.bytes += data.len() as u64;
            }
            Some(Message::Dropped {
                sim_s,
                wall_unix_s,
                link,
                reason,
                data,
            }) => {
                write_chunk_row(
                    &mut line,
                    (sim_s, wall_unix_s, link, reason.as_str(), &data),
                    &mut files.drops,
                    &files.drops_path,
                )?;
                stats.drops += 1;
                stats.dropped_bytes += data.len() as u64;
            }
            Some(Message::State(row)) => {
                writeln!(files.state, "{row}").map_err(|source| RecordError::Io {
                    path: files.state_path.clone(),
                    source,
                })?;
                stats.states += 1;
            }
            Some(Message::Finish) => {
                files.flush()?;
                for (file, path) in [
                    (files.bytes.get_ref(), &files.bytes_path),
                    (files.drops.get_ref(), &files.drops_path),
                    (files.state.get_ref(), &files.state_path),
                ] {
                    // A pipe or a character device (a live consumer) cannot be synced.
                    match file.sync_all() {
                        Err(e) if e.kind() == io::ErrorKind::InvalidInput => {}
                        other => other.map_err(|source| RecordError::Io {
                            path: path.clone(),
                            source,
                        })?,
                    }
                }
                return Ok(stats);
            }
            None => {}
        }
        if last_flush.elapsed() >= FLUSH_INTERVAL {
            files.flush()?;
            last_flush = Instant::now();
        }
    }
}

/// One parsed line of `bytes.tsv`.
#[derive(Debug, Clone, PartialEq)]
pub struct ByteChunk {
    pub sim_s: f64,
    pub wall_unix_s: f64,
    pub link: String,
    pub dir: Direction,
    pub data: Vec<u8>,
}

/// Why a `bytes.tsv` line was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("bytes.tsv line {line}: {reason}")]
pub struct ParseChunkError {
    pub line: usize,
    pub reason: String,
}

/// Parses one non-header line of `bytes.tsv` (`line` is 1-based, for the error).
pub fn parse_chunk(text: &str, line: usize) -> Result<ByteChunk, ParseChunkError> {
    let fail = |reason: &str| ParseChunkError {
        line,
        reason: reason.to_string(),
    };
    let mut fields = text.trim_end_matches(['\r', '\n']).split('\t');
    let mut next = |name: &str| {
        fields
            .next()
            .ok_or_else(|| fail(&format!("missing field `{name}`")))
    };
    let sim_s = next("sim_s")?
        .parse()
        .map_err(|_| fail("sim_s is not a number"))?;
    let wall_unix_s = next("wall_unix_s")?
        .parse()
        .map_err(|_| fail("wall_unix_s is not a number"))?;
    let link = next("link")?.to_string();
    let dir = match next("dir")? {
        "rx" => Direction::Rx,
        "tx" => Direction::Tx,
        _ => return Err(fail("dir must be rx or tx")),
    };
    let data = hex::decode(next("hex")?).map_err(|e| fail(&format!("bad hex: {e}")))?;
    Ok(ByteChunk {
        sim_s,
        wall_unix_s,
        link,
        dir,
        data,
    })
}

/// Header of `state.csv` (and of `simulate`'s trace): SI units, NED world, FRD body.
pub const STATE_HEADER: &str = "t_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad,u_mps,v_mps,w_mps,p_radps,q_radps,r_radps,\
force_port_n,force_starboard_n,force_bow_n,force_stern_n,contact";

/// One `state.csv` row for `state` (full precision, so a trace round-trips exactly).
pub fn state_row(state: &crate::physics::state::VehicleState) -> String {
    let (roll, pitch, yaw) = state.euler_rad();
    let p = &state.position_m;
    let v = &state.velocity_body_mps;
    let w = &state.angular_velocity_body_radps;
    let f = &state.thruster_force_n;
    format!(
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        state.t_s,
        p.x,
        p.y,
        p.z,
        roll,
        pitch,
        yaw,
        v.x,
        v.y,
        v.z,
        w.x,
        w.y,
        w.z,
        f[0],
        f[1],
        f[2],
        f[3],
        u8::from(state.in_contact)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recorded_bytes_parse_back_exactly() {
        let dir = std::env::temp_dir().join(format!("eyebot-hil-rec-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let rec = Recorder::start(&dir, "seed = 1\n", "t_s,x_m").unwrap();
        let all: Vec<u8> = (0..=255u8).collect();
        rec.bytes(0.25, "sensor", Direction::Rx, &all);
        rec.bytes(1.5, "sonar", Direction::Tx, b"$SDDBT,,f,2.0,M,,F*00\r\n");
        rec.state("0.0,1.0".into());
        rec.handle()
            .dropped(1.75, "sensor", DropReason::NotRead, &[0xEB, 0x90]);
        let stats = rec.finish().unwrap();
        assert_eq!(
            stats,
            Stats {
                chunks: 2,
                bytes: 256 + 23,
                states: 1,
                drops: 1,
                dropped_bytes: 2,
                stalls: 0,
            }
        );
        let drops = std::fs::read_to_string(dir.join("drops.tsv")).unwrap();
        let drops: Vec<Vec<&str>> = drops.lines().map(|l| l.split('\t').collect()).collect();
        assert_eq!(drops[0].join("\t"), DROPS_HEADER);
        assert_eq!(drops[1][0], "1.750000000");
        assert_eq!(drops[1][2..], ["sensor", "not-read", "eb90"]);
        assert_eq!(drops.len(), 2);

        let text = std::fs::read_to_string(dir.join("bytes.tsv")).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some(BYTES_HEADER));
        let first = parse_chunk(lines.next().unwrap(), 2).unwrap();
        assert_eq!(first.data, all);
        assert_eq!(first.dir, Direction::Rx);
        assert_eq!(first.sim_s, 0.25);
        let second = parse_chunk(lines.next().unwrap(), 3).unwrap();
        assert_eq!(second.link, "sonar");
        assert_eq!(second.data, b"$SDDBT,,f,2.0,M,,F*00\r\n");
        assert_eq!(
            std::fs::read_to_string(dir.join("state.csv")).unwrap(),
            "t_s,x_m\n0.0,1.0\n"
        );
        std::fs::remove_dir_all(dir).unwrap();
    }

    /// A disk that stops taking data (here a FIFO nobody reads) makes the caller wait once
    /// the queue is full, instead of growing memory or dropping: every chunk arrives once the
    /// reader catches up, and the waits are counted.
    #[test]
    fn a_stalled_disk_blocks_the_caller_and_loses_nothing() {
        use std::io::Read;
        use std::os::unix::fs::OpenOptionsExt;
        let dir = std::env::temp_dir().join(format!("eyebot-hil-rec-fifo-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let fifo = dir.join("bytes.tsv");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let mut reader = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(nix::libc::O_NONBLOCK)
            .open(&fifo)
            .unwrap();
        let rec = Recorder::start(&dir, "", "t_s").unwrap();
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
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn malformed_lines_name_the_line_and_the_problem() {
        assert_eq!(
            parse_chunk("1.0\t2.0\tsonar\tup\t00", 7).unwrap_err().line,
            7
        );
        assert!(
            parse_chunk("1.0\t2.0\tsonar\ttx\t0", 1)
                .unwrap_err()
                .reason
                .contains("bad hex")
        );
        assert!(
            parse_chunk("1.0\t2.0\tsonar\ttx\tzz", 1)
                .unwrap_err()
                .reason
                .contains("bad hex")
        );
        assert!(
            parse_chunk("x\t2.0\tsonar\ttx\t00", 1)
                .unwrap_err()
                .reason
                .contains("sim_s")
        );
        assert!(
            parse_chunk("1.0", 1)
                .unwrap_err()
                .reason
                .contains("missing")
        );
    }
}
