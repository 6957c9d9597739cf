//! Naming the missing effect: fit every candidate on the training part of the data with the
//! bounded Levenberg-Marquardt engine ([`crate::gap::lsq`]), score it, test it against its
//! guards, rank, and accept the best candidate that passes every guard; repeat greedily.
//!
//! Residuals are normalised by the model's noise floor and by the square root of the
//! channel's autocorrelation time (`tau`), so `sum r^2` is a chi-square in independent
//! samples and `n_eff = sum n_c / tau_c` is the sample size.
//!
//! Data that come from a real vehicle never fit the model to its own noise floor: what is
//! left after the best fit is model error, larger than the floor and correlated. The gain of
//! a candidate is therefore judged against the residual variance it leaves (a quasi-likelihood
//! scale `s2 = max(1, chi2_after / (n_eff - k))`, as an F-test does) and against the model's
//! own correlated process noise (`noise_factor`):
//! `delta_BIC = (chi2_before - chi2_after) / (s2 * noise_factor) - k ln(n_eff)`.
//!
//! The guards ([`Guards`]): an effect is named only when its parameters lie inside their
//! physical bounds, its 95 % interval is finite and excludes "no effect", it beats "no effect"
//! by [`BIC_MARGIN`], it passes its signature test, and it shrinks the gap on the held-out
//! blocks of the data it was not fitted to by at least [`HELDOUT_MIN_GAIN`].

use nalgebra::DVector;

use crate::gap::GapError;
use crate::gap::candidate::{self, Candidate, Guards};
use crate::gap::effects::{self, Configs, Effect, Kind};
use crate::gap::format::Measurement;
use crate::gap::lsq::{self, Bounds};
use crate::gap::model::EnabledEffect;
use crate::gap::resim::{self, Floor, Run};

pub(crate) use contacts::left_out_where_touched;
use contacts::{beyond_base, search_contacts};

/// A candidate must beat "no effect" by this much BIC to be named (Kass and Raftery 1995:
/// a BIC difference above 10 is "very strong" evidence).
pub const BIC_MARGIN: f64 = 10.0;
/// At most this many effects are added greedily.
pub const MAX_EFFECTS: usize = 3;
/// Signature test: the effect's predicted change must correlate with the residual at least
/// this much in the signature channels...
pub const SIGNATURE_MIN_CORRELATION: f64 = 0.2;
/// ...and at least this share of the chi-square reduction must come from those channels.
pub const SIGNATURE_MIN_SHARE: f64 = 0.5;
/// Held-out guard: the fitted effect must lower the held-out chi-square (scaled as the
/// training gain is) by at least this much: the 95 % point of chi-square with one degree of
/// freedom, so noise fitted on the training blocks rarely passes by chance.
pub const HELDOUT_MIN_GAIN: f64 = 3.84;

/// Starting points scanned along each parameter axis, in units of the effect's scale. The
/// +-0.25 steps find a small effect whose chi-square holds a shallow minimum between zero
/// and the coarser steps.
pub const START_SCAN: [f64; 9] = [-4.0, -2.0, -1.0, -0.25, 0.25, 1.0, 2.0, 4.0, 8.0];
/// The coarser scan of a later round, beside the candidate's values in the round before
/// ([`fit_mean`]).
pub const LATER_SCAN: [f64; 4] = [-2.0, -0.5, 0.5, 2.0];

/// How the data are split into the blocks a candidate is fitted on and the blocks it is
/// judged on: time blocks of `block_s`, even blocks train, odd blocks held out. Alternating
/// blocks put every part of a programme (straight runs, turns, dives) into both halves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Split {
    pub block_s: f64,
}

impl Split {
    /// Two 5 s shooting segments per block.
    pub const DEFAULT: Self = Self { block_s: 10.0 };

    pub fn is_training(&self, t_s: f64) -> bool {
        (t_s / self.block_s).floor().rem_euclid(2.0) < 0.5
    }
}

/// Normalised residuals of the modelled channels, with each element's channel and part.
#[derive(Debug, Clone, Default)]
pub struct Residuals {
    pub values: Vec<f64>,
    pub owner: Vec<usize>,
    pub training: Vec<bool>,
    /// Each element's sample time (s).
    pub times: Vec<f64>,
    /// How long after a contact each element's channel stays left out (s,
    /// [`Run::contact_memory_s`] of the setup's base run).
    pub memory_s: Vec<f64>,
}

impl Residuals {
    pub fn part(&self, training: bool) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.values
            .iter()
            .zip(&self.training)
            .enumerate()
            .filter(move |(_, (_, t))| **t == training)
            .map(|(i, (v, _))| (i, *v))
    }

    pub fn chi2(&self, training: bool) -> f64 {
        self.part(training).map(|(_, v)| v * v).sum()
    }

    pub fn training_vector(&self) -> DVector<f64> {
        DVector::from_iterator(
            self.training.iter().filter(|t| **t).count(),
            self.part(true).map(|(_, v)| v),
        )
    }

    pub fn all_chi2(&self) -> f64 {
        self.values.iter().map(|v| v * v).sum()
    }
}

