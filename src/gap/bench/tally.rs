//! `gap-bench tally FILE...`: totals over campaigns from the files `gap-bench --out` and
//! `gap-bench merge --out` write (the table, then one CSV line per case), so that a record
//! over many campaigns is the output of one command, never a sum made by hand.
//!
//! Every figure is counted with the rules the tables use ([`CaseResult::correct`],
//! [`CaseResult::wrong`], [`CaseResult::any_wrong`], [`CaseResult::false_alarm`]): a
//! single effect's first name at >= 3 sigma, a wrong first name over all single effects, the
//! nulls' false alarms, both of two named (over all pairs, and over those whose weaker effect
//! shows at >= 3 sigma) and a pair naming an effect not hidden.

use std::path::Path;

use super::CaseResult;
use super::table::{CaseRow, PAIRS_ROW};
use crate::gap::GapError;

/// The first line of the per-case CSV, up to its third column.
const CSV_HEADER: &str = "index,effect,seed,";

/// One campaign's file: its cases and how much its calibration shrank the gap of the null
/// run it was not fitted to.
#[derive(Debug, Clone, PartialEq)]
pub struct Campaign {
    /// The file's name without its extension.
    pub name: String,
    pub cases: Vec<CaseResult>,
    /// `(NN % smaller)` of the file's `calibration (...)` line, when it has one.
    pub calibration_pct: Option<f64>,
}

/// Reads a campaign's file.
pub fn read(path: &Path) -> Result<Campaign, GapError> {
    let text = std::fs::read_to_string(path).map_err(|source| GapError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let origin = path.display().to_string();
    let name = path
        .file_stem()
        .map_or_else(|| origin.clone(), |s| s.to_string_lossy().into_owned());
    parse(&origin, name, &text)
}

/// Parses a campaign file's text (`origin` names it in errors).
pub fn parse(origin: &str, name: String, text: &str) -> Result<Campaign, GapError> {
    let start = text
        .lines()
        .position(|l| l.starts_with(CSV_HEADER))
        .ok_or_else(|| {
            GapError::Data(format!(
                "{origin}: no per-case CSV (a line starting `{CSV_HEADER}`): expected a file \
                 written by `gap-bench --out` or `gap-bench merge --out`"
            ))
        })?;
    let csv_text: String = text
        .lines()
        .skip(start)
        .take_while(|l| !l.trim().is_empty())
        .map(|l| format!("{l}\n"))
        .collect();
    let mut reader = csv::ReaderBuilder::new().from_reader(csv_text.as_bytes());
    let mut cases = Vec::new();
    for row in reader.deserialize::<CaseRow>() {
        let row = row.map_err(|e| {
            let line = start + e.position().map_or(1, |p| p.line() as usize);
            GapError::Csv {
                origin: origin.to_string(),
                line,
                column: "-".into(),
                message: format!("{e}: expected a row of `gap-bench`'s per-case CSV"),
            }
        })?;
        let line = start + 2 + cases.len();
        cases.push(case_of(row).map_err(|(column, message)| GapError::Csv {
            origin: origin.to_string(),
            line,
            column: column.into(),
            message,
        })?);
    }
    Ok(Campaign {
        name,
        cases,
        calibration_pct: calibration_pct(text),
    })
}

/// The first `(NN % smaller)` on the line starting `calibration (`.
fn calibration_pct(text: &str) -> Option<f64> {
    let line = text.lines().find(|l| l.starts_with("calibration ("))?;
    let end = line.find(" % smaller)")?;
    let open = line[..end].rfind('(')?;
    line[open + 1..end].trim().parse().ok()
}

/// A CSV row back to the case it was written from; `Err((column, why))` on a cell that
/// does not read.
fn case_of(row: CaseRow) -> Result<CaseResult, (&'static str, String)> {
    let null = row.effect == "null" || row.effect.starts_with("null (");
    let list = |column: &'static str, cell: &str| -> Result<Vec<f64>, (&'static str, String)> {
        cell.split(';')
            .filter(|v| !v.is_empty())
            .map(|v| {
                v.parse()
                    .map_err(|_| (column, format!("`{v}` is not a number")))
            })
            .collect()
    };
    let pair = |cell: &str| -> Option<[String; 2]> {
        let (a, b) = cell.split_once(';')?;
        Some([a.to_string(), b.to_string()])
    };
    let ci95 = row
        .ci95
        .split(';')
        .filter(|v| !v.is_empty())
        .map(|v| {
            let (lo, hi) = v
                .split_once(':')
                .ok_or(("ci95", format!("`{v}` is not LOW:HIGH")))?;
            match (lo.parse(), hi.parse()) {
                (Ok(lo), Ok(hi)) => Ok([lo, hi]),
                _ => Err(("ci95", format!("`{v}` is not LOW:HIGH"))),
            }
        })
        .collect::<Result<Vec<_>, _>>()?;
    let runner_up = match row.runner_up.rsplit_once(':') {
        None => None,
        Some((n, m)) => Some((
            n.to_string(),
            m.parse()
                .map_err(|_| ("runner_up", format!("`{m}` is not a number")))?,
        )),
    };
    Ok(CaseResult {
        index: row.index,
        label: if row.expected_second.is_some() {
            PAIRS_ROW.to_string()
        } else {
            row.effect.clone()
        },
        effect: (!null).then_some(row.effect),
        expected: row.expected,
        seed: row.seed,
        truth: list("truth", &row.truth)?,
        size_sigma: row.size_sigma,
        named: row.named,
        expected_second: row.expected_second,
        named_all: row
            .named_all
            .split(';')
            .filter(|n| !n.is_empty())
            .map(str::to_string)
            .collect(),
        fitted: list("fitted", &row.fitted)?,
        ci95,
        parameter_error: row.parameter_error,
        ci_covers: row.ci_covers,
        held_out_reduction_pct: row.held_out_reduction_pct,
        held_out_truth_reduction_pct: row.held_out_truth_reduction_pct,
        held_out_raw_reduction_pct: row.held_out_raw_reduction_pct,
        held_out_grew: row.held_out_grew,
        ambiguous: pair(&row.ambiguous),
        tie: pair(&row.tie),
        runner_up,
        verdict: (!row.verdict.is_empty()).then_some(row.verdict),
        seconds: row.seconds,
    })
}

