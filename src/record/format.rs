//! The files of a recording as serde types, written and read through `csv` and `toml`
//! (`docs/recording.md`), and the readers every consumer uses: `replay`, `gap convert`, the
//! test harness.
//!
//! A recording directory holds `meta.toml` ([`Meta`]), `config.toml` (the daemon
//! configuration of the run, verbatim), `bytes.tsv` ([`ByteChunk`] rows), `drops.tsv`
//! ([`DropRow`] rows) and `state.csv` ([`StateRow`] rows; `simulate` writes the same rows).
//!
//! [`FORMAT`] numbers the layout. Format 1 (recordings made before `config.toml` existed)
//! had no `format` key and carried the configuration as `#` comments at the end of
//! `meta.toml`; [`read_config`] still recovers it from there. Anything else a reader does
//! not understand fails with an error that names the file, the line and what was expected.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::physics::state::VehicleState;

/// The recording layout this version writes.
pub const FORMAT: u32 = 2;

/// The first layout: configuration as comments in `meta.toml`, no `config.toml`.
pub const FORMAT_COMMENTED_CONFIG: u32 = 1;

/// File names inside a recording directory.
pub const META_FILE: &str = "meta.toml";
pub const CONFIG_FILE: &str = "config.toml";
pub const BYTES_FILE: &str = "bytes.tsv";
pub const DROPS_FILE: &str = "drops.tsv";
pub const STATE_FILE: &str = "state.csv";
pub const EVENTS_FILE: &str = "events.tsv";

/// Header line of `bytes.tsv` (the field names of [`ByteChunk`]).
pub const BYTES_HEADER: &str = "sim_s\twall_unix_s\tlink\tdir\thex";

/// Header line of `drops.tsv` (the field names of [`DropRow`]).
pub const DROPS_HEADER: &str = "sim_s\twall_unix_s\tlink\treason\thex";
/// The header of `events.tsv`.
pub const EVENTS_HEADER: &str = "sim_s\twall_unix_s\tevent\tdetail";

/// Header of `state.csv` and of `simulate`'s trace (the field names of [`StateRow`]).
pub const STATE_HEADER: &str = "t_s,x_m,y_m,z_m,roll_rad,pitch_rad,yaw_rad,u_mps,v_mps,w_mps,\
p_radps,q_radps,r_radps,force_port_n,force_starboard_n,force_bow_n,force_stern_n,contact";

/// `meta.toml`: what produced the recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Meta {
    /// The recording layout ([`FORMAT`]); absent in format 1.
    #[serde(default = "format_commented_config")]
    pub format: u32,
    /// The `eyebot-hil` version that recorded.
    pub version: String,
    pub seed: u64,
    /// `realtime` or `lockstep`.
    pub time_mode: String,
    /// The realtime speed factor (1 in lockstep).
    pub speed: f64,
    /// The daemon configuration's name (a path, or `<embedded>/default.toml`).
    pub config: String,
}

fn format_commented_config() -> u32 {
    FORMAT_COMMENTED_CONFIG
}

impl Meta {
    /// The meta of a recording this version makes.
    pub fn new(seed: u64, time_mode: &str, speed: f64, config: &str) -> Self {
        Self {
            format: FORMAT,
            version: env!("CARGO_PKG_VERSION").to_string(),
            seed,
            time_mode: time_mode.to_string(),
            speed,
            config: config.to_string(),
        }
    }
}

/// Which way bytes crossed a link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
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

/// Why bytes the bridge put on a line never reached the endpoint (`drops.tsv`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
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

/// One row of `bytes.tsv`: bytes that crossed a link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ByteChunk {
    /// Simulated time of the crossing, s (written with 9 decimals: whole nanoseconds).
    #[serde(serialize_with = "nanos_9")]
    pub sim_s: f64,
    /// Wall-clock time the recorder was handed the chunk, Unix s (6 decimals).
    #[serde(serialize_with = "micros_6")]
    pub wall_unix_s: f64,
    pub link: String,
    pub dir: Direction,
    #[serde(rename = "hex", with = "hex_column")]
    pub data: Vec<u8>,
}

