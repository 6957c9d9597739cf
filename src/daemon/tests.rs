//! The daemon in-process over ptys and sockets: each test drives a `Daemon` and checks what
//! crossed its lines.

use bytes::BytesMut;
use firmware_protocol::sensor_link::Message;
use firmware_protocol::sonar_link::SonarCommand;
use firmware_protocol::{Frame, LineDecoder, LineItem, Talker, Transducer};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::*;
use crate::config::{ConfigSource, DEFAULT_CONFIG, Document, Embedded};
use crate::devices::multiplexer::{DepthSentence, InvalidEcho, Multiplexer, MultiplexerSettings};
use crate::devices::sensor_board::{BoardSettings, SensorBoard};
use crate::engine::fake::FakeModel;
use crate::probe::{RetryPolicy, SensorClient};
use crate::transport::serial;

fn config(run_dir: &Path) -> DaemonConfig {
    let text = Embedded.read(DEFAULT_CONFIG).unwrap();
    let mut config = DaemonConfig::resolve(&Document::new("default", &text)).unwrap();
    config.time_mode = TimeMode::Lockstep;
    config.run_dir = run_dir.to_path_buf();
    config
}

/// A fresh scratch directory (removed when it drops) and the default configuration in
/// `time_mode` with its run directory inside.
fn scratch(tag: &str, time_mode: TimeMode) -> (tempfile::TempDir, DaemonConfig) {
    let dir = crate::scratch::dir(tag);
    let mut config = config(&dir.path().join("run"));
    config.time_mode = time_mode;
    (dir, config)
}

fn devices() -> (SensorBoard, Multiplexer) {
    let board = SensorBoard::new(BoardSettings {
        tick_ns: 10_000_000,
        lockstep: true,
        compass_period_ns: 400_000_000,
        line_chars_per_s: 11_520.0,
        watchdog_ns: None,
        sonar_on_this_line: false,
    });
    let mux = Multiplexer::new(MultiplexerSettings {
        sentence: DepthSentence::Dbt,
        talker: Talker::SOUNDER,
        invalid_echo: InvalidEcho::Omit,
        proprietary: false,
    });
    (board, mux)
}

