//! `eyebot-hil gap-bench [--source simulator|independent|bridge] [--cases N] [--seed S]
//! [--effects a,b] [--calibration FILE] [--shard K/N --out-part FILE] [--out FILE]`: the
//! hidden-effect benchmark of the reality-gap workflow ([`crate::gap::bench`]);
//! `eyebot-hil gap-bench calibrate [same options] --out FILE` makes a campaign's calibration
//! once for its shards; `eyebot-hil gap-bench merge PART... [--out FILE]` combines the parts
//! of a sharded run into the table an unsharded run prints.
//!
//! On a terminal a progress bar shows the campaign moving; otherwise (a batch job's log) a
//! line per finished case goes to standard error.

use std::io::IsTerminal;
use std::path::PathBuf;

use clap::ValueEnum;
use clap::builder::TypedValueParser;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::cli::CliError;
use crate::cli::output::{out, outln};
use crate::gap::bench::{
    self, BenchOptions, Calibration, CaseResult, Outcome, Part, Shard, Source,
};
use crate::gap::effects::{self, Effect};

#[derive(Debug, Clone, clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct GapBenchArgs {
    #[command(subcommand)]
    pub command: Option<GapBenchCommand>,
    #[command(flatten)]
    pub campaign: CampaignArgs,
    /// The campaign's calibration (`gap-bench calibrate --out FILE`), made with the same
    /// options: analyse with it instead of calibrating here.
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// Run only shard K of N: the cases whose index i in the fixed case order has
    /// i % N == K - 1. Needs --out-part.
    #[arg(long, value_name = "K/N", requires = "out_part")]
    pub shard: Option<Shard>,
    /// Write this run's results (JSON) for `gap-bench merge`.
    #[arg(long, value_name = "FILE")]
    pub out_part: Option<PathBuf>,
    /// Also write the table (markdown) and one line per case (CSV-like) to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// What decides a campaign's cases and calibration: the same for `gap-bench`, its shards and
