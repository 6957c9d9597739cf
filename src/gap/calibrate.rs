//! `gap calibrate`: fit the base model's continuous parameters on baseline runs before looking
//! for anything new (the thesis's own order: calibrate Mako against baseline runs, then
//! explain what changes).
//!
//! The parameters are those of the library's effects marked [`Effect::calibrated`] (thrust gain and curve, drag,
//! added mass, yaw damping, thruster balance and lag, sensor offsets and gains), fitted
//! jointly with the bounded engine ([`crate::gap::lsq`]) on the re-anchored residuals of every
//! baseline run. These keep a fit of thirty-odd parameters on data that never match the
//! model exactly well posed:
//! - **Channel weights.** Each channel's squared residuals sum to its chi-square per
//!   independent sample ([`channel_weights`]), so every channel counts once, as in the gap
//!   measure the calibration is judged by, whatever its sample rate or how far it is off. The
//!   intervals are then taken with the residuals in units of their own spread, each channel's
//!   samples counted over the residual's correlation time.
//! - **A robust loss.** Each residual is measured against its channel's own spread at the
//!   previous pass (`max(1, rms)` in floor units), and beyond [`HUBER_K`] of those it counts
//!   linearly, not squared (Huber's loss, applied as the square root so the least-squares
//!   engine minimises it). A few samples far off (a wall contact the re-simulation places a
//!   moment earlier, an accelerometer spike) then cannot outvote a disagreement that runs
//!   through a whole channel.
//! - **A weak prior.** Each parameter adds a residual `x / PRIOR_WIDTH` (in units of its
//!   typical size): a direction the data do not inform stays near the model as given instead
//!   of wandering to a bound. Where the model file's `[prior]` says how sure a shipped value
//!   is (a datasheet's tolerance), that standard deviation replaces it: baseline runs inform a
//!   sensor's gain mostly through the model's dynamics, so a hull of another structure would
//!   otherwise move the dynamics' error into the sensor.
//! - **Two starts.** The thrust curve's scale and shape trade off, and the fit has more than
//!   one minimum along them: it runs from the model as given and from a steeper curve
//!   ([`CURVE_START`]), and keeps the result with the smaller gap on the baseline runs.
//!
//! Then the depth channel's duty-correlated noise level (`depth_pwm_emi`, a variance) is
//! fitted on each baseline run of the calibrated model and its mean kept.
//!
//! Last, the between-run spread: how far each library effect's apparent value strays on a
//! null run of the calibrated model, measured on repeat runs (`--spread-from`, else the
//! baseline runs). It widens `gap`'s intervals, so it belongs to the programme later runs
//! use: baseline runs of different programmes hold their differences in model error too.
//!
//! The result is written as the model's `[[calibration]]` entries: applied before any effect,
//! and still free to be found again by `gap` as a change in a later run. Calibration reports
//! its gap before and after on runs it was not fitted to (`--validate`), and the known
//! disagreement `gap` reads each channel against, with how far runs with nothing new stray
//! from it, on the spread runs and the validation runs like them (module `known`).

use std::path::{Path, PathBuf};

use nalgebra::DVector;
use serde::Serialize;

use crate::gap::GapError;
use crate::gap::anchor::Shooting;
use crate::gap::effects::{self, Calibration as Fitted, Configs, Effect};
use crate::gap::fit::{self, Setup, Split};
use crate::gap::format::Measurement;
use crate::gap::lsq::{self, Bounds};
use crate::gap::model::{EnabledEffect, GapModel};

use crate::gap::resim::{self, Floor};
pub use known::Unlike;
use known::{chi2_of_runs, discrepancy, known_runs, run_bounds, run_scatter};
use score::score_runs;
pub use submerged::{SUBMERGED_MARGIN_M, SUBMERGED_MIN_S};
use submerged::{hold_submerged_only, submerged_s};

/// Width of the prior on each parameter, in units of its typical size.
pub const PRIOR_WIDTH: f64 = 10.0;

/// Where the calibration's loss turns from squared to linear, in units of a channel's own
/// spread: three standard deviations, the usual outlier threshold.
pub const HUBER_K: f64 = 3.0;

/// The residual whose square is Huber's loss of `u` with threshold `k`: `u` inside `k`,
/// `sign(u) sqrt(2 k |u| - k^2)` beyond (continuous, with a continuous derivative).
fn huber(u: f64, k: f64) -> f64 {
    if u.abs() <= k {
        u
    } else {
        u.signum() * (2.0 * k * u.abs() - k * k).sqrt()
    }
}

/// One run the calibration reads.
pub struct Run {
    pub dir: PathBuf,
    pub m: Measurement,
}

impl Run {
    pub fn load(dir: &Path) -> Result<Self, GapError> {
        Ok(Self {
            dir: dir.to_path_buf(),
            m: Measurement::load(dir)?,
        })
    }
}

