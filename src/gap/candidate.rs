//! A candidate effect as every objective scores it (the measured time series in
//! [`crate::gap::fit`], the summary observations in [`crate::gap::summary`]), the guards that
//! decide whether it is named, the greedy selection loop that names effects one at a time,
//! and the candidate table of both reports.

use std::fmt::Write as _;

use serde::Serialize;

use crate::gap::GapError;

/// Which guards a candidate passed.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq, Eq)]
pub struct Guards {
    /// Every parameter strictly inside its physical bounds.
    pub inside_bounds: bool,
    /// Every 95 % interval finite, and the no-effect value outside the confidence region.
    pub interval_excludes_zero: bool,
    /// `delta_bic > BIC_MARGIN`.
    pub significant: bool,
    /// The signature test.
    pub signature: bool,
    /// The held-out gain exceeds `HELDOUT_MIN_GAIN` (`None`: the objective has no held-out
    /// part, as summary observations have not).
    pub heldout: Option<bool>,
}

impl Guards {
    pub fn all(&self) -> bool {
        self.inside_bounds
            && self.interval_excludes_zero
            && self.significant
            && self.signature
            && self.heldout != Some(false)
    }

    /// The guards that failed, by name.
    pub fn failed(&self) -> Vec<&'static str> {
        let mut out = Vec::new();
        for (ok, name) in [
            (self.inside_bounds, "bounds"),
            (self.interval_excludes_zero, "interval"),
            (self.significant, "significance"),
            (self.signature, "signature"),
            (self.heldout != Some(false), "held-out"),
        ] {
            if !ok {
                out.push(name);
            }
        }
        out
    }
}

/// An effect accepted in an earlier round, refitted jointly with a later candidate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Refitted {
    pub name: String,
    pub values: Vec<f64>,
    pub ci95: Vec<[f64; 2]>,
}

/// What fitting one candidate gave.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Candidate {
    pub name: String,
    /// (parameter, fitted change relative to the model).
    pub parameters: Vec<(String, f64)>,
    pub ci95: Vec<(String, [f64; 2])>,
    /// Chi-square of the data the fit saw, without and with the effect.
    pub chi2_before: f64,
    pub chi2_after: f64,
    /// BIC gain over "no effect", scaled by `variance_factor * noise_factor`: what the
    /// significance margin is applied to.
    pub delta_bic: f64,
    /// BIC gain without that scaling (the likelihood itself): what candidates are ranked by,
    /// since all are fitted to the same data.
    pub delta_bic_uncalibrated: f64,
    /// Held-out chi-square without and with the effect (fitted values, blocks not fitted
    /// to), and the gain scaled as `delta_bic`'s is; `None` without a held-out part.
    pub heldout_chi2_before: Option<f64>,
    pub heldout_chi2_after: Option<f64>,
    pub heldout_gain: Option<f64>,
    pub signature_pass: bool,
    pub signature: String,
    pub guards: Guards,
    /// False when the data hold nothing the effect shows in.
    pub testable: bool,
    /// Model evaluations the fit needed.
    pub evaluations: usize,
    /// How much more chi-square a fit of this effect gains on the model's own noise than
    /// independent noise would (>= 1).
    pub noise_factor: f64,
    /// Residual variance left beyond the noise floor after the fit (>= 1).
    pub variance_factor: f64,
    /// Effects accepted before, refitted jointly with this one (empty when they are held).
    pub refitted: Vec<Refitted>,
    /// The values of the fit on the training blocks alone, where there was one: a later
    /// round's warm start, which must not have seen the blocks that round judges on.
    #[serde(skip)]
    pub trained: Vec<f64>,
    /// How the fit changed each residual (after less before, all samples, in the order of the
    /// setup's residuals); empty where there is none (a variance effect, a summary fit).
    #[serde(skip)]
    pub change: Vec<f64>,
    /// The model's own noise along `change` ([`NoiseAlong`]); empty where `change` is.
    #[serde(skip)]
    pub noise_along: NoiseAlong,
}

/// The model's own noise, projected on a fit's change of the residuals: what two fits'
/// changes are compared with along the direction in which they differ ([`margin`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NoiseAlong {
    /// The change's dot product with each null residual of the seeded ensemble (process
    /// noise), in the ensemble's order.
    pub process: Vec<f64>,
    /// Each residual's white measurement variance in floor units, in the residuals' order.
    pub white: std::sync::Arc<[f64]>,
}

