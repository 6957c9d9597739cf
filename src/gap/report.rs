//! The output of `gap`: `report.json`, `report.md`, `MODEL.fitted.toml` and SVG plots.

use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;
use serde_json::{Value, json};

use crate::gap::format::Measurement;
use crate::gap::{Analysis, GapError, fit, resim};

/// `report.json`.
pub fn json(a: &Analysis) -> Value {
    let rms = |s: &[crate::gap::residuals::ChannelStats]| -> Value {
        s.iter()
            .map(|c| (c.channel.clone(), json!(c.rms)))
            .collect::<serde_json::Map<_, _>>()
            .into()
    };
    let effect = |r: &crate::gap::candidate::Candidate| {
        json!({
            "name": r.name,
            "parameters": r.parameters.iter().map(|(k, v)| (k.clone(), json!(v))).collect::<serde_json::Map<_,_>>(),
            "ci95": r.ci95.iter().map(|(k, v)| (k.clone(), json!(v))).collect::<serde_json::Map<_,_>>(),
            "delta_bic": r.delta_bic,
            "signature_pass": r.signature_pass,
            "heldout_chi2_before": r.heldout_chi2_before,
            "heldout_chi2_after": r.heldout_chi2_after,
            "heldout_gain": r.heldout_gain,
            "guards": r.guards,
        })
    };
    let finite = |v: f64| if v.is_finite() { json!(v) } else { Value::Null };
    let mut out = json!({
        "effects": a.accepted.iter().map(effect).collect::<Vec<_>>(),
        "verdict": a.verdict,
        "ambiguous": a.ambiguous,
        "bic_margin": fit::BIC_MARGIN,
        "gap_before": rms(&a.before),
        "gap_after": rms(&a.after),
        "gap_reduction_pct": a.gap_reduction_pct,
        "excess_before": a.excess_before,
        "excess_after": a.excess_after,
        "heldout_gap_before": a.heldout_gap_before,
        "heldout_gap_after": a.heldout_gap_after,
        "heldout_reduction_pct": a.heldout_reduction_pct,
        "known_disagreement": a.fitted.discrepancy,
        "noise_floor_only": {
            "excess_before": a.raw.excess_before,
            "excess_after": a.raw.excess_after,
            "gap_reduction_pct": crate::gap::reduction_pct(a.raw.excess_before, a.raw.excess_after),
            "heldout_gap_before": a.raw.heldout_before,
            "heldout_gap_after": a.raw.heldout_after,
            "heldout_reduction_pct": a.raw.heldout_reduction_pct(),
        },
        "unexplained": a.unexplained,
        "segment_s": a.shooting.segment_s,
        "heldout_block_s": a.split.block_s,
        "track_distance_before_m": a.track_distance_before_m,
        "track_distance_after_m": a.track_distance_after_m,
        "channels_before": a.before,
        "channels_after": a.after,
        "unmodelled_channels": a.unmodelled,
        "rounds": a.rounds.iter().map(|r| r.iter().map(|c| json!({
            "name": c.name, "delta_bic": finite(c.delta_bic),
            "parameters": c.parameters, "ci95": c.ci95.iter().map(|(n, v)| (n.clone(), json!([finite(v[0]), finite(v[1])]))).collect::<serde_json::Map<_,_>>(),
            "signature_pass": c.signature_pass,
            "signature": c.signature, "testable": c.testable,
            "chi2_before": c.chi2_before, "chi2_after": c.chi2_after, "noise_factor": c.noise_factor,
            "variance_factor": c.variance_factor,
            "heldout_chi2_before": c.heldout_chi2_before, "heldout_chi2_after": c.heldout_chi2_after,
            "heldout_gain": c.heldout_gain, "guards": c.guards, "evaluations": c.evaluations,
            "delta_bic_uncalibrated": finite(c.delta_bic_uncalibrated),
        })).collect::<Vec<_>>()).collect::<Vec<_>>(),
    });
    // Segments the re-simulation could not step to their end, before and after the fit.
    if let Some(list) = out["effects"].as_array_mut() {
        for (e, share) in list.iter_mut().zip(&a.shares_pct) {
            e["share_of_shrink_pct"] = json!(share);
        }
    }
    // A tie the search carried on past: its pair, and the winner the fitted model carries.
    out["tie"] = a.tie.as_ref().map_or(Value::Null, |t| {
        let mut carried = effect(&t.carried);
        carried["share_of_shrink_pct"] = finite(t.share_pct);
        json!({ "round": t.round + 1, "pair": t.pair, "carried": carried })
    });
    out["diverged"] = json!({
        "before": a.clean_before.divergences,
        "after": a.clean_after.divergences,
    });
    out["contacts_s"] = json!({
        "before": a.clean_before.contacts,
        "after": a.clean_after.contacts,
    });
    out["where_ties_differ"] = json!(a.contrasts);
    out["outranked_by"] = json!(a.outranked_by);
    out["caution"] = json!(a.fitted.caution());
    out["refused"] = json!(a.refused);
    out
}

