//! Summary observations: a quantity measured in an experiment, with its uncertainty, instead
//! of a time series. The thesis reports Mako's vehicle measurements this way (top speed
//! 0.44 m/s, coast-down 32 s, spot-turn circle 0.8 m, ...), so `gap` takes them too.
//!
//! ```toml
//! # summary.toml (in a measurement directory, or any file passed to `gap --measured`)
//! name = "mako-2008"
//! description = "Mako's vehicle measurements, thesis chapter 4"
//!
//! [[observation]]
//! name = "top speed"
//! experiment = "experiments/acceleration.toml"   # embedded name, or relative to this file
//! quantity = "top_speed_mps"                     # see [`Quantity`]
//! value = 0.44                                   # in the quantity's unit
//! sigma = 0.02                                   # 1 sigma, same unit
//! source = "thesis 4.5, fig 4.10"
//! from_s = 25.0                                  # optional, per quantity
//! ```
//!
//! The workflow ([`analyse`]): re-run every experiment with the model (thrust fluctuation off,
//! the experiment's own heading hold on), read each quantity the way the thesis read Mako
//! ([`crate::physics::measure`]), normalise `z = (sim - measured) / sigma` with
//! `sigma^2 = sigma_measured^2 + sigma_model^2` (`sigma_model`: spread over [`ENSEMBLE`] seeded
//! runs with the model's thrust fluctuation on), then fit every physics candidate of the
//! effect library ([`effects::LIBRARY`]) with Levenberg-Marquardt on `z`, rank by
//! `delta_BIC = chi2_0 - chi2_1 - k ln(n)` and add the winner greedily.
//!
//! Significance with few numbers ([`winner`]): a candidate is named only when (1) the data hold
//! more observations than it has parameters, (2) `delta_BIC > fit::BIC_MARGIN`, and (3) at
//! least `fit::SIGNATURE_MIN_SHARE` of its chi-square reduction comes from the observations it
//! should move ([`signature_kinds`]), and (4) its parameters lie strictly inside their
//! physical bounds with finite 95 % intervals, one clear of zero. With fewer than [`FEW_OBSERVATIONS`] observations the
//! report says that the BIC's large-sample footing is weak there and the verdict is a lead,
//! not a proof. After fitting, the remaining chi-square is compared with the chi-square 95 %
//! point for `n - k` degrees of freedom: above it, the model still disagrees beyond the stated
//! uncertainties and the report lists the observations the library could not explain.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{DVector, Vector3};
use plotters::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::config::Document;
use crate::gap::effects::{self, Configs, Effect};
use crate::gap::lsq::{self, Bounds};
use crate::gap::model::{EnabledEffect, GapModel, read_ref};
use crate::gap::{GapError, Verdict, fit, residuals};
use crate::physics::Model;
use crate::physics::experiment::{self, Experiment};
use crate::physics::measure::{self, CAMERA_PERIOD_S, REST_SPEED_MPS, TOP_SPEED_FRACTION};
use crate::physics::state::VehicleState;

/// The file name `gap --measured DIR` looks for.
pub const FILE_NAME: &str = "summary.toml";
/// Seeded runs with thrust fluctuation on, for the model's own spread.
pub const ENSEMBLE: u64 = 4;
/// Below this many observations the report warns that the BIC is a rough guide.
pub const FEW_OBSERVATIONS: usize = 10;
/// Default start of the top-speed average (s): the vehicle has settled (as `validate`).
pub const TOP_SPEED_FROM_S: f64 = crate::thesis::physics::TOP_SPEED_AVERAGE_FROM_S;

/// What an observation measured. Speeds are read like the thesis's pool-side camera (200 ms
/// progress samples along the experiment's initial heading, thesis 4.5); turns like its
/// overhead camera (thesis 4.7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// Mean of the 200 ms samples in `from_s..until_s` (default 25 s .. end), m/s.
    TopSpeedMps,
    /// From `from_s` (default 0) to the first crossing of 85 % of the run's top speed (mean
    /// of the samples from 25 s on), interpolated between samples, s.
    TimeToTopSpeedS,
    /// From `from_s` (default 0) to the first crossing below 1.5 cm/s, interpolated between
    /// samples; a run that never comes to rest gives its end (censored), s.
    TimeToRestS,
    /// Spot turn: diameter of the centre's path over the last full turn, m.
    TurnDiameterM,
    /// Spot turn: mean time per 360 degrees over the full turns after the first, s.
    TurnPeriodS,
    /// Largest increase between consecutive 200 ms samples per sample period in
    /// `from_s..until_s`, m/s^2 (thesis 4.6 reads its bound this way).
    PeakAccelerationMps2,
}

/// Whether a value is a measurement or only a bound (thesis 4.6: the peak acceleration "can be
/// regarded as an upper bound"). A bound is met at no cost; beyond it the miss counts as
/// `(sim - value) / sigma`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    Value,
    Upper,
    Lower,
}

/// Which physical behaviour a quantity shows: straight-line speed or turning.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Behaviour {
    Speed,
    Turn,
}

