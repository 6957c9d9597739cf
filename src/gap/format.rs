//! The measured-data format (`docs/gap.md`): a directory holding `experiment.toml`,
//! `commands.csv` and `measured.csv`.
//!
//! The loader takes text, not paths ([`Measurement::from_texts`]); [`Measurement::load`] reads
//! the three files of a directory. Every error names the file, the line and, for CSV cells,
//! the column. Unknown CSV columns are kept out of the data and reported as notices, as are
//! the isolated gross outliers the loader sets aside ([`crate::gap::outliers`]).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::config::{ConfigError, Document};
use crate::gap::GapError;

/// Measured channels `gap` understands (`measured.csv` column names).
pub const CHANNELS: [&str; 13] = [
    "x_m",
    "y_m",
    "surge_mps",
    "compass_deg",
    "depth_adc",
    "accel_x_adc",
    "accel_y_adc",
    "accel_z_adc",
    "paddle_speed_mps",
    "sonar1_m",
    "sonar2_m",
    "sonar3_m",
    "sonar4_m",
];

/// Header of `commands.csv`.
pub const COMMANDS_HEADER: &str = "t_s,port,starboard,bow,stern";

/// The files of a measurement directory.
pub const FILES: [&str; 3] = ["experiment.toml", "commands.csv", "measured.csv"];

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct RawExperiment {
    name: String,
    #[serde(default)]
    description: String,
    duration_s: f64,
    #[serde(default = "default_world")]
    world: String,
    #[serde(default = "default_sensors")]
    sensors: String,
    initial: RawInitial,
    #[serde(default)]
    camera: Option<RawCamera>,
}

fn default_world() -> String {
    crate::physics::DEFAULT_WORLD.to_string()
}

fn default_sensors() -> String {
    "sensors/mako-2008.toml".to_string()
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct RawInitial {
    x_m: f64,
    y_m: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    z_m: Option<f64>,
    heading_deg: f64,
    #[serde(default)]
    roll_deg: f64,
    #[serde(default)]
    pitch_deg: f64,
    #[serde(default)]
    surge_mps: f64,
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    position_std_m: f64,
    #[serde(default = "default_speed_std")]
    speed_std_mps: f64,
    #[serde(default, skip_serializing_if = "is_centre")]
    marker_body_m: [f64; 2],
}

fn is_centre(marker: &[f64; 2]) -> bool {
    *marker == [0.0; 2]
}

fn default_speed_std() -> f64 {
    0.02
}

/// Where the run started (world NED; `z_m = None`: floating at the surface). The default is
/// at rest at the origin, heading north, floating.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Initial {
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: Option<f64>,
    pub heading_deg: f64,
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub surge_mps: f64,
}

/// `experiment.toml`, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct ExperimentInfo {
    pub name: String,
    pub description: String,
    pub duration_s: f64,
    /// World config: an embedded name (`worlds/pool.toml`) or a path relative to the directory.
    pub world: String,
    /// Sensor config, the same way.
    pub sensors: String,
    pub initial: Initial,
    /// Overhead-camera position noise (m, 1 sigma), the set-up's own figure.
    pub camera_position_std_m: f64,
    /// Camera-derived speed noise (m/s, 1 sigma).
    pub camera_speed_std_mps: f64,
    /// Where the marker the camera tracks sits on the vehicle, forward and starboard of the
    /// centre of mass (m); `[0, 0]` when not stated.
    pub camera_marker_body_m: [f64; 2],
}

/// The commands in force at non-decreasing times ([`Measurement::commands_in_order`]).
#[derive(Debug)]
pub struct CommandCursor<'a> {
    rows: &'a [CommandRow],
    /// The first row after the time last asked for.
    next: usize,
}

