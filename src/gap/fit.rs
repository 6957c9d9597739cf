//! Naming the missing effect: fit every candidate with Levenberg-Marquardt, score it with the
//! BIC, test its residual signature, rank, and accept the best one only when it beats "no
//! effect" by [`BIC_MARGIN`]; repeat greedily.
//!
//! Residuals are normalised by the model's noise floor and by the square root of the
//! channel's autocorrelation time (`tau`), so `sum r^2` is a chi-square in independent
//! samples and `n_eff = sum n_c / tau_c` is the sample size in the BIC:
//! `delta_BIC = chi2(no effect) - chi2(effect) - k ln(n_eff)` (positive favours the effect).

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use serde::Serialize;

use crate::gap::GapError;
use crate::gap::effects::{self, Configs, Effect, Kind};
use crate::gap::format::Measurement;
use crate::gap::resim::{self, Floor, Run};
use crate::physics::state::STERN;
use crate::sensors::AdcBoard;

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

/// Starting points scanned along each parameter axis, in units of the effect's scale. The
/// +-0.25 steps: a thrust gain of -0.05 (a quarter of its scale) was fitted at -0.008 from
/// zero, a shallow minimum that the coarser steps all scored worse than (docs/gap.md,
/// "Benchmark notes (session 3)").
pub const START_SCAN: [f64; 9] = [-4.0, -2.0, -1.0, -0.25, 0.25, 1.0, 2.0, 4.0, 8.0];

/// What fitting one candidate gave.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateResult {
    pub name: String,
    /// (parameter, fitted change relative to the model).
    pub parameters: Vec<(String, f64)>,
    pub ci95: Vec<(String, [f64; 2])>,
    pub chi2_before: f64,
    pub chi2_after: f64,
    /// BIC gain over "no effect" with the chi-square gain divided by `noise_factor`: what
    /// the significance margin is applied to.
    pub delta_bic: f64,
    /// BIC gain without that calibration (the likelihood itself): what candidates that pass
    /// are ranked by, since all are fitted to the same data.
    pub delta_bic_uncalibrated: f64,
    pub signature_pass: bool,
    pub signature: String,
    /// False when the data hold none of the channels the effect shows in.
    pub testable: bool,
    /// Re-simulations the fit needed (an estimate for the Jacobian's share).
    pub evaluations: usize,
    /// How much more chi-square a fit of this effect gains on the model's own noise than
    /// independent noise would (>= 1); the gain in `delta_bic` is divided by it.
    pub noise_factor: f64,
}

/// The re-simulation context one greedy round fits against.
pub struct Setup<'a> {
    pub m: &'a Measurement,
    pub base: Configs,
    pub clean: Run,
    pub floors: &'a [Option<Floor>],
}

