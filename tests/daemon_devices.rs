//! Every device the bridge emulates, exercised over its ptys, one test per device, each
//! against the built binary and against the library's daemon in-process. The shared
//! fixture, [`Rig`], starts the daemon in lockstep 1.5 m off the west wall, opens both links,
//! counts the sensor-link requests and, when the test is done, checks the bridge counted the
//! same requests, saw no error, and sent only well-formed frames.

use std::path::{Path, PathBuf};
use std::time::Duration;

use eyebot_hil::daemon::status::StatusSnapshot;
use eyebot_hil::probe::{ProbeError, SensorClient, SonarClient, SonarItem};
use eyebot_test_support::clients::{sensor_client, sonar_client};
use eyebot_test_support::config::{LOCKSTEP, NEAR_WALL, config_text};
use eyebot_test_support::daemon::link_status;
use eyebot_test_support::{Daemon, InProcessDaemon, RunningDaemon, TempDir};
use firmware_protocol::sensor_link::{
    AdcChannel, CalibrationAction, CalibrationState, CompassMode, CompassOutput, Direction,
    ErrorCode, Message, ThrusterCommand, TimeMode,
};
use firmware_protocol::{HeadingFormat, Sentence, Transducer};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

/// What the port-side transducers see of the west wall from the rig's start (see
/// [`NEAR_WALL`]).
const EXPECTED_WALL_RANGE_M: f64 = 1.22;

const FULL_FORWARD: ThrusterCommand = ThrusterCommand {
    duty: 0x00,
    direction: Direction::Forward,
};

/// How the daemon under test runs.
#[derive(Debug, Clone, Copy)]
enum Runner {
    Binary,
    InProcess,
}

enum UnderTest {
    Binary(Daemon),
    InProcess(InProcessDaemon),
}

impl UnderTest {
    fn daemon(&self) -> &dyn RunningDaemon {
        match self {
            UnderTest::Binary(d) => d,
            UnderTest::InProcess(d) => d,
        }
    }
}

impl RunningDaemon for UnderTest {
    fn run_dir(&self) -> &Path {
        self.daemon().run_dir()
    }

    fn status_socket(&self) -> PathBuf {
        self.daemon().status_socket()
    }
}

/// The shared fixture: a lockstep daemon near the west wall, a client on each link, and the
/// number of sensor-link requests sent.
struct Rig {
    under_test: UnderTest,
    sensor: SensorClient,
    sonar: SonarClient,
    requests: u64,
}

impl Rig {
    fn start(runner: Runner, tag: &str) -> Self {
        let dir = TempDir::new(tag);
        let under_test = match runner {
            Runner::Binary => {
                let config = dir.write_config("near-wall.toml", &[NEAR_WALL]);
                let config = config.to_str().expect("a UTF-8 path");
                let daemon =
                    Daemon::start(BIN, dir, &["--config", config, "--time-mode", "lockstep"]);
                let names: Vec<&str> = daemon.links.iter().map(|l| l.0.as_str()).collect();
                assert_eq!(names, ["sonar", "sensor"], "the links announced");
                UnderTest::Binary(daemon)
            }
            Runner::InProcess => {
                let text = config_text(&[NEAR_WALL, LOCKSTEP]);
                let dir = TempDir::new(tag);
                UnderTest::InProcess(InProcessDaemon::start(dir, &text, None, |_| {}))
            }
        };
        let sensor = sensor_client(&under_test.link("sensor"));
        let sonar = sonar_client(&under_test.link("sonar"));
        Self {
            under_test,
            sensor,
            sonar,
            requests: 0,
        }
    }

    fn status(&self) -> StatusSnapshot {
        self.under_test.status()
    }

    /// Polls the status until `pred` holds.
    fn wait_status(&self, what: &str, pred: impl Fn(&StatusSnapshot) -> bool) -> StatusSnapshot {
        self.under_test
            .wait_status(Duration::from_secs(10), what, pred)
    }

    fn link(&self, name: &str) -> PathBuf {
        self.under_test.link(name)
    }

    async fn try_request(
        &mut self,
        what: &'static str,
        message: Message,
    ) -> Result<Message, ProbeError> {
        self.requests += 1;
        self.sensor.request(what, message, Duration::ZERO).await
    }

    async fn request(&mut self, what: &'static str, message: Message) -> Message {
        self.try_request(what, message)
            .await
            .unwrap_or_else(|e| panic!("{what}: {e}"))
    }

    async fn ack(&mut self, what: &'static str, message: Message) {
        let kind = message.msg_type();
        match self.request(what, message).await {
            Message::Ack { acked_type } => assert_eq!(acked_type, kind, "{what}"),
            other => panic!("{what}: expected ACK, got {other:?}"),
        }
    }

