//! Fitting the effect library to summary observations with the one `lsq` engine, and the
//! greedy selection of what to name.

use nalgebra::DVector;
use serde::Serialize;

use super::{
    Bound, ENSEMBLE, FEW_OBSERVATIONS, Observation, Quantity, Summary, predict, signature_kinds,
};
use crate::gap::candidate::{self, Candidate, Guards, Refitted};
use crate::gap::effects::{self, Configs, Effect};
use crate::gap::lsq::{self, Bounds};
use crate::gap::model::{EnabledEffect, GapModel};
use crate::gap::{GapError, Verdict, fit, residuals};

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

/// Everything the summary workflow found.
#[derive(Debug, Clone)]
pub struct SummaryAnalysis {
    pub observations: Vec<ObservationResult>,
    pub rounds: Vec<Vec<Candidate>>,
    pub accepted: Vec<Candidate>,
    /// The two effects of a round that could not tell them apart
    /// ([`candidate::Selection::ambiguous`]), its winner first.
    pub ambiguous: Option<[String; 2]>,
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

fn untestable(effect: &Effect, chi2_before: f64, why: String) -> Candidate {
    Candidate::untestable(effect, chi2_before, &why)
}

fn fit_one(
    ctx: &Context<'_>,
    start: &Configs,
    prior: &[Prior],
    effect: &'static Effect,
    z0: &[f64],
) -> Candidate {
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
    let refitted: Vec<Refitted> = prior
        .iter()
        .zip(prior_values)
        .map(|(p, values)| {
            let kk = p.effect.parameters.len();
            let ci95 = ci_all[at..at + kk].to_vec();
            at += kk;
            Refitted {
                name: p.effect.name.to_string(),
                values,
                ci95,
            }
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
    let ci95: Vec<(String, [f64; 2])> = names(effect).zip(ci).collect();
    let mut guards = guards(effect, &params, &ci95, delta_bic, signature_pass);
    // The joint refit must leave the effects accepted before inside their bounds too: a
    // candidate that only fits by pushing an earlier one onto its bound is not named.
    guards.inside_bounds &= prior
        .iter()
        .zip(&refitted)
        .all(|(p, r): (_, &Refitted)| effects::inside_bounds(p.effect, &r.values));
    Candidate {
        name: effect.name.to_string(),
        parameters: names(effect).zip(params.iter().copied()).collect(),
        ci95,
        chi2_before,
        chi2_after,
        delta_bic,
        delta_bic_uncalibrated: delta_bic,
        heldout_chi2_before: None,
        heldout_chi2_after: None,
        heldout_gain: None,
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
        guards,
        testable: true,
        evaluations: result.evaluations,
        noise_factor: 1.0,
        variance_factor: 1.0,
        refitted,
        trained: Vec::new(),
        change: Vec::new(),
        noise_along: Default::default(),
    }
}

/// The guards of a summary candidate (see the module doc for the rule): every parameter
/// strictly inside its physical bounds; every 95 % interval finite and one of them clear of
/// zero (a parameter the observations cannot move, a scale of a term the model does not
/// have, has an infinite interval, and an effect that holds one is not named); the margin;
/// the signature. Summary observations have no held-out part.
fn guards(
    effect: &Effect,
    values: &[f64],
    ci95: &[(String, [f64; 2])],
    delta_bic: f64,
    signature: bool,
) -> Guards {
    let finite = ci95
        .iter()
        .all(|(_, c)| c[0].is_finite() && c[1].is_finite());
    let clear = ci95.iter().any(|(_, c)| c[0] > 0.0 || c[1] < 0.0);
    Guards {
        inside_bounds: effects::inside_bounds(effect, values),
        interval_excludes_zero: finite && clear,
        significant: delta_bic > fit::BIC_MARGIN,
        signature,
        heldout: None,
    }
}

/// Runs the summary workflow with `model` (experiments' world: the model's, or the default
/// pool). `progress(round, effect)` is called before each candidate fit.
pub fn analyse(
    model: &GapModel,
    s: &Summary,
    progress: &mut dyn FnMut(usize, &str),
) -> Result<SummaryAnalysis, GapError> {
    let info = summary_experiment(s);
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
    let sigma_model = model_spread(&start, s)?;
    let sigma: Vec<f64> = s
        .observations
        .iter()
        .zip(&sigma_model)
        .map(|(o, m)| (o.sigma * o.sigma + m * m).sqrt())
        .collect();
    let ctx = Context { s, sigma: &sigma };

    let skip_model: Vec<&str> = model.effects.iter().map(|e| e.effect.name).collect();
    let with = |priors: &[Prior]| {
        let mut c = start.clone();
        for p in priors {
            effects::apply(p.effect, &p.values, &mut c);
        }
        c
    };
    // The accepted effects with their latest (jointly refitted) values.
    let priors: std::cell::RefCell<Vec<Prior>> = std::cell::RefCell::new(Vec::new());
    let candidate::Selection {
        rounds,
        accepted,
        ambiguous,
        ..
    } = candidate::select(
        fit::MAX_EFFECTS,
        &mut |round, _, _| {
            let priors = priors.borrow();
            let Some(z0) = ctx.z(&with(&priors)) else {
                return Ok(None);
            };
            let mut results = Vec::new();
            for effect in effects::candidates() {
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
            Ok(Some(results))
        },
        &mut |accepted, _| {
            let Some(win) = accepted.last() else {
                return Ok(None);
            };
            let effect = effects::by_name(&win.name).ok_or_else(|| {
                GapError::Data(format!("`{}` is not in the effect library", win.name))
            })?;
            let mut priors = priors.borrow_mut();
            for (p, r) in priors.iter_mut().zip(&win.refitted) {
                p.values.clone_from(&r.values);
            }
            priors.push(Prior {
                effect,
                values: win.values(),
            });
            Ok(None)
        },
    )?;
    let priors = priors.into_inner();
    let configs = with(&priors);
    let fitted = fitted_model(model, &priors, &accepted);
    let mean1 = predict(&configs, s, None)?;
    let observations = observation_results(s, &sigma_model, &sigma, &mean0, &mean1);
    Ok(conclude(observations, rounds, accepted, ambiguous, fitted))
}

/// The stand-in experiment the model's configurations are built for: the summary's name and
/// description in the default pool, starting at rest at the origin.
fn summary_experiment(s: &Summary) -> crate::gap::format::ExperimentInfo {
    crate::gap::format::ExperimentInfo {
        name: s.name.clone(),
        description: s.description.clone(),
        duration_s: 0.0,
        world: crate::physics::DEFAULT_WORLD.to_string(),
        sensors: "sensors/mako-2008.toml".to_string(),
        initial: crate::gap::format::Initial::default(),
        camera_position_std_m: 0.0,
        camera_speed_std_mps: 0.0,
        camera_marker_body_m: [0.0; 2],
    }
}

/// The model's own spread per observation (thrust fluctuation): the sample standard deviation
/// over an ensemble of seeded runs, 0 where fewer than two runs give a value.
fn model_spread(start: &Configs, s: &Summary) -> Result<Vec<f64>, GapError> {
    let mut runs = Vec::new();
    for seed in 1..=ENSEMBLE {
        runs.push(predict(start, s, Some(seed))?);
    }
    Ok((0..s.observations.len())
        .map(|i| {
            let v: Vec<f64> = runs.iter().filter_map(|r| r[i]).collect();
            if v.len() < 2 {
                return 0.0;
            }
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        })
        .collect())
}

/// The fitted model: the model's own effects, then the accepted ones with their final
/// (jointly refitted) values and intervals.
fn fitted_model(model: &GapModel, priors: &[Prior], accepted: &[Candidate]) -> GapModel {
    let mut fitted = model.clone();
    let last = accepted.last();
    for (i, (p, a)) in priors.iter().zip(accepted).enumerate() {
        let ci95 = match last {
            Some(l) if i + 1 < accepted.len() => l
                .refitted
                .get(i)
                .map_or_else(|| vec![[f64::NAN; 2]; p.values.len()], |r| r.ci95.clone()),
            _ => a.ci95.iter().map(|(_, c)| *c).collect(),
        };
        fitted.effects.push(EnabledEffect {
            effect: p.effect,
            values: p.values.clone(),
            ci95,
            delta_bic: Some(a.delta_bic),
        });
    }
    fitted
}

/// Each observation with the model's prediction and z-score before (`mean0`) and after
/// (`mean1`) the fit; `sigma` combines the measurement's and the model's spread.
fn observation_results(
    s: &Summary,
    sigma_model: &[f64],
    sigma: &[f64],
    mean0: &[Option<f64>],
    mean1: &[Option<f64>],
) -> Vec<ObservationResult> {
    let z = |v: &Option<f64>, o: &Observation, sg: f64| v.map(|v| o.z(v, sg));
    s.observations
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
        .collect()
}

/// The summary's statistics (chi-square, RMS gap before and after, what stays unexplained)
/// and verdict, from the observation results and the selection's outcome.
fn conclude(
    observations: Vec<ObservationResult>,
    rounds: Vec<Vec<Candidate>>,
    accepted: Vec<Candidate>,
    ambiguous: Option<[String; 2]>,
    fitted: GapModel,
) -> SummaryAnalysis {
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
    SummaryAnalysis {
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
        verdict: match (accepted.is_empty(), &ambiguous) {
            (false, _) => Verdict::Effect,
            (true, Some(_)) => Verdict::Ambiguous,
            (true, None) => Verdict::None,
        },
        gap_before: gb,
        gap_after: ga,
        gap_reduction_pct: crate::gap::reduction_pct(gb, ga),
        observations,
        rounds,
        accepted,
        ambiguous,
        fitted,
    }
}
