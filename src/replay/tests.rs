use std::io::Write;
use std::sync::Mutex;

use super::*;
use crate::record::{Direction, Recorder};

#[derive(Clone, Default)]
struct Shared(Arc<Mutex<Vec<u8>>>);

impl Write for Shared {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// What the daemon's recorder writes, replay sends back: the sonar link's `tx` sentences,
/// reassembled across chunk boundaries, without the select/ack traffic or other links.
#[test]
fn a_recording_made_by_the_recorder_replays_its_sonar_sentences() {
    let tmp = crate::scratch::dir("replay-rec");
    let dir = tmp.path().join("rec");
    let meta = crate::record::Meta::new(1, "lockstep", 1.0, "test");
    let rec = Recorder::start(&dir, &meta, "").unwrap();
    let a = b"$SDDBT,6.6,f,2.0,M,1.1,F*04\r\n";
    let b = b"$SDDPT,2.0,0.5*50\r\n";
    rec.bytes(0.100, "sonar", Direction::Rx, b"@S1\r");
    rec.bytes(0.101, "sonar", Direction::Tx, b"@A1\r\n$SDDBT,6.6");
    rec.bytes(0.102, "sensor", Direction::Tx, &[0xEB, 0x90, 0x00]);
    rec.bytes(0.103, "sonar", Direction::Tx, b",f,2.0,M,1.1,F*04\r\n$SDD");
    rec.bytes(0.350, "sonar", Direction::Tx, b"PT,2.0,0.5*50\r\n");
    rec.finish().unwrap();

    let mut opts = Options::new(vec![dir.clone()]);
    opts.pacing = Some(Pacing::Fast);
    let replay = Replay::open(opts).unwrap();
    assert_eq!(replay.inputs()[0].format, Format::Recording);
    let out = Shared::default();
    let mut sink = ByteSink::new(Port::Writer(Box::new(out.clone())), &DEFAULT_LINE);
    let summary = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
    assert_eq!(*out.0.lock().unwrap(), [&a[..], &b[..]].concat());
    assert_eq!(summary.link_messages_skipped, 1);
    assert_eq!(summary.problem_count(), 0);
    assert_eq!(summary.first_time_ns, Some(101_000_000));
    assert_eq!(summary.last_time_ns, Some(103_000_000));
}

/// `--start`/`--end` and the speed factor act on log time. Checked on the modelled line
/// times the sink reports.
#[test]
fn start_end_speed_and_loop_shape_the_schedule() {
    #[derive(Default)]
    struct Times(Vec<(u64, u64)>);
    impl Observer for Times {
        fn sent(&mut self, loc: &Loc, _b: &[u8], sent: &Sent) {
            self.0.push((loc.line, sent.start_ns.unwrap()));
        }
    }
    let tmp = crate::scratch::dir("replay-se");
    let dir = tmp.path();
    let log = dir.join("t.log");
    let text: String = (0..6)
        .map(|i| format!("{}.000 $SDDPT,1.{i},0.3*00\r\n", 100 + i))
        .collect();
    std::fs::write(&log, text).unwrap();
    let mut opts = Options::new(vec![log]);
    opts.start_s = 1.0;
    opts.end_s = Some(3.0);
    opts.speed = 50.0;
    opts.line = Some(LineSettings::n81(115_200));
    let replay = Replay::open(opts).unwrap();
    assert_eq!(replay.pacing(), Pacing::Timestamps);
    let mut sink = ByteSink::new(
        Port::Writer(Box::new(std::io::sink())),
        &replay.line_settings(),
    );
    let mut times = Times::default();
    let summary = replay.run(&mut sink, &mut times, &Shutdown::new()).unwrap();
    // Lines 2..=4 (log 1 s, 2 s, 3 s) at 20 ms intervals (speed 50).
    assert_eq!(times.0, vec![(2, 0), (3, 20_000_000), (4, 40_000_000)]);
    assert_eq!(summary.skipped_before_start, 1);
}

/// `--loop` starts the next pass when the line is free, and keeps the schedule of the
/// first; problems are listed on the first pass only.
#[test]
fn loop_passes_follow_each_other_on_the_line() {
    struct StopAfter(usize, Shutdown, Vec<u64>, usize);
    impl Observer for StopAfter {
        fn sent(&mut self, _loc: &Loc, _b: &[u8], sent: &Sent) {
            self.2.push(sent.start_ns.unwrap());
            if self.2.len() == self.0 {
                self.1.trigger();
            }
        }
        fn problem(&mut self, _p: &Problem) {
            self.3 += 1;
        }
    }
    let tmp = crate::scratch::dir("replay-loop");
    let dir = tmp.path();
    let log = dir.join("l.log");
    std::fs::write(&log, "0.0 $A*41\r\n0.01 $B*00\r\n").unwrap();
    let mut opts = Options::new(vec![log]);
    opts.looping = true;
    opts.line = Some(LineSettings::n81(115_200));
    let replay = Replay::open(opts).unwrap();
    let stop = Shutdown::new();
    let mut obs = StopAfter(5, stop.clone(), Vec::new(), 0);
    let mut sink = ByteSink::new(
        Port::Writer(Box::new(std::io::sink())),
        &replay.line_settings(),
    );
    let summary = replay.run(&mut sink, &mut obs, &stop).unwrap();
    let char_ns = LineSettings::n81(115_200).char_time_ns();
    let pass_ns = 10_000_000 + 7 * char_ns; // B starts at 10 ms and takes 7 characters
    assert_eq!(
        obs.2,
        vec![0, 10_000_000, pass_ns, pass_ns + 10_000_000, 2 * pass_ns]
    );
    assert_eq!(
        obs.3, 1,
        "the bad checksum of $B is listed once, not every pass"
    );
    assert_eq!(summary.problems.get("checksum mismatch"), Some(&1));
}

/// `--comments send` passes comments through as lines, in file order, as gpsfake does;
/// `#Serial:` is never sent, and a conflicting later one is reported.
#[test]
fn comments_are_sent_in_place_when_asked() {
    let tmp = crate::scratch::dir("replay-cm");
    let dir = tmp.path();
    let log = dir.join("c.log");
    std::fs::write(
        &log,
        "#Serial: 9600 8N1\n$A*41\r\n# between\r\n#Serial: 4800 8N1\n$A*41\r\n",
    )
    .unwrap();
    let mut opts = Options::new(vec![log]);
    opts.comments = CommentMode::Send;
    opts.pacing = Some(Pacing::Fast);
    let replay = Replay::open(opts).unwrap();
    assert_eq!(replay.line_settings(), LineSettings::n81(9600));
    let out = Shared::default();
    let mut sink = ByteSink::new(Port::Writer(Box::new(out.clone())), &replay.line_settings());
    let summary = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
    assert_eq!(*out.0.lock().unwrap(), b"$A*41\r\n# between\r\n$A*41\r\n");
    assert_eq!(summary.comments_sent, 1);
    assert_eq!(summary.sentences_sent, 2);
    assert_eq!(summary.problems.get("#Serial conflict"), Some(&1));
}

/// Every line of a text log lands in one counter of the summary, bad timestamps among
/// the dropped, comments counted whatever `--comments` does with them.
#[test]
fn the_summary_accounts_for_every_line_once() {
    let tmp = crate::scratch::dir("replay-acct");
    let log = tmp.path().join("a.log");
    std::fs::write(
        &log,
        "#Serial: 9600 8N1\n# c1\n\n0.0 $A*41\r\nbad $A*41\r\n1.0 $B*00\r\n\n# c2\n2.0 $A*41\r3.0 $A*41\r\n9.0 $A*41\r\n",
    )
    .unwrap();
    for mode in [CommentMode::Report, CommentMode::Send, CommentMode::Ignore] {
        let mut opts = Options::new(vec![log.clone()]);
        opts.pacing = Some(Pacing::Fast);
        opts.policy = Policy::Drop;
        opts.comments = mode;
        opts.start_s = 1.0;
        opts.end_s = Some(5.0);
        let replay = Replay::open(opts).unwrap();
        let out = Shared::default();
        let mut sink = ByteSink::new(Port::Writer(Box::new(out.clone())), &DEFAULT_LINE);
        let s = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
        assert_eq!(s.physical_lines, 11, "{mode:?}");
        assert_eq!((s.comments, s.serial_comments, s.blank_lines), (2, 1, 2));
        assert_eq!(s.lines_read, 6, "{mode:?}: 5 timed lines and `bad`");
        assert_eq!(
            s.physical_lines,
            s.lines_read + s.comments + s.serial_comments + s.blank_lines
        );
        // 0.0 skipped, `bad` and the bad checksum dropped, 2.0 and 3.0 sent, 9.0 past --end.
        assert_eq!(
            (
                s.skipped_before_start,
                s.lines_dropped,
                s.sentences_sent,
                s.past_end
            ),
            (1, 2, 2, 1),
            "{mode:?}"
        );
        let comments_sent = if mode == CommentMode::Send { 2 } else { 0 };
        assert_eq!(s.comments_sent, comments_sent, "{mode:?}");
        assert_eq!(s.problems.get("CR without LF"), Some(&1), "{mode:?}");
    }
}

/// `--speed` outside its range is refused; at the ends of the range a schedule is finite.
#[test]
fn speed_has_a_range() {
    let tmp = crate::scratch::dir("replay-speed");
    let log = tmp.path().join("a.log");
    std::fs::write(&log, "0 $A*41\r\n").unwrap();
    for bad in [1e-300, 0.0009, 1000.5, f64::INFINITY, f64::NAN, -1.0] {
        let mut opts = Options::new(vec![log.clone()]);
        opts.speed = bad;
        let err = Replay::open(opts).unwrap_err().to_string();
        assert!(
            err.contains("--speed must be from 0.001 to 1000"),
            "{bad}: {err}"
        );
        assert!(err.len() < 80, "the value written in full: {err}");
    }
    let mut sched = Scheduler::new(Pacing::Timestamps, 0.001, 0.0, None, 1000);
    assert_eq!(
        sched.place(Some(i64::MIN), 10),
        Placement::Due { offset_ns: 0 }
    );
    assert!(
        matches!(sched.place(Some(i64::MAX), 10), Placement::Due { offset_ns } if offset_ns == u64::MAX)
    );
}

/// A pipe or FIFO is opened once and read once: by `open` for the format and `#Serial:`,
/// then by the first pass. `--loop` over one is refused.
#[test]
fn a_fifo_is_read_once() {
    let tmp = crate::scratch::dir("replay-fifo");
    let fifo = tmp.path().join("log.fifo");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let path = fifo.clone();
    let writer = std::thread::spawn(move || {
        let text: String = std::iter::once("#Serial: 9600 8N1\n".to_string())
            .chain((0..500).map(|i| format!("$GPXXX,{i}*00\r\n")))
            .collect();
        std::fs::write(path, text).unwrap();
    });
    let (tx, rx) = std::sync::mpsc::channel();
    let reader_path = fifo.clone();
    std::thread::spawn(move || {
        let mut opts = Options::new(vec![reader_path]);
        opts.pacing = Some(Pacing::Fast);
        let replay = Replay::open(opts).unwrap();
        let line = replay.line_settings();
        let mut sink = ByteSink::new(Port::Writer(Box::new(std::io::sink())), &line);
        let s = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
        let _ = tx.send((line, s.sentences_sent, s.physical_lines));
    });
    let (line, sent, lines) = rx
        .recv_timeout(std::time::Duration::from_secs(10))
        .expect("the replay of a FIFO ended");
    writer.join().unwrap();
    assert_eq!((line, sent, lines), (LineSettings::n81(9600), 500, 501));

    let writer = {
        let path = fifo.clone();
        std::thread::spawn(move || std::fs::write(path, "$A*41\r\n").unwrap())
    };
    let mut opts = Options::new(vec![fifo]);
    opts.looping = true;
    let err = Replay::open(opts).unwrap_err().to_string();
    writer.join().unwrap();
    assert!(err.contains("--loop") && err.contains("log.fifo"), "{err}");
}

/// A log of many distinct addresses costs a fixed table of types.
#[test]
fn sentence_types_have_a_capped_table() {
    let tmp = crate::scratch::dir("replay-types");
    let log = tmp.path().join("a.log");
    let text: String = (0..1000).map(|i| format!("$X{i:05},1*00\r\n")).collect();
    std::fs::write(&log, text).unwrap();
    let mut opts = Options::new(vec![log]);
    opts.pacing = Some(Pacing::Fast);
    let replay = Replay::open(opts).unwrap();
    let mut sink = ByteSink::new(Port::Writer(Box::new(std::io::sink())), &DEFAULT_LINE);
    let s = replay.run(&mut sink, &mut Quiet, &Shutdown::new()).unwrap();
    assert_eq!(s.by_type.len(), stats::TYPES_LISTED + 1);
    assert_eq!(
        s.by_type.get(stats::OTHER_TYPES),
        Some(&(1000 - stats::TYPES_LISTED as u64))
    );
    assert_eq!(s.by_type.values().sum::<u64>(), 1000);
}

/// A recording with rows timed 0, `inf`, `NaN` and -1 sends the one valid row; the others are
/// bad timestamps, and the statistics show a span of 0 s and no gaps (they showed
/// 9223372036.855 s and negative gaps, and a paced replay stalled on the `inf` row).
#[test]
fn a_recording_with_impossible_times_sends_only_the_valid_row() {
    let tmp = crate::scratch::dir("replay-badtime");
    let path = tmp.path().join("bytes.tsv");
    let mut tsv = format!("{}\n", crate::record::BYTES_HEADER);
    for (i, sim) in ["0", "inf", "NaN", "-1"].iter().enumerate() {
        let sentence = format!("$GPXXX,{i}*00\r\n");
        tsv += &format!("{sim}\t0\tsonar\ttx\t{}\n", hex::encode(sentence));
    }
    std::fs::write(&path, tsv).unwrap();
    let mut opts = Options::new(vec![path]);
    opts.pacing = Some(Pacing::Timestamps);
    opts.policy = Policy::Pass;
    let replay = Replay::open(opts).unwrap();
    let s = replay
        .run(&mut NullSink, &mut Quiet, &Shutdown::new())
        .unwrap();
    assert_eq!(s.sentences_sent, 1);
    assert_eq!(s.problems.get("bad timestamp"), Some(&3));
    assert_eq!(s.lines_dropped, 3);
    let stats = s.stats_text();
    assert!(stats.contains("time span: 0.000 s"), "{stats}");
    assert!(s.gaps.is_empty(), "{stats}");
}
