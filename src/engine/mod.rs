//! The bridge engine: the model, the device emulators and the wire, in simulated time.
//!
//! Sans-IO like the devices it holds. The daemon hands it bytes that arrived on a line
//! ([`Engine::receive`]), tells it how far simulated time may run ([`Engine::advance_to`]), and
//! takes the bytes due on each line ([`Engine::take_output`]). The same calls serve both time
//! modes; only who chooses the target differs (the wall clock, or the client's time frames).
//!
//! Ordering within one call is fixed: inputs are decoded in arrival order, the model steps
//! up to each device deadline before the device is polled, and device outputs are queued on
//! their line in deadline order. So a run is a pure function of the seed, the configuration
//! and the client's bytes with their arrival times: in lockstep, where arrival times are
//! themselves simulated, of the bytes alone.

pub mod plant;

use bytes::{Bytes, BytesMut};
use firmware_protocol::error::LinkError;
use firmware_protocol::{LineDecoder, LineItem};

use crate::SimNanos;
use crate::devices::Plant;
use crate::devices::multiplexer::{Multiplexer, MultiplexerCounters};
use crate::devices::sensor_board::{Output, SensorBoard};
use crate::physics::state::VehicleState;
use crate::record::{Direction, StateRow};
use crate::transport::LineSettings;
use crate::transport::pacer::WirePacer;

/// The simulated vehicle with its sensors, as the core drives it.
pub trait Model: Plant {
    type Error: std::error::Error + Send + Sync + 'static;
    /// Steps the model in fixed steps up to simulated time `t` (the last whole step at or
    /// before `t`). Fails only when the model diverges.
    fn advance_to(&mut self, t: SimNanos) -> Result<(), Self::Error>;
    /// The vehicle after the last step.
    fn state(&self) -> VehicleState;
    /// How many wall/floor contacts began so far.
    fn contacts(&self) -> u64;
    /// Puts the vehicle at rest at `placement` (the live view's control); `Err` says why
    /// not, and nothing changed.
    fn place(&mut self, placement: &Placement) -> Result<(), String> {
        let _ = placement;
        Err("this model cannot be moved".into())
    }
    /// Sets the steady water current (world frame, m/s); `Err` says why not.
    fn set_current(&mut self, north_mps: f64, east_mps: f64) -> Result<(), String> {
        let _ = (north_mps, east_mps);
        Err("this model has no water current to set".into())
    }
    /// Puts the vehicle back at its start pose, at rest.
    fn reset_pose(&mut self) -> Result<(), String> {
        Err("this model cannot be moved".into())
    }
}

/// Where the live view puts the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// North, east and depth of the centre of mass, m.
    pub x_m: f64,
    pub y_m: f64,
    pub depth_m: f64,
    pub heading_deg: f64,
}

/// Which link a line carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Carries {
    pub sonar: bool,
    pub sensor: bool,
}

impl Carries {
    /// The sonar link alone.
    pub const SONAR: Self = Self {
        sonar: true,
        sensor: false,
    };
    /// The sensor link alone.
    pub const SENSOR: Self = Self {
        sonar: false,
        sensor: true,
    };
    /// Both links on one line, told apart by the first byte.
    pub const SHARED: Self = Self {
        sonar: true,
        sensor: true,
    };
}

/// Per-line counters for the status snapshot.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LineCounters {
    pub frames_rx: u64,
    pub frames_tx: u64,
    pub errors: u64,
    pub dropped_tx: u64,
}

struct Line {
    name: &'static str,
    carries: Carries,
    decoder: LineDecoder,
    inbox: BytesMut,
    pacer: WirePacer,
    outbox: Vec<u8>,
    counters: LineCounters,
    last_rx_ns: SimNanos,
    idle_flush_ns: u64,
    /// The decoder consumed garbage it has not reported yet (it reports a run of garbage
    /// only before the next item, or at the idle flush): the inbox can be empty while a
    /// report is owed.
    garbage_pending: bool,
}

