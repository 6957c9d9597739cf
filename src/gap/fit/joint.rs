//! Effects fitted together: the named effects refitted jointly once another is named
//! ([`refit_jointly`]), and a later round's candidate fitted with the effects named before it
//! free ([`with_earlier_free`]).
//!
//! A later round fits each candidate against the model with the earlier names held at their
//! values. An earlier name fitted alone has taken the share of the disagreement it can explain
//! of a correlated effect's too (a thruster lag fitted 1.2 s long where it stood in for part of
//! a compass latency), so held, it leaves the later effect less than its own. Forward stepwise
//! regression scores a term added to a model with the terms already in it re-estimated; a
//! candidate that explained the disagreement on its own the round before is scored that way.

use nalgebra::{DMatrix, DVector};

use super::{
    HELDOUT_MIN_GAIN, Residuals, Setup, beyond_base, held_out_gap_grows, interval_excludes_zero,
    left_out_where_touched, signature,
};
use crate::gap::GapError;
use crate::gap::candidate::{Candidate, Refitted};
use crate::gap::effects::{self, Effect, Kind};
use crate::gap::lsq::{self, Bounds};
use crate::gap::resim;

/// One effect's values and 95 % intervals from a joint refit (no intervals: held as it was).
pub type Refit = (Vec<f64>, Vec<[f64; 2]>);

