//! Multiple shooting: the re-simulation is cut into segments, and at each segment's start the
//! state is re-anchored to what the measurement says there.
//!
//! Minutes of closed-loop commands replayed open loop diverge: a small error in the yaw
//! response turns the replayed track away from the measured one within seconds, and a fit
//! then chases the divergence instead of the effect. Re-anchoring keeps every segment's
//! prediction a few seconds long, so a residual measures what the model gets wrong over those
//! seconds.
//!
//! Only measured quantities are anchored, each through the inverse of the *candidate* sensor
//! model (so a compass or depth-sensor effect changes the anchor, and stays identifiable):
//! - heading from `compass_deg` (the compass model inverted by Newton's method, its latency
//!   bridged with the state's yaw rate);
//! - depth from `depth_adc` (gain, offset and the sensor's lever arm inverted; not at the
//!   surface clamp);
//! - north and east from the camera track `x_m`, `y_m`.
//!
//! Everything else (velocities, roll, pitch, thruster lag) carries over from the end of the
//! previous segment: the model's own estimate, driven by the measured commands.

use nalgebra::{Matrix2, UnitQuaternion, Vector2, Vector3};

use crate::gap::effects::Configs;
use crate::gap::format::{Channel, Measurement};
use crate::physics::Anchor;
use crate::physics::state::VehicleState;
use crate::sensors::AdcBoard;

pub use crate::gap::run::Shooting;

/// Wraps an angle difference into -180..180 deg.
pub fn wrap_deg(a: f64) -> f64 {
    (a + 180.0).rem_euclid(360.0) - 180.0
}

/// The compass heading the model predicts for a state (deg, 0..360, not rounded).
pub fn compass_heading_deg(c: &Configs, earth_ned_ut: &Vector3<f64>, s: &VehicleState) -> f64 {
    let k = &c.sensors.compass;
    let soft = Matrix2::new(
        k.soft_iron[0][0],
        k.soft_iron[0][1],
        k.soft_iron[1][0],
        k.soft_iron[1][1],
    );
    let b = s.attitude.inverse_transform_vector(earth_ned_ut);
    let m = soft * Vector2::new(b.x, b.y) + Vector2::from(k.hard_iron_ut);
    ((-m.y).atan2(m.x).to_degrees() + k.errors.bias).rem_euclid(360.0)
}

/// The 1-sigma error of each anchored quantity, from the measurement noise of the channel it
/// is read from. The process-noise ensemble draws its anchors with these errors, so the noise
/// floor holds what an anchor read from one noisy sample costs over the following segment.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AnchorNoise {
    pub position_m: f64,
    pub heading_rad: f64,
    pub depth_m: f64,
}

impl AnchorNoise {
    /// `anchor` with each anchored quantity moved by its error times a standard normal draw.
    pub fn perturb(&self, anchor: &mut Anchor, draw: &mut dyn FnMut() -> f64) {
        if let Some(x) = anchor.north_m.as_mut() {
            *x += self.position_m * draw();
        }
        if let Some(y) = anchor.east_m.as_mut() {
            *y += self.position_m * draw();
        }
        if let Some(h) = anchor.heading_rad.as_mut() {
            *h += self.heading_rad * draw();
        }
        if let Some(z) = anchor.depth_m.as_mut() {
            *z += self.depth_m * draw();
        }
    }
}

/// A measured sample near `t_s` (within `window_s`), the nearest one.
fn nearest(ch: &Channel, t_s: f64, window_s: f64) -> Option<(f64, f64)> {
    let i = ch.samples.partition_point(|(t, _)| *t < t_s);
    let mut best: Option<(f64, f64)> = None;
    for j in [i.wrapping_sub(1), i] {
        if let Some(&(t, v)) = ch.samples.get(j)
            && (t - t_s).abs() <= window_s
            && best.is_none_or(|(bt, _)| (t - t_s).abs() < (bt - t_s).abs())
        {
            best = Some((t, v));
        }
    }
    best
}