impl Candidate {
    /// A candidate that could not be fitted, with the reason in place of its signature.
    pub fn untestable(effect: &crate::gap::effects::Effect, chi2_before: f64, why: &str) -> Self {
        let names = || effect.parameters.iter().map(|p| p.to_string());
        Self {
            name: effect.name.to_string(),
            parameters: names().map(|n| (n, 0.0)).collect(),
            ci95: names().map(|n| (n, [0.0, 0.0])).collect(),
            chi2_before,
            chi2_after: chi2_before,
            delta_bic: f64::NEG_INFINITY,
            delta_bic_uncalibrated: f64::NEG_INFINITY,
            heldout_chi2_before: None,
            heldout_chi2_after: None,
            heldout_gain: None,
            signature_pass: false,
            signature: why.to_string(),
            guards: Guards::default(),
            testable: false,
            evaluations: 0,
            noise_factor: 1.0,
            variance_factor: 1.0,
            refitted: Vec::new(),
            trained: Vec::new(),
            change: Vec::new(),
            noise_along: NoiseAlong::default(),
        }
    }

    /// The fitted values, in the effect's parameter order.
    pub fn values(&self) -> Vec<f64> {
        self.parameters.iter().map(|(_, v)| *v).collect()
    }
}

/// Ranks a round's candidates: by the likelihood gain, best first.
pub fn rank(round: &mut [Candidate]) {
    round.sort_by(|a, b| {
        b.delta_bic_uncalibrated
            .total_cmp(&a.delta_bic_uncalibrated)
    });
}

/// The winner of a ranked round: the best candidate that passes every guard.
pub fn winner(round: &[Candidate]) -> Option<&Candidate> {
    round.iter().find(|r| r.testable && r.guards.all())
}

/// One round of an objective: round number, the effects accepted so far and the winners
/// refused so far in (a refused winner need not be fitted again: it does not take part), every
/// candidate's fit out (`None`: nothing can be fitted any more).
pub type FitRound<'a> =
    dyn FnMut(usize, &[Candidate], &[Refused]) -> Result<Option<Vec<Candidate>>, GapError> + 'a;
/// Takes a round's winner, the last of the accepted effects, into the model; it may replace
/// the accepted effects' values (the winner's too) by their joint refit. `Some(refusal)`
/// refuses the winner after all (the accepted effects' values left as they were): the round's
/// next candidate is tried in its place, and is handed over with the winners refused before it
/// in the same round.
pub type Accept<'a> =
    dyn FnMut(&mut [Candidate], &[Refused]) -> Result<Option<Refusal>, GapError> + 'a;

/// Why [`Accept`] refused a winner.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    /// In words, with the figures.
    pub why: String,
    /// Set when the refusal is of the winner's form, not of the disagreement it explains: this
    /// term of the base model's structure, fitted in the winner's place, explains that
    /// disagreement as well or better in the winner's own channels. A look-alike the winner
    /// tied with has other channels and another form, and is judged on its own; a refusal of
    /// the disagreement (nothing left beyond what runs with nothing new show) refuses the
    /// look-alike with it.
    pub structure: Option<Box<Candidate>>,
    /// Set when the refusal refuses again what an earlier refusal of its round refused: a
    /// winner held as a stand-in for the structural term that refused the round's first
    /// winner ([`later::held_as_stand_in`](crate::gap::later)) is refused for the disagreement
    /// that term explains. It is no second refusal of the round ([`REFUSALS_PER_ROUND`]).
    pub repeats: bool,
}

impl Refusal {
    /// A refusal of the winner's form: `term`, of the base model's structure, explains what
    /// it does ([`Refusal::structure`]).
    pub fn of_its_form(why: String, term: Candidate) -> Self {
        Self {
            why,
            structure: Some(Box::new(term)),
            repeats: false,
        }
    }

    /// A refusal of what an earlier refusal of the round refused ([`Refusal::repeats`]).
    pub fn repeating(why: String) -> Self {
        Self {
            why,
            structure: None,
            repeats: true,
        }
    }

    /// Whether the refusal is of the winner's form ([`Refusal::structure`]).
    pub fn is_of_its_form(&self) -> bool {
        self.structure.is_some()
    }
}

