//! The one least-squares engine of `gap`: bounded Levenberg-Marquardt (the
//! `levenberg-marquardt` crate) over parameters in units of a typical size, one
//! finite-difference Jacobian, one covariance and interval computation.
//!
//! Bounds are kept by projection: every trial point is clamped into the box before its
//! residuals are computed, and a finite difference at a bound steps inwards. A fit that ends
//! on a bound has found the edge of the physical range, not a minimum; callers see that in
//! [`Fit::at_bound`].

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector, Dyn, Owned};

/// Finite-difference step, in units of a parameter's typical size.
pub const JACOBIAN_STEP: f64 = 0.02;

/// A search ends when [`STALLED_STEPS`] accepted steps in a row each lower the chi-square by
/// less than this. The callers' residuals are scaled so the chi-square counts independent
/// samples (the time-series fit's are in units of their noise floor; calibration's sum to
/// each channel's chi-square per independent sample), and a change of a twentieth is below
/// what noise moves it by. The relative test of
/// the engine alone does not fire while a parameter presses on its bound (the linear model
/// keeps predicting the reduction the bound forbids) or the search zig-zags down a narrow
/// valley: calibration crawled on for thousands of re-simulations at a few thousandths of
/// chi-square per step.
pub const CHI2_TOLERANCE: f64 = 0.05;

/// See [`CHI2_TOLERANCE`].
pub const STALLED_STEPS: usize = 3;

/// What a fit gave.
#[derive(Debug)]
pub struct Fit {
    /// Parameters at the optimum, in units of their typical sizes.
    pub x: DVector<f64>,
    /// Residuals there.
    pub residuals: DVector<f64>,
    /// Jacobian there (residuals per unit of `x`); `None` if an evaluation failed.
    pub jacobian: Option<DMatrix<f64>>,
    /// Residual evaluations used (the Jacobian's included), each point once.
    pub evaluations: usize,
    /// True when some parameter ended on its bound.
    pub at_bound: bool,
    pub termination: TerminationReason,
}

impl Fit {
    /// Sum of squared residuals.
    pub fn chi2(&self) -> f64 {
        self.residuals.norm_squared()
    }

    /// `(J^T J)^-1`: the covariance of `x` for unit-variance residuals. See [`covariance`].
    pub fn covariance(&self) -> Option<DMatrix<f64>> {
        covariance(self.jacobian.as_ref()?)
    }
}

/// `(J^T J)^-1` over the parameters the data move. A parameter whose Jacobian column is zero
/// (scaling a term the model does not have, an observation that does not depend on it) gets
/// an infinite variance and no covariance with the others, so it does not spoil their
/// intervals; `None` when the moved parameters are themselves degenerate.
pub fn covariance(j: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = j.ncols();
    let live: Vec<usize> = (0..n)
        .filter(|&c| j.column(c).iter().any(|v| *v != 0.0))
        .collect();
    if live.len() == n {
        return (j.transpose() * j).try_inverse();
    }
    let mut out = DMatrix::zeros(n, n);
    for i in 0..n {
        if !live.contains(&i) {
            out[(i, i)] = f64::INFINITY;
        }
    }
    if !live.is_empty() {
        let jl = j.select_columns(&live);
        let inv = (jl.transpose() * &jl).try_inverse()?;
        for (a, &i) in live.iter().enumerate() {
            for (b, &k) in live.iter().enumerate() {
                out[(i, k)] = inv[(a, b)];
            }
        }
    }
    Some(out)
}

/// The 95 % interval of each parameter (in the parameters' own units: `x * scale`) from a
/// covariance in units of the scales, inflated by `variance_factor` (>= 1: residual variance
/// beyond the noise floor, correlated noise). An unusable covariance gives infinite intervals.
pub fn intervals(
    x: &DVector<f64>,
    covariance: Option<&DMatrix<f64>>,
    scales: &[f64],
    variance_factor: f64,
) -> Vec<[f64; 2]> {
    (0..x.len())
        .map(|i| {
            let centre = x[i] * scales[i];
            match covariance.map(|c| c[(i, i)]) {
                Some(v) if v.is_finite() && v >= 0.0 => {
                    let sd = (v * variance_factor).sqrt() * scales[i];
                    [centre - 1.96 * sd, centre + 1.96 * sd]
                }
                _ => [f64::NEG_INFINITY, f64::INFINITY],
            }
        })
        .collect()
}

