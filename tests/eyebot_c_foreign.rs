//! A RoBIOS program nobody here wrote (`tests/foreign/robios_demo.c`, written in the style of
//! the public RoBIOS MK4 examples: LCD menu, KEYGet, MOTORDrive, OSGetAD, COMPASS, SERIAL2,
//! KEYWait) compiles against eyebot.h without edits and runs against the bridge.

use std::path::Path;
use std::time::Duration;

use eyebot_test_support::eyebot_c::{self, Target, run_program, start_daemon, stop_daemon};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

#[test]
fn foreign_robios_program_builds_and_runs_unchanged() {
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/foreign/robios_demo.c");
    let out = eyebot_c::build(
        env!("CARGO_TARGET_TMPDIR"),
        "foreign",
        Target::Host,
        &[&source],
        &[],
    );
    // open water (the world's `mid_pool` start): no wall in sonar range, so the first byte
    // on the sonar line after the program's select is the acknowledgement, not a sentence
    let mut daemon = start_daemon(BIN, "foreign", Some(([3.0, 6.25, 0.3], 0.0)), 3);
    let lcd = daemon.dir.join("lcd.txt");
    let run = run_program(
        &daemon,
        Target::Host,
        &out.join("robios_demo"),
        // KEY1 starts it; KEY4 at 60 s ends it
        &[
            ("EYEBOT_KEYS", "1,4@60"),
            ("EYEBOT_LCD", lcd.to_str().expect("utf-8 path")),
        ],
        Duration::from_secs(120),
    );
    let rec = stop_daemon(&mut daemon);
    let text = std::fs::read_to_string(&lcd).expect("LCD file");
    eprintln!("{text}\n{}", run.stderr);
    assert!(run.status.success(), "{:?}: {}", run.status, run.stderr);
    assert_eq!(text.matches("AD0=").count(), 10, "{text}");
    assert!(
        text.contains("serial: got '@'"),
        "the ack starts with '@': {text}"
    );
    assert!(text.contains("bye"), "{text}");
    // it really drove: 5 s at 50 % moves Mako forward
    let (first, last) = (&rec.states[0], rec.states.last().expect("states"));
    assert!(
        last.x_m - first.x_m > 0.5,
        "moved {:.2} m",
        last.x_m - first.x_m
    );
    // the key script's KEY4 at 60 s ended KEYWait: simulated time reached 60 s
    assert!(last.t_s >= 59.9, "ended at {} s", last.t_s);
}