impl From<String> for Refusal {
    fn from(why: String) -> Self {
        Self {
            why,
            structure: None,
            repeats: false,
        }
    }
}

/// Winners one round may refuse before the selection stops. A refusal says the winner is
/// no effect of its own (it does not shrink the gap, or it stands in for what the earlier
/// names or the base model's structure lack), not that the round holds none: the next
/// candidate may be the effect the refused one stood in front of. Two refused in one round
/// say most of what is left is what no candidate is; each refusal also costs a structural
/// check of up to 14 fits. A refusal that repeats the first of its round (a stand-in held for
/// the structural term that refused the first, [`Refusal::repeats`], or a winner that term
/// refuses too) refuses no new disagreement and counts none.
pub const REFUSALS_PER_ROUND: usize = 2;

/// The greedy selection, whatever the objective: up to `max` rounds; in each, `fit_round`
/// fits every candidate not yet accepted against the model with the accepted effects
/// (`None`: nothing can be fitted any more), the round is ranked, and its winner is accepted
/// and handed to `accept` (which may replace the accepted effects' values by their joint
/// refit, or refuse it). A refused winner gives way to the round's next candidate that
/// passes every guard, judged by the same rules without it. Stops at the first round without
/// a winner, or with [`REFUSALS_PER_ROUND`] refused.
/// Returns every round and the accepted effects in order.
pub fn select(
    max: usize,
    fit_round: &mut FitRound<'_>,
    accept: &mut Accept<'_>,
) -> Result<Selection, GapError> {
    select_with(max, false, fit_round, accept)
}

/// [`select`], carrying on past the first round that ends on two look-alikes: its winner is
/// handed to `accept` as if named and, once taken into the model, stays there unnamed
/// ([`Selection::carried`]) while the later rounds look for the disagreement it leaves, its
/// look-alike no longer a candidate. A tie between two effects says nothing of a second
/// effect beside them (a depth offset or gain that one held depth cannot tell apart, beside a
/// depth EMI), and either look-alike takes the same disagreement out of what the later rounds
/// see. A second tie ends the selection as [`select`] does. A winner refused when taken in
/// is no effect, nor its look-alike: both are refused, with no tie, one refusal of the round
/// between them, and the round's next candidate is judged in their place; unless it is
/// refused for its form ([`Refusal::of_its_form`]): then it gives way as any refused winner
/// does, and the look-alike is judged on its own in its place.
pub fn select_past_ties(
    max: usize,
    fit_round: &mut FitRound<'_>,
    accept: &mut Accept<'_>,
) -> Result<Selection, GapError> {
    select_with(max, true, fit_round, accept)
}

