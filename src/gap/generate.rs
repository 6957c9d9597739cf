//! Hidden-effect data: run a truth model (a model file with effects) through an experiment's
//! command schedule with every noise source on, and write what the instruments would have
//! recorded. The output holds only measured channels with their noise: no truth model, no
//! noise-free channel, no derivative.
//!
//! Instruments: overhead camera (`x_m`, `y_m` at 5 Hz, Gaussian position noise), the compass
//! sensor model (`compass_deg`, every completed conversion, rounded to 1 deg), the depth
//! sensor through the ADC (`depth_adc` at 10 Hz), the paddle wheel counted over the
//! firmware's window (`paddle_speed_mps`), the accelerometer through the ADC
//! (`accel_x_adc`, `accel_y_adc`, `accel_z_adc` at 10 Hz). Each ADC channel is read as if
//! alone (no cross-channel retention), as the model predicts it.

use rand::RngExt;
use rand_distr::StandardNormal;

use crate::gap::GapError;
use crate::gap::effects::Configs;
use crate::gap::format::{Channel, CommandRow, ExperimentInfo, Initial, Measurement};
use crate::gap::model::GapModel;
use crate::gap::resim;
use crate::physics::experiment::Experiment;
use crate::sensors::{
    AdcBoard, AdcSource, Compass, DepthSensor, PaddleWheel, accelerometer::Accelerometer, rng,
};

/// Camera sampling period (s): the thesis's pool-side camera read progress every 200 ms.
pub const CAMERA_PERIOD_S: f64 = 0.2;
/// Depth sampling period (s).
pub const DEPTH_PERIOD_S: f64 = 0.1;

/// The set-up of a generated run of `schedule` under `model`: the model's world and sensors
/// (by default the pool and the 2008 sensor set), the schedule's name and duration, a zero
/// initial state (the schedule's own start is applied when generating) and the camera noise.
pub fn setup(
    model: &GapModel,
    schedule: &Experiment,
    camera_position_std_m: f64,
) -> ExperimentInfo {
    ExperimentInfo {
        name: schedule.name.clone(),
        description: String::new(),
        duration_s: schedule.duration_s,
        world: model
            .world_ref
            .clone()
            .unwrap_or_else(|| crate::physics::DEFAULT_WORLD.to_string()),
        sensors: model
            .sensors_ref
            .clone()
            .unwrap_or_else(|| "sensors/mako-2008.toml".to_string()),
        initial: Initial::default(),
        camera_position_std_m,
        camera_speed_std_mps: 0.02,
        camera_marker_body_m: [0.0; 2],
    }
}

/// Generates a measurement of `truth` running `schedule`. `world`/`sensors` are the names the
/// experiment file will reference (the model's base configurations, never the truth's).
pub fn generate(
    truth: &Configs,
    schedule: &Experiment,
    world: &str,
    sensors: &str,
    camera_position_std_m: f64,
    seed: u64,
) -> Result<Measurement, GapError> {
    generate_with(
        truth,
        schedule,
        world,
        sensors,
        camera_position_std_m,
        seed,
        false,
    )
}