impl CommandCursor<'_> {
    /// The percentages in force at `t_s`; a time earlier than the last one asked for starts
    /// the search again from the first row.
    pub fn at(&mut self, t_s: f64) -> [f64; 4] {
        if self.next > 0 && self.rows[self.next - 1].t_s > t_s + 1e-9 {
            self.next = 0;
        }
        while self.next < self.rows.len() && self.rows[self.next].t_s <= t_s + 1e-9 {
            self.next += 1;
        }
        self.next
            .checked_sub(1)
            .map_or([0.0; 4], |k| self.rows[k].percent)
    }
}

/// One `commands.csv` row: MOTORDrive percent for port, starboard, bow, stern from `t_s` on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandRow {
    pub t_s: f64,
    pub percent: [f64; 4],
}

/// One measured channel: samples `(t_s, value)` in time order (empty cells left out).
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    pub name: String,
    pub samples: Vec<(f64, f64)>,
}

/// A measurement directory, loaded and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    pub experiment: ExperimentInfo,
    pub commands: Vec<CommandRow>,
    pub channels: Vec<Channel>,
    /// Things the loader tolerated (extra columns), to be shown to the user.
    pub notices: Vec<String>,
}

impl Measurement {
    /// Reads `experiment.toml`, `commands.csv` and `measured.csv` from `dir`.
    pub fn load(dir: &Path) -> Result<Self, GapError> {
        if dir.is_dir() && !FILES.iter().any(|name| dir.join(name).exists()) {
            return Err(GapError::Data(format!(
                "{}: not a measurement directory: expected {} (docs/gap.md, \"A measurement: a \
                 directory of three files\"; `eyebot-hil gap convert` makes one from a recording)",
                dir.display(),
                FILES.join(", ")
            )));
        }
        let read = |name: &str| {
            let path = dir.join(name);
            std::fs::read_to_string(&path).map_err(|source| GapError::Io { path, source })
        };
        let exp = read("experiment.toml")?;
        let cmd = read("commands.csv")?;
        let meas = read("measured.csv")?;
        let origin = |n: &str| dir.join(n).display().to_string();
        Self::from_texts(
            (&origin("experiment.toml"), &exp),
            (&origin("commands.csv"), &cmd),
            (&origin("measured.csv"), &meas),
        )
    }

    /// Parses the three files from text; each pair is (origin for messages, text).
    pub fn from_texts(
        experiment: (&str, &str),
        commands: (&str, &str),
        measured: (&str, &str),
    ) -> Result<Self, GapError> {
        let info = parse_experiment(experiment.0, experiment.1)?;
        let commands = parse_commands(commands.0, commands.1, info.duration_s)?;
        let mut notices = Vec::new();
        let mut channels = parse_measured(measured.0, measured.1, &mut notices)?;
        crate::gap::outliers::set_aside(measured.0, &mut channels, &mut notices);
        Ok(Self {
            experiment: info,
            commands,
            channels,
            notices,
        })
    }

    /// The channel called `name`, if measured.
    pub fn channel(&self, name: &str) -> Option<&Channel> {
        self.channels.iter().find(|c| c.name == name)
    }

    /// MOTORDrive percentages in force at `t_s`.
    pub fn percent_at(&self, t_s: f64) -> [f64; 4] {
        // Rows are in time order (loading refuses others): the last row at or before `t_s`,
        // found by bisection, as the re-simulation asks for every step.
        let n = self.commands.partition_point(|c| c.t_s <= t_s + 1e-9);
        n.checked_sub(1)
            .map_or([0.0; 4], |k| self.commands[k].percent)
    }

