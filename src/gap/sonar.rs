//! Sonar channels (`sonar1_m`..`sonar4_m`, transducer N of the sensor configuration) in the
//! reality-gap workflow: generation from the sonar model and a likelihood for re-simulation.
//!
//! **Pings.** Every transducer is read once per `sonar.timing.period_s`, at
//! `t = k * period_s` (k >= 1) up to the duration. A ping slot is the interval of one period
//! centred on its time: a sample of the channel in the slot is an echo with that range, no
//! sample (empty cells) is a ping without a valid echo.
//!
//! **Prediction.** For each ping the model's expected echo: every ray of the cone is cast in
//! the model's world (`Pool`, the same rapier pool the daemon uses), and the detection law of
//! `sensors::sonar` gives the probability of a valid echo, used directly (no random draw).
//! The ray cut at `max_incidence_deg` is a step in the model (a ray echoes or it does not);
//! the prediction spreads it linearly over one ring spacing of the cone
//! (`beam_width / 2 / cone_rings`) around the smallest ray incidence, so the probability is
//! continuous in `max_incidence_deg` and a least-squares fit has a gradient.
//!
//! **Likelihood.** Two normalised residuals per ping: the presence deviance residual
//! `sign(y - p) sqrt(-2 ln L)` with `L = p` (echo) or `1 - p` (none), `p` clamped into
//! `[1e-6, 1 - 1e-6]`, and, where both the data and the model have an echo, the range
//! residual ([`range_residual`]), else 0. `sum r^2` is then `-2 ln L` of the sonar data up to
//! a constant, as for the Gaussian channels.
//!
//! **Range likelihood.** The range noise (`errors.gaussian_std`, uniform part and resolution)
//! is a few centimetres, but the model's pose is uncertain by more over a segment, and where a
//! beam grazes a corner or a wall's end a small turn moves its echo to another wall, metres
//! away: a reading no Gaussian about the model's echo holds (one such block of a wall run,
//! ten pings, weighed 9,754 in chi-square against an effect's whole gain of a few hundred).
//! The beam model of Thrun, Burgard and Fox (*Probabilistic Robotics*, 2005, section 6.3)
//! mixes a uniform "random measurement" part into the Gaussian for such readings; the range
//! term is that mixture's deviance residual, with weight [`RANGE_OUTLIER_SHARE`] uniform over
//! the detection table's range. Within about 3 sigma of the echo it is the Gaussian residual;
//! beyond, its square levels off at about 15 (the level moves with the logarithm of the
//! weight: 18 at 1 %, 12 at 20 %).

use crate::gap::effects::Configs;
use crate::gap::format::Channel;
use crate::gap::run::{Floor, Run};
use crate::physics::state::RayCaster;
use crate::physics::world::Pool;
use crate::sensors::config::SonarSettings;
use crate::sensors::sonar::{Transducer, detection_probability};

/// The sonar channels, transducer 1..4 in the sensor configuration's order.
pub const CHANNELS: [&str; 4] = ["sonar1_m", "sonar2_m", "sonar3_m", "sonar4_m"];

/// Presence probabilities are clamped into `[P_MIN, 1 - P_MIN]` in the likelihood.
pub const P_MIN: f64 = 1e-6;

/// The transducer index (0..4) of a sonar channel.
pub fn index(channel: &str) -> Option<usize> {
    CHANNELS.iter().position(|c| *c == channel)
}

/// Ping times of every transducer over `duration_s` (module doc).
pub fn ping_times(s: &SonarSettings, duration_s: f64) -> Vec<f64> {
    let p = s.timing.period_s;
    if p.is_nan() || p <= 0.0 || !duration_s.is_finite() {
        return Vec::new();
    }
    (1..)
        .map(|k| f64::from(k) * p)
        .take_while(|t| *t <= duration_s + 1e-9)
        .collect()
}

/// The measured range in each ping slot (`None`: no echo).
pub fn slots(channel: &Channel, times: &[f64], period_s: f64) -> Vec<Option<f64>> {
    times
        .iter()
        .map(|t| {
            channel
                .samples
                .iter()
                .find(|(ts, _)| (ts - t).abs() <= period_s / 2.0 + 1e-9)
                .map(|(_, v)| *v)
        })
        .collect()
}

