//! The summary workflow's outputs: `report.json`, `report.md` and the plot.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;
use serde_json::{Value, json};

use super::{Bound, ObservationResult, Summary, SummaryAnalysis};
use crate::gap::candidate::Candidate;
use crate::gap::{GapError, fit};

fn finite(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

fn candidate_json(c: &Candidate) -> Value {
    json!({
        "name": c.name,
        "parameters": c.parameters.iter().map(|(k, v)| (k.clone(), json!(v))).collect::<serde_json::Map<_, _>>(),
        "ci95": c.ci95.iter().map(|(k, v)| (k.clone(), json!([finite(v[0]), finite(v[1])]))).collect::<serde_json::Map<_, _>>(),
        "delta_bic": finite(c.delta_bic),
        "chi2_before": c.chi2_before,
        "chi2_after": c.chi2_after,
        "signature_pass": c.signature_pass,
        "signature": c.signature,
        "testable": c.testable,
    })
}

/// `report.json`: `effects`, `verdict`, `gap_before` / `gap_after` (observation -> |z|, the
/// normalised miss), `gap_reduction_pct` (of the RMS of z), and the details.
pub fn json(a: &SummaryAnalysis, s: &Summary) -> Value {
    let gap = |f: fn(&ObservationResult) -> Option<f64>| -> Value {
        a.observations
            .iter()
            .map(|o| (o.name.clone(), f(o).map_or(Value::Null, |z| json!(z.abs()))))
            .collect::<serde_json::Map<_, _>>()
            .into()
    };
    json!({
        "summary": s.name,
        "effects": a.fitted.effects.iter().skip(a.fitted.effects.len() - a.accepted.len()).map(|e| json!({
            "name": e.effect.name,
            "parameters": e.effect.parameters.iter().zip(&e.values).map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
            "ci95": e.effect.parameters.iter().zip(&e.ci95).map(|(k, c)| (k.to_string(), json!([finite(c[0]), finite(c[1])]))).collect::<serde_json::Map<_, _>>(),
            "delta_bic": e.delta_bic,
        })).collect::<Vec<_>>(),
        "verdict": a.verdict,
        "ambiguous": a.ambiguous,
        "bic_margin": fit::BIC_MARGIN,
        "gap_before": gap(|o| o.z_before),
        "gap_after": gap(|o| o.z_after),
        "gap_rms_z_before": a.gap_before,
        "gap_rms_z_after": a.gap_after,
        "gap_reduction_pct": a.gap_reduction_pct,
        "chi2_before": a.chi2_before,
        "chi2_after": a.chi2_after,
        "chi2_critical_95_after": a.chi2_critical_after,
        "consistent_after": a.consistent_after,
        "unexplained": a.unexplained,
        "few_observations": a.few_observations,
        "observations": a.observations,
        "rounds": a.rounds.iter().map(|r| r.iter().map(candidate_json).collect::<Vec<_>>()).collect::<Vec<_>>(),
    })
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{v:.prec$}"))
}

/// `report.md`.
pub fn markdown(a: &SummaryAnalysis, s: &Summary) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "# Reality gap (summary observations): {}\n", s.name);
    if !s.description.is_empty() {
        let _ = writeln!(out, "{}\n", s.description);
    }
    let ambiguous = a.ambiguous.as_ref().map(crate::gap::report::ambiguity);
    let verdict = match (a.accepted.is_empty(), ambiguous) {
        (true, None) => "no significant missing effect".to_string(),
        (true, Some(why)) => format!("**ambiguous**: {why}"),
        (false, then) => format!(
            "missing or wrong: **{}**{}",
            a.accepted
                .iter()
                .map(|c| c.name.as_str())
                .collect::<Vec<_>>()
                .join("**, then **"),
            then.map_or_else(String::new, |why| format!("; then ambiguous: {why}"))
        ),
    };
    let _ = writeln!(
        out,
        "Verdict: {verdict} (rule: delta BIC > {} with k ln(n), n = {} observations, and >= {:.0} % of the improvement from the behaviour the effect acts through).\n",
        fit::BIC_MARGIN,
        a.observations.len(),
        fit::SIGNATURE_MIN_SHARE * 100.0
    );
    if a.few_observations {
        let _ = writeln!(
            out,
            "**Only {} observations.** The BIC's penalty assumes many independent samples; with this few, a named effect is a lead to test with more data, not a proof, and parameters with wide intervals are poorly pinned.\n",
            a.observations.len()
        );
    }
    if a.consistent_after {
        let _ = writeln!(
            out,
            "After fitting, chi2 = {:.1} <= {:.1} (95 % point, {} - k degrees of freedom): the model agrees with the data within the stated uncertainties.\n",
            a.chi2_after,
            a.chi2_critical_after,
            a.observations.len()
        );
    } else {
        let _ = writeln!(
            out,
            "After fitting, chi2 = {:.1} > {:.1} (95 % point): the model still disagrees beyond the stated uncertainties. Still off by more than 2 sigma: {}. No candidate in the library explains them; something else is missing.\n",
            a.chi2_after,
            a.chi2_critical_after,
            if a.unexplained.is_empty() {
                "none individually".to_string()
            } else {
                a.unexplained.join(", ")
            }
        );
    }
    if a.fitted.effects.len() > a.accepted.len() || !a.accepted.is_empty() {
        let _ = writeln!(
            out,
            "## Fitted effects (final values, refitted jointly)\n\n| effect | parameters [95 %] | delta BIC when added |\n|---|---|---|"
        );
        for e in a
            .fitted
            .effects
            .iter()
            .skip(a.fitted.effects.len() - a.accepted.len())
        {
            let p: Vec<String> = e
                .effect
                .parameters
                .iter()
                .zip(&e.values)
                .zip(&e.ci95)
                .map(|((n, v), c)| format!("{n} = {v:.4} [{:.4}, {:.4}]", c[0], c[1]))
                .collect();
            let _ = writeln!(
                out,
                "| {} | {} | {} |",
                e.effect.name,
                p.join("; "),
                e.delta_bic
                    .map_or_else(|| "-".into(), |d| format!("{d:.1}"))
            );
        }
        let _ = writeln!(
            out,
            "\nAn interval of [-inf, inf] marks a parameter the data do not move at the fitted point (a scale on a term the model does not have, or a value held at the edge of its physical range).\n"
        );
    }
    let _ = writeln!(out, "## Observations, before and after\n");
    let _ = writeln!(
        out,
        "| observation | experiment | measured | sigma (meas, model) | model before | z before | model after | z after | source |\n|---|---|---|---|---|---|---|---|---|"
    );
    for o in &a.observations {
        let _ = writeln!(
            out,
            "| {} ({}) | {} | {}{:.3} {} | {:.3}, {:.3} | {} | {} | {} | {} | {} |",
            o.name,
            o.quantity.name(),
            o.experiment,
            match o.bound {
                Bound::Value => "",
                Bound::Upper => "<= ",
                Bound::Lower => ">= ",
            },
            o.measured,
            o.unit,
            o.sigma_measured,
            o.sigma_model,
            opt(o.simulated_before, 3),
            opt(o.z_before, 1),
            opt(o.simulated_after, 3),
            opt(o.z_after, 1),
            o.source
        );
    }
    let _ = writeln!(
        out,
        "\nRMS of z: {:.2} -> {:.2} ({:.0} % smaller).",
        a.gap_before, a.gap_after, a.gap_reduction_pct
    );
    for (i, round) in a.rounds.iter().enumerate() {
        let _ = writeln!(out, "\n## Candidates, round {}\n", i + 1);
        out.push_str(&crate::gap::candidate::round_table(round));
    }
    out
}