impl Quantity {
    pub const ALL: [Quantity; 6] = [
        Quantity::TopSpeedMps,
        Quantity::TimeToTopSpeedS,
        Quantity::TimeToRestS,
        Quantity::TurnDiameterM,
        Quantity::TurnPeriodS,
        Quantity::PeakAccelerationMps2,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Quantity::TopSpeedMps => "top_speed_mps",
            Quantity::TimeToTopSpeedS => "time_to_top_speed_s",
            Quantity::TimeToRestS => "time_to_rest_s",
            Quantity::TurnDiameterM => "turn_diameter_m",
            Quantity::TurnPeriodS => "turn_period_s",
            Quantity::PeakAccelerationMps2 => "peak_acceleration_mps2",
        }
    }

    pub fn unit(self) -> &'static str {
        match self {
            Quantity::TopSpeedMps => "m/s",
            Quantity::TurnDiameterM => "m",
            Quantity::PeakAccelerationMps2 => "m/s^2",
            _ => "s",
        }
    }

    pub fn behaviour(self) -> Behaviour {
        match self {
            Quantity::TopSpeedMps
            | Quantity::TimeToTopSpeedS
            | Quantity::TimeToRestS
            | Quantity::PeakAccelerationMps2 => Behaviour::Speed,
            Quantity::TurnDiameterM | Quantity::TurnPeriodS => Behaviour::Turn,
        }
    }

    fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|q| q.name() == s)
    }
}

/// The behaviours each physics candidate is expected to change (its summary-level
/// signature). Thruster imbalance and reverse asymmetry act through the turning moment (the
/// thesis's spot turn runs one motor in reverse); drag, added mass and thruster lag shape the
/// speed runs; a current and a common thrust gain change both. Effects that only change
/// sensors move none.
pub fn signature_kinds(effect: &Effect) -> &'static [Behaviour] {
    match effect.name {
        "thruster_imbalance" | "reverse_thrust_asymmetry" | "yaw_damping" | "sway_yaw_coupling" => {
            &[Behaviour::Turn]
        }
        "drag_mismatch" | "added_mass" | "thruster_lag" => &[Behaviour::Speed],
        "water_current" | "thrust_gain" => &[Behaviour::Speed, Behaviour::Turn],
        _ => &[],
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSummary {
    name: String,
    #[serde(default)]
    description: String,
    #[serde(rename = "observation")]
    observations: Vec<RawObservation>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObservation {
    name: String,
    experiment: String,
    quantity: String,
    value: f64,
    sigma: f64,
    source: String,
    from_s: Option<f64>,
    until_s: Option<f64>,
    #[serde(default)]
    bound: Option<String>,
}

/// One observation, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    pub name: String,
    /// The experiment reference as written (for the report).
    pub experiment_ref: String,
    /// Index into [`Summary::experiments`].
    pub experiment: usize,
    pub quantity: Quantity,
    pub value: f64,
    /// 1 sigma, in the quantity's unit.
    pub sigma: f64,
    pub source: String,
    pub from_s: f64,
    pub until_s: Option<f64>,
    pub bound: Bound,
}

impl Observation {
    /// The normalised miss of a simulated value `v` (see [`Bound`]).
    pub fn z(&self, v: f64, sigma: f64) -> f64 {
        let d = v - self.value;
        match self.bound {
            Bound::Value => d / sigma,
            Bound::Upper => d.max(0.0) / sigma,
            Bound::Lower => d.min(0.0) / sigma,
        }
    }
}

/// A summary file, resolved: the experiments it refers to (each loaded once) and the
/// observations.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub name: String,
    pub description: String,
    pub experiments: Vec<Experiment>,
    pub observations: Vec<Observation>,
}

impl Summary {
    /// `path` is a summary file, or a directory holding [`FILE_NAME`].
    pub fn load(path: &Path) -> Result<Self, GapError> {
        let file = summary_file(path).unwrap_or_else(|| path.to_path_buf());
        let text = std::fs::read_to_string(&file).map_err(|source| GapError::Io {
            path: file.clone(),
            source,
        })?;
        let base = file.parent().map(Path::to_path_buf).unwrap_or_default();
        Self::from_text(&file.display().to_string(), &text, &base)
    }

    /// Parses a summary file's text; experiment references resolve against `base` first, then
    /// the embedded configs.
    pub fn from_text(origin: &str, text: &str, base: &Path) -> Result<Self, GapError> {
        let doc = Document::new(origin, text);
        let raw: RawSummary = doc.parse()?;
        if raw.observations.is_empty() {
            return Err(doc
                .invalid("observation", "at least one [[observation]] is required")
                .into());
        }
        let mut refs: Vec<String> = Vec::new();
        let mut experiments = Vec::new();
        let mut observations = Vec::new();
        for (i, o) in raw.observations.iter().enumerate() {
            let key = format!("observation.{i}");
            let quantity = Quantity::parse(&o.quantity).ok_or_else(|| {
                doc.invalid(
                    &format!("{key}.quantity"),
                    format!(
                        "unknown quantity `{}`; known: {}",
                        o.quantity,
                        Quantity::ALL.map(Quantity::name).join(", ")
                    ),
                )
            })?;
            if !o.value.is_finite() {
                return Err(doc
                    .invalid(&format!("{key}.value"), "must be a finite number")
                    .into());
            }
            let sigma =
                doc.check_range(&format!("{key}.sigma"), o.sigma, 1e-9, 1e9, quantity.unit())?;
            let experiment = match refs.iter().position(|r| *r == o.experiment) {
                Some(k) => k,
                None => {
                    let (eo, et) = read_ref(base, &o.experiment)?;
                    experiments.push(Experiment::from_document(&Document::new(eo, &et))?);
                    refs.push(o.experiment.clone());
                    refs.len() - 1
                }
            };
            let duration = experiments[experiment].duration_s;
            let from_s = match o.from_s {
                Some(f) => doc.check_range(&format!("{key}.from_s"), f, 0.0, duration, "s")?,
                None if quantity == Quantity::TopSpeedMps => TOP_SPEED_FROM_S.min(duration),
                None => 0.0,
            };
            let bound = match o.bound.as_deref() {
                None | Some("value") => Bound::Value,
                Some("upper") => Bound::Upper,
                Some("lower") => Bound::Lower,
                Some(other) => {
                    return Err(doc
                        .invalid(
                            &format!("{key}.bound"),
                            format!("unknown bound `{other}`; known: value, upper, lower"),
                        )
                        .into());
                }
            };
            let until_s = match o.until_s {
                Some(u) => {
                    Some(doc.check_range(&format!("{key}.until_s"), u, from_s, duration, "s")?)
                }
                None => None,
            };
            observations.push(Observation {
                name: o.name.clone(),
                experiment_ref: o.experiment.clone(),
                experiment,
                quantity,
                value: o.value,
                sigma,
                source: o.source.clone(),
                from_s,
                until_s,
                bound,
            });
        }
        Ok(Self {
            name: raw.name,
            description: raw.description,
            experiments,
            observations,
        })
    }
}

