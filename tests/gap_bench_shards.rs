//! A sharded benchmark merges into the unsharded one: `gap-bench --shard K/3 --out-part`
//! three times, then `gap-bench merge`, gives the table and the per-case results of one
//! unsharded run. Wall time differs run to run: the comparison leaves it out (the `seconds`
//! field of each case is zeroed and the table's last column, s/case, is cut off); every other
//! column and field must be equal. And the bad inputs of a merge (a missing part, overlapping
//! shards, parts from other options or another calibration) and of `--shard` (0/3, 4/3) are clear errors.

use std::path::PathBuf;

use eyebot_hil::gap::bench::{self, BenchOptions, CaseResult, Part, Shard, Source};
use eyebot_hil::gap::effects;
use eyebot_test_support::TempDir;

fn options(seed: u64) -> BenchOptions {
    BenchOptions {
        source: Source::Simulator,
        cases: 2,
        seed,
        effects: vec![effects::by_name("water_current").expect("library effect")],
        hidden: Vec::new(),
        independent_path: PathBuf::new(),
        structure_seed: None,
        drawn_programs: false,
        pairs: 0,
        baselines: 3,
        bridge: Default::default(),
        keep: None,
    }
}

/// The table without its wall-time column (the last one).
fn without_seconds(table: &str) -> String {
    table
        .lines()
        .map(|l| match l.trim_end_matches('|').rsplit_once('|') {
            Some((head, _)) if l.starts_with('|') => format!("{head}|"),
            _ => l.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn timeless(results: &[CaseResult]) -> Vec<CaseResult> {
    results
        .iter()
        .cloned()
        .map(|mut r| {
            r.seconds = 0.0;
            r
        })
        .collect()
}

/// Writes the three shards' parts of `opts` to `dir` and reads them back.
fn parts(opts: &BenchOptions, dir: &TempDir) -> Vec<(PathBuf, Part)> {
    (1..=3)
        .map(|k| {
            let shard = Shard::new(k, 3).expect("valid shard");
            let part =
                bench::run_part(opts, shard, None, &mut |_, _, _, _| {}).expect("shard runs");
            let path = dir.path().join(format!("part-{k}.json"));
            part.write(&path).expect("part written");
            let back = Part::read(&path).expect("part read back");
            assert_eq!(back, part, "a part survives its file");
            (path, back)
        })
        .collect()
}

#[test]
fn three_merged_shards_equal_the_unsharded_run() {
    let dir = TempDir::new("gap-bench-shards");
    let opts = options(4242);
    let whole = bench::run(&opts, None, None, &mut |_, _, _, _| {}).expect("unsharded run");
    assert_eq!(whole.results.len(), 4, "2 water-current and 2 null cases");
    let parts = parts(&opts, &dir);
    // Case i belongs to shard i % 3 + 1: shard 3 of 4 cases holds only case 2.
    assert_eq!(
        parts
            .iter()
            .map(|(_, p)| p.results.iter().map(|r| r.index).collect::<Vec<_>>())
            .collect::<Vec<_>>(),
        vec![vec![0, 3], vec![1], vec![2]]
    );
    // Merged in any order of the files.
    let shuffled = vec![parts[2].clone(), parts[0].clone(), parts[1].clone()];
    let (key, merged) = bench::merge(&shuffled).expect("the parts merge");
    assert_eq!(key, opts.key());
    assert_eq!(timeless(&merged.results), timeless(&whole.results));
    let t_whole = bench::table(Source::Simulator, &whole.results, None);
    let t_merged = bench::table(key.source, &merged.results, None);
    assert_eq!(without_seconds(&t_merged), without_seconds(&t_whole));
    assert!(t_whole.contains("| water_current | 2 |"), "{t_whole}");

    // A missing part is named by its shard.
    let err = bench::merge(&parts[..2]).unwrap_err().to_string();
    assert!(err.contains("3/3") && err.contains("missing"), "{err}");
    // Overlapping shards: the same shard twice names both files.
    let twice = vec![parts[0].clone(), parts[1].clone(), parts[0].clone()];
    let err = bench::merge(&twice).unwrap_err().to_string();
    assert!(
        err.contains("overlap") && err.contains("part-1.json"),
        "{err}"
    );
    // A part from other options (another seed) names its file.
    let mut other = parts[2].clone();
    other.0 = dir.path().join("other-seed.json");
    other.1.options.seed += 1;
    let mixed = vec![parts[0].clone(), parts[1].clone(), other];
    let err = bench::merge(&mixed).unwrap_err().to_string();
    assert!(
        err.contains("other-seed.json") && err.contains("other options"),
        "{err}"
    );
    // A part whose calibration differs (another build or model) names its file.
    let mut recal = parts[1].clone();
    recal.0 = dir.path().join("recalibrated.json");
    recal.1.calibration = Some(bench::CalibrationGap {
        gap_before: 5.0,
        gap_after: 1.0,
        reduction_pct: 80.0,
        seconds: 1.0,
        spread: None,
        baselines: 3,
    });
    let mixed = vec![parts[0].clone(), recal, parts[2].clone()];
    let err = bench::merge(&mixed).unwrap_err().to_string();
    assert!(
        err.contains("recalibrated.json") && err.contains("calibration"),
        "{err}"
    );
    // A part file that holds another shard's cases is refused on reading.
    let mut wrong = parts[0].1.clone();
    wrong.shard = Shard::new(2, 3).expect("valid shard");
    let path = dir.path().join("wrong-cases.json");
    wrong.write(&path).expect("written");
    let err = Part::read(&path).unwrap_err().to_string();
    assert!(err.contains("wrong-cases.json"), "{err}");
}

#[test]
fn a_shard_outside_1_to_n_is_refused() {
    for bad in ["0/3", "4/3", "1/0", "3", "a/3"] {
        let err = bad.parse::<Shard>().unwrap_err();
        assert!(err.contains(bad), "{bad}: {err}");
    }
    assert_eq!("2/3".parse::<Shard>(), Ok(Shard { k: 2, n: 3 }));
}

#[test]
fn a_missing_part_file_is_named() {
    let dir = TempDir::new("gap-bench-missing");
    let path = dir.path().join("absent.json");
    let err = Part::read(&path).unwrap_err().to_string();
    assert!(err.contains("absent.json"), "{err}");
    std::fs::write(&path, "{}").expect("written");
    let err = Part::read(&path).unwrap_err().to_string();
    assert!(
        err.contains("absent.json") && err.contains("part file"),
        "{err}"
    );
}
