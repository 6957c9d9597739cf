//! Daemon benchmarks against the built binary (release profile), printed as plain figures:
//!
//! - `adc`: ADC read over a pty at 115200 baud, request to complete reply, minus the
//!   modelled wire time of the reply; baseline: a raw pty echo round trip in the same run;
//!   also with `release_quantum_ms = 0` (one wake-up per byte), to show what the quantum
//!   costs in latency; and each read in three parts (request to daemon, the daemon's
//!   turnaround, hand-over to client) from the wall times of its `--record` output.
//! - `nmea`: real-time NMEA emission jitter: each byte's arrival at the client against its
//!   sentence's 4800 baud wire schedule; beside it the same figure for the daemon's own
//!   hand-over of each byte, from the wall times its `--record` output gives them, so a late
//!   byte can be told apart as the daemon's or the kernel's pty delivery.
//! - `cpu`: daemon CPU idle and under a 100 Hz ADC stream, from /proc/PID/stat; baseline: the
//!   same stream with `release_quantum_ms = 0` (one wake-up per byte) in the same run. Then
//!   the same two settings under a client polling 800 `ADC_READ`s a second, which is what
//!   releasing replies byte by byte would cost.
//! - `rss`: resident memory over one simulated hour at speed 100 with a client.
//! - `view`: what one live page costs (`run --view`): daemon CPU under the 100 Hz ADC stream,
//!   then under a client polling 800 `ADC_READ`s a second, with a page reading the 20 Hz
//!   event stream, against the same daemon without a page, measured before and after it
//!   (baseline: the mean of those two).
//!
//! The binary measured is the one `EYEBOT_HIL_BIN` names, built by the same command:
//!
//! ```sh
//! cargo build --release --bin eyebot-hil
//! EYEBOT_HIL_BIN=target/release/eyebot-hil cargo bench -p pty-tests --bench daemon [-- adc|nmea|cpu|rss]
//! ```
//!
//! (all five by default). With `EYEBOT_BENCH_VIEW=1` every daemon of `adc`, `nmea`, `cpu`
//! and `rss` also serves `--view` with one page reading its event stream.

use std::io::{Read, Write};
use std::os::fd::AsFd;
use std::time::{Duration, Instant};

use bytes::BytesMut;
use eyebot_hil::record::Direction;
use eyebot_test_support::clients::open_raw;
use eyebot_test_support::daemon::link_status;
use eyebot_test_support::process::clock_ticks_per_s;
use eyebot_test_support::recording::read_chunks;
use eyebot_test_support::{Daemon, RunningDaemon, TempDir};
use firmware_protocol::Frame;
use firmware_protocol::sensor_link::{AdcChannel, Message};
use nix::sys::termios;

/// The binary under measurement, from `EYEBOT_HIL_BIN` (see the crate doc).
fn binary() -> String {
    std::env::var("EYEBOT_HIL_BIN").unwrap_or_else(|_| {
        panic!(
            "set EYEBOT_HIL_BIN to the eyebot-hil binary to measure: cargo build --release \
             --bin eyebot-hil && EYEBOT_HIL_BIN=target/release/eyebot-hil cargo bench -p \
             pty-tests --bench daemon"
        )
    })
}