/// A box in units of the typical sizes.
#[derive(Debug, Clone)]
pub struct Bounds {
    pub lower: Vec<f64>,
    pub upper: Vec<f64>,
}

impl Bounds {
    /// Bounds in the parameters' own units, scaled.
    pub fn scaled(bounds: &[(f64, f64)], scales: &[f64]) -> Self {
        Self {
            lower: bounds.iter().zip(scales).map(|((l, _), s)| l / s).collect(),
            upper: bounds.iter().zip(scales).map(|((_, h), s)| h / s).collect(),
        }
    }

    /// `x` projected into the box.
    pub fn clamp(&self, x: &DVector<f64>) -> DVector<f64> {
        DVector::from_iterator(
            x.len(),
            x.iter()
                .enumerate()
                .map(|(i, v)| v.clamp(self.lower[i], self.upper[i])),
        )
    }

    fn on_bound(&self, x: &DVector<f64>) -> bool {
        (0..x.len()).any(|i| self.on_bound_at(x, i))
    }

    fn on_bound_at(&self, x: &DVector<f64>, i: usize) -> bool {
        let margin = 1e-6 * (self.upper[i] - self.lower[i]);
        x[i] <= self.lower[i] + margin || x[i] >= self.upper[i] - margin
    }
}

/// A point and its residuals (`None`: not evaluable there).
type Point = (DVector<f64>, Option<DVector<f64>>);

/// `residuals_of` with every point it was asked kept, with its residuals (`None`: not
/// evaluable there), and looked up when asked again. A search asks for points again: the
/// engine restores the last accepted point after a refused step, a step the box clamps can
/// land where the last one did, and the Jacobian at a point a search ended on is asked again
/// by the search over the coordinates left free and for the fit's intervals. `residuals_of`
/// is a function of `x` alone (a deterministic re-simulation), so the kept residuals are the
/// ones asking again would give, to the bit; points are matched bit for bit (`0.0` and
/// `-0.0` differ).
struct Kept<'f, F> {
    residuals_of: &'f F,
    seen: Mutex<Vec<Point>>,
    evaluated: AtomicUsize,
}

impl<'f, F> Kept<'f, F>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>> + Sync,
{
    fn new(residuals_of: &'f F) -> Self {
        Self {
            residuals_of,
            seen: Mutex::new(Vec::new()),
            evaluated: AtomicUsize::new(0),
        }
    }

    fn at(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
        let same = |p: &DVector<f64>| {
            p.len() == x.len() && p.iter().zip(x).all(|(a, b)| a.to_bits() == b.to_bits())
        };
        if let Some(found) = self
            .seen
            .lock()
            .ok()
            .and_then(|seen| seen.iter().find(|(p, _)| same(p)).map(|(_, r)| r.clone()))
        {
            return found;
        }
        self.evaluated.fetch_add(1, Ordering::Relaxed);
        let r = (self.residuals_of)(x);
        if let Ok(mut seen) = self.seen.lock() {
            seen.push((x.clone(), r.clone()));
        }
        r
    }
}

struct Problem<'a, F> {
    residuals_of: &'a F,
    bounds: &'a Bounds,
    x: DVector<f64>,
    r: Option<DVector<f64>>,
    /// The best point evaluated: (chi-square, x, residuals).
    best: (f64, DVector<f64>, DVector<f64>),
    /// Accepted steps in a row that gained less than [`CHI2_TOLERANCE`].
    stalled: usize,
}

impl<F> LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_, F>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>> + Sync,
{
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x = self.bounds.clamp(x);
        self.r = (self.residuals_of)(&self.x);
        if let Some(r) = &self.r {
            let c = r.norm_squared();
            tracing::trace!(
                chi2 = c,
                x = ?self.x.as_slice(),
                "trial point"
            );
            if c < self.best.0 {
                if self.best.0 - c < CHI2_TOLERANCE {
                    self.stalled += 1;
                } else {
                    self.stalled = 0;
                }
                self.best = (c, self.x.clone(), r.clone());
            }
        }
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        // A stalled search ends as one whose trial point cannot be evaluated: with the best
        // point evaluated, which is the last.
        if self.stalled >= STALLED_STEPS {
            return None;
        }
        self.r.clone()
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        jacobian(self.residuals_of, self.bounds, &self.x, self.r.as_ref()?)
    }
}