/// The re-simulation context one greedy round fits against.
pub struct Setup<'a> {
    pub m: &'a Measurement,
    pub base: Configs,
    pub clean: Run,
    pub floors: &'a [Option<Floor>],
    pub split: Split,
    /// Between-run spread of each effect on baseline runs (`GapModel::spread`).
    pub spread: Vec<EnabledEffect>,
    /// Each channel's known chi-square per sample (`GapModel::known_chi2`; 1: the noise
    /// floor), by channel index: what the report's gap measure is taken against.
    pub known: Vec<f64>,
}

impl Setup<'_> {
    /// The setup with `model`'s known disagreement as the level of each channel, its excess
    /// over the floor scaled by `weights` (by channel index; [`known_weights`]: 1 where no
    /// named noise source raised the floor).
    #[must_use]
    pub fn with_known(mut self, model: &crate::gap::model::GapModel, weights: &[f64]) -> Self {
        self.known = self
            .m
            .channels
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let w = weights.get(i).copied().unwrap_or(1.0);
                model.known(&c.name).under(w).level
            })
            .collect();
        self
    }

    /// Channel by channel (index), the chi-square per independent sample of `r` on `part`
    /// (the training blocks, the held-out blocks, or all of them): the report's gap measure
    /// before each channel is taken against its known level and averaged. Wall contacts are
    /// left out ([`Setup::residuals`] holds zeros there): counted, they would dilute the level
    /// by the share of a channel's samples the contacts take.
    pub fn part_levels(&self, r: &Residuals, part: Option<bool>) -> Vec<(usize, f64)> {
        self.modelled()
            .into_iter()
            .filter_map(|i| {
                let tau = self.floors[i].as_ref()?.tau;
                let name = &self.m.channels[i].name;
                let (sum, n) = r
                    .values
                    .iter()
                    .zip(&r.owner)
                    .zip(&r.training)
                    .zip(&r.times)
                    .filter(|(((_, o), t), time)| {
                        **o == i
                            && part.is_none_or(|p| **t == p)
                            && !self.clean.in_contact(**time, name)
                    })
                    .fold((0.0, 0usize), |(s, n), (((v, _), _), _)| (s + v * v, n + 1));
                (n > 0).then(|| (i, sum / (n as f64 / tau)))
            })
            .collect()
    }

    /// The between-run variance of each of `effect`'s parameters, in units of its scales.
    fn spread_variance(&self, effect: &Effect) -> Vec<f64> {
        let found = self.spread.iter().find(|s| s.effect.name == effect.name);
        effect
            .scales
            .iter()
            .enumerate()
            .map(|(j, scale)| {
                found
                    .and_then(|s| s.values.get(j))
                    .map_or(0.0, |v| (v / scale).powi(2))
            })
            .collect()
    }

    /// Channels (indices into `m.channels`) that are both modelled and have a floor.
    pub fn modelled(&self) -> Vec<usize> {
        (0..self.m.channels.len())
            .filter(|&i| self.floors[i].is_some())
            .collect()
    }

    fn sample_times(&self, i: usize) -> Vec<f64> {
        let ch = &self.m.channels[i];
        if crate::gap::sonar::index(&ch.name).is_some() {
            let times = crate::gap::sonar::ping_times(
                &self.base.sensors.sonar,
                self.m.experiment.duration_s,
            );
            return times.iter().flat_map(|t| [*t, *t]).collect();
        }
        ch.samples.iter().map(|(t, _)| *t).collect()
    }

    /// Independent sample count of one part (`None`: all).
    pub fn n_eff(&self, part: Option<bool>) -> f64 {
        self.independent_samples(part, |_| true).max(1.0)
    }

    /// Independent sample count of one part (`None`: all) over the modelled channels `keep`
    /// selects (by index), wall contacts left out: the chi-square the noise floor alone puts
    /// there, the residuals being normalised by the floor and its correlation time.
    pub fn independent_samples(&self, part: Option<bool>, keep: impl Fn(usize) -> bool) -> f64 {
        self.weighted_samples(part, keep, |_| 1.0)
    }

    /// The chi-square a run with nothing new puts on one part over the modelled channels
    /// `keep` selects: [`Setup::independent_samples`] with each channel at its known level.
    pub fn known_energy(&self, part: Option<bool>, keep: impl Fn(usize) -> bool) -> f64 {
        self.weighted_samples(part, keep, |i| {
            self.known.get(i).copied().unwrap_or(1.0).max(1.0)
        })
    }

    fn weighted_samples(
        &self,
        part: Option<bool>,
        keep: impl Fn(usize) -> bool,
        weight: impl Fn(usize) -> f64,
    ) -> f64 {
        self.modelled()
            .into_iter()
            .filter(|&i| keep(i))
            .filter_map(|i| {
                let f = self.floors[i].as_ref()?;
                let n = self
                    .sample_times(i)
                    .iter()
                    .filter(|t| part.is_none_or(|p| self.split.is_training(**t) == p))
                    .filter(|t| !self.clean.in_contact(**t, &self.m.channels[i].name))
                    .count();
                Some(weight(i) * n as f64 / f.tau)
            })
            .sum::<f64>()
    }

    /// The model's own null residuals of one part (`Some(true)` training, `Some(false)` held
    /// out, `None` all), normalised as [`Setup::residuals`]: one vector per ensemble run
    /// (process noise only), and the per-element variance the white measurement noise adds.
    pub fn null_vectors(&self, part: Option<bool>) -> (Vec<Vec<f64>>, Vec<f64>) {
        let members = self
            .modelled()
            .iter()
            .filter_map(|&i| self.floors[i].as_ref().map(|f| f.null.len()))
            .min()
            .unwrap_or(0);
        let mut null = vec![Vec::new(); members];
        let mut white = Vec::new();
        for i in self.modelled() {
            let ch = &self.m.channels[i];
            let Some(f) = &self.floors[i] else { continue };
            if resim::predict(&self.base, &self.clean, ch, 0.0).is_none()
                && crate::gap::sonar::index(&ch.name).is_none()
            {
                continue;
            }
            let times = self.sample_times(i);
            let keep: Vec<bool> = times
                .iter()
                .map(|t| part.is_none_or(|p| self.split.is_training(*t) == p))
                .collect();
            // Left out where the fitted residuals are (contact), as zeros of the same length.
            let live: Vec<f64> = times
                .iter()
                .map(|t| f64::from(u8::from(!self.clean.in_contact(*t, &ch.name))))
                .collect();
            let k = f.tau.sqrt();
            for (m, v) in null.iter_mut().enumerate() {
                v.extend(
                    f.null[m]
                        .iter()
                        .zip(&f.sigma)
                        .zip(&keep)
                        .zip(&live)
                        .filter(|((_, k), _)| **k)
                        .map(|(((d, s), _), l)| l * d / (s * k)),
                );
            }
            white.extend(
                f.measurement_std
                    .iter()
                    .zip(&f.sigma)
                    .zip(&keep)
                    .zip(&live)
                    .filter(|((_, k), _)| **k)
                    .map(|(((m, s), _), l)| l * (m / (s * k)).powi(2)),
            );
        }
        (null, white)
    }

    /// Normalised residuals of all modelled channels for configs `c` and run `run`; zero
    /// where the setup's base re-simulation touched the pool ([`Run::contacts`]).
    pub fn residuals(&self, c: &Configs, run: &Run) -> Residuals {
        let mut out = Residuals::default();
        for i in self.modelled() {
            let ch = &self.m.channels[i];
            let Some(f) = &self.floors[i] else { continue };
            let times = self.sample_times(i);
            // Sonar: presence deviance and range residuals, already normalised.
            let values: Vec<f64> = if let Some(r) =
                crate::gap::sonar::residuals(c, run, self.m.experiment.duration_s, ch)
            {
                r
            } else {
                let Some(p) = resim::predict(c, run, ch, 0.0) else {
                    continue;
                };
                let k = f.tau.sqrt();
                resim::residuals(ch, &p)
                    .iter()
                    .zip(&f.sigma)
                    .map(|(r, s)| r / (s * k))
                    .collect()
            };
            let memory_s = self.clean.contact_memory_s(&ch.name);
            for (v, t) in values.iter().zip(&times) {
                // Where the base re-simulation touched the pool, contact impulses make the
                // residual jump with any change of a parameter: left out of every fit (a
                // zero), the same samples for every candidate of the setup.
                out.values.push(if self.clean.in_contact(*t, &ch.name) {
                    0.0
                } else {
                    *v
                });
                out.owner.push(i);
                out.training.push(self.split.is_training(*t));
                out.times.push(*t);
                out.memory_s.push(memory_s);
            }
        }
        out
    }

    /// True when a fit of `effect` must re-run the physics.
    fn resimulates(&self, effect: &Effect) -> bool {
        effect.physics || (self.base.shooting.segment_s.is_some() && effect.moves_anchors)
    }

    /// Residuals with `effect` applied at `params`.
    pub fn eval(&self, effect: &Effect, params: &[f64]) -> Option<Residuals> {
        self.evaluate(effect, params).map(|e| e.residuals)
    }
}