/// `report.md`.
pub fn markdown(a: &Analysis, m: &Measurement) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Reality gap: {}\n", m.experiment.name);
    write_verdict(&mut s, a, m);
    write_gap_before(&mut s, a);
    for (i, round) in a.rounds.iter().enumerate() {
        let _ = writeln!(s, "\n## Candidates, round {}\n", i + 1);
        s.push_str(&crate::gap::candidate::round_table(round));
    }
    write_gap_before_after(&mut s, a, m);
    let _ = writeln!(
        s,
        "\n![trajectories](trajectories.svg)\n![residuals](residuals.svg)\n![ranking](ranking.svg)"
    );
    s
}

/// The verdict in words: the named effect, or why none is named.
fn verdict_text(a: &Analysis) -> String {
    match (a.verdict, a.accepted.first()) {
        (_, Some(w)) if a.accepted.len() == 1 => format!("missing effect: **{}**", w.name),
        (_, Some(_)) => {
            let names: Vec<String> = a
                .accepted
                .iter()
                .map(|c| format!("**{}**", c.name))
                .collect();
            format!("missing effects, in the order named: {}", names.join(", "))
        }
        (crate::gap::Verdict::Unexplained, None) if a.fitted.discrepancy.is_empty() => {
            "**unexplained**: the model disagrees with the data beyond its noise floor and no \
             effect in the library passes every guard"
                .to_string()
        }
        (crate::gap::Verdict::Unexplained, None) => {
            "**unexplained**: the model disagrees with the data beyond its noise floor and its \
             known disagreement on baseline runs, and no effect in the library passes every guard"
                .to_string()
        }
        (crate::gap::Verdict::Ambiguous, None) => {
            let ties: Vec<String> = a.ties().into_iter().map(ambiguity).collect();
            format!("**ambiguous**: {}", ties.join("; then "))
        }
        _ => "no significant missing effect".to_string(),
    }
}

/// Why an ambiguous round names neither of its two effects, each given with its kind.
pub fn ambiguity([first, second]: &[String; 2]) -> String {
    let kind = |name: &str| match crate::gap::effects::by_name(name) {
        Some(e) if e.physics => "the physics effect",
        _ => "the sensor effect",
    };
    format!(
        "{} `{first}` and {} `{second}` explain the same disagreement about as well (delta BIC \
         within the margin); neither is named",
        kind(first),
        kind(second)
    )
}

/// What a tie the search carried on past means for the names after it and the fitted model.
pub fn carried_tie(t: &crate::gap::Tie) -> String {
    let values: Vec<String> = t
        .carried
        .parameters
        .iter()
        .map(|(n, v)| format!("{n} = {v:.4}"))
        .collect();
    format!(
        "in round {}, {}. The search carried on past the tie: the fitted model carries `{}` \
         ({}; {:.0} % of the shrink), the better fit, and the later rounds look for the \
         disagreement it leaves, `{}` no longer a candidate",
        t.round + 1,
        ambiguity(&t.pair),
        t.pair[0],
        values.join(", "),
        t.share_pct,
        t.pair[1]
    )
}

