//! Every device the bridge emulates, exercised over its ptys: against the built binary and
//! against `eyebot_hil::daemon::run` in-process, with the same script.

use std::path::Path;
use std::time::Duration;

use eyebot_hil::daemon::status::StatusSnapshot;
use eyebot_hil::probe::{ProbeError, SensorClient, SonarItem};
use firmware_protocol::sensor_link::{
    AdcChannel, CalibrationAction, CalibrationState, CompassMode, CompassOutput, Direction,
    ErrorCode, Message, ThrusterCommand, TimeMode,
};
use firmware_protocol::{HeadingFormat, Sentence, Transducer};
use pty_tests::daemon::{
    DaemonProcess, InProcessDaemon, TestDir, config_text, link_status, sensor_client, sonar_client,
    status_at,
};

/// Vehicle start for these tests: 1.5 m off the west wall, heading north, so the port-side
/// transducers (1 and 2, pointing 75 and 105 deg to port) see the wall at about
/// (1.5 - 0.32) / sin 75 deg = 1.22 m.
pub const NEAR_WALL: (&str, &str) = (
    "position_m = [3.0, 6.25, 0.3]",
    "position_m = [3.0, 1.5, 0.5]",
);
const EXPECTED_WALL_RANGE_M: f64 = 1.22;

const FULL_FORWARD: ThrusterCommand = ThrusterCommand {
    duty: 0x00,
    direction: Direction::Forward,
};

async fn advance(sensor: &mut SensorClient, ticks: u32) -> u32 {
    match sensor
        .request("advance", Message::TimeAdvance { ticks }, Duration::ZERO)
        .await
        .unwrap()
    {
        Message::Time { ticks, tick_us } => {
            assert_eq!(tick_us, 10_000, "1/100 s ticks");
            ticks
        }
        other => panic!("TIME_ADVANCE answered with {other:?}"),
    }
}

async fn ack(sensor: &mut SensorClient, what: &'static str, message: Message) {
    let kind = message.msg_type();
    match sensor.request(what, message, Duration::ZERO).await.unwrap() {
        Message::Ack { acked_type } => assert_eq!(acked_type, kind),
        other => panic!("{what}: expected ACK, got {other:?}"),
    }
}

async fn pushes(sensor: &mut SensorClient) -> Vec<Message> {
    let mut out = Vec::new();
    // Pushes due before the last TIME reply were sent before it, so they are already here.
    while let Some(frame) = sensor.next_push(Duration::from_millis(50)).await.unwrap() {
        out.push(frame.message);
    }
    out
}

async fn compass_read(sensor: &mut SensorClient) -> Message {
    sensor
        .request("compass read", Message::CompassRead, Duration::ZERO)
        .await
        .unwrap()
}

async fn calibrate(
    sensor: &mut SensorClient,
    action: CalibrationAction,
) -> Result<(CalibrationState, u8), ProbeError> {
    match sensor
        .request(
            "calibrate",
            Message::CompassCalibrate { action },
            Duration::ZERO,
        )
        .await?
    {
        Message::CalibrationStatus { state, points } => Ok((state, points)),
        other => panic!("COMPASS_CALIBRATE answered with {other:?}"),
    }
}

