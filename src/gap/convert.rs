//! `eyebot-hil gap convert RECORD_DIR --out MEAS_DIR`: a daemon recording (`--record`,
//! `docs/recording.md`) turned into the measured-data format (`docs/gap.md`).
//!
//! - `commands.csv`: the thruster frames the EyeBot sent (THRUSTER_SET, THRUSTER_SET_ALL;
//!   HELLO switches all off), decoded with `firmware-protocol` and mapped back from PWM duty and
//!   direction to MOTORDrive percent through the inverse of the vehicle's HDT table.
//! - `measured.csv`: the sensor replies the bridge sent, decoded: `depth_adc` and
//!   `accel_*_adc` from ADC_VALUE and ADC_SAMPLES (channel meaning from the sensor config's
//!   analog table), `compass_deg` from COMPASS_HEADING words (binary or BCD, as the EyeBot set
//!   the compass), `paddle_speed_mps` by counting the velocity channel's pulses per window as
//!   the firmware does, and `sonar1_m..sonar4_m` from `$PEBHS` echo reports (a plain depth
//!   sentence does not say which transducer pinged, so it is counted and left out).
//! - `experiment.toml`: the set-up: the initial state from the first ground-truth row of
//!   `state.csv`, world and sensors from the recorded daemon configuration.
//!
//! Nothing in `measured.csv` is copied from ground truth. The optional camera track
//! (`x_m`, `y_m`; off unless `camera_std_m` is given) is the ground-truth position plus seeded
//! Gaussian noise of that size, standing in for the thesis's overhead camera; the noise is
//! written into `experiment.toml` as the camera's `position_std_m`.

use std::collections::BTreeMap;
use std::path::Path;

use bytes::BytesMut;
use firmware_protocol::compass_word::HeadingFormat;
use firmware_protocol::line::{LineDecoder, LineItem};
use firmware_protocol::nmea::Sentence;
use firmware_protocol::sensor_link::{CompassOutput, Direction as WireDirection, Message};
use rand::RngExt;
use rand_distr::StandardNormal;

use crate::config::Document;
use crate::gap::GapError;
use crate::gap::format::{Channel, CommandRow, ExperimentInfo, Initial, Measurement};
use crate::gap::model::read_ref;
use crate::physics::VehicleConfig;
use crate::record::{self, Direction};
use crate::sensors::{AdcBoard, AdcSource, SensorsConfig, rng};

/// What `convert` needs besides the recording.
#[derive(Debug, Clone, Default)]
pub struct ConvertOptions {
    /// Vehicle config (for the HDT tables); default: the recorded configuration's, else
    /// `vehicles/mako.toml`.
    pub vehicle: Option<String>,
    /// Sensor config (analog table, compass, velocity sensor); default as above.
    pub sensors: Option<String>,
    /// World config written into `experiment.toml`; default as above.
    pub world: Option<String>,
    /// Derive an overhead-camera track from ground truth with this noise (m, 1 sigma).
    pub camera_std_m: Option<f64>,
    /// Seed of the camera noise.
    pub seed: u64,
}

/// A converted recording and what the converter had to leave out.
#[derive(Debug, Clone)]
pub struct Conversion {
    pub measurement: Measurement,
    pub notices: Vec<String>,
}

/// Top-level `key = "value"` of the daemon configuration copied as comments into
/// `meta.toml` (`docs/recording.md`).
fn recorded_key(meta: &str, key: &str) -> Option<String> {
    for line in meta.lines() {
        let l = line.trim_start_matches('#').trim();
        if l.starts_with('[') {
            break; // keys after the first table belong to it
        }
        if let Some((k, v)) = l.split_once('=')
            && k.trim() == key
        {
            let v = v.split('#').next().unwrap_or("").trim().trim_matches('"');
            if !v.is_empty() {
                return Some(v.to_string());
            }
        }
    }
    None
}

