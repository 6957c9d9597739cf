//! Localising the gap: per-channel residual statistics against the noise floor, whiteness
//! (Ljung-Box), correlation with inputs and states at several lags, and a breakdown by regime
//! and by time window.

use serde::Serialize;

use crate::gap::resim::{Floor, Run};

/// Lags (s) at which residuals are correlated with inputs and states.
pub const XCORR_LAGS_S: [f64; 4] = [0.0, 0.5, 1.0, 2.0];
/// Ljung-Box lags (samples).
pub const LJUNG_BOX_LAGS: usize = 10;
/// Length of the time windows of the breakdown (s).
pub const WINDOW_S: f64 = 10.0;

/// Residual statistics of one channel.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelStats {
    pub channel: String,
    pub samples: usize,
    pub mean: f64,
    pub rms: f64,
    /// RMS of the model's own noise at these samples.
    pub noise_floor_rms: f64,
    /// Mean squared normalised residual (1 = as noisy as the model expects).
    pub chi2_per_sample: f64,
    /// Samples per independent sample (autocorrelation of the model's process noise).
    pub tau_samples: f64,
    /// Samples per degree of freedom of the chi-square per sample under the model's own
    /// noise ([`crate::gap::run::chi2_tau`]): what the significance tests read.
    pub chi2_tau_samples: f64,
    /// The calibrated model's known chi2 per sample for this channel on baseline runs (1
    /// without a calibration): what is new is judged against it.
    pub known_chi2_per_sample: f64,
    /// The largest chi2 per sample a run with nothing new reaches, as the calibration's runs
    /// with nothing new scatter ([`crate::gap::model::GapModel::run_bound`]; `None`: not
    /// measured).
    pub run_bound: Option<f64>,
    /// True when chi2 over the known level is beyond the one-sided 3-sigma tail of the
    /// model's own noise (a scaled chi-square, [`chi2_bound`]), and chi2 exceeds the run bound.
    pub significant: bool,
    pub ljung_box_q: f64,
    pub ljung_box_critical_95: f64,
    pub white: bool,
    /// Estimated constant lag (s, + = measurement later than the model) and the RMS with it.
    pub lag_s: f64,
    pub rms_at_lag: f64,
    pub correlations: Vec<Correlation>,
    pub regimes: Vec<RegimeStats>,
    /// Time windows where the disagreement is significant: (start s, end s, chi2 per sample).
    pub windows: Vec<(f64, f64, f64)>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Correlation {
    pub with: &'static str,
    pub lag_s: f64,
    pub r: f64,
    pub significant: bool,
}

#[derive(Debug, Clone, Serialize)]
pub struct RegimeStats {
    pub regime: String,
    pub samples: usize,
    pub chi2_per_sample: f64,
    pub significant: bool,
}

/// The 95 % point of chi-square with `k` degrees of freedom; infinite for `k` = 0 (no
/// statistic exceeds it).
pub fn chi2_critical_95(k: usize) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    ChiSquared::new(k as f64).map_or(f64::INFINITY, |d| d.inverse_cdf(0.95))
}