/// One row of `drops.tsv`: bytes recorded as `tx` that never reached the endpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DropRow {
    #[serde(serialize_with = "nanos_9")]
    pub sim_s: f64,
    #[serde(serialize_with = "micros_6")]
    pub wall_unix_s: f64,
    pub link: String,
    pub reason: DropReason,
    #[serde(rename = "hex", with = "hex_column")]
    pub data: Vec<u8>,
}

/// One row of `events.tsv`: a change made to the run while it ran.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventRow {
    /// Simulated time at which the change took effect.
    pub sim_s: f64,
    pub wall_unix_s: f64,
    /// `pause`, `resume`, `speed`, `pose`, `current` or `reset`.
    pub event: String,
    /// The change's values as space-separated `key=value` pairs (empty for none).
    pub detail: String,
}

/// One row of `state.csv`, and of `simulate`'s trace: the vehicle's true state. World frame
/// NED, body frame forward-starboard-down, ZYX Euler angles, thruster forces after the motor
/// lag; full precision, so a trace reads back bit for bit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StateRow {
    pub t_s: f64,
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: f64,
    pub roll_rad: f64,
    pub pitch_rad: f64,
    pub yaw_rad: f64,
    pub u_mps: f64,
    pub v_mps: f64,
    pub w_mps: f64,
    pub p_radps: f64,
    pub q_radps: f64,
    pub r_radps: f64,
    pub force_port_n: f64,
    pub force_starboard_n: f64,
    pub force_bow_n: f64,
    pub force_stern_n: f64,
    /// 1 while the hull touches the pool, else 0.
    #[serde(with = "zero_one")]
    pub contact: bool,
}

impl StateRow {
    pub fn from_state(state: &VehicleState) -> Self {
        let (roll, pitch, yaw) = state.euler_rad();
        let p = &state.position_m;
        let v = &state.velocity_body_mps;
        let w = &state.angular_velocity_body_radps;
        let f = &state.thruster_force_n;
        Self {
            t_s: state.t_s,
            x_m: p.x,
            y_m: p.y,
            z_m: p.z,
            roll_rad: roll,
            pitch_rad: pitch,
            yaw_rad: yaw,
            u_mps: v.x,
            v_mps: v.y,
            w_mps: v.z,
            p_radps: w.x,
            q_radps: w.y,
            r_radps: w.z,
            force_port_n: f[0],
            force_starboard_n: f[1],
            force_bow_n: f[2],
            force_stern_n: f[3],
            contact: state.in_contact,
        }
    }
}

fn nanos_9<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&format!("{v:.9}"))
}

fn micros_6<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&format!("{v:.6}"))
}

mod hex_column {
    use serde::{Deserialize, Deserializer, Serializer, de::Error};

    pub fn serialize<S: Serializer>(data: &[u8], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&hex::encode(data))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
        let text = <std::borrow::Cow<'de, str>>::deserialize(d)?;
        hex::decode(text.as_ref())
            .map_err(|e| D::Error::custom(format!("column `hex`: bad hex: {e}")))
    }
}

mod zero_one {
    use serde::{Deserialize, Deserializer, Serializer, de::Error};

