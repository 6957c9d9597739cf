//! The binary's offline subcommands as a shell sees them: `simulate` and `replay` write to
//! standard output or a file, and end quietly when their reader has gone.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};

use eyebot_test_support::TempDir;
use eyebot_test_support::config::configs_dir;

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

/// A captured NMEA depth log of the replay fixtures.
fn depth_log() -> PathBuf {
    eyebot_test_support::workspace_root().join("pty-tests/fixtures/replay/depth.log")
}

/// `simulate --out -` writes the same CSV to standard output as to a file (the summary line
/// goes to standard error), and a reader that stops early ends it quietly, as for `cat`.
#[test]
fn simulate_out_dash_writes_the_csv_to_stdout() {
    let exp = configs_dir().join("experiments/acceleration.toml");
    let dir = TempDir::new("simulate");
    let file = dir.join("run.csv");
    let to_file = Command::new(BIN)
        .args([
            "simulate",
            exp.to_str().unwrap(),
            "--out",
            file.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(to_file.status.success(), "{to_file:?}");
    let to_stdout = Command::new(BIN)
        .current_dir(dir.path())
        .args(["simulate", exp.to_str().unwrap(), "--out", "-"])
        .output()
        .unwrap();
    assert!(to_stdout.status.success(), "{to_stdout:?}");
    assert_eq!(to_stdout.stdout, std::fs::read(&file).unwrap());
    assert!(String::from_utf8_lossy(&to_stdout.stderr).contains("-> standard output"));
    assert!(!dir.join("-").exists(), "no file named `-`");
    // A reader that takes one line and goes away.
    let mut child = Command::new(BIN)
        .args(["simulate", exp.to_str().unwrap(), "--out", "-"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with("t_s,"), "{first}");
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{out:?}");
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("panicked"),
        "{out:?}"
    );
}

/// A report whose reader has gone ends quietly with status 0, as a C tool would on SIGPIPE.
/// `replay --dry-run --stats` writes its sentences to standard output and its report to
/// standard error; with either closed, `println!` and `eprintln!` panicked.
#[test]
fn reports_end_quietly_when_their_reader_is_gone() {
    let log = depth_log();
    let replay = |stdout: Stdio, stderr: Stdio| {
        Command::new(BIN)
            .args(["replay", "--dry-run", "--stats", log.to_str().unwrap()])
            .stdout(stdout)
            .stderr(stderr)
            .output()
            .unwrap()
    };
    let closed = || {
        let (reader, writer) = std::io::pipe().expect("a pipe");
        drop(reader);
        Stdio::from(writer)
    };
    let open = replay(Stdio::piped(), Stdio::piped());
    assert!(open.status.success(), "{open:?}");
    assert!(
        !open.stdout.is_empty() && !open.stderr.is_empty(),
        "{open:?}"
    );
    for (what, out) in [
        ("standard output closed", replay(closed(), Stdio::piped())),
        ("standard error closed", replay(Stdio::piped(), closed())),
    ] {
        assert_eq!(out.status.code(), Some(0), "{what}: {out:?}");
        assert!(
            !String::from_utf8_lossy(&out.stderr).contains("panicked"),
            "{what}: {out:?}"
        );
    }
}

/// `replay --stdout | head` ends quietly with status 0 when its reader stops, as Unix tools
/// do; it ended with `writing to stdout: Broken pipe` and status 1.
#[test]
fn replay_to_stdout_ends_quietly_when_its_reader_stops() {
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let out = Command::new(BIN)
        .args(["replay", "--pacing", "fast", "--stdout"])
        .arg(depth_log())
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    assert!(!stderr.contains("Broken pipe"), "{stderr}");
}

/// `simulate configs/experiments/acceleration.toml`, the README's command, works outside the
/// clone: the path names an embedded config (it failed with `cannot read config`).
#[test]
fn simulate_reads_an_embedded_experiment_by_its_path_outside_the_clone() {
    let dir = TempDir::new("simulate-outside");
    let out = Command::new(BIN)
        .current_dir(dir.path())
        .args([
            "simulate",
            "configs/experiments/acceleration.toml",
            "--out",
            "run.csv",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let csv = std::fs::read_to_string(dir.join("run.csv")).unwrap();
    assert!(csv.lines().count() > 10, "{csv}");
}

/// `check` on a scenario file that does not exist says it cannot *read* it (it said
/// `cannot write`).
#[test]
fn check_names_a_missing_scenario_as_unreadable() {
    let dir = TempDir::new("check-missing");
    let missing = dir.join("missing.toml");
    let out = Command::new(BIN)
        .arg("check")
        .arg(&missing)
        .args(["--out"])
        .arg(dir.join("out"))
        .args(["--", "true"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{out:?}");
    assert!(
        stderr.contains(&format!("cannot read `{}`", missing.display())),
        "{stderr}"
    );
}

/// A long-running command carries on when nobody reads its standard output: `replay --pty`
/// with standard output closed still sends every sentence and removes its symlink, as the
/// daemon ignores a closed pipe for its readiness lines. Its announcement line panicked.
#[test]
fn replay_to_a_pty_carries_on_when_its_stdout_is_closed() {
    let dir = TempDir::new("replay-closed");
    let link = dir.join("link");
    let log = depth_log();
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let out = Command::new(BIN)
        .args(["replay", "--pacing", "fast", "--pty"])
        .arg(&link)
        .arg(&log)
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    assert!(stderr.contains("12 sentences sent"), "{stderr}");
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "the pty's symlink is removed"
    );
}

/// `gap-bench` refuses a source-specific flag given with a source that does not read it,
/// naming the flag and the source it goes with, before any case runs: `--keep` with the
/// simulator source used to be accepted and kept nothing.
#[test]
fn gap_bench_refuses_a_flag_its_source_does_not_read() {
    let dir = TempDir::new("gap-bench-flags");
    let cases: [(&[&str], &str, &str); 5] = [
        (&["--keep"], "--keep", "--source independent or bridge"),
        (
            &["--baselines", "2", "--out"],
            "--baselines",
            "--source independent or bridge",
        ),
        (
            &["--source", "bridge", "--drawn-programs", "--out"],
            "--drawn-programs",
            "--source independent",
        ),
        (
            &["--source", "independent", "--programs"],
            "--programs",
            "--source bridge",
        ),
        (
            &["--source", "bridge", "--independent"],
            "--independent",
            "--source independent",
        ),
    ];
    for (args, flag, expected) in cases {
        let out = Command::new(BIN)
            .arg("gap-bench")
            .args(["--cases", "1"])
            .args(args)
            .arg(dir.join("x"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}: {out:?}");
        assert!(stderr.contains(flag), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!dir.join("x").exists(), "{args:?}: nothing is written");
    }
    // A calibration needs a run, and the campaign draws three.
    for n in ["0", "4"] {
        let out = Command::new(BIN)
            .args(["gap-bench", "--source", "independent", "--baselines", n])
            .args(["--out", dir.join("x").to_str().unwrap()])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "--baselines {n}: {out:?}");
        assert!(stderr.contains("--baselines"), "--baselines {n}: {stderr}");
        assert!(stderr.contains("1..=3"), "--baselines {n}: {stderr}");
        assert!(
            !dir.join("x").exists(),
            "--baselines {n}: nothing is written"
        );
    }
}