async fn read_item(
    port: &mut tokio_serial::SerialStream,
    buf: &mut BytesMut,
    decoder: &mut LineDecoder,
) -> LineItem {
    loop {
        if let Some(item) = decoder.decode(buf) {
            return item;
        }
        let mut chunk = [0u8; 256];
        let n = tokio::time::timeout(Duration::from_secs(5), port.read(&mut chunk))
            .await
            .expect("reply within 5 s")
            .unwrap();
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// `run` on a fake model with the test devices, as a task.
fn spawn_run(
    config: DaemonConfig,
    options: RunOptions,
    stop: watch::Receiver<bool>,
    on_ready: impl FnMut(Readiness) + Send + 'static,
) -> tokio::task::JoinHandle<Result<Summary, DaemonError>> {
    let (board, mux) = devices();
    tokio::spawn(async move {
        run(
            &config,
            FakeModel::default(),
            board,
            mux,
            options,
            stop,
            on_ready,
        )
        .await
    })
}

/// A sensor-link client that waits 5 s for each reply, without retries.
fn sensor_client(path: &Path) -> SensorClient {
    let mut client = SensorClient::open(path, &crate::transport::LineSettings::n81(115_200))
        .expect("open the sensor link");
    client.set_policy(RetryPolicy {
        timeout: Duration::from_secs(5),
        retries: 0,
    });
    client
}

/// Sends `message` on the sensor link and returns the reply to it.
async fn ask(sensor: &mut SensorClient, message: Message) -> Message {
    sensor
        .request("test request", message, Duration::ZERO)
        .await
        .expect("the reply within 5 s")
}

/// Opens the sensor and sonar links in `run_dir` and says hello on the sensor link.
async fn hello_on_both_links(run_dir: &Path) -> (SensorClient, tokio_serial::SerialStream) {
    let mut sensor = sensor_client(&run_dir.join("sensor"));
    let sonar = serial::open(
        &run_dir.join("sonar"),
        &crate::transport::LineSettings::n81(4800),
    )
    .unwrap();
    assert!(matches!(
        ask(&mut sensor, Message::Hello { client_version: 1 }).await,
        Message::HelloReply { .. }
    ));
    (sensor, sonar)
}

/// The select of transducer 1 as it crosses the sonar line.
fn select_transducer_1() -> BytesMut {
    let mut select = BytesMut::new();
    SonarCommand::Select(Transducer::new(1).unwrap()).encode(&mut select);
    select
}

/// The daemon in-process, in lockstep, over ptys: a client says hello, advances time,
/// selects a transducer; the sonar line delivers the ack and a sentence; status reports
/// the time; shutdown removes the links and finishes the recording.
/// Regression: every released chunk went to the link task's channel (64 chunks) and was
/// dropped when the channel was full. Paced bytes are released a few at a time, so a link
/// task that stalled for a few ms lost bytes of a client that was reading (33,318 bytes
/// in the one-hour run at speed 100 of `bench daemon rss`). Now they wait in a backlog.
#[test]
fn released_bytes_wait_for_a_busy_link_task_instead_of_being_dropped() {
    let (board, mux) = devices();
    let spec = |name, sonar, baud| LineSpec {
        name,
        carries: Carries {
            sonar,
            sensor: !sonar,
        },
        settings: crate::transport::LineSettings::n81(baud),
        tx_queue_bytes: 4096,
        release_quantum_ns: 1_000_000,
    };
    let specs = [spec("sonar", true, 4800), spec("sensor", false, 115_200)];
    let mut core = Engine::new(FakeModel::default(), board, mux, &specs, false);
    // A link task that takes one chunk and then stalls: a channel with room for one.
    let (sonar_tx, _sonar_rx) = mpsc::channel(1);
    let (sensor_tx, mut sensor_rx) = mpsc::channel(1);
    let runtime = |line, name, to_link| LineRuntime {
        cx: LineContext {
            line,
            name,
            counters: Arc::default(),
            recorder: None,
        },
        describe: String::new(),
        to_link,
        backlog: bytes::BytesMut::new(),
        backlog_limit: 4096,
        last_rx_wall: Instant::now(),
        peek: None,
        carries_sensor: line == 1,
    };
    let mut lines = vec![
        runtime(0, "sonar", sonar_tx),
        runtime(1, "sensor", sensor_tx),
    ];
    let mut stream = BytesMut::new();
    Frame::new(
        1,
        Message::AdcStream {
            channels: 0b1,
            period_ms: 10,
        },
    )
    .encode(&mut stream);
    core.receive(1, &stream).unwrap();
    let mut delivered = 0;
    for step in 1..=100u64 {
        core.advance_to(step * 10_000_000).unwrap();
        flush_outputs(&mut core, &mut lines, None);
        if step % 25 == 0 {
            // The link task catches up now and then.
            while let Ok(chunk) = sensor_rx.try_recv() {
                delivered += chunk.data.len();
                flush_outputs(&mut core, &mut lines, None);
            }
        }
    }
    assert_eq!(lines[1].cx.counters.dropped_tx.load(Ordering::Relaxed), 0);
    // The ACK and about 100 samples of 14 bytes, all delivered.
    assert!(delivered > 1300, "{delivered} bytes delivered");
}

/// Regression: the overrun check compared the time reached at the last wake with the
/// target now, so a normal 20 ms idle sleep at speed 10 (200 ms simulated) counted as an
/// overrun of more than `max_lag` (100 ms); the map re-anchored at the old time on every
/// wake and simulated time never advanced without client traffic.
#[tokio::test]
async fn realtime_at_speed_10_advances_without_a_client() {
    let (_dir, config) = scratch("rt10", TimeMode::Realtime { speed: 10.0 });
    let (stop_tx, stop_rx) = watch::channel(false);
    let daemon = spawn_run(config, RunOptions::default(), stop_rx, |_| {});
    tokio::time::sleep(Duration::from_secs(1)).await;
    stop_tx.send(true).unwrap();
    let summary = daemon.await.unwrap().unwrap();
    // 10 s in an ideal world; a loaded machine may slip a little (counted overruns).
    assert!(summary.sim_time_s >= 5.0, "1 s at speed 10: {summary:?}");
}

/// The three stages on their own: after `start` the links exist before anything is
/// served; a service added with `spawn_service` runs beside them and is told to stop by
/// `finish`; `serve` returns when its shutdown future resolves, having published status.
#[tokio::test]
async fn start_serve_finish_run_a_service_beside_the_links() {
    let (_dir, config) = scratch("stages", TimeMode::Lockstep);
    let run_dir = config.run_dir.clone();
    let (board, mux) = devices();
    let mut daemon = Daemon::start(
        &config,
        FakeModel::default(),
        board,
        mux,
        RunOptions::default(),
    )
    .await
    .unwrap();
    let names: Vec<&str> = daemon.links().iter().map(|l| l.name).collect();
    assert_eq!(names, ["sonar", "sensor"]);
    assert!(std::fs::symlink_metadata(run_dir.join("sensor")).is_ok());
    assert_eq!(daemon.status_socket(), run_dir.join("status.sock"));
    let (told_tx, told_rx) = tokio::sync::oneshot::channel();
    daemon.spawn_service("test", |mut stop| async move {
        let _ = stop.wait_for(|stop| *stop).await;
        let _ = told_tx.send(());
    });
    let mut updates = daemon.status_updates();
    daemon
        .serve(tokio::time::sleep(STATUS_PERIOD * 2))
        .await
        .unwrap();
    assert!(
        updates.has_changed().unwrap(),
        "status published while serving"
    );
    assert_eq!(updates.borrow_and_update().links.len(), 2);
    let summary = daemon.finish().await.unwrap();
    assert_eq!(
        summary.sim_time_s, 0.0,
        "lockstep without a client stays at 0"
    );
    tokio::time::timeout(Duration::from_secs(1), told_rx)
        .await
        .expect("the service stopped within its budget")
        .expect("the service was told to stop");
    for name in ["sonar", "sensor", "status.sock", feed::FEED_SOCKET] {
        assert!(
            std::fs::symlink_metadata(run_dir.join(name)).is_err(),
            "{name} removed"
        );
    }
}

/// Realtime counts from `serve`, not from `start`: time the caller spends in between
/// (announcing readiness) is neither simulated nor an overrun.
#[tokio::test]
async fn realtime_starts_counting_when_serving_begins() {
    let (_dir, config) = scratch("anchor", TimeMode::Realtime { speed: 1.0 });
    let (board, mux) = devices();
    let options = RunOptions::default();
    let mut daemon = Daemon::start(&config, FakeModel::default(), board, mux, options)
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    daemon
        .serve(tokio::time::sleep(Duration::from_millis(100)))
        .await
        .unwrap();
    let summary = daemon.finish().await.unwrap();
    assert_eq!(summary.overruns, 0, "{summary:?}");
    assert!(summary.sim_time_s < 0.4, "{summary:?}");
}

#[tokio::test]
async fn lockstep_daemon_serves_ptys_and_shuts_down_cleanly() {
    let (tmp, config) = scratch("daemon", TimeMode::Lockstep);
    let dir = tmp.path();
    let run_dir = config.run_dir.clone();
    let record = dir.join("rec");
    let (stop_tx, stop_rx) = watch::channel(false);
    let (ready_tx, mut ready_rx) = mpsc::unbounded_channel();
    let options = RunOptions {
        record: Some(record.clone()),
        pid_file: Some(dir.join("pid")),
        config_toml: "seed = 1\n".into(),
        ..RunOptions::default()
    };
    let daemon = spawn_run(config, options, stop_rx, move |r| {
        let _ = ready_tx.send(r);
    });
    let mut links = Vec::new();
    while let Readiness::Link { name, path } =
        ready_rx.recv().await.expect("daemon reports readiness")
    {
        links.push((name, path));
    }
    assert_eq!(
        links.iter().map(|l| l.0).collect::<Vec<_>>(),
        vec!["sonar", "sensor"]
    );
    assert!(dir.join("pid").exists());

    let (mut sensor, mut sonar) = hello_on_both_links(&run_dir).await;
    let select = select_transducer_1();
    sonar.write_all(&select).await.unwrap();
    // Give the select time to cross its pty before time moves on.
    tokio::time::sleep(Duration::from_millis(100)).await;
    let time = ask(&mut sensor, Message::TimeAdvance { ticks: 150 }).await;
    assert!(matches!(time, Message::Time { ticks: 150, .. }), "{time:?}");
    let (mut nbuf, mut ndec) = (BytesMut::new(), LineDecoder::new());
    assert!(matches!(
        read_item(&mut sonar, &mut nbuf, &mut ndec).await,
        LineItem::Sonar(SonarCommand::Ack(_))
    ));
    assert!(matches!(
        read_item(&mut sonar, &mut nbuf, &mut ndec).await,
        LineItem::Nmea(_)
    ));

    tokio::time::sleep(STATUS_PERIOD * 2).await;
    let status = status::query(&run_dir.join("status.sock"), Duration::from_secs(2))
        .await
        .unwrap();
    assert_eq!(status.sim_time_s, 1.5);
    assert_eq!(status.time_mode, "lockstep");

    // `replay --into-sonar`: captured sentences through the feed socket replace the
    // model's; the log's $PEBHS maps each to its transducer (1 is selected, 2 is not).
    let mut feed = tokio::net::UnixStream::connect(run_dir.join(feed::FEED_SOCKET))
        .await
        .unwrap();
    feed.write_all(
        b"$SDDBT,8.2,f,2.5,M,1.4,F*0E\r\n$PEBHS,1,2.5,90*71\r\n$SDDBT,9.9,f,3.0,M,1.6,F*02\r\n$PEBHS,2,3.0,90*76\r\n",
    )
    .await
    .unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    let time = ask(&mut sensor, Message::TimeAdvance { ticks: 50 }).await;
    assert!(matches!(time, Message::Time { ticks: 200, .. }), "{time:?}");
    let fed = read_item(&mut sonar, &mut nbuf, &mut ndec).await;
    let LineItem::Nmea(firmware_protocol::Sentence::Dbt(dbt)) = fed else {
        panic!("expected the fed DBT, got {fed:?}")
    };
    assert_eq!(
        dbt.metres.map(|m| m.tenths()),
        Some(25),
        "transducer 1's logged 2.5 m"
    );
    let mut more = [0u8; 64];
    let late = tokio::time::timeout(Duration::from_millis(300), sonar.read(&mut more)).await;
    assert!(
        nbuf.is_empty() && late.is_err(),
        "transducer 2's 3.0 m was withheld"
    );
    drop(feed);

    stop_tx.send(true).unwrap();
    let summary = tokio::time::timeout(Duration::from_secs(1), daemon)
        .await
        .expect("shutdown within 1 s")
        .unwrap()
        .unwrap();
    assert_eq!(summary.sim_time_s, 2.0);
    let records = summary.records.unwrap();
    assert!(records.chunks >= 6, "{records:?}");
    assert!(records.states > 0);
    for name in ["sonar", "sensor", "status.sock"] {
        assert!(
            std::fs::symlink_metadata(run_dir.join(name)).is_err(),
            "{name} removed"
        );
    }
    assert!(!dir.join("pid").exists());
}

/// In lockstep a client may write a select a byte at a time (RoBIOS's `OSSendCharRS232`)
/// and the host may deschedule it between the writes for longer than the sonar line's
/// idle limit. Simulated time stands still meanwhile, so the select is whole and is
/// acknowledged: what the client gets does not depend on the host's scheduling.
/// Regression: the sonar-only line was also flushed after 200 ms of wall time, which
/// dropped the select's first bytes when the client was slow (qemu under load).
#[tokio::test]
async fn lockstep_select_written_slowly_byte_by_byte_is_acknowledged() {
    let (_tmp, config) = scratch("daemon-slow-select", TimeMode::Lockstep);
    let run_dir = config.run_dir.clone();
    let (stop_tx, stop_rx) = watch::channel(false);
    let (ready_tx, mut ready_rx) = mpsc::unbounded_channel();
    let daemon = spawn_run(config, RunOptions::default(), stop_rx, move |r| {
        let _ = ready_tx.send(r);
    });
    while let Readiness::Link { .. } = ready_rx.recv().await.expect("daemon reports readiness") {}
    let (mut sensor, mut sonar) = hello_on_both_links(&run_dir).await;
    let select = select_transducer_1();
    let pause =
        Duration::from_nanos(crate::engine::SONAR_IDLE_FLUSH_NS) + Duration::from_millis(150);
    for byte in select.iter() {
        sonar.write_all(&[*byte]).await.unwrap();
        tokio::time::sleep(pause).await;
    }
    let time = ask(&mut sensor, Message::TimeAdvance { ticks: 150 }).await;
    assert!(matches!(time, Message::Time { ticks: 150, .. }), "{time:?}");
    let (mut buf, mut decoder) = (BytesMut::new(), LineDecoder::new());
    let first = read_item(&mut sonar, &mut buf, &mut decoder).await;
    assert!(
        matches!(first, LineItem::Sonar(SonarCommand::Ack(_))),
        "the slow select is acknowledged, got {first:?}"
    );
    stop_tx.send(true).unwrap();
    let _ = tokio::time::timeout(Duration::from_secs(1), daemon).await;
}
