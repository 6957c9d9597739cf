//! Hostile EyeBot sides: garbage at full speed, hang-ups mid-frame, endless reopening, and a
//! client that never reads. The daemon keeps answering, counts the trouble, keeps memory
//! bounded.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use eyebot_hil::probe::SonarItem;
use eyebot_hil::record::{Direction, DropReason};
use eyebot_test_support::clients::{expect_hello, open_raw, sensor_client, sonar_client};
use eyebot_test_support::config::NEAR_WALL;
use eyebot_test_support::daemon::link_status;
use eyebot_test_support::recording::{read_chunks, read_drops, stream};
use eyebot_test_support::{Daemon, RunningDaemon};
use firmware_protocol::Transducer;
use firmware_protocol::sensor_link::Message;
use rand::{Rng, SeedableRng};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

const MIB: u64 = 1024;

/// Writes seeded random bytes to `path` for `for_how_long`; returns how many.
fn flood(path: &Path, seed: u64, for_how_long: Duration) -> u64 {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut port = open_raw(path);
    let mut chunk = [0u8; 4096];
    let mut sent = 0u64;
    let started = Instant::now();
    while started.elapsed() < for_how_long {
        rng.fill_bytes(&mut chunk);
        port.write_all(&chunk).expect("write garbage");
        sent += chunk.len() as u64;
    }
    sent
}

/// Garbage at full speed on both links, twice: the daemon keeps answering, counts errors, and
/// its resident memory does not grow with the amount of garbage.
///
/// Bound: the second flood (as long as the first) may add at most 1 MiB, and the whole run
/// at most 8 MiB over the idle daemon. In-flight buffers are bounded by design: 256 inbound
/// chunks of at most 4 KiB (1 MiB), 64 outbound chunks per line, a 4 KiB transmit queue per
/// line and decoder buffers capped at one candidate frame; anything proportional to the
/// flood (many MiB) would exceed both bounds.
#[tokio::test]
async fn garbage_floods_are_survived_with_bounded_memory() {
    let daemon = Daemon::options(BIN, "flood").realtime().start();
    let sensor = daemon.link("sensor");
    let sonar = daemon.link("sonar");
    expect_hello(&sensor, "the daemon still answers HELLO").await;
    let idle_kb = daemon.rss_kb();
    let mut sizes = Vec::new();
    let mut rss = Vec::new();
    for round in 0..2u64 {
        let (a, b) = (sensor.clone(), sonar.clone());
        let t1 = std::thread::spawn(move || flood(&a, round, Duration::from_millis(1500)));
        let t2 = std::thread::spawn(move || flood(&b, 100 + round, Duration::from_millis(1500)));
        sizes.push(t1.join().unwrap() + t2.join().unwrap());
        // Let the daemon work off what it already read.
        daemon.wait_status(Duration::from_secs(10), "the flood was read", |s| {
            link_status(s, "sensor").bytes_rx + link_status(s, "sonar").bytes_rx
                >= sizes.iter().sum::<u64>() * 9 / 10
        });
        rss.push(daemon.rss_kb());
    }
    expect_hello(&sensor, "the daemon still answers HELLO").await;
    let s = daemon.status();
    let sensor_link = link_status(&s, "sensor");
    let sonar_link = link_status(&s, "sonar");
    eprintln!(
        "flood: {} + {} bytes; RSS idle {idle_kb} kB, after each flood {rss:?} kB; sensor {sensor_link:?}; sonar {sonar_link:?}",
        sizes[0], sizes[1]
    );
    assert!(
        sizes[1] > 4 * MIB * 1024,
        "the flood was big: {sizes:?} bytes"
    );
    assert!(sensor_link.errors > 1000, "{sensor_link:?}");
    assert!(sonar_link.errors > 1000, "{sonar_link:?}");
    assert!(
        rss[1] <= rss[0] + MIB,
        "the second flood grew RSS from {} to {} kB",
        rss[0],
        rss[1]
    );
    assert!(
        rss[1] <= idle_kb + 8 * MIB,
        "RSS {idle_kb} kB idle, {} kB after the floods",
        rss[1]
    );
}

