//! The harness leaves nothing behind in the system's temporary directory: every fixture a
//! test uses (temporary directories, the daemon as a binary and in-process, ptys, C builds)
//! removes what it made when it drops, also when the test panics. A test binary of its own,
//! so no other test of this process makes directories while it counts them. Run without
//! `EYEBOT_HIL_KEEP`, which keeps the directories on purpose.

use std::path::{Path, PathBuf};

use eyebot_test_support::config::{LOCKSTEP, config_text};
use eyebot_test_support::dir::process_prefix;
use eyebot_test_support::eyebot_c::{self, Target};
use eyebot_test_support::pty::PtyFixture;
use eyebot_test_support::{Daemon, InProcessDaemon, RunningDaemon, TempDir};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

/// The entries of the system's temporary directory this process's harness made.
fn ours() -> Vec<String> {
    let prefix = process_prefix();
    std::fs::read_dir(std::env::temp_dir())
        .expect("list the temporary directory")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|name| name.starts_with(&prefix))
        .collect()
}

/// Runs each typical fixture; returns the paths they made, all still there at the end.
fn run_fixtures() -> Vec<PathBuf> {
    let mut made = Vec::new();
    let dir = TempDir::new("cleanup-dir");
    dir.write("file", "text");
    std::fs::create_dir(dir.join("sub")).expect("a subdirectory");
    made.push(dir.path().to_path_buf());

    // The binary, recording, stopped cleanly; and one left running for `Drop` to kill.
    let bin_dir = TempDir::new("cleanup-bin");
    let record = bin_dir.join("rec");
    let mut stopped = Daemon::start(
        BIN,
        bin_dir,
        &[
            "--time-mode",
            "lockstep",
            "--record",
            record.to_str().expect("UTF-8"),
        ],
    );
    stopped.stop();
    assert!(
        record.join("bytes.tsv").is_file(),
        "the recording is in the test's directory"
    );
    made.push(stopped.dir.path().to_path_buf());
    let killed = Daemon::start(
        BIN,
        TempDir::new("cleanup-killed"),
        &["--time-mode", "lockstep"],
    );
    made.push(killed.dir.path().to_path_buf());

    // In-process, left running for `Drop` to stop.
    let in_process = InProcessDaemon::start(
        TempDir::new("cleanup-inproc"),
        &config_text(&[LOCKSTEP]),
        None,
        |_| {},
    );
    assert!(in_process.status_socket().exists());
    made.push(in_process.dir.path().to_path_buf());

    // A pty with its symlink.
    let pty_dir = TempDir::new("cleanup-pty");
    let fixture = PtyFixture::new(pty_dir.path(), "link");
    let pty = fixture.open();
    assert!(fixture.link.exists());
    made.push(pty_dir.path().to_path_buf());

    // A C build goes to cargo's own scratch directory under the target directory (which
    // `cargo clean` removes), not to the system's temporary directory. The checkout itself
    // may live under the temporary directory, so the check is where the build is, not where
    // it is not.
    let build = eyebot_c::build(
        env!("CARGO_TARGET_TMPDIR"),
        "cleanup",
        Target::Host,
        &[],
        &[],
    );
    assert!(
        build.starts_with(env!("CARGO_TARGET_TMPDIR")),
        "a C build in {}, outside {}",
        build.display(),
        env!("CARGO_TARGET_TMPDIR")
    );

    for path in &made {
        assert!(
            path.exists(),
            "{} exists while its fixture lives",
            path.display()
        );
    }
    drop((pty, fixture, pty_dir, in_process, killed, stopped, dir));
    made
}

/// A test that panics with a daemon running and a directory full: unwinding removes both.
fn panic_with_fixtures() -> Vec<PathBuf> {
    let made = std::sync::Mutex::new(Vec::new());
    let result = std::panic::catch_unwind(|| {
        let dir = TempDir::new("cleanup-panic");
        dir.write("file", "text");
        let daemon = Daemon::options(BIN, "cleanup-panic-bin").start();
        made.lock()
            .expect("lock")
            .extend([dir.path().to_path_buf(), daemon.dir.path().to_path_buf()]);
        panic!("a failing test");
    });
    assert!(result.is_err());
    made.into_inner().expect("lock")
}

fn assert_gone(paths: &[PathBuf]) {
    let left: Vec<&Path> = paths
        .iter()
        .map(PathBuf::as_path)
        .filter(|p| p.exists())
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn the_harness_leaves_nothing_in_the_temp_dir() {
    assert!(
        std::env::var_os("EYEBOT_HIL_KEEP").is_none(),
        "EYEBOT_HIL_KEEP keeps the test directories on purpose: unset it for this test"
    );
    assert_eq!(ours(), Vec::<String>::new(), "before the fixtures");
    let made = run_fixtures();
    assert_gone(&made);
    let made = panic_with_fixtures();
    assert_gone(&made);
    assert_eq!(ours(), Vec::<String>::new(), "after the fixtures");
}
