//! `replay --serial DEVICE`: the real-serial output path (tokio-serial, termios applied),
//! exercised on one end of a socat-linked pty pair, read on the other end.

use std::time::Duration;

use eyebot_hil::replay::{ByteSink, Options, Pacing, Policy, Port, Quiet, Replay, Shutdown};
use eyebot_hil::transport::serial;
use eyebot_test_support::TempDir;
use eyebot_test_support::process::socat_pair;
use eyebot_test_support::pty::{PtyFixture, TimedReader, concat};
use pty_tests::fixture_dir;

#[test]
fn replay_onto_a_serial_device_reaches_the_other_end() {
    let dir = TempDir::new("replay-serial");
    let (a, b) = (dir.join("a"), dir.join("b"));
    let _socat = socat_pair(&a, &b);
    let reader = TimedReader::spawn(&b);

    let expected = std::fs::read(fixture_dir("replay").join("expected-fix.bin")).unwrap();
    let mut opts = Options::new(vec![fixture_dir("replay").join("timed.log")]);
    opts.policy = Policy::Fix;
    opts.pacing = Some(Pacing::Baud);
    opts.speed = 1.0;
    opts.line = Some("115200 8N1".parse().unwrap());
    let replay = Replay::open(opts).unwrap();
    let runtime = PtyFixture::new(dir.path(), "unused").runtime;
    let _enter = runtime.enter();
    let port = serial::open(&a, &replay.line_settings()).expect("open the serial device");
    let mut sink = ByteSink::new(Port::Serial(port), &replay.line_settings());
    let summary = replay
        .run(&mut sink, &mut Quiet, &Shutdown::new())
        .expect("replay runs");
    let reads = reader.finish_when(expected.len(), Duration::from_secs(5));
    assert_eq!(concat(&reads), expected);
    // 876 bytes back to back at 115200 8N1 take 76 ms on the line; the replay cannot be faster.
    let min_s = expected.len() as f64 * 10.0 / 115_200.0;
    assert!(
        summary.elapsed.as_secs_f64() >= min_s,
        "{} s < wire time {min_s} s",
        summary.elapsed.as_secs_f64()
    );
}