/// The summary file `path` stands for, if it is one: a `.toml` file, or a directory holding
/// [`FILE_NAME`].
pub fn summary_file(path: &Path) -> Option<PathBuf> {
    if path.is_dir() {
        let f = path.join(FILE_NAME);
        f.is_file().then_some(f)
    } else {
        (path.extension().is_some_and(|e| e == "toml") && path.is_file())
            .then(|| path.to_path_buf())
    }
}

/// Linear interpolation of the time at which `v` crosses `level` between two samples.
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

/// One observation, before and after.
#[derive(Debug, Clone, Serialize)]
pub struct ObservationResult {
    pub name: String,
    pub quantity: Quantity,
    pub unit: &'static str,
    pub experiment: String,
    pub source: String,
    pub measured: f64,
    pub bound: Bound,
    pub sigma_measured: f64,
    /// The model's own spread (thrust fluctuation), 1 sigma.
    pub sigma_model: f64,
    pub simulated_before: Option<f64>,
    pub simulated_after: Option<f64>,
    /// (sim - measured) / sigma.
    pub z_before: Option<f64>,
    pub z_after: Option<f64>,
}

/// One candidate's fit on the summary observations.
#[derive(Debug, Clone, Serialize)]
pub struct SummaryCandidate {
    pub name: String,
    pub parameters: Vec<(String, f64)>,
    pub ci95: Vec<(String, [f64; 2])>,
    /// The effects accepted in earlier rounds, refitted jointly with this one: (name, values,
    /// 95 % intervals).
    pub refitted: Vec<(String, Vec<f64>, Vec<[f64; 2]>)>,
    pub chi2_before: f64,
    pub chi2_after: f64,
    pub delta_bic: f64,
    pub signature_pass: bool,
    pub signature: String,
    pub testable: bool,
    pub evaluations: usize,
}

/// Everything the summary workflow found.
#[derive(Debug, Clone)]
pub struct SummaryAnalysis {
    pub observations: Vec<ObservationResult>,
    pub rounds: Vec<Vec<SummaryCandidate>>,
    pub accepted: Vec<SummaryCandidate>,
    pub verdict: Verdict,
    pub fitted: GapModel,
    pub chi2_before: f64,
    pub chi2_after: f64,
    /// Chi-square 95 % point for `n - k` degrees of freedom after fitting.
    pub chi2_critical_after: f64,
    /// True when the fitted model agrees with the data within the stated uncertainties.
    pub consistent_after: bool,
    /// Observations still off by more than 2 sigma after fitting.
    pub unexplained: Vec<String>,
    /// Fewer than [`FEW_OBSERVATIONS`] observations: the verdict is a lead.
    pub few_observations: bool,
    /// RMS of z over the observations.
    pub gap_before: f64,
    pub gap_after: f64,
    pub gap_reduction_pct: f64,
}

fn chi2(z: &[f64]) -> f64 {
    z.iter().map(|v| v * v).sum()
}

struct Context<'a> {
    s: &'a Summary,
    sigma: &'a [f64],
}

impl Context<'_> {
    /// Normalised residuals for configs `c`; `None` if a quantity is undefined there.
    fn z(&self, c: &Configs) -> Option<Vec<f64>> {
        let p = predict(c, self.s, None).ok()?;
        p.iter()
            .zip(&self.s.observations)
            .zip(self.sigma)
            .map(|((v, o), s)| v.map(|v| o.z(v, *s)))
            .collect()
    }
}

/// An effect already accepted in an earlier round, with its current values.
#[derive(Debug, Clone)]
pub struct Prior {
    pub effect: &'static Effect,
    pub values: Vec<f64>,
}

/// One candidate fitted jointly with the effects accepted before it: the parameter vector is
/// the priors' parameters followed by the candidate's, each in units of its scale.
struct Joint<'a, 'b> {
    ctx: &'a Context<'b>,
    start: &'a Configs,
    prior: &'a [Prior],
    effect: &'static Effect,
}

impl Joint<'_, '_> {
    fn effects(&self) -> impl Iterator<Item = &'static Effect> + '_ {
        self.prior
            .iter()
            .map(|p| p.effect)
            .chain(std::iter::once(self.effect))
    }

    fn scales(&self) -> Vec<f64> {
        self.effects()
            .flat_map(|e| e.scales.iter().copied())
            .collect()
    }

    fn bounds(&self) -> Vec<(f64, f64)> {
        self.effects()
            .flat_map(|e| e.bounds.iter().copied())
            .collect()
    }

    fn values(&self, x: &DVector<f64>) -> Vec<f64> {
        x.iter().zip(self.scales()).map(|(v, s)| v * s).collect()
    }

    /// Splits full values into (priors' values, candidate's values).
    fn split(&self, v: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>) {
        let mut at = 0;
        let mut priors = Vec::new();
        for p in self.prior {
            let k = p.effect.parameters.len();
            priors.push(v[at..at + k].to_vec());
            at += k;
        }
        (priors, v[at..].to_vec())
    }