/// MOTORDrive percent for a duty and direction: the inverse of `hdt_command` (table
/// decreasing from 0 % to 100 %). Duties inside the first segment (the deadband) come back as
/// fractions of 10 %, which map to the same duty again.
pub fn percent_from_duty(table: &[f64; 11], duty: u8, direction: WireDirection) -> f64 {
    let d = f64::from(duty);
    let mut p = if d >= table[0] { 0.0 } else { 100.0 };
    for i in 0..10 {
        let (hi, lo) = (table[i], table[i + 1]);
        if d <= hi && d >= lo {
            p = if hi > lo {
                10.0 * (i as f64 + (hi - d) / (hi - lo))
            } else {
                10.0 * i as f64
            };
            break;
        }
    }
    match direction {
        WireDirection::Forward => p,
        WireDirection::Reverse => -p,
    }
}

fn csv_err(origin: &Path, line: usize, column: &str, message: impl Into<String>) -> GapError {
    GapError::Csv {
        origin: origin.display().to_string(),
        line,
        column: column.to_string(),
        message: message.into(),
    }
}

/// One ground-truth row: (t_s, columns by name).
type StateRow = (f64, BTreeMap<String, f64>);

/// Ground-truth rows of `state.csv`.
fn read_state(path: &Path) -> Result<Vec<StateRow>, GapError> {
    let text = std::fs::read_to_string(path).map_err(|source| GapError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut lines = text.lines().enumerate();
    let Some((_, header)) = lines.next() else {
        return Err(csv_err(path, 1, "", "empty file, expected a header"));
    };
    let names: Vec<&str> = header.split(',').collect();
    if names.first() != Some(&"t_s") {
        return Err(csv_err(path, 1, "t_s", "the first column must be t_s"));
    }
    let mut rows = Vec::new();
    for (i, l) in lines {
        if l.trim().is_empty() {
            continue;
        }
        let mut row = BTreeMap::new();
        for (name, cell) in names.iter().zip(l.split(',')) {
            let v: f64 = cell
                .trim()
                .parse()
                .map_err(|_| csv_err(path, i + 1, name, format!("`{cell}` is not a number")))?;
            row.insert((*name).to_string(), v);
        }
        let t = row.get("t_s").copied().unwrap_or(f64::NAN);
        if !t.is_finite() {
            return Err(csv_err(path, i + 1, "t_s", "missing or not finite"));
        }
        rows.push((t, row));
    }
    if rows.is_empty() {
        return Err(csv_err(
            path,
            2,
            "t_s",
            "no ground-truth rows: nothing to start from",
        ));
    }
    Ok(rows)
}

/// Converts the recording in `dir`.
pub fn convert(dir: &Path, opts: &ConvertOptions) -> Result<Conversion, GapError> {
    let meta = std::fs::read_to_string(dir.join("meta.toml")).unwrap_or_default();
    let pick = |given: &Option<String>, key: &str, default: &str| {
        given
            .clone()
            .or_else(|| recorded_key(&meta, key))
            .unwrap_or_else(|| default.to_string())
    };
    let vehicle_ref = pick(&opts.vehicle, "vehicle", crate::physics::DEFAULT_VEHICLE);
    let sensors_ref = pick(&opts.sensors, "sensors", "sensors/mako-2008.toml");
    let world_ref = pick(&opts.world, "world", crate::physics::DEFAULT_WORLD);
    let (o, t) = read_ref(dir, &vehicle_ref)?;
    let vehicle = VehicleConfig::from_document(&Document::new(o, &t))?;
    let (o, t) = read_ref(dir, &sensors_ref)?;
    let sensors = SensorsConfig::from_text(o, &t)?;
    let tables: [[f64; 11]; 4] = std::array::from_fn(|k| vehicle.thrusters[k].hdt_duty);

    let state_path = dir.join("state.csv");
    let states = read_state(&state_path)?;
    let (t0, first) = &states[0];
    let t0 = *t0;
    let get = |k: &str| -> Result<f64, GapError> {
        first
            .get(k)
            .copied()
            .ok_or_else(|| csv_err(&state_path, 2, k, "missing column"))
    };
    let initial = Initial {
        x_m: get("x_m")?,
        y_m: get("y_m")?,
        z_m: Some(get("z_m")?),
        heading_deg: get("yaw_rad")?.to_degrees(),
        roll_deg: get("roll_rad")?.to_degrees(),
        pitch_deg: get("pitch_rad")?.to_degrees(),
        surge_mps: get("u_mps")?,
    };

    // Decode every link and direction in order.
    let bytes_path = dir.join("bytes.tsv");
    let text = std::fs::read_to_string(&bytes_path).map_err(|source| GapError::Io {
        path: bytes_path.clone(),
        source,
    })?;
    let mut notices = Vec::new();
    let mut decoders: BTreeMap<(String, &'static str), (LineDecoder, BytesMut)> = BTreeMap::new();
    let mut percent = [0.0; 4];
    let mut commands: Vec<CommandRow> = vec![CommandRow { t_s: 0.0, percent }];
    let mut format = HeadingFormat::Binary;
    let mut tick_s = 0.01;
    let mut samples: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    let mut velocity_codes: Vec<(f64, f64)> = Vec::new();
    let (mut ambiguous_sonar, mut raw_compass, mut link_errors) = (0usize, 0usize, 0usize);
    let adc_name = |ch: u8| -> Option<AdcSource> { *sensors.adc.channels.get(usize::from(ch))? };
    for (i, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let chunk = record::parse_chunk(line, i + 1)
            .map_err(|e| GapError::Data(format!("{}: {e}", bytes_path.display())))?;
        let t = chunk.sim_s - t0;
        let key = (chunk.link.clone(), chunk.dir.as_str());
        let (decoder, buf) = decoders.entry(key).or_default();
        buf.extend_from_slice(&chunk.data);
        while let Some(item) = decoder.decode(buf) {
            let frame = match item {
                LineItem::Frame(f) => f,
                LineItem::Nmea(Sentence::Echo(e)) if chunk.dir == Direction::Tx => {
                    if let Some(r) = e.range_m {
                        samples
                            .entry(format!("sonar{}_m", e.transducer.get()))
                            .or_default()
                            .push((t, f64::from(r.tenths()) / 10.0));
                    }
                    continue;
                }
                LineItem::Nmea(_) => {
                    if chunk.dir == Direction::Tx {
                        ambiguous_sonar += 1;
                    }
                    continue;
                }
                LineItem::Error(_) => {
                    link_errors += 1;
                    continue;
                }
                LineItem::Sonar(_) => continue,
            };
            match (chunk.dir, frame.message) {
                (Direction::Rx, Message::Hello { .. }) => {
                    percent = [0.0; 4];
                    format = HeadingFormat::Binary;
                }
                (Direction::Rx, Message::ThrusterSet { thruster, command }) => {
                    let k = thruster as usize;
                    if let Some(table) = tables.get(k) {
                        percent[k] = percent_from_duty(table, command.duty, command.direction);
                    }
                }
                (Direction::Rx, Message::ThrusterSetAll { commands: c }) => {
                    for k in 0..4 {
                        percent[k] = percent_from_duty(&tables[k], c[k].duty, c[k].direction);
                    }
                }
                (Direction::Rx, Message::CompassMode { output, .. }) => match output {
                    CompassOutput::Binary => format = HeadingFormat::Binary,
                    CompassOutput::Bcd => format = HeadingFormat::Bcd,
                    CompassOutput::Raw => {}
                },
                (Direction::Tx, Message::HelloReply { tick_us, .. }) => {
                    tick_s = f64::from(tick_us) * 1e-6;
                }
                (Direction::Tx, Message::AdcValue { channel, value }) => {
                    push_adc(
                        &mut samples,
                        &mut velocity_codes,
                        adc_name(channel.get()),
                        t,
                        f64::from(value.get()),
                    );
                }
                (Direction::Tx, Message::AdcSamples { ticks, samples: s }) => {
                    let ts = f64::from(ticks) * tick_s - t0;
                    for (channel, value) in s.iter() {
                        push_adc(
                            &mut samples,
                            &mut velocity_codes,
                            adc_name(channel.get()),
                            ts,
                            f64::from(value.get()),
                        );
                    }
                }
                (
                    Direction::Tx,
                    Message::CompassHeading { word } | Message::CompassHeadingPush { word },
                ) => {
                    if let Ok(h) = word.decode(format) {
                        samples
                            .entry("compass_deg".into())
                            .or_default()
                            .push((t, f64::from(h)));
                    }
                }
                (Direction::Tx, Message::CompassRaw { .. } | Message::CompassRawPush { .. }) => {
                    raw_compass += 1;
                }
                _ => {}
            }
            let last = commands.last().map(|c| c.percent);
            if last != Some(percent) {
                let t_cmd = t.max(0.0);
                match commands.last_mut() {
                    Some(c) if (c.t_s - t_cmd).abs() < 1e-12 => c.percent = percent,
                    _ => commands.push(CommandRow {
                        t_s: t_cmd,
                        percent,
                    }),
                }
            }
        }
    }
    if ambiguous_sonar > 0 {
        notices.push(format!(
            "{ambiguous_sonar} sonar depth sentences left out: a plain DBT/DPT does not say which \
             transducer pinged (enable the $PEBHS echo report to convert sonar ranges)"
        ));
    }
    if raw_compass > 0 {
        notices.push(format!(
            "{raw_compass} raw compass frames left out (only heading words are converted)"
        ));
    }
    if link_errors > 0 {
        notices.push(format!(
            "{link_errors} undecodable stretches of bytes skipped"
        ));
    }
    if let Some(speed) = paddle_speed(&velocity_codes, &sensors) {
        samples.insert("paddle_speed_mps".into(), speed);
    }
    let last_state = states.last().map_or(t0, |(t, _)| *t);
    let duration_s = last_state - t0;
    if duration_s <= 0.0 {
        return Err(GapError::Data(format!(
            "{}: the recording covers no simulated time",
            state_path.display()
        )));
    }
    let mut camera_std = 0.01;
    if let Some(std) = opts.camera_std_m {
        if !(std.is_finite() && std > 0.0) {
            return Err(GapError::Data(format!(
                "camera noise must be a positive number of metres, got {std}"
            )));
        }
        camera_std = std;
        let mut cam = rng::stream(opts.seed, "gap-convert-camera");
        let (mut xs, mut ys) = (Vec::new(), Vec::new());
        // The thesis's camera: a frame every 200 ms (4.5).
        let mut next = 0.0;
        for (t, row) in &states {
            let ts = t - t0;
            if ts + 1e-9 < next {
                continue;
            }
            next = ts + 0.2;
            if let (Some(x), Some(y)) = (row.get("x_m"), row.get("y_m")) {
                let (nx, ny): (f64, f64) = (cam.sample(StandardNormal), cam.sample(StandardNormal));
                xs.push((ts, x + std * nx));
                ys.push((ts, y + std * ny));
            }
        }
        samples.insert("x_m".into(), xs);
        samples.insert("y_m".into(), ys);
    }
    let channels: Vec<Channel> = crate::gap::format::CHANNELS
        .iter()
        .filter_map(|name| {
            let mut s = samples.remove(*name)?;
            s.retain(|(t, _)| *t >= 0.0 && *t <= duration_s);
            s.sort_by(|a, b| a.0.total_cmp(&b.0));
            s.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-9);
            (!s.is_empty()).then(|| Channel {
                name: (*name).to_string(),
                samples: s,
            })
        })
        .collect();
    if channels.is_empty() {
        return Err(GapError::Data(format!(
            "{}: the bridge sent no sensor replies that convert into measured channels",
            bytes_path.display()
        )));
    }
    commands.retain(|c| c.t_s <= duration_s);
    let name = dir.file_name().map_or_else(
        || "recording".to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    Ok(Conversion {
        measurement: Measurement {
            experiment: ExperimentInfo {
                name,
                description: format!(
                    "converted from the recording {} by `eyebot-hil gap convert`{}",
                    dir.display(),
                    if opts.camera_std_m.is_some() {
                        "; x_m, y_m: ground truth plus seeded camera noise"
                    } else {
                        ""
                    }
                ),
                duration_s,
                world: world_ref,
                sensors: sensors_ref,
                initial,
                camera_position_std_m: camera_std,
                camera_speed_std_mps: 0.02,
            },
            commands,
            channels,
            notices: Vec::new(),
        },
        notices,
    })
}

fn push_adc(
    samples: &mut BTreeMap<String, Vec<(f64, f64)>>,
    velocity: &mut Vec<(f64, f64)>,
    source: Option<AdcSource>,
    t: f64,
    code: f64,
) {
    let name = match source {
        Some(AdcSource::Depth) => "depth_adc",
        Some(AdcSource::AccelX) => "accel_x_adc",
        Some(AdcSource::AccelY) => "accel_y_adc",
        Some(AdcSource::AccelZ) => "accel_z_adc",
        Some(AdcSource::Velocity) => {
            velocity.push((t, code));
            return;
        }
        None => return,
    };
    samples.entry(name.into()).or_default().push((t, code));
}

/// The firmware's paddle-wheel speed: rising edges of the velocity channel (above half the
/// pulse level) counted over each `window_s`, times `firmware_scale / (pulses_per_metre *
/// window_s)`, one value at the end of each full window. `None` without enough samples.
fn paddle_speed(codes: &[(f64, f64)], sensors: &SensorsConfig) -> Option<Vec<(f64, f64)>> {
    let v = &sensors.velocity;
    let (first, last) = (codes.first()?.0, codes.last()?.0);
    if last - first < v.window_s {
        return None;
    }
    let lsb = AdcBoard::new(&sensors.adc, 0).lsb_v();
    let threshold = 0.5 * v.high_v.min(sensors.adc.reference_v) / lsb;
    let step = v.firmware_scale / (v.pulses_per_metre * v.window_s);
    let mut out = Vec::new();
    let mut end = first + v.window_s;
    let mut count = 0u32;
    let mut high = codes[0].1 > threshold;
    for &(t, c) in &codes[1..] {
        while t > end + 1e-9 {
            out.push((end, f64::from(count) * step));
            count = 0;
            end += v.window_s;
        }
        let now = c > threshold;
        if now && !high {
            count += 1;
        }
        high = now;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::hdt_command;

    const MAKO_TABLE: [f64; 11] = [
        255.0, 206.6, 183.6, 160.7, 137.7, 114.8, 91.8, 68.9, 45.9, 23.0, 0.0,
    ];

    /// Percent -> duty -> percent -> duty gives the same duty for every command the EyeBot
    /// can send (the converted commands drive the re-simulation to the same PWM).
    #[test]
    fn duty_to_percent_inverts_the_hdt_table() {
        for p10 in -1000..=1000 {
            let p = f64::from(p10) / 10.0;
            let c = hdt_command(&MAKO_TABLE, p);
            let dir = match c.direction {
                crate::physics::Direction::Forward => WireDirection::Forward,
                crate::physics::Direction::Reverse => WireDirection::Reverse,
            };
            let back = percent_from_duty(&MAKO_TABLE, c.duty, dir);
            let again = hdt_command(&MAKO_TABLE, back);
            assert_eq!(again.duty, c.duty, "{p} % -> duty {} -> {back} %", c.duty);
        }
        assert_eq!(
            percent_from_duty(&MAKO_TABLE, 0, WireDirection::Forward),
            100.0
        );
        assert_eq!(
            percent_from_duty(&MAKO_TABLE, 255, WireDirection::Reverse),
            -0.0
        );
    }

    #[test]
    fn recorded_keys_are_read_from_the_commented_configuration() {
        let meta = "version = \"0.1.0\"\nseed = 3\n# The daemon configuration used, verbatim:\n# vehicle = \"vehicles/x.toml\"   # note\n# [run]\n# sensors = \"no\"\n";
        assert_eq!(
            recorded_key(meta, "vehicle").as_deref(),
            Some("vehicles/x.toml")
        );
        assert_eq!(recorded_key(meta, "sensors"), None);
    }

    #[test]
    fn paddle_speed_counts_rising_edges_per_window() {
        let sensors =
            SensorsConfig::load(&crate::config::Embedded, "sensors/mako-2008.toml").unwrap();
        let lsb = AdcBoard::new(&sensors.adc, 0).lsb_v();
        let high = sensors.velocity.high_v.min(sensors.adc.reference_v) / lsb;
        // 4 pulses per second sampled every 10 ms for 3 s.
        let codes: Vec<(f64, f64)> = (0..300)
            .map(|k| {
                let t = f64::from(k) * 0.01;
                (t, if (t * 4.0).fract() < 0.5 { high } else { 0.0 })
            })
            .collect();
        let v = paddle_speed(&codes, &sensors).unwrap();
        let step = sensors.velocity.firmware_scale
            / (sensors.velocity.pulses_per_metre * sensors.velocity.window_s);
        assert!(v.len() >= 2, "{v:?}");
        for (_, s) in &v[1..] {
            assert!((s - 4.0 * step).abs() < 1e-9, "{v:?}");
        }
    }

    mod recording {
        use super::*;
        use firmware_protocol::sensor_link::{
            AdcChannel, AdcValue, CompassMode, Frame, Thruster, ThrusterCommand,
        };
        use firmware_protocol::{Dbt, EchoReport, HeadingWord, Talker, Transducer};

        fn frame(m: Message) -> Vec<u8> {
            let mut b = BytesMut::new();
            Frame::new(1, m).encode(&mut b);
            b.to_vec()
        }

        fn sentence(s: Sentence) -> Vec<u8> {
            let mut b = BytesMut::new();
            s.encode(&mut b).unwrap();
            b.to_vec()
        }

        fn row(sim: f64, link: &str, dir: &str, bytes: &[u8]) -> String {
            format!(
                "{sim:.9}\t0.000000\t{link}\t{dir}\t{}\n",
                hex::encode(bytes)
            )
        }

        fn wire(percent: f64) -> ThrusterCommand {
            let c = crate::physics::hdt_command(&MAKO_TABLE, percent);
            ThrusterCommand {
                duty: c.duty,
                direction: match c.direction {
                    crate::physics::Direction::Forward => WireDirection::Forward,
                    crate::physics::Direction::Reverse => WireDirection::Reverse,
                },
            }
        }

        fn write(dir: &Path, bytes: &str) {
            std::fs::create_dir_all(dir).unwrap();
            std::fs::write(dir.join("meta.toml"), "seed = 1\n").unwrap();
            std::fs::write(
                dir.join("bytes.tsv"),
                format!("{}\n{bytes}", record::BYTES_HEADER),
            )
            .unwrap();
            std::fs::write(
                dir.join("state.csv"),
                format!(
                    "{}\n0,1,2,0.3,0,0,0.5,0.1,0,0,0,0,0,0,0,0,0,0\n3,1.3,2,0.3,0,0,0.5,0.1,0,0,0,0,0,0,0,0,0,0\n",
                    record::STATE_HEADER
                ),
            )
            .unwrap();
        }

        /// Every decoded path of a hand-made recording: HELLO, COMPASS_MODE (BCD), both thruster
        /// frames, ADC values by the analog table, a compass word split across two chunks, an
        /// echo report and an unattributable DBT.
        #[test]
        fn a_hand_made_recording_converts_channel_by_channel() {
            let dir =
                std::env::temp_dir().join(format!("eyebot-hil-convert-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            let heading = frame(Message::CompassHeading {
                word: HeadingWord::encode(124, HeadingFormat::Bcd).unwrap(),
            });
            let mut bytes = String::new();
            bytes += &row(
                0.0,
                "sensor",
                "rx",
                &frame(Message::Hello { client_version: 1 }),
            );
            bytes += &row(
                0.5,
                "sensor",
                "rx",
                &frame(Message::CompassMode {
                    mode: CompassMode::Poll,
                    output: CompassOutput::Bcd,
                }),
            );
            bytes += &row(
                1.0,
                "sensor",
                "rx",
                &frame(Message::ThrusterSetAll {
                    commands: [wire(50.0), wire(50.0), wire(0.0), wire(0.0)],
                }),
            );
            bytes += &row(
                1.2,
                "sensor",
                "tx",
                &frame(Message::CompassHeading {
                    word: HeadingWord::encode(123, HeadingFormat::Bcd).unwrap(),
                }),
            );
            let adc = |c: u8, v: u16| {
                frame(Message::AdcValue {
                    channel: AdcChannel::new(c).unwrap(),
                    value: AdcValue::new(v).unwrap(),
                })
            };
            bytes += &row(1.3, "sensor", "tx", &[adc(0, 200), adc(2, 512)].concat());
            let t2 = Transducer::new(2).unwrap();
            bytes += &row(
                1.4,
                "sonar",
                "tx",
                &[
                    sentence(Sentence::Dbt(
                        Dbt::from_depth_m(Talker::new("SD").unwrap(), 3.2).unwrap(),
                    )),
                    sentence(Sentence::Echo(EchoReport::new(t2, Some(3.2), 87).unwrap())),
                ]
                .concat(),
            );
            bytes += &row(1.5, "sensor", "tx", &heading[..4]);
            bytes += &row(1.6, "sensor", "tx", &heading[4..]);
            bytes += &row(
                2.0,
                "sensor",
                "rx",
                &frame(Message::ThrusterSet {
                    thruster: Thruster::Stern,
                    command: wire(-30.0),
                }),
            );
            write(&dir, &bytes);
            let c = convert(&dir, &ConvertOptions::default()).unwrap();
            let m = &c.measurement;
            let ch = |n: &str| m.channel(n).map(|c| c.samples.clone()).unwrap_or_default();
            assert_eq!(ch("compass_deg"), vec![(1.2, 123.0), (1.6, 124.0)]);
            assert_eq!(ch("depth_adc"), vec![(1.3, 200.0)]);
            assert_eq!(ch("accel_x_adc"), vec![(1.3, 512.0)]);
            assert_eq!(ch("sonar2_m"), vec![(1.4, 3.2)]);
            assert!(m.channel("x_m").is_none(), "no camera track unless asked");
            assert_eq!(m.commands.len(), 3, "{:?}", m.commands);
            assert_eq!(m.commands[0].percent, [0.0; 4]);
            assert_eq!(m.commands[1].t_s, 1.0);
            assert!(
                (m.commands[1].percent[0] - 50.0).abs() < 0.5,
                "{:?}",
                m.commands
            );
            assert_eq!(m.commands[2].t_s, 2.0);
            assert!(
                (m.commands[2].percent[3] + 30.0).abs() < 0.5,
                "{:?}",
                m.commands
            );
            assert!((m.experiment.initial.heading_deg - 0.5f64.to_degrees()).abs() < 1e-9);
            assert_eq!(m.experiment.initial.z_m, Some(0.3));
            assert_eq!(m.experiment.duration_s, 3.0);
            assert!(
                c.notices
                    .iter()
                    .any(|n| n.starts_with("1 sonar depth sentences")),
                "{:?}",
                c.notices
            );

            // With a camera track: ground truth plus noise, never exactly ground truth.
            let opts = ConvertOptions {
                camera_std_m: Some(0.01),
                seed: 3,
                ..Default::default()
            };
            let c = convert(&dir, &opts).unwrap();
            let x = c.measurement.channel("x_m").unwrap();
            assert!(
                x.samples.iter().all(|(_, v)| *v != 1.0 && *v != 1.3),
                "{:?}",
                x.samples
            );
            assert_eq!(c.measurement.experiment.camera_position_std_m, 0.01);

            // A malformed line is an error naming the file and the line, not a panic.
            write(&dir, &format!("{bytes}0.5\tbad\n"));
            let err = convert(&dir, &ConvertOptions::default())
                .unwrap_err()
                .to_string();
            assert!(
                err.contains("bytes.tsv: bytes.tsv line 11: wall_unix_s"),
                "{err}"
            );
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
}