/// A partial message is dropped after this much silence on a line that carries the sensor
/// link (a whole frame takes at most 6.2 ms at 115200 baud; PROTOCOL.md section 3).
pub const SENSOR_IDLE_FLUSH_NS: u64 = 50_000_000;
/// The same for a sonar-only line (a whole sentence takes at most 171 ms at 4800 baud).
pub const SONAR_IDLE_FLUSH_NS: u64 = 200_000_000;

/// One line's construction parameters.
#[derive(Debug, Clone)]
pub struct LineSpec {
    pub name: &'static str,
    pub carries: Carries,
    pub settings: LineSettings,
    pub tx_queue_bytes: usize,
    /// Longest a complete byte waits for its hand-over to the port (`transport::pacer`).
    pub release_quantum_ns: u64,
}

/// The core.
pub struct Engine<M: Model> {
    model: M,
    board: SensorBoard,
    mux: Multiplexer,
    lines: Vec<Line>,
    now: SimNanos,
    lockstep: bool,
    journal: Option<Box<dyn Journal>>,
    state_period_ns: u64,
    next_state_ns: SimNanos,
    device_out: Vec<(SimNanos, firmware_protocol::Frame)>,
    mux_out: Vec<(SimNanos, Bytes)>,
    receiving: Option<usize>,
    feed_decoder: LineDecoder,
    feed_inbox: BytesMut,
    feed_schedule: Option<Box<dyn FeedSchedule>>,
    feed_errors: u64,
}

/// Captured sentences due at simulated times, taken in order (`replay = "FILE"`).
pub trait FeedSchedule: Send {
    /// When the next sentence is due; `None` once the schedule is over.
    fn next_time(&self) -> Option<SimNanos>;
    /// Takes the next sentence.
    fn pop(&mut self) -> Option<(SimNanos, Bytes)>;
}

impl FeedSchedule for std::collections::VecDeque<(SimNanos, Bytes)> {
    fn next_time(&self) -> Option<SimNanos> {
        self.front().map(|(t, _)| *t)
    }
    fn pop(&mut self) -> Option<(SimNanos, Bytes)> {
        self.pop_front()
    }
}

/// Where the engine reports every byte that crossed a line and the ground truth: the
/// recording, in the daemon. Called in the engine's own order, never waited on by it.
pub trait Journal: Send {
    /// Bytes that crossed `line` at simulated time `sim_s`.
    fn bytes(&self, sim_s: f64, line: &'static str, dir: Direction, data: &[u8]);
    /// One ground-truth row.
    fn state(&self, row: StateRow);
}

impl<M: Model> Engine<M> {
    /// `lines` must carry the sonar link exactly once and the sensor link exactly once.
    pub fn new(
        model: M,
        board: SensorBoard,
        mux: Multiplexer,
        lines: &[LineSpec],
        lockstep: bool,
    ) -> Self {
        let lines = lines
            .iter()
            .map(|spec| Line {
                name: spec.name,
                carries: spec.carries,
                decoder: LineDecoder::new(),
                inbox: BytesMut::new(),
                pacer: WirePacer::new(&spec.settings, spec.tx_queue_bytes)
                    .with_quantum(spec.release_quantum_ns),
                outbox: Vec::new(),
                counters: LineCounters::default(),
                last_rx_ns: 0,
                garbage_pending: false,
                idle_flush_ns: if spec.carries.sensor {
                    SENSOR_IDLE_FLUSH_NS
                } else {
                    SONAR_IDLE_FLUSH_NS
                },
            })
            .collect();
        Self {
            model,
            board,
            mux,
            lines,
            now: 0,
            lockstep,
            journal: None,
            state_period_ns: 20_000_000,
            next_state_ns: 0,
            device_out: Vec::new(),
            mux_out: Vec::new(),
            receiving: None,
            feed_decoder: LineDecoder::new(),
            feed_inbox: BytesMut::new(),
            feed_schedule: None,
            feed_errors: 0,
        }
    }

