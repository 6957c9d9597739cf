//! `eyebot-hil gap-bench [--cases N] [--seed S] [--effects a,b] [--out FILE]`: the
//! hidden-effect benchmark of the reality-gap workflow ([`crate::gap::bench`]).

use std::io::IsTerminal;
use std::path::PathBuf;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::cli::CliError;
use crate::cli::output::out;
use crate::gap::bench::{self, BenchOptions};
use crate::gap::effects::{self, Effect};

#[derive(Debug, Clone, clap::Args)]
pub struct GapBenchArgs {
    /// Cases per effect, and null cases.
    #[arg(long, default_value_t = 10)]
    pub cases: usize,
    /// Seed of the case draws (sizes, directions, noise seeds).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Comma-separated effect names (default: the whole library).
    #[arg(long, value_delimiter = ',')]
    pub effects: Vec<String>,
    /// Also write the table (markdown) and one line per case (CSV-like) to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(args: &GapBenchArgs) -> Result<(), CliError> {
    let selected: Vec<&'static Effect> = if args.effects.is_empty() {
        effects::LIBRARY.iter().collect()
    } else {
        args.effects
            .iter()
            .map(|n| {
                effects::by_name(n.trim()).ok_or_else(|| {
                    CliError::Usage(format!(
                        "--effects: unknown effect `{n}`; known: {}",
                        effects::LIBRARY
                            .iter()
                            .map(|e| e.name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })
            })
            .collect::<Result<_, _>>()?
    };
    let opts = BenchOptions {
        cases: args.cases,
        seed: args.seed,
        effects: selected,
    };
    let total = (opts.cases * (opts.effects.len() + 1)) as u64;
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} ({eta})") {
        bar.set_style(style);
    }
    let results = bench::run(&opts, &mut |done, _, label| {
        bar.set_position(done as u64);
        bar.set_message(label.to_string());
    })
    .map_err(|e| CliError::Output(e.to_string()))?;
    bar.finish_and_clear();
    let table = bench::table(&results);
    out!("{table}");
    if let Some(path) = &args.out {
        let mut text = table.clone();
        text.push_str(
            "\neffect,seed,size_sigma,named,truth,fitted,ci95,parameter_error,ci_covers,held_out_reduction_pct,held_out_truth_reduction_pct,seconds\n",
        );
        for r in &results {
            text.push_str(&format!(
                "{},{},{:.2},{},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:.2}\n",
                r.label,
                r.seed,
                r.size_sigma,
                r.named.as_deref().unwrap_or("none"),
                r.truth,
                r.fitted,
                r.ci95,
                r.parameter_error,
                r.ci_covers,
                r.held_out_reduction_pct,
                r.held_out_truth_reduction_pct,
                r.seconds
            ));
        }
        std::fs::write(path, text).map_err(|source| CliError::Io {
            path: path.clone(),
            source,
        })?;
    }
    Ok(())
}