impl Setup<'_> {
    /// Channels (indices into `m.channels`) that are both modelled and have a floor.
    pub fn modelled(&self) -> Vec<usize> {
        (0..self.m.channels.len())
            .filter(|&i| self.floors[i].is_some())
            .collect()
    }

    /// Independent sample count.
    pub fn n_eff(&self) -> f64 {
        self.modelled()
            .iter()
            .filter_map(|&i| {
                self.floors[i]
                    .as_ref()
                    .map(|f| f.sigma.len() as f64 / f.tau)
            })
            .sum::<f64>()
            .max(1.0)
    }

    /// The model's own null residuals, normalised as [`Setup::residual_vector`]: one vector
    /// per ensemble run (process noise only), and the per-element variance the white
    /// measurement noise adds.
    pub fn null_vectors(&self) -> (Vec<Vec<f64>>, Vec<f64>) {
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
            let k = f.tau.sqrt();
            for (m, v) in null.iter_mut().enumerate() {
                v.extend(f.null[m].iter().zip(&f.sigma).map(|(d, s)| d / (s * k)));
            }
            white.extend(
                f.measurement_std
                    .iter()
                    .zip(&f.sigma)
                    .map(|(m, s)| (m / (s * k)).powi(2)),
            );
        }
        (null, white)
    }

    /// Normalised residuals of all modelled channels for configs `c` and run `run`, with the
    /// channel index of each element.
    pub fn residual_vector(&self, c: &Configs, run: &Run) -> (Vec<f64>, Vec<usize>) {
        let mut out = Vec::new();
        let mut owner = Vec::new();
        for i in self.modelled() {
            let ch = &self.m.channels[i];
            let Some(f) = &self.floors[i] else { continue };
            // Sonar: presence deviance and range residuals, already normalised.
            if let Some(r) = crate::gap::sonar::residuals(c, run, self.m.experiment.duration_s, ch)
            {
                owner.extend(std::iter::repeat_n(i, r.len()));
                out.extend(r);
                continue;
            }
            let Some(p) = resim::predict(c, run, ch, 0.0) else {
                continue;
            };
            let k = f.tau.sqrt();
            for (r, s) in resim::residuals(ch, &p).iter().zip(&f.sigma) {
                out.push(r / (s * k));
                owner.push(i);
            }
        }
        (out, owner)
    }

    fn eval(&self, effect: &Effect, params: &[f64]) -> Option<(Vec<f64>, Vec<usize>)> {
        let mut c = self.base.clone();
        effects::apply(effect, params, &mut c);
        if effect.physics {
            let run = resim::simulate(&c, self.m, None).ok()?;
            Some(self.residual_vector(&c, &run))
        } else {
            Some(self.residual_vector(&c, &self.clean))
        }
    }
}

struct Problem<'a, 'b> {
    setup: &'a Setup<'b>,
    effect: &'static Effect,
    /// Parameters in units of the effect's scales.
    x: DVector<f64>,
    r: Option<DVector<f64>>,
    evaluations: usize,
}

impl Problem<'_, '_> {
    fn params(&self, x: &DVector<f64>) -> Vec<f64> {
        x.iter()
            .zip(self.effect.scales)
            .map(|(v, s)| v * s)
            .collect()
    }