    /// Captured sentences to forward as the sonar controllers' output, each at its simulated
    /// time (`replay = "FILE"`): deterministic in both time modes.
    pub fn set_feed_schedule(&mut self, schedule: Vec<(SimNanos, Bytes)>) {
        self.set_feed(Box::new(std::collections::VecDeque::from(schedule)));
    }

    /// A streamed schedule (the daemon's `replay = "FILE"`, read as simulated time reaches
    /// each sentence).
    pub fn set_feed(&mut self, schedule: Box<dyn FeedSchedule>) {
        let active = schedule.next_time().is_some();
        self.mux.set_feed_active(active);
        self.feed_schedule = active.then_some(schedule);
    }

    fn feed_pending(&self) -> bool {
        self.feed_schedule
            .as_ref()
            .is_some_and(|s| s.next_time().is_some())
    }

    /// A live feed (`replay --into-sonar`) connected or left.
    pub fn set_feed_connected(&mut self, connected: bool) {
        self.mux.set_feed_active(connected || self.feed_pending());
        self.feed_inbox.clear();
        self.feed_decoder = LineDecoder::new();
    }

    /// Bytes from a live feed, taken as arriving at the current simulated time.
    pub fn feed_bytes(&mut self, data: &[u8]) {
        self.feed_inbox.extend_from_slice(data);
        loop {
            let d = self.feed_decoder.decode_slice(&self.feed_inbox);
            let raw = self.feed_inbox.split_to(d.consumed).freeze();
            match d.item {
                None => break,
                Some(LineItem::Nmea(sentence)) => {
                    let start = raw.iter().position(|&b| b == b'$').unwrap_or(0);
                    self.forward_fed(&sentence, raw.slice(start..));
                }
                Some(other) => {
                    self.feed_errors += 1;
                    tracing::debug!(item = ?other, "feed input that is not an NMEA sentence");
                }
            }
        }
    }

    /// Feed input that was not a valid sentence (garbage, bad checksum, unknown sentence).
    pub fn feed_errors(&self) -> u64 {
        self.feed_errors
    }

    fn forward_fed(&mut self, sentence: &firmware_protocol::Sentence, raw: Bytes) {
        if let Some(out) = self.mux.feed(sentence, raw, self.now) {
            let line = self.sonar_line();
            self.queue(line, self.now, out, false);
        }
    }

    fn poll_feed(&mut self) {
        while let Some(schedule) = self
            .feed_schedule
            .as_mut()
            .filter(|s| s.next_time().is_some_and(|t| t <= self.now))
        {
            let Some((_, raw)) = schedule.pop() else {
                break;
            };
            match firmware_protocol::nmea::parse_line(&raw) {
                Ok(sentence) => self.forward_fed(&sentence, raw),
                Err(e) => {
                    self.feed_errors += 1;
                    tracing::debug!(error = %e, "scheduled feed line is not a sentence");
                }
            }
        }
        if let Some(out) = self.mux.poll_feed(self.now) {
            let line = self.sonar_line();
            self.queue(line, self.now, out, false);
        }
    }

    /// Reports every byte and the ground truth every `state_period_ns` to `journal`.
    pub fn set_journal(&mut self, journal: Box<dyn Journal>, state_period_ns: u64) {
        self.journal = Some(journal);
        self.state_period_ns = state_period_ns.max(1);
        self.next_state_ns = self.now;
        self.record_state();
    }

    /// Stops reporting to the journal and returns it.
    pub fn take_journal(&mut self) -> Option<Box<dyn Journal>> {
        self.journal.take()
    }

    pub fn now(&self) -> SimNanos {
        self.now
    }

    pub fn model(&self) -> &M {
        &self.model
    }

    pub fn board(&self) -> &SensorBoard {
        &self.board
    }

    pub fn mux_counters(&self) -> MultiplexerCounters {
        self.mux.counters()
    }

    pub fn line_counters(&self, line: usize) -> LineCounters {
        self.lines.get(line).map(|l| l.counters).unwrap_or_default()
    }