/// A run prepared for fitting: its base configuration and noise floor.
struct Prepared<'a> {
    run: &'a Run,
    base: Configs,
    floors: Vec<Option<Floor>>,
}

impl Prepared<'_> {
    fn setup(&self) -> Result<Setup<'_>, GapError> {
        fit::setup(
            &self.run.m,
            self.base.clone(),
            &self.floors,
            Split::DEFAULT,
            &[],
        )
    }
}

/// One fitted parameter.
#[derive(Debug, Clone, Serialize)]
pub struct Parameter {
    pub effect: String,
    pub parameter: String,
    pub value: f64,
    pub ci95: [f64; 2],
    /// True when the fit ended on the parameter's bound.
    pub at_bound: bool,
}

/// What a run is to the calibration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RunRole {
    /// Fitted to (`--measured`).
    Baseline,
    /// Scored, not fitted to (`--validate`).
    Validation,
    /// A null run of the programme later runs use (`--spread-from`), not fitted to.
    Spread,
}

impl RunRole {
    /// How the command line names the run.
    pub fn label(self) -> &'static str {
        match self {
            Self::Baseline => "baseline run",
            Self::Validation => "validation run",
            Self::Spread => "spread run",
        }
    }
}

/// The gap of one run before and after calibration.
#[derive(Debug, Clone, Serialize)]
pub struct RunGap {
    pub dir: String,
    pub role: RunRole,
    pub gap_before: f64,
    pub gap_after: f64,
    pub reduction_pct: f64,
    /// chi2 per independent sample by channel, before and after.
    pub channels: Vec<(String, f64, f64)>,
    /// A run the calibration was not fitted to and fits worse: the calibrated effects that
    /// carry it furthest from the model as given, each with the run's gap when that effect
    /// alone is set back to the model as given (most first, those that shrink it only).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub carried_by: Vec<(String, f64)>,
}

/// An effect whose calibrated value the data do not identify.
#[derive(Debug, Clone, Serialize)]
pub struct Unidentified {
    pub effect: String,
    pub why: String,
}

/// What calibration gave.
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    pub parameters: Vec<Parameter>,
    pub runs: Vec<RunGap>,
    pub evaluations: usize,
    /// Between-run spread of each effect's apparent value (1 sigma) on the `spread_from`
    /// runs, or on the baseline runs when none are given; empty with one run.
    pub spread: Vec<Parameter>,
    /// The runs the spread was measured on.
    pub spread_from: Vec<String>,
    /// Parameters left out because none of their channels is measured.
    pub not_fitted: Vec<String>,
    /// Effects held at the model as given because the baseline runs cannot measure them,
    /// with why ([`Effect::submerged_only`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub held: Vec<Unidentified>,
    /// Effects the baseline runs do not identify, with why (their values stay as fitted).
    pub unidentified: Vec<Unidentified>,
    /// Effects whose per-run fits on the spread runs ended on a bound or were unbounded: their
    /// spread says more of the runs' model error than of the effect.
    pub spread_unidentified: Vec<String>,
    /// The factor the fitted change was shrunk by so that the model re-simulates every
    /// baseline run to its end (1: not shrunk; 0: the model as given).
    pub shrunk: f64,
    /// The calibrated model's chi-square per independent sample by channel, averaged over
    /// the runs of `known_from`: what `gap` later measures a run's gap against.
    pub discrepancy: Vec<(String, f64)>,
    /// The runs the known disagreement was read on: the spread runs and the validation runs
    /// like them; without spread runs the validation runs, else the baseline runs.
    pub known_from: Vec<String>,
    /// Validation runs left out of the known disagreement as unlike the spread runs.
    pub unlike_spread: Vec<Unlike>,
    /// Per channel, the chi-square per sample one more run with nothing new stays under, from
    /// how the unfitted runs of `known_from` scatter ([`run_bounds`]); empty with fewer than
    /// two.
    pub run_bounds: Vec<(String, f64)>,
    #[serde(skip)]
    pub model: GapModel,
}

fn prepare<'a>(model: &GapModel, run: &'a Run) -> Result<Prepared<'a>, GapError> {
    let mut base = model.configs(&run.m.experiment, &run.dir)?;
    base.shooting = Shooting::DEFAULT;
    let clean = resim::simulate(&base, &run.m, None)?;
    let floors = resim::noise_floor(&base, &run.m, &clean)?;
    Ok(Prepared { run, base, floors })
}

