//! Life cycle of the binary: clean shutdown on SIGTERM/SIGINT loses no recorded byte,
//! `kill -9` loses at most the last 100 ms, and `eyebot-hil status` reports the run; and
//! the binary's own client, `eyebot-hil probe`, against it.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use bytes::BytesMut;
use eyebot_hil::daemon::status::StatusSnapshot;
use eyebot_hil::record::Direction;
use eyebot_test_support::clients::open_raw;
use eyebot_test_support::daemon::DaemonOptions;
use eyebot_test_support::daemon::link_status;
use eyebot_test_support::process::stat_fields;
use eyebot_test_support::recording::{read_chunks, stream};
use eyebot_test_support::{Daemon, RunningDaemon};
use firmware_protocol::Frame;
use firmware_protocol::sensor_link::{AdcChannel, Message};
use nix::sys::signal::Signal;

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

fn adc_read(seq: u8) -> Vec<u8> {
    let mut b = BytesMut::new();
    Frame::new(
        seq,
        Message::AdcRead {
            channel: AdcChannel::new(seq % 8).unwrap(),
        },
    )
    .encode(&mut b);
    b.to_vec()
}

/// ADC_READ requests written to a link: every byte, and when each request was written with
/// the byte count so far.
#[derive(Default)]
struct Requests {
    seq: u8,
    written: Vec<u8>,
    log: Vec<(Instant, usize)>,
}

impl Requests {
    fn write_one(&mut self, port: &mut std::fs::File) {
        self.seq = self.seq.wrapping_add(1);
        let frame = adc_read(self.seq);
        port.write_all(&frame).expect("write a request");
        self.written.extend_from_slice(&frame);
        self.log.push((Instant::now(), self.written.len()));
    }

    /// Writes a request every `pause` for `how_long`.
    fn write_for(&mut self, port: &mut std::fs::File, how_long: Duration, pause: Duration) {
        let started = Instant::now();
        while started.elapsed() < how_long {
            self.write_one(port);
            std::thread::sleep(pause);
        }
    }
}

/// Reads everything from `file` on a thread until `stop`; returns the bytes read.
fn reader(mut file: std::fs::File, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<Vec<u8>> {
    let fd = std::os::fd::AsRawFd::as_raw_fd(&file);
    // Poll with a timeout so the thread notices `stop`.
    std::thread::spawn(move || {
        let mut got = Vec::new();
        let mut buf = [0u8; 4096];
        while !stop.load(Ordering::Relaxed) {
            let mut fds = [nix::poll::PollFd::new(
                unsafe { std::os::fd::BorrowedFd::borrow_raw(fd) },
                nix::poll::PollFlags::POLLIN,
            )];
            match nix::poll::poll(&mut fds, 20u16) {
                Ok(n) if n > 0 => match file.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => got.extend_from_slice(&buf[..n]),
                },
                _ => {}
            }
        }
        got
    })
}

/// `--pid-file DIR/eyebot-hil.pid`, and that path.
fn with_pid_file(options: DaemonOptions) -> (DaemonOptions, PathBuf) {
    let pid_file = options.dir().join("eyebot-hil.pid");
    let options = options.args(&["--pid-file", pid_file.to_str().expect("a UTF-8 path")]);
    (options, pid_file)
}

