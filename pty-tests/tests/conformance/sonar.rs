//! The sonar line of section 1.2 against a lockstep daemon: when the first own sentence comes
//! after a select, on average and within its window, and that the master forwards nothing
//! between a select and its acknowledgement.

use super::*;

/// The sonar line of a lockstep run, from its recording: seconds of simulated time.
struct SonarTimeline {
    /// When the select's last byte was received.
    select_s: Option<f64>,
    /// When each depth sentence's last byte was handed out: the end of the one-tick advance
    /// in which it came due, so a sentence recorded at `t` ended in `(t - 10 ms, t]`.
    sentences: Vec<f64>,
    /// The same for each acknowledgement.
    acks: Vec<f64>,
    /// Each sentence as decoded, with its time.
    nmea: Vec<(f64, String)>,
}

/// Runs a lockstep daemon with `config` and `seed` for `ticks` ticks, advancing one tick at a
/// time; `@S2` is sent after `select_after` ticks, if given.
fn sonar_timeline(config: &str, seed: u64, select_after: Option<u32>, ticks: u32) -> SonarTimeline {
    use eyebot_test_support::recording::{Direction, read_chunks};
    let dir = TempDir::new("conf-sonar-timeline");
    let record = dir.join("rec");
    let mut d = InProcessDaemon::start(dir, config, Some(record.clone()), |c| c.seed = seed);
    let mut s = Wire::open(&d.link("sensor"));
    let mut sonar = Wire::open(&d.link("sonar"));
    hello(&mut s, 0);
    for tick in 0..ticks {
        if select_after == Some(tick) {
            sonar.send(b"@S2\r");
            d.wait_status(WAIT, "the select read", |st| {
                link_status(st, "sonar").frames_rx > 0
            });
        }
        advance(&mut s, (tick % 200 + 1) as u8, 1);
        sonar.drain(Duration::ZERO);
    }
    drop((s, sonar));
    d.stop();
    let chunks = read_chunks(&record);
    let select_s = chunks
        .iter()
        .find(|c| c.link == "sonar" && c.dir == Direction::Rx)
        .map(|c| c.sim_s);
    assert_eq!(
        select_s.is_some(),
        select_after.is_some(),
        "the select in the recording"
    );
    // Each item with the time of the chunk holding its last byte.
    let mut decoder = firmware_protocol::LineDecoder::new();
    let mut buf = bytes::BytesMut::new();
    let mut timeline = SonarTimeline {
        select_s,
        sentences: Vec::new(),
        acks: Vec::new(),
        nmea: Vec::new(),
    };
    for chunk in chunks
        .iter()
        .filter(|c| c.link == "sonar" && c.dir == Direction::Tx)
    {
        buf.extend_from_slice(&chunk.data);
        while let Some(item) = decoder.decode(&mut buf) {
            match item {
                LineItem::Nmea(sentence) => {
                    timeline.sentences.push(chunk.sim_s);
                    timeline.nmea.push((chunk.sim_s, format!("{sentence:?}")));
                }
                LineItem::Sonar(SonarCommand::Ack(_)) => timeline.acks.push(chunk.sim_s),
                other => panic!("seed {seed}: on the sonar line: {other:?}"),
            }
        }
    }
    timeline
}

/// Section 1.2: the first sentence from a newly selected transducer's own ping has its last
/// byte 1.23 to 2.23 s after the select (relays settled, the next ping re-acquires, the ping
/// after it echoes, its sentence latency and wire time). A sentence recorded at `t` ended in
/// `(t - 10 ms, t]`, and that interval must meet the window.
///
/// The vehicle lies near the pool's west wall, heading 15 deg, so transducer 2 (port-aft, 105
/// deg to port) faces the wall square while transducer 1 (75 deg to port) meets it 30 deg off
/// its normal and the bow pair looks down the pool: only transducer 2 can echo, and every
/// sentence after the select is its own. Several seeds, so the controller's ping phase falls
/// at different points of the window; for each of them that ping echoes (a missed echo puts
/// the sentence a period later, as 1.2 says and the on-demand mean test below shows).
#[test]
fn the_first_own_sentence_after_a_select_comes_in_the_window_of_section_1_2() {
    use eyebot_test_support::config::{as_edits, start_at};
    let from_s = spec_number_after("own ping has its last byte ");
    let to_s = spec_number_after("own ping has its last byte 1.23 to ");
    assert_eq!((from_s, to_s), (1.23, 2.23));
    let start = start_at([3.0, 1.5, 0.5], 15.0);
    let mut edits = as_edits(&start);
    edits.push(LOCKSTEP);
    let text = config_text(&edits);
    for seed in [1u64, 2, 3, 4, 5] {
        let run = sonar_timeline(&text, seed, Some(300), 700);
        let select_s = run.select_s.expect("a select");
        let sentences: Vec<f64> = run.sentences.iter().map(|t| t - select_s).collect();
        let acks: Vec<f64> = run.acks.iter().map(|t| t - select_s).collect();
        eprintln!("seed {seed}: ack at {acks:?} s, sentences at {sentences:?} s after the select");
        assert_eq!(acks.len(), 1, "seed {seed}: one ack");
        assert!(
            sentences.iter().all(|&t| t > 0.0),
            "seed {seed}: no transducer echoes before the select: {sentences:?}"
        );
        let first = *sentences
            .first()
            .unwrap_or_else(|| panic!("seed {seed}: no sentence within 4 s of the select"));
        assert!(
            first >= from_s && first - TICK_S < to_s,
            "seed {seed}: first sentence ended {:.2}..{first:.2} s after the select, outside \
             {from_s}..{to_s} s",
            first - TICK_S
        );
    }
}

