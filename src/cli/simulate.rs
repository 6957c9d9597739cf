//! `eyebot-hil simulate EXPERIMENT.toml [--model VEHICLE.toml] [--world WORLD.toml] [--seed N]
//! --out run.csv`: runs one experiment offline, as fast as the machine allows, and writes the
//! state trace as CSV (one row per physics step): the rows of a recording's `state.csv`
//! ([`crate::record::StateRow`], `docs/recording.md`).

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::cli::CliError;
use crate::cli::output::{errln, outln};
use crate::config::{BesideOrEmbedded, ConfigSource, Document, Embedded};
use crate::physics::experiment::{self, Experiment};
use crate::physics::{self, DEFAULT_VEHICLE, DEFAULT_WORLD, Model};
use crate::record::StateRow;

/// Arguments of `simulate`.
#[derive(Debug, Clone, clap::Args)]
pub struct SimulateArgs {
    /// The experiment file (see configs/experiments/).
    pub experiment: PathBuf,
    /// Vehicle model file (default: the embedded configs/vehicles/mako.toml).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// World file (default: the embedded configs/worlds/pool.toml).
    #[arg(long)]
    pub world: Option<PathBuf>,
    /// Seed of the physics RNG stream (thruster fluctuation).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where to write the CSV trace (`-`: standard output; the summary line then goes to
    /// standard error).
    #[arg(long)]
    pub out: PathBuf,
}

/// The I/O error inside a csv error, so a closed pipe is still seen as one.
fn csv_io(e: csv::Error) -> std::io::Error {
    match e.into_kind() {
        csv::ErrorKind::Io(e) => e,
        other => std::io::Error::other(format!("{other:?}")),
    }
}

/// Loads a user-named config file of a kind, or the embedded default.
fn load_or_default<T>(
    path: Option<&Path>,
    default: &str,
    load: impl Fn(&dyn ConfigSource, &str) -> Result<T, crate::config::ConfigError>,
) -> Result<T, CliError> {
    Ok(match path {
        Some(p) => {
            let (source, name) = BesideOrEmbedded::for_file(p);
            load(&source, &name)?
        }
        None => load(&Embedded, default)?,
    })
}

pub fn run(args: &SimulateArgs) -> Result<(), CliError> {
    let vehicle = load_or_default(
        args.model.as_deref(),
        DEFAULT_VEHICLE,
        physics::load_vehicle,
    )?;
    let world = load_or_default(args.world.as_deref(), DEFAULT_WORLD, physics::load_world)?;
    let (dir, name) = BesideOrEmbedded::for_file(&args.experiment);
    let text = dir.read(&name)?;
    let exp = Experiment::from_document(&Document::new(dir.describe(&name), &text))?;
    let model = Model::new(vehicle, world);

    let to_stdout = args.out.as_os_str() == "-";
    let sink: Box<dyn Write> = if to_stdout {
        Box::new(std::io::stdout().lock())
    } else {
        Box::new(std::fs::File::create(&args.out).map_err(|e| CliError::Io {
            doing: "create",
            path: args.out.clone(),
            source: e,
        })?)
    };
    let io = |e: std::io::Error| CliError::Io {
        doing: "write",
        path: args.out.clone(),
        source: e,
    };
    let mut out = crate::record::format::state_writer(sink).map_err(|e| io(csv_io(e)))?;
    let mut io_error = None;
    let mut rows = 0u64;
    let started = std::time::Instant::now(); // CLI report only; the model never reads a clock
    let summary = experiment::run(&model, &exp, args.seed, |s| {
        if io_error.is_none() {
            match out.serialize(StateRow::from_state(s)) {
                Ok(()) => rows += 1,
                Err(e) => io_error = Some(csv_io(e)),
            }
        }
    })
    .map_err(|source| CliError::Physics {
        experiment: exp.name.clone(),
        source,
    })?;
    let flushed = match io_error {
        Some(e) => Err(e),
        None => out.flush(),
    };
    match flushed {
        Ok(()) => {}
        // A reader that stopped early (`| head`) ends the output, as it would for `cat`.
        Err(e) if to_stdout && e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(()),
        Err(e) => return Err(io(e)),
    }
    let wall = started.elapsed().as_secs_f64();
    let line = format!(
        "{}: {rows} rows, {:.1} s simulated in {wall:.3} s, step {} ms, {} contact(s) -> {}",
        exp.name,
        exp.duration_s,
        model.step_s() * 1e3,
        summary.contact_count,
        if to_stdout {
            "standard output".to_string()
        } else {
            args.out.display().to_string()
        }
    );
    if to_stdout {
        errln!("{line}");
    } else {
        outln!("{line}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `simulate` writes the rows of a recording's `state.csv`: the state reader takes its
    /// trace, one row per 10 ms step from t = 0, thrust in newtons once the motors run.
    #[test]
    fn the_trace_reads_back_as_state_rows() {
        let tmp = crate::scratch::dir("simulate");
        let out = tmp.path().join("run.csv");
        let args = SimulateArgs {
            experiment: Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("configs/experiments/acceleration.toml"),
            model: None,
            world: None,
            seed: 1,
            out: out.clone(),
        };
        run(&args).unwrap();
        let rows = crate::record::read_state_file(&out).unwrap();
        assert!(rows.len() > 1000, "{} rows", rows.len());
        assert_eq!(rows[0].t_s, 0.0);
        assert!((rows[1].t_s - 0.01).abs() < 1e-12, "{:?}", rows[1]);
        assert!(
            rows.iter().any(|r| r.force_port_n > 1.0),
            "the thrusters push"
        );
    }
}