fn frame(seq: u8, message: Message) -> Vec<u8> {
    let mut b = BytesMut::new();
    Frame::new(seq, message).encode(&mut b);
    b.to_vec()
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

fn summary(values: &mut [f64]) -> (f64, f64, f64) {
    values.sort_by(f64::total_cmp);
    (
        percentile(values, 0.5),
        percentile(values, 0.99),
        values[values.len() - 1],
    )
}

const ROUNDS: usize = 2000;
const WARMUP: usize = 100;

/// Request/response over a raw pty pair, echoed by a thread: what the kernel and two
/// context switches cost, with no daemon.
fn pty_echo_baseline() -> Vec<f64> {
    let pair = nix::pty::openpty(None, None).expect("openpty");
    let mut attrs = termios::tcgetattr(&pair.slave).unwrap();
    termios::cfmakeraw(&mut attrs);
    termios::tcsetattr(&pair.slave, termios::SetArg::TCSANOW, &attrs).unwrap();
    let mut master = std::fs::File::from(pair.master);
    let mut slave = std::fs::File::from(pair.slave);
    let echo = std::thread::spawn(move || {
        let mut req = [0u8; 8];
        for _ in 0..ROUNDS + WARMUP {
            master.read_exact(&mut req).unwrap();
            master.write_all(&[0u8; 10]).unwrap();
        }
        // Closing the master hangs up the slave: keep it until the last reply is read.
        master
    });
    let mut reply = [0u8; 10];
    let mut out = Vec::new();
    for i in 0..ROUNDS + WARMUP {
        let t = Instant::now();
        slave.write_all(&[0u8; 8]).unwrap();
        slave.read_exact(&mut reply).unwrap();
        if i >= WARMUP {
            out.push(t.elapsed().as_secs_f64() * 1e6);
        }
    }
    drop(echo.join().unwrap());
    out
}

/// Starts the binary with `args`; with `EYEBOT_BENCH_VIEW` set, also with `--view` and one
/// page reading its event stream for the daemon's whole life (the benchmarks with a page
/// open).
fn start_daemon(dir: TempDir, args: &[&str]) -> Daemon {
    if std::env::var_os("EYEBOT_BENCH_VIEW").is_none() {
        return Daemon::start(&binary(), dir, args);
    }
    let mut args = args.to_vec();
    args.push("--view");
    let daemon = Daemon::start(&binary(), dir, &args);
    let url = daemon.view_url.clone().expect("run --view prints its URL");
    let (addr, token) = eyebot_test_support::browser::split_view_url(&url);
    // Detached: it ends when the daemon closes the stream.
    std::thread::spawn(move || {
        let mut stream = std::net::TcpStream::connect(addr).unwrap();
        write!(
            stream,
            "GET /api/stream?token={token} HTTP/1.1\r\nHost: {addr}\r\n\r\n"
        )
        .unwrap();
        let mut buf = [0u8; 65536];
        while matches!(stream.read(&mut buf), Ok(n) if n > 0) {}
    });
    daemon
}

/// `--config` arguments for a run with `release_quantum_ms = quantum_ms` (None: the default)
/// and the scheduler requests of [`scheduler_lines`].
fn quantum_args(dir: &TempDir, quantum_ms: Option<f64>) -> Vec<String> {
    let mut args = vec!["--time-mode".to_string(), "realtime".to_string()];
    let extra = scheduler_lines();
    if quantum_ms.is_some() || !extra.is_empty() {
        let line = format!(
            "release_quantum_ms = {:.1}{extra}",
            quantum_ms.unwrap_or(1.0)
        );
        let config = dir.write_config("quantum.toml", &[("release_quantum_ms = 1.0", &line)]);
        args.extend(["--config".to_string(), config.display().to_string()]);
    }
    args
}

/// `run.cpu_latency_us` from `EYEBOT_BENCH_CPU_LATENCY_US` and `run.rt_priority` from
/// `EYEBOT_BENCH_RT_PRIORITY`, when set, as lines to add to the `[run]` table.
fn scheduler_lines() -> String {
    let mut lines = String::new();
    if let Some(us) = cpu_latency_us() {
        lines.push_str(&format!("\ncpu_latency_us = {us}"));
    }
    if let Some(priority) = rt_priority() {
        lines.push_str(&format!("\nrt_priority = {priority}"));
    }
    lines
}

/// The value of environment variable `name`, if set; a set value that does not parse stops
/// the bench, naming the variable and what it should be.
fn env_number<T: std::str::FromStr>(name: &str, what: &str) -> Option<T> {
    let value = std::env::var(name).ok()?;
    Some(
        value
            .parse()
            .unwrap_or_else(|_| panic!("{name} is {what}, not `{value}`")),
    )
}

/// The CPU latency request the daemon is asked to hold (`EYEBOT_BENCH_CPU_LATENCY_US`).
fn cpu_latency_us() -> Option<u32> {
    env_number("EYEBOT_BENCH_CPU_LATENCY_US", "a number of microseconds")
}

/// `EYEBOT_BENCH_OUTLIERS_US`: print every ADC read slower than this (minus wire time), with
/// its monotonic send time, to match against a kernel trace.
fn outlier_us() -> Option<f64> {
    env_number("EYEBOT_BENCH_OUTLIERS_US", "a number of microseconds")
}

/// CLOCK_MONOTONIC now, in seconds.
/// Seconds since the Unix epoch: the clock of `bytes.tsv`'s `wall_unix_s`.
fn unix_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

fn monotonic_s() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: a valid clock id and a pointer to a timespec this function owns.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// The SCHED_FIFO priority the daemon is asked to run at (`EYEBOT_BENCH_RT_PRIORITY`).
fn rt_priority() -> Option<u8> {
    env_number("EYEBOT_BENCH_RT_PRIORITY", "a SCHED_FIFO priority 1-99")
}

fn adc() {
    let baseline = pty_echo_baseline();
    for quantum in [None, Some(0.0)] {
        adc_with(&baseline, quantum);
    }
}

fn adc_with(baseline: &[f64], quantum_ms: Option<f64>) {
    let dir = TempDir::new("bench-adc");
    let record = dir.join("rec");
    let mut args = quantum_args(&dir, quantum_ms);
    args.extend(["--record".to_string(), record.display().to_string()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut daemon = start_daemon(dir, &args);
    let mut port = open_raw(&daemon.link("sensor"));
    // ADC_VALUE is 10 bytes: 10 x 10 bits at 115200 baud.
    let wire_us = 10.0 * 10.0 / 115_200.0 * 1e6;
    let mut latency = Vec::new();
    // When each request was written, on the wall clock the daemon's recording uses.
    let mut sent_unix_s = Vec::new();
    let mut reply = [0u8; 10];
    for i in 0..ROUNDS + WARMUP {
        let request = frame(
            i as u8,
            Message::AdcRead {
                channel: AdcChannel::new((i % 8) as u8).unwrap(),
            },
        );
        let sent_mono_s = monotonic_s();
        let sent_unix = unix_s();
        let t = Instant::now();
        port.write_all(&request).unwrap();
        port.read_exact(&mut reply).unwrap();
        let us = t.elapsed().as_secs_f64() * 1e6;
        if let Some(limit) = outlier_us()
            && us - wire_us > limit
        {
            // On the clock the kernel trace uses (`trace_clock = mono`), to match the two.
            println!(
                "  outlier: request sent at {sent_mono_s:.6} s (monotonic), {:.1} us over the wire time",
                us - wire_us
            );
        }
        assert_eq!(&reply[..3], &[0xEB, 0x90, 0x90], "an ADC_VALUE reply");
        if i >= WARMUP {
            latency.push(us);
            sent_unix_s.push(sent_unix);
        }
    }
    let request_len = frame(
        0,
        Message::AdcRead {
            channel: AdcChannel::new(0).unwrap(),
        },
    )
    .len();
    stop(&mut daemon);
    // Each read in three parts, from the wall times of the daemon's recording: the request
    // reaching the daemon (the kernel's pty delivery and the daemon's wake-up), the daemon's
    // turnaround (from reading the request to handing over the reply's last byte, minus the
    // wire time: its work and its timer's wake-up) and the rest (the write, the kernel's
    // delivery of the reply, the client's wake-up). Requests and replies alternate strictly.
    let (mut rx_done, mut replies) = (Vec::new(), Vec::new());
    let (mut rx_bytes, mut tx_bytes) = (0usize, 0usize);
    for (dir, _, wall) in recorded_bytes(&record, "sensor") {
        match dir {
            Direction::Rx => {
                rx_bytes += 1;
                if rx_bytes % request_len == 0 && rx_bytes / request_len > WARMUP {
                    rx_done.push(wall);
                }
            }
            Direction::Tx => {
                tx_bytes += 1;
                if tx_bytes % reply.len() == 0 && tx_bytes / reply.len() > WARMUP {
                    replies.push(wall);
                }
            }
        }
    }
    assert!(
        rx_done.len() == latency.len() && replies.len() == latency.len(),
        "one recorded request and reply per read"
    );
    let mut arrive = Vec::new();
    let mut turnaround = Vec::new();
    let mut after = Vec::new();
    let mut slow = [0usize; 4];
    for i in 0..latency.len() {
        let a = (rx_done[i] - sent_unix_s[i]) * 1e6;
        let b = (replies[i] - rx_done[i]) * 1e6 - wire_us;
        let c = latency[i] - (replies[i] - sent_unix_s[i]) * 1e6;
        if latency[i] - wire_us > 200.0 {
            slow[0] += 1;
            let parts = [a, b, c];
            let longest = (0..3)
                .max_by(|&x, &y| parts[x].total_cmp(&parts[y]))
                .unwrap_or(0);
            slow[1 + longest] += 1;
        }
        arrive.push(a);
        turnaround.push(b);
        after.push(c);
    }
    let (a50, a99, amax) = summary(&mut arrive);
    let (d50, d99, dmax) = summary(&mut turnaround);
    let (c50, c99, cmax) = summary(&mut after);
    let mut overhead: Vec<f64> = latency.iter().map(|l| l - wire_us).collect();
    let (l50, l99, lmax) = summary(&mut latency);
    let (o50, o99, omax) = summary(&mut overhead);
    let o90 = percentile(&overhead, 0.90);
    let mut baseline = baseline.to_vec();
    let (b50, b99, bmax) = summary(&mut baseline);
    let quantum = quantum_ms.map_or("1.0 (default)".to_string(), |q| format!("{q:.1}"));
    println!(
        "adc read over a pty, 115200 baud, release_quantum_ms {quantum}, {ROUNDS} requests (after {WARMUP} warm-up)"
    );
    println!("  modelled wire time of the 10-byte reply: {wire_us:.1} us");
    println!("  request -> reply:          p50 {l50:8.1} us  p99 {l99:8.1} us  max {lmax:8.1} us");
    println!(
        "  minus wire time:           p50 {o50:8.1} us  p99 {o99:8.1} us  max {omax:8.1} us  (target p99 < 200 us; p90 {o90:.1} us)"
    );
    println!(
        "  in parts (the daemon's recording): request to daemon p50 {a50:6.1} p99 {a99:6.1} max {amax:7.1} us; daemon turnaround minus wire p50 {d50:6.1} p99 {d99:6.1} max {dmax:7.1} us; hand-over to client p50 {c50:6.1} p99 {c99:6.1} max {cmax:7.1} us"
    );
    println!(
        "  reads over 200 us at the client: {} of {}; the longest part was the request to the daemon in {}, the daemon's turnaround in {}, hand-over to client in {}",
        slow[0],
        overhead.len(),
        slow[1],
        slow[2],
        slow[3]
    );
    println!("  baseline raw pty echo RTT: p50 {b50:8.1} us  p99 {b99:8.1} us  max {bmax:8.1} us");
    println!(
        "  ratio (minus wire) / echo: p50 {:.1}x  p99 {:.1}x",
        o50 / b50,
        o99 / b99
    );
}

/// Byte arrivals of each NMEA sentence at the client against the wire schedule.
///
/// The bridge releases a sentence byte by byte, each when its last bit would have left the
/// 4800 baud line: byte k of a sentence is due at S + (k + 1) x 2.083 ms / speed. S (when
/// the sentence went on the wire) is fitted per sentence as the earliest arrival minus its
/// offset, so every byte's lateness is >= 0 and measured against the best byte of its own
/// sentence: the jitter of the emission, without the constant pty transfer time.
fn nmea() {
    // Speed 1 is what a real EyeBot sees; speed 10 gives ten times the sentences per second.
    for speed in [1.0, 10.0] {
        nmea_at(speed, 30.0);
    }
}

fn nmea_at(speed: f64, wall_s: f64) {
    let dir = TempDir::new("bench-nmea");
    let config = dir.write_config(
        "near-wall.toml",
        &[
            (
                "position_m = [3.0, 2.5, 0.3]",
                "position_m = [3.0, 1.5, 0.5]",
            ),
            // Every ping gives a sentence (empty fields without a valid echo), so the
            // jitter is measured over all pings, not only the few with an echo.
            ("invalid_echo = \"omit\"", "invalid_echo = \"empty\""),
            (
                "release_quantum_ms = 1.0",
                &format!("release_quantum_ms = 1.0{}", scheduler_lines()),
            ),
        ],
    );
    let record = dir.join("rec");
    let mut daemon = start_daemon(
        dir,
        &[
            "--config",
            config.to_str().unwrap(),
            "--time-mode",
            "realtime",
            "--speed",
            &speed.to_string(),
            "--record",
            record.to_str().unwrap(),
        ],
    );
    let mut port = open_raw(&daemon.link("sonar"));
    let mut attrs = termios::tcgetattr(port.as_fd()).unwrap();
    termios::cfmakeraw(&mut attrs);
    termios::tcsetattr(port.as_fd(), termios::SetArg::TCSANOW, &attrs).unwrap();
    port.write_all(b"@S1\r").unwrap();
    let char_s = 10.0 / 4800.0 / speed;
    let started = Instant::now();
    let mut arrivals = Vec::new();
    let mut buf = [0u8; 256];
    while started.elapsed() < Duration::from_secs_f64(wall_s) {
        let n = port.read(&mut buf).unwrap();
        let at = started.elapsed().as_secs_f64();
        arrivals.extend(buf[..n].iter().map(|&b| (b, at)));
    }
    let s = daemon.status();
    stop(&mut daemon);
    // The daemon's own hand-over of each byte to the pty, as its recording timed it.
    let handed_over: Vec<(u8, f64)> = recorded_bytes(&record, "sonar")
        .into_iter()
        .filter(|(dir, _, _)| *dir == Direction::Tx)
        .map(|(_, b, wall)| (b, wall))
        .collect();
    let (sentences, mut late_us) = sentence_lateness_us(&arrivals, char_s);
    let (handed_sentences, mut handed_late_us) = sentence_lateness_us(&handed_over, char_s);
    let samples = late_us.len();
    let (p50, p99, max) = summary(&mut late_us);
    let (h50, h99, hmax) = summary(&mut handed_late_us);
    println!(
        "nmea emission jitter, realtime speed {speed}, {sentences} sentences ({samples} bytes) over {wall_s} s wall, overruns {}",
        s.overruns
    );
    println!(
        "  byte lateness vs wire schedule: p50 {p50:8.1} us  p99 {p99:8.1} us  max {max:8.1} us  (target p99 < 1000 us)"
    );
    println!(
        "  the daemon's hand-over alone (its recording, {handed_sentences} sentences): p50 {h50:8.1} us  p99 {h99:8.1} us  max {hmax:8.1} us"
    );
}

/// SIGTERM, and the wait for the daemon to finish its recording.
fn stop(daemon: &mut Daemon) {
    daemon.signal(nix::sys::signal::Signal::SIGTERM);
    daemon
        .wait(Duration::from_secs(5))
        .expect("the daemon stops on SIGTERM");
}

/// Every byte `--record` wrote for `link`, in order, with its direction and the wall time
/// the daemon read it (`rx`) or handed it to the port (`tx`, when it left the pacer, just
/// before the write).
fn recorded_bytes(record: &std::path::Path, link: &str) -> Vec<(Direction, u8, f64)> {
    read_chunks(record)
        .into_iter()
        .filter(|chunk| chunk.link == link)
        .flat_map(|chunk| {
            let (dir, wall) = (chunk.dir, chunk.wall_unix_s);
            chunk.data.into_iter().map(move |b| (dir, b, wall))
        })
        .collect()
}

/// Splits `(byte, time_s)` into sentences (`$` to `\n`) and returns how many, with each
/// byte's lateness against its sentence's wire schedule: byte k is due at S + (k + 1) x
/// `char_s`, S fitted per sentence as the earliest time minus its offset (so the best byte of
/// each sentence is 0 late).
fn sentence_lateness_us(bytes: &[(u8, f64)], char_s: f64) -> (usize, Vec<f64>) {
    let mut sentences: Vec<Vec<f64>> = Vec::new();
    let mut current: Option<Vec<f64>> = None;
    for &(b, at) in bytes {
        if b == b'$' {
            current = Some(Vec::new());
        }
        if let Some(times) = current.as_mut() {
            times.push(at);
            if b == b'\n' {
                sentences.extend(current.take());
            }
        }
    }
    let mut late_us = Vec::new();
    for times in &sentences {
        let offsets: Vec<f64> = times
            .iter()
            .enumerate()
            .map(|(k, t)| t - (k + 1) as f64 * char_s)
            .collect();
        let start = offsets.iter().copied().fold(f64::INFINITY, f64::min);
        late_us.extend(offsets.iter().map(|o| (o - start) * 1e6));
    }
    (sentences.len(), late_us)
}

fn cpu_percent(daemon: &Daemon, over: Duration) -> f64 {
    let c0 = daemon.cpu_time();
    let t0 = Instant::now();
    std::thread::sleep(over);
    let used = daemon.cpu_time() - c0;
    100.0 * used.as_secs_f64() / t0.elapsed().as_secs_f64()
}

fn cpu() {
    let byte_by_byte = cpu_with(Some(0.0));
    let quantum = cpu_with(None);
    println!(
        "  ratio stream CPU, release quantum 1 ms / one wake-up per byte: {:.2}x",
        quantum / byte_by_byte
    );
    let byte_by_byte = cpu_polled(Some(0.0));
    let quantum = cpu_polled(None);
    println!(
        "  ratio polled CPU, release quantum 1 ms / one wake-up per byte: {:.2}x",
        quantum / byte_by_byte
    );
}

/// Prints and returns the CPU while a client polls: `ADC_READ` of channels 0-7 in turn, 800
/// a second (each channel at 100 Hz, as a control loop reading every channel would), each
/// write waiting for its reply.
fn cpu_polled(quantum_ms: Option<f64>) -> f64 {
    let dir = TempDir::new("bench-cpu-poll");
    let args = quantum_args(&dir, quantum_ms);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let daemon = start_daemon(dir, &args);
    let port = open_raw(&daemon.link("sensor"));
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let client = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            poll_adc(port, || stop.load(std::sync::atomic::Ordering::Relaxed))
        })
    };
    std::thread::sleep(Duration::from_secs(1));
    let interval = Duration::from_secs(10);
    let polled = cpu_percent(&daemon, interval);
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let replies = client.join().unwrap();
    let quantum = quantum_ms.map_or("1.0 (default)".to_string(), |q| format!("{q:.1}"));
    println!("daemon CPU over {interval:?}, release_quantum_ms {quantum}");
    println!(
        "  800 ADC reads a second, client waiting for each: {polled:5.2} % of one core  ({replies} replies in {:.1} s)",
        (interval + Duration::from_secs(1)).as_secs_f64()
    );
    polled
}