/// Section 1.2: from a select until its ack the master forwards nothing, from either
/// controller; from the ack on it forwards both again, including a sentence the switching
/// controller pinged before its relays moved.
///
/// Two poses, each with one echoing transducer, and a select of transducer 2 (controller A):
/// - the switching controller's own sentences: near the west wall at heading -15 deg
///   transducer 1 (75 deg to port) faces the wall square; transducer 2 meets it 30 deg off
///   its normal and the bow pair looks down the pool, so neither echoes;
/// - the other controller's: near the north wall, mid-pool, at heading 15 deg transducer 3
///   (bow, 15 deg to port; controller B's at power-up) faces the wall square; the port pair is
///   6 m from the west wall, out of range.
///
/// A control run without a select gives the time `e` an echoing sentence ends (it is handed
/// to the line 62.5 ms before, its wire time). Lockstep runs the same bytes for the same
/// inputs, so two more runs with the same seed select transducer 2 shortly before `e`:
/// - 110 ms before: the sentence is due 37.5-47.5 ms after the select, before the ack (80 ms,
///   its last byte at 90.4): it is dropped, and nothing comes within a ping period (1 s);
/// - 170 ms before: it is due 97.5-107.5 ms after the select, after the ack, and ends at `e`
///   (for controller A it was pinged 7.5-17.5 ms after the select, before the relays move at
///   20 ms: a sentence of the previous transducer after the ack).
#[test]
fn the_master_forwards_nothing_between_a_select_and_its_ack() {
    use eyebot_test_support::config::{as_edits, start_at};
    let period_s = 1.0;
    for (case, position, heading) in [
        ("switching controller", [3.0, 1.5, 0.5], -15.0),
        ("other controller", [23.0, 6.25, 0.5], 15.0),
    ] {
        let start = start_at(position, heading);
        let mut edits = as_edits(&start);
        edits.push(LOCKSTEP);
        let text = config_text(&edits);
        let seed = 7;
        let ticks = 400;
        let control = sonar_timeline(&text, seed, None, ticks);
        let e = *control
            .sentences
            .iter()
            .find(|&&t| t > 2.0 && t < 2.0 + period_s)
            .unwrap_or_else(|| {
                panic!(
                    "{case}: a transducer echoes every second: {:?}",
                    control.sentences
                )
            });
        let before = |t: &f64| *t < e - 0.2;
        for (ahead_s, dropped) in [(0.11, true), (0.17, false)] {
            let select_tick = ((e - ahead_s) / TICK_S).round() as u32;
            let run = sonar_timeline(&text, seed, Some(select_tick), ticks);
            let select_s = run.select_s.expect("a select");
            assert!(
                (select_s - (e - ahead_s)).abs() < 1e-6,
                "{case}: the select at {select_s} s, {ahead_s} s before {e}"
            );
            let same: Vec<f64> = run.sentences.iter().copied().filter(before).collect();
            let expected: Vec<f64> = control.sentences.iter().copied().filter(before).collect();
            assert_eq!(
                same, expected,
                "{case}: the same sentences before the select"
            );
            assert_eq!(run.acks.len(), 1, "{case}: one ack: {:?}", run.acks);
            let ack = run.acks[0];
            let after: Vec<f64> = run
                .sentences
                .iter()
                .copied()
                .filter(|&t| t > select_s && t < select_s + period_s)
                .collect();
            eprintln!(
                "{case}: select {ahead_s} s before a sentence at {e} s: ack at {ack} s, \
                 sentences {after:?} within {period_s} s of the select"
            );
            if dropped {
                assert!(
                    after.is_empty(),
                    "{case}: a sentence due between the select and its ack was forwarded: \
                     {after:?}"
                );
            } else {
                assert_eq!(
                    after.len(),
                    1,
                    "{case}: the sentence due after the ack: {after:?}"
                );
                assert!((after[0] - e).abs() < 1e-9, "{case}: {after:?} against {e}");
                assert!(ack < after[0], "{case}: the sentence follows the ack");
            }
        }
    }
}

