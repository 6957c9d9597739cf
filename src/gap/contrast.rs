//! Where two look-alike effects differ: the channels, regimes and time windows in which their
//! fits change the residuals unlike each other.
//!
//! A round that ends `ambiguous` says the data do not tell two effects apart. What tells them
//! apart is where their predictions differ: a depth offset and a depth gain differ only where
//! the depth read changes, a yaw damping and a sway-yaw coupling only where turn and speed come
//! together. The run's share of samples there against that place's share of the difference says
//! what a run that tells them apart must do more of.

use serde::Serialize;

use super::candidate::Candidate;
use super::fit::Residuals;
use super::format::Measurement;
use super::residuals::{WINDOW_S, regime_of};
use super::run::Run;

/// A regime is listed when it holds at least this share of the squared difference between the
/// two fits' changes (percent).
pub const REGIME_MIN_SHARE_PCT: f64 = 10.0;

/// A regime is listed when it holds at least this many times its share of the samples of
/// the difference: half as much again.
pub const REGIME_MIN_ENRICHMENT: f64 = 1.5;

/// A depth changing faster than this (m/s) is a dive or an ascent, slower it is held.
pub const DEPTH_CHANGING_MPS: f64 = 0.05;

/// Where two effects' changes of the residuals differ.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Contrast {
    /// The two effects, the round's winner first.
    pub pair: [String; 2],
    /// Each channel with its share of the squared difference (percent), largest first; those
    /// under a tenth of a percent left out.
    pub channels: Vec<(String, f64)>,
    /// The regimes that hold [`REGIME_MIN_ENRICHMENT`] times more of the difference than of the
    /// samples or more, by how many times more, each with its share of the difference and of
    /// the samples (percent); those under [`REGIME_MIN_SHARE_PCT`] of the difference left out.
    pub regimes: Vec<RegimeShare>,
    /// The [`WINDOW_S`] windows that hold the most of the difference, up to three: start,
    /// end (s) and share (percent).
    pub windows: Vec<(f64, f64, f64)>,
}

/// A regime's share of two effects' difference against its share of the samples.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RegimeShare {
    pub regime: String,
    pub difference_pct: f64,
    pub samples_pct: f64,
}

/// Where `a` and `b`, two candidates of one round, change the residuals unlike each other:
/// `layout` is that round's residuals (their owners and times: the changes' order), `run` a
/// re-simulation the regimes are read from. `None` when either has no change (a variance
/// effect), the changes do not match the layout, or they do not differ.
pub fn between(
    a: &Candidate,
    b: &Candidate,
    layout: &Residuals,
    m: &Measurement,
    run: &Run,
) -> Option<Contrast> {
    let n = layout.values.len();
    if a.change.len() != n || b.change.len() != n || n == 0 {
        return None;
    }
    let d2: Vec<f64> = a
        .change
        .iter()
        .zip(&b.change)
        .map(|(x, y)| (x - y).powi(2))
        .collect();
    let total: f64 = d2.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let pct = |x: f64| 100.0 * x / total;
    let mut channels: Vec<(String, f64)> = Vec::new();
    for (i, d) in layout.owner.iter().zip(&d2) {
        let name = m.channels.get(*i).map_or("?", |c| c.name.as_str());
        match channels.iter_mut().find(|(c, _)| c == name) {
            Some((_, s)) => *s += d,
            None => channels.push((name.to_string(), *d)),
        }
    }
    let mut channels: Vec<(String, f64)> = channels
        .into_iter()
        .map(|(c, s)| (c, pct(s)))
        .filter(|(_, s)| *s >= 0.1)
        .collect();
    channels.sort_by(|x, y| y.1.total_cmp(&x.1));
    let depths = depth_range(run);
    let mut regimes: Vec<(String, f64, usize)> = Vec::new();
    for (t, d) in layout.times.iter().zip(&d2) {
        for r in regimes_at(run, *t, depths) {
            match regimes.iter_mut().find(|(g, _, _)| *g == r) {
                Some((_, s, k)) => {
                    *s += d;
                    *k += 1;
                }
                None => regimes.push((r, *d, 1)),
            }
        }
    }
    let mut regimes: Vec<RegimeShare> = regimes
        .into_iter()
        .map(|(regime, s, k)| RegimeShare {
            regime,
            difference_pct: pct(s),
            samples_pct: 100.0 * k as f64 / n as f64,
        })
        .filter(|r| {
            r.difference_pct >= REGIME_MIN_SHARE_PCT
                && r.difference_pct >= REGIME_MIN_ENRICHMENT * r.samples_pct
        })
        .collect();
    regimes.sort_by(|x, y| {
        (y.difference_pct / y.samples_pct).total_cmp(&(x.difference_pct / x.samples_pct))
    });
    let mut windows: Vec<(f64, f64, f64)> = Vec::new();
    for (t, d) in layout.times.iter().zip(&d2) {
        let w0 = (t / WINDOW_S).floor() * WINDOW_S;
        match windows.iter_mut().find(|w| w.0 == w0) {
            Some(w) => w.2 += d,
            None => windows.push((w0, w0 + WINDOW_S, *d)),
        }
    }
    windows.sort_by(|x, y| y.2.total_cmp(&x.2));
    windows.truncate(3);
    for w in &mut windows {
        w.2 = pct(w.2);
    }
    Some(Contrast {
        pair: [a.name.clone(), b.name.clone()],
        channels,
        regimes,
        windows,
    })
}