    fn residuals_at(&mut self, x: &DVector<f64>) -> Option<DVector<f64>> {
        self.evaluations += 1;
        let p = self.params(x);
        self.setup
            .eval(self.effect, &p)
            .map(|(r, _)| DVector::from_vec(r))
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_, '_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
        let x = self.x.clone();
        self.r = self.residuals_at(&x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        self.r.clone()
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let r0 = self.r.as_ref()?;
        let n = self.x.len();
        let mut j = DMatrix::zeros(r0.len(), n);
        // Forward differences of 2 % of a typical size; `jacobian` takes &self, so count
        // evaluations on a copy.
        let mut me = Problem {
            setup: self.setup,
            effect: self.effect,
            x: self.x.clone(),
            r: None,
            evaluations: 0,
        };
        for k in 0..n {
            let mut x = self.x.clone();
            let h = 0.02;
            x[k] += h;
            let r = me.residuals_at(&x)?;
            if r.len() != r0.len() {
                return None;
            }
            j.set_column(k, &((r - r0) / h));
        }
        Some(j)
    }
}

/// The mean chi-square gain of a linearised fit along Jacobian `j` (covariance `ainv`) on
/// the null residuals, over its expectation `k` for independent noise; at least 1.
fn null_factor(j: &DMatrix<f64>, ainv: &DMatrix<f64>, null: &[Vec<f64>], white: &[f64]) -> f64 {
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

fn chi2(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Fits one mean-type candidate.
fn fit_mean(
    setup: &Setup<'_>,
    effect: &'static Effect,
    r0: &[f64],
    owner0: &[usize],
    null: &[Vec<f64>],
    white: &[f64],
) -> CandidateResult {
    let k = effect.parameters.len();
    let mut problem = Problem {
        setup,
        effect,
        x: DVector::zeros(k),
        r: None,
        evaluations: 0,
    };
    // Start from the best of a coarse scan along each parameter axis: the chi-square of a
    // dynamic effect (a lag) can hold a shallow local minimum between zero and the truth.
    let mut start = DVector::zeros(k);
    let mut best = chi2(r0);
    for i in 0..k {
        for step in START_SCAN {
            let mut x = DVector::zeros(k);
            x[i] = step;
            if let Some(r) = problem.residuals_at(&x) {
                let c = chi2(r.as_slice());
                if c < best {
                    best = c;
                    start = x;
                }
            }
        }
    }
    problem.set_params(&start);
    let (problem, report) = LevenbergMarquardt::new()
        .with_patience(40)
        .with_stepbound(5.0)
        .minimize(problem);
    tracing::debug!(
        effect = effect.name,
        termination = ?report.termination,
        evaluations = report.number_of_evaluations,
        objective = report.objective_function,
        "fit finished"
    );
    let evaluations = problem.evaluations + report.number_of_evaluations * k;
    let chi2_before = chi2(r0);
    let Some(r1) = problem.r.clone() else {
        return failed(effect, chi2_before, "the fit left the model's valid range");
    };
    let chi2_after = chi2(r1.as_slice());
    let params = problem.params(&problem.x);
    let n_eff = setup.n_eff();
    let jac = problem.jacobian();
    let ainv = jac.as_ref().and_then(|j| (j.transpose() * j).try_inverse());
    // Null calibration: how much chi-square a fit of this effect gains on the model's own
    // noise (the ensemble's process-noise residuals plus the white measurement noise),
    // projected on the effect's Jacobian. Properly independent noise gains k on average;
    // correlated noise along the effect's signature gains more, and the factor scales the
    // gain down by as much (never up).
    let at_fit = match (&jac, &ainv) {
        (Some(j), Some(ai)) => null_factor(j, ai, null, white),
        _ => 1.0,
    };
    // Along a nonlinear parameter (a lag) the fit travels from the model as shipped through
    // directions where the process noise is large and can end where the Jacobian has turned
    // away from them; calibrated at the end point alone, the gain the noise gave on the way
    // is under-counted and nulls are named (docs/gap.md, "Null false alarms"). So the factor
    // is the larger of the two ends of the path: the fitted point and the start (no change).
    let at_start = {
        let mut p0 = Problem {
            setup,
            effect,
            x: DVector::zeros(k),
            r: None,
            evaluations: 0,
        };
        p0.set_params(&DVector::zeros(k));
        p0.jacobian().and_then(|j0| {
            (j0.transpose() * &j0)
                .try_inverse()
                .map(|a0| null_factor(&j0, &a0, null, white))
        })
    };
    let noise_factor = at_start.map_or(at_fit, |f| f.max(at_fit));
    // Residual variance beyond what the floor expects (reduced chi-square), never below 1.
    let reduced = (chi2_after / (n_eff - k as f64).max(1.0)).max(1.0);
    let ci = ainv
        .as_ref()
        .map(|cov| {
            (0..k)
                .map(|i| {
                    let sd =
                        (cov[(i, i)].max(0.0) * noise_factor * reduced).sqrt() * effect.scales[i];
                    [params[i] - 1.96 * sd, params[i] + 1.96 * sd]
                })
                .collect::<Vec<_>>()
        })
        .unwrap_or_else(|| vec![[f64::NEG_INFINITY, f64::INFINITY]; k]);
    let delta_bic = (chi2_before - chi2_after) / noise_factor - k as f64 * n_eff.ln();
    let delta_bic_uncalibrated = chi2_before - chi2_after - k as f64 * n_eff.ln();
    // Signature: does the change the effect makes line up with the residual where the
    // signature says it should, and does the improvement come from there?
    let in_sig = |i: usize| effect.channels.contains(&setup.m.channels[i].name.as_str());
    let (mut dot, mut dd, mut rr, mut gain_sig, mut gain_all) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut gain_by_channel = vec![0.0; setup.m.channels.len()];
    for (idx, (&a, &b)) in r0.iter().zip(r1.iter()).enumerate() {
        let g = a * a - b * b;
        gain_all += g;
        if let Some(v) = gain_by_channel.get_mut(owner0[idx]) {
            *v += g;
        }
        if in_sig(owner0[idx]) {
            gain_sig += g;
            let d = a - b; // = predicted change of the effect, normalised
            dot += d * a;
            dd += d * d;
            rr += a * a;
        }
    }
    let corr = if dd > 0.0 && rr > 0.0 {
        dot / (dd * rr).sqrt()
    } else {
        0.0
    };
    let share = if gain_all > 0.0 {
        gain_sig / gain_all
    } else {
        0.0
    };
    let signature_pass = corr >= SIGNATURE_MIN_CORRELATION && share >= SIGNATURE_MIN_SHARE;
    tracing::debug!(
        effect = effect.name,
        correlation = corr,
        share,
        signature_pass,
        gains = %setup
            .m
            .channels
            .iter()
            .zip(&gain_by_channel)
            .filter(|(_, g)| **g != 0.0)
            .map(|(c, g)| format!("{}={g:.1}", c.name))
            .collect::<Vec<_>>()
            .join(" "),
        "signature test"
    );
    CandidateResult {
        name: effect.name.to_string(),
        parameters: names(effect).zip(params.iter().copied()).collect(),
        ci95: names(effect).zip(ci).collect(),
        chi2_before,
        chi2_after,
        delta_bic,
        delta_bic_uncalibrated,
        signature_pass,
        signature: format!(
            "{}: correlation with the residual in {} = {corr:.2} (>= {SIGNATURE_MIN_CORRELATION}), \
             share of the improvement there = {:.0} % (>= {:.0} %)",
            effect.signature,
            effect.channels.join("/"),
            share * 100.0,
            SIGNATURE_MIN_SHARE * 100.0
        ),
        testable: true,
        evaluations,
        noise_factor,
    }
}

fn names(effect: &Effect) -> impl Iterator<Item = String> + '_ {
    effect.parameters.iter().map(|p| p.to_string())
}

fn failed(effect: &Effect, chi2_before: f64, why: &str) -> CandidateResult {
    CandidateResult {
        name: effect.name.to_string(),
        parameters: names(effect).map(|n| (n, 0.0)).collect(),
        ci95: names(effect).map(|n| (n, [0.0, 0.0])).collect(),
        chi2_before,
        chi2_after: chi2_before,
        delta_bic: f64::NEG_INFINITY,
        delta_bic_uncalibrated: f64::NEG_INFINITY,
        signature_pass: false,
        signature: why.to_string(),
        testable: false,
        evaluations: 0,
        noise_factor: 1.0,
    }
}

/// The depth channel's per-sample variance for an extra EMI amplitude `e` (V rms at full
/// stern duty).
struct EmiData {
    r2: Vec<f64>,
    base_var: Vec<f64>,
    /// Per-sample (duty * attenuation / lsb)^2.
    gain: Vec<f64>,
    emi0: f64,
    tau: f64,
    bins: Vec<Vec<usize>>,
}

impl EmiData {
    fn var(&self, i: usize, e: f64) -> f64 {
        let emi = (self.emi0 + e).max(0.0);
        (self.base_var[i] + (emi * emi - self.emi0 * self.emi0) * self.gain[i]).max(1e-12)
    }

    fn minus2_log_l(&self, e: f64) -> f64 {
        (0..self.r2.len())
            .map(|i| {
                let v = self.var(i, e);
                self.r2[i] / v + v.ln()
            })
            .sum::<f64>()
            / self.tau
    }
}

struct EmiProblem<'a> {
    d: &'a EmiData,
    x: DVector<f64>,
    scale: f64,
}

impl EmiProblem<'_> {
    fn res(&self, e: f64) -> DVector<f64> {
        DVector::from_iterator(
            self.d.bins.len(),
            self.d.bins.iter().map(|b| {
                let n = b.len().max(1) as f64;
                let s2 = b.iter().map(|&i| self.d.r2[i]).sum::<f64>() / n;
                let v = b.iter().map(|&i| self.d.var(i, e)).sum::<f64>() / n;
                (s2 - v) / (v * (2.0 * self.d.tau / n).sqrt())
            }),
        )
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for EmiProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;
    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }
    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        Some(self.res(self.x[0] * self.scale))
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let h = 1e-3;
        let a = self.res(self.x[0] * self.scale);
        let b = self.res((self.x[0] + h) * self.scale);
        Some(DMatrix::from_column_slice(
            a.len(),
            1,
            ((b - a) / h).as_slice(),
        ))
    }
}

