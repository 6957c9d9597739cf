//! An adversarial suite against the daemon over its ptys and sockets, by class: memory and
//! hangs, a local attacker in the run directory, races and configurations, lost or
//! miscounted data, and floods that must cost counters rather than output. (The
//! specification class is `conformance.rs`; the binary-level cases, second-user and SIGTERM
//! tests are the root crate's `daemon_hostile`, `daemon_robustness` and
//! `daemon_shutdown_drain`.) Each case takes well under a few seconds.

use std::io::Write;
use std::os::unix::fs::PermissionsExt;
use std::time::{Duration, Instant};

use eyebot_hil::config::{Directory, Document};
use eyebot_hil::daemon::config::DaemonConfig;
use eyebot_hil::daemon::{Daemon as Bridge, RunOptions};
use eyebot_test_support::config::{LOCKSTEP, config_text};
use eyebot_test_support::{InProcessDaemon, RunningDaemon, TempDir};
use firmware_protocol::sensor_link::Message;
use firmware_protocol::{LineItem, SonarCommand};
use pty_tests::wire::{Wire, frame_bytes};

const WAIT: Duration = Duration::from_secs(10);

fn daemon(tag: &str, lockstep: bool) -> InProcessDaemon {
    let edits: &[(&str, &str)] = if lockstep { &[LOCKSTEP] } else { &[] };
    InProcessDaemon::start(TempDir::new(tag), &config_text(edits), None, |_| {})
}

fn answers_hello(wire: &mut Wire, seq: u8, context: &str) {
    let r = wire.ask(seq, Message::Hello { client_version: 1 });
    assert!(matches!(r, Message::HelloReply { .. }), "{context}: {r:?}");
}

fn acks_select(sonar: &mut Wire, context: &str) {
    sonar.send(b"@S3\r");
    loop {
        match sonar.next_non_nmea(WAIT) {
            Some(LineItem::Sonar(SonarCommand::Ack(t))) if t.get() == 3 => return,
            Some(_) => continue,
            None => panic!("{context}: no ack for @S3"),
        }
    }
}

/// Starts the library's daemon on `config_text` in `dir` and returns how starting ended,
/// within `limit` (a start that hangs fails the test instead of hanging it).
fn try_start(dir: &TempDir, text: &str, limit: Duration) -> Result<(), String> {
    let run_dir = dir.join("run");
    let source = Directory::new(dir.path().to_path_buf());
    let (tx, rx) = std::sync::mpsc::channel();
    let text = text.to_string();
    std::thread::spawn(move || {
        let result = (|| -> Result<(), String> {
            let mut config = DaemonConfig::resolve(&Document::new("test config", &text))
                .map_err(|e| e.to_string())?;
            config.run_dir = run_dir;
            let model = eyebot_hil::daemon::plant::MakoPlant::from_config(&source, &config)
                .map_err(|e| e.to_string())?;
            let (board, mux) = eyebot_hil::daemon::plant::devices(&config);
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .map_err(|e| e.to_string())?;
            runtime.block_on(async {
                let bridge = Bridge::start(&config, model, board, mux, RunOptions::default())
                    .await
                    .map_err(|e| e.to_string())?;
                bridge.finish().await.map_err(|e| e.to_string())?;
                Ok::<(), String>(())
            })
        })();
        let _ = tx.send(result);
    });
    rx.recv_timeout(limit)
        .unwrap_or_else(|_| panic!("starting the daemon hung for {limit:?}"))
}

// ---- memory and hangs ----

/// Headers that each promise a 64-byte payload, back to back, and then silence: the decoder
/// never waits for more than one candidate, and the next request is answered.
#[test]
fn endless_frame_headers_do_not_wedge_the_sensor_link() {
    for lockstep in [false, true] {
        let mut d = daemon("adv-headers", lockstep);
        let mut s = Wire::open(&d.link("sensor"));
        answers_hello(&mut s, 0, "before");
        let header = [0xEB, 0x90, 0x10, 0x00, 0x40];
        let flood: Vec<u8> = header.iter().copied().cycle().take(64 * 1024).collect();
        s.send(&flood);
        // Read the advisory NAKs as they come (a client that does not read would have its
        // later replies dropped, by design), until the line has been quiet for 150 ms.
        s.drain(Duration::from_millis(150));
        // The flood's frames fail their CRCs (advisory NAKs) or are cut short: skip them.
        s.request(1, Message::Hello { client_version: 1 });
        loop {
            let f = s.next_frame("after the header flood", WAIT);
            if f.seq == 1 && matches!(f.message, Message::HelloReply { .. }) {
                break;
            }
        }
        d.stop();
    }
}