/// Counts over some campaigns' cases.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counts {
    /// Single effects at >= 3 sigma, and those whose first name is right.
    pub big: usize,
    pub big_right: usize,
    /// Single effects, and those whose first name is another effect.
    pub singles: usize,
    pub singles_wrong: usize,
    /// Null cases, and those that raised an alarm.
    pub nulls: usize,
    pub nulls_alarm: usize,
    /// Two-effect cases, those naming both, and those naming an effect not hidden.
    pub pairs: usize,
    pub pairs_both: usize,
    pub pairs_not_hidden: usize,
    /// Two-effect cases whose weaker effect shows at >= 3 sigma, and those naming both.
    pub big_pairs: usize,
    pub big_pairs_both: usize,
}

impl Counts {
    pub fn of(cases: &[CaseResult]) -> Self {
        let mut c = Self::default();
        for r in cases {
            if r.effect.is_none() {
                c.nulls += 1;
                c.nulls_alarm += usize::from(r.false_alarm());
            } else if r.is_pair() {
                c.pairs += 1;
                c.pairs_both += usize::from(r.correct());
                c.pairs_not_hidden += usize::from(r.any_wrong());
                if r.size_sigma.is_some_and(|s| s >= 3.0) {
                    c.big_pairs += 1;
                    c.big_pairs_both += usize::from(r.correct());
                }
            } else {
                c.singles += 1;
                c.singles_wrong += usize::from(r.wrong());
                if r.size_sigma.is_some_and(|s| s >= 3.0) {
                    c.big += 1;
                    c.big_right += usize::from(r.correct());
                }
            }
        }
        c
    }
}

fn share(num: usize, den: usize) -> String {
    if den == 0 {
        "-".into()
    } else {
        format!("{num}/{den} ({:.1} %)", 100.0 * num as f64 / den as f64)
    }
}

fn median_seconds(cases: &[&CaseResult]) -> String {
    use statrs::statistics::{Data, Median};
    if cases.is_empty() {
        return "-".into();
    }
    let s: Vec<f64> = cases.iter().map(|c| c.seconds).collect();
    format!("{:.1}", Data::new(s).median())
}

fn row(name: &str, calibration: &str, cases: &[CaseResult]) -> String {
    let c = Counts::of(cases);
    let singles: Vec<&CaseResult> = cases
        .iter()
        .filter(|r| r.effect.is_some() && !r.is_pair())
        .collect();
    let pairs: Vec<&CaseResult> = cases.iter().filter(|r| r.is_pair()).collect();
    format!(
        "| {name} | {calibration} | {} | {} | {} | {} | {} | {} | {} | {} |",
        share(c.big_right, c.big),
        share(c.singles_wrong, c.singles),
        share(c.nulls_alarm, c.nulls),
        share(c.pairs_both, c.pairs),
        share(c.big_pairs_both, c.big_pairs),
        share(c.pairs_not_hidden, c.pairs),
        median_seconds(&singles),
        median_seconds(&pairs),
    )
}