    pub fn line_name(&self, line: usize) -> &'static str {
        self.lines.get(line).map_or("?", |l| l.name)
    }

    fn sonar_line(&self) -> usize {
        self.lines.iter().position(|l| l.carries.sonar).unwrap_or(0)
    }

    fn sensor_line(&self) -> usize {
        self.lines
            .iter()
            .position(|l| l.carries.sensor)
            .unwrap_or(0)
    }

    /// Bytes from the EyeBot side arrived on `line` at the current simulated time.
    pub fn receive(&mut self, line: usize, data: &[u8]) -> Result<(), M::Error> {
        let Some(l) = self.lines.get_mut(line) else {
            return Ok(());
        };
        if let Some(rec) = &self.journal {
            rec.bytes(self.now as f64 * 1e-9, l.name, Direction::Rx, data);
        }
        l.inbox.extend_from_slice(data);
        // Bytes behind a TIME_ADVANCE in this chunk are handled after the advance, in order;
        // the idle flush must not take them early.
        self.receiving = Some(line);
        let result = self.drain_inbox(line);
        self.receiving = None;
        self.lines[line].last_rx_ns = self.now;
        result
    }

    /// Records bytes that arrived on `line` but will not be processed (the daemon is
    /// stopping): the recording still holds every byte the EyeBot sent.
    pub fn record_unprocessed(&mut self, line: usize, data: &[u8]) {
        if let (Some(rec), Some(l)) = (&self.journal, self.lines.get(line)) {
            rec.bytes(self.now as f64 * 1e-9, l.name, Direction::Rx, data);
        }
    }

    fn drain_inbox(&mut self, line: usize) -> Result<(), M::Error> {
        loop {
            let l = &mut self.lines[line];
            let before = l.inbox.len();
            let Some(item) = l.decoder.decode(&mut l.inbox) else {
                // Bytes consumed without an item: garbage, counted inside the decoder.
                l.garbage_pending |= l.inbox.len() < before;
                return Ok(());
            };
            // The decoder reports pending garbage before any other item.
            l.garbage_pending = false;
            self.route(line, item)?;
        }
    }

    fn route(&mut self, line: usize, item: LineItem) -> Result<(), M::Error> {
        let carries = self.lines[line].carries;
        let now = self.now;
        match item {
            LineItem::Frame(frame) if carries.sensor => {
                self.lines[line].counters.frames_rx += 1;
                match self.board.handle(frame, now, &mut self.model) {
                    Some(Output::Send(reply)) => self.queue_reply(line, reply),
                    Some(Output::Advance { to, seq }) => {
                        self.advance_to(to)?;
                        let reply = self.board.finish_advance(seq, self.now);
                        self.queue_reply(line, reply);
                    }
                    Some(Output::Step {
                        to,
                        seq,
                        stop_on_sonar,
                    }) => {
                        let sonar_bytes = self.step_to(to, stop_on_sonar)?;
                        let reply =
                            self.board
                                .finish_step(seq, self.now, sonar_bytes, &mut self.model);
                        self.queue_reply(line, reply);
                    }
                    None => {}
                }
            }
            LineItem::Sonar(command) if carries.sonar => {
                self.lines[line].counters.frames_rx += 1;
                if let Some(reply) = self.mux.handle(command, now, &mut self.model) {
                    self.queue(line, now, reply, true);
                }
            }
            LineItem::Error(error) => {
                self.lines[line].counters.errors += 1;
                tracing::debug!(line = self.lines[line].name, %error, "bad input");
                let to_sonar =
                    carries.sonar && !matches!(error, LinkError::Frame(_) | LinkError::Message(_));
                if carries.sensor
                    && let Some(Output::Send(nak)) = self.board.handle_error(&error)
                {
                    self.queue_reply(line, nak);
                }
                if to_sonar && let Some(nak) = self.mux.handle_error(&error) {
                    self.queue(line, now, nak, true);
                }
            }
            // A frame on a sonar-only line, a command on a sensor-only line, or NMEA sent by
            // the EyeBot: nothing on Mako would answer it.
            other => {
                self.lines[line].counters.errors += 1;
                tracing::debug!(line = self.lines[line].name, item = ?other, "message not expected on this line");
            }
        }
        Ok(())
    }

