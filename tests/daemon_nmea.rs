//! A parser this project did not write (the `nmea` crate) accepts every sentence the sonar
//! link sends, in both sentence settings and with both invalid-echo policies.

use std::time::Duration;

use eyebot_hil::probe::SonarItem;
use eyebot_test_support::clients::{sensor_client, sonar_client};
use eyebot_test_support::config::NEAR_WALL;
use eyebot_test_support::daemon::link_status;
use eyebot_test_support::{Daemon, RunningDaemon, wait_for};
use firmware_protocol::Transducer;
use firmware_protocol::sensor_link::Message;

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

/// Selects each transducer in turn and returns the raw sentences (without CR LF).
async fn collect_sentences(daemon: &Daemon) -> Vec<String> {
    let mut sensor = sensor_client(&daemon.link("sensor"));
    let mut sonar = sonar_client(&daemon.link("sonar"));
    let mut raw = Vec::new();
    for t in [1, 2, 3, 4, 1] {
        let before = link_status(&daemon.status(), "sonar").frames_rx;
        sonar.select(Transducer::new(t).unwrap()).await.unwrap();
        wait_for("select received", Duration::from_secs(10), || {
            (link_status(&daemon.status(), "sonar").frames_rx > before).then_some(())
        });
        sensor
            .request(
                "advance",
                Message::TimeAdvance { ticks: 400 },
                Duration::ZERO,
            )
            .await
            .unwrap();
        while let Some(item) = sonar.next(Duration::from_millis(300)).await.unwrap() {
            match item {
                SonarItem::Sentence { raw: text, .. } => raw.push(text),
                SonarItem::Ack(a) => assert_eq!(a, t),
                other => panic!("unexpected {other:?}"),
            }
        }
    }
    raw
}

fn start(tag: &str, edits: &[(&str, &str)]) -> Daemon {
    let mut all = vec![NEAR_WALL];
    all.extend_from_slice(edits);
    Daemon::options(BIN, tag).config(&all).lockstep().start()
}

/// DBT (the default): the `nmea` crate checks framing and checksum and names the sentence
/// type (it has no DBT field decoder, so it reports DBT as `Unsupported(DBT)` *after*
/// verifying the checksum; a bad checksum would be `Err(ChecksumMismatch)`).
#[tokio::test]
async fn dbt_sentences_are_valid_nmea_to_the_nmea_crate() {
    let daemon = start("nmea-dbt", &[]);
    let sentences = collect_sentences(&daemon).await;
    assert!(sentences.len() >= 4, "{sentences:?}");
    for s in &sentences {
        match nmea::parse_str(s) {
            Ok(nmea::ParseResult::Unsupported(nmea::SentenceType::DBT)) => {}
            other => panic!("nmea rejected {s:?}: {other:?}"),
        }
        let parsed = nmea::parse_nmea_sentence(s).expect("nmea frames it");
        assert_eq!(parsed.talker_id, "SD");
        assert_eq!(parsed.checksum, parsed.calc_checksum());
        let fields: Vec<&str> = parsed.data.split(',').collect();
        assert_eq!(fields.len(), 6, "{s}");
        assert_eq!((fields[1], fields[3], fields[5]), ("f", "M", "F"), "{s}");
        let metres: f64 = fields[2].parse().expect("metres");
        assert!((0.3..=5.0).contains(&metres), "{s}");
    }
}

/// DPT (with a transducer offset): fully decoded by the `nmea` crate.
#[tokio::test]
async fn dpt_sentences_decode_with_the_nmea_crate() {
    let daemon = start(
        "nmea-dpt",
        &[
            ("sentence = \"DBT\"", "sentence = \"DPT\""),
            ("dpt_offset_m = 0.0", "dpt_offset_m = 0.3"),
        ],
    );
    let sentences = collect_sentences(&daemon).await;
    assert!(sentences.len() >= 4, "{sentences:?}");
    for s in &sentences {
        match nmea::parse_str(s) {
            Ok(nmea::ParseResult::DPT(dpt)) => {
                let depth = dpt.water_depth.expect("omit policy: only valid echoes");
                assert!((0.3..=5.0).contains(&depth), "{s}");
                assert_eq!(dpt.offset, Some(0.3), "{s}");
            }
            other => panic!("nmea rejected {s:?}: {other:?}"),
        }
    }
}

/// `invalid_echo = "empty"` sends a sentence with empty fields for each ping without a valid
/// echo (the bow transducers here see no wall), and the `nmea` crate accepts it as a DPT
/// with no depth. Regression: the sonar model reported only valid ranges, so the setting
/// had no effect and nothing was sent.
#[tokio::test]
async fn invalid_echoes_give_empty_sentences_that_the_nmea_crate_accepts() {
    let daemon = start(
        "nmea-empty",
        &[
            ("sentence = \"DBT\"", "sentence = \"DPT\""),
            ("invalid_echo = \"omit\"", "invalid_echo = \"empty\""),
        ],
    );
    let sentences = collect_sentences(&daemon).await;
    let (mut empty, mut ranged) = (0, 0);
    for s in &sentences {
        match nmea::parse_str(s) {
            Ok(nmea::ParseResult::DPT(d)) if d.water_depth.is_none() => empty += 1,
            Ok(nmea::ParseResult::DPT(_)) => ranged += 1,
            other => panic!("nmea rejected {s:?}: {other:?}"),
        }
    }
    assert!(empty >= 1, "the bow transducers see no wall: {sentences:?}");
    assert!(
        ranged >= 1,
        "the port transducers see the wall: {sentences:?}"
    );
}