    fn residuals_at(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
        let (priors, own) = self.split(&self.values(x));
        let mut c = self.start.clone();
        for (p, v) in self.prior.iter().zip(&priors) {
            effects::apply(p.effect, v, &mut c);
        }
        effects::apply(self.effect, &own, &mut c);
        self.ctx.z(&c).map(DVector::from_vec)
    }
}

fn names(effect: &Effect) -> impl Iterator<Item = String> + '_ {
    effect.parameters.iter().map(|p| p.to_string())
}

fn untestable(effect: &Effect, chi2_before: f64, why: String) -> SummaryCandidate {
    SummaryCandidate {
        name: effect.name.to_string(),
        parameters: names(effect).map(|n| (n, 0.0)).collect(),
        ci95: names(effect).map(|n| (n, [0.0, 0.0])).collect(),
        refitted: Vec::new(),
        chi2_before,
        chi2_after: chi2_before,
        delta_bic: f64::NEG_INFINITY,
        signature_pass: false,
        signature: why,
        testable: false,
        evaluations: 0,
    }
}

fn fit_one(
    ctx: &Context<'_>,
    start: &Configs,
    prior: &[Prior],
    effect: &'static Effect,
    z0: &[f64],
) -> SummaryCandidate {
    let k = effect.parameters.len();
    let n = z0.len();
    let chi2_before = chi2(z0);
    let kinds = signature_kinds(effect);
    if kinds.is_empty() {
        return untestable(
            effect,
            chi2_before,
            "not testable from summary observations: it changes only sensor readings".into(),
        );
    }
    if !ctx
        .s
        .observations
        .iter()
        .any(|o| kinds.contains(&o.quantity.behaviour()))
    {
        return untestable(
            effect,
            chi2_before,
            format!("not testable: no observation of its behaviour ({kinds:?})"),
        );
    }
    let joint = Joint {
        ctx,
        start,
        prior,
        effect,
    };
    let x0: Vec<f64> = prior
        .iter()
        .flat_map(|p| p.values.iter().zip(p.effect.scales).map(|(v, s)| v / s))
        .chain(std::iter::repeat_n(0.0, k))
        .collect();
    let scales = joint.scales();
    let bounds = Bounds::scaled(&joint.bounds(), &scales);
    let objective = |x: &DVector<f64>| joint.residuals_at(x);
    let Some(result) = lsq::minimize(&objective, &bounds, &[DVector::from_vec(x0)]) else {
        return untestable(
            effect,
            chi2_before,
            "the model's quantities are undefined even without the effect".into(),
        );
    };
    let (x, r1) = (&result.x, &result.residuals);
    let chi2_after = result.chi2();
    let all = joint.values(x);
    let m = all.len();
    let ci_all = lsq::intervals(x, result.covariance().as_ref(), &scales, 1.0);
    let (prior_values, params) = joint.split(&all);
    let ci = ci_all[m - k..].to_vec();
    let mut at = 0;
    let refitted = prior
        .iter()
        .zip(prior_values)
        .map(|(p, v)| {
            let kk = p.effect.parameters.len();
            let c = ci_all[at..at + kk].to_vec();
            at += kk;
            (p.effect.name.to_string(), v, c)
        })
        .collect();
    // Only the candidate's own parameters are new; the priors' were paid for already.
    let delta_bic = chi2_before - chi2_after - k as f64 * (n as f64).ln();
    // Signature: the candidate's own improvement must come from the behaviour it acts
    // through. Its own share is measured from the refitted priors without it, so what the
    // refit of earlier effects gains is not credited to it.
    let mut x_without = x.clone();
    for i in m - k..m {
        x_without[i] = 0.0;
    }
    let z_mid: Vec<f64> = if prior.is_empty() {
        z0.to_vec()
    } else {
        joint
            .residuals_at(&x_without)
            .map_or_else(|| z0.to_vec(), |r| r.iter().copied().collect())
    };
    let (mut gain_sig, mut gain_all) = (0.0, 0.0);
    for ((a, b), o) in z_mid.iter().zip(r1.iter()).zip(&ctx.s.observations) {
        let g = a * a - b * b;
        gain_all += g;
        if kinds.contains(&o.quantity.behaviour()) {
            gain_sig += g;
        }
    }
    let share = if gain_all > 0.0 {
        gain_sig / gain_all
    } else {
        0.0
    };
    let identifiable = n > m;
    let signature_pass = identifiable && share >= fit::SIGNATURE_MIN_SHARE;
    SummaryCandidate {
        name: effect.name.to_string(),
        parameters: names(effect).zip(params.iter().copied()).collect(),
        ci95: names(effect).zip(ci).collect(),
        refitted,
        chi2_before,
        chi2_after,
        delta_bic,
        signature_pass,
        signature: if identifiable {
            format!(
                "acts through {kinds:?}: {:.0} % of the net improvement comes from those observations (>= {:.0} %)",
                share * 100.0,
                fit::SIGNATURE_MIN_SHARE * 100.0
            )
        } else {
            format!("not identifiable: {m} parameters in all, {n} observations")
        },
        testable: true,
        evaluations: result.evaluations,
    }
}