/// Generates the four sonar channels from `truth`'s sonar model on `run` in `truth`'s world,
/// with the model's own seeded noise streams: one sample per ping with a valid echo.
pub fn generate(truth: &Configs, run: &Run, duration_s: f64, seed: u64) -> Vec<Channel> {
    let s = &truth.sensors.sonar;
    let world = Pool::new(&truth.world);
    let mut transducers: Vec<Transducer> = s
        .transducers
        .iter()
        .map(|t| Transducer::new(t, s, seed))
        .collect();
    let mut samples: Vec<Vec<(f64, f64)>> = vec![Vec::new(); transducers.len()];
    for t in ping_times(s, duration_s) {
        let state = run.at(t);
        for (k, tr) in transducers.iter_mut().enumerate() {
            if let Some(r) = tr.ping(state, &world, s, t) {
                samples[k].push((t, f64::from(r.0) * s.resolution_m));
            }
        }
    }
    samples
        .into_iter()
        .zip(CHANNELS)
        .map(|(samples, name)| Channel {
            name: name.to_string(),
            samples,
        })
        .collect()
}

/// The model's expectation for one ping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Expected {
    /// Probability of a valid echo.
    pub p: f64,
    /// Range of the echo when there is one (m).
    pub range_m: Option<f64>,
}

/// The expected echo of `tr` in state `state` (module doc, "Prediction").
pub fn expected(
    s: &SonarSettings,
    world: &dyn RayCaster,
    tr: &Transducer,
    state: &crate::physics::state::VehicleState,
) -> Expected {
    let max_range = s.detection.last().map_or(0.0, |(r, _)| *r);
    let hits = tr.ray_hits(state, world, max_range);
    let Some(min_inc) = hits.iter().map(|h| h.1).min_by(f64::total_cmp) else {
        return Expected {
            p: 0.0,
            range_m: None,
        };
    };
    let width = if s.cone_rings > 0 {
        s.beam_width_deg / 2.0 / f64::from(s.cone_rings)
    } else {
        1.0
    };
    let exist = ((s.max_incidence_deg - min_inc) / width + 0.5).clamp(0.0, 1.0);
    let cut = s.max_incidence_deg.max(min_inc);
    let Some(&(range, _, beta)) = hits
        .iter()
        .filter(|h| h.1 <= cut + 1e-12)
        .min_by(|a, b| a.0.total_cmp(&b.0))
    else {
        return Expected {
            p: 0.0,
            range_m: None,
        };
    };
    let p = exist * detection_probability(s, range, beta, tr.speed_mps(state));
    Expected {
        p,
        range_m: Some(range),
    }
}

/// The range noise (1 sigma, m) of one reading.
pub fn range_std_m(s: &SonarSettings) -> f64 {
    let e = &s.errors;
    (e.gaussian_std.powi(2) + e.uniform_half_width.powi(2) / 3.0 + s.resolution_m.powi(2) / 12.0)
        .sqrt()
        .max(1e-6)
}

/// The weight of the uniform part of the range likelihood (module doc, "Range likelihood"):
/// the share of readings taken as no echo the model's pose and walls predict.
pub const RANGE_OUTLIER_SHARE: f64 = 0.05;

/// The normalised range residual of a reading `measured_m` against the model's echo at
/// `model_m` (module doc, "Range likelihood"): `sign * sqrt(-2 ln(L / L_max))` for the
/// mixture `L` of the Gaussian range noise and a uniform part over the detection range.
pub fn range_residual(s: &SonarSettings, measured_m: f64, model_m: f64) -> f64 {
    let sigma = range_std_m(s);
    let span = s.detection.last().map_or(0.0, |(r, _)| *r).max(1.0);
    let z = (measured_m - model_m) / sigma;
    let peak = (1.0 - RANGE_OUTLIER_SHARE) / (sigma * std::f64::consts::TAU.sqrt());
    let uniform = RANGE_OUTLIER_SHARE / span;
    let density = peak * (-0.5 * z * z).exp() + uniform;
    z.signum() * (-2.0 * (density / (peak + uniform)).ln()).max(0.0).sqrt()
}

