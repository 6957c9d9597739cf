//! `eyebot-hil gap`: the reality-gap workflow (`docs/gap.md`).
//!
//! - `gap --measured DIR --model MODEL.toml [--out DIR]`: re-simulate, localise, name, add,
//!   show the gap shrink.
//! - `gap generate --truth TRUTH.toml --schedule EXPERIMENT.toml --out DIR`: hidden-effect
//!   data from a truth model.
//! - `gap convert RECORD_DIR --out DIR`: a daemon recording as a measurement.
//! - `gap --measured DIR_WITH_summary.toml --model MODEL.toml`: summary observations.

use std::io::IsTerminal;
use std::path::PathBuf;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::cli::CliError;
use crate::cli::output::{errln, outln};
use crate::config::{BesideOrEmbedded, ConfigSource, Document};
use crate::gap::calibrate::RunRole;
use crate::gap::format::Measurement;
use crate::gap::model::GapModel;
use crate::gap::{self, GapError, effects, generate, report};
use crate::physics::experiment::Experiment;

#[derive(Debug, Clone, clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct GapArgs {
    #[command(subcommand)]
    pub command: Option<GapCommand>,
    /// The measurement directory (experiment.toml, commands.csv, measured.csv), or summary
    /// observations: a directory holding summary.toml, or a summary .toml file.
    #[arg(long)]
    pub measured: Option<PathBuf>,
    /// The model file (configs/models/*.toml format).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Where to write the report (default: DIR/gap-report).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Length of the re-anchored re-simulation segments (s); 0 replays the whole run open
    /// loop.
    #[arg(long, default_value_t = 5.0)]
    pub segment_s: f64,
    /// Length of the alternating fit / held-out time blocks (s).
    #[arg(long, default_value_t = 10.0)]
    pub heldout_block_s: f64,
}

impl GapArgs {
    fn options(&self) -> Result<gap::Options, CliError> {
        if !(self.segment_s.is_finite() && self.segment_s >= 0.0) {
            return Err(CliError::Usage(format!(
                "--segment-s {}: expected a length in seconds >= 0 (0 = open loop)",
                self.segment_s
            )));
        }
        if !(self.heldout_block_s.is_finite() && self.heldout_block_s > 0.0) {
            return Err(CliError::Usage(format!(
                "--heldout-block-s {}: expected a length in seconds > 0",
                self.heldout_block_s
            )));
        }
        Ok(gap::Options {
            shooting: gap::anchor::Shooting {
                segment_s: (self.segment_s > 0.0).then_some(self.segment_s),
            },
            split: gap::fit::Split {
                block_s: self.heldout_block_s,
            },
        })
    }
}

#[derive(Debug, Clone, clap::Subcommand)]
pub enum GapCommand {
    /// Generate a measurement from a truth model (for hidden-effect tests).
    Generate(GenerateArgs),
    /// Convert a daemon recording (`run --record DIR`) into a measurement directory.
    Convert(ConvertArgs),
    /// Fit the base model's continuous parameters on baseline runs (thrust curve, drag,
    /// added mass, yaw damping, sensor offsets and gains, and as model discrepancy the hull's
    /// own sway, yaw-inertia, yaw-under-way, heave, buoyancy and float-depth terms and its
    /// thruster balance and reverse curve) and write a calibrated model.
    Calibrate(CalibrateArgs),
}

#[derive(Debug, Clone, clap::Args)]
pub struct CalibrateArgs {
    /// A baseline measurement directory; repeat for several runs.
    #[arg(long, required = true)]
    pub measured: Vec<PathBuf>,
    /// The model file to calibrate.
    #[arg(long)]
    pub model: PathBuf,
    /// Where to write the calibrated model file (e.g. MODEL.calibrated.toml).
    #[arg(long)]
    pub out: PathBuf,
    /// A run the calibration is not fitted to, on which it reports its gap before and after;
    /// repeat for several.
    #[arg(long)]
    pub validate: Vec<PathBuf>,
    /// A null run, not among the baseline runs, of the programme later runs will use; the
    /// between-run spread is measured on these (two or more) instead of on the baseline runs.
    /// Repeat for several.
    #[arg(long)]
    pub spread_from: Vec<PathBuf>,
}