/// Channel by channel (index), how much of a known level's excess shows against the floors
/// `now` when it was measured against `base` ([`crate::gap::residuals::known_weight`]); 1
/// where either has no floor.
pub fn known_weights(base: &[Option<Floor>], now: &[Option<Floor>]) -> Vec<f64> {
    base.iter()
        .zip(now)
        .map(|(b, f)| match (b, f) {
            (Some(b), Some(f)) => crate::gap::residuals::known_weight(b, f),
            _ => 1.0,
        })
        .collect()
}

/// The mean chi-square gain of a linearised fit along Jacobian `j` (covariance `ainv`) on
/// the null residuals, over its expectation `k` for independent noise; at least 1.
fn null_factor(
    j: &nalgebra::DMatrix<f64>,
    ainv: &nalgebra::DMatrix<f64>,
    null: &[Vec<f64>],
    white: &[f64],
) -> f64 {
    let k = j.ncols();
    if null.is_empty() || k == 0 {
        return 1.0;
    }
    let mut process = 0.0;
    for v in null {
        if v.len() != j.nrows() {
            return 1.0;
        }
        let jt = j.transpose() * DVector::from_column_slice(v);
        process += (jt.transpose() * ainv * &jt)[(0, 0)];
    }
    process /= null.len() as f64;
    // White part: sum_i w_i P_ii with P = J A^-1 J^T.
    let measurement: f64 = (0..j.nrows().min(white.len()))
        .map(|i| {
            let row = j.row(i);
            white[i] * (row * ainv * row.transpose())[(0, 0)]
        })
        .sum();
    ((process + measurement) / k as f64).max(1.0)
}