/// An EyeBot that hangs up mid-frame (50 times on the sensor link, 50 mid-sentence on the
/// sonar link), then one that opens and closes the ptys 100 times: the daemon still answers,
/// reports the broken input, and memory stays flat.
#[tokio::test]
async fn hang_ups_and_reopens_are_survived() {
    let daemon = Daemon::options(BIN, "hangup").realtime().start();
    let sensor = daemon.link("sensor");
    let sonar = daemon.link("sonar");
    expect_hello(&sensor, "the daemon still answers HELLO").await;
    let before = daemon.rss_kb();
    // HELLO is EB 90 01 seq 01 01 crc crc: cut after 5 bytes.
    for i in 0..50u8 {
        open_raw(&sensor)
            .write_all(&[0xEB, 0x90, 0x01, i, 0x01])
            .unwrap();
        open_raw(&sonar).write_all(b"@S").unwrap();
    }
    daemon.wait_status(Duration::from_secs(10), "the broken input counted", |s| {
        link_status(s, "sensor").errors >= 1 && link_status(s, "sonar").errors >= 1
    });
    expect_hello(&sensor, "the daemon still answers HELLO").await;
    let reconnects = |s: &eyebot_hil::daemon::status::StatusSnapshot| {
        (
            link_status(s, "sensor").reconnects,
            link_status(s, "sonar").reconnects,
        )
    };
    for _ in 0..100 {
        drop(open_raw(&sensor));
        drop(open_raw(&sonar));
    }
    // Each reopen is reported (regression: the bridge keeps the slave open, so a reopen was
    // invisible and never counted). Opens so far: sensor 1 + 50 + 1 + 100 (the HELLO
    // clients, the cut frames, the reopens), sonar 50 + 100; the first is a connect.
    let expected = (151, 149);
    let s = daemon.wait_status(Duration::from_secs(10), "the reopens counted", |s| {
        let (a, b) = reconnects(s);
        a >= expected.0 && b >= expected.1
    });
    assert_eq!(reconnects(&s), expected, "one reconnect per reopen");
    expect_hello(&sensor, "the daemon still answers HELLO").await;
    let mut sonar_client = sonar_client(&sonar);
    sonar_client
        .select(Transducer::new(2).unwrap())
        .await
        .unwrap();
    assert_eq!(
        sonar_client.next(Duration::from_secs(10)).await.unwrap(),
        Some(SonarItem::Ack(2)),
        "the sonar link still answers after the hang-ups"
    );
    let after = daemon.rss_kb();
    assert!(
        after <= before + MIB,
        "RSS grew from {before} to {after} kB over 100 hang-ups and 200 reopens"
    );
}

/// A garbage flood on both links with `--record`: the recorder's queue is bounded, so a
/// flood cannot grow memory through it, and nothing read is lost from the recording (the
/// bridge waits for the recorder instead: back-pressure down to the EyeBot's writes).
#[tokio::test]
async fn a_recorded_garbage_flood_loses_nothing_and_keeps_memory_bounded() {
    let mut daemon = Daemon::options(BIN, "flood-rec")
        .realtime()
        .record()
        .start();
    let sensor = daemon.link("sensor");
    let sonar = daemon.link("sonar");
    expect_hello(&sensor, "the daemon still answers HELLO").await;
    let idle_kb = daemon.rss_kb();
    let (a, b) = (sensor.clone(), sonar.clone());
    let t1 = std::thread::spawn(move || flood(&a, 7, Duration::from_millis(2000)));
    let t2 = std::thread::spawn(move || flood(&b, 107, Duration::from_millis(2000)));
    let mut peak_kb = idle_kb;
    while !(t1.is_finished() && t2.is_finished()) {
        peak_kb = peak_kb.max(daemon.rss_kb());
        std::thread::sleep(Duration::from_millis(20));
    }
    let sent = (t1.join().unwrap(), t2.join().unwrap());
    daemon.wait_status(Duration::from_secs(30), "the flood was read", |s| {
        link_status(s, "sensor").bytes_rx >= sent.0 + 8
            && link_status(s, "sonar").bytes_rx >= sent.1
    });
    peak_kb = peak_kb.max(daemon.rss_kb());
    daemon.stop();
    let chunks = read_chunks(daemon.record_dir());
    let recorded = |link: &str| stream(&chunks, link, Direction::Rx).len() as u64;
    eprintln!(
        "recorded flood: sent {sent:?} bytes; recorded rx sensor {} sonar {}; RSS idle {idle_kb} kB, peak {peak_kb} kB",
        recorded("sensor"),
        recorded("sonar")
    );
    assert!(sent.0 > 4 * MIB * 1024, "the flood was big: {sent:?}");
    // HELLO (8 bytes) before the flood on the sensor link.
    assert_eq!(recorded("sensor"), sent.0 + 8, "every sensor byte recorded");
    assert_eq!(recorded("sonar"), sent.1, "every sonar byte recorded");
    assert!(
        peak_kb <= idle_kb + 8 * MIB,
        "RSS {idle_kb} kB idle, peak {peak_kb} kB during the recorded flood"
    );
}