/// The sonar line: 256 KiB of `$`, over-long lines and CRs without LF, then a select.
#[test]
fn a_sonar_line_of_broken_sentences_still_acks_a_select() {
    let mut d = daemon("adv-sonar-junk", false);
    let mut sonar = Wire::open(&d.link("sonar"));
    let mut junk = Vec::new();
    while junk.len() < 256 * 1024 {
        junk.extend_from_slice(b"$$$$");
        junk.extend(std::iter::repeat_n(b'A', 90));
        junk.extend_from_slice(b"\r$SDDBT,1.0\r\r@Z\r@");
    }
    sonar.send(&junk);
    std::thread::sleep(Duration::from_millis(250));
    acks_select(&mut sonar, "after the junk");
    d.wait_status(WAIT, "the junk counted", |st| {
        st.links.iter().map(|l| l.errors).sum::<u64>() > 1000
    });
    d.stop();
}

/// A status client that sends garbage and never reads, and a feeder that writes random bytes
/// into the sonar feed socket: other status queries and both links keep working.
#[test]
fn hostile_socket_clients_do_not_stall_the_daemon() {
    let mut d = daemon("adv-sockets", false);
    let mut stuck = std::os::unix::net::UnixStream::connect(d.status_socket()).expect("status");
    // The server may close on garbage; a refused write is fine.
    let _ = stuck.write_all(&[0xFF; 4096]);
    let mut feeder = std::os::unix::net::UnixStream::connect(d.run_dir.join("sonar-feed.sock"))
        .expect("feed socket");
    let mut x = 0x1234_5678u32;
    let noise: Vec<u8> = (0..256 * 1024)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u8
        })
        .collect();
    let _ = feeder.write_all(&noise);
    drop(feeder);
    let status = d.status();
    assert!(!status.links.is_empty());
    let mut s = Wire::open(&d.link("sensor"));
    answers_hello(&mut s, 0, "with a stuck status client");
    let mut sonar = Wire::open(&d.link("sonar"));
    acks_select(&mut sonar, "after a noisy feeder");
    drop(stuck);
    d.stop();
}

// ---- a local attacker in the run directory ----

/// A FIFO planted as `status.sock`, and one as a link's owner file: start-up is refused with
/// a reason, never hangs, and the FIFOs are left alone.
#[test]
fn planted_fifos_are_refused_without_hanging() {
    for planted in ["status.sock", ".sensor.owner"] {
        let dir = TempDir::new("adv-fifo");
        let run = dir.join("run");
        std::fs::create_dir(&run).unwrap();
        std::fs::set_permissions(&run, std::fs::Permissions::from_mode(0o700)).unwrap();
        let fifo = run.join(planted);
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
        let started = Instant::now();
        let result = try_start(&dir, &config_text(&[]), Duration::from_secs(10));
        assert!(result.is_err(), "{planted}: a FIFO was accepted");
        assert!(
            started.elapsed() < Duration::from_secs(5),
            "{planted}: slow refusal"
        );
        let kind = std::fs::symlink_metadata(&fifo)
            .expect("still there")
            .file_type();
        assert!(
            std::os::unix::fs::FileTypeExt::is_fifo(&kind),
            "{planted}: the FIFO was replaced"
        );
    }
}

/// A symlink planted where a link's pty symlink goes, pointing at a file of ours: the file is
/// never written, truncated or removed, whatever the daemon decides about the link.
#[test]
fn a_planted_link_symlink_never_touches_its_target() {
    let dir = TempDir::new("adv-planted");
    let run = dir.join("run");
    std::fs::create_dir(&run).unwrap();
    std::fs::set_permissions(&run, std::fs::Permissions::from_mode(0o700)).unwrap();
    let victim = dir.join("victim.txt");
    std::fs::write(&victim, b"precious").unwrap();
    std::os::unix::fs::symlink(&victim, run.join("sensor")).unwrap();
    let _ = try_start(&dir, &config_text(&[]), Duration::from_secs(20));
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
}