fn shutdown_loses_nothing(signal: Signal, tag: &str) {
    let (options, pid_file) = with_pid_file(Daemon::options(BIN, tag).realtime().record());
    let mut daemon = options.start();
    let record = daemon.record_dir().to_path_buf();
    assert_eq!(
        std::fs::read_to_string(&pid_file).unwrap().trim(),
        daemon.pid().to_string()
    );
    let mut sensor = open_raw(&daemon.link("sensor"));
    let mut sonar = open_raw(&daemon.link("sonar"));
    let stop = Arc::new(AtomicBool::new(false));
    let sensor_rx = reader(sensor.try_clone().unwrap(), stop.clone());
    let sonar_rx = reader(sonar.try_clone().unwrap(), stop.clone());

    sonar.write_all(b"@S1\r").unwrap();
    // Requests back to back for a second (the line is busy), then the signal right after a
    // write, while replies are still on their way.
    let mut requests = Requests::default();
    requests.write_for(
        &mut sensor,
        Duration::from_millis(1500),
        Duration::from_millis(1),
    );
    // A last burst, back to back, with the signal straight after it.
    for _ in 0..50 {
        requests.write_one(&mut sensor);
    }
    let written = requests.written;
    let signalled = Instant::now();
    daemon.signal(signal);
    let exit = daemon
        .wait(Duration::from_secs(5))
        .expect("the daemon exits after the signal");
    let took = signalled.elapsed();
    assert!(exit.success(), "{signal}: exit {exit:?}\n{}", daemon.log());
    assert!(
        took < Duration::from_secs(1),
        "{signal}: shutdown took {took:?}"
    );
    // Give the readers a moment to take what is still in the ptys, then stop them.
    std::thread::sleep(Duration::from_millis(100));
    stop.store(true, Ordering::Relaxed);
    let sensor_got = sensor_rx.join().unwrap();
    let sonar_got = sonar_rx.join().unwrap();

    let chunks = read_chunks(&record);
    let rx = stream(&chunks, "sensor", Direction::Rx);
    assert!(
        rx == written,
        "{signal}: the recording holds {} of the {} bytes the client sent",
        rx.len(),
        written.len()
    );
    assert_eq!(stream(&chunks, "sonar", Direction::Rx), b"@S1\r");
    let tx = stream(&chunks, "sensor", Direction::Tx);
    assert!(
        sensor_got.len() > 100,
        "replies arrived: {}",
        sensor_got.len()
    );
    assert!(
        tx.starts_with(&sensor_got),
        "{signal}: what the client received ({} bytes) is not what was recorded ({} bytes)",
        sensor_got.len(),
        tx.len()
    );
    assert!(
        stream(&chunks, "sonar", Direction::Tx).starts_with(&sonar_got),
        "sonar bytes received and recorded differ"
    );
    assert_cleaned_up(&daemon, &pid_file, signal.as_ref());
}

/// The links, the status socket and the pid file are gone.
fn assert_cleaned_up(daemon: &Daemon, pid_file: &Path, context: &str) {
    for name in ["sonar", "sensor", "status.sock"] {
        let path = daemon.run_dir.join(name);
        assert!(
            std::fs::symlink_metadata(&path).is_err(),
            "{context}: {} left behind",
            path.display()
        );
    }
    assert!(!pid_file.exists(), "{context}: pid file left behind");
}

/// SIGTERM while a client talks and the recorder writes: every byte is recorded, exit 0
/// within 1 s, links, socket and pid file removed.
#[test]
fn sigterm_mid_recording_loses_nothing() {
    shutdown_loses_nothing(Signal::SIGTERM, "sigterm");
}

/// The same for SIGINT (Ctrl-C).
#[test]
fn sigint_mid_recording_loses_nothing() {
    shutdown_loses_nothing(Signal::SIGINT, "sigint");
}

/// `kill -9` while a client streams requests: every chunk written more than 100 ms before
/// the kill is in `bytes.tsv`.
#[test]
fn kill_9_loses_at_most_the_last_100_ms() {
    let mut daemon = Daemon::options(BIN, "kill9").realtime().record().start();
    let record = daemon.record_dir().to_path_buf();
    let mut sensor = open_raw(&daemon.link("sensor"));
    let stop = Arc::new(AtomicBool::new(false));
    let replies = reader(sensor.try_clone().unwrap(), stop.clone());
    let mut requests = Requests::default();
    requests.write_for(
        &mut sensor,
        Duration::from_millis(1500),
        Duration::from_millis(2),
    );
    let Requests { written, log, .. } = requests;
    let killed = Instant::now();
    daemon.signal(Signal::SIGKILL);
    daemon.wait(Duration::from_secs(5)).expect("killed");
    stop.store(true, Ordering::Relaxed);
    let _ = replies.join();

    let must_have = log
        .iter()
        .filter(|(t, _)| killed.duration_since(*t) > Duration::from_millis(100))
        .map(|(_, n)| *n)
        .max()
        .expect("writes more than 100 ms before the kill");
    let rx = stream(&read_chunks(&record), "sensor", Direction::Rx);
    assert!(
        written.starts_with(&rx),
        "the recording holds bytes that were never sent"
    );
    assert!(
        rx.len() >= must_have,
        "kill -9 lost bytes written more than 100 ms before it: recorded {} of {} required ({} written)",
        rx.len(),
        must_have,
        written.len()
    );
}