    /// [`Measurement::percent_at`] for times read in order, as a re-simulation reads them:
    /// each call moves on from where the last one stopped instead of bisecting again.
    pub fn commands_in_order(&self) -> CommandCursor<'_> {
        CommandCursor {
            rows: &self.commands,
            next: 0,
        }
    }

    /// Writes the three files into `dir` (created if needed).
    pub fn write(&self, dir: &Path) -> Result<(), GapError> {
        std::fs::create_dir_all(dir).map_err(|source| GapError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let write = |name: &str, text: String| {
            let path = dir.join(name);
            std::fs::write(&path, text).map_err(|source| GapError::Io { path, source })
        };
        write("experiment.toml", self.experiment_toml()?)?;
        write("commands.csv", self.commands_csv()?)?;
        write("measured.csv", self.measured_csv()?)
    }

    /// `experiment.toml`, written by the `toml` crate from the same raw types the loader reads.
    fn experiment_toml(&self) -> Result<String, GapError> {
        let e = &self.experiment;
        let i = &e.initial;
        let raw = RawExperiment {
            name: e.name.clone(),
            description: e.description.clone(),
            duration_s: e.duration_s,
            world: e.world.clone(),
            sensors: e.sensors.clone(),
            initial: RawInitial {
                x_m: i.x_m,
                y_m: i.y_m,
                z_m: i.z_m,
                heading_deg: i.heading_deg,
                roll_deg: i.roll_deg,
                pitch_deg: i.pitch_deg,
                surge_mps: i.surge_mps,
            },
            camera: Some(RawCamera {
                position_std_m: e.camera_position_std_m,
                speed_std_mps: e.camera_speed_std_mps,
                marker_body_m: e.camera_marker_body_m,
            }),
        };
        let body = toml::to_string(&raw)
            .map_err(|e| GapError::Data(format!("experiment.toml cannot be written: {e}")))?;
        Ok(format!("{EXPERIMENT_UNITS}{body}"))
    }

    /// `commands.csv`: one row per command change.
    fn commands_csv(&self) -> Result<String, GapError> {
        let mut w = csv_writer();
        for row in &self.commands {
            let [port, starboard, bow, stern] = row.percent;
            w.serialize(CommandCsvRow {
                t_s: row.t_s,
                port,
                starboard,
                bow,
                stern,
            })
            .map_err(csv_write_error("commands.csv"))?;
        }
        csv_text(w, "commands.csv")
    }

    /// `measured.csv`: one row per distinct sample time, empty cells where a channel has none.
    fn measured_csv(&self) -> Result<String, GapError> {
        let mut times: Vec<f64> = self
            .channels
            .iter()
            .flat_map(|c| c.samples.iter().map(|(t, _)| *t))
            .collect();
        times.sort_by(f64::total_cmp);
        times.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        let mut cursors = vec![0usize; self.channels.len()];
        let mut w = csv_writer();
        let header = std::iter::once("t_s").chain(self.channels.iter().map(|c| c.name.as_str()));
        w.write_record(header)
            .map_err(csv_write_error("measured.csv"))?;
        for t in times {
            let mut cells = vec![format!("{t:.3}")];
            for (c, k) in self.channels.iter().zip(cursors.iter_mut()) {
                match c.samples.get(*k) {
                    Some((tc, v)) if (tc - t).abs() < 1e-9 => {
                        cells.push(format!("{v:.6}"));
                        *k += 1;
                    }
                    _ => cells.push(String::new()),
                }
            }
            w.write_record(&cells)
                .map_err(csv_write_error("measured.csv"))?;
        }
        csv_text(w, "measured.csv")
    }
}

/// What the numbers of `experiment.toml` are in (the `toml` crate writes no comments).
const EXPERIMENT_UNITS: &str = "# duration_s: s; initial x_m, y_m (north, east), z_m (depth of the centre of mass): m;\n\
# angles: deg; surge_mps: m/s; camera noise: 1 sigma, m and m/s\n\n";

/// One `commands.csv` row as written (the header is `COMMANDS_HEADER`).
#[derive(Debug, Serialize)]
struct CommandCsvRow {
    t_s: f64,
    port: f64,
    starboard: f64,
    bow: f64,
    stern: f64,
}

fn csv_writer() -> csv::Writer<Vec<u8>> {
    csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new())
}

fn csv_write_error(file: &'static str) -> impl Fn(csv::Error) -> GapError {
    move |e| GapError::Data(format!("{file} cannot be written: {e}"))
}

fn csv_text(w: csv::Writer<Vec<u8>>, file: &'static str) -> Result<String, GapError> {
    let bytes = w
        .into_inner()
        .map_err(|e| GapError::Data(format!("{file} cannot be written: {e}")))?;
    String::from_utf8(bytes).map_err(|e| GapError::Data(format!("{file} is not UTF-8: {e}")))
}