/// A world-writable run directory is refused, and nothing is created in it.
#[test]
fn a_world_writable_run_directory_is_refused() {
    let dir = TempDir::new("adv-0777");
    let run = dir.join("run");
    std::fs::create_dir(&run).unwrap();
    std::fs::set_permissions(&run, std::fs::Permissions::from_mode(0o777)).unwrap();
    let err = try_start(&dir, &config_text(&[]), Duration::from_secs(10))
        .expect_err("a 0777 run directory was used");
    assert!(err.contains("writable"), "{err}");
    assert_eq!(std::fs::read_dir(&run).unwrap().count(), 0, "created files");
}

// ---- races and configurations ----

/// Two daemons on one run directory at the same instant: exactly one runs.
#[test]
fn two_in_process_daemons_on_one_directory_give_one_winner() {
    let dir = TempDir::new("adv-race");
    let winner = std::sync::Arc::new(std::sync::Barrier::new(2));
    let text = config_text(&[]);
    let starts: Vec<_> = (0..2)
        .map(|_| {
            let (dir_path, text, barrier) =
                (dir.path().to_path_buf(), text.clone(), winner.clone());
            std::thread::spawn(move || {
                let run_dir = dir_path.join("run");
                let source = Directory::new(dir_path.clone());
                let mut config =
                    DaemonConfig::resolve(&Document::new("test config", &text)).unwrap();
                config.run_dir = run_dir;
                let model =
                    eyebot_hil::daemon::plant::MakoPlant::from_config(&source, &config).unwrap();
                let (board, mux) = eyebot_hil::daemon::plant::devices(&config);
                let runtime = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                    .unwrap();
                let _ = barrier.wait();
                runtime.block_on(async {
                    match Bridge::start(&config, model, board, mux, RunOptions::default()).await {
                        Ok(bridge) => {
                            tokio::time::sleep(Duration::from_millis(300)).await;
                            let _ = bridge.finish().await;
                            Ok(())
                        }
                        Err(e) => Err(e.to_string()),
                    }
                })
            })
        })
        .collect();
    let results: Vec<Result<(), String>> = starts.into_iter().map(|t| t.join().unwrap()).collect();
    let ok = results.iter().filter(|r| r.is_ok()).count();
    assert_eq!(ok, 1, "exactly one daemon runs: {results:?}");
    let loser = results.iter().find_map(|r| r.clone().err()).unwrap();
    assert!(loser.contains("another eyebot-hil daemon"), "{loser}");
}

/// A sonar replay log that is a directory or a FIFO is refused at start with its path (a FIFO
/// would stall the simulation, which reads the log as it reaches each sentence).
#[test]
fn a_sonar_replay_that_is_not_a_file_is_refused() {
    let dir = TempDir::new("adv-feed");
    let fifo = dir.join("feed.fifo");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
    for log in [fifo, dir.path().to_path_buf()] {
        let line = format!("replay = \"{}\"\n\n[devices.compass]", log.display());
        let text = config_text(&[("[devices.compass]", line.as_str())]);
        let err = try_start(&dir, &text, Duration::from_secs(10)).expect_err("accepted");
        assert!(
            err.contains(&log.display().to_string()) && err.contains("not a regular file"),
            "{err}"
        );
    }
}

// ---- lost or miscounted data ----

/// Requests written one byte at a time with a millisecond between bytes (well inside the
/// 50 ms idle limit) are whole frames: answered, and no framing or CRC error counted.
#[test]
fn frames_written_byte_by_byte_are_whole_frames() {
    let mut d = daemon("adv-bytewise", false);
    let mut s = Wire::open(&d.link("sensor"));
    answers_hello(&mut s, 0, "start");
    let before = s.counters(1);
    for seq in 2..6u8 {
        for b in frame_bytes(seq, Message::TimeGet) {
            s.send(&[b]);
            std::thread::sleep(Duration::from_millis(1));
        }
        let f = s.next_frame("byte-wise TIME_GET", WAIT);
        assert_eq!(f.seq, seq);
        assert!(matches!(f.message, Message::Time { .. }), "{:?}", f.message);
    }
    let after = s.counters(6);
    assert_eq!(after.rx_framing_errors, before.rx_framing_errors);
    assert_eq!(after.rx_crc_errors, before.rx_crc_errors);
    assert_eq!(
        after.rx_frames.wrapping_sub(before.rx_frames),
        5,
        "4 TIME_GET + COUNTERS_GET"
    );
    d.stop();
}