    /// Advances simulated time by `ticks` (10 ms each); returns the tick count now.
    async fn advance(&mut self, ticks: u32) -> u32 {
        match self
            .request("advance", Message::TimeAdvance { ticks })
            .await
        {
            Message::Time { ticks, tick_us } => {
                assert_eq!(tick_us, 10_000, "1/100 s ticks");
                ticks
            }
            other => panic!("TIME_ADVANCE answered with {other:?}"),
        }
    }

    /// The pushes received so far: those due before the last TIME reply were sent before it.
    async fn pushes(&mut self) -> Vec<Message> {
        let mut out = Vec::new();
        while let Some(frame) = self
            .sensor
            .next_push(Duration::from_millis(50))
            .await
            .expect("read pushes")
        {
            out.push(frame.message);
        }
        out
    }

    async fn compass_read(&mut self) -> Message {
        self.request("compass read", Message::CompassRead).await
    }

    async fn calibrate(
        &mut self,
        action: CalibrationAction,
    ) -> Result<(CalibrationState, u8), ProbeError> {
        match self
            .try_request("calibrate", Message::CompassCalibrate { action })
            .await?
        {
            Message::CalibrationStatus { state, points } => Ok((state, points)),
            other => panic!("COMPASS_CALIBRATE answered with {other:?}"),
        }
    }

    /// Sends a sonar select and waits until the bridge has it, so what follows happens after
    /// it in simulated time.
    async fn select(&mut self, transducer: u8) {
        let before = link_status(&self.status(), "sonar").frames_rx;
        self.sonar
            .select(Transducer::new(transducer).expect("a transducer number"))
            .await
            .expect("send the select");
        self.wait_status("the select reached the bridge", |s| {
            link_status(s, "sonar").frames_rx > before
        });
    }

    /// Every sonar item until the line stays quiet for 200 ms.
    async fn sonar_items(&mut self) -> Vec<SonarItem> {
        let mut items = Vec::new();
        while let Some(item) = self
            .sonar
            .next(Duration::from_millis(200))
            .await
            .expect("read the sonar link")
        {
            items.push(item);
        }
        items
    }

    /// The bridge counted every request this test sent, saw no error on the sensor link, and
    /// sent only well-formed frames; an in-process run then stops cleanly at the simulated
    /// time the status showed.
    fn finish(self) {
        let n = self.requests;
        let s = self.wait_status("every request counted", |s| {
            link_status(s, "sensor").frames_rx >= n
        });
        assert_eq!(s.time_mode, "lockstep");
        let sensor_link = link_status(&s, "sensor");
        assert_eq!(sensor_link.errors, 0, "{sensor_link:?}");
        assert_eq!(sensor_link.frames_rx, n, "{sensor_link:?}");
        assert_eq!(
            self.sensor.errors(),
            0,
            "the bridge sent only well-formed frames"
        );
        if let UnderTest::InProcess(mut daemon) = self.under_test {
            let summary = daemon.stop();
            assert_eq!(summary.sim_time_s, s.sim_time_s, "{summary:?}");
        }
    }
}

