//! A consumer this project did not write reads the replayed pty: Debian's gpsd, with gpspipe
//! printing the raw sentences it accepted. gpsd checks NMEA checksums itself, so the one bad
//! sentence in the fixture (sent unchanged under policy `pass`) must not come out.

use std::process::{Command, Stdio};
use std::thread;
use std::time::Duration;

use eyebot_hil::replay::{ByteSink, Options, Pacing, Policy, Port, Quiet, Replay, Shutdown};
use eyebot_test_support::process::{ChildGuard, free_tcp_port};
use eyebot_test_support::pty::PtyFixture;
use eyebot_test_support::{TempDir, require_tool, wait_for};
use pty_tests::fixture_dir;

#[test]
fn gpsd_reads_the_replayed_depth_sentences() {
    let gpsd = require_tool("gpsd", "gpsd");
    let gpspipe = require_tool("gpspipe", "gpsd-clients");
    let log = fixture_dir("replay").join("depth.log");
    let text = String::from_utf8(std::fs::read(&log).unwrap()).unwrap();
    let all: Vec<&str> = text.lines().collect();
    let bad = all[5];
    let good: Vec<&str> = all.iter().copied().filter(|l| *l != bad).collect();

    let dir = TempDir::new("replay-gpsd");
    let fixture = PtyFixture::new(dir.path(), "depth");
    let pty = fixture.open();
    let socket = dir.join("gpsd.sock");
    let port = free_tcp_port();
    let mut daemon = ChildGuard::spawn(
        "gpsd",
        Command::new(&gpsd)
            .args(["-N", "-n", "-b", "-F"])
            .arg(&socket)
            .args(["-S", &port.to_string()])
            .arg(&fixture.link)
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
    .remove_on_drop(&socket);
    wait_for("gpsd to listen", Duration::from_secs(10), || {
        std::net::TcpStream::connect(("127.0.0.1", port)).ok()
    });
    daemon.assert_running();

    // Replay in a loop at 20 sentences/s until gpspipe has what it wants.
    let stop = Shutdown::new();
    let mut opts = Options::new(vec![log.clone()]);
    opts.policy = Policy::Pass;
    opts.pacing = Some(Pacing::Rate { per_s: 20.0 });
    opts.looping = true;
    let replay = Replay::open(opts).unwrap();
    let line = replay.line_settings();
    let replay_stop = stop.clone();
    let runner = thread::spawn(move || {
        let mut sink = ByteSink::new(Port::Pty(pty), &line);
        replay.run(&mut sink, &mut Quiet, &replay_stop)
    });

    let want = 3 * good.len();
    let pipe = ChildGuard::spawn(
        "gpspipe",
        Command::new(&gpspipe)
            .args(["-r", "-n", &(want + 3).to_string()]) // + gpsd's 3 JSON header lines
            .arg(format!("127.0.0.1:{port}"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    );
    let output = pipe.wait_output(Duration::from_secs(30));
    stop.trigger();
    let summary = runner.join().unwrap().expect("replay ran");
    let out = String::from_utf8_lossy(&output.stdout);
    let sentences: Vec<&str> = out.lines().filter(|l| l.starts_with('$')).collect();
    eprintln!(
        "gpspipe printed {} sentences; replay sent {}",
        sentences.len(),
        summary.sentences_sent
    );
    assert!(
        sentences.len() >= 2 * good.len(),
        "gpspipe output:\n{out}\nstderr: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    for s in &sentences {
        assert!(
            good.contains(s),
            "gpsd passed on {s:?}, not a good fixture sentence"
        );
    }
    for g in &good {
        assert!(sentences.contains(g), "gpsd never showed {g}");
    }
    assert!(!sentences.contains(&bad), "gpsd rejects the bad checksum");
    assert!(summary.checksum_failures >= 1);
}