    pub fn serialize<S: Serializer>(v: &bool, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u8(u8::from(*v))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<bool, D::Error> {
        match u8::deserialize(d)? {
            0 => Ok(false),
            1 => Ok(true),
            other => Err(D::Error::custom(format!(
                "column `contact`: {other} is not 0 or 1"
            ))),
        }
    }
}

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A line that is not what the format says; `line` is 1-based.
    #[error("{} line {line}: {problem}", path.display())]
    Line {
        path: PathBuf,
        line: u64,
        problem: String,
    },
    /// A layout this version cannot read.
    #[error("{}: {problem}", path.display())]
    Version { path: PathBuf, problem: String },
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> ReadError + '_ {
    move |source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Reads `meta.toml` of the recording in `dir`.
pub fn read_meta(dir: &Path) -> Result<Meta, ReadError> {
    let path = dir.join(META_FILE);
    let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
    let meta: Meta = toml::from_str(&text).map_err(|e| {
        let line = e.span().map_or(1, |span| {
            text[..span.start].matches('\n').count() as u64 + 1
        });
        ReadError::Line {
            path: path.clone(),
            line,
            problem: format!(
                "expected the recording's meta (format, version, seed, time_mode, speed, \
                 config); recorded by an older version? {}",
                e.message()
            ),
        }
    })?;
    if meta.format > FORMAT {
        return Err(ReadError::Version {
            path,
            problem: format!(
                "recording format {} was written by a newer version ({}); this one reads up \
                 to format {FORMAT}",
                meta.format, meta.version
            ),
        });
    }
    Ok(meta)
}

/// The line of a format-1 `meta.toml` after which the configuration follows as comments.
const COMMENTED_CONFIG_MARK: &str = "# The daemon configuration used, verbatim:";

/// The daemon configuration the recording in `dir` was made with, as its TOML text:
/// `config.toml`, or, in a format-1 recording, the commented copy in `meta.toml`.
pub fn read_config(dir: &Path) -> Result<String, ReadError> {
    let meta = read_meta(dir)?;
    if meta.format > FORMAT_COMMENTED_CONFIG {
        let path = dir.join(CONFIG_FILE);
        return std::fs::read_to_string(&path).map_err(io_error(&path));
    }
    let path = dir.join(META_FILE);
    let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
    let Some((_, commented)) = text.split_once(COMMENTED_CONFIG_MARK) else {
        return Err(ReadError::Version {
            path,
            problem: format!(
                "recorded by an older version without the configuration: no line \
                 `{COMMENTED_CONFIG_MARK}` and no {CONFIG_FILE}"
            ),
        });
    };
    let mut config = String::new();
    // The writer put `# ` before every line of the configuration (`#` alone for an empty
    // line would have been `# `, so both forms are accepted).
    for line in commented.lines().skip(1) {
        let line = line
            .strip_prefix("# ")
            .or_else(|| line.strip_prefix('#'))
            .unwrap_or(line);
        config.push_str(line);
        config.push('\n');
    }
    Ok(config)
}

/// The model files a recorded daemon configuration names (top-level keys).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
pub struct ModelFiles {
    pub vehicle: String,
    pub world: String,
    pub sensors: String,
}

/// The model files of the recording in `dir` ([`read_config`], then its top-level keys).
pub fn read_model_files(dir: &Path) -> Result<ModelFiles, ReadError> {
    let text = read_config(dir)?;
    toml::from_str(&text).map_err(|e| ReadError::Line {
        path: dir.join(CONFIG_FILE),
        line: e.span().map_or(1, |span| {
            text[..span.start].matches('\n').count() as u64 + 1
        }),
        problem: format!(
            "expected a daemon configuration naming `vehicle`, `world` and `sensors`: {}",
            e.message()
        ),
    })
}

/// Why one `bytes.tsv` line was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("bytes.tsv line {line}: {reason}")]
pub struct ParseChunkError {
    pub line: usize,
    pub reason: String,
}

/// Parses one non-header line of `bytes.tsv` (`line` is 1-based, for the error); for a
/// reader that streams (replay reads compressed and growing files line by line).
pub fn parse_chunk(text: &str, line: usize) -> Result<ByteChunk, ParseChunkError> {
    let fields: csv::StringRecord = text.trim_end_matches(['\r', '\n']).split('\t').collect();
    let headers: csv::StringRecord = BYTES_HEADER.split('\t').collect();
    fields
        .deserialize(Some(&headers))
        .map_err(|e| ParseChunkError {
            line,
            reason: describe_csv_error(&e, &headers),
        })
}

/// What a csv deserialisation error says, with the column named (csv knows the column of a
/// cell it could not parse; the row types' own checks name theirs in the message).
fn describe_csv_error(e: &csv::Error, headers: &csv::StringRecord) -> String {
    match e.kind() {
        csv::ErrorKind::Deserialize { err, .. } => {
            let column = err
                .field()
                .and_then(|i| headers.get(i as usize))
                .map_or(String::new(), |name| format!("column `{name}`: "));
            let what = match err.kind() {
                csv::DeserializeErrorKind::UnexpectedEndOfRow => {
                    "missing field (the row is too short)".to_string()
                }
                other => other.to_string(),
            };
            format!("{column}{what}")
        }
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!("{len} fields, expected {expected_len}"),
        _ => e.to_string(),
    }
}

/// Reads every row of one of the recording's tables, checking the header first and each row
/// with `check` (which says what is wrong with a row that parsed).
fn read_table<T: serde::de::DeserializeOwned>(
    path: &Path,
    delimiter: u8,
    header: &str,
    check: impl Fn(&T) -> Result<(), String>,
) -> Result<Vec<T>, ReadError> {
    let file = std::fs::File::open(path).map_err(io_error(path))?;
    let mut reader = csv::ReaderBuilder::new()
        .delimiter(delimiter)
        .has_headers(true)
        .from_reader(std::io::BufReader::new(file));
    let line_error = |line: u64, problem: String| ReadError::Line {
        path: path.to_path_buf(),
        line,
        problem,
    };
    let headers = reader
        .headers()
        .map_err(|e| line_error(1, e.to_string()))?
        .clone();
    let expected: csv::StringRecord = header.split(delimiter as char).collect();
    if headers != expected {
        return Err(line_error(
            1,
            format!(
                "expected the header `{header}`, found `{}`",
                headers
                    .iter()
                    .collect::<Vec<_>>()
                    .join(&(delimiter as char).to_string())
            ),
        ));
    }
    let mut rows = Vec::new();
    let mut record = csv::StringRecord::new();
    loop {
        match reader.read_record(&mut record) {
            Ok(true) => {}
            Ok(false) => return Ok(rows),
            Err(e) => {
                let line = e.position().map_or(0, csv::Position::line);
                return Err(line_error(line, describe_csv_error(&e, &headers)));
            }
        }
        let line = record.position().map_or(0, csv::Position::line);
        let row: T = record
            .deserialize(Some(&headers))
            .map_err(|e| line_error(line, describe_csv_error(&e, &headers)))?;
        check(&row).map_err(|problem| line_error(line, problem))?;
        rows.push(row);
    }
}

/// A simulated time must be a finite number of seconds.
fn finite_time(column: &str, value: f64) -> Result<(), String> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(format!(
            "column `{column}`: expected a finite time in seconds, found {value}"
        ))
    }
}

