//! Foxglove: a WebSocket client of `run --foxglove` sees the channels advertised and pose
//! messages that follow `status`; `export --mcap` writes a recording that the `mcap` crate
//! reads back with every channel, in time order, with the recording's message counts.

use std::collections::BTreeMap;
use std::time::Duration;

use eyebot_hil::view::foxglove::TOPICS;
use eyebot_test_support::clients::LockstepDriver;
use eyebot_test_support::foxglove::FoxgloveClient;
use eyebot_test_support::{Daemon, Recording, RunningDaemon};
use firmware_protocol::LineDecoder;
use firmware_protocol::sensor_link::Message;
use foxglove::Decode as _;
use foxglove::messages::{FrameTransform, Log};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");
const WAIT: Duration = Duration::from_secs(20);

/// Heading (deg, 0-360) of a NED attitude quaternion.
fn heading_deg(q: &foxglove::messages::Quaternion) -> f64 {
    let yaw = (2.0 * (q.w * q.z + q.x * q.y)).atan2(1.0 - 2.0 * (q.y * q.y + q.z * q.z));
    yaw.to_degrees().rem_euclid(360.0)
}

/// A lockstep daemon with `--foxglove`: a client sees every channel advertised with
/// Foxglove's schemas; the `/tf` pose at each `status` time is `status`'s pose; the link
/// messages arrive as `foxglove.Log` lines.
#[test]
fn a_foxglove_client_sees_the_channels_and_the_pose_follows_status() {
    let daemon = Daemon::options(BIN, "foxglove-live")
        .lockstep()
        .args(&["--foxglove", "127.0.0.1:0"])
        .start();
    let url = daemon
        .foxglove_url
        .clone()
        .expect("run --foxglove prints `foxglove: URL`");
    assert!(url.starts_with("ws://127.0.0.1:"), "{url}");
    let mut client = FoxgloveClient::connect(&url, TOPICS.len(), WAIT);
    let schema = |topic: &str| {
        let c = &client.channels[topic];
        (c.encoding.clone(), c.schema_name.clone())
    };
    let protobuf = |name: &str| ("protobuf".to_string(), name.to_string());
    assert_eq!(schema("/scene"), protobuf("foxglove.SceneUpdate"));
    assert_eq!(schema("/sonar"), protobuf("foxglove.SceneUpdate"));
    assert_eq!(schema("/tf"), protobuf("foxglove.FrameTransform"));
    assert_eq!(schema("/tf_static"), protobuf("foxglove.FrameTransform"));
    assert_eq!(schema("/links"), protobuf("foxglove.Log"));
    assert_eq!(schema("/sensors").0, "json");
    assert_eq!(schema("/thrusters").0, "json");
    client.subscribe(&["/tf", "/links"]);

    let mut drive = LockstepDriver::new(&daemon, "foxglove test");
    let _sonar = drive.busy(&daemon);
    let mut kinds = BTreeMap::new();
    for step in 0..4 {
        drive.advance(40);
        let status = daemon.wait_status(WAIT, "time to reach the advance", |s| {
            (s.sim_time_s - drive.ticks as f64 * 0.01).abs() < 1e-6
        });
        let want_ns = (status.sim_time_s * 1e9).round() as u64;
        let pose = loop {
            let m = client
                .next(WAIT)
                .unwrap_or_else(|| panic!("no /tf at {} s (step {step})", status.sim_time_s));
            match m.topic.as_str() {
                "/tf" if m.log_time_ns == want_ns => {
                    break FrameTransform::decode(m.payload.as_slice()).expect("a FrameTransform");
                }
                "/tf" => assert!(m.log_time_ns < want_ns, "a pose from the future"),
                _ => {
                    let log = Log::decode(m.payload.as_slice()).expect("a Log");
                    *kinds.entry(log.name).or_insert(0) += 1;
                }
            }
        };
        assert_eq!(
            (pose.parent_frame_id.as_str(), pose.child_frame_id.as_str()),
            ("pool", "vehicle")
        );
        let t = pose.translation.expect("translation");
        let p = &status.pose;
        assert!(
            (t.x - p.x_m).abs() < 1e-9
                && (t.y - p.y_m).abs() < 1e-9
                && (t.z - p.depth_m).abs() < 1e-9,
            "step {step}: /tf {t:?}, status {p:?}"
        );
        let h = heading_deg(&pose.rotation.expect("rotation"));
        let dh = (h - p.heading_deg + 540.0).rem_euclid(360.0) - 180.0;
        assert!(
            dh.abs() < 1e-6,
            "step {step}: /tf heading {h}, status {}",
            p.heading_deg
        );
    }
    for kind in [
        "sensor rx TimeAdvance",
        "sensor tx Time",
        "sensor tx AdcSamples",
    ] {
        assert!(
            kinds.get(kind).is_some_and(|n| *n > 0),
            "no `{kind}` in {kinds:?}"
        );
    }
}