/// The winner of a round, if any (see the module doc for the rule): besides the margin and
/// the signature, every parameter strictly inside its physical bounds and every 95 %
/// interval finite, one of them clear of zero. A parameter the observations cannot move (a
/// scale of a term the model does not have) has an infinite interval, and an effect that
/// holds one is not named.
pub fn winner(results: &[SummaryCandidate]) -> Option<&SummaryCandidate> {
    results.iter().find(|r| {
        let values: Vec<f64> = r.parameters.iter().map(|(_, v)| *v).collect();
        let inside = effects::by_name(&r.name).is_some_and(|e| effects::inside_bounds(e, &values));
        let finite = r
            .ci95
            .iter()
            .all(|(_, c)| c[0].is_finite() && c[1].is_finite());
        let clear = r.ci95.iter().any(|(_, c)| c[0] > 0.0 || c[1] < 0.0);
        r.testable && r.delta_bic > fit::BIC_MARGIN && r.signature_pass && inside && finite && clear
    })
}

/// Runs the summary workflow with `model` (experiments' world: the model's, or the default
/// pool). `progress(round, effect)` is called before each candidate fit.
pub fn analyse(
    model: &GapModel,
    s: &Summary,
    progress: &mut dyn FnMut(usize, &str),
) -> Result<SummaryAnalysis, GapError> {
    let info = crate::gap::format::ExperimentInfo {
        name: s.name.clone(),
        description: s.description.clone(),
        duration_s: 0.0,
        world: crate::physics::DEFAULT_WORLD.to_string(),
        sensors: "sensors/mako-2008.toml".to_string(),
        initial: crate::gap::format::Initial {
            x_m: 0.0,
            y_m: 0.0,
            z_m: None,
            heading_deg: 0.0,
            roll_deg: 0.0,
            pitch_deg: 0.0,
            surge_mps: 0.0,
        },
        camera_position_std_m: 0.0,
        camera_speed_std_mps: 0.0,
    };
    let start = model.configs(&info, &model.base)?;
    let mean0 = predict(&start, s, None)?;
    if let Some((o, _)) = s.observations.iter().zip(&mean0).find(|(_, v)| v.is_none()) {
        return Err(GapError::Data(format!(
            "observation `{}`: the model gives no {} in `{}` (e.g. fewer than two full turns)",
            o.name,
            o.quantity.name(),
            o.experiment_ref
        )));
    }
    // The model's own spread.
    let mut runs = Vec::new();
    for seed in 1..=ENSEMBLE {
        runs.push(predict(&start, s, Some(seed))?);
    }
    let sigma_model: Vec<f64> = (0..s.observations.len())
        .map(|i| {
            let v: Vec<f64> = runs.iter().filter_map(|r| r[i]).collect();
            if v.len() < 2 {
                return 0.0;
            }
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        })
        .collect();
    let sigma: Vec<f64> = s
        .observations
        .iter()
        .zip(&sigma_model)
        .map(|(o, m)| (o.sigma * o.sigma + m * m).sqrt())
        .collect();
    let ctx = Context { s, sigma: &sigma };

    let mut priors: Vec<Prior> = Vec::new();
    let mut accepted: Vec<SummaryCandidate> = Vec::new();
    let mut rounds = Vec::new();
    let skip_model: Vec<&str> = model.effects.iter().map(|e| e.effect.name).collect();
    let with = |priors: &[Prior]| {
        let mut c = start.clone();
        for p in priors {
            effects::apply(p.effect, &p.values, &mut c);
        }
        c
    };
    for round in 0..fit::MAX_EFFECTS {
        let Some(z0) = ctx.z(&with(&priors)) else {
            break;
        };
        let mut results = Vec::new();
        for effect in effects::LIBRARY.iter() {
            progress(round, effect.name);
            if skip_model.contains(&effect.name)
                || priors.iter().any(|p| p.effect.name == effect.name)
            {
                continue;
            }
            let r = fit_one(&ctx, &start, &priors, effect, &z0);
            tracing::debug!(
                effect = effect.name,
                delta_bic = r.delta_bic,
                "summary candidate fitted"
            );
            results.push(r);
        }
        results.sort_by(|a, b| b.delta_bic.total_cmp(&a.delta_bic));
        let win = winner(&results).cloned();
        rounds.push(results);
        let Some(win) = win else { break };
        let Some(effect) = effects::by_name(&win.name) else {
            break;
        };
        for (p, (_, v, _)) in priors.iter_mut().zip(&win.refitted) {
            p.values.clone_from(v);
        }
        priors.push(Prior {
            effect,
            values: win.parameters.iter().map(|(_, v)| *v).collect(),
        });
        accepted.push(win);
    }
    let configs = with(&priors);
    // The fitted model: the model's own effects, then the accepted ones with their final
    // (jointly refitted) values and intervals.
    let mut fitted = model.clone();
    let last = accepted.last();
    for (i, (p, a)) in priors.iter().zip(&accepted).enumerate() {
        let ci95 = match last {
            Some(l) if i + 1 < accepted.len() => l
                .refitted
                .get(i)
                .map_or_else(|| vec![[f64::NAN; 2]; p.values.len()], |r| r.2.clone()),
            _ => a.ci95.iter().map(|(_, c)| *c).collect(),
        };
        fitted.effects.push(EnabledEffect {
            effect: p.effect,
            values: p.values.clone(),
            ci95,
            delta_bic: Some(a.delta_bic),
        });
    }
    let mean1 = predict(&configs, s, None)?;
    let z = |v: &Option<f64>, o: &Observation, sg: f64| v.map(|v| o.z(v, sg));
    let observations: Vec<ObservationResult> = s
        .observations
        .iter()
        .enumerate()
        .map(|(i, o)| ObservationResult {
            name: o.name.clone(),
            quantity: o.quantity,
            unit: o.quantity.unit(),
            experiment: o.experiment_ref.clone(),
            source: o.source.clone(),
            measured: o.value,
            bound: o.bound,
            sigma_measured: o.sigma,
            sigma_model: sigma_model[i],
            simulated_before: mean0[i],
            simulated_after: mean1[i],
            z_before: z(&mean0[i], o, sigma[i]),
            z_after: z(&mean1[i], o, sigma[i]),
        })
        .collect();
    let zs = |f: fn(&ObservationResult) -> Option<f64>| -> Vec<f64> {
        // An undefined quantity after fitting counts as a large miss, not as agreement.
        observations.iter().map(|o| f(o).unwrap_or(1e3)).collect()
    };
    let zb = zs(|o| o.z_before);
    let za = zs(|o| o.z_after);
    let n = observations.len();
    let k: usize = fitted
        .effects
        .iter()
        .map(|e| e.effect.parameters.len())
        .sum();
    let dof = n.saturating_sub(k).max(1);
    let chi2_critical_after = residuals::chi2_critical_95(dof);
    let rms = |z: &[f64]| (chi2(z) / n.max(1) as f64).sqrt();
    let (gb, ga) = (rms(&zb), rms(&za));
    Ok(SummaryAnalysis {
        unexplained: observations
            .iter()
            .zip(&za)
            .filter(|(_, z)| z.abs() > 2.0)
            .map(|(o, _)| o.name.clone())
            .collect(),
        chi2_before: chi2(&zb),
        chi2_after: chi2(&za),
        consistent_after: chi2(&za) <= chi2_critical_after,
        chi2_critical_after,
        few_observations: n < FEW_OBSERVATIONS,
        verdict: if accepted.is_empty() {
            Verdict::None
        } else {
            Verdict::Effect
        },
        gap_before: gb,
        gap_after: ga,
        gap_reduction_pct: crate::gap::reduction_pct(gb, ga),
        observations,
        rounds,
        accepted,
        fitted,
    })
}

