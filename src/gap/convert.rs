//! `eyebot-hil gap convert RECORD_DIR --out MEAS_DIR`: a daemon recording (`--record`,
//! `docs/recording.md`) turned into the measured-data format (`docs/gap.md`).
//!
//! - `commands.csv`: the thruster frames the EyeBot sent (THRUSTER_SET, THRUSTER_SET_ALL, the
//!   thrusters of a TIME_STEP, at the request's time; HELLO switches all off), decoded with `firmware-protocol` and mapped back from PWM duty and
//!   direction to MOTORDrive percent through the inverse of the vehicle's HDT table.
//! - `measured.csv`: the sensor replies the bridge sent, decoded: `depth_adc` and
//!   `accel_*_adc` from ADC_VALUE and ADC_SAMPLES (channel meaning from the sensor config's
//!   analog table), `compass_deg` from COMPASS_HEADING words (binary or BCD, as the EyeBot set
//!   the compass), both also from the values of STEP replies (value i is the reading the
//!   TIME_STEP's code i asked for, at the reply's tick; only the values the EyeBot used count:
//!   those it took back, and those of a last reply it never answered, never happened,
//!   `firmware-protocol/PROTOCOL.md` 2.9), `paddle_speed_mps` by counting the velocity channel's pulses per window as
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

use firmware_protocol::sensor_link::Direction as WireDirection;
use rand::RngExt;
use rand_distr::StandardNormal;

use crate::config::Document;
use crate::gap::GapError;
use crate::gap::format::{Channel, CommandRow, ExperimentInfo, Initial, Measurement};
use crate::gap::model::read_ref;
use crate::physics::VehicleConfig;
use crate::record;
use crate::sensors::{AdcBoard, AdcSource, SensorsConfig, rng};
use crate::transcript::{Event, Transcript};

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

/// A recording that cannot be read, as the gap workflow reports it.
fn recording_error(e: record::ReadError) -> GapError {
    GapError::Data(e.to_string())
}

/// Converts the recording in `dir`.
pub fn convert(dir: &Path, opts: &ConvertOptions) -> Result<Conversion, GapError> {
    let recorded = record::read_model_files(dir).map_err(recording_error)?;
    let pick = |given: &Option<String>, recorded: &str| {
        given.clone().unwrap_or_else(|| recorded.to_string())
    };
    let vehicle_ref = pick(&opts.vehicle, &recorded.vehicle);
    let sensors_ref = pick(&opts.sensors, &recorded.sensors);
    let world_ref = pick(&opts.world, &recorded.world);
    let (o, t) = read_ref(dir, &vehicle_ref)?;
    let vehicle = VehicleConfig::from_document(&Document::new(o, &t))?;
    let (o, t) = read_ref(dir, &sensors_ref)?;
    let sensors = SensorsConfig::from_text(o, &t)?;
    let tables: [[f64; 11]; 4] = std::array::from_fn(|k| vehicle.thrusters[k].hdt_duty);

    let states = record::read_state(dir).map_err(recording_error)?;
    let state_path = dir.join(record::format::STATE_FILE);
    let Some(first) = states.first() else {
        return Err(GapError::Data(format!(
            "{}: no ground-truth rows: nothing to start from",
            state_path.display()
        )));
    };
    let t0 = first.t_s;
    let initial = Initial {
        x_m: first.x_m,
        y_m: first.y_m,
        z_m: Some(first.z_m),
        heading_deg: first.yaw_rad.to_degrees(),
        roll_deg: first.roll_rad.to_degrees(),
        pitch_deg: first.pitch_rad.to_degrees(),
        surge_mps: first.u_mps,
    };

    // Decode every link and direction in order.
    let bytes_path = dir.join(record::format::BYTES_FILE);
    let chunks = record::read_bytes(dir).map_err(recording_error)?;
    let Decoded {
        mut commands,
        mut samples,
        velocity_codes,
        mut notices,
    } = decode(&chunks, t0, &tables, &sensors);
    if let Some(compass) = samples.get_mut("compass_deg") {
        let merged = first_read_of_each_conversion(compass);
        if merged > 0 {
            notices.push(format!(
                "{merged} compass readings repeated the reading before them (the compass's \
                 last conversion read again) and were merged into its first read"
            ));
        }
    }
    if let Some(speed) = paddle_speed(&velocity_codes, &sensors) {
        samples.insert("paddle_speed_mps".into(), speed);
    }
    let last_state = states.last().map_or(t0, |row| row.t_s);
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
        let (xs, ys) = camera_track(&states, t0, std, opts.seed);
        samples.insert("x_m".into(), xs);
        samples.insert("y_m".into(), ys);
    }
    let channels = measured_channels(samples, duration_s);
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
                camera_marker_body_m: [0.0; 2],
            },
            commands,
            channels,
            notices: Vec::new(),
        },
        notices,
    })
}

/// What the recording's links said, in the measured-data format's terms.
struct Decoded {
    commands: Vec<CommandRow>,
    samples: BTreeMap<String, Vec<(f64, f64)>>,
    /// The velocity channel's codes, for the paddle-wheel count.
    velocity_codes: Vec<(f64, f64)>,
    notices: Vec<String>,
}