fn select_with(
    max: usize,
    carry: bool,
    fit_round: &mut FitRound<'_>,
    accept: &mut Accept<'_>,
) -> Result<Selection, GapError> {
    let mut rounds: Vec<Vec<Candidate>> = Vec::new();
    let mut accepted: Vec<Candidate> = Vec::new();
    let mut ambiguous = None;
    let mut carried: Option<Carried> = None;
    let mut outranked_by = None;
    let mut refused = Vec::new();
    'rounds: for round in 0..max {
        let Some(mut results) = fit_round(round, &accepted, &refused)? else {
            break;
        };
        // A carried tie's look-alike is no candidate beside its winner.
        if let Some(c) = &carried {
            results.retain(|r| r.name != c.pair[1]);
        }
        rank(&mut results);
        rounds.push(results);
        let results = rounds.last().map_or(&[][..], Vec::as_slice);
        // The round's candidates less those refused in it or before: a refused winner is
        // judged no effect, so it neither wins again nor counts as a rival of the next.
        let mut refused_here = 0;
        // The refused records of this round begin here (a tie refused leaves two).
        let round_start = refused.len();
        loop {
            let pool: Vec<Candidate> = results
                .iter()
                .filter(|c| refused.iter().all(|r: &Refused| r.name != c.name))
                .cloned()
                .collect();
            let Some(win) = winner(&pool).cloned() else {
                break 'rounds;
            };
            if let Some(c) = unconfirmed_rival(&pool, &win) {
                outranked_by = Some(Outranked {
                    name: c.name.clone(),
                    failed: c.guards.failed(),
                });
                break 'rounds;
            }
            if let Some(alt) = lookalike(&pool, &win, !accepted.is_empty()) {
                let pair = [win.name.clone(), alt.name.clone()];
                if carry && carried.is_none() {
                    accepted.push(win);
                    let this_round = &refused[round_start..];
                    let Some(refusal) = accept(&mut accepted, this_round)? else {
                        tracing::debug!(
                            round,
                            ?pair,
                            "a tie carried: its winner in the model, unnamed"
                        );
                        carried = Some(Carried { round, pair });
                        continue 'rounds;
                    };
                    accepted.pop();
                    let of_its_form = refusal.is_of_its_form();
                    let repeats = repeats_the_round(&refused[round_start..], &refusal);
                    let Refusal { why, structure, .. } = refusal;
                    tracing::debug!(
                        round,
                        ?pair,
                        why,
                        of_its_form,
                        repeats,
                        "a tie's winner refused"
                    );
                    let [name, alt] = pair;
                    if of_its_form {
                        // Its form refused, the winner gives way as any refused winner does,
                        // and the look-alike is judged on its own in its place.
                        refused.push(Refused {
                            round,
                            name,
                            why,
                            structure,
                        });
                    } else {
                        // Refused, the winner is no effect, and its look-alike, which explains
                        // the same disagreement about as well, none either: no tie to report.
                        // One disagreement refused, one refusal of the round: its next
                        // candidate, which the two took the lead from, is judged in their place.
                        let alt_why = format!("it ties with `{name}`, refused: {why}");
                        refused.push(Refused::of_the_disagreement(round, name, why));
                        refused.push(Refused::of_the_disagreement(round, alt, alt_why));
                    }
                    refused_here += usize::from(!repeats);
                    if refused_here >= REFUSALS_PER_ROUND {
                        break 'rounds;
                    }
                    continue;
                }
                ambiguous = Some(pair);
                break 'rounds;
            }
            let name = win.name.clone();
            accepted.push(win);
            let this_round = &refused[round_start..];
            let Some(refusal) = accept(&mut accepted, this_round)? else {
                continue 'rounds;
            };
            accepted.pop();
            let repeats = repeats_the_round(&refused[round_start..], &refusal);
            let Refusal { why, structure, .. } = refusal;
            tracing::debug!(
                round,
                winner = name,
                why,
                repeats,
                "a round's winner refused"
            );
            refused.push(Refused {
                round,
                name,
                why,
                structure,
            });
            refused_here += usize::from(!repeats);
            if refused_here >= REFUSALS_PER_ROUND {
                break 'rounds;
            }
        }
    }
    Ok(Selection {
        rounds,
        accepted,
        ambiguous,
        carried,
        outranked_by,
        refused,
    })
}

/// Whether `refusal` refuses again what the first refusal of its round (`this_round`, the
/// round's refused records) refused: it says so ([`Refusal::repeats`]), or it gives way to the
/// same term of the base model's structure. A round whose winners one structural term
/// explains has found one thing, that term; the next candidate may be an effect beside it.
fn repeats_the_round(this_round: &[Refused], refusal: &Refusal) -> bool {
    let first = this_round.first().and_then(|r| r.structure.as_deref());
    refusal.repeats
        || first
            .zip(refusal.structure.as_deref())
            .is_some_and(|(a, b)| a.name == b.name)
}

/// What the greedy selection found.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Every round's candidates, ranked.
    pub rounds: Vec<Vec<Candidate>>,
    /// The accepted effects, in order.
    pub accepted: Vec<Candidate>,
    /// A round whose winner has a look-alike that explains the same residual about as well
    /// (both pass every guard, delta BIC within [`crate::gap::fit::BIC_MARGIN`]; two effects
    /// of one kind, or a physics effect behind a sensor winner): the winner's name first.
    /// Selection stops there and names neither: the data do not say which it is.
    pub ambiguous: Option<[String; 2]>,
    /// A tie the selection carried on past ([`select_past_ties`]): its winner is among
    /// `accepted`, in the model but not named.
    pub carried: Option<Carried>,
    /// A round whose winner another candidate outranks by more than
    /// [`crate::gap::fit::BIC_MARGIN`] in the likelihood, passing every guard but its bounds:
    /// the disagreement looks most like that effect, larger than its physical range lets the
    /// fit go. Selection stops there: the winner would be a stand-in taking the share of the
    /// disagreement it can.
    pub outranked_by: Option<Outranked>,
    /// Winners that passed every guard but that the model could not take in (see
    /// [`Accept`]), in the order refused: none is named, and the next candidate of the same
    /// round takes its place, up to [`REFUSALS_PER_ROUND`] refusals in a round.
    pub refused: Vec<Refused>,
}

