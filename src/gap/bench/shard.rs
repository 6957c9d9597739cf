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

use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::gap::GapError;
use crate::gap::bench::{CalibrationGap, CaseResult, OptionsKey, Outcome};

/// Version of the part file format.
pub const FORMAT: u32 = 1;

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