/// How many messages the recording's bytes decode to, each link and direction decoded whole
/// by the protocol crate.
fn decoded_messages(record: &std::path::Path) -> usize {
    let recording = Recording::read(record);
    let mut n = 0;
    for link in ["sensor", "sonar"] {
        for dir in [
            eyebot_hil::record::Direction::Rx,
            eyebot_hil::record::Direction::Tx,
        ] {
            let mut buf = bytes::BytesMut::from(recording.stream(link, dir).as_slice());
            let mut decoder = LineDecoder::default();
            while decoder.decode(&mut buf).is_some() {
                n += 1;
            }
        }
    }
    n
}

/// A short lockstep run with every kind of traffic, recorded, exported: the MCAP file holds
/// every channel with its schema, the messages in time order, one `/tf`, `/sonar`,
/// `/sensors` and `/thrusters` per state row, one `/links` line per decoded message, and one
/// `/scene` per simulated second.
#[test]
fn an_exported_recording_holds_every_channel_in_time_order() {
    let mut daemon = Daemon::options(BIN, "foxglove-export")
        .lockstep()
        .record()
        .start();
    let mut drive = LockstepDriver::new(&daemon, "foxglove test");
    let sonar = drive.busy(&daemon);
    for _ in 0..5 {
        drive.advance(50);
        drive.ask(Message::CompassRead);
    }
    drop(sonar);
    drop(drive);
    daemon.stop();
    let record = daemon.record_dir().to_path_buf();
    let out = daemon.dir.join("run.mcap");
    daemon.cli(&[
        "export".as_ref(),
        record.as_os_str(),
        "--mcap".as_ref(),
        out.as_os_str(),
    ]);

    let bytes = std::fs::read(&out).expect("the MCAP file");
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    let mut schemas = BTreeMap::new();
    let mut last = 0u64;
    for message in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let message = message.expect("a readable message");
        assert!(
            message.log_time >= last,
            "{} at {} ns after {last} ns",
            message.channel.topic,
            message.log_time
        );
        last = message.log_time;
        *counts.entry(message.channel.topic.clone()).or_default() += 1;
        schemas.insert(
            message.channel.topic.clone(),
            message.channel.schema.as_ref().map(|s| s.name.clone()),
        );
    }
    let states = eyebot_test_support::recording::read_states(&record);
    assert!(states.len() > 50, "{} state rows", states.len());
    for topic in TOPICS {
        assert!(counts.contains_key(topic), "{topic} missing: {counts:?}");
    }
    for topic in ["/tf", "/sonar", "/sensors", "/thrusters"] {
        assert_eq!(counts[topic], states.len(), "{topic}");
    }
    let messages = decoded_messages(&record);
    assert!(messages > 20, "{messages} decoded messages");
    assert_eq!(
        counts["/links"], messages,
        "one log line per decoded message"
    );
    let seconds: std::collections::BTreeSet<i64> =
        states.iter().map(|r| r.t_s.floor() as i64).collect();
    assert_eq!(counts["/scene"], seconds.len());
    assert_eq!(counts["/tf_static"], seconds.len());
    assert_eq!(schemas["/tf"].as_deref(), Some("foxglove.FrameTransform"));
    assert_eq!(schemas["/links"].as_deref(), Some("foxglove.Log"));
    assert_eq!(schemas["/scene"].as_deref(), Some("foxglove.SceneUpdate"));
    assert_eq!(schemas["/sensors"].as_deref(), Some("eyebot.Sensors"));
    let last_state_ns = (states.last().expect("rows").t_s * 1e9).round() as u64;
    assert!(
        last >= last_state_ns,
        "the last message is the last state row or later"
    );
}