/// One named effect as the joint fits take it: the library effect, its values and its round's
/// noise factor.
pub type Named = (&'static Effect, Vec<f64>, f64);

/// The accepted candidates as the joint fits take them.
pub fn named(accepted: &[Candidate]) -> Result<Vec<Named>, GapError> {
    accepted
        .iter()
        .map(|c| {
            let effect = effects::by_name(&c.name).ok_or_else(|| {
                GapError::Data(format!("`{}` is not in the effect library", c.name))
            })?;
            Ok((effect, c.values(), c.noise_factor))
        })
        .collect()
}

/// The mean-type effects of a set fitted together on all the data.
struct Joint {
    /// Indices of the set's mean-type effects, and those effects.
    free: Vec<usize>,
    chosen: Vec<&'static Effect>,
    scales: Vec<f64>,
    fit: lsq::Fit,
    /// The chi-square of the set's start values with the last effect at no effect, on the
    /// samples the fit saw.
    without_last: Option<f64>,
    n_eff: f64,
    /// The joint covariance (units of the scales) times each parameter's effect's noise factor
    /// and the fit's own variance factor, plus the between-run spread.
    cov: Option<DMatrix<f64>>,
    /// The 95 % intervals, in the parameters' units.
    ci: Vec<[f64; 2]>,
    /// The set's variance-type effects applied to the setup's base.
    held: effects::Configs,
    /// Where the start's re-simulation touches the pool and the base's does not.
    start_contacts: Option<Vec<[f64; 2]>>,
    /// The set's start values, in units of the scales.
    start: DVector<f64>,
}

/// `x` with its last `k` elements at zero.
fn last_zeroed(x: &DVector<f64>, k: usize) -> DVector<f64> {
    let mut x = x.clone();
    let n = x.len();
    x.rows_mut(n - k, k).fill(0.0);
    x
}

impl Joint {
    /// The residuals (every sample, the start's extra contacts left out) at `x`, in units of
    /// the scales.
    fn residuals_at(&self, setup: &Setup<'_>, x: &DVector<f64>) -> Option<Residuals> {
        let c = effects::apply_joint(&self.held, &self.chosen, x);
        let run = resim::simulate(&c, setup.m, None)
            .ok()
            .filter(|r| r.divergences.is_empty())?;
        let r = setup.residuals(&c, &run);
        Some(left_out_where_touched(&r, self.start_contacts.as_deref()).into_owned())
    }

    /// `x` with the last effect's parameters at no effect.
    fn zeroing_last(&self, x: &DVector<f64>) -> DVector<f64> {
        last_zeroed(x, self.chosen.last().map_or(0, |e| e.parameters.len()))
    }
}

/// Fits the mean-type effects of `set` (each with its start values and its round's
/// `noise_factor`) together against `setup`, whose base holds none of them; the variance-type
/// ones are applied as they are. `part`: the training samples only (`Some(true)`), or all
/// (`None`). `None` when none is mean-type or the fit fails.
fn fit_joint(setup: &Setup<'_>, set: &[Named], part: Option<bool>) -> Option<Joint> {
    let free: Vec<usize> = (0..set.len())
        .filter(|&i| set[i].0.kind == Kind::Mean)
        .collect();
    if free.is_empty() {
        return None;
    }
    let chosen: Vec<&'static Effect> = free.iter().map(|&i| set[i].0).collect();
    let (scales, bounds) = effects::joint_scales_and_bounds(&chosen);
    let mut held = setup.base.clone();
    for (effect, values, _) in set.iter().filter(|a| a.0.kind != Kind::Mean) {
        effects::apply(effect, values, &mut held);
    }
    let run_at = |x: &DVector<f64>| {
        let c = effects::apply_joint(&held, &chosen, x);
        let run = resim::simulate(&c, setup.m, None)
            .ok()
            .filter(|r| r.divergences.is_empty())?;
        Some((c, run))
    };
    let start = DVector::from_iterator(
        scales.len(),
        free.iter()
            .flat_map(|&i| set[i].1.iter().zip(set[i].0.scales).map(|(v, s)| v / s)),
    );
    // Where the start's re-simulation touches the pool and the base's does not, left out of
    // the search as in a candidate's own fit.
    let start_contacts = beyond_base(setup, run_at(&start).map(|(_, run)| run.contacts));
    let objective = |x: &DVector<f64>| -> Option<DVector<f64>> {
        let (c, run) = run_at(x)?;
        let r = setup.residuals(&c, &run);
        let r = left_out_where_touched(&r, start_contacts.as_deref());
        Some(match part {
            Some(_) => r.training_vector(),
            None => DVector::from_column_slice(&r.values),
        })
    };
    let without_last = free
        .last()
        .and_then(|&i| objective(&last_zeroed(&start, set[i].0.parameters.len())))
        .map(|r| r.norm_squared());
    let fit = lsq::minimize(
        &objective,
        &Bounds::scaled(&bounds, &scales),
        std::slice::from_ref(&start),
    )?;
    let n_eff = setup.n_eff(part);
    let variance_factor = (fit.chi2() / (n_eff - scales.len() as f64).max(1.0)).max(1.0);
    // Each parameter's noise factor is its own effect's: the covariance scaled by their
    // square roots on both sides, so each variance carries its own effect's factor.
    let noise: Vec<f64> = free
        .iter()
        .flat_map(|&i| std::iter::repeat_n(set[i].2.max(1.0).sqrt(), set[i].0.parameters.len()))
        .collect();
    let spread: Vec<f64> = free
        .iter()
        .flat_map(|&i| setup.spread_variance(set[i].0))
        .collect();
    let cov = fit.covariance().map(|c| {
        let mut total = DMatrix::from_fn(c.nrows(), c.ncols(), |a, b| {
            c[(a, b)] * noise[a] * noise[b] * variance_factor
        });
        for (j, v) in spread.iter().enumerate() {
            total[(j, j)] += v;
        }
        total
    });
    let ci = lsq::intervals(&fit.x, cov.as_ref(), &scales, 1.0);
    Some(Joint {
        free,
        chosen,
        scales,
        fit,
        without_last,
        n_eff,
        cov,
        ci,
        held,
        start_contacts,
        start,
    })
}

/// The accepted effects refitted together on all the data, from their values when named.
/// Each was fitted with only the effects named before it in the model, so an earlier one has
/// taken part of a later one's disagreement; fitted together, the later rounds fit against
/// what is really left. `accepted` holds each effect with its values and its round's
/// `noise_factor`; variance-type effects (EMI) are applied as they are and not refitted.
/// Returns, per effect in order, the values and their 95 % intervals: the joint covariance
/// times each effect's noise factor and the joint fit's own variance factor, plus the
/// between-run spread. `None` when no mean-type effect is accepted or the joint fit fails (the round values
/// stand). The guards are not taken again at the joint values.
pub fn refit_jointly(setup: &Setup<'_>, accepted: &[Named]) -> Option<Vec<Refit>> {
    let joint = fit_joint(setup, accepted, None)?;
    let mut fitted = effects::joint_values(&joint.chosen, &joint.fit.x).into_iter();
    let mut k = 0;
    Some(
        accepted
            .iter()
            .map(|(effect, values, _)| {
                if effect.kind != Kind::Mean {
                    return (values.clone(), Vec::new());
                }
                let n = effect.parameters.len();
                k += n;
                (
                    fitted.next().unwrap_or_default(),
                    joint.ci[k - n..k].to_vec(),
                )
            })
            .collect(),
    )
}

/// The named effects with `candidate` last, and its library effect: `None` unless it is a
/// mean-type effect and some named effect is too (a joint fit has nothing to free otherwise).
fn with_candidate(named: &[Named], candidate: &Candidate) -> Option<(&'static Effect, Vec<Named>)> {
    let effect = effects::by_name(&candidate.name).filter(|e| e.kind == Kind::Mean)?;
    if named.iter().all(|n| n.0.kind != Kind::Mean) {
        return None;
    }
    let mut set = named.to_vec();
    set.push((effect, candidate.values(), candidate.noise_factor));
    Some((effect, set))
}

/// A later round's candidate fitted with the effects named before it (`named`, as
/// [`refit_jointly`] takes them) free, against `setup`, whose base holds none of them: its
/// values, intervals, delta BIC and the guards those decide (bounds, interval, significance)
/// from the joint fit, scored against the named effects' own fit on the same samples. The
/// held-out and signature guards stay those of its fit with them held. Asked of a candidate
/// that passed every guard the round before; returns whether the candidate was rescored (only
/// where the joint fit explains more than the held one did).
pub fn with_earlier_free(setup: &Setup<'_>, named: &[Named], candidate: &mut Candidate) -> bool {
    let Some((effect, set)) = with_candidate(named, candidate) else {
        return false;
    };
    let Some(joint) = fit_joint(setup, &set, None) else {
        return false;
    };
    let Some(before) = joint.without_last else {
        return false;
    };
    let (k, n) = (effect.parameters.len(), joint.scales.len());
    let x = joint.fit.x.rows(n - k, k).into_owned();
    let values: Vec<f64> = x.iter().zip(effect.scales).map(|(v, s)| v * s).collect();
    let cov = joint
        .cov
        .as_ref()
        .map(|c| c.view((n - k, n - k), (k, k)).into_owned());
    let ci = joint.ci[n - k..].to_vec();
    let gain = before - joint.fit.chi2();
    let variance_factor = (joint.fit.chi2() / (joint.n_eff - n as f64).max(1.0)).max(1.0);
    let scale = candidate.noise_factor * variance_factor;
    let penalty = k as f64 * joint.n_eff.ln();
    let delta_bic = gain / scale - penalty;
    tracing::debug!(
        effect = effect.name,
        delta_bic,
        held = candidate.delta_bic,
        ?values,
        ?ci,
        "a candidate fitted with the earlier names free"
    );
    if delta_bic <= candidate.delta_bic {
        return false;
    }
    let earlier_inside = joint
        .chosen
        .iter()
        .zip(effects::joint_values(&joint.chosen, &joint.fit.x))
        .all(|(e, v)| effects::inside_bounds(e, &v));
    candidate.guards.inside_bounds = earlier_inside && !joint.fit.at_bound;
    candidate.guards.interval_excludes_zero = interval_excludes_zero(&ci, &x, cov.as_ref(), 1.0);
    candidate.guards.significant = delta_bic > super::BIC_MARGIN;
    candidate.delta_bic = delta_bic;
    candidate.delta_bic_uncalibrated = gain - penalty;
    candidate.chi2_before = before;
    candidate.chi2_after = joint.fit.chi2();
    candidate.variance_factor = variance_factor;
    for ((_, v), new) in candidate.parameters.iter_mut().zip(&values) {
        *v = *new;
    }
    for ((_, c), new) in candidate.ci95.iter_mut().zip(&ci) {
        *c = *new;
    }
    let mut k0 = 0;
    candidate.refitted = joint
        .free
        .iter()
        .zip(effects::joint_values(&joint.chosen, &joint.fit.x))
        .take(joint.free.len() - 1)
        .map(|(&i, values)| {
            let e = set[i].0;
            let m = e.parameters.len();
            k0 += m;
            Refitted {
                name: e.name.to_string(),
                values,
                ci95: joint.ci[k0 - m..k0].to_vec(),
            }
        })
        .collect();
    true
}

/// [`with_earlier_free`] for a candidate the earlier names left failing its signature or its
/// held-out blocks too: a sensor effect that passed every guard fitted alone the round before,
/// on a channel an earlier sensor name explains ([`crate::gap::candidate::of_its_kind`]: a
/// depth gain beside a depth offset that took the gain's share with its own). Held, the earlier name keeps what it
/// took, and the candidate's fit against it finds nothing; so its held-out and signature guards
/// are judged again as its own fit's are, on the joint fit: the set, the candidate with it,
/// fitted together on the training blocks, and scored on the held-out blocks against the model
/// as named (a gain beyond [`HELDOUT_MIN_GAIN`] on the candidate's scale, no channel's gap
/// grown), its signature read on the change it makes at those values. Where both pass, it is
/// rescored on all the data as [`with_earlier_free`] does. Returns whether it was.
pub fn judged_with_earlier_free(
    setup: &Setup<'_>,
    named: &[Named],
    candidate: &mut Candidate,
) -> bool {
    let Some((effect, set)) = with_candidate(named, candidate) else {
        return false;
    };
    let Some(train) = fit_joint(setup, &set, Some(true)) else {
        return false;
    };
    let start = train.zeroing_last(&train.start);
    let (Some(as_named), Some(trained), Some(trained_without)) = (
        train.residuals_at(setup, &start),
        train.residuals_at(setup, &train.fit.x),
        train.residuals_at(setup, &train.zeroing_last(&train.fit.x)),
    ) else {
        return false;
    };
    let variance_factor =
        (train.fit.chi2() / (train.n_eff - train.scales.len() as f64).max(1.0)).max(1.0);
    let scale = candidate.noise_factor * variance_factor;
    let (before, after) = (as_named.chi2(false), trained.chi2(false));
    let heldout_gain = (before - after) / scale;
    let heldout =
        heldout_gain > HELDOUT_MIN_GAIN && !held_out_gap_grows(setup, &as_named, &trained);
    let (signature_pass, signature_text) = signature(setup, effect, &trained_without, &trained);
    tracing::debug!(
        effect = effect.name,
        heldout_gain,
        heldout,
        signature = signature_pass,
        "a candidate judged on a joint fit with the earlier names free"
    );
    if !(heldout && signature_pass) {
        return false;
    }
    let mut judged = candidate.clone();
    judged.guards.signature = true;
    judged.guards.heldout = Some(true);
    if !with_earlier_free(setup, named, &mut judged) {
        return false;
    }
    judged.heldout_chi2_before = Some(before);
    judged.heldout_chi2_after = Some(after);
    judged.heldout_gain = Some(heldout_gain);
    judged.signature_pass = true;
    judged.signature = signature_text;
    *candidate = judged;
    true
}

#[cfg(test)]
mod tests;
