//! The noise package (thesis 5.2, fig 5.7): reusable error sources composed into a per-sensor
//! error model.
//!
//! A sensor pushes its ideal physical value into its [`ErrorModel`] whenever the physics
//! advances ([`ErrorModel::push`]) and takes a corrupted value out when the device is read
//! ([`ErrorModel::sample`]). The model applies, in this fixed order:
//!
//! 1. **latency**: the value that was pushed `latency_s` ago (a delay line);
//! 2. **rate limit**: at most one fresh value per `1 / rate_hz`, held in between
//!    (sample-and-hold; the held value keeps its noise);
//! 3. **bias**: a constant offset;
//! 4. **drift**: a random walk, `std_per_sqrt_s * sqrt(dt)` per step, so its variance grows
//!    linearly with simulated time however often it is sampled;
//! 5. **Gaussian** noise (thesis eq. 5.4) and **uniform** noise (eq. 5.5);
//! 6. **impulse** ("salt and pepper", eq. 5.6): with probability `p` the value is replaced
//!    by the low or the high extreme;
//! 7. **quantisation** to a step (round to nearest);
//! 8. **dropout**: with probability `p` there is no reading at all.
//!
//! Every source is off unless configured. Time is always an argument (simulated seconds);
//! nothing here reads a clock. All randomness comes from the sensor's own stream.

use std::collections::VecDeque;

use rand::RngExt;
use rand_distr::StandardNormal;

use super::rng::SensorRng;

/// The settings of one error model, all optional (`None` / 0 = source off). Units are the
/// sensor's physical unit (m, m/s, m/s^2, deg) unless the name says otherwise.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NoiseSettings {
    pub latency_s: f64,
    pub rate_hz: Option<f64>,
    pub bias: f64,
    pub drift_std_per_sqrt_s: f64,
    pub gaussian_std: f64,
    pub uniform_half_width: f64,
    /// Probability per sample, low value, high value.
    pub impulse: Option<(f64, f64, f64)>,
    pub quantisation_step: Option<f64>,
    pub dropout_probability: f64,
}

impl NoiseSettings {
    /// True when the model passes values through unchanged.
    pub fn is_ideal(&self) -> bool {
        *self == Self::default()
    }
}

/// One value-shaping stage.
#[derive(Debug, Clone, PartialEq)]
enum Stage {
    Bias(f64),
    Drift { std_per_sqrt_s: f64 },
    Gaussian(f64),
    Uniform(f64),
    Impulse { p: f64, low: f64, high: f64 },
    Quantise(f64),
    Dropout(f64),
}

/// A delay line over pushed `(t_s, value)` pairs.
#[derive(Debug, Clone)]
pub struct DelayLine<T> {
    latency_s: f64,
    queue: VecDeque<(f64, T)>,
}

impl<T: Clone> DelayLine<T> {
    pub fn new(latency_s: f64) -> Self {
        Self {
            latency_s,
            queue: VecDeque::new(),
        }
    }

    /// Records `value` as the input at `t_s` (times must not decrease).
    pub fn push(&mut self, t_s: f64, value: T) {
        self.queue.push_back((t_s, value));
    }

    /// The input as it was `latency_s` before `t_s`: the newest pushed value whose time is
    /// at or before `t_s - latency_s`; `None` before the first such value.
    pub fn get(&mut self, t_s: f64) -> Option<T> {
        let due = t_s - self.latency_s;
        while self.queue.len() >= 2 && self.queue[1].0 <= due {
            self.queue.pop_front();
        }
        match self.queue.front() {
            Some((t, v)) if *t <= due => Some(v.clone()),
            _ => None,
        }
    }
}

/// A per-sensor error model: see the module documentation for the order of the stages.
#[derive(Debug, Clone)]
pub struct ErrorModel {
    delay: DelayLine<f64>,
    period_s: Option<f64>,
    held: Option<(f64, Option<f64>)>,
    stages: Vec<Stage>,
    drift: f64,
    drift_t_s: Option<f64>,
}

