//! The thesis's measurement methods applied to simulated traces, so simulated numbers are
//! read the way Mako's were.
//!
//! Speed runs (thesis 4.5): a camera on the vehicle filmed a tape along the pool wall and the
//! progress was read every 200 ms; a velocity is progress per 200 ms. "Reached top speed" and
//! "at rest" are therefore statements about those samples, with the thresholds below
//! (justified in `docs/calibration.md`). Spot turns (4.7): an overhead camera; the circle is
//! the path of the vehicle's centre and a turn is 360 degrees of heading.

use nalgebra::Vector3;

use crate::physics::state::VehicleState;

/// The pool-side camera's sampling period (thesis 4.5: progress read every 200 ms).
pub const CAMERA_PERIOD_S: f64 = 0.2;
/// A 200 ms sample at or above this fraction of top speed counts as "at top speed".
pub const TOP_SPEED_FRACTION: f64 = 0.85;
/// A 200 ms sample below this speed counts as "at rest".
pub const REST_SPEED_MPS: f64 = 0.015;

/// Progress velocities along `axis` from positions sampled every `period_s`: (time at the end
/// of the interval, velocity). Samples are taken at the trace states nearest to multiples of
/// the period.
pub fn camera_velocities(
    trace: &[VehicleState],
    axis: &Vector3<f64>,
    period_s: f64,
) -> Vec<(f64, f64)> {
    let Some(first) = trace.first() else {
        return Vec::new();
    };
    let dt = if trace.len() > 1 {
        trace[1].t_s - first.t_s
    } else {
        return Vec::new();
    };
    let every = ((period_s / dt).round() as usize).max(1);
    let samples: Vec<&VehicleState> = trace.iter().step_by(every).collect();
    samples
        .windows(2)
        .map(|w| {
            let progress = (w[1].position_m - w[0].position_m).dot(axis);
            (w[1].t_s, progress / (w[1].t_s - w[0].t_s))
        })
        .collect()
}

/// Mean of the velocity samples from `from_s` on (the thesis's "average maximum velocity").
pub fn mean_from(samples: &[(f64, f64)], from_s: f64) -> Option<f64> {
    let tail: Vec<f64> = samples
        .iter()
        .filter(|(t, _)| *t >= from_s)
        .map(|(_, v)| *v)
        .collect();
    (!tail.is_empty()).then(|| tail.iter().sum::<f64>() / tail.len() as f64)
}

/// Time of the first sample at or above `TOP_SPEED_FRACTION` of `top_mps`, from `start_s`.
pub fn time_to_top_speed(samples: &[(f64, f64)], top_mps: f64, start_s: f64) -> Option<f64> {
    samples
        .iter()
        .find(|(t, v)| *t >= start_s && *v >= TOP_SPEED_FRACTION * top_mps)
        .map(|(t, _)| t - start_s)
}

/// Time from `start_s` to the first sample below `REST_SPEED_MPS`.
pub fn time_to_rest(samples: &[(f64, f64)], start_s: f64) -> Option<f64> {
    samples
        .iter()
        .find(|(t, v)| *t > start_s && v.abs() < REST_SPEED_MPS)
        .map(|(t, _)| t - start_s)
}

/// Largest increase between consecutive velocity samples per sample period (m/s^2).
pub fn peak_acceleration(samples: &[(f64, f64)]) -> Option<f64> {
    samples
        .windows(2)
        .map(|w| (w[1].1 - w[0].1) / (w[1].0 - w[0].0))
        .reduce(f64::max)
}

/// A spot turn read from the overhead camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurnMeasurement {
    /// Mean time per 360 degrees of heading over the full turns after the first.
    pub period_s: f64,
    /// Diameter of the centre's path over the last full turn (mean of north and east spans).
    pub diameter_m: f64,
    /// +1 clockwise seen from above (heading increasing), -1 anticlockwise.
    pub sense: f64,
    pub full_turns: usize,
}

/// Measures a spot turn; needs at least two full turns (the first is the spin-up).
pub fn spot_turn(trace: &[VehicleState]) -> Option<TurnMeasurement> {
    let first = trace.first()?;
    // Unwrapped heading.
    let mut unwrapped = Vec::with_capacity(trace.len());
    let mut prev = first.euler_rad().2;
    let mut acc = 0.0;
    for s in trace {
        let yaw = s.euler_rad().2;
        let mut d = yaw - prev;
        d = (d + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        acc += d;
        prev = yaw;
        unwrapped.push(acc);
    }
    let total = *unwrapped.last()?;
    let sense = total.signum();
    // Times at which the heading completes each full turn.
    let mut crossings = vec![0usize];
    let mut next = std::f64::consts::TAU;
    for (i, h) in unwrapped.iter().enumerate() {
        if h * sense >= next {
            crossings.push(i);
            next += std::f64::consts::TAU;
        }
    }
    let full_turns = crossings.len() - 1;
    if full_turns < 2 {
        return None;
    }
    let t = |i: usize| trace[i].t_s;
    let period_s = (t(crossings[full_turns]) - t(crossings[1])) / (full_turns - 1) as f64;
    let last = &trace[crossings[full_turns - 1]..=crossings[full_turns]];
    let span = |axis: usize| {
        let (lo, hi) = last
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
                (lo.min(s.position_m[axis]), hi.max(s.position_m[axis]))
            });
        hi - lo
    };
    Some(TurnMeasurement {
        period_s,
        diameter_m: 0.5 * (span(0) + span(1)),
        sense,
        full_turns,
    })
}

/// Heading change over a trace in degrees (positive = turned right, clockwise from above).
pub fn heading_change_deg(trace: &[VehicleState]) -> Option<f64> {
    let mut acc = 0.0;
    let mut prev = trace.first()?.euler_rad().2;
    for s in trace {
        let yaw = s.euler_rad().2;
        acc += (yaw - prev + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        prev = yaw;
    }
    Some(acc.to_degrees())
}