/// The tally's markdown table: a row per campaign and one for all of them.
pub fn table(campaigns: &[Campaign]) -> String {
    let pct = |p: Option<f64>| p.map_or("-".to_string(), |p| format!("{p:.0} %"));
    let mut out = String::from(
        "| campaign | calibration | first name right, >= 3 sigma | wrong first name | \
         false alarm on nulls | both of two named | both, weaker >= 3 sigma | \
         pair naming one not hidden | median s/case, single | median s/case, pair |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    for c in campaigns {
        out += &row(&c.name, &pct(c.calibration_pct), &c.cases);
        out.push('\n');
    }
    let all: Vec<CaseResult> = campaigns.iter().flat_map(|c| c.cases.clone()).collect();
    let shrinks: Vec<f64> = campaigns.iter().filter_map(|c| c.calibration_pct).collect();
    let range = match (
        shrinks.iter().copied().reduce(f64::min),
        shrinks.iter().copied().reduce(f64::max),
    ) {
        (Some(lo), Some(hi)) => format!("{lo:.0}-{hi:.0} %"),
        _ => "-".into(),
    };
    out += &row(&format!("all {}", campaigns.len()), &range, &all);
    out.push('\n');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "index,effect,seed,size_sigma,named,expected,expected_second,named_all,\
truth,fitted,ci95,parameter_error,ci_covers,held_out_reduction_pct,held_out_truth_reduction_pct,\
held_out_raw_reduction_pct,held_out_grew,ambiguous,tie,runner_up,verdict,seconds";

    fn file(rows: &[&str]) -> String {
        format!(
            "# gap-bench\n\ncalibration (3 baseline runs, scored on a further null run): gap 7.89 -> 0.93 \
             (88 % smaller); on the spread runs: gap 7.98 -> 0.94 (87 % smaller), 114 s\n\n\
             | effect | cases |\n|---|---|\n\n{HEADER}\n{}\n",
            rows.join("\n")
        )
    }

    /// Every kind of case counts where the tables count it: a right single at >= 3 sigma, a
    /// wrong one under 3 sigma (counted wrong, not in the >= 3 sigma column), a null naming
    /// nothing and one ending `unexplained`, a pair naming both and a third not hidden.
    #[test]
    fn a_file_is_counted_as_its_tables_count() {
        let text = file(&[
            "0,thrust_gain,1,5.0,thrust_gain,thrust_gain,,thrust_gain,-0.2,-0.19,-0.25:-0.13,,,90,,50,false,,,,effect,9.0",
            "1,yaw_damping,2,2.0,sway_yaw_coupling,yaw_damping,,sway_yaw_coupling,0.5,3.0,1:5,,,80,,40,false,,,,effect,11.0",
            "2,null,3,,,,,,,,,,,,,,,,,,none,5.0",
            "3,null,4,,,,,,,,,,,,,,,,,,unexplained,6.0",
            "4,thrust_gain+compass_offset,5,4.0,thrust_gain,thrust_gain,compass_offset,thrust_gain;compass_offset;added_mass,-0.2,-0.2,-0.3:-0.1,,,90,,60,false,,yaw_damping;sway_yaw_coupling,added_mass:12.5,effect,17.0",
        ]);
        let c = parse("t.md", "t".into(), &text).expect("parses");
        assert_eq!(c.calibration_pct, Some(88.0));
        assert_eq!(c.cases.len(), 5);
        assert_eq!(
            c.cases[4].tie,
            Some(["yaw_damping".into(), "sway_yaw_coupling".into()])
        );
        assert_eq!(c.cases[4].runner_up, Some(("added_mass".into(), 12.5)));
        let n = Counts::of(&c.cases);
        assert_eq!(
            n,
            Counts {
                big: 1,
                big_right: 1,
                singles: 2,
                singles_wrong: 1,
                nulls: 2,
                nulls_alarm: 1,
                pairs: 1,
                pairs_both: 1,
                pairs_not_hidden: 1,
                big_pairs: 1,
                big_pairs_both: 1,
            }
        );
        let t = table(&[c.clone(), c]);
        let all = t.lines().last().expect("a total row");
        assert!(
            all.starts_with("| all 2 | 88-88 % | 2/2 (100.0 %) | 2/4 (50.0 %) |"),
            "{all}"
        );
        assert!(
            all.contains(
                "| 2/4 (50.0 %) | 2/2 (100.0 %) | 2/2 (100.0 %) | 2/2 (100.0 %) | 10.0 | 17.0 |"
            ),
            "{all}"
        );
    }

    /// A file without the per-case CSV, or with a cell that does not read, is refused with
    /// the file, the line and what was expected.
    #[test]
    fn a_file_that_is_not_a_campaign_is_refused_by_name() {
        let e = parse("notes.md", "notes".into(), "# notes\n").expect_err("no CSV");
        assert!(e.to_string().contains("notes.md: no per-case CSV"), "{e}");
        let text = file(&[
            "0,thrust_gain,1,5.0,thrust_gain,thrust_gain,,thrust_gain,-0.2,-0.19,-0.25/-0.13,,,90,,50,false,,,,effect,9.0",
        ]);
        let e = parse("bad.md", "bad".into(), &text).expect_err("a bad interval");
        let msg = e.to_string();
        assert!(
            msg.contains("bad.md:") && msg.contains("ci95") && msg.contains("LOW:HIGH"),
            "{msg}"
        );
        let text = file(&["0,thrust_gain,one,5.0"]);
        let e = parse("short.md", "short".into(), &text).expect_err("a bad seed");
        assert!(e.to_string().contains("short.md:"), "{e}");
    }
}