/// The forward-difference Jacobian, its columns computed in parallel (each column is its own
/// re-simulation; the result does not depend on the order).
fn jacobian<F>(
    residuals_of: &F,
    bounds: &Bounds,
    x: &DVector<f64>,
    r0: &DVector<f64>,
) -> Option<DMatrix<f64>>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>> + Sync,
{
    use rayon::prelude::*;
    let columns: Vec<DVector<f64>> = (0..x.len())
        .into_par_iter()
        .map(|k| column(residuals_of, bounds, x, r0, k))
        .collect::<Option<_>>()?;
    let mut j = DMatrix::zeros(r0.len(), x.len());
    for (k, col) in columns.into_iter().enumerate() {
        j.set_column(k, &col);
    }
    Some(j)
}

/// Column `k` of the forward-difference Jacobian (stepping inwards at an upper bound).
fn column<F>(
    residuals_of: &F,
    bounds: &Bounds,
    x: &DVector<f64>,
    r0: &DVector<f64>,
    k: usize,
) -> Option<DVector<f64>>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>>,
{
    let mut xk = x.clone();
    let h = if x[k] + JACOBIAN_STEP > bounds.upper[k] {
        -JACOBIAN_STEP
    } else {
        JACOBIAN_STEP
    };
    xk[k] += h;
    let r = residuals_of(&xk)?;
    if r.len() != r0.len() {
        return None;
    }
    let mut col = (r - r0) / h;
    // Where the step changes nothing (a parameter at the edge of the range where the model
    // responds, e.g. a reverse ratio that cannot exceed 1), the other side.
    if col.iter().all(|v| *v == 0.0) && x[k] - h >= bounds.lower[k] && x[k] - h <= bounds.upper[k] {
        let mut xb = x.clone();
        xb[k] -= h;
        if let Some(rb) = residuals_of(&xb).filter(|rb| rb.len() == r0.len()) {
            col = (r0 - rb) / h;
        }
    }
    Some(col)
}

/// The forward-difference Jacobian at `x` (stepping inwards at an upper bound); `at_x`, the
/// residuals there when the caller has them, saves their evaluation.
pub fn jacobian_at<F>(
    residuals_of: &F,
    bounds: &Bounds,
    x: &DVector<f64>,
    at_x: Option<DVector<f64>>,
) -> Option<DMatrix<f64>>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>> + Sync,
{
    let r0 = match at_x {
        Some(r) => r,
        None => residuals_of(x)?,
    };
    jacobian(residuals_of, bounds, x, &r0)
}

/// Minimises `|residuals_of(x)|^2` over `x` inside `bounds`, from the best of `starts` (each
/// a full parameter vector; the first is also the reference a failed scan falls back to).
/// `None` when no start could be evaluated.
///
/// Bounds are active constraints, not only a clamp: a parameter the search drives onto its
/// bound is held there and the search goes on over the others (an active set). Projection
/// alone stalls there: every Gauss-Newton step keeps pointing out of the box, is clamped,
/// falls short of its predicted reduction, and the trust region shrinks until the search
/// ends with the free parameters barely moved.
pub fn minimize<F>(residuals_of: &F, bounds: &Bounds, starts: &[DVector<f64>]) -> Option<Fit>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>> + Sync,
{
    let kept = Kept::new(residuals_of);
    let residuals_of = &|x: &DVector<f64>| kept.at(x);
    let mut best: Option<(f64, DVector<f64>, DVector<f64>)> = None;
    for s in starts {
        let s = bounds.clamp(s);
        if let Some(r) = residuals_of(&s) {
            let c = r.norm_squared();
            if best.as_ref().is_none_or(|(b, _, _)| c < *b) {
                best = Some((c, s, r));
            }
        }
    }
    let (_, mut x, mut residuals) = best?;
    tracing::trace!(chi2 = residuals.norm_squared(), "start");
    let dims = x.len();
    let mut held = vec![false; dims];
    let mut termination = TerminationReason::Converged {
        ftol: true,
        xtol: true,
    };
    loop {
        let free: Vec<usize> = (0..dims).filter(|&i| !held[i]).collect();
        if free.is_empty() {
            break;
        }
        let round = search(residuals_of, bounds, &x, &residuals, &free);
        (x, residuals, termination) = round;
        let reached: Vec<usize> = free
            .into_iter()
            .filter(|&i| bounds.on_bound_at(&x, i))
            .collect();
        if reached.is_empty() {
            break;
        }
        tracing::trace!(held = ?reached, "parameters on their bounds held there");
        for i in reached {
            held[i] = true;
        }
    }
    let jacobian = jacobian(residuals_of, bounds, &x, &residuals);
    Some(Fit {
        at_bound: bounds.on_bound(&x),
        x,
        residuals,
        jacobian,
        evaluations: kept.evaluated.load(Ordering::Relaxed),
        termination,
    })
}