/// Fits the variance-type candidate (depth EMI) on the depth channel.
fn fit_emi(setup: &Setup<'_>, effect: &'static Effect) -> Option<CandidateResult> {
    let i = setup
        .m
        .channels
        .iter()
        .position(|c| c.name == "depth_adc")?;
    let floor = setup.floors[i].as_ref()?;
    let ch = &setup.m.channels[i];
    let p = resim::predict(&setup.base, &setup.clean, ch, 0.0)?;
    let r = resim::residuals(ch, &p);
    let d = &setup.base.sensors.depth;
    let lsb = AdcBoard::new(&setup.base.sensors.adc, 0).lsb_v();
    let att = d.low_pass_cutoff_hz.map_or(1.0, |fc| {
        (std::f64::consts::FRAC_PI_2 * fc / d.emi_bandwidth_hz).sqrt()
    });
    let duty: Vec<f64> = ch
        .samples
        .iter()
        .map(|(t, _)| setup.clean.at(*t).thruster_effort[STERN].abs().min(1.0))
        .collect();
    let g: Vec<f64> = duty.iter().map(|u| (u * att / lsb).powi(2)).collect();
    let w: Vec<f64> = floor.measurement_std.iter().map(|s| s * s).collect();
    // Successive differences: a mean error that varies slowly (a missing dynamic effect, the
    // process noise) cancels, the white sensor noise and EMI add up. So the fit sees only
    // the spread, and a mean-type effect cannot pose as EMI.
    let idx: Vec<usize> = (1..r.len()).collect();
    let mut bins: Vec<Vec<usize>> = vec![Vec::new(); 5];
    for (k, &i) in idx.iter().enumerate() {
        bins[((duty[i].max(duty[i - 1]) * 5.0) as usize).min(4)].push(k);
    }
    bins.retain(|b| b.len() >= 5);
    let data = EmiData {
        r2: idx.iter().map(|&i| (r[i] - r[i - 1]).powi(2)).collect(),
        base_var: idx.iter().map(|&i| w[i] + w[i - 1]).collect(),
        gain: idx.iter().map(|&i| g[i] + g[i - 1]).collect(),
        emi0: d.emi_v_rms_full_duty,
        tau: 1.0,
        bins,
    };
    let scale = effect.scales[0];
    let problem = EmiProblem {
        d: &data,
        x: DVector::zeros(1),
        scale,
    };
    let (problem, _) = LevenbergMarquardt::new().minimize(problem);
    let e = problem.x[0] * scale;
    let j = problem.jacobian()?;
    let sd = (j.transpose() * &j)
        .try_inverse()
        .map_or(f64::INFINITY, |c| c[(0, 0)].max(0.0).sqrt() * scale);
    let before = data.minus2_log_l(0.0);
    let after = data.minus2_log_l(e);
    // One parameter; the sample size is that of the differences the likelihood uses.
    let delta_bic = before - after - (data.r2.len().max(2) as f64).ln();
    // Signature: squared residuals grow with the stern duty.
    let r2: Vec<f64> = data.r2.clone();
    let g: Vec<f64> = data.gain.clone();
    let corr = {
        let n = r2.len() as f64;
        let (ma, mb) = (r2.iter().sum::<f64>() / n, g.iter().sum::<f64>() / n);
        let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
        for k in 0..r2.len() {
            ab += (r2[k] - ma) * (g[k] - mb);
            aa += (r2[k] - ma).powi(2);
            bb += (g[k] - mb).powi(2);
        }
        if aa > 0.0 && bb > 0.0 {
            ab / (aa * bb).sqrt()
        } else {
            0.0
        }
    };
    Some(CandidateResult {
        name: effect.name.to_string(),
        parameters: vec![(effect.parameters[0].to_string(), e)],
        ci95: vec![(
            effect.parameters[0].to_string(),
            [e - 1.96 * sd, e + 1.96 * sd],
        )],
        chi2_before: before,
        chi2_after: after,
        delta_bic,
        delta_bic_uncalibrated: delta_bic,
        signature_pass: e > 0.0 && corr >= SIGNATURE_MIN_CORRELATION,
        signature: format!(
            "{}: correlation of squared depth residuals with stern duty^2 = {corr:.2} (>= {SIGNATURE_MIN_CORRELATION})",
            effect.signature
        ),
        testable: true,
        evaluations: 0, // a variance fit needs no re-simulation
        noise_factor: 1.0,
    })
}