    fn queue_reply(&mut self, line: usize, frame: firmware_protocol::Frame) {
        let mut buf = BytesMut::new();
        frame.encode(&mut buf);
        self.queue(line, self.now, buf.freeze(), true);
    }

    /// Puts bytes on the wire at `at`. In lockstep a reply is released at once: the client
    /// is waiting for it and simulated time will not move until it gets it (the reply's wire
    /// time is still charged to the line, so later bytes queue behind it).
    fn queue(&mut self, line: usize, at: SimNanos, data: Bytes, is_reply: bool) {
        let l = &mut self.lines[line];
        l.counters.frames_tx += 1;
        match l.pacer.push(at, data) {
            Ok(end) => {
                if is_reply && self.lockstep {
                    l.pacer.release(end, &mut l.outbox);
                }
            }
            Err(full) => {
                l.counters.dropped_tx += full.dropped as u64;
                crate::warn_limited!("transmit queue full", line = l.name, %full, "transmit queue full");
            }
        }
    }

    /// Runs simulated time forward to `target`, stepping the model to each device deadline
    /// and queueing what the devices emit.
    pub fn advance_to(&mut self, target: SimNanos) -> Result<(), M::Error> {
        while self.now < target {
            let idle = self
                .lines
                .iter()
                .enumerate()
                .filter(|(i, l)| {
                    (!l.inbox.is_empty() || l.garbage_pending) && self.receiving != Some(*i)
                })
                .map(|(_, l)| l)
                .map(|l| l.last_rx_ns + l.idle_flush_ns);
            let next = [
                self.board.poll_timeout(),
                self.mux.poll_timeout(&self.model),
                self.mux.feed_timeout(),
                self.feed_schedule.as_ref().and_then(|s| s.next_time()),
                self.journal.as_ref().map(|_| self.next_state_ns),
            ]
            .into_iter()
            .flatten()
            .chain(idle)
            .filter(|&t| t > self.now)
            .fold(target, SimNanos::min);
            self.model.advance_to(next)?;
            self.now = next;
            self.flush_idle_lines()?;
            self.poll_devices();
            self.record_state();
            // What is complete leaves the pacer as time passes, so a long lockstep advance
            // does not count a stream's earlier samples against the transmit queue.
            self.release_due();
        }
        self.poll_devices();
        self.release_due();
        Ok(())
    }

    /// A TIME_STEP's advance: to `target`, or with `stop_on_sonar` to the end of the first
    /// tick in which bytes went out on the sonar line (its own line; a shared line is refused
    /// by the board). Returns how many bytes went out on the sonar's own line meanwhile.
    fn step_to(&mut self, target: SimNanos, stop_on_sonar: bool) -> Result<u16, M::Error> {
        let sonar = self.sonar_line();
        let own_line = sonar != self.sensor_line();
        let before = self.lines[sonar].outbox.len();
        if stop_on_sonar && own_line {
            let tick = self.board.tick_ns().max(1);
            while self.now < target && self.lines[sonar].outbox.len() == before {
                let next = (self.now + tick).min(target);
                self.advance_to(next)?;
            }
        } else {
            self.advance_to(target)?;
        }
        let sent = if own_line {
            self.lines[sonar].outbox.len() - before
        } else {
            0
        };
        Ok(u16::try_from(sent).unwrap_or(u16::MAX))
    }

    /// Drops partial messages that have waited longer than their line's idle limit.
    fn flush_idle_lines(&mut self) -> Result<(), M::Error> {
        for line in 0..self.lines.len() {
            let l = &self.lines[line];
            if self.receiving == Some(line)
                || (l.inbox.is_empty() && !l.garbage_pending)
                || self.now < l.last_rx_ns + l.idle_flush_ns
            {
                continue;
            }
            self.flush_line(line)?;
        }
        Ok(())
    }