/// Ljung-Box Q over `h` lags of `x`.
pub fn ljung_box(x: &[f64], h: usize) -> f64 {
    let n = x.len();
    if n <= h + 1 {
        return 0.0;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let c0: f64 = x.iter().map(|v| (v - mean).powi(2)).sum();
    if c0 <= 0.0 {
        return 0.0;
    }
    let nf = n as f64;
    (1..=h)
        .map(|k| {
            let ck: f64 = (0..n - k).map(|i| (x[i] - mean) * (x[i + k] - mean)).sum();
            let r = ck / c0;
            r * r / (nf - k as f64)
        })
        .sum::<f64>()
        * nf
        * (nf + 2.0)
}

/// The integrated autocorrelation time of `x` in samples, `1 + 2 sum rho_k`, summed up to
/// Sokal's self-consistent window (the first lag `M >= 5 tau`, at most `n / 2`): 1 for white
/// noise, `(1 + phi) / (1 - phi)` for an AR(1) series. `x` holds `n / tau` independent
/// samples' worth of information. At least 1; 1 for a constant or short series.
pub fn correlation_time(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 4 {
        return 1.0;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let c0: f64 = x.iter().map(|v| (v - mean).powi(2)).sum();
    if c0 <= 0.0 {
        return 1.0;
    }
    let mut tau = 1.0;
    for k in 1..n / 2 {
        let ck: f64 = (0..n - k).map(|i| (x[i] - mean) * (x[i + k] - mean)).sum();
        tau += 2.0 * ck / c0;
        if k as f64 >= 5.0 * tau {
            break;
        }
    }
    tau.clamp(1.0, n as f64)
}

/// Pearson's correlation of two series (0 when either is constant or shorter than 3).
pub fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    if n < 3 {
        return 0.0;
    }
    let ma = a[..n].iter().sum::<f64>() / n as f64;
    let mb = b[..n].iter().sum::<f64>() / n as f64;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for i in 0..n {
        sab += (a[i] - ma) * (b[i] - mb);
        saa += (a[i] - ma).powi(2);
        sbb += (b[i] - mb).powi(2);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// Inputs and states the residuals are correlated with, at time `t`.
fn regressors(run: &Run, t: f64) -> [(&'static str, f64); 9] {
    let s = run.at(t);
    let (_, pitch, yaw) = s.euler_rad();
    let p = run.percent_at(t);
    [
        ("sin(heading)", yaw.sin()),
        ("cos(heading)", yaw.cos()),
        ("sin(2 heading)", (2.0 * yaw).sin()),
        ("cos(2 heading)", (2.0 * yaw).cos()),
        ("thrust sum", p[0] + p[1]),
        ("thrust difference", p[0] - p[1]),
        ("stern duty", p[3].abs()),
        ("surge speed", s.velocity_body_mps.x),
        ("turn rate", s.angular_velocity_body_radps.z),
    ]
    .map(|(n, v)| (n, if n == "tilt" { pitch } else { v }))
}

pub(crate) fn regime_of(run: &Run, t: f64) -> [String; 4] {
    let s = run.at(t);
    let (roll, pitch, yaw) = s.euler_rad();
    let p = run.percent_at(t);
    let heading = yaw.to_degrees().rem_euclid(360.0);
    let quadrant = ["heading N", "heading E", "heading S", "heading W"]
        [(((heading + 45.0) % 360.0) / 90.0) as usize % 4];
    let thrust = if p[0].abs() < 1.0 && p[1].abs() < 1.0 {
        "thrust off"
    } else if p[0] * p[1] < 0.0 {
        "spot turn"
    } else if p[0] + p[1] < 0.0 {
        "thrust reverse"
    } else if p[0] + p[1] > 120.0 {
        "thrust forward > 60 %"
    } else {
        "thrust forward <= 60 %"
    };
    let tilt = if roll.abs().max(pitch.abs()).to_degrees() > 3.0 {
        "tilted > 3 deg"
    } else {
        "level"
    };
    let u = s.velocity_body_mps.x.abs();
    let speed = if u < 0.1 {
        "speed < 0.1 m/s"
    } else if u < 0.25 {
        "speed 0.1-0.25 m/s"
    } else {
        "speed > 0.25 m/s"
    };
    [quadrant, thrust, tilt, speed].map(str::to_string)
}

/// The probability a normal variable stays below 3 standard deviations: the significance
/// tests' one-sided tail.
pub const THREE_SIGMA_CDF: f64 = 0.998_650_101_968_37;

/// The chi-square per sample that noise alone exceeds with the one-sided 3-sigma tail
/// probability, for `dof` degrees of freedom: the chi-square's quantile over `dof`. With few
/// degrees of freedom (a position channel whose process noise wanders over the whole run) it
/// lies far above the normal approximation `1 + 3 sqrt(2 / dof)`.
pub fn chi2_bound(dof: f64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    let dof = dof.max(1.0);
    ChiSquared::new(dof).map_or(f64::INFINITY, |d| d.inverse_cdf(THREE_SIGMA_CDF) / dof)
}

/// Whether chi2 per sample over `n` samples, `tau` samples per degree of freedom, is beyond
/// what the noise reaches ([`chi2_bound`]).
fn excess(chi2: f64, n: usize, tau: f64) -> bool {
    chi2 > chi2_bound(n as f64 / tau)
}

/// What a channel's disagreement is judged against: the calibrated model's known level
/// (1 = the noise floor alone) and, when the calibration measured how its runs with nothing
/// new scatter, the bound one such run stays under.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Known {
    pub level: f64,
    pub run_bound: Option<f64>,
}

impl Known {
    /// The same disagreement judged against another noise floor: the excess of the level and
    /// of the run bound over the floor scaled by `w` ([`known_weight`]). `w = 1` (the floor the
    /// levels were measured on) leaves them as they are.
    #[must_use]
    pub fn under(self, w: f64) -> Self {
        Self {
            level: level_under(self.level, w),
            run_bound: self.run_bound.map(|b| level_under(b, w)),
        }
    }
}

/// A chi-square per sample `level` over the noise floor with its excess over 1 scaled by `w`
/// ([`known_weight`]); `level` itself for `w = 1`.
pub fn level_under(level: f64, w: f64) -> f64 {
    if w == 1.0 {
        level
    } else {
        1.0 + (level - 1.0).max(0.0) * w
    }
}

/// How much of a channel's known disagreement shows against the noise floor `now` when it was
/// measured against the floor `base` (the calibrated model's). A channel's level is its mean
/// `r^2 / sigma^2` over the samples (the chi-square per independent sample: the residuals are
/// normalised by the floor's `sigma` and correlation time, and counted per independent
/// sample), so a residual `d` the model's runs share reads `sum(d^2 / sigma^2) / n` of excess
/// over 1, and against a floor with more noise (a named depth EMI raises `sigma` where the
/// stern motor runs) `sum(1 / sigma_now^2)` over `sum(1 / sigma_base^2)` of it, for a `d` of
/// one size throughout. Against the old level, the chi-square a disagreement the calibration's
/// own runs show keeps under the new floor looks below the known level, and a real second
/// effect there looks like a fit of known disagreement. 1 for identical floors, or where the
/// two do not describe the same samples.
pub fn known_weight(base: &Floor, now: &Floor) -> f64 {
    if base.sigma.len() != now.sigma.len() || base.sigma.is_empty() {
        return 1.0;
    }
    let precision = |f: &Floor| f.sigma.iter().map(|s| 1.0 / (s * s)).sum::<f64>();
    let w = precision(now) / precision(base);
    if w.is_finite() && w > 0.0 { w } else { 1.0 }
}

/// Whether a whole channel's chi-square per sample `chi2` over `n` samples (`tau` samples
/// per degree of freedom, [`crate::gap::run::chi2_tau`]) disagrees: over its known level
/// beyond the 3-sigma tail of the noise, and above the bound a run with nothing new stays
/// under, when known.
pub fn disagrees(chi2: f64, n: usize, tau: f64, known: Known) -> bool {
    excess(chi2 / known.level.max(1.0), n, tau) && known.run_bound.is_none_or(|b| chi2 > b)
}

/// Statistics of one channel's residuals `r` at times `t` against the floor; significance
/// (whole channel, regimes, windows) is judged on chi2 over `known.level`; the whole channel
/// is significant only above `known.run_bound` too (a regime or a window is a share of the
/// run, which the bound does not speak for).
pub fn channel_stats(
    name: &str,
    t: &[f64],
    r: &[f64],
    floor: &Floor,
    run: &Run,
    lag: (f64, f64),
    known: Known,
) -> ChannelStats {
    let Known { level, run_bound } = known;
    let known = level.max(1.0);
    let n = r.len();
    let nf = n.max(1) as f64;
    let z: Vec<f64> = r.iter().zip(&floor.sigma).map(|(a, s)| a / s).collect();
    let chi2 = z.iter().map(|v| v * v).sum::<f64>() / nf;
    let q = ljung_box(&z, LJUNG_BOX_LAGS);
    let crit = chi2_critical_95(LJUNG_BOX_LAGS);
    // Correlations with inputs and states at several lags.
    let mut correlations = Vec::new();
    let n_eff = (nf / floor.tau).max(3.0);
    for lag_s in XCORR_LAGS_S {
        let regs: Vec<[(&'static str, f64); 9]> =
            t.iter().map(|ti| regressors(run, ti - lag_s)).collect();
        for j in 0..9 {
            let x: Vec<f64> = regs.iter().map(|r| r[j].1).collect();
            let rr = pearson(&z, &x);
            correlations.push(Correlation {
                with: regs.first().map_or("", |r| r[j].0),
                lag_s,
                r: rr,
                significant: rr.abs() > 3.0 / n_eff.sqrt(),
            });
        }
    }
    correlations.sort_by(|a, b| b.r.abs().total_cmp(&a.r.abs()));
    correlations.truncate(6);
    // Regimes.
    let mut groups: std::collections::BTreeMap<String, (usize, f64)> = Default::default();
    for (ti, zi) in t.iter().zip(&z) {
        for g in regime_of(run, *ti) {
            let e = groups.entry(g).or_default();
            e.0 += 1;
            e.1 += zi * zi;
        }
    }
    let regimes = groups
        .into_iter()
        .map(|(regime, (k, s))| {
            let c = s / k.max(1) as f64;
            RegimeStats {
                regime,
                samples: k,
                chi2_per_sample: c,
                significant: excess(c / known, k, floor.chi2_tau()),
            }
        })
        .collect();
    // Time windows.
    let mut windows = Vec::new();
    let end = t.last().copied().unwrap_or(0.0);
    let mut w0 = 0.0;
    while w0 < end {
        let idx: Vec<usize> = (0..n)
            .filter(|&i| t[i] >= w0 && t[i] < w0 + WINDOW_S)
            .collect();
        if !idx.is_empty() {
            let c = idx.iter().map(|&i| z[i] * z[i]).sum::<f64>() / idx.len() as f64;
            if excess(c / known, idx.len(), floor.chi2_tau()) {
                windows.push((w0, w0 + WINDOW_S, c));
            }
        }
        w0 += WINDOW_S;
    }
    ChannelStats {
        channel: name.to_string(),
        samples: n,
        mean: r.iter().sum::<f64>() / nf,
        rms: (r.iter().map(|v| v * v).sum::<f64>() / nf).sqrt(),
        noise_floor_rms: (floor.sigma.iter().map(|s| s * s).sum::<f64>() / nf).sqrt(),
        chi2_per_sample: chi2,
        tau_samples: floor.tau,
        chi2_tau_samples: floor.chi2_tau(),
        known_chi2_per_sample: known,
        run_bound,
        significant: disagrees(chi2, n, floor.chi2_tau(), Known { level, run_bound }),
        ljung_box_q: q,
        ljung_box_critical_95: crit,
        white: q <= crit,
        lag_s: lag.0,
        rms_at_lag: lag.1,
        correlations,
        regimes,
        windows,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A channel disagrees above its known level by more than the noise allows, unless runs
    /// with nothing new reach that far too: then only above their bound.
    #[test]
    fn a_channel_disagrees_only_beyond_the_scatter_of_runs_with_nothing_new() {
        let known = |run_bound| Known {
            level: 2.0,
            run_bound,
        };
        // 10,000 independent samples: 3 sigma of the noise is 4.2 % of the level.
        let (n, tau) = (10_000, 1.0);
        assert!(!disagrees(2.05, n, tau, known(None)));
        assert!(disagrees(2.2, n, tau, known(None)));
        assert!(disagrees(3.5, n, tau, known(None)));
        assert!(!disagrees(3.5, n, tau, known(Some(4.0))));
        assert!(disagrees(4.5, n, tau, known(Some(4.0))));
        // A bound below the known level does not lower the noise criterion.
        assert!(!disagrees(2.05, n, tau, known(Some(1.5))));
        // Without a calibration the level is the noise floor.
        let floor = Known {
            level: 0.5,
            run_bound: None,
        };
        assert!(disagrees(1.1, n, tau, floor));
    }

    /// The bound is the chi-square's one-sided 3-sigma quantile per degree of freedom: at
    /// one degree, the square of the two-sided 3-sigma normal quantile 3.2049 (10.27); at many,
    /// near the normal approximation `1 + 3 sqrt(2 / dof)` (Wilson-Hilferty 1.04297 at 10,000).
    #[test]
    fn the_bound_is_the_chi_square_quantile() {
        assert!(
            (chi2_bound(1.0) - 3.2049_f64.powi(2)).abs() < 0.01,
            "{}",
            chi2_bound(1.0)
        );
        assert!(
            (chi2_bound(10_000.0) - 1.04297).abs() < 1e-4,
            "{}",
            chi2_bound(10_000.0)
        );
        assert!(chi2_bound(4.0) > 1.0 + 3.0 * (2.0f64 / 4.0).sqrt() + 1.0);
    }

    #[test]
    fn chi2_critical_matches_tables() {
        // chi2(0.95; k) from standard tables.
        for (k, table) in [(1, 3.841), (2, 5.991), (10, 18.307), (30, 43.773)] {
            assert!((chi2_critical_95(k) - table).abs() < 1e-3, "k = {k}");
        }
    }

    /// White noise has a correlation time of one sample; an AR(1) series with coefficient
    /// phi has (1 + phi) / (1 - phi) (to 15 %: over 3 standard errors at 200,000 samples).
    #[test]
    fn correlation_time_of_white_and_ar1_series() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let white: Vec<f64> = (0..200_000)
            .map(|_| StandardNormal.sample(&mut rng))
            .collect();
        let t = correlation_time(&white);
        assert!((t - 1.0).abs() < 0.15, "white noise: {t}");
        for phi in [0.5_f64, 0.9] {
            let mut v = 0.0;
            let ar: Vec<f64> = white
                .iter()
                .map(|e| {
                    v = phi * v + e;
                    v
                })
                .collect();
            let want = (1.0 + phi) / (1.0 - phi);
            let t = correlation_time(&ar);
            assert!(
                (t - want).abs() < 0.15 * want,
                "phi {phi}: {t}, want {want}"
            );
        }
        assert_eq!(correlation_time(&[2.0; 50]), 1.0);
    }

    /// White noise exceeds the 95 % critical value about 5 % of the time (the test is
    /// calibrated), and a sine is flagged by a wide margin.
    #[test]
    fn ljung_box_flags_a_sine_and_passes_noise() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let trials = 400;
        let rejected = (0..trials)
            .filter(|_| {
                let noise: Vec<f64> = (0..500).map(|_| StandardNormal.sample(&mut rng)).collect();
                ljung_box(&noise, 10) >= chi2_critical_95(10)
            })
            .count();
        let rate = rejected as f64 / trials as f64;
        assert!((0.02..=0.09).contains(&rate), "false-alarm rate {rate}");
        let sine: Vec<f64> = (0..500).map(|i| (i as f64 * 0.1).sin()).collect();
        assert!(ljung_box(&sine, 10) > 10.0 * chi2_critical_95(10));
    }
}