/// Per-channel chi-square per independent sample of `c` on a prepared run.
fn channel_chi2(p: &Prepared<'_>, setup: &Setup<'_>, c: &Configs) -> Option<Vec<(usize, f64)>> {
    // A run that diverges is no chi-square: its evaluation fails, as a fit's does.
    let run = resim::simulate(c, &p.run.m, None)
        .ok()
        .filter(|r| r.divergences.is_empty())?;
    let r = setup.residuals(c, &run);
    let mut out = Vec::new();
    for i in setup.modelled() {
        let f = p.floors[i].as_ref()?;
        // Over the samples the residuals keep: a wall contact is left out of the count too,
        // as `gap` leaves it out of the statistics it judges a run by.
        let (sum, n) = r
            .values
            .iter()
            .zip(&r.owner)
            .zip(&r.times)
            .filter(|((_, o), t)| {
                **o == i && !setup.clean.in_contact(**t, &setup.m.channels[i].name)
            })
            .fold((0.0, 0usize), |(s, n), ((v, _), _)| (s + v * v, n + 1));
        if n > 0 {
            out.push((i, sum / (n as f64 / f.tau)));
        }
    }
    Some(out)
}

/// How one channel of a prepared run enters the calibration, from its residual at a point.
#[derive(Debug, Clone, Copy)]
struct ChannelWeight {
    /// The fit's weight per sample, `sqrt(tau_floor / n)`: the channel's squared residuals
    /// sum to its chi-square per independent sample, so every channel counts once, as in the
    /// gap measure calibration is judged by ([`crate::gap::excess`]), whatever its sample
    /// rate. Weighted by its samples instead, three 100 Hz accelerometer channels whose
    /// disagreement is white held most of the objective; weighted to bring each channel's
    /// chi-square to one, a position track below its floor outvoted a compass four times above
    /// it. Either way the fit settled where the compass still disagreed, and the gap stayed.
    fit: f64,
    /// The weight per sample for the intervals, `sqrt(tau_floor / tau / max(1, chi2/n))`:
    /// the chi-square per independent sample brought to one, samples counted over the
    /// residual's own correlation time where that is longer than the floor's (model error is
    /// correlated over a manoeuvre). The residuals are then in units of their own spread, so
    /// the Jacobian gives the parameters' uncertainty.
    intervals: f64,
    /// The channel's spread, `max(1, rms)` of its residual in floor units: the unit of the
    /// robust loss ([`HUBER_K`]).
    spread: f64,
}

impl ChannelWeight {
    /// A channel the run cannot evaluate.
    const UNIT: Self = Self {
        fit: 1.0,
        intervals: 1.0,
        spread: 1.0,
    };
}

/// Each channel's weights on a prepared run under `c`.
fn channel_weights(p: &Prepared<'_>, setup: &Setup<'_>, c: &Configs) -> Vec<ChannelWeight> {
    let mut w = vec![ChannelWeight::UNIT; p.run.m.channels.len()];
    let Some(run) = resim::simulate(c, &p.run.m, None)
        .ok()
        .filter(|r| r.divergences.is_empty())
    else {
        return w;
    };
    let r = setup.residuals(c, &run);
    for i in setup.modelled() {
        let Some(f) = p.floors[i].as_ref() else {
            continue;
        };
        let z: Vec<f64> = r
            .values
            .iter()
            .zip(&r.owner)
            .filter(|(_, o)| **o == i)
            .map(|(v, _)| *v)
            .collect();
        if z.is_empty() {
            continue;
        }
        let n = z.len() as f64;
        let sum_sq = z.iter().map(|v| v * v).sum::<f64>();
        let chi2 = sum_sq / (n / f.tau);
        let tau = crate::gap::residuals::correlation_time(&z).max(f.tau);
        w[i] = ChannelWeight {
            fit: (f.tau / n).sqrt(),
            intervals: (f.tau / tau / chi2.max(1.0)).sqrt(),
            spread: (sum_sq / n).sqrt().max(1.0),
        };
    }
    w
}

/// The gap measure `gap` reports against the noise floor alone (every known level 1): a
/// model without a known disagreement is what calibration starts from and ends with.
fn excess(per_channel: &[(usize, f64)]) -> f64 {
    crate::gap::excess(per_channel.iter().map(|(_, c)| (*c, 1.0)))
}

/// The mean of per-run fitted values and its 95 % interval: from the between-run spread for
/// two or more runs, the run's own interval for one.
fn mean_level(levels: &[(f64, [f64; 2])]) -> Option<(f64, [f64; 2])> {
    match levels {
        [] => None,
        [one] => Some(*one),
        _ => {
            use statrs::statistics::Statistics;
            let n = levels.len() as f64;
            let mean = levels.iter().map(|l| l.0).mean();
            let var = levels.iter().map(|l| l.0).variance();
            let half = 1.96 * (var / n).sqrt();
            Some((mean, [mean - half, mean + half]))
        }
    }
}