fn angle_between_deg(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

/// The whole device script. `status` fetches a snapshot from the daemon under test.
async fn exercise_every_device(
    sensor_path: &Path,
    sonar_path: &Path,
    status: &dyn Fn() -> StatusSnapshot,
) {
    let mut sensor = sensor_client(sensor_path);
    let mut sonar = sonar_client(sonar_path);

    // HELLO and the time service.
    match sensor
        .request(
            "hello",
            Message::Hello { client_version: 1 },
            Duration::ZERO,
        )
        .await
        .unwrap()
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
    ack(
        &mut sensor,
        "time mode",
        Message::TimeMode {
            mode: TimeMode::Lockstep,
        },
    )
    .await;
    let refused = sensor
        .request(
            "time mode",
            Message::TimeMode {
                mode: TimeMode::RealTime,
            },
            Duration::ZERO,
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
    let Message::Time { ticks: 0, .. } = sensor
        .request("time", Message::TimeGet, Duration::ZERO)
        .await
        .unwrap()
    else {
        panic!("a fresh lockstep bridge is at tick 0");
    };

    // ADC: every channel polled, then a stream of two channels.
    for channel in 0..8 {
        let reply = sensor
            .request(
                "adc",
                Message::AdcRead {
                    channel: AdcChannel::new(channel).unwrap(),
                },
                Duration::ZERO,
            )
            .await
            .unwrap();
        let Message::AdcValue { channel: c, value } = reply else {
            panic!("ADC_READ answered with {reply:?}");
        };
        assert_eq!(c.get(), channel);
        assert!(value.get() < 1024);
    }
    ack(
        &mut sensor,
        "adc stream",
        Message::AdcStream {
            channels: 0b0000_0101,
            period_ms: 10,
        },
    )
    .await;
    assert_eq!(advance(&mut sensor, 10).await, 10);
    let samples = pushes(&mut sensor).await;
    let ticks: Vec<u32> = samples
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
    ack(
        &mut sensor,
        "adc stream stop",
        Message::AdcStream {
            channels: 0,
            period_ms: 0,
        },
    )
    .await;
    assert_eq!(advance(&mut sensor, 10).await, 20);
    assert_eq!(
        pushes(&mut sensor).await,
        vec![],
        "a stopped stream stays quiet"
    );

    // Compass: binary, BCD and raw polls of the same measurement, then continuous mode.
    let heading = |output| Message::CompassMode {
        mode: CompassMode::Poll,
        output,
    };
    ack(
        &mut sensor,
        "compass binary",
        heading(CompassOutput::Binary),
    )
    .await;
    let Message::CompassHeading { word } = compass_read(&mut sensor).await else {
        panic!("binary poll")
    };
    let binary_deg = word
        .decode(HeadingFormat::Binary)
        .expect("a binary heading word");
    assert!(
        angle_between_deg(f64::from(binary_deg), 0.0) < 20.0,
        "the vehicle faces north: {binary_deg} deg"
    );
    ack(&mut sensor, "compass bcd", heading(CompassOutput::Bcd)).await;
    let Message::CompassHeading { word } = compass_read(&mut sensor).await else {
        panic!("bcd poll")
    };
    assert_eq!(
        word.decode(HeadingFormat::Bcd).expect("a BCD word"),
        binary_deg
    );
    ack(&mut sensor, "compass raw", heading(CompassOutput::Raw)).await;
    let Message::CompassRaw { x, y } = compass_read(&mut sensor).await else {
        panic!("raw poll")
    };
    assert!(x != 0 || y != 0, "a magnetometer sees a field");
    let raw_deg = (-f64::from(y)).atan2(f64::from(x)).to_degrees();
    assert!(
        angle_between_deg(raw_deg, f64::from(binary_deg)) < 15.0,
        "raw X/Y ({x}, {y}) give {raw_deg:.1} deg, the word {binary_deg}"
    );
    ack(
        &mut sensor,
        "compass continuous",
        Message::CompassMode {
            mode: CompassMode::Continuous,
            output: CompassOutput::Binary,
        },
    )
    .await;
    advance(&mut sensor, 100).await;
    let heading_pushes = pushes(&mut sensor).await;
    assert!(
        (2..=3).contains(&heading_pushes.len())
            && heading_pushes
                .iter()
                .all(|m| matches!(m, Message::CompassHeadingPush { .. })),
        "one push per 0.4 s over 1 s: {heading_pushes:?}"
    );
    ack(&mut sensor, "compass reset", Message::CompassReset).await;
    advance(&mut sensor, 100).await;
    assert_eq!(pushes(&mut sensor).await, vec![], "reset stops the pushes");

    // Calibration state machine (PROTOCOL.md 2.6 table).
    use CalibrationAction::*;
    use CalibrationState::*;
    assert_eq!(
        calibrate(&mut sensor, Start).await.unwrap(),
        (Collecting, 0)
    );
    assert!(matches!(
        calibrate(&mut sensor, Finish).await,
        Err(ProbeError::Refused {
            code: ErrorCode::BadState,
            ..
        })
    ));
    assert_eq!(
        calibrate(&mut sensor, TakePoint).await.unwrap(),
        (Collecting, 1)
    );
    assert_eq!(
        calibrate(&mut sensor, TakePoint).await.unwrap(),
        (ReadyToFinish, 2)
    );
    assert_eq!(calibrate(&mut sensor, Finish).await.unwrap(), (Idle, 2));
    assert!(matches!(
        calibrate(&mut sensor, TakePoint).await,
        Err(ProbeError::Refused {
            code: ErrorCode::BadState,
            ..
        })
    ));
    assert_eq!(calibrate(&mut sensor, Clear).await.unwrap(), (Idle, 0));

    // Sonar: the master forwards its power-up transducer's sentences from the start; take
    // those, then select the port-fore transducer and, once the bridge has it, advance time.
    let mut earlier = 0;
    while let Some(item) = sonar.next(Duration::from_millis(200)).await.unwrap() {
        assert!(matches!(item, SonarItem::Sentence { .. }), "{item:?}");
        earlier += 1;
    }
    assert!(
        earlier > 0,
        "20 s near a wall gave no sentence before the select"
    );
    let before = link_status(&status(), "sonar").frames_rx;
    sonar.select(Transducer::new(1).unwrap()).await.unwrap();
    wait_for(status, "the select reached the bridge", |s| {
        link_status(s, "sonar").frames_rx > before
    });
    advance(&mut sensor, 300).await;
    let first = sonar.next(Duration::from_secs(5)).await.unwrap();
    assert_eq!(first, Some(SonarItem::Ack(1)));
    let mut ranges = Vec::new();
    while let Some(item) = sonar.next(Duration::from_millis(200)).await.unwrap() {
        match item {
            SonarItem::Sentence {
                sentence: Sentence::Dbt(dbt),
                ..
            } => ranges.push(dbt.metres.expect("a valid echo has metres").as_f64()),
            other => panic!("unexpected sonar item {other:?}"),
        }
    }
    assert!(!ranges.is_empty(), "3 s after a select, sentences follow");
    for r in &ranges {
        assert!(
            (r - EXPECTED_WALL_RANGE_M).abs() < 0.3,
            "wall at {EXPECTED_WALL_RANGE_M} m, sonar says {r} m"
        );
    }
    // A bad digit is refused with @N, relays unchanged.
    // (A second handle on the line, as a person typing into a terminal would have.)
    let mut raw = std::fs::OpenOptions::new()
        .write(true)
        .open(sonar_path)
        .unwrap();
    std::io::Write::write_all(&mut raw, b"@S5\r").unwrap();
    let before = link_status(&status(), "sonar").frames_rx;
    wait_for(status, "the bad select reached the bridge", |s| {
        link_status(s, "sonar").frames_rx + link_status(s, "sonar").errors > before
    });
    advance(&mut sensor, 10).await;
    assert_eq!(
        sonar.next(Duration::from_secs(5)).await.unwrap(),
        Some(SonarItem::Nak)
    );

    // Thrusters: full ahead for 5 s moves the vehicle north; then all off.
    let start = status().pose;
    ack(
        &mut sensor,
        "thrusters",
        Message::ThrusterSetAll {
            commands: [
                FULL_FORWARD,
                FULL_FORWARD,
                ThrusterCommand::OFF,
                ThrusterCommand::OFF,
            ],
        },
    )
    .await;
    advance(&mut sensor, 500).await;
    let moved = wait_for(status, "the vehicle moved", |s| s.sim_time_s >= 10.29).pose;
    assert!(
        moved.x_m - start.x_m > 0.5,
        "5 s at full thrust: from x {:.2} to {:.2} m",
        start.x_m,
        moved.x_m
    );
    assert!(moved.surge_mps > 0.2, "surge {:.3} m/s", moved.surge_mps);
    ack(
        &mut sensor,
        "thrusters off",
        Message::ThrusterSetAll {
            commands: [ThrusterCommand::OFF; 4],
        },
    )
    .await;

    // 38 requests in all; the snapshot refreshes every 100 ms.
    let s = wait_for(status, "every request counted", |s| {
        link_status(s, "sensor").frames_rx >= 38
    });
    assert_eq!(s.time_mode, "lockstep");
    let sensor_link = link_status(&s, "sensor");
    assert_eq!(sensor_link.errors, 0, "{sensor_link:?}");
    assert_eq!(sensor_link.frames_rx, 38, "{sensor_link:?}");
    assert_eq!(sensor.errors, 0, "the bridge sent only well-formed frames");
}

fn wait_for(
    status: &dyn Fn() -> StatusSnapshot,
    what: &str,
    pred: impl Fn(&StatusSnapshot) -> bool,
) -> StatusSnapshot {
    pty_tests::daemon::poll_until(Duration::from_secs(10), what, || {
        let s = status();
        pred(&s).then_some(s)
    })
}

/// The built binary, in lockstep, with a config file written for the test.
#[tokio::test]
async fn every_device_answers_over_ptys_binary() {
    let dir = TestDir::new("devices-bin");
    let config = dir.write_config("near-wall.toml", &[NEAR_WALL]);
    let daemon = DaemonProcess::start(
        dir,
        &[
            "--config",
            config.to_str().unwrap(),
            "--time-mode",
            "lockstep",
        ],
    );
    assert_eq!(
        daemon
            .links
            .lines
            .iter()
            .map(|l| l.0.as_str())
            .collect::<Vec<_>>(),
        vec!["sonar", "sensor"]
    );
    exercise_every_device(&daemon.link("sensor"), &daemon.link("sonar"), &|| {
        daemon.status()
    })
    .await;
}

/// `eyebot_hil::daemon::run` in-process with the same script.
#[tokio::test]
async fn every_device_answers_over_ptys_in_process() {
    let dir = TestDir::new("devices-inproc");
    let text = config_text(&[
        NEAR_WALL,
        ("time_mode = \"realtime\"", "time_mode = \"lockstep\""),
    ]);
    let mut daemon = InProcessDaemon::start(dir, &text, None, |_| {});
    let socket = daemon.status_socket.clone();
    exercise_every_device(&daemon.link("sensor"), &daemon.link("sonar"), &|| {
        status_at(&socket)
    })
    .await;
    let summary = daemon.stop();
    assert!(summary.sim_time_s >= 10.29, "{summary:?}");
}