// ---------------------------------------------------------------------------------------------
// Output
// ---------------------------------------------------------------------------------------------

fn finite(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

fn candidate_json(c: &SummaryCandidate) -> Value {
    json!({
        "name": c.name,
        "parameters": c.parameters.iter().map(|(k, v)| (k.clone(), json!(v))).collect::<serde_json::Map<_, _>>(),
        "ci95": c.ci95.iter().map(|(k, v)| (k.clone(), json!([finite(v[0]), finite(v[1])]))).collect::<serde_json::Map<_, _>>(),
        "delta_bic": finite(c.delta_bic),
        "chi2_before": c.chi2_before,
        "chi2_after": c.chi2_after,
        "signature_pass": c.signature_pass,
        "signature": c.signature,
        "testable": c.testable,
    })
}

/// `report.json`: `effects`, `verdict`, `gap_before` / `gap_after` (observation -> |z|, the
/// normalised miss), `gap_reduction_pct` (of the RMS of z), and the details.
pub fn json(a: &SummaryAnalysis, s: &Summary) -> Value {
    let gap = |f: fn(&ObservationResult) -> Option<f64>| -> Value {
        a.observations
            .iter()
            .map(|o| (o.name.clone(), f(o).map_or(Value::Null, |z| json!(z.abs()))))
            .collect::<serde_json::Map<_, _>>()
            .into()
    };
    json!({
        "summary": s.name,
        "effects": a.fitted.effects.iter().skip(a.fitted.effects.len() - a.accepted.len()).map(|e| json!({
            "name": e.effect.name,
            "parameters": e.effect.parameters.iter().zip(&e.values).map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
            "ci95": e.effect.parameters.iter().zip(&e.ci95).map(|(k, c)| (k.to_string(), json!([finite(c[0]), finite(c[1])]))).collect::<serde_json::Map<_, _>>(),
            "delta_bic": e.delta_bic,
        })).collect::<Vec<_>>(),
        "verdict": a.verdict,
        "bic_margin": fit::BIC_MARGIN,
        "gap_before": gap(|o| o.z_before),
        "gap_after": gap(|o| o.z_after),
        "gap_rms_z_before": a.gap_before,
        "gap_rms_z_after": a.gap_after,
        "gap_reduction_pct": a.gap_reduction_pct,
        "chi2_before": a.chi2_before,
        "chi2_after": a.chi2_after,
        "chi2_critical_95_after": a.chi2_critical_after,
        "consistent_after": a.consistent_after,
        "unexplained": a.unexplained,
        "few_observations": a.few_observations,
        "observations": a.observations,
        "rounds": a.rounds.iter().map(|r| r.iter().map(candidate_json).collect::<Vec<_>>()).collect::<Vec<_>>(),
    })
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{v:.prec$}"))
}

/// `report.md`.
pub fn markdown(a: &SummaryAnalysis, s: &Summary) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "# Reality gap (summary observations): {}\n", s.name);
    if !s.description.is_empty() {
        let _ = writeln!(out, "{}\n", s.description);
    }
    let verdict = if a.accepted.is_empty() {
        "no significant missing effect".to_string()
    } else {
        format!(
            "missing or wrong: **{}**",
            a.accepted
                .iter()
                .map(|c| c.name.as_str())
                .collect::<Vec<_>>()
                .join("**, then **")
        )
    };
    let _ = writeln!(
        out,
        "Verdict: {verdict} (rule: delta BIC > {} with k ln(n), n = {} observations, and >= {:.0} % of the improvement from the behaviour the effect acts through).\n",
        fit::BIC_MARGIN,
        a.observations.len(),
        fit::SIGNATURE_MIN_SHARE * 100.0
    );
    if a.few_observations {
        let _ = writeln!(
            out,
            "**Only {} observations.** The BIC's penalty assumes many independent samples; with this few, a named effect is a lead to test with more data, not a proof, and parameters with wide intervals are poorly pinned.\n",
            a.observations.len()
        );
    }
    if a.consistent_after {
        let _ = writeln!(
            out,
            "After fitting, chi2 = {:.1} <= {:.1} (95 % point, {} - k degrees of freedom): the model agrees with the data within the stated uncertainties.\n",
            a.chi2_after,
            a.chi2_critical_after,
            a.observations.len()
        );
    } else {
        let _ = writeln!(
            out,
            "After fitting, chi2 = {:.1} > {:.1} (95 % point): the model still disagrees beyond the stated uncertainties. Still off by more than 2 sigma: {}. No candidate in the library explains them; something else is missing.\n",
            a.chi2_after,
            a.chi2_critical_after,
            if a.unexplained.is_empty() {
                "none individually".to_string()
            } else {
                a.unexplained.join(", ")
            }
        );
    }
    if a.fitted.effects.len() > a.accepted.len() || !a.accepted.is_empty() {
        let _ = writeln!(
            out,
            "## Fitted effects (final values, refitted jointly)\n\n| effect | parameters [95 %] | delta BIC when added |\n|---|---|---|"
        );
        for e in a
            .fitted
            .effects
            .iter()
            .skip(a.fitted.effects.len() - a.accepted.len())
        {
            let p: Vec<String> = e
                .effect
                .parameters
                .iter()
                .zip(&e.values)
                .zip(&e.ci95)
                .map(|((n, v), c)| format!("{n} = {v:.4} [{:.4}, {:.4}]", c[0], c[1]))
                .collect();
            let _ = writeln!(
                out,
                "| {} | {} | {} |",
                e.effect.name,
                p.join("; "),
                e.delta_bic
                    .map_or_else(|| "-".into(), |d| format!("{d:.1}"))
            );
        }
        let _ = writeln!(
            out,
            "\nAn interval of [-inf, inf] marks a parameter the data do not move at the fitted point (a scale on a term the model does not have, or a value held at the edge of its physical range).\n"
        );
    }
    let _ = writeln!(out, "## Observations, before and after\n");
    let _ = writeln!(
        out,
        "| observation | experiment | measured | sigma (meas, model) | model before | z before | model after | z after | source |\n|---|---|---|---|---|---|---|---|---|"
    );
    for o in &a.observations {
        let _ = writeln!(
            out,
            "| {} ({}) | {} | {}{:.3} {} | {:.3}, {:.3} | {} | {} | {} | {} | {} |",
            o.name,
            o.quantity.name(),
            o.experiment,
            match o.bound {
                Bound::Value => "",
                Bound::Upper => "<= ",
                Bound::Lower => ">= ",
            },
            o.measured,
            o.unit,
            o.sigma_measured,
            o.sigma_model,
            opt(o.simulated_before, 3),
            opt(o.z_before, 1),
            opt(o.simulated_after, 3),
            opt(o.z_after, 1),
            o.source
        );
    }
    let _ = writeln!(
        out,
        "\nRMS of z: {:.2} -> {:.2} ({:.0} % smaller).",
        a.gap_before, a.gap_after, a.gap_reduction_pct
    );
    for (i, round) in a.rounds.iter().enumerate() {
        let _ = writeln!(out, "\n## Candidates, round {}\n", i + 1);
        let _ = writeln!(
            out,
            "| rank | effect | delta BIC | chi2 before -> after | parameters [95 %] | signature |\n|---|---|---|---|---|---|"
        );
        for (k, c) in round.iter().enumerate() {
            let p: Vec<String> = c
                .parameters
                .iter()
                .zip(&c.ci95)
                .map(|((n, v), (_, ci))| format!("{n} = {v:.4} [{:.4}, {:.4}]", ci[0], ci[1]))
                .collect();
            let _ = writeln!(
                out,
                "| {} | {} | {} | {:.1} -> {:.1} | {} | {} {} |",
                k + 1,
                c.name,
                if c.delta_bic.is_finite() {
                    format!("{:.1}", c.delta_bic)
                } else {
                    "-".into()
                },
                c.chi2_before,
                c.chi2_after,
                if c.testable { p.join("; ") } else { "-".into() },
                if c.signature_pass { "pass:" } else { "fail:" },
                c.signature
            );
        }
    }
    out
}

