//! The one least-squares engine of `gap`: bounded Levenberg-Marquardt (the
//! `levenberg-marquardt` crate) over parameters in units of a typical size, one
//! finite-difference Jacobian, one covariance and interval computation.
//!
//! Bounds are kept by projection: every trial point is clamped into the box before its
//! residuals are computed, and a finite difference at a bound steps inwards. A fit that ends
//! on a bound has found the edge of the physical range, not a minimum; callers see that in
//! [`Fit::at_bound`].

use std::cell::Cell;

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector, Dyn, Owned};

/// Finite-difference step, in units of a parameter's typical size.
pub const JACOBIAN_STEP: f64 = 0.02;

/// What a fit gave.
#[derive(Debug)]
pub struct Fit {
    /// Parameters at the optimum, in units of their typical sizes.
    pub x: DVector<f64>,
    /// Residuals there.
    pub residuals: DVector<f64>,
    /// Jacobian there (residuals per unit of `x`); `None` if an evaluation failed.
    pub jacobian: Option<DMatrix<f64>>,
    /// Residual evaluations used (the Jacobian's included).
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

    /// `(J^T J)^-1`: the covariance of `x` for unit-variance residuals.
    pub fn covariance(&self) -> Option<DMatrix<f64>> {
        let j = self.jacobian.as_ref()?;
        (j.transpose() * j).try_inverse()
    }
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

    fn clamp(&self, x: &DVector<f64>) -> DVector<f64> {
        DVector::from_iterator(
            x.len(),
            x.iter()
                .enumerate()
                .map(|(i, v)| v.clamp(self.lower[i], self.upper[i])),
        )
    }

    fn on_bound(&self, x: &DVector<f64>) -> bool {
        x.iter().enumerate().any(|(i, v)| {
            let margin = 1e-6 * (self.upper[i] - self.lower[i]);
            *v <= self.lower[i] + margin || *v >= self.upper[i] - margin
        })
    }
}

struct Problem<'a, F> {
    residuals_of: &'a F,
    bounds: &'a Bounds,
    x: DVector<f64>,
    r: Option<DVector<f64>>,
    evaluations: &'a Cell<usize>,
}

impl<F> Problem<'_, F>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>>,
{
    fn eval(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
        self.evaluations.set(self.evaluations.get() + 1);
        (self.residuals_of)(x)
    }
}

impl<F> LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_, F>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>>,
{
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x = self.bounds.clamp(x);
        self.r = self.eval(&self.x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        self.r.clone()
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        jacobian(
            self.residuals_of,
            self.bounds,
            &self.x,
            self.r.as_ref()?,
            self.evaluations,
        )
    }
}

fn jacobian<F>(
    residuals_of: &F,
    bounds: &Bounds,
    x: &DVector<f64>,
    r0: &DVector<f64>,
    evaluations: &Cell<usize>,
) -> Option<DMatrix<f64>>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>>,
{
    let mut j = DMatrix::zeros(r0.len(), x.len());
    for k in 0..x.len() {
        let mut xk = x.clone();
        // Step inwards at the upper bound.
        let h = if x[k] + JACOBIAN_STEP > bounds.upper[k] {
            -JACOBIAN_STEP
        } else {
            JACOBIAN_STEP
        };
        xk[k] += h;
        evaluations.set(evaluations.get() + 1);
        let r = residuals_of(&xk)?;
        if r.len() != r0.len() {
            return None;
        }
        j.set_column(k, &((r - r0) / h));
    }
    Some(j)
}

/// The forward-difference Jacobian at `x` (stepping inwards at an upper bound).
pub fn jacobian_at<F>(residuals_of: &F, bounds: &Bounds, x: &DVector<f64>) -> Option<DMatrix<f64>>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>>,
{
    let r0 = residuals_of(x)?;
    jacobian(residuals_of, bounds, x, &r0, &Cell::new(0))
}

/// Minimises `|residuals_of(x)|^2` over `x` inside `bounds`, from the best of `starts` (each
/// a full parameter vector; the first is also the reference a failed scan falls back to).
/// `None` when no start could be evaluated.
pub fn minimize<F>(residuals_of: &F, bounds: &Bounds, starts: &[DVector<f64>]) -> Option<Fit>
where
    F: Fn(&DVector<f64>) -> Option<DVector<f64>>,
{
    let evaluations = Cell::new(0);
    let mut best: Option<(f64, DVector<f64>)> = None;
    for s in starts {
        let s = bounds.clamp(s);
        evaluations.set(evaluations.get() + 1);
        if let Some(r) = residuals_of(&s) {
            let c = r.norm_squared();
            if best.as_ref().is_none_or(|(b, _)| c < *b) {
                best = Some((c, s));
            }
        }
    }
    let (_, start) = best?;
    let mut problem = Problem {
        residuals_of,
        bounds,
        x: start.clone(),
        r: None,
        evaluations: &evaluations,
    };
    problem.set_params(&start);
    let (problem, report) = LevenbergMarquardt::new()
        .with_patience(40)
        .with_stepbound(5.0)
        .minimize(problem);
    let x = problem.x.clone();
    let residuals = problem.r.clone()?;
    let jacobian = jacobian(residuals_of, bounds, &x, &residuals, &evaluations);
    Some(Fit {
        at_bound: bounds.on_bound(&x),
        x,
        residuals,
        jacobian,
        evaluations: evaluations.get(),
        termination: report.termination,
    })
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
}
