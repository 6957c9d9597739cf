//! Determinism of the running daemon: lockstep transcripts are byte-identical whatever the
//! speed factor, the client's pace and whether it runs as a binary or in-process; realtime
//! physics does not depend on the speed factor.

use std::path::{Path, PathBuf};
use std::time::Duration;

use eyebot_hil::daemon::status::StatusSnapshot;
use eyebot_hil::probe::SensorClient;
use firmware_protocol::Transducer;
use firmware_protocol::sensor_link::{
    AdcChannel, CompassMode, CompassOutput, Direction, Message, ThrusterCommand,
};
use nix::sys::signal::Signal;
use pty_tests::daemon::{
    DaemonProcess, InProcessDaemon, TestDir, config_text, link_status, poll_until, read_chunks,
    sensor_client, sonar_client, status_at, transcript,
};

const NEAR_WALL: (&str, &str) = (
    "position_m = [3.0, 6.25, 0.3]",
    "position_m = [3.0, 1.5, 0.5]",
);

type Transcript = Vec<(String, String, &'static str, String)>;

/// A scripted EyeBot: streams, compass pushes, two sonar selects, thrusters, polls. `pace` is
/// slept before every request (a slow client).
async fn script(
    sensor_path: &Path,
    sonar_path: &Path,
    status: &dyn Fn() -> StatusSnapshot,
    pace: Duration,
) {
    let mut sensor = sensor_client(sensor_path);
    let mut sonar = sonar_client(sonar_path);
    async fn req(sensor: &mut SensorClient, pace: Duration, m: Message) -> Message {
        tokio::time::sleep(pace).await;
        sensor.request("script", m, Duration::ZERO).await.unwrap()
    }
    let adc = |c| Message::AdcRead {
        channel: AdcChannel::new(c).unwrap(),
    };
    req(&mut sensor, pace, Message::Hello { client_version: 1 }).await;
    req(
        &mut sensor,
        pace,
        Message::AdcStream {
            channels: 0b0001_0011,
            period_ms: 20,
        },
    )
    .await;
    req(&mut sensor, pace, Message::TimeAdvance { ticks: 50 }).await;
    req(
        &mut sensor,
        pace,
        Message::CompassMode {
            mode: CompassMode::Continuous,
            output: CompassOutput::Bcd,
        },
    )
    .await;
    for transducer in [1, 2] {
        let before = link_status(&status(), "sonar").frames_rx;
        tokio::time::sleep(pace).await;
        sonar
            .select(Transducer::new(transducer).unwrap())
            .await
            .unwrap();
        // The sonar line is a different pty: wait until the bridge has the select, so it
        // lands at the same simulated time in every run.
        poll_until(
            Duration::from_secs(10),
            "the select reached the bridge",
            || (link_status(&status(), "sonar").frames_rx > before).then_some(()),
        );
        req(&mut sensor, pace, Message::TimeAdvance { ticks: 150 }).await;
        for c in 0..4 {
            req(&mut sensor, pace, adc(c)).await;
        }
        req(
            &mut sensor,
            pace,
            Message::ThrusterSetAll {
                commands: [
                    ThrusterCommand {
                        duty: 0x40,
                        direction: Direction::Forward,
                    },
                    ThrusterCommand {
                        duty: 0x80,
                        direction: Direction::Reverse,
                    },
                    ThrusterCommand::OFF,
                    ThrusterCommand::OFF,
                ],
            },
        )
        .await;
        req(&mut sensor, pace, Message::TimeAdvance { ticks: 150 }).await;
        req(&mut sensor, pace, Message::CompassRead).await;
    }
    req(
        &mut sensor,
        pace,
        Message::AdcStream {
            channels: 0,
            period_ms: 0,
        },
    )
    .await;
    req(&mut sensor, pace, Message::TimeAdvance { ticks: 20 }).await;
    // Keep the sonar port open to the end, like a real EyeBot.
    drop(sonar);
}

fn binary_run(tag: &str, seed: &str, speed: &str, pace: Duration) -> Transcript {
    let dir = TestDir::new(tag);
    let config = dir.write_config("near-wall.toml", &[NEAR_WALL]);
    let record = dir.join("rec");
    let mut daemon = DaemonProcess::start(
        dir,
        &[
            "--config",
            config.to_str().unwrap(),
            "--time-mode",
            "lockstep",
            "--seed",
            seed,
            "--speed",
            speed,
            "--record",
            record.to_str().unwrap(),
        ],
    );
    let socket = daemon.status_socket();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(script(
        &daemon.link("sensor"),
        &daemon.link("sonar"),
        &|| status_at(&socket),
        pace,
    ));
    daemon.signal(Signal::SIGTERM);
    let exit = daemon.wait(Duration::from_secs(5)).expect("daemon exits");
    assert!(exit.success(), "{exit:?}");
    transcript(&read_chunks(&record))
}

fn in_process_run(tag: &str, seed: u64) -> Transcript {
    let dir = TestDir::new(tag);
    let record: PathBuf = dir.join("rec");
    let text = config_text(&[
        NEAR_WALL,
        ("time_mode = \"realtime\"", "time_mode = \"lockstep\""),
        ("speed = 1.0", "speed = 0.5"),
    ]);
    let mut daemon = InProcessDaemon::start(dir, &text, Some(record.clone()), |c| c.seed = seed);
    let socket = daemon.status_socket.clone();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(script(
        &daemon.link("sensor"),
        &daemon.link("sonar"),
        &|| status_at(&socket),
        Duration::ZERO,
    ));
    let records = daemon.stop().records.expect("recording");
    assert!(records.chunks > 0);
    let chunks = read_chunks(&record);
    transcript(&chunks)
}

fn first_difference(a: &Transcript, b: &Transcript) -> String {
    match a.iter().zip(b).position(|(x, y)| x != y) {
        Some(i) => format!("line {i}: {:?} vs {:?}", a[i], b[i]),
        None => format!("lengths {} vs {}", a.len(), b.len()),
    }
}

/// Same seed, same scripted client: the same bytes at the same simulated times, whether
/// the client is fast or slow, the speed factor 1 or 10, the binary or in-process.
#[test]
fn lockstep_transcripts_are_identical_across_speeds_pace_and_runners() {
    let fast = binary_run("tr-fast", "7", "1", Duration::ZERO);
    // Non-trivial: both links carried traffic both ways, with sentences and pushes.
    for (link, dir) in [
        ("sonar", "rx"),
        ("sonar", "tx"),
        ("sensor", "rx"),
        ("sensor", "tx"),
    ] {
        assert!(
            fast.iter().any(|c| c.1 == link && c.2 == dir),
            "no {link} {dir} chunk in {fast:#?}"
        );
    }
    let sonar_tx: String = fast
        .iter()
        .filter(|c| c.1 == "sonar" && c.2 == "tx")
        .map(|c| c.3.clone())
        .collect();
    let sonar_tx = hex::decode(sonar_tx).unwrap();
    assert!(
        String::from_utf8_lossy(&sonar_tx).matches("DBT").count() >= 2,
        "depth sentences were sent: {}",
        String::from_utf8_lossy(&sonar_tx)
    );

    let slow = binary_run("tr-slow", "7", "10", Duration::from_millis(15));
    assert!(
        fast == slow,
        "speed 10 + slow client differ: {}",
        first_difference(&fast, &slow)
    );
    let in_process = in_process_run("tr-inproc", 7);
    assert!(
        fast == in_process,
        "in-process run differs: {}",
        first_difference(&fast, &in_process)
    );
    // The comparison can fail: another seed changes the sensor noise, so the bytes.
    let other_seed = binary_run("tr-seed", "8", "1", Duration::ZERO);
    assert!(
        fast != other_seed,
        "seed 8 gave the same transcript as seed 7"
    );
}

fn realtime_states(tag: &str, speed: &str, until_sim_s: f64) -> Vec<String> {
    let dir = TestDir::new(tag);
    let record = dir.join("rec");
    let mut daemon = DaemonProcess::start(
        dir,
        &[
            "--time-mode",
            "realtime",
            "--speed",
            speed,
            "--seed",
            "3",
            "--record",
            record.to_str().unwrap(),
        ],
    );
    daemon.wait_status(Duration::from_secs(15), "enough simulated time", |s| {
        s.sim_time_s >= until_sim_s
    });
    daemon.signal(Signal::SIGTERM);
    assert!(daemon.wait(Duration::from_secs(5)).expect("exit").success());
    let text = std::fs::read_to_string(record.join("state.csv")).unwrap();
    text.lines().skip(1).map(str::to_string).collect()
}

/// Realtime at speed 1 and 10, no client: every ground-truth row at the same simulated time
/// is identical, bit for bit (rows print full precision), over the overlapping span.
#[test]
fn realtime_speed_1_and_10_give_the_same_physics() {
    let slow = realtime_states("rt-1", "1", 2.0);
    let fast = realtime_states("rt-10", "10", 4.0);
    let time = |row: &String| row.split(',').next().unwrap().to_string();
    let fast_by_time: std::collections::HashMap<String, &String> =
        fast.iter().map(|r| (time(r), r)).collect();
    let mut compared = 0;
    for row in &slow {
        if let Some(other) = fast_by_time.get(&time(row)) {
            assert_eq!(row, *other, "state at t = {} s differs", time(row));
            compared += 1;
        }
    }
    assert!(
        compared >= 75,
        "only {compared} common rows (speed 1: {}, speed 10: {})",
        slow.len(),
        fast.len()
    );
    // Not vacuous: the vehicle moves (it is buoyant and starts below the surface).
    let last_common = slow
        .iter()
        .rev()
        .find(|r| fast_by_time.contains_key(&time(r)))
        .unwrap();
    let columns = |r: &str| r.split(',').skip(1).map(str::to_string).collect::<Vec<_>>();
    assert_ne!(
        columns(&slow[0]),
        columns(last_common),
        "the state never changed"
    );
}