#[derive(Debug, Clone, clap::Args)]
pub struct ConvertArgs {
    /// The recording directory (meta.toml, bytes.tsv, state.csv).
    pub record: PathBuf,
    /// The measurement directory to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Vehicle config for the HDT tables (default: the recorded configuration's).
    #[arg(long)]
    pub vehicle: Option<String>,
    /// Sensor config (default: the recorded configuration's).
    #[arg(long)]
    pub sensors: Option<String>,
    /// World config (default: the recorded configuration's).
    #[arg(long)]
    pub world: Option<String>,
    /// Also write an overhead-camera track (x_m, y_m): ground truth plus seeded Gaussian
    /// noise of this size (m, 1 sigma). Off by default.
    #[arg(long)]
    pub camera_std_m: Option<f64>,
    /// Seed of the camera noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

#[derive(Debug, Clone, clap::Args)]
pub struct GenerateArgs {
    /// The truth model: a model file whose [[effect]]s are hidden in the data.
    #[arg(long)]
    pub truth: PathBuf,
    /// The command schedule: an experiment file (configs/experiments/ format).
    #[arg(long)]
    pub schedule: PathBuf,
    /// Seed of every noise source.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Overhead-camera position noise (m, 1 sigma).
    #[arg(long, default_value_t = 0.01)]
    pub camera_std_m: f64,
    /// The measurement directory to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Also ping the four sonar transducers (`sonar1_m`..`sonar4_m`, empty cell = no echo).
    #[arg(long)]
    pub sonar: bool,
}

pub fn run(args: &GapArgs) -> Result<(), CliError> {
    match &args.command {
        Some(GapCommand::Generate(g)) => return run_generate(g),
        Some(GapCommand::Convert(c)) => return run_convert(c),
        Some(GapCommand::Calibrate(c)) => return run_calibrate(c),
        None => {}
    }
    let (Some(measured), Some(model_path)) = (&args.measured, &args.model) else {
        return Err(CliError::Usage(
            "gap needs --measured DIR and --model MODEL.toml (or a subcommand)".into(),
        ));
    };
    if let Some(file) = gap::summary::summary_file(measured) {
        return run_summary(&file, model_path, args.out.as_deref());
    }
    let m = Measurement::load(measured)?;
    for n in &m.notices {
        errln!("notice: {n}");
    }
    let model = GapModel::load(model_path)?;
    if let Some(why) = model.caution() {
        errln!("caution: {}: {why}", model_path.display());
    }
    let total = (gap::fit::MAX_EFFECTS * effects::candidates().count()) as u64;
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template("{bar:30} {pos}/{len} {msg}") {
        bar.set_style(style);
    }
    let options = args.options()?;
    let analysis = gap::analyse_with(&model, &m, measured, options, &mut |round, name| {
        bar.inc(1);
        bar.set_message(format!("round {}: {name}", round + 1));
    })?;
    bar.finish_and_clear();
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| measured.join("gap-report"));
    report::write_all(&analysis, &m, measured, model_path, &out)?;
    if let Some(t) = &analysis.tie {
        outln!("ambiguous: {}", gap::report::carried_tie(t));
    }
    match analysis.accepted.first() {
        Some(_) => {
            for (e, share) in analysis.accepted.iter().zip(&analysis.shares_pct) {
                let p: Vec<String> = e
                    .parameters
                    .iter()
                    .zip(&e.ci95)
                    .map(|((n, v), (_, c))| format!("{n} = {v:.4} [{:.4}, {:.4}]", c[0], c[1]))
                    .collect();
                let share = if analysis.accepted.len() > 1 {
                    format!(", {share:.0} % of the shrink")
                } else {
                    String::new()
                };
                outln!(
                    "effect: {} ({}), delta BIC {:.1}{share}",
                    e.name,
                    p.join(", "),
                    e.delta_bic
                );
            }
            if let Some(pair) = &analysis.ambiguous {
                outln!(
                    "then ambiguous: {}; nothing more is named",
                    gap::report::ambiguity(pair)
                );
            }
        }
        None if analysis.verdict == gap::Verdict::Unexplained
            && analysis.fitted.discrepancy.is_empty() =>
        {
            outln!(
                "unexplained: the model disagrees beyond its noise floor and no effect in the library passes every guard"
            )
        }
        None if analysis.verdict == gap::Verdict::Unexplained => {
            outln!(
                "unexplained: the model disagrees beyond its noise floor and its known disagreement, and no effect in the library passes every guard"
            )
        }
        None if analysis.verdict == gap::Verdict::Ambiguous => {
            if let Some(pair) = &analysis.ambiguous {
                let then = if analysis.tie.is_some() { "then " } else { "" };
                outln!("{then}ambiguous: {}", gap::report::ambiguity(pair));
            }
        }
        None => outln!("no significant missing effect"),
    }
    for (when, run) in [
        ("before", &analysis.clean_before),
        ("after", &analysis.clean_after),
    ] {
        for d in &run.divergences {
            outln!(
                "diverged ({when} the fit): segment from {:.1} s, at {:.2} s: {} (held to the segment's end, counted as disagreement)",
                d.segment_start_s,
                d.t_s,
                d.what
            );
        }
    }
    for u in &analysis.unexplained {
        outln!(
            "still off: {} (chi2/n {:.2}){}",
            u.channel,
            u.chi2_per_sample,
            if u.regimes.is_empty() {
                String::new()
            } else {
                format!(" in {}", u.regimes.join(", "))
            }
        );
    }
    outln!(
        "gap: {:.2} -> {:.2} ({:.0} % smaller); held out: {:.2} -> {:.2} ({:.0} % smaller); report in {}",
        analysis.excess_before,
        analysis.excess_after,
        analysis.gap_reduction_pct,
        analysis.heldout_gap_before,
        analysis.heldout_gap_after,
        analysis.heldout_reduction_pct,
        out.display()
    );
    if !analysis.fitted.discrepancy.is_empty() {
        outln!(
            "against the noise floor alone (without the calibration's known disagreement): gap {:.2} -> {:.2}; held out {:.2} -> {:.2} ({:.0} % smaller)",
            analysis.raw.excess_before,
            analysis.raw.excess_after,
            analysis.raw.heldout_before,
            analysis.raw.heldout_after,
            analysis.raw.heldout_reduction_pct()
        );
    }
    Ok(())
}

