//! Splitting a benchmark over machines: `gap-bench --shard K/N --out-part FILE` runs the cases
//! whose index `i` in the fixed case order has `i % N == K - 1` and writes them to a part file;
//! `gap-bench merge PART...` checks the parts belong together and rebuilds the whole result.
//!
//! Every case is planned (seed, size, direction) in the same order whatever the shard, so a
//! case is the same whichever shard runs it, and the merged table is the unsharded one.
//!
//! **Part file** (JSON): `{"format": 1, "options": {source, cases, seed, effects}, "shard":
//! {"k": K, "n": N}, "total": cases in the whole benchmark, "calibration": null or {gap_before,
//! gap_after, reduction_pct, seconds}, "results": [CaseResult with its "index", ...]}`.
//!
//! **Calibration file** (JSON, `gap-bench calibrate --out FILE`, read by `--calibration
//! FILE`): a campaign's calibration made once for all its shards. `{"format": 1, "options":
//! {...}, "base_model_sha256": hex, "truth_sha256": hex or null, "gap": null or {...},
//! "model": the calibrated model file (TOML) or null}`. A shard refuses one made with other
//! options (source, cases, seed, effects: the calibration's seeds are drawn with the cases),
//! from another base model, or from another independent model program.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::gap::GapError;
use crate::gap::bench::calibrated::Calibrated;
use crate::gap::bench::{CalibrationGap, CaseResult, OptionsKey, Outcome};

/// Version of the part file format.
pub const FORMAT: u32 = 1;
/// Version of the calibration file format.
pub const CALIBRATION_FORMAT: u32 = 1;

/// A campaign's calibration, made once (`gap-bench calibrate`) and read by every shard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    pub format: u32,
    /// The campaign it was made for.
    pub options: OptionsKey,
    /// [`super::base_model_sha256`] of the build that made it.
    pub base_model_sha256: String,
    /// [`super::truth_sha256`]: the independent model program it calibrated on.
    pub truth_sha256: Option<String>,
    /// How the calibrated model did on the null run it was not fitted to.
    pub gap: Option<CalibrationGap>,
    /// The calibrated model file (TOML); `None` for the simulator source, whose cases are
    /// analysed with the base model.
    pub model: Option<String>,
}

impl Calibration {
    /// The calibrated model, for the case loop.
    pub fn calibrated(&self) -> Option<Calibrated> {
        self.model.as_ref().map(|m| Calibrated {
            model_toml: m.clone(),
            gap: self.gap.clone(),
        })
    }

    pub fn write(&self, path: &Path) -> Result<(), GapError> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| GapError::Data(format!("{}: cannot encode: {e}", path.display())))?;
        std::fs::write(path, text + "\n").map_err(|source| GapError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Reads a calibration file; the model it holds must parse.
    pub fn read(path: &Path) -> Result<Self, GapError> {
        let text = std::fs::read_to_string(path).map_err(|source| GapError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let c: Calibration = serde_json::from_str(&text).map_err(|e| {
            GapError::Data(format!(
                "{}: not a gap-bench calibration file (expected the JSON `gap-bench calibrate \
                 --out` writes): {e}",
                path.display()
            ))
        })?;
        if c.format != CALIBRATION_FORMAT {
            return Err(GapError::Data(format!(
                "{}: calibration file format {} (this build reads {CALIBRATION_FORMAT})",
                path.display(),
                c.format
            )));
        }
        if let Some(cal) = c.calibrated() {
            cal.model(&format!("{}: model", path.display()))?;
        }
        Ok(c)
    }

    /// Checks the calibration belongs to the campaign `options` of this build: the same
    /// options, base model and truth program; and that it holds a model exactly when the
    /// source calibrates.
    pub fn check(
        &self,
        options: &OptionsKey,
        base_model_sha256: &str,
        truth_sha256: Option<&str>,
    ) -> Result<(), GapError> {
        let refuse = |what: String| {
            Err(GapError::Data(format!(
                "--calibration: {what}; make it with `gap-bench calibrate` and the same options \
                 as the shards"
            )))
        };
        if &self.options != options {
            return refuse(format!(
                "made for other options ({}) than this run's ({})",
                describe(&self.options),
                describe(options)
            ));
        }
        if self.base_model_sha256 != base_model_sha256 {
            return refuse(format!(
                "made from another base model (sha256 {}, this build's is {base_model_sha256}): \
                 another build of eyebot-hil",
                self.base_model_sha256
            ));
        }
        if self.truth_sha256.as_deref() != truth_sha256 {
            return refuse(format!(
                "made on another independent model program (sha256 {}, this run's is {})",
                self.truth_sha256.as_deref().unwrap_or("none"),
                truth_sha256.unwrap_or("none")
            ));
        }
        let calibrates = options.source != super::Source::Simulator;
        if self.model.is_some() != calibrates {
            return refuse(format!(
                "it {} a calibrated model, but the {} source {}",
                if self.model.is_some() {
                    "holds"
                } else {
                    "lacks"
                },
                options.source.name(),
                if calibrates {
                    "analyses with one"
                } else {
                    "calibrates nothing"
                }
            ));
        }
        Ok(())
    }
}

/// Shard `k` of `n` (1-based): the cases with `index % n == k - 1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub k: usize,
    pub n: usize,
}