/// One Levenberg-Marquardt search over the `free` coordinates of `x` (the others held),
/// from `x` with its residuals `r`: the best point it evaluated, its residuals, and why it
/// ended.
fn search<F>(
    residuals_of: &F,
    bounds: &Bounds,
    x: &DVector<f64>,
    r: &DVector<f64>,
    free: &[usize],
) -> (DVector<f64>, DVector<f64>, TerminationReason)
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>> + Sync,
{
    let embed = |sub: &DVector<f64>| {
        let mut full = x.clone();
        for (k, &i) in free.iter().enumerate() {
            full[i] = sub[k];
        }
        full
    };
    let sub_residuals = |sub: &DVector<f64>| residuals_of(&embed(sub));
    let sub_bounds = Bounds {
        lower: free.iter().map(|&i| bounds.lower[i]).collect(),
        upper: free.iter().map(|&i| bounds.upper[i]).collect(),
    };
    let start = DVector::from_iterator(free.len(), free.iter().map(|&i| x[i]));
    let problem = Problem {
        residuals_of: &sub_residuals,
        bounds: &sub_bounds,
        x: start.clone(),
        r: Some(r.clone()),
        best: (r.norm_squared(), start, r.clone()),
        stalled: 0,
    };
    let (problem, report) = LevenbergMarquardt::new()
        .with_patience(40)
        .with_stepbound(5.0)
        .minimize(problem);
    // A trial point the model cannot evaluate (a quantity undefined there) ends the search;
    // the fit is then the best point evaluated, never an undefined one.
    let (sub, residuals) = match problem.r.clone() {
        Some(r) if r.norm_squared() <= problem.best.0 => (problem.x.clone(), r),
        _ => (problem.best.1.clone(), problem.best.2.clone()),
    };
    (embed(&sub), residuals, report.termination)
}