/// `eyebot-hil status` prints uptime, simulated time, mode, per-link counters and the pose;
/// `--json` parses and agrees.
#[test]
fn status_reports_uptime_time_mode_links_and_pose() {
    let daemon = Daemon::options(BIN, "status")
        .realtime()
        .args(&["--speed", "2"])
        .start();
    let mut sensor = open_raw(&daemon.link("sensor"));
    sensor.write_all(&adc_read(1)).unwrap();
    sensor.write_all(b"\x00\x01garbage").unwrap();
    let s = daemon.wait_status(Duration::from_secs(10), "the request and the junk", |s| {
        let l = link_status(s, "sensor");
        l.frames_rx >= 1 && l.errors >= 1 && s.sim_time_s > 0.5
    });
    assert_eq!(s.time_mode, "realtime");
    assert_eq!(s.speed, 2.0);
    assert_eq!(s.pid, daemon.pid());
    assert!(s.uptime_s > 0.0);
    // Realtime at speed 2: simulated time runs at about twice the uptime.
    assert!(
        (s.sim_time_s / s.uptime_s - 2.0).abs() < 0.5,
        "sim {} s after {} s up",
        s.sim_time_s,
        s.uptime_s
    );
    let sensor_link = link_status(&s, "sensor");
    assert_eq!(sensor_link.bytes_rx, 8 + 9);
    assert!(sensor_link.bytes_tx >= 10, "{sensor_link:?}");
    assert!(
        (s.pose.depth_m - 0.3).abs() < 0.5 && (s.pose.x_m - 3.0).abs() < 0.5,
        "{:?}",
        s.pose
    );

    let json: StatusSnapshot =
        serde_json::from_str(&daemon.status_command(&["--json"])).expect("status --json parses");
    assert_eq!(
        (json.pid, json.time_mode.as_str(), json.speed),
        (s.pid, s.time_mode.as_str(), s.speed),
        "status --json agrees with the socket"
    );
    assert!(json.uptime_s >= s.uptime_s, "{json:?} after {s:?}");
    let text = daemon.status_command(&[]);
    for needle in [
        "uptime",
        "sim time",
        "time mode   realtime",
        "pose",
        "depth",
        "heading",
        "sonar",
        "sensor",
        "errors",
    ] {
        assert!(text.contains(needle), "`{needle}` missing from:\n{text}");
    }
    let sensor_row = text
        .lines()
        .find(|l| l.starts_with("sensor "))
        .expect("a sensor row");
    assert!(
        sensor_row.split_whitespace().any(|f| f == "17"),
        "the sensor row shows the 17 bytes received: {sensor_row}"
    );
    drop(sensor);
}