fn parse_experiment(origin: &str, text: &str) -> Result<ExperimentInfo, GapError> {
    let doc = Document::new(origin, text);
    let raw: RawExperiment = doc.parse()?;
    let i = &raw.initial;
    let check = |k: &str, v: f64, lo: f64, hi: f64, u: &str| -> Result<f64, ConfigError> {
        doc.check_range(k, v, lo, hi, u)
    };
    let (pos_std, speed_std, marker) = match &raw.camera {
        Some(c) => (
            check("camera.position_std_m", c.position_std_m, 1e-4, 1.0, "m")?,
            check("camera.speed_std_mps", c.speed_std_mps, 1e-4, 1.0, "m/s")?,
            [
                check("camera.marker_body_m.0", c.marker_body_m[0], -2.0, 2.0, "m")?,
                check("camera.marker_body_m.1", c.marker_body_m[1], -2.0, 2.0, "m")?,
            ],
        ),
        None => (0.01, default_speed_std(), [0.0; 2]),
    };
    Ok(ExperimentInfo {
        duration_s: check("duration_s", raw.duration_s, 0.1, 3600.0, "s")?,
        initial: Initial {
            x_m: check("initial.x_m", i.x_m, 0.0, 1e3, "m")?,
            y_m: check("initial.y_m", i.y_m, 0.0, 1e3, "m")?,
            z_m: match i.z_m {
                Some(z) => Some(check("initial.z_m", z, -0.5, 100.0, "m")?),
                None => None,
            },
            heading_deg: check("initial.heading_deg", i.heading_deg, -360.0, 360.0, "deg")?,
            roll_deg: check("initial.roll_deg", i.roll_deg, -90.0, 90.0, "deg")?,
            pitch_deg: check("initial.pitch_deg", i.pitch_deg, -90.0, 90.0, "deg")?,
            surge_mps: check("initial.surge_mps", i.surge_mps, -2.0, 2.0, "m/s")?,
        },
        name: raw.name,
        description: raw.description,
        world: raw.world,
        sensors: raw.sensors,
        camera_position_std_m: pos_std,
        camera_speed_std_mps: speed_std,
        camera_marker_body_m: marker,
    })
}

fn csv_error(origin: &str, line: usize, column: &str, message: impl Into<String>) -> GapError {
    GapError::Csv {
        origin: origin.to_string(),
        line,
        column: column.to_string(),
        message: message.into(),
    }
}

/// Reads a CSV text with the `csv` crate: (line number, cells trimmed) for each row that is
/// not empty and not a `#` comment.
fn rows(origin: &str, text: &str) -> Result<Vec<(usize, Vec<String>)>, GapError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut out = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line() as usize);
            csv_error(origin, line, "", e.to_string())
        })?;
        if record.iter().all(str::is_empty) {
            continue;
        }
        let line = record.position().map_or(0, |p| p.line() as usize);
        out.push((line, record.iter().map(str::to_string).collect()));
    }
    Ok(out)
}

fn number(origin: &str, line: usize, column: &str, cell: &str) -> Result<f64, GapError> {
    let v: f64 = cell.parse().map_err(|_| {
        csv_error(
            origin,
            line,
            column,
            format!("expected a number, found `{cell}`"),
        )
    })?;
    if !v.is_finite() {
        return Err(csv_error(origin, line, column, "value is not finite"));
    }
    Ok(v)
}

