//! Data from the independent vehicle model (`pty-tests/independent/mako_independent.py`): a
//! different model form, closed-loop programs on measured sensors, its own sensors and noise.
//! By default every run drives the `mixed` program for three minutes; with drawn programmes
//! ([`Programs::Drawn`]) each baseline and validation run drives a program the model draws
//! per run, and the cases and spread runs one program drawn for the campaign. The
//! between-run spread is measured on [`SPREAD_RUNS`] null runs of the cases' program; the
//! case loop, calibration and scoring are [`super::calibrated`]'s. Sizes are multiples of
//! the model's default sizes (its `--list`).

use std::path::Path;
use std::process::Command;
use std::sync::LazyLock;

use rand::RngExt;

use crate::gap::GapError;
use crate::gap::bench::calibrated::{Hidden, Truth};
use crate::gap::effects;

/// Length of every run (s).
pub const DURATION_S: f64 = 180.0;
/// The program every run drives unless programmes are drawn.
pub const PROGRAM: &str = "mixed";

/// Which program each run drives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Programs {
    /// Every run drives [`PROGRAM`].
    Mixed,
    /// Each baseline and validation run drives a program the model draws from its own kinds
    /// per run (`--program random`, from the run's seed and the structure seed); the spread
    /// runs and the cases drive `cases`. So the calibration sees other programmes than the
    /// cases, as a user's calibration runs may, and the spread is measured on the cases' one,
    /// as the README's protocol asks.
    Drawn { cases: String },
}

/// The programs the independent model offers, from its `--list`.
pub fn program_kinds(program: &Path) -> Result<Vec<String>, GapError> {
    let text = python(program, &["--list".to_string()])?;
    let kinds: Vec<String> = text
        .lines()
        .skip_while(|l| !l.starts_with("programs"))
        .skip(1)
        .take_while(|l| l.starts_with(' '))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect();
    if kinds.is_empty() {
        return Err(GapError::Data(format!(
            "{} --list: expected a `programs:` section naming at least one program",
            program.display()
        )));
    }
    Ok(kinds)
}

/// The cases' program of a campaign with drawn programmes: one of `kinds`, uniformly, drawn
/// from the campaign's seed and structure seed (the same for every shard).
pub fn draw_case_program(kinds: &[String], seed: u64, structure_seed: Option<u64>) -> String {
    let mixed = seed ^ structure_seed.unwrap_or(0).rotate_left(32);
    let mut rng = crate::sensors::rng::stream(mixed, "gap-bench-independent-programs");
    kinds[rng.random_range(0..kinds.len())].clone()
}
/// Null runs the between-run spread is measured on.
pub const SPREAD_RUNS: usize = 3;

/// The independent model's effects the benchmark runs, in the library's order.
pub static HIDDEN: LazyLock<Vec<Hidden>> = LazyLock::new(|| {
    effects::LIBRARY
        .iter()
        .filter_map(|e| {
            let h = e.hidden?;
            Some(Hidden::of(e, h.independent, h.factor))
        })
        .collect()
});

/// The effect the independent model calls `name`.
pub fn by_name(name: &str) -> Result<&'static Hidden, GapError> {
    HIDDEN.iter().find(|h| h.name == name).ok_or_else(|| {
        GapError::Data(format!(
            "--effects: `{name}` is not an effect of the independent model the benchmark \
             runs; known: {}",
            HIDDEN.iter().map(|h| h.name).collect::<Vec<_>>().join(", ")
        ))
    })
}

/// The program, built into the binary so a run needs no copy of the repository.
pub const EMBEDDED: &str = include_str!("../../../pty-tests/independent/mako_independent.py");

/// The embedded program written to a private temporary file (removed when dropped), for a
/// run not given `--independent PATH`.
pub fn embedded_program() -> Result<tempfile::NamedTempFile, GapError> {
    let dir = std::env::temp_dir();
    let cannot = |e: std::io::Error| {
        GapError::Data(format!(
            "cannot write the built-in independent model to a temporary file in {} ({e}); \
             set TMPDIR to a writable directory or give --independent PATH",
            dir.display()
        ))
    };
    let mut file = tempfile::Builder::new()
        .prefix("eyebot-mako_independent-")
        .suffix(".py")
        .tempfile_in(&dir)
        .map_err(cannot)?;
    std::io::Write::write_all(&mut file, EMBEDDED.as_bytes()).map_err(cannot)?;
    Ok(file)
}