/// `ADC_READ` of channels 0-7 in turn, 800 a second, each write waiting for its reply, until
/// `stop` says so; returns the number of replies.
fn poll_adc(mut port: std::fs::File, stop: impl Fn() -> bool) -> u32 {
    const PERIOD: Duration = Duration::from_micros(1250);
    let started = Instant::now();
    let mut reply = [0u8; 10];
    let mut i = 0u32;
    while !stop() {
        let due = started + PERIOD * i;
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        let request = frame(
            i as u8,
            Message::AdcRead {
                channel: AdcChannel::new((i % 8) as u8).unwrap(),
            },
        );
        port.write_all(&request).unwrap();
        port.read_exact(&mut reply).unwrap();
        i += 1;
    }
    i
}

/// Prints and returns the CPU under the stream.
fn cpu_with(quantum_ms: Option<f64>) -> f64 {
    let dir = TempDir::new("bench-cpu");
    let args = quantum_args(&dir, quantum_ms);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let daemon = start_daemon(dir, &args);
    std::thread::sleep(Duration::from_secs(1));
    let interval = Duration::from_secs(10);
    let idle = cpu_percent(&daemon, interval);
    let mut port = open_raw(&daemon.link("sensor"));
    port.write_all(&frame(
        1,
        Message::AdcStream {
            channels: 0xFF,
            period_ms: 10,
        },
    ))
    .unwrap();
    let mut reader = port.try_clone().unwrap();
    let drain = std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        let mut total = 0usize;
        let started = Instant::now();
        while started.elapsed() < Duration::from_secs(12) {
            total += reader.read(&mut buf).unwrap_or(0);
        }
        total
    });
    std::thread::sleep(Duration::from_secs(1));
    let streaming = cpu_percent(&daemon, interval);
    let received = drain.join().unwrap();
    let s = daemon.status();
    let quantum = quantum_ms.map_or("1.0 (default)".to_string(), |q| format!("{q:.1}"));
    println!(
        "daemon CPU over {interval:?}, release_quantum_ms {quantum} (ticks of {} Hz; /proc/PID/stat utime+stime)",
        clock_ticks_per_s()
    );
    println!("  idle (realtime, speed 1, no client):          {idle:5.2} % of one core");
    println!(
        "  100 Hz ADC stream, 8 channels, client reading: {streaming:5.2} % of one core  ({received} bytes received, {} frames sent)  (target < 5 %)",
        link_status(&s, "sensor").frames_tx
    );
    streaming
}