/// Valid requests, damaged ones and garbage interleaved, in uneven chunks, in lockstep: the
/// counters account for each exactly, and the status's byte count is what was written.
#[test]
fn mixed_traffic_is_counted_exactly() {
    let mut d = daemon("adv-mixed", true);
    let mut s = Wire::open(&d.link("sensor"));
    answers_hello(&mut s, 0, "start");
    let before = s.counters(1);
    // HELLO and COUNTERS_GET so far: 8 + 7 bytes.
    let bytes_before = 15u64;
    let mut stream = Vec::new();
    let (mut good, mut damaged, mut garbage) = (0u32, 0u32, 0u32);
    for i in 0..40u8 {
        let seq = 10 + i;
        let mut frame = frame_bytes(seq, Message::TimeGet);
        if i % 5 == 0 {
            let n = frame.len();
            frame[n - 1] ^= 0x0F;
            damaged += 1;
        } else {
            good += 1;
        }
        stream.extend_from_slice(&frame);
        if i % 3 == 0 {
            // Bytes that start nothing (not 0xEB, '$', '@', CR or LF).
            stream.extend_from_slice(&[0x01, 0x02, 0x03]);
            garbage += 3;
        }
    }
    for chunk in stream.chunks(13) {
        s.send(chunk);
    }
    // Every frame, good or damaged, gets exactly one answer (the damaged ones a BAD_CRC NAK).
    let mut answers = 0;
    while answers < 40 {
        let f = s.next_frame("mixed traffic", WAIT);
        assert!(f.seq >= 10 && f.seq < 50, "{f:?}");
        answers += 1;
    }
    let after = s.counters(60);
    let d_ = |a: u32, b: u32| b.wrapping_sub(a);
    assert_eq!(
        d_(before.rx_frames, after.rx_frames),
        good + 1,
        "received OK (+ COUNTERS_GET)"
    );
    assert_eq!(
        d_(before.rx_crc_errors, after.rx_crc_errors),
        damaged,
        "CRC errors"
    );
    // The garbage, and the tails of the damaged frames (rescanned after their 0xEB).
    assert!(
        d_(before.rx_skipped_bytes, after.rx_skipped_bytes) >= garbage,
        "skipped {before:?} -> {after:?}"
    );
    assert_eq!(
        after.rx_framing_errors, before.rx_framing_errors,
        "framing errors"
    );
    assert_eq!(d_(before.tx_naks, after.tx_naks), damaged, "NAKs");
    // The COUNTERS_GET after the stream is 7 bytes more.
    let expected = bytes_before + stream.len() as u64 + 7;
    let counted = d.wait_status(WAIT, "the byte count", |st| {
        st.links
            .iter()
            .any(|l| l.name == "sensor" && l.bytes_rx >= expected)
    });
    let rx = counted
        .links
        .iter()
        .find(|l| l.name == "sensor")
        .map(|l| l.bytes_rx);
    assert_eq!(rx, Some(expected), "bytes received on the sensor link");
    d.stop();
}

// ---- floods cost counters ----

/// Bad selects back to back: each one is answered `@N` and counted, none is lost, and the
/// line still acks a good select after them.
#[test]
fn a_flood_of_bad_selects_is_answered_and_counted_one_by_one() {
    let mut d = daemon("adv-bad-selects", false);
    let mut sonar = Wire::open(&d.link("sonar"));
    let errors_before: u64 = d.status().links.iter().map(|l| l.errors).sum();
    let n = 100;
    let flood: Vec<u8> = b"@S9\r".iter().copied().cycle().take(4 * n).collect();
    sonar.send(&flood);
    let mut naks = 0;
    let deadline = Instant::now() + WAIT;
    while naks < n && Instant::now() < deadline {
        match sonar.next_non_nmea(WAIT) {
            Some(LineItem::Sonar(SonarCommand::Nak)) => naks += 1,
            other => panic!("in the flood: {other:?}"),
        }
    }
    assert_eq!(naks, n, "one @N per bad select");
    acks_select(&mut sonar, "after the flood");
    let errors: u64 = d.status().links.iter().map(|l| l.errors).sum();
    assert!(
        errors >= errors_before + n as u64,
        "{errors_before} -> {errors}"
    );
    d.stop();
}