/// Runs `python3 program args`, returning its standard output; errors name the program.
fn python(program: &Path, args: &[String]) -> Result<String, GapError> {
    let out = Command::new("python3")
        .arg(program)
        .args(args)
        .output()
        .map_err(|e| {
            GapError::Data(format!(
                "cannot run `python3` (needed for the independent model {}): {e}",
                program.display()
            ))
        })?;
    if !out.status.success() {
        return Err(GapError::Data(format!(
            "python3 {} {}: {}: {}",
            program.display(),
            args.join(" "),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The default size of every hidden effect, from the program's `--list`.
pub fn default_sizes(program: &Path) -> Result<Vec<(String, Vec<f64>)>, GapError> {
    let text = python(program, &["--list".to_string()])?;
    let mut out = Vec::new();
    let mut in_effects = false;
    for line in text.lines() {
        if line.starts_with("hidden effects") {
            in_effects = true;
            continue;
        }
        if !in_effects || !line.starts_with(' ') {
            continue;
        }
        let mut words = line.split_whitespace();
        let (Some(name), Some(size)) = (words.next(), words.next()) else {
            continue;
        };
        if size == "-" {
            continue;
        }
        let values: Result<Vec<f64>, _> = size.split(',').map(str::parse::<f64>).collect();
        let values = values.map_err(|_| {
            GapError::Data(format!(
                "{} --list: effect `{name}`: default size `{size}` is not a number list",
                program.display()
            ))
        })?;
        out.push((name.to_string(), values));
    }
    Ok(out)
}

/// Writes one run of the independent model to `out`; with a structure seed, of the vehicle
/// that seed draws, started away from its stated start.
fn generate(
    program: &Path,
    kind: &str,
    seed: u64,
    structure_seed: Option<u64>,
    hidden: &[(&str, &[f64])],
    out: &Path,
) -> Result<(), GapError> {
    let mut args: Vec<String> = [
        "--program",
        kind,
        "--seed",
        &seed.to_string(),
        "--duration",
        &DURATION_S.to_string(),
        "--out",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    args.push(out.display().to_string());
    if let Some(k) = structure_seed {
        args.extend([
            "--structure-seed".to_string(),
            k.to_string(),
            "--start-offset".to_string(),
            "random".to_string(),
        ]);
    }
    if hidden.is_empty() {
        args.extend(["--hidden".to_string(), "none".to_string()]);
    } else {
        // Two effects: `--hidden A+B --size 'SA;SB'`, a size's components joined by commas.
        let names: Vec<&str> = hidden.iter().map(|(name, _)| *name).collect();
        let sizes: Vec<String> = hidden
            .iter()
            .map(|(_, size)| {
                let parts: Vec<String> = size.iter().map(|v| format!("{v}")).collect();
                parts.join(",")
            })
            .collect();
        // `--size=V`, not `--size V`: a value such as `-0.03;8` would read as an option.
        args.extend([
            "--hidden".to_string(),
            names.join("+"),
            format!("--size={}", sizes.join(";")),
        ]);
    }
    python(program, &args).map(|_| ())
}

/// The independent model as a truth source: its program at `path`, its nominal vehicle or
/// the one `structure_seed` draws, driving `programs`.
pub struct Independent<'a> {
    pub program: &'a Path,
    pub structure_seed: Option<u64>,
    pub programs: Programs,
}

impl Independent<'_> {
    /// Checks the program exists; with `drawn`, draws the cases' program from the model's
    /// kinds and the campaign's `seed`.
    pub fn new(
        program: &Path,
        structure_seed: Option<u64>,
        drawn: bool,
        seed: u64,
    ) -> Result<Independent<'_>, GapError> {
        if !program.is_file() {
            return Err(GapError::Data(format!(
                "the independent model {} does not exist (--independent PATH)",
                program.display()
            )));
        }
        let programs = if drawn {
            Programs::Drawn {
                cases: draw_case_program(&program_kinds(program)?, seed, structure_seed),
            }
        } else {
            Programs::Mixed
        };
        Ok(Independent {
            program,
            structure_seed,
            programs,
        })
    }

    /// The program the cases and spread runs drive.
    pub fn case_program(&self) -> &str {
        match &self.programs {
            Programs::Mixed => PROGRAM,
            Programs::Drawn { cases } => cases,
        }
    }
}

impl Truth for Independent<'_> {
    fn default_sizes(&self) -> Result<Vec<(String, Vec<f64>)>, GapError> {
        default_sizes(self.program)
    }

    fn baseline(&self, _index: usize, seed: u64, out: &Path) -> Result<(), GapError> {
        let kind = match self.programs {
            Programs::Mixed => PROGRAM,
            Programs::Drawn { .. } => "random",
        };
        generate(self.program, kind, seed, self.structure_seed, &[], out)
    }

    /// As the README's protocol has it: repeat null runs of the cases' programme, apart
    /// from the runs the calibration is fitted to (three give the spread three degrees of
    /// freedom; the baseline runs would give two).
    fn spread_runs(&self) -> usize {
        SPREAD_RUNS
    }

    fn case(&self, seed: u64, hidden: &[(&Hidden, &[f64])], out: &Path) -> Result<(), GapError> {
        let named: Vec<(&str, &[f64])> = hidden.iter().map(|(h, s)| (h.name, *s)).collect();
        let kind = self.case_program();
        generate(self.program, kind, seed, self.structure_seed, &named, out)
    }
}
