//! The constancy test of an effect named after others: fitted apart where the earlier names
//! changed the fit most and where they changed it least, does it keep one value?

use nalgebra::DVector;

use super::{Residuals, Setup};
use crate::gap::effects::Effect;
use crate::gap::lsq::{self, Bounds};
use crate::gap::resim::Floor;

/// The constancy test of an effect named after others: its values fitted separately where
/// the earlier names changed the model's fit most and where they changed it least.
#[derive(Debug, Clone)]
pub struct Constancy {
    /// Values where the earlier names act strongly, then where they act weakly.
    pub strong: Vec<f64>,
    pub weak: Vec<f64>,
    /// The Wald statistic of their difference, and its 99 % point (chi-square, one degree
    /// of freedom per parameter).
    pub statistic: f64,
    pub critical: f64,
}

impl Constancy {
    pub fn holds(&self) -> bool {
        self.statistic <= self.critical
    }
}

/// Level of the constancy test.
pub const CONSTANCY_LEVEL: f64 = 0.99;

/// Per element of `after`, whether it lies in a time block (of `block_s`) where the effects
/// named so far changed the chi-square most: blocks at or above the median change. `before`
/// and `after` are the same samples' normalised residuals without and with those effects.
pub fn strong_blocks(before: &Residuals, after: &Residuals, block_s: f64) -> Vec<bool> {
    let block = |t: f64| (t / block_s).floor().max(0.0) as usize;
    let blocks = after.times.iter().map(|t| block(*t) + 1).max().unwrap_or(0);
    let mut change = vec![0.0; blocks];
    for ((t, a), b) in after.times.iter().zip(&after.values).zip(&before.values) {
        change[block(*t)] += b * b - a * a;
    }
    let mut sorted: Vec<f64> = change.iter().map(|c| c.abs()).collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    after
        .times
        .iter()
        .map(|t| change[block(*t)].abs() >= median)
        .collect()
}

/// Per element of `r`, whether it lies in a time block (of `block_s`) where a named noise
/// source acts: where, at some sample of the block, a channel's white measurement noise in the
/// floors `now` (with the source) is wider than in `base` (without it). Where it is the same
/// everywhere in a block, the source adds nothing there, and what a later name fits in those
/// blocks is free of it: a depth EMI that follows the stern duty acts while the depth hold
/// works and not while the motors are off. `r`'s elements of a channel are its samples in
/// order, as [`Setup::residuals`] makes them.
pub fn noise_source_blocks(
    r: &Residuals,
    base: &[Option<Floor>],
    now: &[Option<Floor>],
    block_s: f64,
) -> Vec<bool> {
    let block = |t: f64| (t / block_s).floor().max(0.0) as usize;
    let blocks = r.times.iter().map(|t| block(*t) + 1).max().unwrap_or(0);
    let mut acts = vec![false; blocks];
    let mut sample = vec![0usize; base.len().max(now.len())];
    for (t, &owner) in r.times.iter().zip(&r.owner) {
        let Some(k) = sample.get_mut(owner) else {
            continue;
        };
        let std_of = |floors: &[Option<Floor>]| {
            floors
                .get(owner)
                .and_then(Option::as_ref)
                .and_then(|f| f.measurement_std.get(*k).copied())
        };
        if let (Some(without), Some(with)) = (std_of(base), std_of(now))
            && with > without * (1.0 + 1e-9)
        {
            acts[block(*t)] = true;
        }
        *k += 1;
    }
    r.times.iter().map(|t| acts[block(*t)]).collect()
}

/// Fits `effect` on the elements of `mask` only, from `start` (its values): the values in
/// units of the effect's scales and their covariance, inflated as a candidate's is (its
/// `noise_factor`, the fit's own residual variance, the between-run spread).
fn fit_masked(
    setup: &Setup<'_>,
    effect: &'static Effect,
    mask: &[bool],
    start: &[f64],
    noise_factor: f64,
) -> Option<(DVector<f64>, nalgebra::DMatrix<f64>)> {
    let scales = effect.scales;
    let to_params =
        |x: &DVector<f64>| -> Vec<f64> { x.iter().zip(scales).map(|(v, s)| v * s).collect() };
    let objective = |x: &DVector<f64>| -> Option<DVector<f64>> {
        let r = setup.eval(effect, &to_params(x))?;
        Some(DVector::from_iterator(
            mask.iter().filter(|m| **m).count(),
            r.values
                .iter()
                .zip(mask)
                .filter(|(_, m)| **m)
                .map(|(v, _)| *v),
        ))
    };
    let x0 = DVector::from_iterator(start.len(), start.iter().zip(scales).map(|(v, s)| v / s));
    let fit = lsq::minimize(&objective, &Bounds::scaled(effect.bounds, scales), &[x0])?;
    let r = setup.eval(effect, &to_params(&fit.x))?;
    let n_eff: f64 = r
        .owner
        .iter()
        .zip(mask)
        .filter(|(_, m)| **m)
        .filter_map(|(o, _)| setup.floors[*o].as_ref().map(|f| 1.0 / f.tau))
        .sum();
    let k = start.len() as f64;
    let variance_factor = (fit.residuals.norm_squared() / (n_eff - k).max(1.0)).max(1.0);
    let mut cov = fit.covariance()? * (noise_factor * variance_factor);
    for (j, v) in setup.spread_variance(effect).iter().enumerate() {
        cov[(j, j)] += v;
    }
    Some((fit.x, cov))
}

/// The constancy test of `effect` (values `values`, fitted against `setup`'s base, which
/// holds the effects named before it) over the elements of `strong` and the others. `None`
/// when either half cannot be fitted.
pub fn constancy(
    setup: &Setup<'_>,
    effect: &'static Effect,
    values: &[f64],
    noise_factor: f64,
    strong: &[bool],
) -> Option<Constancy> {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    // With every element on one side there is nothing to compare.
    if strong.iter().all(|s| *s) || !strong.iter().any(|s| *s) {
        return None;
    }
    let weak: Vec<bool> = strong.iter().map(|s| !s).collect();
    let (xs, cs) = fit_masked(setup, effect, strong, values, noise_factor)?;
    let (xw, cw) = fit_masked(setup, effect, &weak, values, noise_factor)?;
    let d = &xs - &xw;
    let statistic = (d.transpose() * (cs + cw).try_inverse()? * &d)[(0, 0)];
    if !statistic.is_finite() {
        return None;
    }
    let critical = ChiSquared::new(values.len() as f64)
        .ok()?
        .inverse_cdf(CONSTANCY_LEVEL);
    let unscale = |x: &DVector<f64>| -> Vec<f64> {
        x.iter().zip(effect.scales).map(|(v, s)| v * s).collect()
    };
    Some(Constancy {
        strong: unscale(&xs),
        weak: unscale(&xw),
        statistic,
        critical,
    })
}
