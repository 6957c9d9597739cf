//! Where a run starts: course starts named in the world file, `run --start NAME` or
//! `--start NORTH,EAST,HEADING`, the check that a start lies inside the pool, and what
//! `probe sonar` says when it hears nothing.

use std::ffi::OsStr;
use std::process::Command;

use eyebot_test_support::config::DEFAULT_START;
use eyebot_test_support::{Daemon, TempDir};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

/// `eyebot-hil ARGS` in a fresh directory: (success, stderr).
fn refused(tag: &str, args: &[&str]) -> String {
    let dir = TempDir::new(tag);
    let out = Command::new(BIN)
        .args(args)
        .current_dir(dir.path())
        .output()
        .expect("run eyebot-hil");
    assert!(!out.status.success(), "{args:?} was accepted");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The `pose` line of `status`.
fn pose(daemon: &Daemon) -> String {
    let status = daemon.status_command(&[]);
    status
        .lines()
        .find(|l| l.starts_with("pose"))
        .unwrap_or_else(|| panic!("no pose in {status}"))
        .to_string()
}

#[test]
fn a_named_course_start_and_a_pose_place_the_vehicle() {
    let mut d = Daemon::options(BIN, "start-named")
        .lockstep()
        .args(&["--start", "wall_following"])
        .start();
    let p = pose(&d);
    d.stop();
    // configs/worlds/pool.toml [wall_following]: start_m = [2.0, 1.5, 0.5], heading 0
    assert!(
        p.contains("x 2.00 m  y 1.50 m") && p.contains("heading 0.0 deg"),
        "{p}"
    );

    let mut d = Daemon::options(BIN, "start-pose")
        .lockstep()
        .args(&["--start", "5,3,90"])
        .start();
    let p = pose(&d);
    d.stop();
    assert!(
        p.contains("x 5.00 m  y 3.00 m") && p.contains("heading 90.0 deg"),
        "{p}"
    );
}

#[test]
fn starts_outside_the_pool_or_unknown_are_refused_with_the_reason() {
    let err = refused("start-unknown", &["run", "--start", "nowhere"]);
    assert!(
        err.contains("--start nowhere: no such course start")
            && err.contains("centre, mid_pool, wall_following, west_wall"),
        "{err}"
    );
    let err = refused("start-outside", &["run", "--start", "30,2,0"]);
    assert!(
        err.contains("outside the pool: north 30.00 m is not within 0.3..24.70 m"),
        "{err}"
    );
    let err = refused("start-bad", &["run", "--start", "2,x,0"]);
    assert!(err.contains("expected NORTH,EAST,HEADING"), "{err}");

    // the configuration's own [start] is checked too
    let dir = TempDir::new("start-config");
    let config = dir.write_config(
        "outside.toml",
        &[(DEFAULT_START, "position_m = [3.0, 12.4, 0.3]")],
    );
    let err = refused(
        "start-config-run",
        &["run", "--config", config.to_str().expect("utf-8 path")],
    );
    assert!(
        err.contains("start.position_m") && err.contains("east 12.40 m is not within 0.3..12.20 m"),
        "{err}"
    );
}

/// `probe sonar` that hears nothing says why: in open water, no wall within range, with the
/// distances; in lockstep, that nobody advances time.
#[test]
fn a_silent_sonar_probe_says_why() {
    for (tag, args, expected) in [
        (
            "probe-open-water",
            vec!["--time-mode", "realtime", "--start", "mid_pool"],
            "no echo within the sonar's range",
        ),
        (
            "probe-lockstep",
            vec!["--time-mode", "lockstep"],
            "simulated time moves only when a client advances it",
        ),
    ] {
        let mut d = Daemon::options(BIN, tag).args(&args).start();
        let out = Command::new(BIN)
            .args([
                OsStr::new("probe"),
                OsStr::new("--link"),
                d.run_dir.join("sonar").as_os_str(),
                OsStr::new("sonar"),
                OsStr::new("1"),
                OsStr::new("--timeout-s"),
                OsStr::new("3"),
            ])
            .output()
            .expect("run probe");
        d.stop();
        let err = String::from_utf8_lossy(&out.stderr);
        eprintln!("{tag}: {err}");
        assert!(!out.status.success(), "{tag}: probe succeeded");
        // in lockstep even the ack waits for simulated time
        let first = if tag == "probe-lockstep" {
            "no ack"
        } else {
            "the ack came but no sentence"
        };
        assert!(err.contains(first), "{tag}: {err}");
        assert!(err.contains(expected), "{tag}: {err}");
        if tag == "probe-open-water" {
            assert!(err.contains("6.2 m west, 6.2 m east, 3.0 m south"), "{err}");
        }
    }
}