    /// Whether `line` holds a partial message (or an unreported run of garbage) that the
    /// idle limit would drop.
    pub fn holds_partial(&self, line: usize) -> bool {
        self.lines
            .get(line)
            .is_some_and(|l| !l.inbox.is_empty() || l.garbage_pending)
    }

    /// The wall-clock idle limit of `line` in lockstep (PROTOCOL.md section 3): 50 ms on a
    /// line that carries the sensor link, where a partial frame would otherwise wait for the
    /// CRC rescan of the next request. `None` on a sonar-only line: there the limit runs in
    /// simulated time only, so a select the client writes a byte at a time is never cut by
    /// how the host scheduled the writes.
    pub fn lockstep_wall_idle_limit(&self, line: usize) -> Option<std::time::Duration> {
        self.lines
            .get(line)
            .filter(|l| l.carries.sensor)
            .map(|l| std::time::Duration::from_nanos(l.idle_flush_ns))
    }

    /// Drops the partial message `line` holds now, at the current simulated time: what the
    /// daemon does in lockstep once a line that carries the sensor link has been silent for
    /// its idle limit of wall time (simulated time stands still while the bridge waits for
    /// a request).
    pub fn flush_line(&mut self, line: usize) -> Result<(), M::Error> {
        let Some(l) = self.lines.get_mut(line) else {
            return Ok(());
        };
        l.garbage_pending = false;
        loop {
            let l = &mut self.lines[line];
            let Some(item) = l.decoder.decode_eof(&mut l.inbox) else {
                break;
            };
            self.route(line, item)?;
        }
        Ok(())
    }

    fn poll_devices(&mut self) {
        let now = self.now;
        self.device_out.clear();
        self.board.poll(now, &mut self.model, &mut self.device_out);
        let sensor_line = self.sensor_line();
        for i in 0..self.device_out.len() {
            let (at, frame) = self.device_out[i];
            let mut buf = BytesMut::new();
            frame.encode(&mut buf);
            self.queue(sensor_line, at, buf.freeze(), false);
        }
        self.poll_feed();
        self.mux_out.clear();
        self.mux.poll(now, &mut self.model, &mut self.mux_out);
        let sonar_line = self.sonar_line();
        for (at, bytes) in std::mem::take(&mut self.mux_out) {
            self.queue(sonar_line, at, bytes, false);
        }
    }

    fn record_state(&mut self) {
        let Some(rec) = &self.journal else {
            return;
        };
        if self.now >= self.next_state_ns {
            rec.state(StateRow::from_state(&self.model.state()));
            // Rows fall on the period's grid; a gap (none in normal stepping) is skipped.
            let periods = (self.now - self.next_state_ns) / self.state_period_ns + 1;
            self.next_state_ns += periods * self.state_period_ns;
        }
    }

    fn release_due(&mut self) {
        for l in &mut self.lines {
            l.pacer.release(self.now, &mut l.outbox);
        }
    }

    /// When something next becomes due: a device deadline or a byte completing on a line.
    pub fn next_deadline(&self) -> Option<SimNanos> {
        let lines = self.lines.iter().filter_map(|l| l.pacer.next_release_ns());
        [
            self.board.poll_timeout(),
            self.mux.poll_timeout(&self.model),
        ]
        .into_iter()
        .flatten()
        .chain(lines)
        .min()
    }

    /// The bytes due on `line`, in order; recorded as they leave.
    pub fn take_output(&mut self, line: usize) -> Option<Bytes> {
        let l = self.lines.get_mut(line)?;
        if l.outbox.is_empty() {
            return None;
        }
        let data = Bytes::from(std::mem::take(&mut l.outbox));
        if let Some(rec) = &self.journal {
            rec.bytes(self.now as f64 * 1e-9, l.name, Direction::Tx, &data);
        }
        Some(data)
    }

