//! The structural rival of an effect named after others: a term of the base model's
//! structure (a calibration discrepancy term or a structural rival of the library) that
//! explains the same disagreement.

use super::{BIC_MARGIN, Residuals, Setup, fit_effects};
use crate::gap::candidate::{
    self, Candidate, change_cosine_where_changed, change_projection_where_changed,
};
use crate::gap::effects;
use crate::gap::later;
use crate::gap::resim;

/// A structural rival must take out of the winner's own signature channels at least this
/// share of the chi-square the winner takes out of them: most of it, so that it explains the
/// same disagreement, not another one beside it.
pub const RIVAL_MIN_SHARE: f64 = 0.5;

/// A rival whose change of the residuals has at least this cosine with the winner's makes
/// most of the same change (the squared cosine, the share of the winner's change along the
/// rival's, is at least a half): what the winner adds beside it is then more of the pattern
/// the structural term's form does not quite reach, not a disagreement of its own.
pub const RIVAL_SAME_PATTERN_COSINE: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// The structural term that explains what `win` explains, fitted alone against the setup's
/// model and passing every guard; `None` when none does. It explains as much overall
/// ([`explains_as_much`]: `win`'s lead over it on the significance scale under
/// [`BIC_MARGIN`]), and it explains the same: of the chi-square `win` takes out of its own
/// signature channels, it takes out at least [`RIVAL_MIN_SHARE`]. A term that gains only
/// elsewhere is no rival of a winner whose disagreement it leaves (a thruster spin-down that
/// makes the compass fit worse, of a compass offset). Only the terms acting on a channel of
/// `win`'s signature are tried ([`effects::structural_rivals`]). A twin of `win`'s form
/// ([`effects::FORM_TWINS`]) must explain more than `win` by the margin on that scale: the
/// two tie on runs that hold the state they differ by fixed, and a tie is no sign of a
/// stand-in.
///
/// The share is of chi-square, not of the pattern: a rival may take it out by another change
/// of the residuals than the winner's. The debug line reports how much of the winner's change
/// the rival's carries (its projection on it) and their cosine. The pattern alone does not
/// tell a stand-in: a surge accelerometer offset that nothing hid, named after a depth EMI,
/// carried less than 0.4 of the spin-down's change, as a true compass offset after a water
/// current carried 0.06 of the reverse thrust curve's.
///
/// Such a rival refuses the winner unless the winner explains what the rival does not, in a
/// pattern of its own: fitted against the model with the rival in it, the winner passes every
/// guard again (the nested test of whether it adds to the structure), and the two changes of
/// the residuals differ (cosine below [`RIVAL_SAME_PATTERN_COSINE`]). A stand-in adds nothing
/// once the structure it stands in for is mended, or adds only more of the rival's pattern; a
/// real effect beside a loose structure adds its own (that compass offset, whose constant
/// heading error no change of the thrust curve reproduces; the accelerometer offset added
/// beside the spin-down too, but at a cosine of 0.78 with it).
///
/// The earlier names of an analysis can drive the vehicle where the baseline runs never took
/// it (a lag many times the calibrated one, a depth hold that chatters its vertical
/// thrusters on a noisy depth reading), and there the structure the baseline runs left loose
/// can be what is off: a new effect is then a stand-in for it.
pub fn structural_rival(setup: &Setup<'_>, win: &Candidate) -> Option<Candidate> {
    RivalFits::default().rival_of(setup, win)
}

/// The structural terms' fits against one setup, kept for the next winner judged against the
/// same setup. A fit depends only on the setup (the model, the floors it is judged by, the
/// split and the known levels), not on the winner: two winners of one round whose channels
/// share terms have them fitted once.
#[derive(Default)]
pub struct RivalFits {
    key: Option<SetupKey>,
    fits: Vec<Candidate>,
}

/// A floor's figures that a fit reads: its sigma, correlation time, white part and null
/// ensemble ([`crate::gap::resim::Floor`]).
type FloorKey = (Vec<f64>, f64, Vec<f64>, Vec<Vec<f64>>);

/// What a fit of a structural term reads from its [`Setup`], compared by value.
struct SetupKey {
    m: *const crate::gap::format::Measurement,
    base: crate::gap::effects::Configs,
    floors: Vec<Option<FloorKey>>,
    split: super::Split,
    spread: Vec<crate::gap::model::EnabledEffect>,
    known: Vec<f64>,
}

impl SetupKey {
    fn of(setup: &Setup<'_>) -> Self {
        Self {
            m: std::ptr::from_ref(setup.m),
            base: setup.base.clone(),
            floors: setup
                .floors
                .iter()
                .map(|f| {
                    f.as_ref().map(|f| {
                        (
                            f.sigma.clone(),
                            f.tau,
                            f.measurement_std.clone(),
                            f.null.clone(),
                        )
                    })
                })
                .collect(),
            split: setup.split,
            spread: setup.spread.clone(),
            known: setup.known.clone(),
        }
    }