/// What the EyeBot side does while `view` measures.
#[derive(Debug, Clone, Copy)]
enum Load {
    /// The 100 Hz, 8-channel ADC stream.
    Stream,
    /// 800 `ADC_READ`s a second, each waiting for its reply.
    Polled,
}

fn view() {
    view_under(Load::Stream);
    view_under(Load::Polled);
}

/// The CPU a reading page adds: 10 s without a page, 10 s with one, 10 s without again, all
/// under `load`.
fn view_under(load: Load) {
    let dir = TempDir::new("bench-view");
    let mut args = quantum_args(&dir, None);
    args.push("--view".into());
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let daemon = Daemon::start(&binary(), dir, &args);
    let url = daemon.view_url.clone().expect("run --view prints its URL");
    let (addr, token) = eyebot_test_support::browser::split_view_url(&url);
    let interval = Duration::from_secs(10);
    let mut port = open_raw(&daemon.link("sensor"));
    let span = Duration::from_secs(33);
    let drain = match load {
        Load::Stream => {
            port.write_all(&frame(
                1,
                Message::AdcStream {
                    channels: 0xFF,
                    period_ms: 10,
                },
            ))
            .unwrap();
            std::thread::spawn(move || {
                let mut buf = [0u8; 4096];
                let started = Instant::now();
                while started.elapsed() < span {
                    let _ = port.read(&mut buf);
                }
            })
        }
        Load::Polled => std::thread::spawn(move || {
            let started = Instant::now();
            poll_adc(port, || started.elapsed() >= span);
        }),
    };
    std::thread::sleep(Duration::from_secs(1));
    let before = cpu_percent(&daemon, interval);
    let page = std::thread::spawn(move || {
        let mut stream = std::net::TcpStream::connect(addr).unwrap();
        write!(
            stream,
            "GET /api/stream?token={token} HTTP/1.1\r\nHost: {addr}\r\n\r\n"
        )
        .unwrap();
        stream
            .set_read_timeout(Some(Duration::from_millis(100)))
            .unwrap();
        let (mut bytes, mut frames) = (0usize, 0usize);
        let mut buf = [0u8; 65536];
        let started = Instant::now();
        while started.elapsed() < interval + Duration::from_millis(500) {
            if let Ok(n) = stream.read(&mut buf) {
                bytes += n;
                frames += buf[..n]
                    .windows(12)
                    .filter(|w| w == b"event: frame")
                    .count();
            }
        }
        (bytes, frames)
    });
    std::thread::sleep(Duration::from_millis(250));
    let with_page = cpu_percent(&daemon, interval);
    let (bytes, frames) = page.join().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let after = cpu_percent(&daemon, interval);
    drain.join().unwrap();
    let baseline = (before + after) / 2.0;
    let what = match load {
        Load::Stream => "100 Hz ADC stream",
        Load::Polled => "800 ADC reads a second",
    };
    println!("daemon CPU over {interval:?} each, {what}, run --view (/proc/PID/stat utime+stime)");
    println!("  no page:  {before:5.2} % before, {after:5.2} % after (baseline {baseline:5.2} %)");
    println!(
        "  one page reading the event stream: {with_page:5.2} % ({frames} frames, {bytes} bytes in {:.1} s)",
        (interval + Duration::from_millis(500)).as_secs_f64()
    );
    println!(
        "  a page costs {:+.2} % of one core (target < 2 %); ratio with / without {:.2}x",
        with_page - baseline,
        with_page / baseline
    );
}

