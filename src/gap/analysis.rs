//! What `gap` found ([`Analysis`]): the verdict, the names, the rounds, the gap before and
//! after, and where it is left.

use serde::Serialize;

use super::candidate::{self, Candidate};
use super::effects::Configs;
use super::model::GapModel;
use super::residuals::ChannelStats;
use super::{anchor, fit, reduction_pct, resim};

/// The verdict of one run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// At least one effect passed every guard and was named.
    Effect,
    /// The model agrees with the data within its noise floor: nothing to explain.
    None,
    /// The data disagree with the model beyond its noise floor and nothing in the library
    /// explains it; `Analysis::unexplained` says where.
    Unexplained,
    /// Two effects explain the same disagreement about as well (`Analysis::ambiguous` or
    /// `Analysis::tie` names both; a physics effect close behind a sensor winner, or two of
    /// one kind), and nothing else was named.
    Ambiguous,
}

impl Verdict {
    /// The verdict's word, as reports write it.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Effect => "effect",
            Verdict::None => "none",
            Verdict::Unexplained => "unexplained",
            Verdict::Ambiguous => "ambiguous",
        }
    }
}

/// Two look-alikes the search carried on past ([`Analysis::tie`]).
#[derive(Debug, Clone)]
pub struct Tie {
    /// The round (0 the first).
    pub round: usize,
    /// The winner, then its look-alike.
    pub pair: [String; 2],
    /// The winner as the model carries it (the later names' joint refit): in `fitted` and
    /// `configs_after`, not among the names.
    pub carried: Candidate,
    /// Its share of the shrink (percent), as `Analysis::shares_pct` counts the names'.
    pub share_pct: f64,
}

impl Analysis {
    /// Every look-alike pair the search ended on or carried on past, in the order met.
    pub fn ties(&self) -> Vec<&[String; 2]> {
        self.tie
            .as_ref()
            .map(|t| &t.pair)
            .into_iter()
            .chain(self.ambiguous.as_ref())
            .collect()
    }
}

/// Where a gap nothing explains lies: one channel, its regimes and windows.
#[derive(Debug, Clone, Serialize)]
pub struct Unexplained {
    pub channel: String,
    pub chi2_per_sample: f64,
    /// Regimes (thrust states) in which the channel disagrees significantly.
    pub regimes: Vec<String>,
    /// Time windows (start s, end s, chi2 per sample) in which it does.
    pub windows: Vec<(f64, f64, f64)>,
}

/// Gap measures against the noise floor alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawGap {
    pub excess_before: f64,
    pub excess_after: f64,
    pub heldout_before: f64,
    pub heldout_after: f64,
}

impl RawGap {
    pub fn heldout_reduction_pct(&self) -> f64 {
        reduction_pct(self.heldout_before, self.heldout_after)
    }
}

/// Everything `gap` found.
#[derive(Debug, Clone)]
pub struct Analysis {
    pub before: Vec<ChannelStats>,
    pub after: Vec<ChannelStats>,
    /// Candidate results of each greedy round, best first.
    pub rounds: Vec<Vec<Candidate>>,
    /// The two effects the last round could not tell apart, its winner first
    /// ([`candidate::Selection::ambiguous`]).
    pub ambiguous: Option<[String; 2]>,
    /// A round whose two look-alikes the search carried on past
    /// ([`candidate::select_past_ties`]): neither is named, and the model carries its winner.
    pub tie: Option<Tie>,
    /// The candidate the last round's winner was not named for
    /// ([`candidate::Selection::outranked_by`]).
    pub outranked_by: Option<candidate::Outranked>,
    /// Winners refused when taken into the model, in order
    /// ([`candidate::Selection::refused`]).
    pub refused: Vec<candidate::Refused>,
    pub accepted: Vec<Candidate>,
    pub verdict: Verdict,
    pub fitted: GapModel,
    /// Channels present in the data that the re-simulation does not model.
    pub unmodelled: Vec<String>,
    /// Mean distance between measured and simulated track at matched times (thesis [49]).
    pub track_distance_before_m: Option<f64>,
    pub track_distance_after_m: Option<f64>,
    /// The gap measure ([`excess`]: per channel, chi2 per sample over the model's known
    /// level) over the whole run, before and after.
    pub excess_before: f64,
    pub excess_after: f64,
    pub gap_reduction_pct: f64,
    /// The same gap measure on the held-out blocks only (data no fit saw), before and after.
    pub heldout_gap_before: f64,
    pub heldout_gap_after: f64,
    pub heldout_reduction_pct: f64,
    /// The same measures against the noise floor alone (without the calibrated model's known
    /// disagreement); equal to the above for a model without a `[discrepancy]`.
    pub raw: RawGap,
    /// Channels still significantly off after the accepted effects, with where.
    pub unexplained: Vec<Unexplained>,
    /// Each accepted effect's share of the shrink (percent, in `accepted` order): how much
    /// the gap grows back when that effect alone is left out, over the sum of those growths.
    pub shares_pct: Vec<f64>,
    /// How the re-simulation was cut and the data split.
    pub shooting: anchor::Shooting,
    pub split: fit::Split,
    /// Traces for the plots.
    pub clean_before: resim::Run,
    pub clean_after: resim::Run,
    pub configs_before: Configs,
    pub configs_after: Configs,
    pub floors: Vec<Option<resim::Floor>>,
    /// For each look-alike pair of [`Analysis::ties`], in order, where the two effects'
    /// predictions differ ([`crate::gap::contrast`]); a pair whose changes are not known is
    /// left out.
    pub contrasts: Vec<crate::gap::contrast::Contrast>,
}