/// The yaw (rad) at which the candidate compass model reads `reading_deg`, for a vehicle at
/// `state`'s roll and pitch.
pub fn invert_compass(
    c: &Configs,
    earth_ned_ut: &Vector3<f64>,
    state: &VehicleState,
    reading_deg: f64,
) -> f64 {
    let (roll, pitch, _) = state.euler_rad();
    let mut probe = *state;
    let read = |probe: &mut VehicleState, yaw: f64| {
        probe.attitude = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        compass_heading_deg(c, earth_ned_ut, probe)
    };
    let mut yaw = (reading_deg - c.sensors.compass.errors.bias).to_radians();
    let h = 0.01;
    for _ in 0..8 {
        let f = wrap_deg(read(&mut probe, yaw) - reading_deg);
        if f.abs() < 1e-6 {
            break;
        }
        let d = wrap_deg(read(&mut probe, yaw + h) - read(&mut probe, yaw - h)) / (2.0 * h);
        // A compass whose reading does not turn with the heading cannot be inverted here;
        // keep the best guess rather than divide by (nearly) zero.
        if d.abs() < 1.0 {
            break;
        }
        yaw -= f / d;
    }
    yaw.rem_euclid(std::f64::consts::TAU)
}

/// True when the depth channel at a run's start `t_s` (read as [`Read::StartMedian`]) sits on
/// the ADC's surface clamp (the sensor at or above the surface: the reading says only "at
/// most this deep").
pub fn depth_on_surface_clamp(c: &Configs, m: &Measurement, t_s: f64) -> bool {
    m.channel("depth_adc")
        .and_then(|ch| first_median(ch, t_s, false))
        .is_some_and(|(_, code)| code <= c.sensors.adc.offset_lsb + SURFACE_CLAMP_LSB)
}

/// Codes within this many LSB of the ADC offset are the depth sensor's surface clamp.
const SURFACE_CLAMP_LSB: f64 = 2.0;

/// How the samples an anchor is read from are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Read {
    /// The sample nearest the anchor's time (a segment start: the previous segment's state
    /// bridges what one sample misses).
    Nearest,
    /// The median of the first [`START_SAMPLES`] samples from the anchor's time on, within
    /// [`START_WINDOW_S`] of the first of them (a run's start: nothing before it to fall back
    /// on, and the first reading of a sensor is the one most often wrong, such as a compass
    /// read before its first full conversion).
    StartMedian,
}

/// A run's start heading is read from every compass sample while the vehicle still rests
/// (no motor commanded), up to this long from the first sample, when there are at least
/// [`REST_MIN_SAMPLES`] of them ([`rest_median`]).
pub const REST_MAX_S: f64 = 5.0;
/// ... and at least this many samples there.
pub const REST_MIN_SAMPLES: usize = 5;

/// A run's start is read from the median of this many samples per channel ...
pub const START_SAMPLES: usize = 3;
/// ... taken within this long of the first of them.
pub const START_WINDOW_S: f64 = 1.5;

impl Read {
    fn pick(self, ch: &Channel, t_s: f64, window_s: f64, wrap: bool) -> Option<(f64, f64)> {
        match self {
            Read::Nearest => nearest(ch, t_s, window_s),
            Read::StartMedian => first_median(ch, t_s, wrap),
        }
    }
}

/// The median of the first [`START_SAMPLES`] samples of `ch` from `t_s` on, within
/// [`START_WINDOW_S`] of the first of them (with `wrap`, of angles in degrees: the sample with
/// the least summed wrapped distance to the others); with two samples there, the second; with
/// one, that one. The window opens at the first sample, not at `t_s`: a sensor with a latency
/// delivers its first readings late, and a window that closed before the third of them left
/// the first, the one most often wrong, to stand alone (a compass 0.9 s late read 82 deg
/// before the 174 and 176 deg that followed it).
fn first_median(ch: &Channel, t_s: f64, wrap: bool) -> Option<(f64, f64)> {
    let i = ch.samples.partition_point(|(t, _)| *t < t_s);
    let opens = ch.samples.get(i)?.0;
    let first: Vec<(f64, f64)> = ch.samples[i..]
        .iter()
        .take_while(|(t, _)| *t <= opens + START_WINDOW_S)
        .take(START_SAMPLES)
        .copied()
        .collect();
    if first.len() < START_SAMPLES {
        return first.last().copied();
    }
    medoid(&first, wrap)
}