/// The interval guard: every interval finite, and the no-effect point 0 outside the joint
/// 95 % confidence region (the Wald statistic `x^T C^-1 x` above the 95 % point of
/// chi-square with k degrees of freedom). For one parameter that is "the interval excludes
/// 0"; for two correlated parameters (linear and quadratic drag) each interval may hold 0
/// while their combination is clearly off.
pub fn interval_excludes_zero(
    ci: &[[f64; 2]],
    x: &DVector<f64>,
    covariance: Option<&nalgebra::DMatrix<f64>>,
    variance_factor: f64,
) -> bool {
    if !ci.iter().all(|c| c[0].is_finite() && c[1].is_finite()) {
        return false;
    }
    let Some(inv) = covariance.and_then(|c| (c * variance_factor).try_inverse()) else {
        return false;
    };
    let wald = (x.transpose() * inv * x)[(0, 0)];
    wald > crate::gap::residuals::chi2_critical_95(x.len())
}

/// The signature test of a mean-type fit: correlation of the effect's change with the
/// disagreement in the signature channels, and their share of the gain.
///
/// The residual there is new disagreement plus noise plus the disagreement the calibration's
/// own runs show (each channel's known level), and neither of the last two correlates with a
/// new effect: a true effect's correlation with the raw residual falls with what they carry,
/// however well it explains the new disagreement. The correlation is therefore taken against
/// the residual's energy beyond what a run with nothing new puts there (the noise floor at
/// each channel's known level, [`Setup::known_energy`]; the floor alone on an uncalibrated
/// model), Spearman's correction for attenuation (1904): the observed correlation over the
/// square root of the residual's reliability.
/// The energy beyond the floor is never taken below what the effect explains, so the
/// corrected correlation stays at most about 1.
///
/// The sonar ranges are a function of the pose (the walls seen from the vehicle's position
/// along its heading): an effect whose signature channels include the pose moves them as it
/// moves the track or the heading (a compass offset turns every segment's anchored heading,
/// and with it every transducer's line of sight), so their gain counts as its own, as an
/// effect's `also_moves` channels do. They do not enter the correlation.
fn signature(setup: &Setup<'_>, effect: &Effect, r0: &Residuals, r1: &Residuals) -> (bool, String) {
    let in_sig = |i: usize| effect.channels.contains(&setup.m.channels[i].name.as_str());
    let witnesses = pose_witnesses(setup, effect);
    let moves = |i: usize| {
        let name = setup.m.channels[i].name.as_str();
        effect.also_moves.contains(&name) || witnesses.contains(&name)
    };
    let (mut dot, mut dd, mut rr, mut gain_sig, mut gain_all) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut by_channel = vec![0.0; setup.m.channels.len()];
    for (idx, a) in r0.part(true) {
        let b = r1.values[idx];
        let g = a * a - b * b;
        gain_all += g;
        by_channel[r0.owner[idx]] += g;
        if in_sig(r0.owner[idx]) || moves(r0.owner[idx]) {
            gain_sig += g;
        }
        if in_sig(r0.owner[idx]) {
            let d = a - b; // = predicted change of the effect, normalised
            dot += d * a;
            dd += d * d;
            rr += a * a;
        }
    }
    // Sonar channels' presence deviance is normalised otherwise: no floor share taken out.
    let floor_share = setup.known_energy(Some(true), |i| {
        in_sig(i) && crate::gap::sonar::index(&setup.m.channels[i].name).is_none()
    });
    let beyond_noise = (rr - floor_share).max(dd);
    let corr = if dd > 0.0 && beyond_noise > 0.0 {
        dot / (dd * beyond_noise).sqrt()
    } else {
        0.0
    };
    if tracing::enabled!(tracing::Level::DEBUG) {
        let gains: Vec<String> = by_channel
            .iter()
            .enumerate()
            .filter(|(_, g)| **g != 0.0)
            .map(|(i, g)| format!("{} {g:.1}", setup.m.channels[i].name))
            .collect();
        tracing::debug!(
            effect = effect.name,
            gains = gains.join(", "),
            "signature: the improvement by channel"
        );
    }
    let share = if gain_all > 0.0 {
        gain_sig / gain_all
    } else {
        0.0
    };
    (
        corr >= SIGNATURE_MIN_CORRELATION && share >= SIGNATURE_MIN_SHARE,
        format!(
            "{}: correlation with the disagreement beyond what runs with nothing new show in {} = {corr:.2} (>= {SIGNATURE_MIN_CORRELATION}), \
             share of the improvement there{} = {:.0} % (>= {:.0} %)",
            effect.signature,
            effect.channels.join("/"),
            {
                let also: Vec<&str> = effect
                    .also_moves
                    .iter()
                    .copied()
                    .chain(witnesses.iter().copied())
                    .collect();
                if also.is_empty() {
                    String::new()
                } else {
                    format!(" and in {}", also.join("/"))
                }
            },
            share * 100.0,
            SIGNATURE_MIN_SHARE * 100.0
        ),
    )
}

