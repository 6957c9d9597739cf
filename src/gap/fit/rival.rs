//! The structural rival of an effect named after others: a term of the base model's
//! structure (a calibration discrepancy term or a structural rival of the library) that
//! explains the same disagreement.

use super::{BIC_MARGIN, Residuals, Setup, fit_effects};
use crate::gap::candidate::{
    Candidate, change_cosine_where_changed, change_projection_where_changed,
};
use crate::gap::effects;

/// A structural rival must take out of the winner's own signature channels at least this
/// share of the chi-square the winner takes out of them: most of it, so that it explains the
/// same disagreement, not another one beside it.
pub const RIVAL_MIN_SHARE: f64 = 0.5;

/// The structural term that explains what `win` explains, fitted alone against the setup's
/// model and passing every guard; `None` when none does. It explains as much overall (its
/// delta BIC within [`BIC_MARGIN`] of `win`'s, in the likelihood rounds are ranked by, or
/// above it), and it explains the same: of the chi-square `win` takes out of its own
/// signature channels, it takes out at least [`RIVAL_MIN_SHARE`], and either more than `win`
/// does there or by the same pattern: its change of the residuals carries at least that share
/// of `win`'s (projected on `win`'s change, on the readings `win` changes).
///
/// A term that gains only elsewhere is no rival of a winner whose disagreement it leaves (a
/// thruster spin-down that makes the compass fit worse, of a compass offset), nor is one that
/// gains less in the same channels by another pattern (a reverse thrust curve that mends the
/// spot turns' headings carries 0.06 of a compass offset's constant angle). A term that
/// explains a larger disagreement there, of which the winner's is a part, is a rival whatever
/// the angle between the two (a lag's shape carries 0.83 of a stand-in surge added mass at a
/// cosine of 0.29). Only the terms acting on a channel of `win`'s signature are tried
/// ([`effects::structural_rivals`]).
///
/// The earlier names of an analysis can drive the vehicle where the baseline runs never took
/// it (a lag many times the calibrated one, a depth hold that chatters its vertical
/// thrusters on a noisy depth reading), and there the structure the baseline runs left loose
/// can be what is off: a new effect is then a stand-in for it.
pub fn structural_rival(setup: &Setup<'_>, win: &Candidate) -> Option<Candidate> {
    let effect = effects::by_name(&win.name)?;
    let in_own = |r: &Residuals| own_channels_chi2(setup, r, effect.channels);
    let before = in_own(&setup.residuals(&setup.base, &setup.clean));
    let takes_out = |c: &Candidate| -> Option<f64> {
        let e = effects::by_name(&c.name)?;
        Some(before - in_own(&setup.eval(e, &c.values())?))
    };
    let win_takes = takes_out(win)?;
    let rivals = effects::structural_rivals(effect);
    fit_effects(setup, &rivals, &mut |_| {})
        .into_iter()
        .find(|r| {
            let carries = change_projection_where_changed(r, win);
            tracing::debug!(
                winner = win.name,
                win_takes,
                rival = r.name,
                rival_takes = takes_out(r),
                rival_delta_bic = r.delta_bic_uncalibrated,
                winner_delta_bic = win.delta_bic_uncalibrated,
                carries,
                cosine = change_cosine_where_changed(r, win),
                "a structural rival"
            );
            r.testable
                && r.guards.all()
                && r.delta_bic_uncalibrated > win.delta_bic_uncalibrated - BIC_MARGIN
                && takes_out(r).is_some_and(|t| {
                    t >= RIVAL_MIN_SHARE * win_takes
                        && (t >= win_takes || carries.is_some_and(|p| p >= RIVAL_MIN_SHARE))
                })
        })
}

/// The chi-square of `r` in the channels named.
fn own_channels_chi2(setup: &Setup<'_>, r: &Residuals, channels: &[&str]) -> f64 {
    r.values
        .iter()
        .zip(&r.owner)
        .filter(|(_, o)| {
            setup
                .m
                .channels
                .get(**o)
                .is_some_and(|c| channels.contains(&c.name.as_str()))
        })
        .map(|(v, _)| v * v)
        .sum()
}
