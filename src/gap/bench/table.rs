//! The benchmark's markdown table: one row per effect and for the nulls, a group row, and
//! overall. Each source has its own columns.

use crate::gap::bench::{CalibrationGap, CaseResult, Source};
use crate::gap::effects;

/// The median (of an even count: the mean of the middle two); `None` for none.
fn median(v: Vec<f64>) -> Option<f64> {
    use statrs::statistics::{Data, Median};
    (!v.is_empty()).then(|| Data::new(v).median())
}

fn pct(num: usize, den: usize) -> String {
    if den == 0 {
        "-".to_string()
    } else {
        format!("{:.0} % ({num}/{den})", 100.0 * num as f64 / den as f64)
    }
}

fn opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.map_or("-".to_string(), f)
}

/// A row's cases split: hidden-effect cases, nulls, and the hidden ones at >= 3 sigma.
struct Split<'a> {
    hidden: Vec<&'a CaseResult>,
    nulls: Vec<&'a CaseResult>,
    big: Vec<&'a CaseResult>,
}

impl<'a> Split<'a> {
    fn of(cases: &[&'a CaseResult]) -> Self {
        let (hidden, nulls): (Vec<&CaseResult>, Vec<&CaseResult>) =
            cases.iter().partition(|c| c.effect.is_some());
        let big = hidden
            .iter()
            .copied()
            .filter(|c| c.size_sigma.is_some_and(|s| s >= 3.0))
            .collect();
        Self { hidden, nulls, big }
    }

    /// The naming columns every source shows: correct name, at >= 3 sigma, wrong name,
    /// any wrong name (first or later), false alarm.
    fn naming(&self) -> String {
        let (hidden, big, nulls) = (&self.hidden, &self.big, &self.nulls);
        format!(
            "{} | {} | {} | {} | {}",
            pct(hidden.iter().filter(|c| c.correct()).count(), hidden.len()),
            pct(big.iter().filter(|c| c.correct()).count(), big.len()),
            pct(hidden.iter().filter(|c| c.wrong()).count(), hidden.len()),
            pct(
                hidden.iter().filter(|c| c.any_wrong()).count(),
                hidden.len()
            ),
            pct(
                nulls.iter().filter(|c| c.false_alarm()).count(),
                nulls.len()
            ),
        )
    }
}

fn simulator_row(label: &str, cases: &[&CaseResult]) -> String {
    let split = Split::of(cases);
    let hidden = &split.hidden;
    let perr = median(hidden.iter().filter_map(|c| c.parameter_error).collect());
    let cover: Vec<bool> = hidden.iter().filter_map(|c| c.ci_covers).collect();
    let held = median(
        hidden
            .iter()
            .filter_map(|c| c.held_out_reduction_pct)
            .collect(),
    );
    let held_truth = median(
        hidden
            .iter()
            .filter_map(|c| c.held_out_truth_reduction_pct)
            .collect(),
    );
    let secs = median(cases.iter().map(|c| c.seconds).collect());
    format!(
        "| {label} | {} | {} | {} | {} | {} | {} | {} |",
        cases.len(),
        split.naming(),
        opt(perr, |v| format!("{:.1} %", 100.0 * v)),
        pct(cover.iter().filter(|c| **c).count(), cover.len()),
        opt(held, |v| format!("{v:.0} %")),
        opt(held_truth, |v| format!("{v:.0} %")),
        opt(secs, |v| format!("{v:.2}")),
    )
}

/// The benchmark table (markdown) of `source`; the independent source's starts with the
/// calibration's line.
pub fn table(
    source: Source,
    results: &[CaseResult],
    calibration: Option<&CalibrationGap>,
) -> String {
    match source {
        Source::Simulator => simulator_table(results),
        Source::Independent | Source::Bridge => independent_table(results, calibration),
    }
}

/// The row labels in order of first appearance (the case order).
fn labels(results: &[CaseResult]) -> Vec<&str> {
    let mut names: Vec<&str> = Vec::new();
    for r in results {
        if !names.contains(&r.label.as_str()) {
            names.push(&r.label);
        }
    }
    names
}

/// The simulator source's table: per effect, nulls, the gains-offsets-current group and
/// overall.
pub fn simulator_table(results: &[CaseResult]) -> String {
    let mut s = String::from(
        "| effect | cases | correct name | correct name >= 3 sigma | wrong name | any wrong name | false alarm | median param error | CI95 covers truth | held-out reduction (data) | held-out reduction (vs truth) | s/case |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for n in labels(results) {
        let cases: Vec<&CaseResult> = results.iter().filter(|r| r.label == n).collect();
        s.push_str(&simulator_row(n, &cases));
        s.push('\n');
    }
    // The parameter-error target is for gains, offsets and the current.
    let target: Vec<&CaseResult> = results
        .iter()
        .filter(|r| {
            r.effect
                .as_deref()
                .and_then(effects::by_name)
                .is_some_and(|e| e.parameter_error_target)
        })
        .collect();
    if !target.is_empty() {
        s.push_str(&simulator_row("gains, offsets and current", &target));
        s.push('\n');
    }
    let all: Vec<&CaseResult> = results.iter().collect();
    s.push_str(&simulator_row("overall", &all));
    s.push('\n');
    s
}

/// One row of the independent source's table.
fn independent_row(label: &str, cases: &[&CaseResult]) -> String {
    let split = Split::of(cases);
    let held = median(
        cases
            .iter()
            .filter_map(|c| c.held_out_reduction_pct)
            .collect(),
    );
    let held_raw = median(
        cases
            .iter()
            .filter_map(|c| c.held_out_raw_reduction_pct)
            .collect(),
    );
    let grew = cases
        .iter()
        .filter(|c| c.held_out_grew == Some(true))
        .count();
    let named = cases.iter().filter(|c| c.named.is_some()).count();
    let size = median(split.hidden.iter().filter_map(|c| c.size_sigma).collect());
    let secs = median(cases.iter().map(|c| c.seconds).collect());
    format!(
        "| {label} | {} | {} | {} | {} | {} | {} | {} |",
        cases.len(),
        split.naming(),
        opt(held, |v| format!("{v:.0} %")),
        opt(held_raw, |v| format!("{v:.0} %")),
        pct(grew, named),
        opt(size, |v| format!("{v:.1}")),
        opt(secs, |v| format!("{v:.2}")),
    )
}

/// The independent source's table: the calibration's gap on a null run it was not fitted
/// to, then per effect (the independent model's names), nulls, overall and the two-effect
/// cases' row ([`PAIRS_ROW`]). "correct name"
/// for an effect the library has no counterpart for is no name at all; "wrong name" counts
/// hidden-effect cases whose first name is another effect (worse than none), "any wrong
/// name" those naming, first or later, any effect that was not hidden; "size" is the
/// post-hoc size in sigma of the right candidate in round 1; the held-out reduction is
/// against the calibrated model's known disagreement, then against the noise floor alone;
/// "fit grew held-out gap" counts,
/// among the cases where an effect was named, those whose held-out gap grew.
pub fn independent_table(results: &[CaseResult], calibration: Option<&CalibrationGap>) -> String {
    let mut s = String::new();
    if let Some(c) = calibration {
        s.push_str(&format!(
            "calibration ({} baseline run{}, scored on a further null run): gap {:.2} -> {:.2} ({:.0} % smaller){}, {:.0} s\n\n",
            c.baselines,
            if c.baselines == 1 { "" } else { "s" },
            c.gap_before,
            c.gap_after,
            c.reduction_pct,
            c.spread_clause(),
            c.seconds
        ));
    }
    s.push_str(
        "| effect | cases | correct name | correct name >= 3 sigma | wrong name | any wrong name | false alarm | median held-out reduction | same, noise floor only | fit grew held-out gap | median size (sigma) | s/case |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let (pairs, single): (Vec<&CaseResult>, Vec<&CaseResult>) =
        results.iter().partition(|r| r.is_pair());
    for n in labels(results) {
        let cases: Vec<&CaseResult> = single.iter().copied().filter(|r| r.label == n).collect();
        if !cases.is_empty() {
            s.push_str(&independent_row(n, &cases));
            s.push('\n');
        }
    }
    s.push_str(&independent_row("overall", &single));
    s.push('\n');
    if !pairs.is_empty() {
        s.push_str(&independent_row(PAIRS_ROW, &pairs));
        s.push('\n');
    }
    s.push_str(&pointing_line(&single, &pairs));
    s
}

/// The line under the independent source's table: how often the answer points at the truth
/// and at nothing else ([`CaseResult::points_at_truth`]), right names and honest
/// `ambiguous` verdicts together; the table's "correct name" columns count names only.
fn pointing_line(single: &[&CaseResult], pairs: &[&CaseResult]) -> String {
    let split = Split::of(single);
    let points = |v: &[&CaseResult]| v.iter().filter(|c| c.points_at_truth()).count();
    let pairs: Vec<&CaseResult> = pairs
        .iter()
        .copied()
        .filter(|c| c.effect.is_some())
        .collect();
    let mut line = format!(
        "\nright name, or `ambiguous` between the truth and one look-alike, with no other name: {}, at >= 3 sigma {}",
        pct(points(&split.hidden), split.hidden.len()),
        pct(points(&split.big), split.big.len()),
    );
    if !pairs.is_empty() {
        line.push_str(&format!(
            "; two effects, each named or in the ambiguous pair: {}",
            pct(points(&pairs), pairs.len())
        ));
    }
    let (led, lookalikes) = single
        .iter()
        .chain(&pairs)
        .map(|c| c.lookalikes_led_by_truth())
        .fold((0, 0), |(l, n), (a, b)| (l + a, n + b));
    if lookalikes > 0 {
        line.push_str(&format!(
            "\nlook-alike pairs left `ambiguous` or carried past that hold one hidden effect: its \
             round's winner is the hidden one in {} (named by the winner, the rest would be wrong \
             names)",
            pct(led, lookalikes)
        ));
    }
    line.push('\n');
    line
}

/// The row of the cases with two hidden effects, below "overall": "correct name" there is
/// both effects named, "wrong name" any other name among those accepted.
pub const PAIRS_ROW: &str = "two effects (both named)";

/// One line of the per-case CSV that `gap-bench --out` writes after the table. A list is
/// one cell, its values joined by `;` (an interval as `low:high`); an empty cell is "none".
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CaseRow {
    pub index: usize,
    /// The source's name of the hidden effect (`A+B` for two), or the null row's label.
    pub effect: String,
    pub seed: u64,
    pub size_sigma: Option<f64>,
    pub named: Option<String>,
    /// The right answer (the library effect; a two-effect case: the first one's).
    pub expected: Option<String>,
    /// Two-effect cases: the second effect's right answer.
    pub expected_second: Option<String>,
    /// Every effect named, in order.
    pub named_all: String,
    pub truth: String,
    pub fitted: String,
    pub ci95: String,
    pub parameter_error: Option<f64>,
    pub ci_covers: Option<bool>,
    pub held_out_reduction_pct: Option<f64>,
    pub held_out_truth_reduction_pct: Option<f64>,
    pub held_out_raw_reduction_pct: Option<f64>,
    pub held_out_grew: Option<bool>,
    /// The two look-alikes the search ended on, `A;B`.
    #[serde(default)]
    pub ambiguous: String,
    /// The two look-alikes the search carried on past, `A;B` (the model carries `A`).
    #[serde(default)]
    pub tie: String,
    /// The first round's best other passing candidate and its delta-BIC margin behind the
    /// winner, `NAME:MARGIN`.
    #[serde(default)]
    pub runner_up: String,
    /// The analysis's verdict (empty: not recorded).
    #[serde(default)]
    pub verdict: String,
    pub seconds: f64,
}

fn joined(values: impl Iterator<Item = String>) -> String {
    values.collect::<Vec<_>>().join(";")
}

impl From<&CaseResult> for CaseRow {
    fn from(r: &CaseResult) -> Self {
        Self {
            index: r.index,
            effect: r.effect.clone().unwrap_or_else(|| r.label.clone()),
            seed: r.seed,
            size_sigma: r.size_sigma,
            named: r.named.clone(),
            expected: r.expected.clone(),
            expected_second: r.expected_second.clone(),
            named_all: r.named_all.join(";"),
            truth: joined(r.truth.iter().map(f64::to_string)),
            fitted: joined(r.fitted.iter().map(f64::to_string)),
            ci95: joined(r.ci95.iter().map(|[lo, hi]| format!("{lo}:{hi}"))),
            parameter_error: r.parameter_error,
            ci_covers: r.ci_covers,
            held_out_reduction_pct: r.held_out_reduction_pct,
            held_out_truth_reduction_pct: r.held_out_truth_reduction_pct,
            held_out_raw_reduction_pct: r.held_out_raw_reduction_pct,
            held_out_grew: r.held_out_grew,
            ambiguous: r.ambiguous.as_ref().map_or(String::new(), |a| a.join(";")),
            tie: r.tie.as_ref().map_or(String::new(), |a| a.join(";")),
            runner_up: r
                .runner_up
                .as_ref()
                .map_or(String::new(), |(n, m)| format!("{n}:{m:.1}")),
            verdict: r.verdict.clone().unwrap_or_default(),
            seconds: r.seconds,
        }
    }
}

/// The per-case CSV (header and one row per case), written by the `csv` crate so that any
/// CSV reader reads it back.
pub fn cases_csv(results: &[CaseResult]) -> Result<String, csv::Error> {
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    for r in results {
        w.serialize(CaseRow::from(r))?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| csv::Error::from(e.into_error()))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn case(effect: Option<&'static str>, error: Option<f64>) -> CaseResult {
        CaseResult {
            index: 0,
            effect: effect.map(str::to_string),
            expected: effect.map(str::to_string),
            label: effect.unwrap_or("null").to_string(),
            seed: 0,
            truth: vec![1.0],
            size_sigma: Some(5.0),
            named: effect.map(str::to_string),
            expected_second: None,
            named_all: effect.map(str::to_string).into_iter().collect(),
            fitted: vec![1.0],
            ci95: vec![[0.0, 2.0]],
            parameter_error: error,
            ci_covers: error.map(|_| true),
            held_out_reduction_pct: effect.map(|_| 90.0),
            held_out_truth_reduction_pct: effect.map(|_| 90.0),
            held_out_raw_reduction_pct: effect.map(|_| 20.0),
            held_out_grew: None,
            ambiguous: None,
            tie: None,
            runner_up: None,
            verdict: Some(if effect.is_some() { "effect" } else { "none" }.to_string()),
            seconds: 1.0,
        }
    }

    /// The group row takes exactly the gains, offsets and current cases: here the median of
    /// 0.02 and 0.04 (water current, hard iron), not the lag's 0.5.
    #[test]
    fn the_gains_offsets_current_row_holds_only_its_effects() {
        let results = [
            case(Some("water_current"), Some(0.02)),
            case(Some("compass_hard_iron"), Some(0.04)),
            case(Some("thruster_lag"), Some(0.5)),
            case(None, None),
        ];
        let t = simulator_table(&results);
        let group = t
            .lines()
            .find(|l| l.starts_with("| gains, offsets and current |"))
            .expect("the group row");
        assert!(group.contains("| 2 | 100 % (2/2) |"), "{group}");
        assert!(group.contains("| 0 % (0/2) |"), "no wrong name: {group}");
        assert!(group.contains("| 3.0 % |"), "{group}");
        let overall = t.lines().find(|l| l.starts_with("| overall |")).unwrap();
        assert!(overall.contains("| 4 |"), "{overall}");
    }

    /// A null case is a false alarm when it names an effect or ends `unexplained`: either
    /// sends the user after a cause that is not there. A part file without a verdict counts
    /// its names only.
    #[test]
    fn a_null_called_unexplained_is_a_false_alarm() {
        let verdict = |v: Option<&str>| CaseResult {
            verdict: v.map(str::to_string),
            ..case(None, None)
        };
        let nulls = [
            verdict(Some("none")),
            verdict(Some("unexplained")),
            verdict(Some("ambiguous")),
            verdict(None),
        ];
        let alarms: Vec<bool> = nulls.iter().map(CaseResult::false_alarm).collect();
        assert_eq!(alarms, [false, true, true, false]);
        let t = simulator_table(&nulls);
        let row = t.lines().find(|l| l.starts_with("| overall |")).unwrap();
        assert!(row.contains("| 50 % (2/4) |"), "{row}");
    }

    /// The per-case CSV reads back through `csv::Reader` as the rows that were written,
    /// lists, intervals and empty values included (it once wrote Rust's `Some(x)` and `[a, b]`).
    #[test]
    fn the_per_case_csv_round_trips_through_a_csv_reader() {
        let case = |index: usize, named: Option<&str>| CaseResult {
            index,
            effect: Some("sway, drag \"quoted\"".into()),
            expected: Some("sway_drag".into()),
            label: "sway, drag \"quoted\"".into(),
            seed: 7,
            truth: vec![0.25, -1.5],
            size_sigma: named.map(|_| 4.2),
            named: named.map(str::to_string),
            expected_second: None,
            named_all: named.map(str::to_string).into_iter().collect(),
            fitted: vec![0.26, -1.4],
            ci95: vec![[0.2, 0.3], [-1.7, -1.1]],
            parameter_error: Some(0.06),
            ci_covers: Some(true),
            held_out_reduction_pct: None,
            held_out_truth_reduction_pct: Some(12.5),
            held_out_raw_reduction_pct: None,
            held_out_grew: Some(false),
            ambiguous: None,
            tie: None,
            runner_up: Some(("yaw_damping".into(), 12.5)),
            verdict: Some("effect".into()),
            seconds: 17.25,
        };
        let results = [case(0, Some("sway_drag")), case(1, None)];
        let text = cases_csv(&results).unwrap();
        assert!(!text.contains("Some("), "{text}");
        let mut reader = csv::Reader::from_reader(text.as_bytes());
        let back: Vec<CaseRow> = reader.deserialize().collect::<Result<_, _>>().unwrap();
        let want: Vec<CaseRow> = results.iter().map(CaseRow::from).collect();
        assert_eq!(back, want);
        assert_eq!(back[1].named, None);
        assert_eq!(back[0].ci95, "0.2:0.3;-1.7:-1.1");
        assert_eq!(back[0].effect, "sway, drag \"quoted\"");
        assert_eq!(back[0].expected.as_deref(), Some("sway_drag"));
        assert_eq!(back[0].runner_up, "yaw_damping:12.5");
    }

    /// A two-effect case is right when both effects are named, in any order, and wrong when
    /// anything else is named beside them; pair cases get their own row below "overall",
    /// which they do not enter.
    #[test]
    fn two_effect_cases_are_scored_on_both_names() {
        let pair = |named: &[&str]| {
            let mut c = case(Some("water_current"), None);
            c.label = PAIRS_ROW.to_string();
            c.effect = Some("water_current+compass_offset".into());
            c.expected_second = Some("compass_offset".into());
            c.named_all = named.iter().map(|n| n.to_string()).collect();
            c.named = c.named_all.first().cloned();
            c
        };
        let both = pair(&["compass_offset", "water_current"]);
        assert!(both.correct() && !both.wrong());
        let one = pair(&["water_current"]);
        assert!(!one.correct() && !one.wrong());
        let other = pair(&["water_current", "compass_offset", "thrust_gain"]);
        assert!(other.correct() && other.wrong());
        let none = pair(&[]);
        assert!(!none.correct() && !none.wrong());
        let single = case(Some("water_current"), None);
        let results = [single, both, one, other, none];
        let t = independent_table(&results, None);
        let overall = t.lines().find(|l| l.starts_with("| overall |")).unwrap();
        assert!(
            overall.starts_with("| overall | 1 | 100 % (1/1) |"),
            "{overall}"
        );
        let row = t
            .lines()
            .find(|l| l.starts_with(&format!("| {PAIRS_ROW} |")))
            .expect("the two-effect row");
        assert!(
            row.starts_with(&format!("| {PAIRS_ROW} | 4 | 50 % (2/4) |")),
            "{row}"
        );
        assert!(row.contains("| 25 % (1/4) |"), "one wrong name: {row}");
        assert_eq!(t.matches(PAIRS_ROW).count(), 1, "{t}");
    }

    /// "wrong name" reads the first name of a one-effect case; "any wrong name" every name:
    /// a right first name followed by another effect is a wrong name there, as it sends the
    /// user after a cause that is not in the data.
    #[test]
    fn a_later_wrong_name_is_counted_apart_from_the_first() {
        let named = |names: &[&str]| {
            let mut c = case(Some("thruster_lag"), None);
            c.named_all = names.iter().map(|n| n.to_string()).collect();
            c.named = c.named_all.first().cloned();
            c
        };
        let right_then_other = named(&["thruster_lag", "added_mass"]);
        assert!(right_then_other.correct() && !right_then_other.wrong());
        assert!(right_then_other.any_wrong());
        let only_right = named(&["thruster_lag"]);
        assert!(!only_right.any_wrong());
        let other_first = named(&["added_mass"]);
        assert!(other_first.wrong() && other_first.any_wrong());
        let null = case(None, None);
        let t = independent_table(&[right_then_other, only_right, other_first, null], None);
        let row = t
            .lines()
            .find(|l| l.starts_with("| thruster_lag |"))
            .unwrap();
        assert!(
            row.starts_with(
                "| thruster_lag | 3 | 67 % (2/3) | 67 % (2/3) | 33 % (1/3) | 67 % (2/3) | - |"
            ),
            "{row}"
        );
    }
    /// An `ambiguous` verdict between the truth and its look-alike points at the truth; one
    /// between two other effects, or any wrong name beside it, does not. A two-effect case
    /// points at both when each is named or in the ambiguous pair (or a tie carried past).
    #[test]
    fn an_ambiguous_verdict_naming_the_truth_points_at_it() {
        let single = |named: &[&str], ambiguous: Option<[&str; 2]>| {
            let mut c = case(Some("depth_offset"), None);
            c.named_all = named.iter().map(|n| n.to_string()).collect();
            c.named = c.named_all.first().cloned();
            c.ambiguous = ambiguous.map(|a| a.map(str::to_string));
            c
        };
        let tie = single(&[], Some(["depth_gain", "depth_offset"]));
        assert!(tie.points_at_truth() && !tie.correct());
        let elsewhere = single(&[], Some(["depth_gain", "float_depth"]));
        assert!(!elsewhere.points_at_truth());
        let wrong_then_tie = single(&["thrust_gain"], Some(["depth_gain", "depth_offset"]));
        assert!(!wrong_then_tie.points_at_truth());
        let right = single(&["depth_offset"], None);
        assert!(right.points_at_truth());
        assert!(!single(&[], None).points_at_truth());
        assert!(
            !case(None, None).points_at_truth(),
            "a null points at nothing"
        );
        let mut pair = single(&["depth_pwm_emi"], Some(["depth_gain", "depth_offset"]));
        pair.label = PAIRS_ROW.to_string();
        pair.effect = Some("depth_emi+depth_offset".into());
        pair.expected_second = Some("depth_pwm_emi".into());
        assert!(pair.points_at_truth() && !pair.correct());
        let mut half = pair.clone();
        half.named_all.clear();
        assert!(
            !half.points_at_truth(),
            "the EMI is neither named nor in the pair"
        );
        // A tie the search carried on past counts as an ambiguous pair does.
        let mut carried = pair.clone();
        carried.tie = carried.ambiguous.take();
        assert!(carried.points_at_truth());
        let mut elsewhere_carried = carried.clone();
        elsewhere_carried.tie = Some(["depth_gain".into(), "float_depth".into()]);
        assert!(!elsewhere_carried.points_at_truth());
        let t = independent_table(&[tie, elsewhere, right, pair, half], None);
        let line = t
            .lines()
            .find(|l| l.starts_with("right name, or `ambiguous`"))
            .expect("the line");
        assert!(
            line.contains(": 67 % (2/3), at >= 3 sigma 67 % (2/3); two effects, each named or in the ambiguous pair: 50 % (1/2)"),
            "{line}"
        );
    }

    /// The look-alike line counts the pairs that hold exactly one hidden effect, by whether
    /// that effect won its round (listed first): a pair of two other effects says nothing of
    /// the order, and a pair of both hidden effects has no wrong one to name.
    #[test]
    fn the_lookalike_line_counts_pairs_led_by_the_hidden_effect() {
        let with = |ambiguous: Option<[&str; 2]>, tie: Option<[&str; 2]>| {
            let mut c = case(Some("depth_offset"), None);
            c.ambiguous = ambiguous.map(|a| a.map(str::to_string));
            c.tie = tie.map(|a| a.map(str::to_string));
            c
        };
        let led = with(Some(["depth_offset", "depth_gain"]), None);
        assert_eq!(led.lookalikes_led_by_truth(), (1, 1));
        let trailing = with(None, Some(["depth_gain", "depth_offset"]));
        assert_eq!(trailing.lookalikes_led_by_truth(), (0, 1));
        let elsewhere = with(Some(["depth_gain", "float_depth"]), None);
        assert_eq!(elsewhere.lookalikes_led_by_truth(), (0, 0));
        let mut both_hidden = with(Some(["depth_offset", "depth_gain"]), None);
        both_hidden.expected_second = Some("depth_gain".into());
        assert_eq!(both_hidden.lookalikes_led_by_truth(), (0, 0));
        let t = independent_table(&[led, trailing.clone(), trailing, elsewhere], None);
        assert!(
            t.contains("its round's winner is the hidden one in 33 % (1/3)"),
            "{t}"
        );
        let none = independent_table(&[case(Some("depth_offset"), None)], None);
        assert!(!none.contains("look-alike pairs left"), "{none}");
    }
}