/// The pose channels: the track (`x_m`, `y_m`) and the heading (`compass_deg`).
const POSE_CHANNELS: [&str; 3] = ["x_m", "y_m", "compass_deg"];

/// The measurement's sonar channels, where `effect`'s signature channels include the pose
/// ([`signature`]); none otherwise.
fn pose_witnesses<'m>(setup: &Setup<'m>, effect: &Effect) -> Vec<&'m str> {
    if !effect.channels.iter().any(|c| POSE_CHANNELS.contains(c)) {
        return Vec::new();
    }
    setup
        .m
        .channels
        .iter()
        .map(|c| c.name.as_str())
        .filter(|n| crate::gap::sonar::index(n).is_some() && !effect.channels.contains(n))
        .collect()
}

/// A fit of one candidate on one part of the data, scored.
struct Scored {
    params: Vec<f64>,
    ci: Vec<[f64; 2]>,
    chi2_before: f64,
    chi2_after: f64,
    delta_bic: f64,
    delta_bic_uncalibrated: f64,
    /// The effect's scaling of chi-square gains (`noise_factor * variance_factor`).
    scale: f64,
    noise_factor: f64,
    variance_factor: f64,
    interval_excludes_zero: bool,
    inside_bounds: bool,
    residuals: Residuals,
    evaluations: usize,
}