fn plot_err(path: &Path, e: impl std::fmt::Display) -> GapError {
    GapError::Plot {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// `observations.svg`: z before (red) and after (blue) per observation, with the +-2 band.
pub fn plot(a: &SummaryAnalysis, out: &Path) -> Result<(), GapError> {
    let path = out.join("observations.svg");
    let n = a.observations.len().max(1);
    let clamp = |z: f64| z.clamp(-40.0, 40.0);
    let zmax = a
        .observations
        .iter()
        .flat_map(|o| [o.z_before, o.z_after])
        .flatten()
        .map(|z| clamp(z).abs())
        .fold(3.0, f64::max)
        * 1.1;
    let root = SVGBackend::new(&path, (900, 120 + 50 * n as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(&path, e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "(sim - measured) / sigma per observation: red = model, blue = model + fitted effects",
            ("sans-serif", 15),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(220)
        .build_cartesian_2d(-zmax..zmax, (0..n).into_segmented())
        .map_err(|e| plot_err(&path, e))?;
    let labels: Vec<String> = a.observations.iter().map(|o| o.name.clone()).collect();
    chart
        .configure_mesh()
        .y_label_formatter(&|v| match v {
            SegmentValue::CenterOf(i) => labels.get(*i).cloned().unwrap_or_default(),
            _ => String::new(),
        })
        .y_labels(n)
        .x_desc("z (clamped to +-40)")
        .draw()
        .map_err(|e| plot_err(&path, e))?;
    for (i, o) in a.observations.iter().enumerate() {
        if let Some(z) = o.z_before {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [
                        (0.0, SegmentValue::Exact(i)),
                        (clamp(z), SegmentValue::Exact(i + 1)),
                    ],
                    RED.mix(0.6).filled(),
                )))
                .map_err(|e| plot_err(&path, e))?;
        }
        if let Some(z) = o.z_after {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [
                        (0.0, SegmentValue::Exact(i)),
                        (clamp(z), SegmentValue::Exact(i + 1)),
                    ],
                    BLUE.mix(0.8).filled(),
                )))
                .map_err(|e| plot_err(&path, e))?;
        }
    }
    for x in [-2.0, 2.0] {
        chart
            .draw_series(LineSeries::new(
                [(x, SegmentValue::Exact(0)), (x, SegmentValue::Exact(n))],
                BLACK,
            ))
            .map_err(|e| plot_err(&path, e))?;
    }
    root.present().map_err(|e| plot_err(&path, e))?;
    Ok(())
}

