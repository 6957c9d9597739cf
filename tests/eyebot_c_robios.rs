//! libeyebot's RoBIOS back-end (`firmware-protocol/c/eb_robios.c`), built with
//! `BACKEND=robios` and `-Wall -Wextra -Werror` against a TEST-ONLY stand-in for the RoBIOS
//! serial and timing calls (`tests/robios_stub/`: the calls mapped onto POSIX ttys), linked
//! with unchanged examples and run against the bridge over ptys. What this proves and what it
//! does not: docs/eyebot.md, "Testing the RoBIOS back-end".

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use eyebot_hil::record::Direction;

use eyebot_test_support::eyebot_c::{self, Target, assert_same_run, run_to_end, start_daemon};
use eyebot_test_support::pty::PtyFixture;
use eyebot_test_support::{Daemon, TempDir, require_tool};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");
const TMP: &str = env!("CARGO_TARGET_TMPDIR");

const TIMEOUT: Duration = Duration::from_secs(300);
/// Where the wall-following course starts (configs/worlds/pool.toml [wall_following]).
const WALL_START: ([f64; 3], f64) = ([2.0, 1.5, 0.5], 0.0);

fn stub_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/robios_stub")
}

/// Builds libeyebot with the RoBIOS back-end, the stand-in and the examples into
/// `CARGO_TARGET_TMPDIR/eyebot-c/<name>-host/`. `timeout_ms` is the compiled-in reply timeout
/// (`EYEBOT_HIL_TIMEOUT_MS`); the time mode is lockstep.
fn build_robios(name: &str, timeout_ms: u32) -> PathBuf {
    let stub = stub_dir();
    let objects = Path::new(TMP).join("eyebot-c").join(format!("{name}-stub"));
    std::fs::create_dir_all(&objects).expect("create the stub directory");
    let stub_o = objects.join("robios_stub.o");
    // the stand-in itself is held to the same flags as the library
    let status = Command::new(require_tool("cc", "gcc"))
        .args([
            "-std=c99",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            "-O2",
            "-c",
        ])
        .arg(stub.join("robios_stub.c"))
        .arg("-o")
        .arg(&stub_o)
        .status()
        .expect("run cc");
    assert!(status.success(), "the RoBIOS stand-in does not compile");
    let cflags = format!(
        "CFLAGS=-O2 -I{} -DEYEBOT_ROBIOS_HEADER='\"robios_stub.h\"' \
         -DEYEBOT_HIL_TIME_MODE='\"lockstep\"' -DEYEBOT_HIL_TIMEOUT_MS='\"{timeout_ms}\"'",
        stub.display()
    );
    eyebot_c::build(
        TMP,
        name,
        Target::Host,
        &[],
        &[
            "BACKEND=robios".into(),
            // timer_square uses RoBIOS's own timers and threads, which the stand-in lacks
            "EXAMPLES=heading_hold spot_turn dive_hold sonar_three wall_follower".into(),
            cflags,
            format!("LDLIBS={}", stub_o.display()),
        ],
    )
}

/// The stand-in's serial ports: SERIAL1 is the sensor link (EYEBOT_HIL_SENSOR_PORT's
/// default), SERIAL2 the sonar line.
fn stub_env(daemon: &Daemon) -> Vec<(String, String)> {
    vec![
        (
            "ROBIOS_STUB_SERIAL1".into(),
            daemon.run_dir.join("sensor").display().to_string(),
        ),
        (
            "ROBIOS_STUB_SERIAL2".into(),
            daemon.run_dir.join("sonar").display().to_string(),
        ),
    ]
}

/// The same program and seed in lockstep: the RoBIOS build (byte-by-byte serial calls, a
/// 1/100 s polling clock) sends and receives exactly the bytes the POSIX build does, at the
/// same simulated times, and prints the same LCD text. sonar_three uses the sensor link
/// (HELLO, TIME_MODE, TIME_ADVANCE for every tick it waits) and SERIAL2 (selects, acks,
/// NMEA) through the stand-in.
#[test]
fn robios_backend_gives_the_posix_transcript() {
    let robios = build_robios("robios", 3000);
    let posix = eyebot_c::build(TMP, "robios-posix", Target::Host, &[], &[]);
    let program = "sonar_three";
    let mut runs = Vec::new();
    for (label, dir) in [("posix", &posix), ("robios", &robios)] {
        let daemon = start_daemon(BIN, &format!("robios-{label}"), Some(WALL_START), 7);
        let env = stub_env(&daemon);
        let env: Vec<(&str, &str)> = env.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
        let (rec, stdout) = run_to_end(daemon, Target::Host, &dir.join(program), &env, TIMEOUT);
        runs.push((rec.transcript(), stdout));
    }
    let (p, r) = (&runs[0], &runs[1]);
    assert!(
        r.0.iter()
            .any(|c| c.link == "sonar" && c.dir == Direction::Rx),
        "the RoBIOS build sent nothing on SERIAL2"
    );
    assert_same_run("sonar_three, POSIX and RoBIOS", p, r);
    eprintln!(
        "{program}: POSIX and RoBIOS back-ends give the same transcript ({} chunks)\n{}",
        p.0.len(),
        r.1
    );
}

/// A bridge that never answers: the RoBIOS back-end sends HELLO, waits the compiled-in
/// timeout on the RoBIOS clock, resends the identical frame 3 times (PROTOCOL.md 2.2), then
/// ends the program with status 3 and says why on the LCD.
#[test]
fn robios_backend_times_out_and_resends_the_identical_frame() {
    const TIMEOUT_MS: u32 = 300;
    let out = build_robios("robios-timeout", TIMEOUT_MS);
    let dir = TempDir::new("robios-timeout");
    let pty = PtyFixture::new(dir.path(), "sensor");
    let master = pty.open();
    let started = Instant::now();
    let run = Command::new(out.join("heading_hold"))
        .env("ROBIOS_STUB_SERIAL1", &pty.link)
        .output()
        .expect("run heading_hold");
    let elapsed = started.elapsed();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert_eq!(run.status.code(), Some(3), "{:?}: {stdout}", run.status);
    assert!(stdout.contains("no HELLO_REPLY"), "{stdout}");
    // four attempts, each waiting the timeout (the clock ticks in 1/100 s)
    assert!(
        elapsed >= Duration::from_millis(4 * u64::from(TIMEOUT_MS) - 40),
        "gave up after {elapsed:?}"
    );
    assert!(elapsed < Duration::from_secs(10), "took {elapsed:?}");
    // what reached the bridge's side: the same HELLO frame four times
    let mut master = master;
    let bytes = pty.runtime.block_on(async {
        use tokio::io::AsyncReadExt;
        let mut bytes = Vec::new();
        let mut buf = [0u8; 256];
        while let Ok(Ok(n)) =
            tokio::time::timeout(Duration::from_millis(200), master.read(&mut buf)).await
        {
            if n == 0 {
                break;
            }
            bytes.extend_from_slice(&buf[..n]);
        }
        bytes
    });
    let hello = [0xEB, 0x90, 0x01, 0x01, 0x01, 0x01];
    assert_eq!(bytes.len(), 4 * 8, "bytes on the wire: {bytes:02x?}");
    for frame in bytes.chunks(8) {
        assert_eq!(&frame[..6], &hello, "not HELLO seq 1: {frame:02x?}");
        assert_eq!(frame, &bytes[..8], "a resend differs: {bytes:02x?}");
    }
}