fn parse_commands(origin: &str, text: &str, duration_s: f64) -> Result<Vec<CommandRow>, GapError> {
    let mut it = rows(origin, text)?.into_iter();
    let (hl, header) = it
        .next()
        .ok_or_else(|| csv_error(origin, 1, "", "empty file: expected the header"))?;
    let expected: Vec<&str> = COMMANDS_HEADER.split(',').collect();
    if header
        .iter()
        .map(String::as_str)
        .ne(expected.iter().copied())
    {
        return Err(csv_error(
            origin,
            hl,
            "",
            format!(
                "expected the header `{COMMANDS_HEADER}`, found `{}`",
                header.join(",")
            ),
        ));
    }
    let mut out: Vec<CommandRow> = Vec::new();
    for (line, cells) in it {
        if cells.len() != 5 {
            return Err(csv_error(
                origin,
                line,
                "",
                format!("expected 5 cells, found {}", cells.len()),
            ));
        }
        let t_s = number(origin, line, "t_s", &cells[0])?;
        if t_s < 0.0 || t_s > duration_s {
            return Err(csv_error(
                origin,
                line,
                "t_s",
                format!("{t_s} s is outside the experiment (0..{duration_s} s)"),
            ));
        }
        if out.last().is_some_and(|p| t_s < p.t_s) {
            return Err(csv_error(origin, line, "t_s", "rows must be in time order"));
        }
        let mut percent = [0.0; 4];
        for j in 0..4 {
            let p = number(origin, line, expected[j + 1], &cells[j + 1])?;
            if !(-100.0..=100.0).contains(&p) {
                return Err(csv_error(
                    origin,
                    line,
                    expected[j + 1],
                    format!("{p} is outside -100..100 % (MOTORDrive)"),
                ));
            }
            percent[j] = p;
        }
        out.push(CommandRow { t_s, percent });
    }
    if out.is_empty() {
        return Err(csv_error(origin, hl, "", "no command rows"));
    }
    Ok(out)
}

fn parse_measured(
    origin: &str,
    text: &str,
    notices: &mut Vec<String>,
) -> Result<Vec<Channel>, GapError> {
    let mut it = rows(origin, text)?.into_iter();
    let (hl, header) = it
        .next()
        .ok_or_else(|| csv_error(origin, 1, "", "empty file: expected the header"))?;
    if header.first().map(String::as_str) != Some("t_s") {
        return Err(csv_error(
            origin,
            hl,
            header.first().map_or("", String::as_str),
            "the first column must be `t_s`",
        ));
    }
    // Column index -> channel slot (None = ignored).
    let mut slots: Vec<Option<usize>> = vec![None];
    let mut channels: Vec<Channel> = Vec::new();
    for name in &header[1..] {
        if CHANNELS.contains(&name.as_str()) {
            if channels.iter().any(|c| c.name == *name) {
                return Err(csv_error(origin, hl, name, "column appears twice"));
            }
            slots.push(Some(channels.len()));
            channels.push(Channel {
                name: name.clone(),
                samples: Vec::new(),
            });
        } else {
            notices.push(format!(
                "{origin}:{hl}: column `{name}` is not a channel gap knows; ignored"
            ));
            slots.push(None);
        }
    }
    if channels.is_empty() {
        return Err(csv_error(
            origin,
            hl,
            "",
            format!("no known channel; expected some of {}", CHANNELS.join(", ")),
        ));
    }
    let mut last_t = f64::NEG_INFINITY;
    for (line, cells) in it {
        if cells.len() != header.len() {
            return Err(csv_error(
                origin,
                line,
                "",
                format!(
                    "expected {} cells (as the header), found {}",
                    header.len(),
                    cells.len()
                ),
            ));
        }
        let t = number(origin, line, "t_s", &cells[0])?;
        if t < last_t {
            return Err(csv_error(origin, line, "t_s", "rows must be in time order"));
        }
        last_t = t;
        for (k, cell) in cells.iter().enumerate().skip(1) {
            let Some(slot) = slots[k] else { continue };
            if cell.is_empty() {
                continue;
            }
            let v = number(origin, line, &header[k], cell)?;
            channels[slot].samples.push((t, v));
        }
    }
    Ok(channels)
}

#[cfg(test)]
mod tests {
    use super::*;

