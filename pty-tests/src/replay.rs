//! Shared pieces of the replay pty tests: fixtures, an observer that records what the
//! replay reports, and a replay into a fresh pty read by a timestamping consumer.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use eyebot_hil::replay::{
    ByteSink, Loc, Observer, Options, Port, Problem, Replay, Sent, Shutdown, Summary,
};

use eyebot_test_support::TempDir;
use eyebot_test_support::pty::{PtyFixture, TimedRead, TimedReader};

use crate::fixture_dir;

pub fn fixture(name: &str) -> PathBuf {
    fixture_dir("replay").join(name)
}

pub fn read_fixture(name: &str) -> Vec<u8> {
    std::fs::read(fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Records what the replay reports.
#[derive(Default)]
pub struct Collect {
    pub origin: Option<Instant>,
    pub problems: Vec<Problem>,
    pub sent: Vec<(Loc, usize, Sent)>,
}

impl Observer for Collect {
    fn started(&mut self, origin: Instant) {
        self.origin = Some(origin);
    }
    fn problem(&mut self, problem: &Problem) {
        self.problems.push(problem.clone());
    }
    fn sent(&mut self, loc: &Loc, bytes: &[u8], sent: &Sent) {
        self.sent.push((loc.clone(), bytes.len(), *sent));
    }
}

pub struct Outcome {
    pub realtime: bool,
    /// (bytes written so far, when) per write, from the sink.
    pub write_trace: Vec<(u64, Instant)>,
    pub reads: Vec<TimedRead>,
    pub observed: Collect,
    pub summary: Summary,
}

/// Replays `opts` into a fresh pty and reads the slave until `expect_bytes` arrived.
pub fn replay_to_pty(
    mut opts: Options,
    expect_bytes: usize,
    lead: Duration,
    reader_fifo: Option<i32>,
) -> Outcome {
    let dir = TempDir::new("replay");
    let fixture = PtyFixture::new(dir.path(), "replay");
    let pty = fixture.open();
    let reader = TimedReader::spawn_with(&fixture.link, reader_fifo);
    let realtime = reader.realtime;
    opts.origin = Some(Instant::now() + lead);
    let replay = Replay::open(opts).expect("open the replay");
    let mut sink = ByteSink::new(Port::Pty(pty), &replay.line_settings()).with_write_trace();
    let mut observed = Collect::default();
    let summary = replay
        .run(&mut sink, &mut observed, &Shutdown::new())
        .expect("replay runs");
    let reads = reader.finish_when(expect_bytes, Duration::from_secs(5));
    let write_trace = sink.write_trace().to_vec();
    drop(sink);
    assert!(
        std::fs::symlink_metadata(&fixture.link).is_err(),
        "the pty's symlink is removed when the output drops"
    );
    Outcome {
        reads,
        observed,
        summary,
        realtime,
        write_trace,
    }
}