/// Fits `effect` on the training part (`Some(true)`) or on all the data (`None`), from
/// `starts`, and scores it.
fn fit_part(
    setup: &Setup<'_>,
    effect: &'static Effect,
    r0: &Residuals,
    part: Option<bool>,
    starts: &[DVector<f64>],
    evaluations: &memo::Evaluations<'_, '_>,
) -> Option<Scored> {
    let k = effect.parameters.len();
    let scales = effect.scales;
    let to_params =
        |x: &DVector<f64>| -> Vec<f64> { x.iter().zip(scales).map(|(v, s)| v * s).collect() };
    let select = |r: &Residuals| -> DVector<f64> {
        match part {
            Some(_) => r.training_vector(),
            None => DVector::from_column_slice(&r.values),
        }
    };
    // The starts inside the box, as the search takes them: the contacts below are the ones
    // of the start it begins from.
    let bounds = Bounds::scaled(effect.bounds, scales);
    let starts: Vec<DVector<f64>> = starts.iter().map(|s| bounds.clamp(s)).collect();
    // The search leaves out, beside what the base leaves out, where its start point's
    // re-simulation touches the pool ([`search_contacts`]); the figures it is scored by are
    // masked below.
    let contacts = search_contacts(setup, &starts, |x| evaluations.at(&to_params(x)), select);
    let objective = |x: &DVector<f64>| -> Option<DVector<f64>> {
        let r = evaluations.at(&to_params(x))?.residuals;
        Some(select(&left_out_where_touched(&r, contacts.as_deref())))
    };
    let fit = lsq::minimize(&objective, &bounds, &starts)?;
    tracing::debug!(
        effect = effect.name,
        part = ?part,
        termination = ?fit.termination,
        evaluations = fit.evaluations,
        objective = fit.chi2(),
        "fit finished"
    );
    let params = to_params(&fit.x);
    // The fitted point's full residuals (the fit selects one part).
    let fitted = evaluations.at(&params)?;
    let r1 = fitted.residuals;
    // Re-anchored, the fit is scored where neither the base nor its fitted point touched the
    // pool, as its held-out blocks are judged: a contact lasts to its segment's end and its
    // memory, and its impulses are no effect of the library (a hidden hard iron of 8.9 uT
    // fitted right gained 4990 in its search and lost 1044 in delta BIC to the accelerometer
    // samples of a wall its point reaches and the base does not). Open loop, a contact lasts
    // to the run's end, and what the fit would leave out is most of what tells it apart.
    let touched =
        beyond_base(setup, fitted.contacts).filter(|_| setup.base.shooting.segment_s.is_some());
    let (s0, s1) = (
        left_out_where_touched(r0, touched.as_deref()),
        left_out_where_touched(&r1, touched.as_deref()),
    );
    let (chi2_before, chi2_after) = match part {
        Some(_) => (s0.chi2(true), s1.chi2(true)),
        None => (s0.all_chi2(), s1.all_chi2()),
    };
    let n_eff = setup.n_eff(part);
    let (null, white) = setup.null_vectors(part);
    let cov = fit.covariance();
    // Null calibration: how much chi-square a fit of this effect gains on the model's own
    // noise (the ensemble's process-noise residuals plus the white measurement noise),
    // projected on the effect's Jacobian, at both ends of the fit's path (the fitted point and
    // the start): along a nonlinear parameter (a lag) the fit can travel through directions
    // where the process noise is large and end where the Jacobian has turned away from them.
    let at_fit = match (&fit.jacobian, &cov) {
        (Some(j), Some(ai)) => null_factor(j, ai, &null, &white),
        _ => 1.0,
    };
    let at_start = lsq::jacobian_at(
        &objective,
        &bounds,
        &DVector::zeros(k),
        Some(select(&left_out_where_touched(r0, contacts.as_deref()))),
    )
    .and_then(|j| {
        let a = (j.transpose() * &j).try_inverse()?;
        Some(null_factor(&j, &a, &null, &white))
    });
    let noise_factor = at_start.map_or(at_fit, |f| f.max(at_fit));
    let variance_factor = (chi2_after / (n_eff - k as f64).max(1.0)).max(1.0);
    let scale = noise_factor * variance_factor;
    // The fit's own covariance, inflated, plus what baseline runs say the effect strays by
    // when nothing changed.
    let spread = setup.spread_variance(effect);
    let cov = cov.map(|c| {
        let mut total = c * scale;
        for (j, v) in spread.iter().enumerate() {
            total[(j, j)] += v;
        }
        total
    });
    let ci = lsq::intervals(&fit.x, cov.as_ref(), scales, 1.0);
    Some(Scored {
        interval_excludes_zero: interval_excludes_zero(&ci, &fit.x, cov.as_ref(), 1.0),
        inside_bounds: !fit.at_bound && effects::inside_bounds(effect, &params),
        delta_bic: (chi2_before - chi2_after) / scale - k as f64 * n_eff.ln(),
        delta_bic_uncalibrated: chi2_before - chi2_after - k as f64 * n_eff.ln(),
        params,
        ci,
        chi2_before,
        chi2_after,
        scale,
        noise_factor,
        variance_factor,
        residuals: r1,
        evaluations: fit.evaluations,
    })
}

/// Whether the held-out blocks' gap, as the report measures it (each channel's chi-square per
/// independent sample over its known level, averaged over channels), is larger with residuals
/// `after` than with `before`. A fit that buys a large chi-square gain in one dense channel
/// with losses in the others has not made the model better where the report looks.
pub(crate) fn held_out_gap_grows(setup: &Setup<'_>, before: &Residuals, after: &Residuals) -> bool {
    let measure = |r: &Residuals| {
        let levels = setup.part_levels(r, Some(false));
        crate::gap::channel_mean(
            levels
                .into_iter()
                .map(|(i, chi2)| (chi2, setup.known.get(i).copied().unwrap_or(1.0))),
        )
    };
    match (measure(after), measure(before)) {
        (Some(a), Some(b)) => a > b,
        _ => false,
    }
}