/// The time from `t_s` on until which no motor is commanded: `t_s` itself when one is.
pub fn rest_until(m: &Measurement, t_s: f64) -> f64 {
    if m.commands_in_order().at(t_s).iter().any(|p| *p != 0.0) {
        return t_s;
    }
    m.commands
        .iter()
        .find(|row| row.t_s > t_s && row.percent.iter().any(|p| *p != 0.0))
        .map_or(f64::INFINITY, |row| row.t_s)
}

/// The median of `ch`'s samples from the first one at or after `t_s` until `until` (at most
/// [`REST_MAX_S`] after that first sample), with `wrap` of angles in degrees; `None` with fewer
/// than [`REST_MIN_SAMPLES`] there. At rest every sample says the same, and a dozen of them
/// read the start better than the first three, of which the first is the one most often wrong.
fn rest_median(ch: &Channel, t_s: f64, until: f64, wrap: bool) -> Option<(f64, f64)> {
    let i = ch.samples.partition_point(|(t, _)| *t < t_s);
    let opens = ch.samples.get(i)?.0;
    let closes = until.min(opens + REST_MAX_S);
    let rest: Vec<(f64, f64)> = ch.samples[i..]
        .iter()
        .take_while(|(t, _)| *t < closes)
        .copied()
        .collect();
    if rest.len() < REST_MIN_SAMPLES {
        return None;
    }
    medoid(&rest, wrap)
}

/// The sample with the least summed distance to the others (wrapped, in degrees, with `wrap`).
fn medoid(samples: &[(f64, f64)], wrap: bool) -> Option<(f64, f64)> {
    let distance = |a: f64, b: f64| {
        if wrap {
            wrap_deg(a - b).abs()
        } else {
            (a - b).abs()
        }
    };
    samples
        .iter()
        .map(|&(t, v)| {
            let spread: f64 = samples.iter().map(|&(_, w)| distance(v, w)).sum();
            (spread, (t, v))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, sample)| sample)
}