/// Decodes every link and direction in order through the one transcript decoder; times from
/// `t0`.
fn decode(
    chunks: &[record::ByteChunk],
    t0: f64,
    tables: &[[f64; 11]; 4],
    sensors: &SensorsConfig,
) -> Decoded {
    let mut transcript = Transcript::new();
    let mut commands: Vec<CommandRow> = vec![CommandRow {
        t_s: 0.0,
        percent: [0.0; 4],
    }];
    let mut samples: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    let mut velocity_codes: Vec<(f64, f64)> = Vec::new();
    let (mut ambiguous_sonar, mut raw_compass, mut link_errors) = (0usize, 0usize, 0usize);
    let adc_name = |ch: u8| -> Option<AdcSource> { *sensors.adc.channels.get(usize::from(ch))? };
    for chunk in chunks {
        let t = chunk.sim_s - t0;
        transcript.feed(
            chunk.sim_s,
            &chunk.link,
            chunk.dir,
            &chunk.data,
            |event| match event {
                Event::Thrusters { commands: c, .. } => {
                    let percent: [f64; 4] = std::array::from_fn(|k| {
                        c[k].map_or(0.0, |c| percent_from_duty(&tables[k], c.duty, c.direction))
                    });
                    add_command(&mut commands, t, percent);
                }
                Event::Adc {
                    t_s,
                    channel,
                    value,
                } => push_adc(
                    &mut samples,
                    &mut velocity_codes,
                    adc_name(channel),
                    t_s - t0,
                    f64::from(value),
                ),
                Event::Compass { t_s, heading_deg } => samples
                    .entry("compass_deg".into())
                    .or_default()
                    .push((t_s - t0, heading_deg)),
                Event::Echo {
                    t_s,
                    transducer,
                    range_m,
                } => {
                    if let Some(r) = range_m {
                        samples
                            .entry(format!("sonar{transducer}_m"))
                            .or_default()
                            .push((t_s - t0, r));
                    }
                }
                Event::Depth { .. } => ambiguous_sonar += 1,
                Event::CompassRaw => raw_compass += 1,
                Event::Error => link_errors += 1,
                Event::Item(_) | Event::SonarSelected { .. } => {}
            },
        );
    }
    let notices = left_out_notices(
        transcript.step_values_unused(),
        ambiguous_sonar,
        raw_compass,
        link_errors,
    );
    Decoded {
        commands,
        samples,
        velocity_codes,
        notices,
    }
}

/// Keeps, of each run of equal consecutive compass readings (in time order), the first, and
/// returns how many it removed. The compass converts on its own clock (the Vector 2X in
/// continuous mode, `[compass] continuous_period_s`), and a program that reads it faster is
/// given its last conversion again. A repeat is no new measurement: kept, forty reads of one
/// conversion would count as forty samples, and stamped at their read times they would say
/// the heading was still what the conversion saw up to a period later, a sawtooth of delay
/// that no latency of the model reproduces. The first read of a new value comes within one
/// read interval of the conversion. Two conversions that happen to read the same (a vehicle at
/// rest) merge too: the later one only repeats what the first said.
fn first_read_of_each_conversion(readings: &mut Samples) -> usize {
    readings.sort_by(|a, b| a.0.total_cmp(&b.0));
    let before = readings.len();
    readings.dedup_by(|later, first| later.1 == first.1);
    before - readings.len()
}

/// What the conversion left out, one notice per kind that occurred.
fn left_out_notices(
    unused_readings: usize,
    ambiguous_sonar: usize,
    raw_compass: usize,
    link_errors: usize,
) -> Vec<String> {
    let mut notices = Vec::new();
    if unused_readings > 0 {
        notices.push(format!(
            "{unused_readings} values of STEP replies left out: the EyeBot took them back \
             unused, or the recording ended before it said whether it used them"
        ));
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
    notices
}

/// One channel's samples: (time s, value).
type Samples = Vec<(f64, f64)>;

/// The thesis's overhead camera (4.5): a frame every 200 ms of the ground-truth position plus
/// seeded Gaussian noise of `std` m; times from `t0`.
fn camera_track(states: &[record::StateRow], t0: f64, std: f64, seed: u64) -> (Samples, Samples) {
    let mut cam = rng::stream(seed, "gap-convert-camera");
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    let mut next = 0.0;
    for row in states {
        let ts = row.t_s - t0;
        if ts + 1e-9 < next {
            continue;
        }
        next = ts + 0.2;
        let (nx, ny): (f64, f64) = (cam.sample(StandardNormal), cam.sample(StandardNormal));
        xs.push((ts, row.x_m + std * nx));
        ys.push((ts, row.y_m + std * ny));
    }
    (xs, ys)
}

/// The channels `gap` knows, in its order: samples inside the run, in time order, one per time.
fn measured_channels(
    mut samples: BTreeMap<String, Vec<(f64, f64)>>,
    duration_s: f64,
) -> Vec<Channel> {
    crate::gap::format::CHANNELS
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
        .collect()
}

/// Appends the thruster commands at `t` (from 0) unless they are the last ones again; commands
/// at the same moment replace each other.
fn add_command(commands: &mut Vec<CommandRow>, t: f64, percent: [f64; 4]) {
    if commands.last().map(|c| c.percent) == Some(percent) {
        return;
    }
    let t_cmd = t.max(0.0);
    match commands.last_mut() {
        Some(c) if (c.t_s - t_cmd).abs() < 1e-12 => c.percent = percent,
        _ => commands.push(CommandRow {
            t_s: t_cmd,
            percent,
        }),
    }
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
mod tests;