    /// Puts the vehicle at rest at `placement` now (the model checks it).
    pub fn place(&mut self, placement: &Placement) -> Result<(), String> {
        self.model.place(placement)
    }

    /// Sets the water current now.
    pub fn set_current(&mut self, north_mps: f64, east_mps: f64) -> Result<(), String> {
        self.model.set_current(north_mps, east_mps)
    }

    /// The vehicle back at its start pose now.
    pub fn reset_pose(&mut self) -> Result<(), String> {
        self.model.reset_pose()
    }
}

/// A scripted model for core and daemon tests.
#[cfg(test)]
pub(crate) mod fake {
    use nalgebra::{UnitQuaternion, Vector3};

    use super::*;
    use crate::devices::fake::FakePlant;
    use crate::devices::{CalibrationProgress, CalibrationRefused, CompassSample, SonarEvent};

    const MS: u64 = 1_000_000;

    /// A plant whose "physics" only counts steps of 1 ms.
    #[derive(Default)]
    pub struct FakeModel {
        pub plant: FakePlant,
        pub t: SimNanos,
    }

    impl Plant for FakeModel {
        fn adc(&mut self, channel: u8, now: SimNanos) -> u16 {
            // A value that changes with time, so ordering mistakes show.
            (self.plant.adc(channel, now) + (now / MS) as u16) & 0x3FF
        }
        fn compass(&mut self, now: SimNanos) -> CompassSample {
            self.plant.compass(now)
        }
        fn compass_calibrate(
            &mut self,
            action: firmware_protocol::sensor_link::CalibrationAction,
            now: SimNanos,
        ) -> Result<CalibrationProgress, CalibrationRefused> {
            self.plant.compass_calibrate(action, now)
        }
        fn compass_reset(&mut self, now: SimNanos) {
            self.plant.compass_reset(now)
        }
        fn set_thrusters(
            &mut self,
            commands: [firmware_protocol::sensor_link::ThrusterCommand; 4],
            now: SimNanos,
        ) {
            self.plant.set_thrusters(commands, now)
        }
        fn sonar_select(&mut self, transducer: u8, now: SimNanos) {
            self.plant.sonar_select(transducer, now);
            self.plant
                .sonar
                .push((now + 50 * MS, SonarEvent::Switched { transducer }));
            self.plant.sonar.push((
                now + 1_000 * MS,
                SonarEvent::Reading {
                    transducer,
                    range_m: Some(2.5),
                    quality_pct: 90,
                },
            ));
        }
        fn sonar_poll(&mut self, now: SimNanos, out: &mut Vec<(SimNanos, SonarEvent)>) {
            self.plant.sonar_poll(now, out)
        }
        fn sonar_timeout(&self) -> Option<SimNanos> {
            self.plant.sonar_timeout()
        }
        fn readings_checkpoint(&mut self) {
            self.plant.readings_checkpoint()
        }
        fn readings_restore(&mut self) {
            self.plant.readings_restore()
        }
    }

    impl Model for FakeModel {
        type Error = std::convert::Infallible;
        fn advance_to(&mut self, t: SimNanos) -> Result<(), Self::Error> {
            self.t = t - t % MS;
            Ok(())
        }
        fn state(&self) -> VehicleState {
            VehicleState {
                t_s: self.t as f64 * 1e-9,
                position_m: Vector3::zeros(),
                attitude: UnitQuaternion::identity(),
                velocity_body_mps: Vector3::zeros(),
                angular_velocity_body_radps: Vector3::zeros(),
                velocity_water_body_mps: Vector3::zeros(),
                specific_force_body_mps2: Vector3::new(0.0, 0.0, -9.81),
                angular_accel_body_radps2: Vector3::zeros(),
                thruster_force_n: [0.0; 4],
                thruster_effort: [0.0; 4],
                in_contact: false,
            }
        }
        fn contacts(&self) -> u64 {
            0
        }
    }
}

#[cfg(test)]
mod tests;