/// As [`generate`]; with `sonar` the four transducers are pinged too (`sonar1_m`..`sonar4_m`,
/// [`crate::gap::sonar`]), from the truth's sonar model in the truth's world. Without it the
/// output is exactly [`generate`]'s.
pub fn generate_with(
    truth: &Configs,
    schedule: &Experiment,
    world: &str,
    sensors: &str,
    camera_position_std_m: f64,
    seed: u64,
    sonar: bool,
) -> Result<Measurement, GapError> {
    let commands: Vec<CommandRow> = schedule
        .schedule
        .iter()
        .map(|c| CommandRow {
            t_s: c.t_s,
            percent: c.percent,
        })
        .collect();
    let s = &schedule.start;
    let mut m = Measurement {
        experiment: ExperimentInfo {
            name: schedule.name.clone(),
            description: schedule.description.clone(),
            duration_s: schedule.duration_s,
            world: world.to_string(),
            sensors: sensors.to_string(),
            initial: Initial {
                x_m: s.north_m,
                y_m: s.east_m,
                z_m: s.depth_m,
                heading_deg: s.heading_rad.to_degrees(),
                roll_deg: 0.0,
                pitch_deg: 0.0,
                surge_mps: s.surge_mps,
            },
            camera_position_std_m,
            camera_speed_std_mps: 0.02,
            camera_marker_body_m: [0.0; 2],
        },
        commands,
        channels: Vec::new(),
        notices: Vec::new(),
    };
    let run = resim::simulate(truth, &m, Some(seed))?;
    let mut cam = rng::stream(seed, "gap-camera");
    let mut compass = Compass::new(&truth.sensors.compass, seed);
    let mut depth = DepthSensor::new(&truth.sensors.depth, seed);
    let mut adc = AdcBoard::new(&truth.sensors.adc, seed);
    let mut paddle = PaddleWheel::new(&truth.sensors.velocity, seed);
    let depth_channel = adc.channel_of(AdcSource::Depth);
    let mut accel = Accelerometer::new(&truth.sensors.accelerometer, seed);
    let accel_sources = [AdcSource::AccelX, AdcSource::AccelY, AdcSource::AccelZ];
    // One converter per axis (seeded apart) so no channel switch happens between reads.
    let mut accel_adc: Vec<AdcBoard> = (0..3u64)
        .map(|k| AdcBoard::new(&truth.sensors.adc, seed ^ (0xacce_1000 + k)))
        .collect();
    let mut accel_codes: [Vec<(f64, f64)>; 3] = Default::default();
    let v = &truth.sensors.velocity;
    let (mut xs, mut ys, mut hs, mut ds, mut ps) = (vec![], vec![], vec![], vec![], vec![]);
    let cam_every = (CAMERA_PERIOD_S / run.dt_s).round() as usize;
    let depth_every = (DEPTH_PERIOD_S / run.dt_s).round() as usize;
    let window_every = (v.window_s / run.dt_s).round() as usize;
    let mut last_half_turns = 0.0f64;
    for (k, state) in run.states.iter().enumerate() {
        let t = state.t_s;
        compass.update(state);
        depth.update(state);
        paddle.update(state);
        accel.update(state);
        if k % cam_every.max(1) == 0 {
            let nx: f64 = cam.sample(StandardNormal);
            let ny: f64 = cam.sample(StandardNormal);
            xs.push((t, state.position_m.x + camera_position_std_m * nx));
            ys.push((t, state.position_m.y + camera_position_std_m * ny));
        }
        if let Some(r) = compass.poll()
            && let Some((tc, _)) = compass.latest()
        {
            hs.push((tc, f64::from(r.heading_deg)));
        }
        if k % depth_every.max(1) == 0
            && let Some(ch) = depth_channel
        {
            let volts = depth.voltage(t);
            if let Ok(code) = adc.convert(ch, volts, 0.0) {
                ds.push((t, f64::from(code)));
            }
            for axis in 0..3 {
                if let Some(ch) = accel_adc[axis].channel_of(accel_sources[axis]) {
                    let volts = accel.voltage(axis, t);
                    if let Ok(code) = accel_adc[axis].convert(ch, volts, 0.0) {
                        let a = &truth.sensors.accelerometer;
                        let lsb = accel_adc[axis].lsb_v();
                        let zero = a.zero_g_v / lsb + truth.sensors.adc.offset_lsb;
                        let full = f64::from((1u32 << truth.sensors.adc.bits) - 1);
                        let read = truth.analog.accel_code(axis, f64::from(code), zero);
                        accel_codes[axis].push((t, read.round().clamp(0.0, full)));
                    }
                }
            }
        }
        if k > 0 && k % window_every.max(1) == 0 {
            let h = paddle.half_turns();
            let count = h.floor() - last_half_turns.floor();
            last_half_turns = h;
            ps.push((
                t,
                count / (v.pulses_per_metre * v.window_s) * v.firmware_scale,
            ));
        }
    }
    let [ax, ay, az] = accel_codes;
    for (name, samples) in [
        ("x_m", xs),
        ("y_m", ys),
        ("compass_deg", hs),
        ("depth_adc", ds),
        ("accel_x_adc", ax),
        ("accel_y_adc", ay),
        ("accel_z_adc", az),
        ("paddle_speed_mps", ps),
    ] {
        m.channels.push(Channel {
            name: name.to_string(),
            samples,
        });
    }
    if sonar {
        let duration = m.experiment.duration_s;
        m.channels.extend(crate::gap::sonar::generate(
            truth,
            &run,
            duration,
            seed ^ 0x50_4e41_5200,
        ));
    }
    Ok(m)
}