    proptest::proptest! {
        /// The command in force is the last row at or before the time (within 1 ns), rows
        /// at the same time the last of them, and none before the first row: what a scan from
        /// the start gives, found by bisection.
        #[test]
        fn the_command_in_force_is_the_last_row_not_after_the_time(
            steps in proptest::collection::vec((0u8..4, -100.0f64..100.0), 1..40),
            query in -1.0f64..50.0,
        ) {
            let mut t = 0.0;
            let commands: Vec<CommandRow> = steps
                .iter()
                .map(|(dt, p)| {
                    t += f64::from(*dt) * 0.5;
                    CommandRow { t_s: t, percent: [*p, -*p, 0.0, 1.0] }
                })
                .collect();
            let mut m = Measurement::from_texts(
                ("e", EXP),
                ("c", "t_s,port,starboard,bow,stern\n0,0,0,0,0\n"),
                ("m", "t_s,x_m\n0.0,1.0\n"),
            )
            .unwrap();
            m.commands = commands.clone();
            // Every row read: the last one at or before the time wins.
            let scan = |t: f64| {
                commands
                    .iter()
                    .fold([0.0; 4], |now, c| if c.t_s <= t + 1e-9 { c.percent } else { now })
            };
            proptest::prop_assert_eq!(m.percent_at(query), scan(query));
            for c in &commands {
                proptest::prop_assert_eq!(m.percent_at(c.t_s), scan(c.t_s));
            }
            // Read in order, in steps that land on rows, between them and on several rows at
            // one time; then once back to the query.
            let mut cursor = m.commands_in_order();
            for k in 0..=(t / 0.25).ceil() as usize + 2 {
                let at = k as f64 * 0.25 - 0.5;
                proptest::prop_assert_eq!(cursor.at(at), scan(at));
            }
            proptest::prop_assert_eq!(cursor.at(query), scan(query));
        }
    }

    const EXP: &str =
        "name = \"t\"\nduration_s = 10.0\n[initial]\nx_m = 1.0\ny_m = 2.0\nheading_deg = 0.0\n";

    #[test]
    fn loads_a_minimal_measurement_and_notes_extra_columns() {
        let m = Measurement::from_texts(
            ("e", EXP),
            (
                "c",
                "t_s,port,starboard,bow,stern\n0,50,50,0,0\n5,0,0,0,0\n",
            ),
            (
                "m",
                "t_s,x_m,extra,compass_deg\n0.0,1.0,9,\n0.2,1.01,9,12\n",
            ),
        )
        .unwrap();
        assert_eq!(m.commands.len(), 2);
        assert_eq!(m.channel("x_m").unwrap().samples.len(), 2);
        assert_eq!(m.channel("compass_deg").unwrap().samples, vec![(0.2, 12.0)]);
        assert_eq!(m.notices.len(), 1);
        assert!(m.notices[0].contains("extra"), "{:?}", m.notices);
        assert_eq!(m.percent_at(6.0), [0.0; 4]);
        assert_eq!(m.percent_at(1.0), [50.0, 50.0, 0.0, 0.0]);
    }