/// `gap calibrate`.
fn run_calibrate(args: &CalibrateArgs) -> Result<(), CliError> {
    let load = |dirs: &[PathBuf]| -> Result<Vec<gap::calibrate::Run>, CliError> {
        dirs.iter()
            .map(|d| gap::calibrate::Run::load(d).map_err(CliError::from))
            .collect()
    };
    let baseline = load(&args.measured)?;
    let validate = load(&args.validate)?;
    let spread_from = load(&args.spread_from)?;
    for r in baseline.iter().chain(&validate).chain(&spread_from) {
        for n in &r.m.notices {
            errln!("notice: {}: {n}", r.dir.display());
        }
    }
    let model = GapModel::load(&args.model)?;
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    let c = gap::calibrate::calibrate(&model, &baseline, &validate, &spread_from, &mut |msg| {
        bar.set_message(msg.to_string());
        bar.tick();
    })?;
    bar.finish_and_clear();
    let out_dir = args
        .out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), std::path::Path::to_path_buf);
    std::fs::create_dir_all(&out_dir).map_err(|source| GapError::Io {
        path: out_dir.clone(),
        source,
    })?;
    let list = |dirs: &[PathBuf]| {
        dirs.iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut provenance = format!(
        "calibrated by `eyebot-hil gap calibrate` on {}",
        list(&args.measured)
    );
    if !args.spread_from.is_empty() {
        provenance.push_str(&format!("; spread from {}", list(&args.spread_from)));
    }
    let text = c.model.to_toml(&provenance, &out_dir);
    std::fs::write(&args.out, text).map_err(|source| GapError::Io {
        path: args.out.clone(),
        source,
    })?;
    let json_path = args.out.with_extension("json");
    let json = serde_json::to_string_pretty(&c).map_err(|e| GapError::Data(e.to_string()))?;
    std::fs::write(&json_path, json).map_err(|source| GapError::Io {
        path: json_path.clone(),
        source,
    })?;
    outln!("| effect | parameter | value | 95 % interval |");
    for p in &c.parameters {
        outln!(
            "| {} | {} | {:.4}{} | [{:.4}, {:.4}] |",
            p.effect,
            p.parameter,
            p.value,
            if p.at_bound { " (at bound)" } else { "" },
            p.ci95[0],
            p.ci95[1]
        );
    }
    if c.spread.is_empty() {
        outln!(
            "one baseline run: no between-run spread measured; give two or more --measured (or \
             --spread-from) runs so `gap` knows how far an effect strays when nothing changed"
        );
    } else {
        let dof = c.model.spread_dof.map_or(String::new(), |d| {
            format!(
                " ({d} degrees of freedom: `gap` widens it x{:.2} in its intervals)",
                crate::gap::model::spread_factor(d)
            )
        });
        outln!(
            "between-run spread measured on {}{dof}",
            c.spread_from.join(", ")
        );
        outln!("| effect | parameter | between-run spread (1 sigma) |");
        for p in &c.spread {
            outln!("| {} | {} | {:.4} |", p.effect, p.parameter, p.value);
        }
    }
    if !c.not_fitted.is_empty() {
        outln!(
            "not fitted (no channel of theirs measured): {}",
            c.not_fitted.join(", ")
        );
    }
    for u in &c.held {
        outln!("held at the model as given: {} ({})", u.effect, u.why);
    }
    for u in &c.unidentified {
        outln!(
            "not identified by the baseline runs (its value is what the fit left: read it as \"this channel disagrees\"): {} ({})",
            u.effect,
            u.why
        );
    }
    if !c.spread_unidentified.is_empty() {
        outln!(
            "spread runs whose fits ended on a bound or unbounded (the spread holds their model error): {}",
            c.spread_unidentified.join(", ")
        );
    }
    if c.shrunk < 1.0 {
        outln!(
            "the fitted change diverged on a baseline run and was shrunk to {:.3} of itself",
            c.shrunk
        );
    }
    // Per-channel figures as `x_m 1.52, y_m 2.65`.
    let per_channel = |v: &[(String, f64)]| {
        v.iter()
            .map(|(ch, v)| format!("{ch} {v:.2}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    for u in &c.unlike_spread {
        outln!("{}", u.warning());
    }
    if !c.discrepancy.is_empty() {
        outln!(
            "known disagreement (chi2 per sample of the calibrated model, on {}): {}",
            c.known_from.join(", "),
            per_channel(&c.discrepancy)
        );
    }
    if !c.run_bounds.is_empty() {
        outln!(
            "a run with nothing new stays under (chi2 per sample, 95 % for all channels together, from how the unfitted runs among those scatter): {}",
            per_channel(&c.run_bounds)
        );
    }
    for r in &c.runs {
        outln!(
            "{} {}: gap {:.2} -> {:.2} ({:.0} % smaller)",
            match r.role {
                RunRole::Baseline => "fitted on",
                RunRole::Validation => "validated on",
                RunRole::Spread => "checked on spread run",
            },
            r.dir,
            r.gap_before,
            r.gap_after,
            r.reduction_pct
        );
        if let Some(w) = r.grown_warning() {
            outln!("{w}");
        }
    }
    outln!(
        "calibrated model in {} ({} re-simulations); details in {}",
        args.out.display(),
        c.evaluations,
        json_path.display()
    );
    Ok(())
}

/// The summary-observation workflow (`summary.toml`, docs/gap.md).
fn run_summary(
    file: &std::path::Path,
    model_path: &std::path::Path,
    out: Option<&std::path::Path>,
) -> Result<(), CliError> {
    let s = gap::summary::Summary::load(file)?;
    let model = GapModel::load(model_path)?;
    let total = (gap::fit::MAX_EFFECTS * effects::candidates().count()) as u64;
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template("{bar:30} {pos}/{len} {msg}") {
        bar.set_style(style);
    }
    let a = gap::summary::analyse(&model, &s, &mut |round, name| {
        bar.inc(1);
        bar.set_message(format!("round {}: {name}", round + 1));
    })?;
    bar.finish_and_clear();
    let out = out.map_or_else(
        || {
            file.parent()
                .unwrap_or(std::path::Path::new("."))
                .join("gap-report")
        },
        std::path::Path::to_path_buf,
    );
    gap::summary::write_all(&a, &s, file, model_path, &out)?;
    outln!(
        "{} summary observations of `{}` against `{}`{}",
        s.observations.len(),
        s.name,
        model.name,
        if a.few_observations {
            " (few numbers: a named effect is a lead, not a proof)"
        } else {
            ""
        }
    );
    outln!("| observation | measured | model before | z before | model after | z after |");
    for o in &a.observations {
        let f =
            |v: Option<f64>, p: usize| v.map_or_else(|| "-".to_string(), |v| format!("{v:.p$}"));
        outln!(
            "| {} | {}{:.3} {} | {} | {} | {} | {} |",
            o.name,
            match o.bound {
                gap::summary::Bound::Value => "",
                gap::summary::Bound::Upper => "<= ",
                gap::summary::Bound::Lower => ">= ",
            },
            o.measured,
            o.unit,
            f(o.simulated_before, 3),
            f(o.z_before, 1),
            f(o.simulated_after, 3),
            f(o.z_after, 1)
        );
    }
    match (&a.ambiguous, a.accepted.is_empty()) {
        (Some(pair), true) => outln!("ambiguous: {}", gap::report::ambiguity(pair)),
        (Some(pair), false) => outln!(
            "then ambiguous: {}; nothing more is named",
            gap::report::ambiguity(pair)
        ),
        (None, true) => outln!("no significant missing effect"),
        (None, false) => {}
    }
    // Final values: each accepted effect as refitted jointly with the ones after it.
    for e in a.fitted.effects.iter().skip(model.effects.len()) {
        let p: Vec<String> = e
            .effect
            .parameters
            .iter()
            .zip(&e.values)
            .zip(&e.ci95)
            .map(|((n, v), c)| format!("{n} = {v:.4} [{:.4}, {:.4}]", c[0], c[1]))
            .collect();
        outln!(
            "effect: {} ({}), delta BIC {:.1} when added",
            e.effect.name,
            p.join(", "),
            e.delta_bic.unwrap_or(f64::NAN)
        );
    }
    outln!(
        "gap (RMS of z): {:.2} -> {:.2} ({:.0} % smaller); chi2 after {:.1} vs 95 % point {:.1}: {}",
        a.gap_before,
        a.gap_after,
        a.gap_reduction_pct,
        a.chi2_after,
        a.chi2_critical_after,
        if a.consistent_after {
            "consistent".to_string()
        } else {
            format!("still unexplained: {}", a.unexplained.join(", "))
        }
    );
    outln!("report in {}", out.display());
    Ok(())
}

fn run_convert(c: &ConvertArgs) -> Result<(), CliError> {
    let opts = gap::convert::ConvertOptions {
        vehicle: c.vehicle.clone(),
        sensors: c.sensors.clone(),
        world: c.world.clone(),
        camera_std_m: c.camera_std_m,
        seed: c.seed,
    };
    let conv = gap::convert::convert(&c.record, &opts)?;
    for n in &conv.notices {
        errln!("notice: {n}");
    }
    conv.measurement.write(&c.out)?;
    let m = &conv.measurement;
    outln!(
        "{}: {:.1} s, {} command rows, channels {} -> {}",
        c.record.display(),
        m.experiment.duration_s,
        m.commands.len(),
        m.channels
            .iter()
            .map(|ch| format!("{} ({})", ch.name, ch.samples.len()))
            .collect::<Vec<_>>()
            .join(", "),
        c.out.display()
    );
    Ok(())
}

fn run_generate(g: &GenerateArgs) -> Result<(), CliError> {
    let truth = GapModel::load(&g.truth)?;
    let (dir, name) = BesideOrEmbedded::for_file(&g.schedule);
    let text = dir.read(&name)?;
    let schedule = Experiment::from_document(&Document::new(dir.describe(&name), &text))?;
    let info = generate::setup(&truth, &schedule, g.camera_std_m);
    let (world, sensors) = (info.world.clone(), info.sensors.clone());
    let configs = truth.configs(&info, &truth.base)?;
    let m = generate::generate_with(
        &configs,
        &schedule,
        &world,
        &sensors,
        g.camera_std_m,
        g.seed,
        g.sonar,
    )?;
    m.write(&g.out)?;
    outln!(
        "{}: {} channels, {:.0} s -> {}",
        m.experiment.name,
        m.channels.len(),
        m.experiment.duration_s,
        g.out.display()
    );
    Ok(())
}