    fn same(&self, other: &Self) -> bool {
        std::ptr::eq(self.m, other.m)
            && self.base == other.base
            && self.floors == other.floors
            && self.split == other.split
            && self.spread == other.spread
            && self.known == other.known
    }
}

impl RivalFits {
    /// The fits of `todo` against `setup`, ranked as [`fit_effects`] ranks them: those kept
    /// from an earlier call against the same setup, the rest fitted now.
    fn fits(&mut self, setup: &Setup<'_>, todo: &[&'static effects::Effect]) -> Vec<Candidate> {
        let key = SetupKey::of(setup);
        if !self.key.as_ref().is_some_and(|k| k.same(&key)) {
            self.key = Some(key);
            self.fits.clear();
        }
        let missing: Vec<&'static effects::Effect> = todo
            .iter()
            .copied()
            .filter(|e| !self.fits.iter().any(|c| c.name == e.name))
            .collect();
        if !missing.is_empty() {
            self.fits.extend(fit_effects(setup, &missing, &mut |_| {}));
        }
        let mut out: Vec<Candidate> = todo
            .iter()
            .filter_map(|e| self.fits.iter().find(|c| c.name == e.name).cloned())
            .collect();
        candidate::rank(&mut out);
        out
    }

    /// [`structural_rival`], with the structural terms' fits kept between calls.
    pub fn rival_of(&mut self, setup: &Setup<'_>, win: &Candidate) -> Option<Candidate> {
        let effect = effects::by_name(&win.name)?;
        let in_own = |r: &Residuals| own_channels_chi2(setup, r, effect.channels);
        let before = in_own(&setup.residuals(&setup.base, &setup.clean));
        let takes_out = |c: &Candidate| -> Option<f64> {
            let e = effects::by_name(&c.name)?;
            Some(before - in_own(&setup.eval(e, &c.values())?))
        };
        let win_takes = takes_out(win)?;
        let rivals = effects::structural_rivals(effect);
        self.fits(setup, &rivals).into_iter().find(|r| {
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
                guards = ?r.guards,
                heldout_gain = r.heldout_gain,
                "a structural rival"
            );
            let twin = effects::by_name(&r.name).is_some_and(|t| effects::twins(effect, t));
            stands(r)
                && explains_as_much(win, r, twin)
                && takes_out(r).is_some_and(|t| t >= RIVAL_MIN_SHARE * win_takes)
                && (change_cosine_where_changed(r, win)
                    .is_none_or(|c| c >= RIVAL_SAME_PATTERN_COSINE)
                    || !adds_to(setup, effect, r))
        })
    }
}

/// Whether the structural term `r` explains as much as `win`: the winner's lead over it on
/// the significance scale ([`candidate::margin`]: their chi-square gains over the scale of the
/// lead itself, the model's noise along where the two fits differ) is under [`BIC_MARGIN`]. A `twin` of the winner's
/// form ties with it on most runs: it is a rival only where the data prefer its form, by the
/// margin.
///
/// The scale is the model's correlated error both fits leave: where it is large, an unscaled
/// lead of a few tens is that error, not the data's preference. After a depth EMI, a thrust
/// curve took 681.3 against a net buoyancy's 647.1 unscaled, 1.1 on the scale, on a run
/// with nothing else hidden (structure 622951, seed 568421, case 28), and was named beside
/// the EMI.
pub(super) fn explains_as_much(win: &Candidate, r: &Candidate, twin: bool) -> bool {
    let lead = candidate::margin(win, r);
    tracing::debug!(
        winner = win.name,
        rival = r.name,
        lead,
        "the winner's lead over a structural rival on the significance scale"
    );
    if twin {
        lead < -BIC_MARGIN
    } else {
        lead < BIC_MARGIN
    }
}

/// Whether a structural term's fit can stand as the rival of a name: it passes every guard a
/// name must pass, except that its held-out blocks need only not get worse (gain at least 0)
/// rather than confirm it by [`super::HELDOUT_MIN_GAIN`]. The rival is not named; it only has
/// to show that the base model's own structure, set otherwise, accounts for the disagreement.
/// A loose structure driven where the baseline runs never took it is fitted in the training
/// blocks to the regime it met there, and the other blocks meet the regime at other moments:
/// a thruster's lag shape fitted to a depth hold that chatters on a noisy reading (structure
/// seed 132049, seed 121061, case 26) gains 3309.5 in delta BIC and only 2.4 on the held-out
/// blocks.
pub(super) fn stands(r: &Candidate) -> bool {
    let mut rest = r.guards;
    rest.heldout = None;
    r.testable && rest.all() && r.heldout_gain.is_none_or(|g| g >= 0.0)
}