/// Shutdown is bounded even when part of the daemon hangs: the recording goes to a pipe
/// that nobody reads (a disk that stopped taking data), a garbage flood fills the
/// recorder's queue, and the daemon's loop waits for the recorder. SIGTERM still ends the
/// process within 1 s, with an exit status that says the shutdown was cut short, and the
/// links, the status socket and the pid file are removed. Regression: the 1 s limit was
/// declared but not enforced (the signal was handled on the blocked runtime).
#[test]
fn shutdown_is_bounded_when_the_recorder_hangs() {
    use std::os::unix::fs::OpenOptionsExt;
    let options = Daemon::options(BIN, "hung").realtime().record();
    std::fs::create_dir_all(options.record_dir()).unwrap();
    let fifo = options.record_dir().join("bytes.tsv");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    // Hold the read end open (so the recorder can open its end) and never read.
    let _stalled_reader = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(&fifo)
        .unwrap();
    let (options, pid_file) = with_pid_file(options);
    let mut daemon = options.start();
    // Non-blocking garbage for a second: the pipe (64 KiB) and the recorder's queue fill,
    // then the daemon stops reading (its writes would otherwise block here too).
    let mut port = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(daemon.link("sensor"))
        .unwrap();
    let garbage = [0x55u8; 4096];
    let started = Instant::now();
    let mut written = 0usize;
    while started.elapsed() < Duration::from_millis(1000) {
        match port.write(&garbage) {
            Ok(n) => written += n,
            Err(_) => std::thread::sleep(Duration::from_millis(1)),
        }
    }
    assert!(written > 0);
    let signalled = Instant::now();
    daemon.signal(Signal::SIGTERM);
    let exit = daemon
        .wait(Duration::from_secs(5))
        .expect("the daemon exits although its recorder hangs");
    let took = signalled.elapsed();
    assert!(
        took < Duration::from_secs(1),
        "shutdown took {took:?}\n{}",
        daemon.log()
    );
    assert_eq!(
        exit.code(),
        Some(3),
        "cut short: {exit:?}\n{}",
        daemon.log()
    );
    assert!(daemon.log().contains("shutdown did not finish in time"));
    assert!(
        daemon.log().contains("still waiting for"),
        "the error names what shutdown was waiting for:\n{}",
        daemon.log()
    );
    assert_cleaned_up(&daemon, &pid_file, "cut short");
}

/// `(policy, rt_priority)` of one thread, from `/proc/PID/task/TID/stat` (fields 41 and 40;
/// counted after the parenthesised command name, which may hold spaces).
fn scheduling(pid: u32, tid: &str) -> (u32, u32) {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/task/{tid}/stat"))
        .expect("read /proc/PID/task/TID/stat");
    let fields = stat_fields(&stat);
    (
        fields[41 - 3].parse().unwrap(),
        fields[40 - 3].parse().unwrap(),
    )
}