fn rss() {
    let dir = TempDir::new("bench-rss");
    let record = dir.join("rec");
    let daemon = start_daemon(
        dir,
        &[
            "--time-mode",
            "realtime",
            "--speed",
            "100",
            "--record",
            record.to_str().unwrap(),
        ],
    );
    let mut port = open_raw(&daemon.link("sensor"));
    port.write_all(&frame(
        1,
        Message::AdcStream {
            channels: 0b0000_0111,
            period_ms: 100,
        },
    ))
    .unwrap();
    let mut sonar = open_raw(&daemon.link("sonar"));
    sonar.write_all(b"@S3\r").unwrap();
    let mut readers = Vec::new();
    for mut f in [port.try_clone().unwrap(), sonar.try_clone().unwrap()] {
        readers.push(std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            let mut total = 0usize;
            while let Ok(n) = f.read(&mut buf) {
                if n == 0 {
                    break;
                }
                total += n;
            }
            total
        }));
    }
    let mut series = Vec::new();
    let started = Instant::now();
    loop {
        let s = daemon.status();
        series.push((s.sim_time_s, daemon.rss_kb()));
        if s.sim_time_s >= 3600.0 || started.elapsed() > Duration::from_secs(60) {
            break;
        }
        std::thread::sleep(Duration::from_secs(2));
    }
    let s = daemon.status();
    // Least-squares slope over the second half (after start-up allocations settle).
    let half = &series[series.len() / 2..];
    let n = half.len() as f64;
    let mx = half.iter().map(|p| p.0).sum::<f64>() / n;
    let my = half.iter().map(|p| p.1 as f64).sum::<f64>() / n;
    let sxy: f64 = half.iter().map(|p| (p.0 - mx) * (p.1 as f64 - my)).sum();
    let sxx: f64 = half.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let slope_kb_per_h = sxy / sxx * 3600.0;
    println!(
        "resident memory, realtime speed 100 with a client (ADC stream + sonar) and --record, {:.0} s wall",
        started.elapsed().as_secs_f64()
    );
    println!(
        "  sim_s:rss_kB  {}",
        series
            .iter()
            .map(|(t, r)| format!("{t:.0}:{r}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    println!(
        "  first {} kB, last {} kB, slope over the second half {slope_kb_per_h:+.1} kB per simulated hour; overruns {}; sensor tx {} bytes, dropped {}",
        series[0].1,
        series[series.len() - 1].1,
        s.overruns,
        link_status(&s, "sensor").bytes_tx,
        link_status(&s, "sensor").dropped_tx
    );
    drop(daemon);
    for r in readers {
        let _ = r.join();
    }
}

fn main() {
    match cpu_latency_us() {
        Some(us) => {
            println!("daemon runs hold a CPU latency request of {us} us (run.cpu_latency_us)")
        }
        None => println!("no CPU latency request (set EYEBOT_BENCH_CPU_LATENCY_US to ask for one)"),
    }
    match rt_priority() {
        Some(p) => println!("daemon runs its bridge thread under SCHED_FIFO {p} (run.rt_priority)"),
        None => println!("default scheduler (set EYEBOT_BENCH_RT_PRIORITY to ask for SCHED_FIFO)"),
    }
    // `cargo bench` passes `--bench`; any other argument picks sections.
    let picked: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let run = |name: &str| picked.is_empty() || picked.iter().any(|p| p == name);
    if run("adc") {
        adc();
    }
    if run("nmea") {
        nmea();
    }
    if run("cpu") {
        cpu();
    }
    if run("rss") {
        rss();
    }
    if run("view") {
        view();
    }
}