/// The verdict paragraph with the naming rules, then one bullet per channel left unexplained
/// after the fit, per diverged re-simulation segment, per measurement notice and for the
/// channels not re-simulated.
fn write_verdict(s: &mut String, a: &Analysis, m: &Measurement) {
    let verdict = verdict_text(a);
    let _ = writeln!(
        s,
        "Verdict: {verdict}.\n\nAn effect is named only when its parameters lie inside their \
         physical bounds, its 95 % interval is finite and excludes no effect, delta BIC > {} \
         (gain scaled by the residual variance and the correlated process noise), it passes its \
         signature test, and it lowers the held-out chi-square by more than {} without raising \
         the held-out gap (re-simulation in {} segments; even {} s blocks fitted, odd blocks \
         held out).\n",
        fit::BIC_MARGIN,
        fit::HELDOUT_MIN_GAIN,
        a.shooting
            .segment_s
            .map_or("one open-loop".to_string(), |s| format!(
                "re-anchored {s} s"
            )),
        a.split.block_s
    );
    if let Some(o) = &a.outranked_by {
        let _ = writeln!(
            s,
            "- the disagreement left looks most like **{}**, which explains it better than any \
             candidate that passes every guard (by over {} delta BIC), but its fit ends on a \
             physical bound: it is larger than its range. Nothing more is named, as the best \
             passing candidate would only stand in for it",
            o.name,
            fit::BIC_MARGIN
        );
    }
    for r in &a.refused {
        let _ = writeln!(
            s,
            "- **{}**, round {}'s winner, passed every guard but is not named: {}",
            r.name,
            r.round + 1,
            r.why
        );
    }
    if let Some(t) = &a.tie {
        let _ = writeln!(s, "- {}", carried_tie(t));
    }
    if let Some(pair) = a.ambiguous.as_ref().filter(|_| !a.accepted.is_empty()) {
        let _ = writeln!(
            s,
            "- after the effects named, {}. Nothing more is named",
            ambiguity(pair)
        );
    }
    for c in &a.contrasts {
        let _ = writeln!(s, "- where they differ: {}", crate::gap::contrast::text(c));
    }
    for u in &a.unexplained {
        let w: Vec<String> = u
            .windows
            .iter()
            .map(|(a, b, x)| format!("{a:.0}-{b:.0} s ({x:.1})"))
            .collect();
        let _ = writeln!(
            s,
            "- unexplained after the fit: **{}** (chi2/n {:.2}); regimes: {}; windows: {}",
            u.channel,
            u.chi2_per_sample,
            if u.regimes.is_empty() {
                "-".to_string()
            } else {
                u.regimes.join(", ")
            },
            if w.is_empty() {
                "-".to_string()
            } else {
                w.join(", ")
            }
        );
    }
    for (when, run) in [("before", &a.clean_before), ("after", &a.clean_after)] {
        for d in &run.divergences {
            let _ = writeln!(
                s,
                "- the re-simulation {when} the fit diverged in the segment from {:.1} s at \
                 {:.2} s ({}): held there to the segment's end, counted as disagreement",
                d.segment_start_s, d.t_s, d.what
            );
        }
    }
    let spans = |run: &crate::gap::resim::Run| -> Vec<String> {
        // Contiguous spans (a contact running on into the next segment) as one.
        let mut merged: Vec<[f64; 2]> = Vec::new();
        for &[from, to] in &run.contacts {
            match merged.last_mut() {
                Some(last) if from <= last[1] + 1e-9 => last[1] = last[1].max(to),
                _ => merged.push([from, to]),
            }
        }
        merged
            .iter()
            .map(|[from, to]| format!("{from:.1}-{:.1} s", to.min(m.experiment.duration_s)))
            .collect()
    };
    let (before, after) = (spans(&a.clean_before), spans(&a.clean_after));
    let touched = if before == after {
        vec![("before and after", before)]
    } else {
        vec![("before", before), ("after", after)]
    };
    for (when, list) in touched.into_iter().filter(|(_, l)| !l.is_empty()) {
        let _ = writeln!(
            s,
            "- the re-simulation {when} the fit touched the pool at {}: those samples, {:.0} s \
             before and {:.0} s after each are left out of the fits and of every chi-square in \
             this report (a contact impulse is no effect of the library)",
            list.join(", "),
            crate::gap::run::CONTACT_LEAD_S,
            crate::gap::run::CONTACT_MEMORY_S
        );
    }
    for n in &m.notices {
        let _ = writeln!(s, "- notice: {n}");
    }
    if let Some(why) = a.fitted.caution() {
        let _ = writeln!(s, "- caution: {why}");
    }
    if !a.unmodelled.is_empty() {
        let _ = writeln!(s, "- not re-simulated: {}", a.unmodelled.join(", "));
    }
}