#[test]
fn rt_priority_runs_the_bridge_thread_under_sched_fifo() {
    let daemon = Daemon::options(BIN, "rt-priority")
        .config(&[(
            "release_quantum_ms = 1.0",
            "release_quantum_ms = 1.0\nrt_priority = 7",
        )])
        .realtime()
        .start();
    let pid = daemon.pid();
    // SAFETY: geteuid has no preconditions and cannot fail.
    if unsafe { libc::geteuid() } != 0 {
        // Without the privilege the daemon must say so and run on.
        let deadline = Instant::now() + Duration::from_secs(5);
        while !daemon.log().contains("no SCHED_FIFO") {
            assert!(Instant::now() < deadline, "no warning: {}", daemon.log());
            std::thread::sleep(Duration::from_millis(20));
        }
        eprintln!(
            "NOT ROOT: checked the warning only; SCHED_FIFO itself needs root or CAP_SYS_NICE"
        );
        return;
    }
    // The bridge thread (the main thread, which runs the runtime) switches right after the
    // `ready` line.
    let deadline = Instant::now() + Duration::from_secs(5);
    while scheduling(pid, &pid.to_string()) != (libc::SCHED_FIFO as u32, 7) {
        assert!(
            Instant::now() < deadline,
            "main thread scheduling {:?}; log:\n{}",
            scheduling(pid, &pid.to_string()),
            daemon.log()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // The helper threads keep the default scheduler.
    let mut others = 0;
    for task in std::fs::read_dir(format!("/proc/{pid}/task")).unwrap() {
        let tid = task.unwrap().file_name().into_string().unwrap();
        if tid != pid.to_string() {
            assert_eq!(
                scheduling(pid, &tid).0,
                libc::SCHED_OTHER as u32,
                "thread {tid}"
            );
            others += 1;
        }
    }
    assert!(others >= 1, "the signal thread exists");
    // Still a working bridge.
    let mut sensor = open_raw(&daemon.link("sensor"));
    sensor.write_all(&adc_read(3)).unwrap();
    let mut reply = [0u8; 10];
    sensor.read_exact(&mut reply).unwrap();
    assert_eq!(&reply[..3], &[0xEB, 0x90, 0x90], "an ADC_VALUE reply");
}

/// Runs `eyebot-hil probe --link LINK ARGS` and returns its standard output, which must be
/// a success.
fn probe(link: &std::path::Path, args: &[&str]) -> String {
    let out = std::process::Command::new(BIN)
        .arg("probe")
        .arg("--link")
        .arg(link)
        .args(args)
        .output()
        .expect("run eyebot-hil probe");
    assert!(out.status.success(), "probe {args:?}: {out:?}");
    String::from_utf8(out.stdout).expect("probe prints UTF-8")
}

/// `eyebot-hil probe`, the client people and scripts use, against the built daemon in
/// lockstep: every sensor-link action prints its line, and `advance` moves simulated time by
/// exactly the ticks asked for.
#[test]
fn probe_reads_the_sensor_link_and_drives_lockstep_time() {
    let daemon = Daemon::options(BIN, "probe-sensor").lockstep().start();
    let sensor = daemon.link("sensor");
    let hello = probe(&sensor, &["hello"]);
    assert!(hello.starts_with("protocol "), "{hello}");
    let adc = probe(&sensor, &["adc", "0", "--count", "3"]);
    assert_eq!(adc.lines().count(), 3, "{adc}");
    for line in adc.lines() {
        let code: u16 = line
            .strip_prefix("adc 0 = ")
            .and_then(|rest| rest.split(' ').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("an ADC line: {line}"));
        assert!(code <= 1023, "a 10-bit code: {line}");
    }
    let counters = probe(&sensor, &["counters"]);
    assert!(counters.starts_with("rx_frames "), "{counters}");
    let compass = probe(&sensor, &["compass"]);
    assert!(compass.starts_with("heading "), "{compass}");
    assert_eq!(
        probe(&sensor, &["thrusters", "50", "50", "0", "-20"]),
        "thrusters set\n"
    );
    let ticks = |line: &str| -> u64 {
        line.strip_prefix("time ")
            .and_then(|rest| rest.split(' ').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("a time line: {line}"))
    };
    let before = ticks(&probe(&sensor, &["time"]));
    let after = ticks(&probe(&sensor, &["advance", "250"]));
    assert_eq!(after, before + 250);
    assert_eq!(
        ticks(&probe(&sensor, &["time"])),
        after,
        "time holds in lockstep"
    );
}

/// `probe ... sonar N` selects a transducer and prints the multiplexer's ack, then the
/// sentences, each a valid NMEA line.
#[test]
fn probe_selects_a_transducer_and_prints_its_sentences() {
    // Every ping gives a sentence, with or without an echo.
    let daemon = Daemon::options(BIN, "probe-sonar")
        .config(&[("invalid_echo = \"omit\"", "invalid_echo = \"empty\"")])
        .start();
    let out = probe(
        &daemon.link("sonar"),
        &["sonar", "2", "--count", "2", "--timeout-s", "20"],
    );
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.first(), Some(&"ack transducer 2"), "{out}");
    let sentences: Vec<&str> = lines
        .iter()
        .copied()
        .filter(|l| l.starts_with('$'))
        .collect();
    assert_eq!(sentences.len(), 2, "{out}");
    for s in sentences {
        // probe prints each sentence as a line; on the wire it ended in CR LF.
        firmware_protocol::nmea::parse_line(format!("{s}\r\n").as_bytes())
            .unwrap_or_else(|e| panic!("{s}: {e}"));
    }
}