/// The anchor at `t_s` for a state that the previous segment ended in.
pub fn estimate(
    c: &Configs,
    m: &Measurement,
    earth_ned_ut: &Vector3<f64>,
    t_s: f64,
    state: &VehicleState,
    read: Read,
) -> Anchor {
    let mut anchor = Anchor::default();
    let velocity_ned = state.attitude * state.velocity_body_mps;
    if let (Some(x), Some(y)) = (m.channel("x_m"), m.channel("y_m"))
        && let (Some((tx, vx)), Some((ty, vy))) = (
            read.pick(x, t_s, 0.25, false),
            read.pick(y, t_s, 0.25, false),
        )
    {
        // The camera sees its marker, not the centre of mass.
        let [mx, my] = c.camera_marker_ned(&state.attitude);
        anchor.north_m = Some(vx - mx + velocity_ned.x * (t_s - tx));
        anchor.east_m = Some(vy - my + velocity_ned.y * (t_s - ty));
    }
    if let Some(ch) = m.channel("compass_deg") {
        // The reading of a conversion finished at `tc` describes the heading at `tc - latency`.
        let latency = c.sensors.compass.errors.latency_s;
        let at_rest = (read == Read::StartMedian)
            .then(|| rest_median(ch, t_s, rest_until(m, t_s), true))
            .flatten();
        if let Some((tc, reading)) = at_rest.or_else(|| read.pick(ch, t_s, 0.5, true)) {
            let yaw = invert_compass(c, earth_ned_ut, state, reading);
            let rate = state.angular_velocity_body_radps.z;
            anchor.heading_rad = Some(yaw + rate * (t_s - (tc - latency)));
        }
    }
    if let Some(ch) = m.channel("depth_adc")
        && let Some((td, code)) = read.pick(ch, t_s, 0.25, false)
    {
        let d = &c.sensors.depth;
        let lsb = AdcBoard::new(&c.sensors.adc, 0).lsb_v();
        // Below about 2 LSB the reading sits on the surface clamp and says only "at most
        // this deep"; the state keeps its own depth there.
        if code > c.sensors.adc.offset_lsb + SURFACE_CLAMP_LSB && d.volts_per_m > 0.0 {
            let volts = (code - c.sensors.adc.offset_lsb) * lsb;
            let sensor_depth = volts / d.volts_per_m - d.errors.bias;
            let lever = state.attitude * Vector3::from(d.position_body_m);
            let vz = velocity_ned.z;
            anchor.depth_m = Some(sensor_depth - lever.z + vz * (t_s - td));
        }
    }
    anchor
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ConfigSource, Document, Embedded};
    use crate::physics::VehicleConfig;
    use crate::physics::WorldConfig;
    use crate::sensors::{Compass, SensorsConfig};

    fn configs() -> Configs {
        let read = |name: &str| {
            let text = Embedded.read(name).expect("embedded config");
            (Embedded.describe(name), text.into_owned())
        };
        let (o, t) = read("vehicles/mako.toml");
        let vehicle = VehicleConfig::from_document(&Document::new(o, &t)).expect("vehicle");
        let (o, t) = read("worlds/pool.toml");
        let world = WorldConfig::from_document(&Document::new(o, &t)).expect("world");
        let (o, t) = read("sensors/mako-2008.toml");
        let sensors = SensorsConfig::from_text(o, &t).expect("sensors");
        Configs::new(vehicle, world, sensors)
    }

    fn level_state(yaw_deg: f64) -> VehicleState {
        VehicleState {
            t_s: 0.0,
            position_m: Vector3::new(5.0, 5.0, 0.5),
            attitude: UnitQuaternion::from_euler_angles(0.02, -0.03, yaw_deg.to_radians()),
            velocity_body_mps: Vector3::zeros(),
            angular_velocity_body_radps: Vector3::zeros(),
            velocity_water_body_mps: Vector3::zeros(),
            specific_force_body_mps2: Vector3::zeros(),
            angular_accel_body_radps2: Vector3::zeros(),
            thruster_force_n: [0.0; 4],
            thruster_effort: [0.0; 4],
            in_contact: false,
        }
    }

    /// The inverse gives back the heading the compass model was read at, with a hard iron,
    /// a soft iron and a bias all present, at every heading around the circle.
    #[test]
    fn compass_inverse_recovers_the_heading_through_a_distorted_compass() {
        let mut c = configs();
        c.sensors.compass.hard_iron_ut = [4.0, -3.0];
        c.sensors.compass.soft_iron = [[1.03, 0.02], [0.02, 0.97]];
        c.sensors.compass.errors.bias = 2.5;
        let earth = Compass::new(&c.sensors.compass, 0).earth_field_ned_ut();
        for k in 0..72 {
            let yaw = f64::from(k) * 5.0;
            let s = level_state(yaw);
            let reading = compass_heading_deg(&c, &earth, &s);
            let back = invert_compass(&c, &earth, &s, reading).to_degrees();
            assert!(
                wrap_deg(back - yaw).abs() < 1e-3,
                "heading {yaw} deg read {reading:.3} deg, inverted to {back:.3} deg"
            );
        }
    }

    /// The camera tracks a marker off the centre of mass: the anchored position is the
    /// marker's reading less the marker's offset at the state's heading, at every heading, so
    /// that a re-simulation started there predicts the reading back.
    #[test]
    fn a_camera_marker_off_the_centre_anchors_the_centre() {
        let mut c = configs();
        c.camera_marker_body_m = [0.12, -0.05];
        for k in 0..8 {
            let s = level_state(f64::from(k) * 45.0);
            let [mx, my] = c.camera_marker_ned(&s.attitude);
            assert!(
                ((mx * mx + my * my).sqrt() - 0.13).abs() < 2e-3,
                "the marker is 0.13 m from the centre at any heading: {mx} {my}"
            );
            let measured = format!(
                "t_s,x_m,y_m\n1.0,{},{}\n",
                s.position_m.x + mx,
                s.position_m.y + my
            );
            let m = Measurement::from_texts(
                ("e", "name = \"t\"\nduration_s = 10.0\n[initial]\nx_m = 1.0\ny_m = 2.0\nheading_deg = 0.0\n"),
                ("c", "t_s,port,starboard,bow,stern\n0,0,0,0,0\n"),
                ("m", &measured),
            )
            .expect("measurement");
            let earth = Compass::new(&c.sensors.compass, 0).earth_field_ned_ut();
            let a = estimate(&c, &m, &earth, 1.0, &s, Read::Nearest);
            let (north, east) = (a.north_m.expect("north"), a.east_m.expect("east"));
            assert!(
                (north - s.position_m.x).abs() < 1e-9 && (east - s.position_m.y).abs() < 1e-9,
                "anchored at ({north}, {east}), the centre is at {:?}",
                s.position_m
            );
        }
    }

    /// A run's start read from one wrong first sample (a compass read before its first full
    /// conversion, 90 deg off) takes the heading of the samples after it; a segment start
    /// takes the nearest sample as it is. Around north the median wraps: 359, 2 and 1 deg give
    /// 1 deg, not 2 or 359.
    #[test]
    fn a_start_is_read_from_the_median_of_the_first_samples() {
        let ch = |name: &str, samples: &[(f64, f64)]| Channel {
            name: name.to_string(),
            samples: samples.to_vec(),
        };
        let compass = ch("compass_deg", &[(0.1, 277.0), (0.5, 188.0), (0.9, 189.0)]);
        assert_eq!(
            Read::StartMedian.pick(&compass, 0.0, 0.5, true),
            Some((0.9, 189.0))
        );
        assert_eq!(
            Read::Nearest.pick(&compass, 0.0, 0.5, true),
            Some((0.1, 277.0))
        );
        let north = ch("compass_deg", &[(0.1, 359.0), (0.5, 2.0), (0.9, 1.0)]);
        assert_eq!(
            Read::StartMedian.pick(&north, 0.0, 0.5, true),
            Some((0.9, 1.0))
        );
        // A compass 0.9 s late: its first reading, wrong, comes at 1.05 s, and the window
        // opens there, so the two after it outvote it.
        let late = ch(
            "compass_deg",
            &[(1.05, 82.0), (1.45, 174.0), (1.85, 176.0), (2.25, 177.0)],
        );
        assert_eq!(
            Read::StartMedian.pick(&late, 0.0, 0.5, true),
            Some((1.45, 174.0))
        );
        // Two samples within the window: the second; one: that one.
        let two = ch("compass_deg", &[(0.1, 82.0), (1.2, 174.0), (3.0, 176.0)]);
        assert_eq!(
            Read::StartMedian.pick(&two, 0.0, 0.5, true),
            Some((1.2, 174.0))
        );
        let sparse = ch("x_m", &[(0.2, 4.0), (3.0, 9.0)]);
        assert_eq!(
            Read::StartMedian.pick(&sparse, 0.0, 0.25, false),
            Some((0.2, 4.0))
        );
        assert_eq!(
            Read::StartMedian.pick(&ch("x_m", &[]), 0.0, 0.25, false),
            None
        );
    }

    /// While the vehicle rests, the start heading is the median of every compass sample up to
    /// the first motor command (at most 5 s): a compass that reads 348, 346 and 346 deg in its
    /// first 1.2 s and 345 after starts at 345, not at the first three's 346. With fewer than
    /// five samples at rest the first three are read as before.
    #[test]
    fn a_start_at_rest_is_read_from_every_sample_before_the_motors_run() {
        let mut readings = vec![(0.4, 348.0), (0.8, 346.0), (1.2, 346.0)];
        readings.extend((4..=12).map(|k| (0.4 * f64::from(k), 345.0)));
        let compass = Channel {
            name: "compass_deg".to_string(),
            samples: readings,
        };
        assert_eq!(
            rest_median(&compass, 0.0, 5.0, true).map(|s| s.1),
            Some(345.0)
        );
        assert_eq!(first_median(&compass, 0.0, true).map(|s| s.1), Some(346.0));
        assert_eq!(
            rest_median(&compass, 0.0, 1.5, true),
            None,
            "three samples at rest"
        );
    }
}