/// The "where the gap is" section: the per-channel table before the fit, then for each
/// significant channel its strongest correlations, regimes and windows.
fn write_gap_before(s: &mut String, a: &Analysis) {
    let _ = writeln!(s, "\n## Where the gap is (before)\n");
    let _ = writeln!(
        s,
        "| channel | n | RMS | noise floor | chi2/n | significant | Ljung-Box Q (crit) | lag s |\n|---|---|---|---|---|---|---|---|"
    );
    for c in &a.before {
        let _ = writeln!(
            s,
            "| {} | {} | {:.4} | {:.4} | {:.2} | {} | {:.1} ({:.1}) | {:+.2} |",
            c.channel,
            c.samples,
            c.rms,
            c.noise_floor_rms,
            c.chi2_per_sample,
            if c.significant { "yes" } else { "no" },
            c.ljung_box_q,
            c.ljung_box_critical_95,
            c.lag_s
        );
    }
    for c in a.before.iter().filter(|c| c.significant) {
        let _ = writeln!(s, "\n**{}**: strongest correlations:", c.channel);
        for k in c.correlations.iter().filter(|k| k.significant) {
            let _ = writeln!(s, "- {} at lag {} s: r = {:.2}", k.with, k.lag_s, k.r);
        }
        let regs: Vec<String> = c
            .regimes
            .iter()
            .filter(|r| r.significant)
            .map(|r| format!("{} (chi2/n {:.1})", r.regime, r.chi2_per_sample))
            .collect();
        let _ = writeln!(s, "- significant regimes: {}", regs.join(", "));
        let w: Vec<String> = c
            .windows
            .iter()
            .map(|(a, b, x)| format!("{a:.0}-{b:.0} s ({x:.1})"))
            .collect();
        let _ = writeln!(s, "- significant windows: {}", w.join(", "));
    }
}

/// The "before and after" section: RMS and fit % per channel, track distance, the gap's
/// reduction overall and on the held-out blocks, and the known disagreement if any.
fn write_gap_before_after(s: &mut String, a: &Analysis, m: &Measurement) {
    let _ = writeln!(s, "\n## The gap, before and after\n");
    let _ = writeln!(
        s,
        "| channel | RMS before | RMS after | fit % before | fit % after |\n|---|---|---|---|---|"
    );
    for (b, af) in a.before.iter().zip(&a.after) {
        let _ = writeln!(
            s,
            "| {} | {:.4} | {:.4} | {:.1} | {:.1} |",
            b.channel,
            b.rms,
            af.rms,
            fit_pct(m, &b.channel, b.rms),
            fit_pct(m, &b.channel, af.rms)
        );
    }
    if let (Some(x), Some(y)) = (a.track_distance_before_m, a.track_distance_after_m) {
        let _ = writeln!(
            s,
            "\nTrack distance at matched times (thesis [49]): {x:.3} m before, {y:.3} m after."
        );
    }
    let against = if a.fitted.discrepancy.is_empty() {
        "the noise floor"
    } else {
        "the noise floor and the calibrated model's known disagreement"
    };
    let _ = writeln!(
        s,
        "\nGap (excess of the normalised residual over {against}): {:.2} before, {:.2} after: {:.0} % smaller. On the held-out blocks: {:.2} before, {:.2} after: {:.0} % smaller.",
        a.excess_before,
        a.excess_after,
        a.gap_reduction_pct,
        a.heldout_gap_before,
        a.heldout_gap_after,
        a.heldout_reduction_pct
    );
    if !a.fitted.discrepancy.is_empty() {
        let known: Vec<String> = a
            .fitted
            .discrepancy
            .iter()
            .map(|(c, v)| format!("{c} {v:.2}"))
            .collect();
        let _ = writeln!(
            s,
            "\nKnown disagreement (chi2 per sample on baseline runs): {}. Against the noise floor alone the gap is {:.2} before, {:.2} after; held out {:.2} before, {:.2} after ({:.0} % smaller).",
            known.join(", "),
            a.raw.excess_before,
            a.raw.excess_after,
            a.raw.heldout_before,
            a.raw.heldout_after,
            a.raw.heldout_reduction_pct()
        );
    }
}