impl ErrorModel {
    pub fn new(s: &NoiseSettings) -> Self {
        let mut stages = Vec::new();
        if s.bias != 0.0 {
            stages.push(Stage::Bias(s.bias));
        }
        if s.drift_std_per_sqrt_s > 0.0 {
            stages.push(Stage::Drift {
                std_per_sqrt_s: s.drift_std_per_sqrt_s,
            });
        }
        if s.gaussian_std > 0.0 {
            stages.push(Stage::Gaussian(s.gaussian_std));
        }
        if s.uniform_half_width > 0.0 {
            stages.push(Stage::Uniform(s.uniform_half_width));
        }
        if let Some((p, low, high)) = s.impulse
            && p > 0.0
        {
            stages.push(Stage::Impulse { p, low, high });
        }
        if let Some(step) = s.quantisation_step
            && step > 0.0
        {
            stages.push(Stage::Quantise(step));
        }
        if s.dropout_probability > 0.0 {
            stages.push(Stage::Dropout(s.dropout_probability));
        }
        Self {
            delay: DelayLine::new(s.latency_s),
            period_s: s.rate_hz.filter(|r| *r > 0.0).map(|r| 1.0 / r),
            held: None,
            stages,
            drift: 0.0,
            drift_t_s: None,
        }
    }

    /// An error model that changes nothing.
    pub fn ideal() -> Self {
        Self::new(&NoiseSettings::default())
    }

    /// Records the sensor's ideal value at `t_s`.
    pub fn push(&mut self, t_s: f64, value: f64) {
        if self.delay.latency_s > 0.0 {
            self.delay.push(t_s, value);
        } else {
            // No latency: keep only the newest value.
            self.delay.queue.clear();
            self.delay.queue.push_back((t_s, value));
        }
    }

    /// The corrupted reading at `t_s`; `None` for a dropout, or before any value has come
    /// through the delay line.
    pub fn sample(&mut self, t_s: f64, rng: &mut SensorRng) -> Option<f64> {
        if let (Some(period), Some((t_held, out))) = (self.period_s, self.held)
            && t_s < t_held + period
        {
            return out;
        }
        let input = self.delay.get(t_s)?;
        let out = self.apply(input, t_s, rng);
        if let Some(period) = self.period_s {
            // Rate-limited samples fall on a fixed grid (multiples of the period).
            let slot = (t_s / period).floor() * period;
            self.held = Some((slot, out));
        }
        out
    }

    /// Applies the value stages (bias .. dropout) to `value` at `t_s`.
    pub fn apply(&mut self, value: f64, t_s: f64, rng: &mut SensorRng) -> Option<f64> {
        let mut v = value;
        for stage in &self.stages {
            match *stage {
                Stage::Bias(b) => v += b,
                Stage::Drift { std_per_sqrt_s } => {
                    let last = self.drift_t_s.unwrap_or(t_s);
                    let dt = (t_s - last).max(0.0);
                    if dt > 0.0 {
                        let n: f64 = rng.sample(StandardNormal);
                        self.drift += std_per_sqrt_s * dt.sqrt() * n;
                    }
                    self.drift_t_s = Some(t_s.max(last));
                    v += self.drift;
                }
                Stage::Gaussian(std) => {
                    let n: f64 = rng.sample(StandardNormal);
                    v += std * n;
                }
                Stage::Uniform(h) => v += rng.random_range(-h..=h),
                Stage::Impulse { p, low, high } => {
                    if rng.random_bool(p) {
                        v = if rng.random_bool(0.5) { low } else { high };
                    }
                }
                Stage::Quantise(step) => v = (v / step).round() * step,
                Stage::Dropout(p) => {
                    if rng.random_bool(p) {
                        return None;
                    }
                }
            }
        }
        Some(v)
    }
}

/// A one-pole low-pass filter, discretised exactly for any step (`y += (x - y)(1 - e^-dt/tau)`),
/// so its response does not depend on the physics step.
#[derive(Debug, Clone)]
pub struct LowPass {
    tau_s: f64,
    y: Option<f64>,
    t_s: f64,
    /// The last step and its gain, so a fixed physics step costs no `exp` per update.
    cached: (f64, f64),
}

impl LowPass {
    pub fn new(cutoff_hz: f64) -> Self {
        Self {
            tau_s: 1.0 / (2.0 * std::f64::consts::PI * cutoff_hz),
            y: None,
            t_s: 0.0,
            cached: (0.0, 0.0),
        }
    }