/// A round's two look-alikes the selection carried on past ([`Selection::carried`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Carried {
    /// The round (0 the first).
    pub round: usize,
    /// The winner, which the model carries, then its look-alike.
    pub pair: [String; 2],
}

/// A winner refused when it was taken into the model ([`Selection::refused`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Refused {
    /// The round it won (0 the first).
    pub round: usize,
    pub name: String,
    /// Why, in words with the figures.
    pub why: String,
    /// The term of the base model's structure that explains its disagreement as well or better,
    /// where it was refused for its form ([`Refusal::structure`]).
    #[serde(skip)]
    pub structure: Option<Box<Candidate>>,
}

impl Refused {
    /// A winner refused for the disagreement it explains, not for its form.
    pub fn of_the_disagreement(round: usize, name: String, why: String) -> Self {
        Self {
            round,
            name,
            why,
            structure: None,
        }
    }
}

/// The candidate a round's winner was not named for ([`Selection::outranked_by`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Outranked {
    pub name: String,
    /// The guards it failed (its bounds).
    pub failed: Vec<&'static str>,
}

/// A candidate of `round` that explains the round's disagreement better than `win` by more
/// than the delta-BIC margin and fails no guard but its bounds: its interval excludes no
/// effect even with the between-run spread, it passes its signature and the held-out blocks,
/// and its fit ends on a bound. The effect is larger than its range; the winner is not what
/// the data point to. (A rival that fails only its interval is no such evidence: the
/// calibration's own known disagreement shows in every run as an effect null runs also
/// show, beside whatever the winner explains.)
fn unconfirmed_rival<'a>(round: &'a [Candidate], win: &Candidate) -> Option<&'a Candidate> {
    round.iter().find(|c| {
        let mut rest = c.guards;
        rest.inside_bounds = true;
        c.testable
            && !c.guards.inside_bounds
            && rest.all()
            && c.delta_bic_uncalibrated > win.delta_bic_uncalibrated + crate::gap::fit::BIC_MARGIN
    })
}

/// An effect of `round` that explains the same disagreement as `win` about as well: it
/// passes every guard, is of the same kind (mean or variance: their delta BICs come from
/// different likelihoods), shares a signature channel with it, and trails it by less than
/// the delta-BIC margin, which is not very strong evidence for either (Kass and Raftery
/// 1995). Two sensor effects or two physics effects that close are a tie, and so is a
/// physics effect close behind a sensor winner (a sensor effect may take a disagreement only
/// with its own signature). Only a sensor effect close behind a physics winner is no tie:
/// the physics wins. Two physics effects that change the residuals alike are judged on the
/// significance scale too ([`physics_tie`]): in a round after the first (`later`) from a
/// cosine of [`SAME_CHANGE_COSINE`], in the first from [`FIRST_ROUND_SAME_CHANGE_COSINE`].
/// Library effects only.
fn lookalike<'a>(round: &'a [Candidate], win: &Candidate, later: bool) -> Option<&'a Candidate> {
    round.iter().find(|c| {
        let kin = c.name != win.name
            && c.testable
            && (c.guards.all() || same_change_but_interval(c, win))
            && of_its_kind(c, win);
        if kin {
            tracing::debug!(
                winner = win.name,
                rival = c.name,
                cosine = change_cosine(c, win),
                behind = win.delta_bic_uncalibrated - c.delta_bic_uncalibrated,
                "a rival of the same kind"
            );
        }
        kin && (c.delta_bic_uncalibrated > win.delta_bic_uncalibrated - crate::gap::fit::BIC_MARGIN
            || sensor_tie(c, win)
            || physics_tie(c, win, later))
    })
}