/// Normalised residuals of a sonar channel for configs `c` on `run` (two per ping, module
/// doc), or `None` when `channel` is not a sonar channel of the configuration.
pub fn residuals(c: &Configs, run: &Run, duration_s: f64, channel: &Channel) -> Option<Vec<f64>> {
    let k = index(&channel.name)?;
    let s = &c.sensors.sonar;
    let t = s.transducers.get(k)?;
    let tr = Transducer::new(t, s, 0);
    let world = Pool::new(&c.world);
    let times = ping_times(s, duration_s);
    let measured = slots(channel, &times, s.timing.period_s);
    let mut out = Vec::with_capacity(2 * times.len());
    for (t, y) in times.iter().zip(measured) {
        let e = expected(s, &world, &tr, run.at(*t));
        let p = e.p.clamp(P_MIN, 1.0 - P_MIN);
        let (ind, l) = if y.is_some() {
            (1.0, p)
        } else {
            (0.0, 1.0 - p)
        };
        out.push((ind - p).signum() * (-2.0 * l.ln()).max(0.0).sqrt());
        out.push(match (y, e.range_m) {
            (Some(m), Some(r)) => range_residual(s, m, r),
            _ => 0.0,
        });
    }
    Some(out)
}

/// Residuals for the per-channel statistics (`gap`'s localisation and the before/after gap):
/// the Pearson residual `(y - p) / sqrt(p (1 - p))` of each ping (mean square 1 under the
/// model whatever `p`, unlike the deviance), `p` clamped into `[1e-3, 1 - 1e-3]`, then the
/// range residual ([`range_residual`]) where both the data and the model have an echo. Returns
/// `(times, residuals)`.
pub fn stats_residuals(
    c: &Configs,
    run: &Run,
    duration_s: f64,
    channel: &Channel,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let k = index(&channel.name)?;
    let s = &c.sensors.sonar;
    let t = s.transducers.get(k)?;
    let tr = Transducer::new(t, s, 0);
    let world = Pool::new(&c.world);
    let times = ping_times(s, duration_s);
    let measured = slots(channel, &times, s.timing.period_s);
    let (mut ts, mut out) = (Vec::new(), Vec::new());
    for (t, y) in times.iter().zip(measured) {
        let e = expected(s, &world, &tr, run.at(*t));
        let p = e.p.clamp(1e-3, 1.0 - 1e-3);
        let ind = if y.is_some() { 1.0 } else { 0.0 };
        ts.push(*t);
        out.push((ind - p) / (p * (1.0 - p)).sqrt());
        if let (Some(m), Some(r)) = (y, e.range_m) {
            ts.push(*t);
            out.push(range_residual(s, m, r));
        }
    }
    Some((ts, out))
}

/// The noise floor of a sonar channel: its residuals are already normalised (unit sigma,
/// independent pings); process noise is not propagated into the sonar (zero null deviations,
/// one per ensemble member, so the other channels' null calibration keeps its members).
pub fn floor(c: &Configs, duration_s: f64, channel: &Channel) -> Option<Floor> {
    let k = index(&channel.name)?;
    c.sensors.sonar.transducers.get(k)?;
    let n = 2 * ping_times(&c.sensors.sonar, duration_s).len();
    Some(Floor {
        sigma: vec![1.0; n],
        tau: 1.0,
        measurement_std: vec![1.0; n],
        null: vec![vec![0.0; n]; crate::gap::run::ENSEMBLE as usize],
        chi2_tau_once: Default::default(),
    })
}

#[cfg(test)]
mod tests {
    use nalgebra::{UnitQuaternion, Vector3};

    use super::*;
    use crate::config::Document;
    use crate::physics::WorldConfig;
    use crate::physics::state::VehicleState;
    use crate::sensors::SensorsConfig;
    use crate::sensors::scene::at_rest;

    fn settings() -> (SonarSettings, Pool) {
        let s = SensorsConfig::from_text(
            "mako-2008.toml",
            include_str!("../../configs/sensors/mako-2008.toml"),
        )
        .unwrap();
        let w = WorldConfig::from_document(&Document::new(
            "pool.toml",
            include_str!("../../configs/worlds/pool.toml"),
        ))
        .unwrap();
        (s.sonar, Pool::new(&w))
    }