fn plot_err(path: &Path, e: impl std::fmt::Display) -> GapError {
    GapError::Plot {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// `observations.svg`: z before (red) and after (blue) per observation, with the +-2 band.
pub fn plot(a: &SummaryAnalysis, out: &Path) -> Result<(), GapError> {
    let path = out.join("observations.svg");
    let n = a.observations.len().max(1);
    let clamp = |z: f64| z.clamp(-40.0, 40.0);
    let zmax = a
        .observations
        .iter()
        .flat_map(|o| [o.z_before, o.z_after])
        .flatten()
        .map(|z| clamp(z).abs())
        .fold(3.0, f64::max)
        * 1.1;
    let root = SVGBackend::new(&path, (900, 120 + 50 * n as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(&path, e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "(sim - measured) / sigma per observation: red = model, blue = model + fitted effects",
            ("sans-serif", 15),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(220)
        .build_cartesian_2d(-zmax..zmax, (0..n).into_segmented())
        .map_err(|e| plot_err(&path, e))?;
    let labels: Vec<String> = a.observations.iter().map(|o| o.name.clone()).collect();
    chart
        .configure_mesh()
        .y_label_formatter(&|v| match v {
            SegmentValue::CenterOf(i) => labels.get(*i).cloned().unwrap_or_default(),
            _ => String::new(),
        })
        .y_labels(n)
        .x_desc("z (clamped to +-40)")
        .draw()
        .map_err(|e| plot_err(&path, e))?;
    for (i, o) in a.observations.iter().enumerate() {
        if let Some(z) = o.z_before {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [
                        (0.0, SegmentValue::Exact(i)),
                        (clamp(z), SegmentValue::Exact(i + 1)),
                    ],
                    RED.mix(0.6).filled(),
                )))
                .map_err(|e| plot_err(&path, e))?;
        }
        if let Some(z) = o.z_after {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [
                        (0.0, SegmentValue::Exact(i)),
                        (clamp(z), SegmentValue::Exact(i + 1)),
                    ],
                    BLUE.mix(0.8).filled(),
                )))
                .map_err(|e| plot_err(&path, e))?;
        }
    }
    for x in [-2.0, 2.0] {
        chart
            .draw_series(LineSeries::new(
                [(x, SegmentValue::Exact(0)), (x, SegmentValue::Exact(n))],
                BLACK,
            ))
            .map_err(|e| plot_err(&path, e))?;
    }
    root.present().map_err(|e| plot_err(&path, e))?;
    Ok(())
}