impl Shard {
    /// The whole benchmark as one shard.
    pub const WHOLE: Shard = Shard { k: 1, n: 1 };

    pub fn new(k: usize, n: usize) -> Result<Self, String> {
        if n == 0 {
            return Err(format!("shard {k}/{n}: N must be at least 1"));
        }
        if k == 0 || k > n {
            return Err(format!("shard {k}/{n}: K must be between 1 and {n}"));
        }
        Ok(Self { k, n })
    }

    /// True when case `index` belongs to this shard.
    pub fn contains(self, index: usize) -> bool {
        index % self.n == self.k - 1
    }

    /// How many of `total` cases this shard runs.
    pub fn count(self, total: usize) -> usize {
        (0..total).filter(|i| self.contains(*i)).count()
    }
}

impl FromStr for Shard {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("`{s}`: expected K/N, e.g. 2/3 (shard K of N, 1 <= K <= N)");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let k: usize = k.trim().parse().map_err(|_| bad())?;
        let n: usize = n.trim().parse().map_err(|_| bad())?;
        Shard::new(k, n).map_err(|e| format!("`{s}`: {e}"))
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

/// Options as the command line gives them.
fn describe(k: &OptionsKey) -> String {
    format!(
        "--source {} --cases {} --seed {} --effects {}",
        k.source.name(),
        k.cases,
        k.seed,
        k.effects.join(",")
    )
}

/// One shard's results, as written to and read from a part file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Part {
    pub format: u32,
    pub options: OptionsKey,
    pub shard: Shard,
    /// Cases in the whole benchmark (every shard).
    pub total: usize,
    pub calibration: Option<CalibrationGap>,
    pub results: Vec<CaseResult>,
}

impl Part {
    pub fn new(options: OptionsKey, shard: Shard, total: usize, outcome: Outcome) -> Self {
        Self {
            format: FORMAT,
            options,
            shard,
            total,
            calibration: outcome.calibration,
            results: outcome.results,
        }
    }