/// Each effect's between-run spread, per parameter (1 sigma).
type Spread = Vec<(&'static Effect, Vec<f64>)>;

/// Each library effect's apparent value when nothing changed: every candidate fitted on each
/// of `runs` with the calibration `x` applied, and the root mean square of the per-run values
/// (1 sigma). Runs the joint calibration was `fitted_on` are pulled towards zero by
/// `sqrt((n - 1) / n)`, which is undone; runs it never saw are taken as they are. Needs two
/// or more runs (none from fewer).
fn apparent_spread(
    runs: &[Prepared<'_>],
    fitted_on: bool,
    chosen: &[&'static Effect],
    x: &DVector<f64>,
    progress: &mut dyn FnMut(&str),
) -> Result<(Spread, Vec<String>), GapError> {
    if runs.len() < 2 {
        return Ok((Vec::new(), Vec::new()));
    }
    let mut on_bound: Vec<&'static Effect> = Vec::new();
    let n = runs.len() as f64;
    let pull = if fitted_on { n / (n - 1.0) } else { 1.0 };
    let mut apparent: Vec<(&'static Effect, Vec<Vec<f64>>)> = Vec::new();
    for (i, p) in runs.iter().enumerate() {
        progress(&format!("spread: run {} of {}", i + 1, runs.len()));
        let base = effects::apply_joint(&p.base, chosen, x);
        let s = fit::setup(&p.run.m, base, &p.floors, Split::DEFAULT, &[])?;
        for r in fit::fit_candidates(&s, &[], &[], &mut |_| {}) {
            let Some(e) = effects::by_name(&r.name) else {
                continue;
            };
            if !r.testable || e.kind != effects::Kind::Mean {
                continue;
            }
            // A fit that ends on a bound or leaves a parameter unbounded is named: its spread
            // says more of the data than of the effect.
            let bounded = r
                .ci95
                .iter()
                .all(|(_, [a, b])| a.is_finite() && b.is_finite());
            if (!r.guards.inside_bounds || !bounded) && !on_bound.iter().any(|t| t.name == e.name) {
                on_bound.push(e);
            }
            let values: Vec<f64> = r.parameters.iter().map(|(_, v)| *v).collect();
            match apparent.iter_mut().find(|(a, _)| a.name == e.name) {
                Some((_, v)) => v.push(values),
                None => apparent.push((e, vec![values])),
            }
        }
    }
    let unidentified = on_bound.iter().map(|t| t.name.to_string()).collect();
    let spread = apparent
        .into_iter()
        .filter(|(_, per_run)| per_run.len() >= 2)
        .map(|(e, per_run)| (e, spread_of(e, &per_run, pull)))
        .collect();
    Ok((spread, unidentified))
}

/// One effect's between-run spread from its apparent values on each run: per parameter the
/// root mean square about no effect, times `pull` (the factor that undoes a fit's pull toward
/// its own runs). The two components of a vector in a plane share one spread, the root of
/// their mean squares' mean ([`effects::plane_vector`]).
fn spread_of(e: &Effect, per_run: &[Vec<f64>], pull: f64) -> Vec<f64> {
    let ms = |j: usize| per_run.iter().map(|v| v[j] * v[j]).sum::<f64>() / per_run.len() as f64;
    let k = e.parameters.len();
    if effects::plane_vector(e) {
        let pooled = (0..k).map(ms).sum::<f64>() / k as f64;
        vec![(pooled * pull).sqrt(); k]
    } else {
        (0..k).map(|j| (ms(j) * pull).sqrt()).collect()
    }
}

/// Where the joint fit starts: the model as given, and one more start per further value of
/// an effect's first parameter ([`Fitted::JointTwoStarts`], [`Fitted::DiscrepancyStarts`]).
/// The thrust curve's scale (`thrust_gain`) and shape (`thrust_curve`) trade off against
/// each other, and from the linear curve alone the fit can stop at half the exponent a
/// propeller's thrust has (thrust ~ rpm^2, rpm less than linear in duty), with a larger gap
/// left on the baseline runs. The camera marker's position and the hull's sway in spins
/// (its sway damping and added mass) trade off too: a marker ahead of the centre moves
/// sideways in a spin as a swaying hull does, and from the marker as stated the fit can end
/// with the marker on the wrong side of the centre and a sway the hull does not have.
fn starts(chosen: &[&'static Effect]) -> Vec<DVector<f64>> {
    let dims = chosen.iter().map(|e| e.parameters.len()).sum();
    let mut out = vec![DVector::zeros(dims)];
    let mut k = 0;
    for e in chosen {
        let values: &[f64] = match &e.calibration {
            Fitted::JointTwoStarts(_, start) => std::slice::from_ref(start),
            Fitted::DiscrepancyStarts(_, starts) => starts,
            _ => &[],
        };
        for start in values {
            let mut x = DVector::zeros(dims);
            x[k] = start / e.scales[0];
            out.push(x);
        }
        k += e.parameters.len();
    }
    out
}

/// Each joint parameter's prior width in units of its typical size: the model's `[prior]`
/// standard deviation where it gives one, else the weak [`PRIOR_WIDTH`].
fn prior_widths(model: &GapModel, chosen: &[&'static Effect]) -> Vec<f64> {
    chosen
        .iter()
        .flat_map(|e| {
            e.parameters.iter().zip(e.scales).map(|(p, scale)| {
                model
                    .prior_sd(e.name, p)
                    .map_or(PRIOR_WIDTH, |sd| sd / scale)
            })
        })
        .collect()
}

/// The joint fit of `chosen` on every prepared run: `passes` passes (channel weights from the
/// residual at the previous pass) from each of `starts`; the start whose result leaves the
/// smallest gap on the baseline runs is kept. Returns the point, its fit and the residual
/// evaluations used.
fn joint_fit(
    model: &GapModel,
    prepared: &[Prepared<'_>],
    setups: &[Setup<'_>],
    chosen: &[&'static Effect],
    starts: Vec<DVector<f64>>,
    passes: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<(DVector<f64>, lsq::Fit, usize), GapError> {
    let (scales, bounds_raw) = effects::joint_scales_and_bounds(chosen);
    let bounds = Bounds::scaled(&bounds_raw, &scales);
    let dims = scales.len();
    let prior_widths = prior_widths(model, chosen);
    // Channel weights, one per (run, channel), from the residual at the current point.
    let weights_at = |x: &DVector<f64>| -> Vec<Vec<ChannelWeight>> {
        prepared
            .iter()
            .zip(setups)
            .map(|(p, s)| channel_weights(p, s, &effects::apply_joint(&p.base, chosen, x)))
            .collect()
    };
    // The residuals at `x` under `weights`, each channel's by `pick` of its weights.
    let residuals_with = |x: &DVector<f64>,
                          weights: &[Vec<ChannelWeight>],
                          pick: fn(&ChannelWeight) -> f64|
     -> Option<DVector<f64>> {
        let mut out = Vec::new();
        for ((p, s), w) in prepared.iter().zip(setups).zip(weights) {
            let c = effects::apply_joint(&p.base, chosen, x);
            // A trial point under which a run diverges is a failed evaluation: the
            // bounded fit steps back from it.
            let run = resim::simulate(&c, &p.run.m, None)
                .ok()
                .filter(|r| r.divergences.is_empty())?;
            let r = s.residuals(&c, &run);
            out.extend(r.values.iter().zip(&r.owner).map(|(v, o)| {
                let w = &w[*o];
                huber(v / w.spread, HUBER_K) * w.spread * pick(w)
            }));
        }
        out.extend(x.iter().zip(&prior_widths).map(|(v, w)| v / w));
        Some(DVector::from_vec(out))
    };
    let mut evaluations = 0;
    let mut best: Option<(f64, DVector<f64>, lsq::Fit)> = None;
    for (i, start) in starts.iter().enumerate() {
        let mut x = start.clone();
        let mut last = None;
        for pass in 0..passes {
            progress(&format!(
                "start {} of {}, pass {} of {passes}: {dims} parameters",
                i + 1,
                starts.len(),
                pass + 1
            ));
            let weights = weights_at(&x);
            let objective = |x: &DVector<f64>| residuals_with(x, &weights, |w| w.fit);
            let Some(fit) = lsq::minimize(&objective, &bounds, std::slice::from_ref(&x)) else {
                return Err(GapError::Data(
                    "calibration: the model could not be re-simulated at the starting point".into(),
                ));
            };
            evaluations += fit.evaluations;
            tracing::debug!(
                start = i + 1,
                pass = pass + 1,
                evaluations = fit.evaluations,
                chi2 = fit.chi2(),
                termination = ?fit.termination,
                "calibration pass done"
            );
            x = fit.x.clone();
            last = Some(fit);
        }
        let Some(fit) = last else {
            return Err(GapError::Data("calibration: no fit".into()));
        };
        let gap = prepared
            .iter()
            .zip(setups)
            .map(|(p, s)| {
                excess(
                    &channel_chi2(p, s, &effects::apply_joint(&p.base, chosen, &x))
                        .unwrap_or_default(),
                )
            })
            .sum::<f64>();
        tracing::debug!(
            start = i + 1,
            gap,
            objective = fit.chi2(),
            values = ?chosen
                .iter()
                .map(|e| e.name)
                .zip(effects::joint_values(chosen, &x))
                .collect::<Vec<_>>(),
            "calibration start done"
        );
        if best.as_ref().is_none_or(|(b, _, _)| gap < *b) {
            best = Some((gap, x, fit));
        }
    }
    let Some((_, x, mut fit)) = best else {
        return Err(GapError::Data("calibration: no fit".into()));
    };
    // The intervals come from the residuals in units of their own spread, not from the
    // fit's per-channel weights (which count each channel once, not each disagreement).
    let weights = weights_at(&x);
    let in_spread_units = |x: &DVector<f64>| residuals_with(x, &weights, |w| w.intervals);
    if let Some(r) = in_spread_units(&x) {
        fit.jacobian = lsq::jacobian_at(&in_spread_units, &bounds, &x, None);
        fit.residuals = r;
        evaluations += dims + 1;
    }
    Ok((x, fit, evaluations))
}

/// The effects of `chosen` whose fit at `x` the data do not support, with the reason: an
/// interval that is infinite or wider than the parameter's physical range, or a sensor
/// effect's parameter on its bound.
fn unidentified_effects(
    chosen: &[&'static Effect],
    x: &DVector<f64>,
    fit: &lsq::Fit,
) -> Vec<(&'static Effect, String)> {
    let scales: Vec<f64> = chosen
        .iter()
        .flat_map(|e| e.scales.iter().copied())
        .collect();
    let dims = scales.len();
    let n = fit.residuals.len() as f64;
    let variance_factor = (fit.chi2() / (n - dims as f64).max(1.0)).max(1.0);
    let ci = lsq::intervals(x, fit.covariance().as_ref(), &scales, variance_factor);
    let mut out = Vec::new();
    let mut k = 0;
    for e in chosen {
        let mut why = None;
        for (j, (lo, hi)) in e.bounds.iter().enumerate() {
            let value = x[k + j] * scales[k + j];
            let [a, b] = ci[k + j];
            let margin = 1e-6 * (hi - lo);
            if !(a.is_finite() && b.is_finite()) {
                why = Some(format!("`{}`: the data do not bound it", e.parameters[j]));
            } else if b - a > hi - lo {
                why = Some(format!(
                    "`{}`: 95 % interval {:.3}..{:.3} wider than its physical range {lo}..{hi}",
                    e.parameters[j], a, b
                ));
            } else if !e.physics && (value <= lo + margin || value >= hi - margin) {
                why = Some(format!(
                    "`{}`: driven onto its bound {value}: a disagreement this sensor effect's \
                     signature does not explain",
                    e.parameters[j]
                ));
            }
        }
        if let Some(why) = why {
            out.push((*e, why));
        }
        k += e.parameters.len();
    }
    out
}

/// True when the model with `chosen` at `x` diverges on one of the runs.
fn diverges(prepared: &[Prepared<'_>], chosen: &[&'static Effect], x: &DVector<f64>) -> bool {
    prepared.iter().any(|p| {
        resim::simulate(&effects::apply_joint(&p.base, chosen, x), &p.run.m, None)
            .map_or(true, |run| !run.divergences.is_empty())
    })
}

/// Fits the calibration parameters on `baseline` runs and scores the result on `validate`
/// runs (and on the baseline). The between-run spread comes from `spread_from` when given
/// (two or more null runs of the programme later runs will use, none of them a baseline
/// run), else from the baseline runs. `progress(pass, evaluations)` is called as the fit
/// goes.
pub fn calibrate(
    model: &GapModel,
    baseline: &[Run],
    validate: &[Run],
    spread_from: &[Run],
    progress: &mut dyn FnMut(&str),
) -> Result<Calibration, GapError> {
    check_runs(baseline, spread_from)?;
    progress("noise floors");
    let prepared: Vec<Prepared<'_>> = baseline
        .iter()
        .map(|r| prepare(model, r))
        .collect::<Result<_, _>>()?;
    let setups: Vec<Setup<'_>> = prepared
        .iter()
        .map(Prepared::setup)
        .collect::<Result<_, _>>()?;
    let measured: Vec<&str> = setups
        .iter()
        .flat_map(|s| {
            s.modelled()
                .into_iter()
                .map(|i| s.m.channels[i].name.as_str())
        })
        .collect();
    let (chosen, not_fitted) = choose_effects(&measured);
    let below_s: f64 = prepared
        .iter()
        .map(|p| submerged_s(&p.base, &p.run.m))
        .sum();
    let (chosen, held) = hold_submerged_only(chosen, below_s);
    let (mut x, fit, evaluations) = joint_fit(
        model,
        &prepared,
        &setups,
        &chosen,
        starts(&chosen),
        2,
        progress,
    )?;
    // Parameters the data do not identify are named: an interval that is infinite or wider
    // than the parameter's physical range, or a sensor parameter driven onto its bound (a
    // sensor effect taking a disagreement its own signature does not explain). Their values
    // stay in the model, as the fit left them: read them as "this channel disagrees".
    let unidentified: Vec<Unidentified> = unidentified_effects(&chosen, &x, &fit)
        .into_iter()
        .map(|(e, why)| Unidentified {
            effect: e.name.to_string(),
            why,
        })
        .collect();
    let shrunk = shrink_until_stable(&prepared, &chosen, &mut x);
    let mut out = fitted_parameters(model, &chosen, &x, &fit);
    fit_noise_levels(&prepared, &chosen, &x, &measured, &mut out, progress)?;
    let (apparent, spread_unidentified) =
        between_run_spread(model, &prepared, spread_from, &chosen, &x, progress)?;
    let spread = record_spread(apparent, &mut out.model);
    // The scatter is measured on the spread runs, or on the baseline runs the joint fit
    // already pulled towards zero: one degree of freedom fewer.
    out.model.spread_dof = match spread_from.len() {
        0 => baseline.len().checked_sub(1),
        n => Some(n),
    }
    .filter(|_| !spread.is_empty())
    .and_then(|n| u32::try_from(n).ok());

    progress("scoring");
    let runs = score_runs(model, baseline, validate, spread_from, &chosen, &x)?;
    progress("discrepancy");
    let mut calibrated = out.model;
    let validated = chi2_of_runs(&calibrated, validate)?;
    let spread_chi2 = chi2_of_runs(&calibrated, spread_from)?;
    let known = known_runs(&validated, &spread_chi2, || {
        chi2_of_runs(&calibrated, baseline)
    })?;
    let discrepancy = discrepancy(&known.levels);
    let bounds = run_bounds(&known.unfitted);
    calibrated.discrepancy = discrepancy.iter().cloned().collect();
    calibrated.discrepancy_bound = bounds.iter().cloned().collect();
    calibrated.discrepancy_scatter = run_scatter(&known.unfitted);
    Ok(Calibration {
        parameters: out.parameters,
        runs,
        evaluations,
        spread,
        spread_from: if spread_from.is_empty() {
            baseline
        } else {
            spread_from
        }
        .iter()
        .map(|r| r.dir.display().to_string())
        .collect(),
        not_fitted,
        held,
        unidentified,
        spread_unidentified,
        shrunk,
        discrepancy,
        known_from: known.from,
        unlike_spread: known.unlike,
        run_bounds: bounds,
        model: calibrated,
    })
}

/// Refuses run lists calibration cannot use: no baseline run, a single spread run (no
/// spread), or a spread run that is also a baseline run (the spread must come from runs the
/// calibration was not fitted to).
fn check_runs(baseline: &[Run], spread_from: &[Run]) -> Result<(), GapError> {
    if baseline.is_empty() {
        return Err(GapError::Data(
            "calibration needs at least one baseline run (--measured DIR)".into(),
        ));
    }
    if spread_from.len() == 1 {
        return Err(GapError::Data(format!(
            "--spread-from {}: one run gives no spread; give two or more null runs of the \
             programme you will analyse",
            spread_from[0].dir.display()
        )));
    }
    if let Some(r) = spread_from
        .iter()
        .find(|r| baseline.iter().any(|b| b.dir == r.dir))
    {
        return Err(GapError::Data(format!(
            "--spread-from {}: also a --measured baseline run; the spread is measured on runs \
             the calibration was not fitted to",
            r.dir.display()
        )));
    }
    Ok(())
}

/// The jointly calibrated effects in their calibration order, split into those with a
/// `measured` channel (fitted) and the names of those without (not fitted).
fn choose_effects(measured: &[&str]) -> (Vec<&'static Effect>, Vec<String>) {
    let mut chosen: Vec<&'static Effect> = Vec::new();
    let mut not_fitted = Vec::new();
    let mut joint: Vec<(u8, &'static Effect)> = effects::LIBRARY
        .iter()
        .filter_map(|e| e.calibration.joint_place().map(|k| (k, e)))
        .collect();
    joint.sort_by_key(|(k, _)| *k);
    for (_, e) in joint {
        if e.channels.iter().any(|c| measured.contains(c)) {
            chosen.push(e);
        } else {
            not_fitted.push(e.name.to_string());
        }
    }
    (chosen, not_fitted)
}

/// A model that diverges on its own runs is never written: halves the fitted change `x`
/// towards the model as given until every baseline run re-simulates to its end (or drops it
/// altogether), and returns the factor it was shrunk by.
fn shrink_until_stable(
    prepared: &[Prepared<'_>],
    chosen: &[&'static Effect],
    x: &mut DVector<f64>,
) -> f64 {
    let mut shrunk = 1.0;
    while shrunk > 1e-3 && diverges(prepared, chosen, x) {
        *x *= 0.5;
        shrunk *= 0.5;
    }
    if shrunk <= 1e-3 {
        x.fill(0.0);
        shrunk = 0.0;
    }
    shrunk
}

/// The calibrated parameters so far and the model carrying them.
struct Calibrated {
    parameters: Vec<Parameter>,
    model: GapModel,
}

/// The jointly fitted parameters at `x` with their intervals (widened by the residual
/// variance beyond the weighted floor, as in `fit`), and `model` with them as calibration
/// entries.
fn fitted_parameters(
    model: &GapModel,
    chosen: &[&'static Effect],
    x: &DVector<f64>,
    fit: &lsq::Fit,
) -> Calibrated {
    let (scales, bounds_raw) = effects::joint_scales_and_bounds(chosen);
    let dims = scales.len();
    let n = fit.residuals.len() as f64;
    let variance_factor = (fit.chi2() / (n - dims as f64).max(1.0)).max(1.0);
    let ci = lsq::intervals(x, fit.covariance().as_ref(), &scales, variance_factor);
    let mut parameters = Vec::new();
    let mut calibrated = model.clone();
    let mut k = 0;
    for e in chosen {
        let n = e.parameters.len();
        let values: Vec<f64> = (0..n).map(|j| x[k + j] * scales[k + j]).collect();
        let cis: Vec<[f64; 2]> = (0..n).map(|j| ci[k + j]).collect();
        for j in 0..n {
            let (lo, hi) = bounds_raw[k + j];
            let margin = 1e-6 * (hi - lo);
            parameters.push(Parameter {
                effect: e.name.to_string(),
                parameter: e.parameters[j].to_string(),
                value: values[j],
                ci95: cis[j],
                at_bound: values[j] <= lo + margin || values[j] >= hi - margin,
            });
        }
        calibrated.calibration.push(EnabledEffect {
            effect: e,
            values,
            ci95: cis,
            delta_bic: None,
        });
        k += n;
    }
    Calibrated {
        parameters,
        model: calibrated,
    }
}

/// Noise levels (the motor noise on the depth channel: a variance, not a mean), fitted on
/// each baseline run of the calibrated model, their mean over the runs added to `out`.
/// Without them a vehicle whose depth jitters with the stern duty, whatever the cause, would
/// report that jitter as new in every later run.
fn fit_noise_levels(
    prepared: &[Prepared<'_>],
    chosen: &[&'static Effect],
    x: &DVector<f64>,
    measured: &[&str],
    out: &mut Calibrated,
    progress: &mut dyn FnMut(&str),
) -> Result<(), GapError> {
    for emi in effects::LIBRARY.iter().filter(|e| {
        e.calibration == Fitted::NoiseLevel && measured.iter().any(|c| e.channels.contains(c))
    }) {
        progress("noise levels");
        let mut levels = Vec::new();
        for p in prepared {
            let s = fit::setup(
                &p.run.m,
                effects::apply_joint(&p.base, chosen, x),
                &p.floors,
                Split::DEFAULT,
                &[],
            )?;
            if let Some(c) = fit::fit_emi(&s, emi) {
                levels.push((c.parameters[0].1, c.ci95[0].1));
            }
        }
        if let Some(level) = mean_level(&levels)
            && level.0 > 0.0
        {
            out.parameters.push(Parameter {
                effect: emi.name.to_string(),
                parameter: emi.parameters[0].to_string(),
                value: level.0,
                ci95: level.1,
                at_bound: false,
            });
            out.model.calibration.push(EnabledEffect {
                effect: emi,
                values: vec![level.0],
                ci95: vec![level.1],
                delta_bic: None,
            });
        }
    }
    Ok(())
}

/// Between-run spread: every candidate fitted on each run of the calibrated model, on
/// the `spread_from` runs when given, else on the baseline runs (`prepared`).
fn between_run_spread(
    model: &GapModel,
    prepared: &[Prepared<'_>],
    spread_from: &[Run],
    chosen: &[&'static Effect],
    x: &DVector<f64>,
    progress: &mut dyn FnMut(&str),
) -> Result<(Spread, Vec<String>), GapError> {
    let spread_prepared: Vec<Prepared<'_>> = spread_from
        .iter()
        .map(|r| prepare(model, r))
        .collect::<Result<_, _>>()?;
    let (spread_runs, fitted_on) = if spread_prepared.is_empty() {
        (prepared, true)
    } else {
        (spread_prepared.as_slice(), false)
    };
    apparent_spread(spread_runs, fitted_on, chosen, x, progress)
}

/// Records each effect's between-run spread in `calibrated` (replacing any it had) and
/// returns it as parameters, one per effect parameter.
fn record_spread(apparent: Spread, calibrated: &mut GapModel) -> Vec<Parameter> {
    let mut spread = Vec::new();
    for (e, values) in apparent {
        for (j, v) in values.iter().enumerate() {
            spread.push(Parameter {
                effect: e.name.to_string(),
                parameter: e.parameters[j].to_string(),
                value: *v,
                ci95: [f64::NAN, f64::NAN],
                at_bound: false,
            });
        }
        calibrated.spread.retain(|s| s.effect.name != e.name);
        calibrated.spread.push(EnabledEffect {
            effect: e,
            ci95: values.iter().map(|v| [*v, *v]).collect(),
            values,
            delta_bic: None,
        });
    }
    spread
}

mod known;
mod score;
mod submerged;
#[cfg(test)]
mod tests;