/// Reads `bytes.tsv` of the recording in `dir`, in the order the chunks crossed.
pub fn read_bytes(dir: &Path) -> Result<Vec<ByteChunk>, ReadError> {
    read_table(
        &dir.join(BYTES_FILE),
        b'\t',
        BYTES_HEADER,
        |c: &ByteChunk| finite_time("sim_s", c.sim_s),
    )
}

/// Reads `events.tsv` of the recording in `dir`: the changes made to the run while it ran
/// (the live view's controls). A recording made before the file existed has none.
pub fn read_events(dir: &Path) -> Result<Vec<EventRow>, ReadError> {
    let path = dir.join(EVENTS_FILE);
    if !path.exists() {
        return Ok(Vec::new());
    }
    read_table(&path, b'\t', EVENTS_HEADER, |e: &EventRow| {
        finite_time("sim_s", e.sim_s)
    })
}

/// Reads `drops.tsv` of the recording in `dir`.
pub fn read_drops(dir: &Path) -> Result<Vec<DropRow>, ReadError> {
    read_table(&dir.join(DROPS_FILE), b'\t', DROPS_HEADER, |d: &DropRow| {
        finite_time("sim_s", d.sim_s)
    })
}

/// Reads `state.csv` of the recording in `dir`.
pub fn read_state(dir: &Path) -> Result<Vec<StateRow>, ReadError> {
    read_state_file(&dir.join(STATE_FILE))
}

/// Reads state rows from the file at `path` (a `state.csv`, or a `simulate` trace).
pub fn read_state_file(path: &Path) -> Result<Vec<StateRow>, ReadError> {
    read_table(path, b',', STATE_HEADER, |r: &StateRow| {
        finite_time("t_s", r.t_s)
    })
}

/// A table writer of the recording's layout: `delimiter`-separated, the header written at
/// once (so an empty table still names its columns).
pub(crate) fn table_writer<W: std::io::Write>(
    out: W,
    delimiter: u8,
    header: &str,
) -> csv::Result<csv::Writer<W>> {
    let mut writer = csv::WriterBuilder::new()
        .delimiter(delimiter)
        .has_headers(false)
        .from_writer(out);
    writer.write_record(header.split(delimiter as char))?;
    Ok(writer)
}

/// A writer of `state.csv` rows (also `simulate`'s trace).
pub fn state_writer<W: std::io::Write>(out: W) -> csv::Result<csv::Writer<W>> {
    table_writer(out, b',', STATE_HEADER)
}