    pub fn write(&self, path: &Path) -> Result<(), GapError> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| GapError::Data(format!("{}: cannot encode: {e}", path.display())))?;
        std::fs::write(path, text + "\n").map_err(|source| GapError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    pub fn read(path: &Path) -> Result<Self, GapError> {
        let text = std::fs::read_to_string(path).map_err(|source| GapError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let part: Part = serde_json::from_str(&text).map_err(|e| {
            GapError::Data(format!(
                "{}: not a gap-bench part file: {e}",
                path.display()
            ))
        })?;
        if part.format != FORMAT {
            return Err(GapError::Data(format!(
                "{}: part file format {} (this build reads {FORMAT})",
                path.display(),
                part.format
            )));
        }
        // The part must hold exactly its shard's cases.
        let want: Vec<usize> = (0..part.total)
            .filter(|i| part.shard.contains(*i))
            .collect();
        let have: Vec<usize> = part.results.iter().map(|r| r.index).collect();
        if want != have {
            return Err(GapError::Data(format!(
                "{}: shard {} of {} cases should hold cases {want:?}, holds {have:?}",
                path.display(),
                part.shard,
                part.total
            )));
        }
        Ok(part)
    }
}

/// Combines parts into the whole benchmark's outcome, in case order. The parts must come
/// from the same options, have the same number of shards, and cover every shard once.
pub fn merge(parts: &[(PathBuf, Part)]) -> Result<(OptionsKey, Outcome), GapError> {
    let Some((first_path, first)) = parts.first() else {
        return Err(GapError::Data("merge: no part files given".into()));
    };
    let mut seen: Vec<Option<&PathBuf>> = vec![None; first.shard.n];
    for (path, p) in parts {
        if p.options != first.options || p.total != first.total {
            return Err(GapError::Data(format!(
                "{}: made with other options ({:?}, {} cases) than {} ({:?}, {} cases)",
                path.display(),
                p.options,
                p.total,
                first_path.display(),
                first.options,
                first.total
            )));
        }
        if p.shard.n != first.shard.n {
            return Err(GapError::Data(format!(
                "{}: shard {} is one of {} shards, {} is shard {} of {}",
                path.display(),
                p.shard,
                p.shard.n,
                first_path.display(),
                first.shard,
                first.shard.n
            )));
        }
        // Every shard calibrates on the same runs, deterministically: other figures mean
        // another calibration (another build or independent model).
        let figures = |c: &Option<CalibrationGap>| c.as_ref().map(|c| (c.gap_before, c.gap_after));
        if figures(&p.calibration) != figures(&first.calibration) {
            return Err(GapError::Data(format!(
                "{}: its calibration ({:?}) differs from {}'s ({:?}): made by another build or \
                 independent model",
                path.display(),
                figures(&p.calibration),
                first_path.display(),
                figures(&first.calibration)
            )));
        }
        let slot = &mut seen[p.shard.k - 1];
        if let Some(other) = slot {
            return Err(GapError::Data(format!(
                "{}: shard {} is also in {}: the parts overlap",
                path.display(),
                p.shard,
                other.display()
            )));
        }
        *slot = Some(path);
    }
    let missing: Vec<String> = seen
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_none())
        .map(|(k, _)| format!("{}/{}", k + 1, first.shard.n))
        .collect();
    if !missing.is_empty() {
        return Err(GapError::Data(format!(
            "merge: shard(s) {} missing (given: {})",
            missing.join(", "),
            parts
                .iter()
                .map(|(p, _)| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    let mut results: Vec<CaseResult> = parts
        .iter()
        .flat_map(|(_, p)| p.results.iter().cloned())
        .collect();
    results.sort_by_key(|r| r.index);
    // Every shard calibrates on the same runs: keep the first shard's figures.
    let calibration = parts
        .iter()
        .find(|(_, p)| p.shard.k == 1)
        .and_then(|(_, p)| p.calibration.clone());
    Ok((
        first.options.clone(),
        Outcome {
            results,
            calibration,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::bench::Source;

    fn key(seed: u64) -> OptionsKey {
        OptionsKey {
            source: Source::Independent,
            cases: 2,
            seed,
            effects: vec!["depth_offset".into()],
            structure_seed: None,
            pairs: 0,
            baselines: 3,
            drawn_programs: false,
        }
    }

    fn calibration() -> Calibration {
        Calibration {
            format: CALIBRATION_FORMAT,
            options: key(7),
            base_model_sha256: "base".into(),
            truth_sha256: Some("truth".into()),
            gap: None,
            model: Some("name = \"mako\"\nvehicle = \"vehicles/mako.toml\"\n".into()),
        }
    }

    /// A shard takes the calibration of its own campaign and refuses one of another seed,
    /// base model or independent program, or one with no model for a calibrated source,
    /// naming what differs.
    #[test]
    fn a_calibration_belongs_to_one_campaign() {
        let c = calibration();
        assert!(c.check(&key(7), "base", Some("truth")).is_ok());
        let refused = |r: Result<(), GapError>| match r {
            Ok(()) => panic!("accepted"),
            Err(e) => e.to_string(),
        };
        let e = refused(c.check(&key(8), "base", Some("truth")));
        assert!(e.contains("other options") && e.contains("--seed 8"), "{e}");
        let e = refused(c.check(&key(7), "other", Some("truth")));
        assert!(e.contains("another base model"), "{e}");
        let e = refused(c.check(&key(7), "base", Some("edited")));
        assert!(e.contains("another independent model program"), "{e}");
        let mut no_model = c.clone();
        no_model.model = None;
        let e = refused(no_model.check(&key(7), "base", Some("truth")));
        assert!(e.contains("lacks a calibrated model"), "{e}");
    }

    /// A calibration file survives its file, and one whose model does not parse is refused
    /// when read, naming the file.
    #[test]
    fn a_calibration_file_is_read_back_and_checked() {
        let dir = tempfile::tempdir().expect("scratch directory");
        let path = dir.path().join("calibration.json");
        let c = calibration();
        c.write(&path).expect("written");
        assert_eq!(Calibration::read(&path).expect("read back"), c);
        let mut bad = c.clone();
        bad.model = Some("name = \"mako\"\n".into());
        bad.write(&path).expect("written");
        let e = Calibration::read(&path).expect_err("a model without a vehicle");
        assert!(e.to_string().contains("calibration.json"), "{e}");
        std::fs::write(&path, "{}").expect("written");
        let e = Calibration::read(&path).expect_err("not a calibration");
        assert!(
            e.to_string().contains("not a gap-bench calibration file"),
            "{e}"
        );
    }
}