    /// Feeds `x` at `t_s` (held since the previous call) and returns the output.
    pub fn update(&mut self, t_s: f64, x: f64) -> f64 {
        let y = match self.y {
            None => x,
            Some(y) => {
                let dt = (t_s - self.t_s).max(0.0);
                if dt != self.cached.0 {
                    self.cached = (dt, 1.0 - (-dt / self.tau_s).exp());
                }
                y + (x - y) * self.cached.1
            }
        };
        self.y = Some(y);
        self.t_s = t_s;
        y
    }
}

/// Hysteresis as backlash (play): the output follows the input only once it has moved more
/// than half the band away, so rising and falling inputs read `band` apart.
#[derive(Debug, Clone)]
pub struct Backlash {
    half_band: f64,
    y: Option<f64>,
}

impl Backlash {
    pub fn new(band: f64) -> Self {
        Self {
            half_band: band / 2.0,
            y: None,
        }
    }

    pub fn update(&mut self, x: f64) -> f64 {
        let y = match self.y {
            None => x,
            Some(y) if x > y + self.half_band => x - self.half_band,
            Some(y) if x < y - self.half_band => x + self.half_band,
            Some(y) => y,
        };
        self.y = Some(y);
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensors::rng::stream;

    fn stats(xs: &[f64]) -> (f64, f64) {
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var.sqrt())
    }

    fn model(s: NoiseSettings) -> (ErrorModel, SensorRng) {
        (ErrorModel::new(&s), stream(1, "noise-test"))
    }

    #[test]
    fn ideal_model_passes_values_through() {
        let (mut m, mut rng) = model(NoiseSettings::default());
        for i in 0..100 {
            let t = f64::from(i) * 0.01;
            m.push(t, t * 3.0);
            assert_eq!(m.sample(t, &mut rng), Some(t * 3.0));
        }
    }

    #[test]
    fn gaussian_has_its_standard_deviation_and_zero_mean() {
        let (mut m, mut rng) = model(NoiseSettings {
            gaussian_std: 0.2,
            ..Default::default()
        });
        let xs: Vec<f64> = (0..20_000)
            .map(|_| m.apply(1.0, 0.0, &mut rng).unwrap())
            .collect();
        let (mean, std) = stats(&xs);
        assert!((mean - 1.0).abs() < 0.01, "{mean}");
        assert!((std - 0.2).abs() < 0.005, "{std}");
    }

    #[test]
    fn uniform_stays_in_its_band_with_the_uniform_variance() {
        let (mut m, mut rng) = model(NoiseSettings {
            uniform_half_width: 0.5,
            ..Default::default()
        });
        let xs: Vec<f64> = (0..20_000)
            .map(|_| m.apply(0.0, 0.0, &mut rng).unwrap())
            .collect();
        assert!(xs.iter().all(|x| x.abs() <= 0.5));
        let (_, std) = stats(&xs);
        // Uniform on [-h, h]: std = h / sqrt(3).
        assert!((std - 0.5 / 3f64.sqrt()).abs() < 0.005, "{std}");
    }

    #[test]
    fn dropout_rate_matches_its_probability() {
        let (mut m, mut rng) = model(NoiseSettings {
            dropout_probability: 0.2,
            ..Default::default()
        });
        let n = 20_000;
        let lost = (0..n)
            .filter(|_| m.apply(1.0, 0.0, &mut rng).is_none())
            .count();
        let rate = lost as f64 / f64::from(n);
        // 4.5 sigma of a binomial(20000, 0.2): 0.0127.
        assert!((rate - 0.2).abs() < 0.0127, "{rate}");
    }

    #[test]
    fn impulse_replaces_values_by_the_extremes_at_its_rate() {
        let (mut m, mut rng) = model(NoiseSettings {
            impulse: Some((0.1, -5.0, 5.0)),
            ..Default::default()
        });
        let xs: Vec<f64> = (0..20_000)
            .map(|_| m.apply(1.0, 0.0, &mut rng).unwrap())
            .collect();
        let low = xs.iter().filter(|&&x| x == -5.0).count() as f64 / 20_000.0;
        let high = xs.iter().filter(|&&x| x == 5.0).count() as f64 / 20_000.0;
        let same = xs.iter().filter(|&&x| x == 1.0).count() as f64 / 20_000.0;
        assert!((low - 0.05).abs() < 0.007 && (high - 0.05).abs() < 0.007);
        assert!((same + low + high - 1.0).abs() < 1e-12);
    }