/// Two physics effects that both pass every guard and change the residuals alike, where the
/// winner's lead on the significance scale ([`margin`]) is under the delta-BIC margin: in a
/// round after the first (`later`), from a cosine of [`SAME_CHANGE_COSINE`]; in the first,
/// from [`FIRST_ROUND_SAME_CHANGE_COSINE`].
///
/// The earlier names took the disagreement the run shows most clearly; what is left holds
/// the model's correlated error in a larger share, and there a lead read unscaled names one of
/// two look-alikes the data do not tell apart (a yaw damping 10.1 ahead of a sway-yaw
/// coupling unscaled, 4.3 on the scale, cosine 0.985, on a vehicle of another structure whose
/// coupling was hidden). In the first round only two changes that are nearly one are read on
/// the scale: the simulator's thrust gains and curves, imbalances and couplings tie there at
/// lower cosines, and a first-round tie names neither. Nearly one, the unscaled lead is the
/// base model's error, not the data's preference: a yaw damping 25.5 ahead unscaled, 7.9 on
/// the scale, cosine 0.996, of a hidden sway-yaw coupling beside a paddle-wheel scale
/// (structure 618937, seed 564391, pair 37) was named in its place.
fn physics_tie(c: &Candidate, win: &Candidate, later: bool) -> bool {
    let least = if later {
        SAME_CHANGE_COSINE
    } else {
        FIRST_ROUND_SAME_CHANGE_COSINE
    };
    // The cosine is logged with the rival ("a rival of the same kind").
    both_of_one_sort(c, win, true)
        && change_cosine(c, win).is_some_and(|cosine| cosine >= least)
        && lead_on_the_scale(c, win) < crate::gap::fit::BIC_MARGIN
}

/// Two sensor effects that both pass every guard, where the winner's lead read on the scale
/// of the significance test ([`margin`]) is under the delta-BIC margin. Two sensor effects of
/// one channel are told apart only by the readings where their changes differ (a depth
/// offset and a depth gain, cosine 0.9999 on a run that holds one depth, only where the depth
/// changes), and there the model's correlated error weighs as much as in the significance
/// test: read unscaled, such a lead of 10-15 named the other of the two. In the first round
/// physics look-alikes keep the unscaled lead: the simulator's thrust gains and curves,
/// imbalances and couplings tie on the scale.
fn sensor_tie(c: &Candidate, win: &Candidate) -> bool {
    both_of_one_sort(c, win, false) && lead_on_the_scale(c, win) < crate::gap::fit::BIC_MARGIN
}

/// Whether `c` and `win` are both physics effects (`physics`) or both sensor effects.
fn both_of_one_sort(c: &Candidate, win: &Candidate, physics: bool) -> bool {
    let of_sort =
        |name: &str| crate::gap::effects::by_name(name).is_some_and(|e| e.physics == physics);
    of_sort(&win.name) && of_sort(&c.name)
}

/// The winner's lead over `c` on the significance scale ([`margin`]), logged.
fn lead_on_the_scale(c: &Candidate, win: &Candidate) -> f64 {
    let lead = margin(win, c);
    tracing::debug!(
        winner = win.name,
        rival = c.name,
        lead,
        "two look-alikes of one sort, the lead on the significance scale"
    );
    lead
}

/// How much more the data favour `win` than `rival`, in BIC on the scale the significance
/// margin uses: the difference of their chi-square gains over a quasi-likelihood scale (as an
/// F-test divides by the residual variance), less the difference of their parameter
/// penalties. The scale is the one the lead itself has ([`contrast_scale`]); where the two
/// fits' changes are not known, the larger of their own scales (`noise_factor *
/// variance_factor`).
pub fn margin(win: &Candidate, rival: &Candidate) -> f64 {
    let gain = |c: &Candidate| c.chi2_before - c.chi2_after;
    let penalty = |c: &Candidate| gain(c) - c.delta_bic_uncalibrated;
    let own = |c: &Candidate| (c.noise_factor * c.variance_factor).max(1.0);
    let scale = contrast_scale(win, rival).unwrap_or_else(|| own(win).max(own(rival)));
    (gain(win) - gain(rival)) / scale - (penalty(win) - penalty(rival))
}

