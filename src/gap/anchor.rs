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

/// True when the depth channel's sample nearest `t_s` sits on the ADC's surface clamp (the
/// sensor at or above the surface: the reading says only "at most this deep").
pub fn depth_on_surface_clamp(c: &Configs, m: &Measurement, t_s: f64) -> bool {
    m.channel("depth_adc")
        .and_then(|ch| nearest(ch, t_s, 0.25))
        .is_some_and(|(_, code)| code <= c.sensors.adc.offset_lsb + SURFACE_CLAMP_LSB)
}

/// Codes within this many LSB of the ADC offset are the depth sensor's surface clamp.
const SURFACE_CLAMP_LSB: f64 = 2.0;

/// The anchor at `t_s` for a state that the previous segment ended in.
pub fn estimate(
    c: &Configs,
    m: &Measurement,
    earth_ned_ut: &Vector3<f64>,
    t_s: f64,
    state: &VehicleState,
) -> Anchor {
    let mut anchor = Anchor::default();
    let velocity_ned = state.attitude * state.velocity_body_mps;
    if let (Some(x), Some(y)) = (m.channel("x_m"), m.channel("y_m"))
        && let (Some((tx, vx)), Some((ty, vy))) = (nearest(x, t_s, 0.25), nearest(y, t_s, 0.25))
    {
        anchor.north_m = Some(vx + velocity_ned.x * (t_s - tx));
        anchor.east_m = Some(vy + velocity_ned.y * (t_s - ty));
    }
    if let Some(ch) = m.channel("compass_deg") {
        // The reading of a conversion finished at `tc` describes the heading at `tc - latency`.
        let latency = c.sensors.compass.errors.latency_s;
        if let Some((tc, reading)) = nearest(ch, t_s, 0.5) {
            let yaw = invert_compass(c, earth_ned_ut, state, reading);
            let rate = state.angular_velocity_body_radps.z;
            anchor.heading_rad = Some(yaw + rate * (t_s - (tc - latency)));
        }
    }
    if let Some(ch) = m.channel("depth_adc")
        && let Some((td, code)) = nearest(ch, t_s, 0.25)
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
}