fn angle_between_deg(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

/// HELLO, the time mode (set once, then refused) and lockstep time.
async fn hello_and_time(runner: Runner) {
    let mut rig = Rig::start(runner, "dev-time");
    match rig
        .request("hello", Message::Hello { client_version: 1 })
        .await
    {
        Message::HelloReply {
            protocol_version,
            tick_us,
            ..
        } => {
            assert_eq!(protocol_version, 1);
            assert_eq!(tick_us, 10_000);
        }
        other => panic!("HELLO answered with {other:?}"),
    }
    let lockstep = Message::TimeMode {
        mode: TimeMode::Lockstep,
    };
    rig.ack("time mode", lockstep).await;
    let refused = rig
        .try_request(
            "time mode",
            Message::TimeMode {
                mode: TimeMode::RealTime,
            },
        )
        .await;
    assert!(
        matches!(
            refused,
            Err(ProbeError::Refused {
                code: ErrorCode::BadState,
                ..
            })
        ),
        "{refused:?}"
    );
    let Message::Time { ticks: 0, .. } = rig.request("time", Message::TimeGet).await else {
        panic!("a fresh lockstep bridge is at tick 0");
    };
    assert_eq!(rig.advance(25).await, 25);
    assert_eq!(rig.advance(10).await, 35, "time adds up");
    rig.finish();
}

/// ADC: every channel polled answers for itself; a stream of two channels pushes one sample
/// per period, and a stopped stream stays quiet.
async fn adc(runner: Runner) {
    let mut rig = Rig::start(runner, "dev-adc");
    for channel in 0..8 {
        let reply = rig
            .request(
                "adc",
                Message::AdcRead {
                    channel: AdcChannel::new(channel).expect("channel 0..8"),
                },
            )
            .await;
        let Message::AdcValue { channel: c, .. } = reply else {
            panic!("ADC_READ answered with {reply:?}");
        };
        assert_eq!(c.get(), channel);
    }
    let stream = Message::AdcStream {
        channels: 0b0000_0101,
        period_ms: 10,
    };
    rig.ack("adc stream", stream).await;
    assert_eq!(rig.advance(10).await, 10);
    let ticks: Vec<u32> = rig
        .pushes()
        .await
        .iter()
        .map(|m| match m {
            Message::AdcSamples { ticks, samples } => {
                assert_eq!(samples.mask(), 0b0000_0101, "{m:?}");
                *ticks
            }
            other => panic!("unexpected push {other:?}"),
        })
        .collect();
    assert_eq!(ticks, (1..=10).collect::<Vec<_>>(), "one sample per 10 ms");
    let stop = Message::AdcStream {
        channels: 0,
        period_ms: 0,
    };
    rig.ack("adc stream stop", stop).await;
    assert_eq!(rig.advance(10).await, 20);
    assert_eq!(rig.pushes().await, vec![], "a stopped stream stays quiet");
    rig.finish();
}

/// Compass: binary, BCD and raw polls of the same measurement agree and face north; the
/// continuous mode pushes every 0.4 s until a reset.
async fn compass(runner: Runner) {
    let mut rig = Rig::start(runner, "dev-compass");
    let poll = |output| Message::CompassMode {
        mode: CompassMode::Poll,
        output,
    };
    rig.ack("compass binary", poll(CompassOutput::Binary)).await;
    let Message::CompassHeading { word } = rig.compass_read().await else {
        panic!("binary poll")
    };
    let binary_deg = word
        .decode(HeadingFormat::Binary)
        .expect("a binary heading word");
    assert!(
        angle_between_deg(f64::from(binary_deg), 0.0) < 20.0,
        "the vehicle faces north: {binary_deg} deg"
    );
    rig.ack("compass bcd", poll(CompassOutput::Bcd)).await;
    let Message::CompassHeading { word } = rig.compass_read().await else {
        panic!("bcd poll")
    };
    assert_eq!(
        word.decode(HeadingFormat::Bcd).expect("a BCD word"),
        binary_deg
    );
    rig.ack("compass raw", poll(CompassOutput::Raw)).await;
    let Message::CompassRaw { x, y } = rig.compass_read().await else {
        panic!("raw poll")
    };
    assert!(x != 0 || y != 0, "a magnetometer sees a field");
    let raw_deg = (-f64::from(y)).atan2(f64::from(x)).to_degrees();
    assert!(
        angle_between_deg(raw_deg, f64::from(binary_deg)) < 15.0,
        "raw X/Y ({x}, {y}) give {raw_deg:.1} deg, the word {binary_deg}"
    );
    let continuous = Message::CompassMode {
        mode: CompassMode::Continuous,
        output: CompassOutput::Binary,
    };
    rig.ack("compass continuous", continuous).await;
    rig.advance(100).await;
    let heading_pushes = rig.pushes().await;
    assert!(
        (2..=3).contains(&heading_pushes.len())
            && heading_pushes
                .iter()
                .all(|m| matches!(m, Message::CompassHeadingPush { .. })),
        "one push per 0.4 s over 1 s: {heading_pushes:?}"
    );
    rig.ack("compass reset", Message::CompassReset).await;
    rig.advance(100).await;
    assert_eq!(rig.pushes().await, vec![], "reset stops the pushes");
    rig.finish();
}

/// The compass calibration state machine (PROTOCOL.md 2.6 table).
async fn compass_calibration(runner: Runner) {
    use CalibrationAction::*;
    use CalibrationState::*;
    let mut rig = Rig::start(runner, "dev-calibration");
    let bad_state = |r: Result<(CalibrationState, u8), ProbeError>| {
        matches!(
            r,
            Err(ProbeError::Refused {
                code: ErrorCode::BadState,
                ..
            })
        )
    };
    assert_eq!(rig.calibrate(Start).await.unwrap(), (Collecting, 0));
    assert!(
        bad_state(rig.calibrate(Finish).await),
        "finish before 2 points"
    );
    assert_eq!(rig.calibrate(TakePoint).await.unwrap(), (Collecting, 1));
    assert_eq!(rig.calibrate(TakePoint).await.unwrap(), (ReadyToFinish, 2));
    assert_eq!(rig.calibrate(Finish).await.unwrap(), (Idle, 2));
    assert!(
        bad_state(rig.calibrate(TakePoint).await),
        "a point when idle"
    );
    assert_eq!(rig.calibrate(Clear).await.unwrap(), (Idle, 0));
    rig.finish();
}

/// Sonar: the master forwards its power-up transducer's sentences from the start; after a
/// select of the port-fore transducer it acks and its sentences range the wall.
async fn sonar_select(runner: Runner) {
    let mut rig = Rig::start(runner, "dev-sonar");
    rig.advance(200).await;
    let earlier = rig.sonar_items().await;
    assert!(
        !earlier.is_empty()
            && earlier
                .iter()
                .all(|i| matches!(i, SonarItem::Sentence { .. })),
        "2 s near a wall: sentences before the select, {earlier:?}"
    );
    rig.select(1).await;
    rig.advance(300).await;
    let first = rig.sonar.next(Duration::from_secs(5)).await.unwrap();
    assert_eq!(first, Some(SonarItem::Ack(1)));
    let ranges: Vec<f64> = rig
        .sonar_items()
        .await
        .into_iter()
        .map(|item| match item {
            SonarItem::Sentence {
                sentence: Sentence::Dbt(dbt),
                ..
            } => dbt.metres.expect("a valid echo has metres").as_f64(),
            other => panic!("unexpected sonar item {other:?}"),
        })
        .collect();
    assert!(!ranges.is_empty(), "3 s after a select, sentences follow");
    for r in &ranges {
        assert!(
            (r - EXPECTED_WALL_RANGE_M).abs() < 0.3,
            "wall at {EXPECTED_WALL_RANGE_M} m, sonar says {r} m"
        );
    }
    rig.finish();
}

/// A select with a bad digit is refused with `@N`; a second handle on the line (a person
/// typing into a terminal) sends it.
async fn sonar_bad_select(runner: Runner) {
    let mut rig = Rig::start(runner, "dev-sonar-nak");
    let mut raw = std::fs::OpenOptions::new()
        .write(true)
        .open(rig.link("sonar"))
        .expect("open the sonar link");
    let status = rig.status();
    let before = link_status(&status, "sonar").frames_rx + link_status(&status, "sonar").errors;
    std::io::Write::write_all(&mut raw, b"@S5\r").expect("write a bad select");
    rig.wait_status("the bad select reached the bridge", |s| {
        link_status(s, "sonar").frames_rx + link_status(s, "sonar").errors > before
    });
    rig.advance(10).await;
    let items = rig.sonar_items().await;
    assert!(
        items.contains(&SonarItem::Nak) && !items.iter().any(|i| matches!(i, SonarItem::Ack(_))),
        "@S5 is refused with @N and selects nothing: {items:?}"
    );
    rig.finish();
}

/// Thrusters: full ahead for 5 s moves the vehicle north; then all off.
async fn thrusters(runner: Runner) {
    let mut rig = Rig::start(runner, "dev-thrusters");
    let start = rig.status().pose;
    let ahead = Message::ThrusterSetAll {
        commands: [
            FULL_FORWARD,
            FULL_FORWARD,
            ThrusterCommand::OFF,
            ThrusterCommand::OFF,
        ],
    };
    rig.ack("thrusters", ahead).await;
    rig.advance(500).await;
    let moved = rig
        .wait_status("5 s of simulated time", |s| s.sim_time_s >= 4.99)
        .pose;
    assert!(
        moved.x_m - start.x_m > 0.5,
        "5 s at full thrust: from x {:.2} to {:.2} m",
        start.x_m,
        moved.x_m
    );
    assert!(moved.surge_mps > 0.2, "surge {:.3} m/s", moved.surge_mps);
    let off = Message::ThrusterSetAll {
        commands: [ThrusterCommand::OFF; 4],
    };
    rig.ack("thrusters off", off).await;
    rig.finish();
}

/// One `#[tokio::test]` per device and runner.
macro_rules! on_both_runners {
    ($($device:ident),* $(,)?) => {
        mod binary {
            $(
                #[tokio::test]
                async fn $device() {
                    super::$device(super::Runner::Binary).await
                }
            )*
        }
        mod in_process {
            $(
                #[tokio::test]
                async fn $device() {
                    super::$device(super::Runner::InProcess).await
                }
            )*
        }
    };
}

on_both_runners!(
    hello_and_time,
    adc,
    compass,
    compass_calibration,
    sonar_select,
    sonar_bad_select,
    thrusters,
);