/// Fits one mean-type candidate: on the training blocks first, judged on the held-out
/// blocks; a candidate that the held-out blocks confirm is then fitted on all the data for
/// its values, interval and significance (the structure validated on data it was not
/// fitted to, the values estimated from everything).
///
/// The training fit starts from the best of a scan along each parameter's axis
/// ([`START_SCAN`]), or, given `warm` (the candidate's training-fit values in the round
/// before, with one more effect in the model since), from the best of those values and a
/// coarser scan ([`LATER_SCAN`]): the newly named effect either took the disagreement the
/// candidate explained (its optimum falls back toward no effect) or left it (it stays near
/// those values), or, where the earlier effect had pushed the candidate into a basin of the
/// wrong sign, the coarse scan finds the other side.
fn fit_mean(
    setup: &Setup<'_>,
    effect: &'static Effect,
    r0: &Residuals,
    warm: Option<&[f64]>,
) -> Candidate {
    let k = effect.parameters.len();
    let starts = match warm {
        Some(values) if values.len() == k => {
            let mut starts = lsq::axis_scan(k, &LATER_SCAN);
            starts.push(DVector::from_iterator(
                k,
                values.iter().zip(effect.scales).map(|(v, s)| v / s),
            ));
            starts
        }
        _ => lsq::axis_scan(k, &START_SCAN),
    };
    let kept = memo::Evaluations::new(setup, effect, r0);
    let Some(train) = fit_part(setup, effect, r0, Some(true), &starts, &kept) else {
        return Candidate::untestable(
            effect,
            r0.chi2(true),
            "the fit left the model's valid range",
        );
    };
    // Where the trained point's re-simulation touches the pool and the base's does not, contact
    // impulses make the readings jump as they do where the base touches (left out of every
    // fit): the held-out comparison leaves those samples out too.
    let touched = beyond_base(setup, kept.at(&train.params).and_then(|e| e.contacts));
    let (held_before, held_after) = (
        left_out_where_touched(r0, touched.as_deref()),
        left_out_where_touched(&train.residuals, touched.as_deref()),
    );
    let heldout_chi2_before = held_before.chi2(false);
    let heldout_chi2_after = held_after.chi2(false);
    let heldout_gain = (heldout_chi2_before - heldout_chi2_after) / train.scale;
    let (signature_pass, signature_text) = signature(setup, effect, r0, &train.residuals);
    let heldout =
        heldout_gain > HELDOUT_MIN_GAIN && !held_out_gap_grows(setup, &held_before, &held_after);
    if !heldout && tracing::enabled!(tracing::Level::DEBUG) {
        tracing::debug!(
            effect = effect.name,
            heldout_gain,
            worst = ?worst_heldout_blocks(setup, r0, &train.residuals),
            "a training fit that fails its held-out blocks"
        );
    }
    let mut evaluations = train.evaluations;
    let trained = train.params.clone();
    let chosen = if heldout && signature_pass {
        let start = DVector::from_iterator(
            k,
            train.params.iter().zip(effect.scales).map(|(p, s)| p / s),
        );
        match fit_part(setup, effect, r0, None, &[start], &kept) {
            Some(all) => {
                evaluations += all.evaluations;
                all
            }
            None => train,
        }
    } else {
        train
    };
    let guards = Guards {
        inside_bounds: chosen.inside_bounds,
        interval_excludes_zero: chosen.interval_excludes_zero,
        significant: chosen.delta_bic > BIC_MARGIN,
        signature: signature_pass,
        heldout: Some(heldout),
    };
    let change: Vec<f64> = if chosen.residuals.values.len() == r0.values.len() {
        chosen
            .residuals
            .values
            .iter()
            .zip(&r0.values)
            .map(|(a, b)| a - b)
            .collect()
    } else {
        Vec::new()
    };
    let noise_along = noise_along(setup, &change);
    Candidate {
        name: effect.name.to_string(),
        parameters: names(effect).zip(chosen.params.iter().copied()).collect(),
        ci95: names(effect).zip(chosen.ci.iter().copied()).collect(),
        chi2_before: chosen.chi2_before,
        chi2_after: chosen.chi2_after,
        delta_bic: chosen.delta_bic,
        delta_bic_uncalibrated: chosen.delta_bic_uncalibrated,
        heldout_chi2_before: Some(heldout_chi2_before),
        heldout_chi2_after: Some(heldout_chi2_after),
        heldout_gain: Some(heldout_gain),
        signature_pass,
        signature: signature_text,
        guards,
        testable: true,
        evaluations,
        noise_factor: chosen.noise_factor,
        variance_factor: chosen.variance_factor,
        refitted: Vec::new(),
        trained,
        change,
        noise_along,
    }
}

/// The setup's null residuals and white measurement variance over all the data, projected on
/// `change` ([`candidate::NoiseAlong`]); empty where the two do not describe the same
/// residuals.
fn noise_along(setup: &Setup<'_>, change: &[f64]) -> candidate::NoiseAlong {
    let (null, white) = setup.null_vectors(None);
    if change.is_empty()
        || white.len() != change.len()
        || null.iter().any(|v| v.len() != change.len())
    {
        return candidate::NoiseAlong::default();
    }
    candidate::NoiseAlong {
        process: null
            .iter()
            .map(|v| v.iter().zip(change).map(|(a, b)| a * b).sum())
            .collect(),
        white: white.into(),
    }
}

/// The three held-out blocks (start time s, channel) whose chi-square `after` raises most over
/// `before`, with the rise: where a fit that fails its held-out blocks fails them.
fn worst_heldout_blocks(
    setup: &Setup<'_>,
    before: &Residuals,
    after: &Residuals,
) -> Vec<(f64, String, f64)> {
    let mut rise: std::collections::BTreeMap<(i64, usize), f64> = Default::default();
    for (i, v) in after.part(false) {
        let (Some(b), Some(t), Some(o)) =
            (before.values.get(i), after.times.get(i), after.owner.get(i))
        else {
            continue;
        };
        let block = (t / setup.split.block_s).floor() as i64;
        *rise.entry((block, *o)).or_default() += v * v - b * b;
    }
    let mut out: Vec<(f64, String, f64)> = rise
        .into_iter()
        .map(|((block, o), r)| {
            let name = setup.m.channels.get(o).map_or("?", |c| c.name.as_str());
            (block as f64 * setup.split.block_s, name.to_string(), r)
        })
        .collect();
    out.sort_by(|a, b| b.2.total_cmp(&a.2));
    out.truncate(3);
    out
}