/// Section 1.2's mean: the first own sentence after a select ends 1.73 s after it on average
/// (the next ping falls uniformly within one period of the relays settling), when its ping
/// echoes. On demand, over `EYEBOT_HIL_SONAR_SEEDS` seeds (default 100), in the pose of the
/// window test:
/// `EYEBOT_HIL_SONAR_SEEDS=100 cargo test -p pty-tests --test conformance -- --ignored --nocapture`.
///
/// A seed whose first sentence comes after the window is shown again with invalid echoes sent
/// as empty sentences and each reading's transducer in `$PEBHS`, so the output says why (a
/// missed echo puts the first sentence a period later); the mean is over the others.
/// A sentence recorded at `t` ended in `(t - 10 ms, t]`: its midpoint stands for it (at most
/// 5 ms off). The mean of N uniform phases over a 1 s period has a standard deviation of
/// 0.289 s / sqrt(N); the mean must lie within three of them (plus the 5 ms) of the spec's.
#[test]
#[ignore = "many seeds: run on demand (docs/hostile.md)"]
fn the_first_own_sentence_comes_on_average_when_section_1_2_says() {
    use eyebot_test_support::config::{as_edits, start_at};
    let mean_s = spec_number_after("own ping has its last byte 1.23 to 2.23 s after the select, ");
    assert_eq!(mean_s, 1.73);
    let seeds: u64 = std::env::var("EYEBOT_HIL_SONAR_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100);
    let start = start_at([3.0, 1.5, 0.5], 15.0);
    let mut edits = as_edits(&start);
    edits.push(LOCKSTEP);
    let text = config_text(&edits);
    let started = Instant::now();
    let firsts: Vec<f64> = (1..=seeds)
        .map(|seed| {
            let run = sonar_timeline(&text, seed, Some(300), 600);
            let select_s = run.select_s.expect("a select");
            let first = run
                .sentences
                .iter()
                .map(|t| t - select_s)
                .find(|&t| t > 0.0)
                .unwrap_or_else(|| panic!("seed {seed}: no sentence within 3 s of the select"));
            first - TICK_S / 2.0
        })
        .collect();
    let late: Vec<(u64, f64)> = (1..=seeds)
        .zip(firsts.iter().copied())
        .filter(|&(_, t)| t > 2.23)
        .collect();
    let in_window: Vec<f64> = firsts.iter().copied().filter(|&t| t <= 2.23).collect();
    eprintln!("after the window: {late:?}");
    // Why: the same runs with invalid echoes sent as empty sentences and each reading's
    // transducer in `$PEBHS`.
    let shown = config_text(&[
        edits[0],
        edits[1],
        LOCKSTEP,
        ("invalid_echo = \"omit\"", "invalid_echo = \"empty\""),
        ("proprietary = false", "proprietary = true"),
    ]);
    for &(seed, _) in &late {
        let run = sonar_timeline(&shown, seed, Some(300), 600);
        let select_s = run.select_s.expect("a select");
        for (t, sentence) in run.nmea.iter().filter(|(t, _)| *t > select_s) {
            eprintln!("  seed {seed} at {:.3} s: {sentence}", t - select_s);
        }
    }
    let n = in_window.len() as f64;
    let mean = in_window.iter().sum::<f64>() / n;
    let (lo, hi) = in_window
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &t| (lo.min(t), hi.max(t)));
    let allowed = 3.0 * (1.0 / 12f64.sqrt()) / n.sqrt() + TICK_S / 2.0;
    eprintln!(
        "first own sentence over {seeds} seeds: {} after the window; over the other {n}: mean \
         {mean:.3} s (spec {mean_s}, allowed +-{allowed:.3}), range {lo:.3}..{hi:.3} s; {:.1} s",
        late.len(),
        started.elapsed().as_secs_f64()
    );
    assert!(
        (mean - mean_s).abs() <= allowed,
        "mean {mean:.3} s against {mean_s} s"
    );
}