/// Fits every candidate not yet in the model; `progress` is called before each.
pub fn fit_candidates(
    setup: &Setup<'_>,
    skip: &[&str],
    progress: &mut dyn FnMut(&str),
) -> Vec<CandidateResult> {
    let (r0, owner0) = setup.residual_vector(&setup.base, &setup.clean);
    let (null, white) = setup.null_vectors();
    let measured: Vec<&str> = setup
        .modelled()
        .iter()
        .map(|&i| setup.m.channels[i].name.as_str())
        .collect();
    let mut out = Vec::new();
    for effect in &effects::LIBRARY {
        progress(effect.name);
        if skip.contains(&effect.name) {
            continue;
        }
        if !effect.channels.iter().any(|c| measured.contains(c)) {
            out.push(failed(
                effect,
                chi2(&r0),
                &format!(
                    "not testable: none of its channels ({}) is measured and modelled",
                    effect.channels.join(", ")
                ),
            ));
            continue;
        }
        let result = match effect.kind {
            Kind::Mean => fit_mean(setup, effect, &r0, &owner0, &null, &white),
            Kind::Variance => {
                fit_emi(setup, effect).unwrap_or_else(|| failed(effect, chi2(&r0), "no depth data"))
            }
        };
        tracing::debug!(
            effect = effect.name,
            delta_bic = result.delta_bic,
            "candidate fitted"
        );
        out.push(result);
    }
    out.sort_by(|a, b| {
        b.delta_bic_uncalibrated
            .total_cmp(&a.delta_bic_uncalibrated)
    });
    out
}

/// The winner of a round: the best-ranked candidate (by the likelihood, see
/// [`CandidateResult::delta_bic_uncalibrated`]) that beats "no effect" by the margin after
/// the noise calibration and passes its signature test.
pub fn winner(results: &[CandidateResult]) -> Option<&CandidateResult> {
    results
        .iter()
        .find(|r| r.testable && r.delta_bic > BIC_MARGIN && r.signature_pass)
}

/// Builds a setup for the given configs.
pub fn setup<'a>(
    m: &'a Measurement,
    base: Configs,
    floors: &'a [Option<Floor>],
) -> Result<Setup<'a>, GapError> {
    let clean = resim::simulate(&base, m, None)?;
    Ok(Setup {
        m,
        base,
        clean,
        floors,
    })
}