    #[test]
    fn bias_and_quantisation_are_exact() {
        let (mut m, mut rng) = model(NoiseSettings {
            bias: 0.26,
            quantisation_step: Some(0.1),
            ..Default::default()
        });
        let v = m.apply(1.0, 0.0, &mut rng).unwrap();
        assert!((v - 1.3).abs() < 1e-12, "{v}");
    }

    /// A random walk's variance grows linearly with time, and does not depend on how often
    /// it is sampled.
    #[test]
    fn drift_variance_grows_linearly_with_time_at_any_sampling_rate() {
        let s = NoiseSettings {
            drift_std_per_sqrt_s: 0.1,
            ..Default::default()
        };
        let runs = 2000;
        let mut end_1s = Vec::new();
        let mut end_4s_fine = Vec::new();
        let mut end_4s_coarse = Vec::new();
        let mut rng = stream(3, "drift");
        for _ in 0..runs {
            let mut m = ErrorModel::new(&s);
            m.apply(0.0, 0.0, &mut rng);
            end_1s.push(m.apply(0.0, 1.0, &mut rng).unwrap());
            let mut v = 0.0;
            for k in 2..=40 {
                v = m.apply(0.0, f64::from(k) * 0.1 + 0.0, &mut rng).unwrap();
            }
            let _ = v;
            end_4s_fine.push(m.apply(0.0, 4.0, &mut rng).unwrap());
            let mut c = ErrorModel::new(&s);
            c.apply(0.0, 0.0, &mut rng);
            end_4s_coarse.push(c.apply(0.0, 4.0, &mut rng).unwrap());
        }
        let (_, s1) = stats(&end_1s);
        let (_, s4) = stats(&end_4s_fine);
        let (_, s4c) = stats(&end_4s_coarse);
        // Expected 0.1 and 0.2; sample std of 2000 values is within ~5 % (3 sigma ~ 4.7 %).
        assert!((s1 - 0.1).abs() < 0.005, "{s1}");
        assert!((s4 - 0.2).abs() < 0.01, "{s4}");
        assert!((s4c - 0.2).abs() < 0.01, "{s4c}");
    }

    #[test]
    fn latency_delays_by_exactly_its_time() {
        let (mut m, mut rng) = model(NoiseSettings {
            latency_s: 0.25,
            ..Default::default()
        });
        let mut out = Vec::new();
        for i in 0..100 {
            let t = f64::from(i) * 0.01;
            m.push(t, t);
            out.push((t, m.sample(t, &mut rng)));
        }
        for (t, v) in out {
            if t < 0.25 - 1e-9 {
                assert_eq!(v, None, "at {t}");
            } else {
                let v = v.unwrap();
                assert!((v - (t - 0.25)).abs() < 0.0101, "at {t}: {v}");
                assert!(v <= t - 0.25 + 1e-9);
            }
        }
    }

    #[test]
    fn rate_limit_holds_between_samples() {
        let (mut m, mut rng) = model(NoiseSettings {
            rate_hz: Some(2.0),
            gaussian_std: 1.0,
            ..Default::default()
        });
        let mut values = Vec::new();
        for i in 0..200 {
            let t = f64::from(i) * 0.01;
            m.push(t, 0.0);
            values.push(m.sample(t, &mut rng).unwrap());
        }
        let mut distinct = values.clone();
        distinct.dedup();
        // 2 s at 2 Hz: four held values.
        assert_eq!(distinct.len(), 4, "{distinct:?}");
    }

    #[test]
    fn low_pass_reaches_63_percent_after_one_time_constant_at_any_step() {
        for dt in [0.001, 0.01] {
            let mut f = LowPass::new(1.0);
            f.update(0.0, 0.0);
            let tau = 1.0 / (2.0 * std::f64::consts::PI);
            let steps = (tau / dt).round() as usize;
            let mut y = 0.0;
            for k in 1..=steps {
                y = f.update(k as f64 * dt, 1.0);
            }
            let t = steps as f64 * dt;
            assert!((y - (1.0 - (-t / tau).exp())).abs() < 1e-9, "{dt}: {y}");
        }
    }

    #[test]
    fn backlash_reads_a_band_apart_rising_and_falling() {
        let mut b = Backlash::new(0.1);
        b.update(0.0);
        let up = b.update(1.0);
        let down = {
            b.update(2.0);
            b.update(1.0)
        };
        assert!((down - up - 0.1).abs() < 1e-12, "{up} {down}");
    }
}