    #[test]
    fn bad_cell_names_file_line_and_column() {
        let err = Measurement::from_texts(
            ("e", EXP),
            ("cmd.csv", "t_s,port,starboard,bow,stern\n0,50,abc,0,0\n"),
            ("m", "t_s,x_m\n0,1\n"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("cmd.csv:2") && err.contains("starboard"),
            "{err}"
        );
        let err = Measurement::from_texts(
            ("e", EXP),
            ("c", "t_s,port,starboard,bow,stern\n0,150,0,0,0\n"),
            ("m", "t_s,x_m\n0,1\n"),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("-100..100"), "{err}");
        let err = Measurement::from_texts(
            ("e", EXP),
            ("c", "t_s,port,starboard,bow,stern\n0,0,0,0,0\n"),
            ("meas.csv", "t_s,x_m\n0,1\n1,nan\n"),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("meas.csv:3") && err.contains("x_m"), "{err}");
    }

    #[test]
    fn write_then_load_round_trips() {
        let m = Measurement::from_texts(
            ("e", EXP),
            ("c", "t_s,port,starboard,bow,stern\n0,50,50,0,0\n"),
            (
                "m",
                "t_s,x_m,y_m\n0.000,1.000000,\n0.200,1.010000,2.000000\n",
            ),
        )
        .unwrap();
        let scratch = crate::scratch::dir("gap-format");
        let dir = scratch.path().join("m");
        m.write(&dir).unwrap();
        let back = Measurement::load(&dir).unwrap();
        assert_eq!(back.channels, m.channels);
        assert_eq!(back.commands, m.commands);
    }

    /// `[camera] marker_body_m` states where the tracked marker sits: read, written back, and
    /// refused out of range with its key; absent, the centre of mass.
    #[test]
    fn a_stated_camera_marker_is_read_written_and_checked() {
        let commands = "t_s,port,starboard,bow,stern\n0,0,0,0,0\n";
        let with = |camera: &str| {
            Measurement::from_texts(
                ("e", &format!("{EXP}[camera]\n{camera}\n")),
                ("c", commands),
                ("m", "t_s,x_m\n0,1\n"),
            )
        };
        let m = with("position_std_m = 0.01\nmarker_body_m = [0.11, -0.02]").unwrap();
        assert_eq!(m.experiment.camera_marker_body_m, [0.11, -0.02]);
        let scratch = crate::scratch::dir("gap-format-marker");
        m.write(scratch.path()).unwrap();
        let back = Measurement::load(scratch.path()).unwrap();
        assert_eq!(back.experiment.camera_marker_body_m, [0.11, -0.02]);
        let plain = Measurement::from_texts(("e", EXP), ("c", commands), ("m", "t_s,x_m\n0,1\n"));
        assert_eq!(plain.unwrap().experiment.camera_marker_body_m, [0.0; 2]);
        let err = with("position_std_m = 0.01\nmarker_body_m = [3.0, 0.0]")
            .unwrap_err()
            .to_string();
        assert!(err.contains("camera.marker_body_m.0"), "{err}");
    }

    /// A directory with none of the three files is named as not a measurement, with what one
    /// holds; a missing file of a started one is named.
    #[test]
    fn an_empty_directory_says_what_a_measurement_holds() {
        let scratch = crate::scratch::dir("gap-format-empty");
        let err = Measurement::load(scratch.path()).unwrap_err().to_string();
        assert!(
            err.contains("not a measurement directory")
                && err.contains("experiment.toml, commands.csv, measured.csv"),
            "{err}"
        );
        std::fs::write(scratch.path().join("experiment.toml"), EXP).unwrap();
        let err = Measurement::load(scratch.path()).unwrap_err().to_string();
        assert!(err.contains("commands.csv"), "{err}");
    }

    /// What `write` makes reads back through `csv::Reader` and `toml` as the same values,
    /// quoted cells and comments included.
    #[test]
    fn written_files_read_back_with_the_crates() {
        let m = Measurement::from_texts(
            ("e", EXP),
            (
                "c",
                "# a comment\nt_s,port,starboard,bow,stern\n0, 50 ,\"50\",0,0\n2.5,-12.5,0,0,0\n",
            ),
            ("m", "t_s,x_m\n0,1\n"),
        )
        .unwrap();
        assert_eq!(m.commands[0].percent, [50.0, 50.0, 0.0, 0.0]);
        let text = m.commands_csv().unwrap();
        let mut r = csv::Reader::from_reader(text.as_bytes());
        let back: Vec<(f64, f64, f64, f64, f64)> = r.deserialize().map(Result::unwrap).collect();
        assert_eq!(
            back,
            vec![(0.0, 50.0, 50.0, 0.0, 0.0), (2.5, -12.5, 0.0, 0.0, 0.0)]
        );
        assert_eq!(
            r.headers().unwrap().iter().collect::<Vec<_>>().join(","),
            COMMANDS_HEADER
        );
        let raw: RawExperiment = toml::from_str(&m.experiment_toml().unwrap()).unwrap();
        assert_eq!(raw.duration_s, 10.0);
        assert_eq!(raw.initial.y_m, 2.0);
    }
}