fn names(effect: &Effect) -> impl Iterator<Item = String> + '_ {
    effect.parameters.iter().map(|p| p.to_string())
}

/// Fits every candidate not yet in the model, on as many threads as the machine has cores
/// (each fit is independent and deterministic, and results keep the library's order before
/// ranking, so the outcome does not depend on the thread count); `progress` is called as
/// each candidate finishes. `previous`, the round before's candidates, warm-starts each
/// candidate fitted there (see [`fit_mean`]); empty, every fit scans.
pub fn fit_candidates(
    setup: &Setup<'_>,
    skip: &[&str],
    previous: &[Candidate],
    progress: &mut dyn FnMut(&str),
) -> Vec<Candidate> {
    let todo: Vec<&'static Effect> = effects::candidates()
        .filter(|e| !skip.contains(&e.name))
        .collect();
    fit_warm(setup, &todo, previous, progress)
}

/// Fits each of `todo` alone against the setup's model (in parallel), ranked; as
/// [`fit_candidates`] does for the library's candidates.
pub fn fit_effects(
    setup: &Setup<'_>,
    todo: &[&'static Effect],
    progress: &mut dyn FnMut(&str),
) -> Vec<Candidate> {
    fit_warm(setup, todo, &[], progress)
}

fn fit_warm(
    setup: &Setup<'_>,
    todo: &[&'static Effect],
    previous: &[Candidate],
    progress: &mut dyn FnMut(&str),
) -> Vec<Candidate> {
    let warm = |name: &str| -> Option<Vec<f64>> {
        previous
            .iter()
            .find(|c| c.name == name && c.testable && !c.trained.is_empty())
            .map(|c| c.trained.clone())
    };
    let r0 = setup.residuals(&setup.base, &setup.clean);
    let measured: Vec<&str> = setup
        .modelled()
        .iter()
        .map(|&i| setup.m.channels[i].name.as_str())
        .collect();
    let one = |effect: &'static Effect| -> Candidate {
        if !effect.channels.iter().any(|c| measured.contains(c)) {
            return Candidate::untestable(
                effect,
                r0.chi2(true),
                &format!(
                    "not testable: none of its channels ({}) is measured and modelled",
                    effect.channels.join(", ")
                ),
            );
        }
        let result = match effect.kind {
            Kind::Mean => fit_mean(setup, effect, &r0, warm(effect.name).as_deref()),
            Kind::Variance => fit_emi(setup, effect)
                .unwrap_or_else(|| Candidate::untestable(effect, r0.chi2(true), "no depth data")),
        };
        tracing::debug!(
            effect = effect.name,
            delta_bic = result.delta_bic,
            heldout_gain = result.heldout_gain,
            guards = ?result.guards,
            parameters = ?result.parameters,
            ci95 = ?result.ci95,
            "candidate fitted"
        );
        result
    };
    let (tx, rx) = std::sync::mpsc::channel::<(usize, Candidate)>();
    let mut slots: Vec<Option<Candidate>> = vec![None; todo.len()];
    std::thread::scope(|scope| {
        let (todo, one) = (&todo, &one);
        scope.spawn(move || {
            use rayon::prelude::*;
            todo.par_iter()
                .enumerate()
                .for_each_with(tx, |tx, (i, effect)| {
                    // The receiver lives until every sender is gone.
                    let _ = tx.send((i, one(effect)));
                });
        });
        for (i, result) in rx {
            progress(&result.name);
            slots[i] = Some(result);
        }
    });
    let mut out: Vec<Candidate> = slots.into_iter().flatten().collect();
    candidate::rank(&mut out);
    out
}

/// Builds a setup for the given configs.
pub fn setup<'a>(
    m: &'a Measurement,
    base: Configs,
    floors: &'a [Option<Floor>],
    split: Split,
    spread: &[EnabledEffect],
) -> Result<Setup<'a>, GapError> {
    let clean = resim::simulate(&base, m, None)?;
    Ok(Setup {
        m,
        base,
        clean,
        floors,
        split,
        spread: spread.to_vec(),
        known: vec![1.0; m.channels.len()],
    })
}

mod contacts;
mod emi;
mod memo;
pub use emi::{EMI_WINDOW_S, fit_emi};
mod constancy;
mod joint;
pub use constancy::{CONSTANCY_LEVEL, Constancy, constancy, noise_source_blocks, strong_blocks};
pub use joint::{Named, Refit, judged_with_earlier_free, named, refit_jointly, with_earlier_free};
mod rival;
pub use rival::{RivalFits, earlier_change_dynamics, moved_to_new_regime, structural_rival};

#[cfg(test)]
mod tests;