/// The quasi-likelihood scale of the lead of `win` over `rival`. The two fits leave the
/// residuals `r0 + c_w` and `r0 + c_r`; the noise in `r0` moves the difference of their
/// chi-squares by `2 e . (c_r - c_w)`, so the lead's noise is the residuals' noise along
/// `d = c_w - c_r`, not along either change: noise both fits take alike (a level both a depth
/// offset and a depth gain follow) favours neither. Its variance over that of independent
/// noise of the floor is `(mean_j (d . e_j)^2 + sum_i w_i d_i^2) / |d|^2` over the seeded
/// ensemble's null residuals `e_j` and the white variances `w_i` (as
/// `noise_factor` is along one fit's Jacobian), at least 1, times the larger residual variance
/// the two fits leave (`variance_factor`: the model error beyond the floor). `None` where
/// either change or its noise is not known, or the two changes are one.
fn contrast_scale(win: &Candidate, rival: &Candidate) -> Option<f64> {
    let (a, b) = (&win.noise_along, &rival.noise_along);
    let n = win.change.len();
    if n == 0
        || rival.change.len() != n
        || a.white.len() != n
        || a.process.is_empty()
        || a.process.len() != b.process.len()
    {
        return None;
    }
    let d: Vec<f64> = win
        .change
        .iter()
        .zip(&rival.change)
        .map(|(x, y)| x - y)
        .collect();
    let norm2: f64 = d.iter().map(|x| x * x).sum();
    if norm2 <= 0.0 || !norm2.is_finite() {
        return None;
    }
    let process = a
        .process
        .iter()
        .zip(&b.process)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        / a.process.len() as f64;
    let white: f64 = a.white.iter().zip(&d).map(|(w, x)| w * x * x).sum();
    let factor = ((process + white) / norm2).max(1.0);
    let scale = (factor * win.variance_factor.max(rival.variance_factor)).max(1.0);
    tracing::debug!(
        winner = win.name,
        rival = rival.name,
        factor,
        own_winner = win.noise_factor,
        own_rival = rival.noise_factor,
        scale,
        "the noise along the difference of two fits"
    );
    Some(scale)
}

/// Whether `c` could stand where `win` stands: library effects of the same kind (mean or
/// variance), sharing a signature channel, and not a sensor effect in a physics effect's
/// place (where both explain a residual, the physics wins).
pub(crate) fn of_its_kind(c: &Candidate, win: &Candidate) -> bool {
    let (Some(e), Some(w)) = (
        crate::gap::effects::by_name(&c.name),
        crate::gap::effects::by_name(&win.name),
    ) else {
        return false;
    };
    (e.physics || !w.physics)
        && e.kind == w.kind
        && e.channels.iter().any(|ch| w.channels.contains(ch))
}

/// The cosine of the angle between the changes of the residuals the fits of `a` and `b` make;
/// `None` when either is unknown or zero.
pub(crate) fn change_cosine(a: &Candidate, b: &Candidate) -> Option<f64> {
    if a.change.len() != b.change.len() {
        return None;
    }
    let dot: f64 = a.change.iter().zip(&b.change).map(|(x, y)| x * y).sum();
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let n = norm(&a.change) * norm(&b.change);
    (n > 0.0).then(|| dot / n)
}