/// Writes `report.json`, `report.md`, `MODEL.fitted.toml` and `observations.svg` into `out`.
pub fn write_all(
    a: &SummaryAnalysis,
    s: &Summary,
    summary_path: &Path,
    model_path: &Path,
    out: &Path,
) -> Result<(), GapError> {
    let write = crate::gap::report::output_dir(out)?;
    let text =
        serde_json::to_string_pretty(&json(a, s)).map_err(|e| GapError::Data(e.to_string()))?;
    write("report.json", text)?;
    write("report.md", markdown(a, s))?;
    let stem = model_path
        .file_stem()
        .map_or_else(|| "model".to_string(), |x| x.to_string_lossy().into_owned());
    let provenance = format!(
        "Written by `eyebot-hil gap --measured {} --model {}` (eyebot-hil {}).\n\
         Effects fitted by Levenberg-Marquardt on the summary observations `{}` ({} numbers);\n\
         each accepted because it beat \"no effect\" by delta BIC > {} and its improvement came\n\
         from the behaviour it acts through. Parameters are changes relative to the base\n\
         configuration (see docs/gap.md).",
        summary_path.display(),
        model_path.display(),
        env!("CARGO_PKG_VERSION"),
        s.name,
        s.observations.len(),
        fit::BIC_MARGIN
    );
    write(
        &format!("{stem}.fitted.toml"),
        a.fitted.to_toml(&provenance, out),
    )?;
    plot(a, out)
}

/// Observations by name, for tests and callers.
pub fn by_name(a: &SummaryAnalysis) -> BTreeMap<&str, &ObservationResult> {
    a.observations
        .iter()
        .map(|o| (o.name.as_str(), o))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const ONE: &str = r#"name = "t"
[[observation]]
name = "top speed"
experiment = "experiments/acceleration.toml"
quantity = "top_speed_mps"
value = 0.44
sigma = 0.02
source = "thesis 4.5"
"#;

    #[test]
    fn parses_and_defaults_the_top_speed_window() {
        let s = Summary::from_text("s.toml", ONE, Path::new("/nonexistent")).unwrap();
        assert_eq!(s.observations.len(), 1);
        assert_eq!(s.observations[0].quantity, Quantity::TopSpeedMps);
        assert_eq!(s.observations[0].from_s, TOP_SPEED_FROM_S);
        assert_eq!(s.experiments[0].name, "acceleration");
    }

    #[test]
    fn unknown_quantity_names_the_file_line_and_choices() {
        let text = ONE.replace("top_speed_mps", "speed");
        let err = Summary::from_text("s.toml", &text, Path::new("/nonexistent"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("s.toml:5:"), "{err}");
        assert!(err.contains("turn_diameter_m"), "{err}");
    }

    #[test]
    fn a_zero_sigma_is_rejected() {
        let text = ONE.replace("sigma = 0.02", "sigma = 0.0");
        let err = Summary::from_text("s.toml", &text, Path::new("/nonexistent"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("sigma"), "{err}");
    }

    #[test]
    fn an_unknown_experiment_is_an_error_not_a_panic() {
        let text = ONE.replace("experiments/acceleration.toml", "experiments/nope.toml");
        assert!(Summary::from_text("s.toml", &text, Path::new("/nonexistent")).is_err());
    }

    #[test]
    fn an_upper_bound_costs_nothing_inside_and_counts_beyond() {
        let text = ONE.replace("source =", "bound = \"upper\"\nsource =");
        let s = Summary::from_text("s.toml", &text, Path::new("/nonexistent")).unwrap();
        let o = &s.observations[0];
        assert_eq!(o.bound, Bound::Upper);
        assert_eq!(o.z(0.30, 0.02), 0.0);
        assert!((o.z(0.48, 0.02) - 2.0).abs() < 1e-9);
        let bad = ONE.replace("source =", "bound = \"above\"\nsource =");
        let err = Summary::from_text("s.toml", &bad, Path::new("/nonexistent"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("unknown bound `above`"), "{err}");
    }

    #[test]
    fn crossing_interpolates_between_samples() {
        assert!((crossing((1.0, 0.0), (2.0, 1.0), 0.25) - 1.25).abs() < 1e-12);
        // Falling through a level works the same way.
        assert!((crossing((1.0, 1.0), (2.0, 0.0), 0.25) - 1.75).abs() < 1e-12);
    }

    /// Every physics candidate moves at least one summary behaviour, and no sensor-only one
    /// claims to (else the summary fit would credit an effect with nothing it can change).
    #[test]
    fn signature_kinds_follow_the_physics_flag() {
        for e in &effects::LIBRARY {
            assert_eq!(!signature_kinds(e).is_empty(), e.physics, "{}", e.name);
        }
    }
}