/// `gap-bench calibrate`.
#[derive(Debug, Clone, clap::Args)]
pub struct CampaignArgs {
    /// Where the data come from: this project's simulator; the independent Python vehicle
    /// model (`pty-tests/independent`, built into the binary); or closed-loop recordings of
    /// the C examples through the bridge with a vehicle of another form. The last two are
    /// analysed after calibration.
    #[arg(long, value_enum, default_value_t = SourceArg::Simulator)]
    pub source: SourceArg,
    /// Cases per effect, and null cases.
    #[arg(long, default_value_t = 10)]
    pub cases: usize,
    /// Seed of the case draws (sizes, directions, noise seeds).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Comma-separated effect names (default: the whole library, or for the independent
    /// source every effect of the independent model that the benchmark runs).
    #[arg(long, value_delimiter = ',')]
    pub effects: Vec<String>,
    /// The independent model's program (default: the copy built into this binary).
    #[arg(long, value_name = "PATH")]
    pub independent: Option<PathBuf>,
    /// Independent source: a vehicle whose structure the model draws with this seed (drag
    /// laws, couplings, thruster maps, buoyancy, lever arms), every run started away from its
    /// stated start; absent: the model's nominal vehicle.
    #[arg(long, value_name = "K")]
    pub structure_seed: Option<u64>,
    /// Independent source: each baseline and validation run drives a programme the model
    /// draws per run, and the cases and spread runs one programme drawn for the campaign
    /// (its name is printed); default: every run drives `mixed`.
    #[arg(long)]
    pub drawn_programs: bool,
    /// Independent and bridge sources: this many further cases with two hidden effects at
    /// once (two distinct effects drawn from `--effects`), scored on both being named.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub pairs: usize,
    /// Independent and bridge sources: calibrate on this many baseline runs (1 to 3: the
    /// first of the three the campaign draws; its validation run, spread runs and cases stay
    /// the same), as a user with fewer runs would.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u16).range(1..=3).map(usize::from))]
    pub baselines: usize,
    /// Bridge source: a directory with host builds of the C examples (`make -C
    /// firmware-protocol/c OUT=DIR`); default: built with `make` into a scratch directory.
    #[arg(long, value_name = "DIR")]
    pub programs: Option<PathBuf>,
    /// Independent and bridge sources: keep the calibrated model (`calibrated.toml`), the
    /// baseline runs and each case's measurement directory (`case-INDEX-EFFECT`) in DIR, to
    /// analyse a case again with `eyebot-hil gap`.
    #[arg(long, value_name = "DIR")]
    pub keep: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SourceArg {
    Simulator,
    Independent,
    Bridge,
}

#[derive(Debug, Clone, clap::Subcommand)]
pub enum GapBenchCommand {
    /// Calibrate a campaign once, for every shard to read with `--calibration FILE` (the
    /// simulator source calibrates nothing: its file holds only what the shards check).
    Calibrate {
        #[command(flatten)]
        campaign: CampaignArgs,
        /// Where to write the calibration (JSON).
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
    },
    /// Combine the part files of a sharded run into the table an unsharded run prints.
    Merge {
        /// The part files (`--out-part`), one per shard.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Also write the table and one line per case to this file.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Totals over campaigns: a row per file written by `gap-bench --out` or `merge --out`
    /// (first names right at >= 3 sigma, wrong first names, false alarms on nulls, both of
    /// two named, also where the weaker shows at >= 3 sigma, pairs naming an effect not
    /// hidden, seconds per case) and one for all.
    Tally {
        /// The campaigns' files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
}

/// A source-specific flag given with a source that does not read it: refused, not ignored.
fn check_flags_fit_source(args: &CampaignArgs) -> Result<(), CliError> {
    let misplaced = [
        (
            args.keep.is_some() && args.source == SourceArg::Simulator,
            "--keep",
            "--source independent or bridge (the simulator source calibrates nothing and \
             writes no runs to keep; `eyebot-hil gap generate` makes one of its cases)",
        ),
        (
            args.programs.is_some() && args.source != SourceArg::Bridge,
            "--programs",
            "--source bridge",
        ),
        (
            args.independent.is_some() && args.source != SourceArg::Independent,
            "--independent",
            "--source independent",
        ),
        (
            args.structure_seed.is_some() && args.source != SourceArg::Independent,
            "--structure-seed",
            "--source independent",
        ),
        (
            args.drawn_programs && args.source != SourceArg::Independent,
            "--drawn-programs",
            "--source independent",
        ),
        (
            args.pairs > 0 && args.source == SourceArg::Simulator,
            "--pairs",
            "--source independent or bridge",
        ),
        (
            args.baselines != 3 && args.source == SourceArg::Simulator,
            "--baselines",
            "--source independent or bridge",
        ),
    ];
    match misplaced.iter().find(|(bad, _, _)| *bad) {
        Some((_, flag, expected)) => Err(CliError::Usage(format!(
            "{flag} is not read by --source {}; it goes with {expected}",
            args.source
                .to_possible_value()
                .map_or_else(String::new, |v| v.get_name().to_string())
        ))),
        None => Ok(()),
    }
}

/// The options of `args`, and the built-in independent model's temporary file when the run
/// uses it (it must outlive the run).
fn options(
    args: &CampaignArgs,
) -> Result<(BenchOptions, Option<tempfile::NamedTempFile>), CliError> {
    check_flags_fit_source(args)?;
    let source = match args.source {
        SourceArg::Simulator => Source::Simulator,
        SourceArg::Independent => Source::Independent,
        SourceArg::Bridge => Source::Bridge,
    };
    let names: Vec<&str> = args.effects.iter().map(|n| n.trim()).collect();
    let mut opts = BenchOptions {
        source,
        cases: args.cases,
        seed: args.seed,
        effects: Vec::new(),
        hidden: Vec::new(),
        independent_path: PathBuf::new(),
        structure_seed: args.structure_seed,
        drawn_programs: args.drawn_programs,
        pairs: args.pairs,
        baselines: args.baselines,
        bridge: bench::bridge::BridgeOptions {
            exe: None,
            programs: args.programs.clone(),
        },
        keep: args.keep.clone(),
    };
    let mut embedded = None;
    if source == Source::Independent {
        opts.independent_path = match &args.independent {
            Some(path) => path.clone(),
            None => {
                let file = bench::independent::embedded_program()?;
                let path = file.path().to_path_buf();
                embedded = Some(file);
                path
            }
        };
    }
    let usage = |e: crate::gap::GapError| CliError::Usage(e.to_string());
    match source {
        Source::Simulator => {
            opts.effects = if names.is_empty() {
                effects::candidates().collect::<Vec<&'static Effect>>()
            } else {
                names
                    .iter()
                    .map(|n| bench::library_effect(n))
                    .collect::<Result<_, _>>()
                    .map_err(usage)?
            }
        }
        Source::Independent | Source::Bridge => {
            let (all, by_name): (&'static [bench::calibrated::Hidden], fn(&str) -> _) =
                if source == Source::Bridge {
                    (bench::bridge::HIDDEN.as_slice(), bench::bridge::by_name)
                } else {
                    (
                        bench::independent::HIDDEN.as_slice(),
                        bench::independent::by_name,
                    )
                };
            opts.hidden = if names.is_empty() {
                all.iter().collect()
            } else {
                names
                    .iter()
                    .map(|n| by_name(n))
                    .collect::<Result<_, _>>()
                    .map_err(usage)?
            }
        }
    }
    Ok((opts, embedded))
}

/// With drawn programmes, says on stderr which programme the campaign's cases drive.
fn note_programs(opts: &BenchOptions) -> Result<(), CliError> {
    if opts.drawn_programs {
        let kinds = bench::independent::program_kinds(&opts.independent_path)?;
        let cases = bench::independent::draw_case_program(&kinds, opts.seed, opts.structure_seed);
        eprintln!(
            "gap-bench: programmes drawn: each baseline and validation run its own (`--program \
             random`), the spread runs and cases `{cases}`"
        );
    }
    Ok(())
}

/// The table followed by one CSV line per case (`bench::table::cases_csv`), as `--out`
/// writes it.
fn report(table: &str, results: &[CaseResult]) -> Result<String, csv::Error> {
    Ok(format!("{table}\n{}", bench::table::cases_csv(results)?))
}

fn write(path: &PathBuf, text: &str) -> Result<(), CliError> {
    std::fs::write(path, text).map_err(|source| CliError::Io {
        doing: "write",
        path: path.clone(),
        source,
    })
}

fn print(source: Source, outcome: &Outcome, out_file: Option<&PathBuf>) -> Result<(), CliError> {
    let table = bench::table(source, &outcome.results, outcome.calibration.as_ref());
    out!("{table}");
    if let Some(path) = out_file {
        let text = report(&table, &outcome.results).map_err(|e| CliError::Io {
            doing: "write",
            path: path.clone(),
            source: std::io::Error::other(e),
        })?;
        write(path, &text)?;
    }
    Ok(())
}

/// What the log of a campaign without a terminal says about a finished case: right, a
/// false alarm, wrong (another effect named) or missed (nothing, or one of two, named).
fn verdict(r: &CaseResult) -> String {
    let named = if r.named_all.is_empty() {
        r.named.clone().unwrap_or_else(|| "nothing".to_string())
    } else {
        r.named_all.join("+")
    };
    let expected = [&r.expected, &r.expected_second]
        .iter()
        .filter_map(|e| e.as_deref())
        .collect::<Vec<_>>()
        .join("+");
    let expected = if expected.is_empty() {
        "nothing"
    } else {
        &expected
    };
    match &r.effect {
        None if !r.false_alarm() => "null, nothing named: right".to_string(),
        None if r.named.is_none() => format!(
            "null, {}: false alarm",
            r.verdict.as_deref().unwrap_or("unexplained")
        ),
        None => format!("null, named {named}: false alarm"),
        Some(_) if r.correct() && !r.wrong() => format!("named {named}: right"),
        Some(_) if r.wrong() => format!("named {named}, expected {expected}: wrong"),
        Some(_) => format!("named {named}, expected {expected}: missed"),
    }
}

pub fn run(args: &GapBenchArgs) -> Result<(), CliError> {
    match &args.command {
        Some(GapBenchCommand::Merge { parts, out }) => {
            let mut read = Vec::new();
            for p in parts {
                let part = Part::read(p)?;
                read.push((p.clone(), part));
            }
            let (key, outcome) = bench::merge(&read)?;
            return print(key.source, &outcome, out.as_ref());
        }
        Some(GapBenchCommand::Tally { files }) => {
            let campaigns = files
                .iter()
                .map(|f| bench::tally::read(f))
                .collect::<Result<Vec<_>, _>>()?;
            outln!("{}", bench::tally::table(&campaigns));
            return Ok(());
        }
        Some(GapBenchCommand::Calibrate { campaign, out }) => {
            let (opts, _embedded) = options(campaign)?;
            if !matches!(opts.source, Source::Simulator) {
                eprintln!("gap-bench calibrate: calibrating on the baseline runs");
            }
            note_programs(&opts)?;
            let c = bench::calibrate(&opts)?;
            c.write(out)?;
            match &c.gap {
                Some(g) => outln!(
                    "calibration: gap {:.3} -> {:.3} ({:.1} % smaller) on a null run it was not \
                     fitted to{}, in {:.1} s; written to {}",
                    g.gap_before,
                    g.gap_after,
                    g.reduction_pct,
                    g.spread_clause(),
                    g.seconds,
                    out.display()
                ),
                None => outln!(
                    "calibration: the {} source calibrates nothing; its options and base model \
                     written to {}",
                    opts.source.name(),
                    out.display()
                ),
            }
            return Ok(());
        }
        None => {}
    }
    if args.out_part.is_some() && args.shard.is_none() {
        return Err(CliError::Usage(
            "--out-part: give the shard too (--shard K/N; 1/1 for the whole benchmark)".into(),
        ));
    }
    let (opts, _embedded) = options(&args.campaign)?;
    note_programs(&opts)?;
    let calibration = match &args.calibration {
        Some(path) => Some(Calibration::read(path)?),
        None => None,
    };
    let shard = args.shard.unwrap_or(Shard::WHOLE);
    let terminal = std::io::stderr().is_terminal();
    let bar = if terminal {
        ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} ({eta})") {
        bar.set_style(style);
    }
    let outcome = bench::run(
        &opts,
        Some(shard),
        calibration.as_ref(),
        &mut |done, total, label, case| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
            bar.set_message(label.to_string());
            if terminal {
                return;
            }
            match case {
                Some(r) => eprintln!(
                    "gap-bench: shard {shard}: {done}/{total}: case {} {}: {}, {:.1} s",
                    r.index,
                    r.effect.as_deref().unwrap_or(&r.label),
                    verdict(r),
                    r.seconds
                ),
                None => eprintln!("gap-bench: shard {shard}: {label}"),
            }
        },
    )?;
    bar.finish_and_clear();
    if let Some(path) = &args.out_part {
        Part::new(opts.key(), shard, bench::case_count(&opts), outcome.clone()).write(path)?;
    }
    print(opts.source, &outcome, args.out.as_ref())
}