/// A client that opens the sensor link, starts a fast stream and never reads: the sonar link
/// keeps being served, and status reports the dropped bytes.
#[tokio::test]
async fn a_client_that_never_reads_does_not_stall_the_other_link() {
    // Near the west wall, so the port transducer has echoes.
    let mut daemon = Daemon::options(BIN, "noread")
        .config(&[NEAR_WALL])
        .realtime()
        .args(&["--speed", "10"])
        .record()
        .start();
    let mut sensor = sensor_client(&daemon.link("sensor"));
    let reply = sensor
        .request(
            "stream",
            Message::AdcStream {
                channels: 0xFF,
                period_ms: 5,
            },
            Duration::ZERO,
        )
        .await
        .unwrap();
    assert!(matches!(reply, Message::Ack { .. }), "{reply:?}");
    // From here on nobody reads the sensor link.
    let s = daemon.wait_status(Duration::from_secs(15), "dropped bytes", |s| {
        link_status(s, "sensor").dropped_tx > 0
    });
    let dropped = link_status(&s, "sensor").dropped_tx;
    let mut sonar = sonar_client(&daemon.link("sonar"));
    sonar.select(Transducer::new(1).unwrap()).await.unwrap();
    let mut sentences = 0;
    let deadline = Instant::now() + Duration::from_secs(10);
    while sentences < 3 && Instant::now() < deadline {
        match sonar.next(Duration::from_secs(2)).await.unwrap() {
            Some(SonarItem::Sentence { .. }) => sentences += 1,
            Some(SonarItem::Ack(1)) | None => {}
            Some(other) => panic!("unexpected {other:?}"),
        }
    }
    assert_eq!(
        sentences, 3,
        "the sonar link is served while the sensor link is stuck"
    );
    let later = daemon.status();
    assert!(
        link_status(&later, "sensor").dropped_tx > dropped,
        "dropping goes on while the client does not read"
    );
    // The recording says which released bytes never reached the client (regression: they
    // were recorded as sent, with nothing to tell them apart).
    let dropped_before_stop = link_status(&later, "sensor").dropped_tx;
    daemon.stop();
    let drops = read_drops(daemon.record_dir());
    let not_read: usize = drops
        .iter()
        .filter(|d| d.link == "sensor" && d.reason == DropReason::NotRead)
        .map(|d| d.data.len())
        .sum();
    assert!(
        not_read as u64 >= dropped_before_stop,
        "drops.tsv holds {not_read} not-read bytes, status counted {dropped_before_stop}"
    );
    // Only the stuck link dropped anything.
    assert!(
        drops.iter().all(|d| d.link == "sensor"),
        "only the sensor link dropped"
    );
    drop(sensor);
}

/// The rate-limited warning kinds a sonar flood can raise: "transmit queue full" (answers
/// the client never reads), "sonar select refused" and "overrun" (a starved loop).
const FLOOD_WARNING_KINDS: u64 = 3;

/// A flood of selects on the sonar link, half of them bad (`@S1\r@S9\r`, a megabyte): every
/// byte, select and bad select is counted, and stderr gets a bounded number of lines, not
/// one per sentence. The bound is the limiter's own: per kind, `BURST` warnings and one
/// "suppressed N" line per window, over the windows the daemon was alive.
#[test]
fn a_sonar_flood_costs_counters_not_log_lines() {
    use eyebot_hil::daemon::warn_limit::{BURST, WINDOW};
    let started = Instant::now();
    let mut daemon = Daemon::options(BIN, "log-flood").realtime().start();
    let pairs: u64 = 128 * 1024;
    let flood: Vec<u8> = b"@S1\r@S9\r"
        .iter()
        .copied()
        .cycle()
        .take(8 * pairs as usize)
        .collect();
    let mut sonar = open_raw(&daemon.link("sonar"));
    sonar.write_all(&flood).expect("write the flood");
    // Bytes are counted as the link task reads them, sentences as the engine decodes them.
    let s = daemon.wait_status(Duration::from_secs(20), "the flood read and decoded", |s| {
        let l = link_status(s, "sonar");
        l.bytes_rx >= flood.len() as u64 && l.frames_rx >= pairs && l.errors >= pairs
    });
    let link = link_status(&s, "sonar").clone();
    drop(sonar);
    daemon.stop();
    let alive = started.elapsed();
    assert_eq!(link.bytes_rx, flood.len() as u64, "{link:?}");
    assert_eq!(link.frames_rx, pairs, "every good select counted: {link:?}");
    assert_eq!(link.errors, pairs, "every bad select counted: {link:?}");
    assert!(
        link.frames_tx >= pairs,
        "every bad select answered: {link:?}"
    );
    let log = daemon.log();
    let warnings: Vec<&str> = log.lines().filter(|l| l.contains("WARN")).collect();
    let windows = alive.as_nanos().div_ceil(WINDOW.as_nanos()) as u64 + 1;
    let bound = FLOOD_WARNING_KINDS * (u64::from(BURST) + 1) * windows;
    eprintln!(
        "{} selects in {alive:?}: {} stderr lines, {} warnings (bound {bound}); {link:?}",
        2 * pairs,
        log.lines().count(),
        warnings.len()
    );
    assert!(
        warnings.len() as u64 <= bound,
        "{} warning lines for {} sentences in {alive:?} (bound {bound}):\n{log}",
        warnings.len(),
        2 * pairs
    );
    // The other lines are the daemon's start and stop, whatever the flood.
    assert!(
        log.lines().count() - warnings.len() <= 20,
        "more than start-up and shut-down lines besides the warnings:\n{log}"
    );
    assert!(
        link.dropped_tx == 0
            || warnings
                .iter()
                .any(|l| l.contains("suppressed") && l.contains("transmit queue full")),
        "answers were dropped but no `suppressed` line reports the hidden warnings:\n{log}"
    );
}
