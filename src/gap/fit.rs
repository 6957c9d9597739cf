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

/// What fitting one candidate gave.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateResult {
    pub name: String,
    /// (parameter, fitted change relative to the model).
    pub parameters: Vec<(String, f64)>,
    pub ci95: Vec<(String, [f64; 2])>,
    pub chi2_before: f64,
    pub chi2_after: f64,
    pub delta_bic: f64,
    pub signature_pass: bool,
    pub signature: String,
    /// False when the data hold none of the channels the effect shows in.
    pub testable: bool,
    /// Re-simulations the fit needed (an estimate for the Jacobian's share).
    pub evaluations: usize,
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

    /// Normalised residuals of all modelled channels for configs `c` and run `run`, with the
    /// channel index of each element.
    pub fn residual_vector(&self, c: &Configs, run: &Run) -> (Vec<f64>, Vec<usize>) {
        let mut out = Vec::new();
        let mut owner = Vec::new();
        for i in self.modelled() {
            let ch = &self.m.channels[i];
            let Some(f) = &self.floors[i] else { continue };
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

fn chi2(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Fits one mean-type candidate.
fn fit_mean(
    setup: &Setup<'_>,
    effect: &'static Effect,
    r0: &[f64],
    owner0: &[usize],
) -> CandidateResult {
    let k = effect.parameters.len();
    let mut problem = Problem {
        setup,
        effect,
        x: DVector::zeros(k),
        r: None,
        evaluations: 0,
    };
    problem.set_params(&DVector::zeros(k));
    let (problem, _report) = LevenbergMarquardt::new()
        .with_patience(12)
        .with_stepbound(5.0)
        .minimize(problem);
    let evaluations = problem.evaluations + 2 * k * 12;
    let chi2_before = chi2(r0);
    let Some(r1) = problem.r.clone() else {
        return failed(effect, chi2_before, "the fit left the model's valid range");
    };
    let chi2_after = chi2(r1.as_slice());
    let params = problem.params(&problem.x);
    // Covariance from the Jacobian at the solution (residuals are already normalised).
    let ci = problem
        .jacobian()
        .and_then(|j| (j.transpose() * &j).try_inverse())
        .map(|cov| {
            (0..k)
                .map(|i| {
                    let sd = cov[(i, i)].max(0.0).sqrt() * effect.scales[i];
                    [params[i] - 1.96 * sd, params[i] + 1.96 * sd]
                })
                .collect::<Vec<_>>()
        })
        .unwrap_or_else(|| vec![[f64::NEG_INFINITY, f64::INFINITY]; k]);
    let n_eff = setup.n_eff();
    let delta_bic = chi2_before - chi2_after - k as f64 * n_eff.ln();
    // Signature: does the change the effect makes line up with the residual where the
    // signature says it should, and does the improvement come from there?
    let in_sig = |i: usize| effect.channels.contains(&setup.m.channels[i].name.as_str());
    let (mut dot, mut dd, mut rr, mut gain_sig, mut gain_all) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (idx, (&a, &b)) in r0.iter().zip(r1.iter()).enumerate() {
        let g = a * a - b * b;
        gain_all += g;
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
    CandidateResult {
        name: effect.name.to_string(),
        parameters: names(effect).zip(params.iter().copied()).collect(),
        ci95: names(effect).zip(ci).collect(),
        chi2_before,
        chi2_after,
        delta_bic,
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
        signature_pass: false,
        signature: why.to_string(),
        testable: false,
        evaluations: 0,
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
    let mut bins: Vec<Vec<usize>> = vec![Vec::new(); 5];
    for (k, u) in duty.iter().enumerate() {
        bins[((u * 5.0) as usize).min(4)].push(k);
    }
    bins.retain(|b| b.len() >= 5);
    let data = EmiData {
        r2: r.iter().map(|v| v * v).collect(),
        base_var: floor.sigma.iter().map(|s| s * s).collect(),
        gain: duty.iter().map(|u| (u * att / lsb).powi(2)).collect(),
        emi0: d.emi_v_rms_full_duty,
        tau: floor.tau,
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
    let n_eff = setup.n_eff();
    let delta_bic = before - after - n_eff.ln();
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
        signature_pass: e > 0.0 && corr >= SIGNATURE_MIN_CORRELATION,
        signature: format!(
            "{}: correlation of squared depth residuals with stern duty^2 = {corr:.2} (>= {SIGNATURE_MIN_CORRELATION})",
            effect.signature
        ),
        testable: true,
        evaluations: 0, // a variance fit needs no re-simulation
    })
}

/// Fits every candidate not yet in the model; `progress` is called before each.
pub fn fit_candidates(
    setup: &Setup<'_>,
    skip: &[&str],
    progress: &mut dyn FnMut(&str),
) -> Vec<CandidateResult> {
    let (r0, owner0) = setup.residual_vector(&setup.base, &setup.clean);
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
            Kind::Mean => fit_mean(setup, effect, &r0, &owner0),
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
    out.sort_by(|a, b| b.delta_bic.total_cmp(&a.delta_bic));
    out
}

/// The winner of a round, if one beats "no effect" by the margin and passes its signature.
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
