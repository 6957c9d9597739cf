//! The structural rival of an effect named after others: a term of the base model's
//! structure (a calibration discrepancy term or a structural rival of the library) that
//! explains the same disagreement.

use super::{BIC_MARGIN, Setup, fit_effects};
use crate::gap::candidate::Candidate;
use crate::gap::effects;

/// The structural term that explains what `win` explains as well (its delta
/// BIC within [`BIC_MARGIN`] of `win`'s, in the likelihood rounds are ranked by) or better,
/// passing every guard, fitted alone against the setup's model; `None` when none does. Only
/// the terms acting on a channel of `win`'s signature are tried
/// ([`effects::structural_rivals`]).
///
/// The earlier names of an analysis can drive the vehicle where the baseline runs never took
/// it (a lag many times the calibrated one, a depth hold that chatters its vertical
/// thrusters on a noisy depth reading), and there the structure the baseline runs left loose
/// can be what is off: a new effect is then a stand-in for it.
pub fn structural_rival(setup: &Setup<'_>, win: &Candidate) -> Option<Candidate> {
    let effect = effects::by_name(&win.name)?;
    let rivals = effects::structural_rivals(effect);
    fit_effects(setup, &rivals, &mut |_| {})
        .into_iter()
        .find(|r| {
            r.testable
                && r.guards.all()
                && r.delta_bic_uncalibrated > win.delta_bic_uncalibrated - BIC_MARGIN
        })
}
