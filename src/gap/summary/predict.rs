//! Reading each observation's quantity from a re-simulated experiment, the way the thesis
//! read Mako.

use nalgebra::Vector3;

use super::{Observation, Quantity, Summary, TOP_SPEED_FROM_S};
use crate::gap::GapError;
use crate::gap::effects::Configs;
use crate::physics::Model;
use crate::physics::experiment::{self, Experiment};
use crate::physics::measure::{self, CAMERA_PERIOD_S, REST_SPEED_MPS, TOP_SPEED_FRACTION};
use crate::physics::state::VehicleState;

fn crossing(a: (f64, f64), b: (f64, f64), level: f64) -> f64 {
    let dv = b.1 - a.1;
    if dv.abs() < 1e-15 {
        b.0
    } else {
        a.0 + (level - a.1) / dv * (b.0 - a.0)
    }
}

/// Reads one observation's quantity from a run of its experiment (`None`: undefined here,
/// e.g. fewer than two full turns).
pub fn quantity(o: &Observation, exp: &Experiment, trace: &[VehicleState]) -> Option<f64> {
    let h = exp.start.heading_rad;
    let axis = Vector3::new(h.cos(), h.sin(), 0.0);
    let until = o.until_s.unwrap_or(f64::INFINITY);
    match o.quantity {
        Quantity::TopSpeedMps => {
            let v = measure::camera_velocities(trace, &axis, CAMERA_PERIOD_S);
            let w: Vec<(f64, f64)> = v.into_iter().filter(|(t, _)| *t <= until).collect();
            measure::mean_from(&w, o.from_s)
        }
        Quantity::TimeToTopSpeedS => {
            let v = measure::camera_velocities(trace, &axis, CAMERA_PERIOD_S);
            let top = measure::mean_from(&v, TOP_SPEED_FROM_S)?;
            let level = TOP_SPEED_FRACTION * top;
            let mut prev: Option<(f64, f64)> = None;
            for &(t, x) in v.iter().filter(|(t, _)| *t >= o.from_s && *t <= until) {
                if x >= level {
                    return Some(prev.map_or(t, |p| crossing(p, (t, x), level)) - o.from_s);
                }
                prev = Some((t, x));
            }
            None
        }
        Quantity::TimeToRestS => {
            let v = measure::camera_velocities(trace, &axis, CAMERA_PERIOD_S);
            let mut prev: Option<(f64, f64)> = None;
            let mut last = o.from_s;
            for &(t, x) in v.iter().filter(|(t, _)| *t > o.from_s && *t <= until) {
                if x.abs() < REST_SPEED_MPS {
                    return Some(
                        prev.map_or(t, |p| crossing(p, (t, x.abs()), REST_SPEED_MPS)) - o.from_s,
                    );
                }
                prev = Some((t, x.abs()));
                last = t;
            }
            // Never at rest within the run: censored at its end.
            Some(last - o.from_s)
        }
        Quantity::PeakAccelerationMps2 => {
            let v = measure::camera_velocities(trace, &axis, CAMERA_PERIOD_S);
            let w: Vec<(f64, f64)> = v
                .into_iter()
                .filter(|(t, _)| *t >= o.from_s && *t <= until)
                .collect();
            measure::peak_acceleration(&w)
        }
        Quantity::TurnDiameterM | Quantity::TurnPeriodS => {
            let end = trace.partition_point(|s| s.t_s <= until);
            let turn = measure::spot_turn(&trace[..end.max(1)])?;
            Some(if o.quantity == Quantity::TurnDiameterM {
                turn.diameter_m
            } else {
                turn.period_s
            })
        }
    }
}

/// Runs every experiment of the summary with configs `c` and reads each observation.
/// `noise_seed = None` switches the thrust fluctuation off (the mean prediction).
pub fn predict(
    c: &Configs,
    s: &Summary,
    noise_seed: Option<u64>,
) -> Result<Vec<Option<f64>>, GapError> {
    let mut vehicle = c.vehicle.clone();
    if noise_seed.is_none() {
        vehicle.thruster_common.fluctuation_rel_std = 0.0;
    }
    let model = Model::new(vehicle, c.world.clone());
    let mut traces = Vec::with_capacity(s.experiments.len());
    for e in &s.experiments {
        traces.push(
            experiment::trace(&model, e, noise_seed.unwrap_or(0)).map_err(|source| {
                GapError::Physics {
                    experiment: e.name.clone(),
                    source,
                }
            })?,
        );
    }
    Ok(s.observations
        .iter()
        .map(|o| quantity(o, &s.experiments[o.experiment], &traces[o.experiment]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossing_interpolates_between_samples() {
        assert!((crossing((1.0, 0.0), (2.0, 1.0), 0.25) - 1.25).abs() < 1e-12);
        // Falling through a level works the same way.
        assert!((crossing((1.0, 1.0), (2.0, 0.0), 0.25) - 1.75).abs() < 1e-12);
    }
}