/// NRMSE fit % = 100 (1 - RMS / std(measured)).
fn fit_pct(m: &Measurement, channel: &str, rms: f64) -> f64 {
    let Some(c) = m.channel(channel) else {
        return f64::NAN;
    };
    let n = c.samples.len().max(1) as f64;
    let mean = c.samples.iter().map(|(_, v)| v).sum::<f64>() / n;
    let sd = (c
        .samples
        .iter()
        .map(|(_, v)| (v - mean).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    if sd > 0.0 {
        100.0 * (1.0 - rms / sd)
    } else {
        f64::NAN
    }
}

fn plot_err(path: &Path, e: impl std::fmt::Display) -> GapError {
    GapError::Plot {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Writes trajectories.svg, residuals.svg and ranking.svg into `out`.
pub fn plots(a: &Analysis, m: &Measurement, out: &Path) -> Result<(), GapError> {
    plot_trajectories(a, m, &out.join("trajectories.svg"))?;
    plot_residuals(a, m, &out.join("residuals.svg"))?;
    plot_ranking(a, &out.join("ranking.svg"))?;
    Ok(())
}

/// The track over the pool (east vs north): the measured positions, the model's and the
/// model's with the fitted effects.
fn plot_trajectories(a: &Analysis, m: &Measurement, path: &Path) -> Result<(), GapError> {
    let root = SVGBackend::new(path, (800, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let pool = a.configs_before.world.pool_m;
    let mut chart = ChartBuilder::on(&root)
        .caption("track over the pool (east vs north)", ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .build_cartesian_2d(0.0..pool.y, 0.0..pool.x)
        .map_err(|e| plot_err(path, e))?;
    chart
        .configure_mesh()
        .x_desc("east (m)")
        .y_desc("north (m)")
        .draw()
        .map_err(|e| plot_err(path, e))?;
    if let (Some(x), Some(y)) = (m.channel("x_m"), m.channel("y_m")) {
        chart
            .draw_series(
                x.samples
                    .iter()
                    .zip(&y.samples)
                    .map(|((_, a), (_, b))| Circle::new((*b, *a), 1, BLACK.filled())),
            )
            .map_err(|e| plot_err(path, e))?
            .label("measured")
            .legend(|(x, y)| Circle::new((x, y), 3, BLACK.filled()));
    }
    for (run, colour, label) in [
        (&a.clean_before, RED, "model"),
        (&a.clean_after, BLUE, "model + fitted effects"),
    ] {
        chart
            .draw_series(LineSeries::new(
                run.states
                    .iter()
                    .step_by(10)
                    .map(|s| (s.position_m.y, s.position_m.x)),
                colour,
            ))
            .map_err(|e| plot_err(path, e))?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], colour));
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE)
        .draw()
        .map_err(|e| plot_err(path, e))?;
    root.present().map_err(|e| plot_err(path, e))?;
    Ok(())
}

/// The normalised residuals (residual / noise floor) over time, one panel per modelled
/// channel, before and after the fit.
fn plot_residuals(a: &Analysis, m: &Measurement, path: &Path) -> Result<(), GapError> {
    let modelled: Vec<usize> = (0..m.channels.len())
        .filter(|&i| a.floors[i].is_some())
        .collect();
    let rows = modelled.len().max(1);
    let root = SVGBackend::new(path, (900, 160 * rows as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let areas = root.split_evenly((rows, 1));
    for (area, &i) in areas.iter().zip(&modelled) {
        let ch = &m.channels[i];
        let Some(floor) = &a.floors[i] else { continue };
        let series = |c: &crate::gap::effects::Configs, run: &resim::Run| -> Vec<(f64, f64)> {
            resim::predict(c, run, ch, 0.0)
                .map(|p| {
                    resim::residuals(ch, &p)
                        .iter()
                        .zip(&floor.sigma)
                        .zip(&ch.samples)
                        .map(|((r, s), (t, _))| (*t, (r / s).clamp(-20.0, 20.0)))
                        .collect()
                })
                .unwrap_or_default()
        };
        let b = series(&a.configs_before, &a.clean_before);
        let af = series(&a.configs_after, &a.clean_after);
        let t1 = m.experiment.duration_s;
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("{}: residual / noise floor", ch.name),
                ("sans-serif", 14),
            )
            .margin(5)
            .x_label_area_size(25)
            .y_label_area_size(40)
            .build_cartesian_2d(0.0..t1, -20.0..20.0)
            .map_err(|e| plot_err(path, e))?;
        chart
            .configure_mesh()
            .x_desc("t (s)")
            .draw()
            .map_err(|e| plot_err(path, e))?;
        chart
            .draw_series(b.iter().map(|p| Circle::new(*p, 1, RED.filled())))
            .map_err(|e| plot_err(path, e))?;
        chart
            .draw_series(af.iter().map(|p| Circle::new(*p, 1, BLUE.filled())))
            .map_err(|e| plot_err(path, e))?;
    }
    root.present().map_err(|e| plot_err(path, e))?;
    Ok(())
}

/// The first round's candidates ranked by their signed log delta BIC, green where every guard
/// passes, with the acceptance margin as a line.
fn plot_ranking(a: &Analysis, path: &Path) -> Result<(), GapError> {
    let round: Vec<&crate::gap::candidate::Candidate> = a
        .rounds
        .first()
        .map(|r| r.iter().filter(|c| c.delta_bic.is_finite()).collect())
        .unwrap_or_default();
    let root = SVGBackend::new(path, (800, 400)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let n = round.len().max(1);
    let sym = |v: f64| v.signum() * (1.0 + v.abs()).log10();
    let hi = round.iter().map(|c| sym(c.delta_bic)).fold(2.0, f64::max);
    let lo = round.iter().map(|c| sym(c.delta_bic)).fold(-1.0, f64::min);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "candidates, round 1: sign(dBIC) log10(1 + |dBIC|); line = margin",
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(160)
        .build_cartesian_2d(lo..hi, 0..n)
        .map_err(|e| plot_err(path, e))?;
    let names: Vec<String> = round.iter().map(|c| c.name.clone()).collect();
    chart
        .configure_mesh()
        .y_label_formatter(&|i| names.get(*i).cloned().unwrap_or_default())
        .y_labels(n)
        .draw()
        .map_err(|e| plot_err(path, e))?;
    chart
        .draw_series(round.iter().enumerate().map(|(i, c)| {
            let colour = if c.guards.all() { GREEN } else { RED };
            Rectangle::new([(0.0, i), (sym(c.delta_bic), i + 1)], colour.filled())
        }))
        .map_err(|e| plot_err(path, e))?;
    chart
        .draw_series(LineSeries::new(
            [(sym(fit::BIC_MARGIN), 0), (sym(fit::BIC_MARGIN), n)],
            BLACK,
        ))
        .map_err(|e| plot_err(path, e))?;
    root.present().map_err(|e| plot_err(path, e))?;
    Ok(())
}

/// Creates the output directory `out` and returns a writer of named text files inside it.
pub(crate) fn output_dir(
    out: &Path,
) -> Result<impl Fn(&str, String) -> Result<(), GapError> + '_, GapError> {
    std::fs::create_dir_all(out).map_err(|source| GapError::Io {
        path: out.to_path_buf(),
        source,
    })?;
    Ok(move |name: &str, text: String| {
        let path = out.join(name);
        std::fs::write(&path, text).map_err(|source| GapError::Io { path, source })
    })
}

/// Writes every output file into `out`; `model_stem` names `MODEL.fitted.toml`.
pub fn write_all(
    a: &Analysis,
    m: &Measurement,
    measured_dir: &Path,
    model_path: &Path,
    out: &Path,
) -> Result<(), GapError> {
    let write = output_dir(out)?;
    let text = serde_json::to_string_pretty(&json(a)).map_err(|e| GapError::Data(e.to_string()))?;
    write("report.json", text)?;
    write("report.md", markdown(a, m))?;
    let stem = model_path
        .file_stem()
        .map_or_else(|| "model".to_string(), |s| s.to_string_lossy().into_owned());
    let provenance = format!(
        "Written by `eyebot-hil gap --measured {} --model {}` (eyebot-hil {}).\n\
         Effects fitted by Levenberg-Marquardt on the measurement `{}`; each accepted because it\n\
         beat \"no effect\" by delta BIC > {} and passed its residual-signature test.\n\
         Parameters are changes relative to the base configuration (see docs/gap.md).",
        measured_dir.display(),
        model_path.display(),
        env!("CARGO_PKG_VERSION"),
        m.experiment.name,
        fit::BIC_MARGIN
    );
    write(
        &format!("{stem}.fitted.toml"),
        a.fitted.to_toml(&provenance, out),
    )?;
    plots(a, m, out)
}