/// Writes `report.json`, `report.md`, `MODEL.fitted.toml` and `observations.svg` into `out`.
pub fn write_all(
    a: &SummaryAnalysis,
    s: &Summary,
    summary_path: &Path,
    model_path: &Path,
    out: &Path,
) -> Result<(), GapError> {
    let write = crate::gap::report::output_dir(out)?;
    let text =
        serde_json::to_string_pretty(&json(a, s)).map_err(|e| GapError::Data(e.to_string()))?;
    write("report.json", text)?;
    write("report.md", markdown(a, s))?;
    let stem = model_path
        .file_stem()
        .map_or_else(|| "model".to_string(), |x| x.to_string_lossy().into_owned());
    let provenance = format!(
        "Written by `eyebot-hil gap --measured {} --model {}` (eyebot-hil {}).\n\
         Effects fitted by Levenberg-Marquardt on the summary observations `{}` ({} numbers);\n\
         each accepted because it beat \"no effect\" by delta BIC > {} and its improvement came\n\
         from the behaviour it acts through. Parameters are changes relative to the base\n\
         configuration (see docs/gap.md).",
        summary_path.display(),
        model_path.display(),
        env!("CARGO_PKG_VERSION"),
        s.name,
        s.observations.len(),
        fit::BIC_MARGIN
    );
    write(
        &format!("{stem}.fitted.toml"),
        a.fitted.to_toml(&provenance, out),
    )?;
    plot(a, out)
}

/// Observations by name, for tests and callers.
pub fn by_name(a: &SummaryAnalysis) -> BTreeMap<&str, &ObservationResult> {
    a.observations
        .iter()
        .map(|o| (o.name.as_str(), o))
        .collect()
}