/// The shallowest and deepest depth of the centre of mass over the run (m).
fn depth_range(run: &Run) -> (f64, f64) {
    run.states
        .iter()
        .map(|s| s.position_m.z)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
            (lo.min(z), hi.max(z))
        })
}

/// The regimes of the sample at `t`: those the residual statistics read
/// ([`crate::gap::residuals`]), whether the depth changes or is held, and the half of the
/// run's depths it lies in (`depths`: the shallowest and deepest).
fn regimes_at(run: &Run, t: f64, (lo, hi): (f64, f64)) -> Vec<String> {
    let s = run.at(t);
    let sink = (s.attitude * s.velocity_body_mps).z;
    let mut out: Vec<String> = regime_of(run, t).into();
    out.push(
        if sink.abs() > DEPTH_CHANGING_MPS {
            "depth changing"
        } else {
            "depth held"
        }
        .to_string(),
    );
    if hi - lo > 0.1 {
        let mid = 0.5 * (lo + hi);
        out.push(if s.position_m.z < mid {
            format!("CG depth {lo:.2}-{mid:.2} m")
        } else {
            format!("CG depth {mid:.2}-{hi:.2} m")
        });
    }
    out
}

/// The contrast in words, for the report: "`a` and `b` differ most in ...".
pub fn text(c: &Contrast) -> String {
    let channels: Vec<String> = c
        .channels
        .iter()
        .take(3)
        .map(|(ch, s)| format!("{ch} ({s:.0} %)"))
        .collect();
    let regimes: Vec<String> = c
        .regimes
        .iter()
        .take(3)
        .map(|r| {
            format!(
                "{} ({:.0} % of the difference in {:.0} % of the samples)",
                r.regime, r.difference_pct, r.samples_pct
            )
        })
        .collect();
    let windows: Vec<String> = c
        .windows
        .iter()
        .map(|(a, b, s)| format!("{a:.0}-{b:.0} s ({s:.0} %)"))
        .collect();
    let mut out = format!(
        "`{}` and `{}` predict the run differently mostly in {}",
        c.pair[0],
        c.pair[1],
        channels.join(", ")
    );
    if !regimes.is_empty() {
        out.push_str(&format!(", in {}", regimes.join(", ")));
    }
    if !windows.is_empty() {
        out.push_str(&format!("; windows {}", windows.join(", ")));
    }
    out.push_str(
        ". There the data can tell the two apart: a run with more of those regimes, or with \
         them at other values, separates them better",
    );
    out
}

#[cfg(test)]
mod tests;