    /// Still, 2.5 m off the west wall (y = 0), heading `deg` (0 = north, wall to port).
    fn beside_wall(deg: f64) -> VehicleState {
        at_rest(
            0.0,
            Vector3::new(12.0, 2.5, 0.5),
            UnitQuaternion::from_euler_angles(0.0, 0.0, deg.to_radians()),
        )
    }

    /// The prediction's probability is the rate at which the sonar model itself returns
    /// echoes (port-fore, 15 deg off the wall normal, well inside the incidence cut).
    #[test]
    fn predicted_probability_matches_the_sonar_models_echo_rate() {
        let (s, pool) = settings();
        let state = beside_wall(0.0);
        let mut tr = Transducer::new(&s.transducers[0], &s, 3);
        let e = expected(&s, &pool, &tr, &state);
        assert!(e.p > 0.2 && e.p < 0.5, "p = {}", e.p);
        let r = e.range_m.unwrap();
        assert!((r - 2.2).abs() < 0.2, "range {r}");
        let n = 4000;
        let hits = (0..n)
            .filter(|k| tr.ping(&state, &pool, &s, f64::from(*k)).is_some())
            .count();
        let rate = hits as f64 / f64::from(n);
        let sd = (e.p * (1.0 - e.p) / f64::from(n)).sqrt();
        assert!(
            (rate - e.p).abs() < 4.0 * sd,
            "rate {rate}, predicted {}",
            e.p
        );
    }

    /// A cut below the smallest ray incidence removes the echo in the model and the
    /// prediction alike; the prediction moves continuously with the cut in between.
    #[test]
    fn incidence_cut_removes_the_echo_and_the_prediction_is_continuous() {
        let (mut s, pool) = settings();
        let state = beside_wall(0.0);
        s.max_incidence_deg = 8.0; // rays reach 10 deg at best (15 deg axis, 5 deg half beam)
        let mut tr = Transducer::new(&s.transducers[0], &s, 3);
        assert_eq!(expected(&s, &pool, &tr, &state).p, 0.0);
        assert!((0..500).all(|k| tr.ping(&state, &pool, &s, f64::from(k)).is_none()));
        let p: Vec<f64> = [8.0, 9.5, 10.0, 10.5, 12.0]
            .iter()
            .map(|c| {
                s.max_incidence_deg = *c;
                expected(&s, &pool, &tr, &state).p
            })
            .collect();
        assert!(p.windows(2).all(|w| w[1] >= w[0]), "{p:?}");
        assert!(p[1] > 0.0 && p[3] < p[4], "{p:?}");
    }

    /// The range residual is the Gaussian one near the model's echo, keeps its sign, grows
    /// with the distance, and levels off for a reading metres away (an echo off another
    /// wall) where the Gaussian's would be dozens of sigma.
    #[test]
    fn a_range_metres_off_costs_a_bounded_residual() {
        let (s, _) = settings();
        let sigma = range_std_m(&s);
        let near = range_residual(&s, 2.0 + sigma, 2.0);
        assert!((near - 1.0).abs() < 0.01, "one sigma: {near}");
        assert!(range_residual(&s, 2.0 - sigma, 2.0) < 0.0);
        let r: Vec<f64> = [0.0, 1.0, 2.0, 3.0, 5.0, 10.0, 100.0]
            .iter()
            .map(|k| range_residual(&s, 2.0 + k * sigma, 2.0))
            .collect();
        assert!(r.windows(2).all(|w| w[1] >= w[0]), "{r:?}");
        assert!((r[3] - 3.0).abs() < 0.1, "three sigma: {r:?}");
        let far = range_residual(&s, 4.0, 2.0);
        assert!(2.0 / sigma > 20.0, "the Gaussian residual: {}", 2.0 / sigma);
        assert!(far > 3.0 && far < 4.5, "two metres off: {far}");
    }

    /// A ping slot takes the sample within half a period of its time; a slot without one is
    /// a ping without an echo.
    #[test]
    fn slots_read_empty_cells_as_missing_echoes() {
        let ch = Channel {
            name: "sonar1_m".into(),
            samples: vec![(1.02, 2.3), (3.0, 2.4)],
        };
        assert_eq!(
            slots(&ch, &[1.0, 2.0, 3.0], 1.0),
            vec![Some(2.3), None, Some(2.4)]
        );
        assert_eq!(index("sonar3_m"), Some(2));
        assert_eq!(index("depth_adc"), None);
    }
}