/// Starting points: the origin and a scan along each axis at `steps` (units of the scales).
pub fn axis_scan(dims: usize, steps: &[f64]) -> Vec<DVector<f64>> {
    let mut out = vec![DVector::zeros(dims)];
    for i in 0..dims {
        for s in steps {
            let mut x = DVector::zeros(dims);
            x[i] = *s;
            out.push(x);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bounded fit of a line stops at the bound, says so, and an unbounded one finds the
    /// slope with the textbook interval.
    #[test]
    fn fits_a_line_inside_and_at_its_bounds() {
        let t: Vec<f64> = (0..50).map(|k| f64::from(k) * 0.1).collect();
        let noise = [0.1, -0.2, 0.15, -0.05, 0.0];
        let y: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(i, t)| 2.0 * t + noise[i % noise.len()])
            .collect();
        let f = |x: &DVector<f64>| {
            Some(DVector::from_iterator(
                t.len(),
                t.iter().zip(&y).map(|(t, y)| y - x[0] * t),
            ))
        };
        let free = Bounds {
            lower: vec![-10.0],
            upper: vec![10.0],
        };
        let fit = minimize(&f, &free, &axis_scan(1, &[1.0])).expect("fit");
        assert!((fit.x[0] - 2.0).abs() < 0.02, "slope {}", fit.x[0]);
        assert!(!fit.at_bound);
        let ci = intervals(&fit.x, fit.covariance().as_ref(), &[1.0], 1.0);
        let sum_t2: f64 = t.iter().map(|t| t * t).sum();
        let half = 1.96 / sum_t2.sqrt();
        assert!(((ci[0][1] - ci[0][0]) / 2.0 - half).abs() < 1e-6);

        let capped = Bounds {
            lower: vec![-1.0],
            upper: vec![1.5],
        };
        let fit = minimize(&f, &capped, &axis_scan(1, &[1.0])).expect("fit");
        assert!((fit.x[0] - 1.5).abs() < 1e-9, "slope {}", fit.x[0]);
        assert!(fit.at_bound);
    }

    /// A parameter driven onto its bound is held there and the search goes on over the
    /// others: with the first parameter capped at 1, the second reaches its constrained
    /// optimum 14 instead of stalling near the unconstrained one, 2.
    #[test]
    fn a_parameter_on_its_bound_does_not_stall_the_others() {
        let f = |x: &DVector<f64>| {
            Some(DVector::from_vec(vec![
                10.0 * (x[0] - 5.0),
                (x[1] - 2.0) + 3.0 * (x[0] - 5.0),
            ]))
        };
        let bounds = Bounds {
            lower: vec![-10.0, -20.0],
            upper: vec![1.0, 20.0],
        };
        let fit = minimize(&f, &bounds, &[DVector::zeros(2)]).expect("fit");
        assert!((fit.x[0] - 1.0).abs() < 1e-9, "x0 {}", fit.x[0]);
        assert!((fit.x[1] - 14.0).abs() < 1e-3, "x1 {}", fit.x[1]);
        assert!(fit.at_bound);
    }

    /// A parameter the residuals do not depend on gets an infinite interval; the one they do
    /// depend on keeps its textbook interval.
    #[test]
    fn a_parameter_the_data_do_not_move_does_not_spoil_the_others() {
        let t: Vec<f64> = (1..=20).map(f64::from).collect();
        let f = |x: &DVector<f64>| {
            Some(DVector::from_iterator(
                t.len(),
                t.iter().map(|t| 3.0 * t - x[0] * t),
            ))
        };
        let bounds = Bounds {
            lower: vec![-10.0, -10.0],
            upper: vec![10.0, 10.0],
        };
        let fit = minimize(&f, &bounds, &[DVector::zeros(2)]).expect("fit");
        let ci = intervals(&fit.x, fit.covariance().as_ref(), &[1.0, 1.0], 1.0);
        assert!(ci[0][0].is_finite() && ci[0][1].is_finite(), "{ci:?}");
        assert!(ci[0][0] < 3.0 && ci[0][1] > 3.0, "{ci:?}");
        assert!(ci[1][0].is_infinite() && ci[1][1].is_infinite(), "{ci:?}");
    }

    /// No point is evaluated twice, though the engine asks for some again (the last accepted
    /// point after a refused step, the Jacobian at a point on a bound in the next round over
    /// the free coordinates and for the intervals), and what the kept points give is what
    /// evaluating again gives: a curved valley with a bound across it, from several starts.
    #[test]
    fn no_point_is_evaluated_twice() {
        use std::sync::Mutex;
        let asked: Mutex<Vec<Vec<u64>>> = Mutex::new(Vec::new());
        let f = |x: &DVector<f64>| {
            if let Ok(mut a) = asked.lock() {
                a.push(x.iter().map(|v| v.to_bits()).collect());
            }
            Some(DVector::from_vec(vec![
                10.0 * (x[1] - x[0] * x[0]),
                1.0 - x[0],
                0.3 * (x[0] * x[1] - 0.5).sin(),
            ]))
        };
        let bounds = Bounds {
            lower: vec![-2.0, -1.0],
            upper: vec![0.8, 3.0],
        };
        for start in [[-1.2, 1.0], [0.0, 0.0], [0.7, -0.9], [-2.0, 3.0]] {
            asked.lock().unwrap().clear();
            let fit = minimize(&f, &bounds, &[DVector::from_row_slice(&start)]).expect("fit");
            let points = asked.lock().unwrap().clone();
            let mut distinct = points.clone();
            distinct.sort();
            distinct.dedup();
            assert_eq!(distinct.len(), points.len(), "from {start:?}: {points:?}");
            assert_eq!(fit.evaluations, points.len(), "from {start:?}");
            let again = jacobian_at(&f, &bounds, &fit.x, Some(fit.residuals.clone()));
            assert_eq!(fit.jacobian, again, "from {start:?}");
        }
    }

    /// A model that cannot be evaluated beyond some point (a quantity undefined there) ends
    /// the search at the best point it could evaluate, not with no fit.
    #[test]
    fn an_undefined_trial_point_keeps_the_best_evaluated_fit() {
        let f = |x: &DVector<f64>| {
            (x[0] <= 2.0).then(|| DVector::from_vec(vec![x[0] - 3.0, 0.5 * (x[0] - 3.0)]))
        };
        let bounds = Bounds {
            lower: vec![-10.0],
            upper: vec![10.0],
        };
        let fit = minimize(&f, &bounds, &[DVector::zeros(1)]).expect("a fit");
        assert!(fit.x[0] <= 2.0, "x {}", fit.x[0]);
        assert!(
            fit.chi2() <= 1.25 * 9.0,
            "chi2 {} above the start's",
            fit.chi2()
        );
    }
}