/// As [`change_cosine`], on the residuals `b`'s fit changes only: how closely `a` moves
/// those readings as `b` does, whatever else `a` moves.
pub(crate) fn change_cosine_where_changed(a: &Candidate, b: &Candidate) -> Option<f64> {
    if a.change.len() != b.change.len() {
        return None;
    }
    let (mut dot, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.change.iter().zip(&b.change) {
        if *y != 0.0 {
            dot += x * y;
            aa += x * x;
            bb += y * y;
        }
    }
    (aa > 0.0 && bb > 0.0).then(|| dot / (aa * bb).sqrt())
}

/// How much of `b`'s change of the residuals `a`'s change carries, on the readings `b`
/// changes: the coefficient of `a`'s change projected on `b`'s (1 when `a` moves them exactly
/// as `b` does, whatever else it moves; 0 when it moves them across `b`'s direction).
pub(crate) fn change_projection_where_changed(a: &Candidate, b: &Candidate) -> Option<f64> {
    if a.change.len() != b.change.len() {
        return None;
    }
    let (mut dot, mut bb) = (0.0, 0.0);
    for (x, y) in a.change.iter().zip(&b.change) {
        dot += x * y;
        bb += y * y;
    }
    (bb > 0.0).then(|| dot / bb)
}

/// Two fits whose changes of the residuals point the same way at least this closely (the
/// cosine of the angle between them) explain the same disagreement.
pub const SAME_CHANGE_COSINE: f64 = 0.9;

/// Two physics fits of a first round whose changes of the residuals point the same way at
/// least this closely are told apart on the significance scale ([`physics_tie`]): the share
/// of either change the other does not carry is at most 1 - 0.99^2, about 2 %.
pub const FIRST_ROUND_SAME_CHANGE_COSINE: f64 = 0.99;

/// `c` fails no guard but its interval, and changes the residuals as `win` does (cosine at
/// least [`SAME_CHANGE_COSINE`]): it explains the same disagreement, and its interval holds 0
/// only because null runs stray by as much (a depth gain beside a depth offset, both read at
/// the surface where the buoyancy fixes the depth). The winner is then not established over
/// it either. A rival that fails its interval and explains another part of the disagreement
/// (a hard iron's once-per-turn error beside a compass offset) is no look-alike.
///
/// A sensor winner changes only its own channels; a physics rival changes those and others.
/// There the two are compared on the readings the sensor effect changes: a physics effect
/// that takes the sensor's disagreement as part of a larger one (a thruster imbalance's
/// steady turn reads as a sway accelerometer offset) explains the same residual, and the
/// physics wins; that null runs stray by as much says the whole pattern is the vehicle's
/// run-to-run variation, the sensor's part of it included.
fn same_change_but_interval(c: &Candidate, win: &Candidate) -> bool {
    let mut rest = c.guards;
    rest.interval_excludes_zero = true;
    if c.guards.interval_excludes_zero || !rest.all() {
        return false;
    }
    let physics = |name: &str| crate::gap::effects::by_name(name).is_some_and(|e| e.physics);
    let cosine = if physics(&c.name) && !physics(&win.name) {
        change_cosine_where_changed(c, win)
    } else {
        change_cosine(c, win)
    };
    let Some(cosine) = cosine else {
        return false;
    };
    tracing::debug!(
        winner = win.name,
        rival = c.name,
        cosine,
        "a rival that fails only its interval"
    );
    cosine >= SAME_CHANGE_COSINE
}

/// The winner of `round` and the best other candidate that passes every guard, with how far
/// behind it is in the likelihood the round is ranked by (`None` when nothing else passes):
/// the margin the look-alike rule reads.
pub fn runner_up(round: &[Candidate]) -> Option<(&Candidate, &Candidate, f64)> {
    let win = winner(round)?;
    let next = round
        .iter()
        .find(|c| c.name != win.name && c.testable && c.guards.all())?;
    Some((
        win,
        next,
        win.delta_bic_uncalibrated - next.delta_bic_uncalibrated,
    ))
}

/// The candidate table of one round (markdown): rank, effect, delta BIC, the chi-square the
/// fit saw before and after, the held-out gain, the parameters with their 95 % intervals,
/// the guards that failed, and the signature test.
pub fn round_table(round: &[Candidate]) -> String {
    let mut s = String::from(
        "| rank | effect | delta BIC | chi2 before -> after | held-out gain | parameters [95 %] | failed guards | signature |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for (k, c) in round.iter().enumerate() {
        let p: Vec<String> = c
            .parameters
            .iter()
            .zip(&c.ci95)
            .map(|((n, v), (_, ci))| format!("{n} = {v:.4} [{:.4}, {:.4}]", ci[0], ci[1]))
            .collect();
        let failed = if c.testable {
            let f = c.guards.failed();
            if f.is_empty() {
                "none".to_string()
            } else {
                f.join(", ")
            }
        } else {
            "not testable".to_string()
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.1} -> {:.1} | {} | {} | {} | {} {} |",
            k + 1,
            c.name,
            if c.delta_bic.is_finite() {
                format!("{:.1}", c.delta_bic)
            } else {
                "-".into()
            },
            c.chi2_before,
            c.chi2_after,
            c.heldout_gain.map_or("-".into(), |g| format!("{g:.1}")),
            if c.testable { p.join("; ") } else { "-".into() },
            failed,
            if c.signature_pass { "pass:" } else { "fail:" },
            c.signature
        );
    }
    s
}

#[cfg(test)]
mod tests;