/// Whether `effect`, fitted against the setup's model with `rival` applied, passes every
/// guard: it explains what the rival leaves.
pub(super) fn adds_to(
    setup: &Setup<'_>,
    effect: &'static effects::Effect,
    rival: &Candidate,
) -> bool {
    let Some(rival_effect) = effects::by_name(&rival.name) else {
        return false;
    };
    let mut base = setup.base.clone();
    effects::apply(rival_effect, &rival.values(), &mut base);
    let Ok(clean) = resim::simulate(&base, setup.m, None) else {
        return false;
    };
    let with = Setup {
        base,
        clean,
        spread: setup.spread.clone(),
        known: setup.known.clone(),
        ..*setup
    };
    let again = fit_effects(&with, &[effect], &mut |_| {});
    let adds = again.first().is_some_and(|c| c.testable && c.guards.all());
    tracing::debug!(
        winner = effect.name,
        rival = rival.name,
        adds,
        guards = ?again.first().map(|c| c.guards),
        delta_bic = again.first().map(|c| c.delta_bic),
        "the winner fitted beside its structural rival"
    );
    adds
}

/// Whether the effects named before a later winner (`earlier`) change the vehicle's dynamics
/// at all: one changes the physics, or is a noise source (the floor it raises reads as a move
/// of every channel it touches). Sensor effects of the mean type (a hard iron, a compass or
/// depth offset, a paddle-wheel scale) change only how readings map to states: the re-simulation
/// replays the recorded commands, so they move the vehicle's states through the anchors alone,
/// its speeds and turn rates not at all, and the structure the baseline runs pinned at those
/// speeds and rates stays pinned. Read on the readings alone, a hard iron named first moved a
/// coupling's channels by 3964 against the coupling's own 813 (structure seed 134059, seed
/// 123067, case 73) and a compass latency's by more than a quarter (208577, seed 191413, case
/// 79), and both were refused for a structural term.
///
/// A water current changes the physics but not the motion through the water
/// ([`effects::with_the_water`]): it moves the ground track, which the readings of the
/// track and of every channel anchored to it show, while the speeds and turn rates stay
/// pinned. Counted as a change of the dynamics, a current named first moved a true yaw
/// damping's channels by 4122 against its own 1030 (bridge seed 341749, case 75) and the
/// damping was refused for `yaw_damping_under_way`.
pub fn earlier_change_dynamics(earlier: &[&effects::Effect]) -> bool {
    earlier
        .iter()
        .any(|e| (e.physics && !effects::with_the_water(e)) || e.kind != effects::Kind::Mean)
}

/// The earlier names take the vehicle somewhere new for a later winner only where they move
/// the re-simulated readings of its signature channels by at least this share of the
/// chi-square the winner's own change makes there.
pub const NEW_REGIME_MIN_SHARE: f64 = 0.25;

/// Whether the effects named before `win` moved the readings of `win`'s signature channels
/// into a regime the baseline runs did not pin: the change they made there (`unnamed`, the
/// setup's residuals of the model without them, against the setup's own) has a chi-square of
/// at least [`NEW_REGIME_MIN_SHARE`] of the winner's own change in those channels. Only then
/// can a structural term be a better account of the winner's disagreement than the winner:
/// in the regime the baseline runs took the vehicle through, the calibration set those terms,
/// as it did for a first name, which no structural rival is asked about. A depth offset named
/// first moves the heading and track little (structure seed 188491, seed 171347, case 71:
/// 25.9 against the sway-yaw coupling's 862.3), a lag several times the calibrated one
/// moves them all.
///
/// A noise source among the earlier names (`earlier`) takes a winner that moves the noise
/// source's own channel somewhere new whatever the readings show. The source acts on readings
/// only; what it did to the vehicle went through the loop closed on that channel into the
/// commands (a depth hold that chatters its vertical thrusters on a noisy depth reading), which
/// the re-simulation replays whether the source is named or not, so no reading it predicts
/// moves when it is named. A winner whose form acts where that loop acts (a thrust curve,
/// through every thruster and so the depth) meets the chatter; one that moves other channels
/// alone (a yaw damping: heading, track, sway) does not.
pub fn moved_to_new_regime(
    setup: &Setup<'_>,
    earlier: &[&effects::Effect],
    unnamed: &Residuals,
    win: &Candidate,
) -> bool {
    let Some(effect) = effects::by_name(&win.name) else {
        return true;
    };
    if earlier.iter().any(|e| {
        e.kind != effects::Kind::Mean && e.channels.iter().any(|c| later::moves(effect, c))
    }) {
        return true;
    }
    let now = setup.residuals(&setup.base, &setup.clean);
    if now.values.len() != unnamed.values.len() || win.change.len() != now.values.len() {
        return true;
    }
    let moved = Residuals {
        values: now
            .values
            .iter()
            .zip(&unnamed.values)
            .map(|(a, b)| a - b)
            .collect(),
        ..now.clone()
    };
    let change = Residuals {
        values: win.change.clone(),
        ..now
    };
    let moved = own_channels_chi2(setup, &moved, effect.channels);
    let own = own_channels_chi2(setup, &change, effect.channels);
    tracing::debug!(
        winner = win.name,
        moved,
        own,
        "how far the earlier names moved a later winner's channels"
    );
    moved >= NEW_REGIME_MIN_SHARE * own
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
