//! `eyebot-hil replay` onto a real pty, read from the slave side as a control program would.
//!
//! The fixtures and the bytes a consumer must see are written by
//! `fixtures/replay/make_fixtures.py`, which computes checksums and policies on its own, so
//! these tests compare the replay against an independent oracle.

use std::time::Duration;

use eyebot_hil::replay::{Options, Pacing, Policy};
use eyebot_test_support::TempDir;
use eyebot_test_support::pty::concat;
use pty_tests::replay::{fixture, read_fixture, replay_to_pty};

fn expected_problems() -> Vec<(u64, String, String)> {
    String::from_utf8(read_fixture("problems.tsv"))
        .unwrap()
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            (f[0].parse().unwrap(), f[1].to_string(), f[2].to_string())
        })
        .collect()
}

/// Each policy gives exactly the bytes the oracle computed, and every problem is reported
/// once with its file:line.
#[test]
fn each_policy_gives_the_expected_bytes_and_reports_each_problem_once() {
    for (policy, expected_file) in [
        (Policy::Pass, "expected-pass.bin"),
        (Policy::Drop, "expected-drop.bin"),
        (Policy::Fix, "expected-fix.bin"),
    ] {
        let expected = read_fixture(expected_file);
        let mut opts = Options::new(vec![fixture("timed.log")]);
        opts.policy = policy;
        opts.pacing = Some(Pacing::Fast);
        let out = replay_to_pty(opts, expected.len(), Duration::ZERO, None);
        let got = concat(&out.reads);
        assert_eq!(
            String::from_utf8_lossy(&got),
            String::from_utf8_lossy(&expected),
            "consumer bytes under {policy:?}"
        );
        assert_eq!(got, expected, "byte for byte under {policy:?}");

        let reported: Vec<(u64, String)> = out
            .observed
            .problems
            .iter()
            .map(|p| (p.loc.line, p.kind.name().to_string()))
            .collect();
        let oracle = expected_problems();
        assert_eq!(
            reported,
            oracle
                .iter()
                .map(|(l, k, _)| (*l, k.clone()))
                .collect::<Vec<_>>(),
            "problems under {policy:?}: {:#?}",
            out.observed.problems
        );
        for p in &out.observed.problems {
            assert!(
                p.to_string()
                    .contains(&format!("timed.log:{}:", p.loc.line)),
                "report names file:line: {p}"
            );
        }
        if policy == Policy::Fix {
            for (p, (_, _, action)) in out.observed.problems.iter().zip(&oracle) {
                let shown = p.action.to_string();
                assert!(
                    shown.contains(action.as_str()),
                    "line {}: action `{shown}`, oracle says {action}",
                    p.loc.line
                );
            }
        }
        // Counted in the summary: three LF-only lines, one report.
        assert_eq!(out.summary.problems.get("LF without CR"), Some(&3));
        assert_eq!(out.summary.checksum_failures, 2);
        assert_eq!(out.summary.comments, 2, "two comments besides #Serial");
    }
}

/// Two ISO 8601 logs merged by time; ties go to the log named first.
#[test]
fn merged_logs_keep_time_order_with_ties_by_file_order() {
    let expected = read_fixture("expected-merge.bin");
    let mut opts = Options::new(vec![fixture("merge-a.log"), fixture("merge-b.log")]);
    opts.pacing = Some(Pacing::Fast);
    let out = replay_to_pty(opts, expected.len(), Duration::ZERO, None);
    assert_eq!(
        String::from_utf8_lossy(&concat(&out.reads)),
        String::from_utf8_lossy(&expected)
    );
}

/// A gzip copy (named without .gz) replays exactly like the plain log.
#[test]
fn gzip_log_replays_like_the_plain_one() {
    use std::io::Write;
    let dir = TempDir::new("replay-gz");
    let gz = dir.join("timed-log-copy");
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(&read_fixture("timed.log")).unwrap();
    std::fs::write(&gz, enc.finish().unwrap()).unwrap();
    let expected = read_fixture("expected-fix.bin");
    let mut opts = Options::new(vec![gz]);
    opts.policy = Policy::Fix;
    opts.pacing = Some(Pacing::Fast);
    let out = replay_to_pty(opts, expected.len(), Duration::ZERO, None);
    assert_eq!(concat(&out.reads), expected);
}
