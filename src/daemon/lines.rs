//! The lines of a run: their endpoints opened and link tasks spawned, the bytes the engine
//! released handed to the link tasks (and to the observer), and the status each line reports.

use super::*;

/// The loop's side of one line.
pub(super) struct LineRuntime {
    /// The line's name, counters and recorder, shared with its link task.
    pub(super) cx: LineContext,
    pub(super) describe: String,
    pub(super) to_link: mpsc::Sender<Outbound>,
    /// Released bytes the link task has not taken yet, sent as one chunk when it has room.
    pub(super) backlog: bytes::BytesMut,
    /// Beyond this many waiting bytes the client is taken for not reading: drop and count.
    pub(super) backlog_limit: usize,
    /// When bytes last arrived (lockstep's wall-clock idle limit).
    pub(super) last_rx_wall: Instant,
    /// A duplicate of a pty's master, read by the loop itself in lockstep: what the EyeBot
    /// side wrote on this line before a request on another line is taken before that
    /// request ([`super::Daemon::take_earlier_input`]).
    pub(super) peek: Option<ReadAhead>,
    /// The line carries the sensor link, whose requests move simulated time in lockstep.
    pub(super) carries_sensor: bool,
}

/// A pty master read ahead by the loop, with the buffer its reads go through (read once per
/// request in lockstep, so it is kept rather than made each time).
pub(super) struct ReadAhead {
    pty: crate::transport::pty::PtyDrain,
    buf: Box<[u8; READ_AHEAD_BYTES]>,
}

/// The most one read ahead takes from a pty.
const READ_AHEAD_BYTES: usize = 4096;

impl ReadAhead {
    fn new(pty: crate::transport::pty::PtyDrain) -> Self {
        Self {
            pty,
            buf: Box::new([0; READ_AHEAD_BYTES]),
        }
    }

    /// What the pty holds now, up to [`READ_AHEAD_BYTES`]; empty when it holds nothing (or
    /// `Err(WouldBlock)`, as a non-blocking read says it).
    pub(super) fn read_now(&mut self) -> std::io::Result<&[u8]> {
        let n = self.pty.read_now(&mut self.buf[..])?;
        Ok(&self.buf[..n])
    }
}

/// The lines the configuration asks for, each with its endpoint opened: the sonar line
/// (carrying the sensor link too when it is shared), then the sensor line. Symlinks we own
/// are noted in `leftovers`.
pub(super) async fn open_lines(
    config: &DaemonConfig,
    run_dir: &Path,
    leftovers: &shutdown::Leftovers,
) -> Result<(Vec<LineSpec>, Vec<OpenEndpoint>), DaemonError> {
    let shared = config.sensor.endpoint == Endpoint::SharedWithSonar;
    let line_spec = |name, carries, link: &config::LinkConfig| LineSpec {
        name,
        carries,
        settings: link.line,
        tx_queue_bytes: link.tx_queue_bytes,
        release_quantum_ns: config.release_quantum.as_nanos() as u64,
    };
    let mut specs = vec![if shared {
        line_spec("shared", Carries::SHARED, &config.sonar)
    } else {
        line_spec("sonar", Carries::SONAR, &config.sonar)
    }];
    let mut endpoints = vec![OpenEndpoint::open("sonar", &config.sonar, run_dir).await?];
    if !shared {
        specs.push(line_spec("sensor", Carries::SENSOR, &config.sensor));
        endpoints.push(OpenEndpoint::open("sensor", &config.sensor, run_dir).await?);
    }
    for endpoint in &endpoints {
        if let Some((path, target)) = endpoint.owned_link() {
            leftovers.symlink(path, target);
        }
    }
    Ok((specs, endpoints))
}

/// What [`spawn_link_tasks`] started.
pub(super) struct Spawned {
    pub(super) lines: Vec<LineRuntime>,
    pub(super) links: Vec<LinkInfo>,
    pub(super) link_tasks: Vec<tokio::task::JoinHandle<()>>,
    /// Everything the link tasks read, in arrival order.
    pub(super) inbound: mpsc::Receiver<Inbound>,
}

/// One link task per line, on its endpoint; the loop's side of each in `lines`.
pub(super) fn spawn_link_tasks(
    specs: &[LineSpec],
    endpoints: Vec<OpenEndpoint>,
    recorder: Option<crate::record::RecordHandle>,
    stop: &watch::Receiver<bool>,
) -> Spawned {
    let (in_tx, inbound) = mpsc::channel::<Inbound>(256);
    let mut spawned = Spawned {
        lines: Vec::new(),
        links: Vec::new(),
        link_tasks: Vec::new(),
        inbound,
    };
    for ((index, endpoint), spec) in endpoints.into_iter().enumerate().zip(specs) {
        let describe = endpoint.describe();
        let peek = match &endpoint {
            OpenEndpoint::Pty(pty, _) => pty.drain_handle().ok().map(ReadAhead::new),
            _ => None,
        };
        spawned.links.push(LinkInfo {
            name: spec.name,
            path: describe.clone(),
        });
        let (out_tx, out_rx) = mpsc::channel(link::TX_CHANNEL_CHUNKS);
        let counters = Arc::new(LinkCounters::default());
        let cx = LineContext {
            line: index,
            name: spec.name,
            counters,
            recorder: recorder.clone(),
        };
        spawned.link_tasks.push(tokio::spawn(link::run_line(
            cx.clone(),
            endpoint,
            in_tx.clone(),
            out_rx,
            stop.clone(),
        )));
        spawned.lines.push(LineRuntime {
            cx,
            describe,
            to_link: out_tx,
            backlog: bytes::BytesMut::new(),
            backlog_limit: spec.tx_queue_bytes,
            last_rx_wall: Instant::now(),
            peek,
            carries_sensor: spec.carries.sensor,
        });
    }
    spawned
}

/// Hands released bytes to the link tasks. Paced bytes are released a few at a time, so the
/// hand-over channel (counted in chunks) fills after a short stall of the link task even
/// when the client reads: bytes that do not fit wait in the line's backlog and go as one
/// chunk next time. Only when the channel is full and the backlog would exceed the line's
/// `tx_queue_bytes` (a client that does not read, or is gone) are the newly released bytes
/// dropped, counted and recorded as drops (the older ones keep their place, as in a UART
/// overrun); the daemon never blocks on a client.
pub(super) fn flush_outputs<M: Model>(
    core: &mut Engine<M>,
    lines: &mut [LineRuntime],
    observer: Option<&ObserverEnd>,
) {
    let sim_s = core.now() as f64 * 1e-9;
    for (index, line) in lines.iter_mut().enumerate() {
        let waiting = line.backlog.len();
        while let Some(data) = core.take_output(index) {
            line.backlog.extend_from_slice(&data);
            if let Some(observer) = observer {
                observer
                    .tap
                    .bytes(sim_s, line.cx.name, crate::record::Direction::Tx, data);
            }
        }
        if line.backlog.is_empty() {
            continue;
        }
        let chunk = Outbound {
            sim_s,
            data: line.backlog.split().freeze(),
        };
        match line.to_link.try_send(chunk) {
            Ok(()) => {}
            Err(mpsc::error::TrySendError::Full(chunk))
                if chunk.data.len() <= line.backlog_limit =>
            {
                line.backlog.extend_from_slice(&chunk.data);
            }
            Err(mpsc::error::TrySendError::Full(chunk)) => {
                line.backlog.extend_from_slice(&chunk.data[..waiting]);
                line.cx
                    .dropped(sim_s, DropReason::NotRead, &chunk.data[waiting..]);
            }
            Err(mpsc::error::TrySendError::Closed(chunk)) => {
                line.cx
                    .dropped(sim_s, DropReason::EndpointGone, &chunk.data);
            }
        }
    }
}

pub(super) fn snapshot<M: Model>(
    core: &Engine<M>,
    lines: &[LineRuntime],
    started: Instant,
    config: &DaemonConfig,
    map: Option<&RealtimeMap>,
    record: Option<&Path>,
) -> StatusSnapshot {
    let state = core.model().state();
    let (roll, pitch, yaw) = state.euler_rad();
    StatusSnapshot {
        pid: std::process::id(),
        version: env!("CARGO_PKG_VERSION").to_string(),
        uptime_s: started.elapsed().as_secs_f64(),
        sim_time_s: core.now() as f64 * 1e-9,
        time_mode: config.time_mode.name().to_string(),
        speed: map.map_or(0.0, RealtimeMap::speed),
        overruns: map.map_or(0, RealtimeMap::overruns),
        links: lines
            .iter()
            .enumerate()
            .map(|(i, l)| {
                let c = core.line_counters(i);
                LinkStatus {
                    name: l.cx.name.to_string(),
                    path: l.describe.clone(),
                    bytes_rx: l.cx.counters.bytes_rx.load(Ordering::Relaxed),
                    bytes_tx: l.cx.counters.bytes_tx.load(Ordering::Relaxed),
                    frames_rx: c.frames_rx,
                    frames_tx: c.frames_tx,
                    errors: c.errors + l.cx.counters.io_errors.load(Ordering::Relaxed),
                    dropped_tx: c.dropped_tx + l.cx.counters.dropped_tx.load(Ordering::Relaxed),
                    reconnects: l.cx.counters.reconnects.load(Ordering::Relaxed),
                }
            })
            .collect(),
        pose: Pose {
            x_m: state.position_m.x,
            y_m: state.position_m.y,
            depth_m: state.position_m.z,
            roll_deg: roll.to_degrees(),
            pitch_deg: pitch.to_degrees(),
            heading_deg: yaw.to_degrees().rem_euclid(360.0),
            surge_mps: state.velocity_body_mps.x,
        },
        contacts: core.model().contacts(),
        recording: record.map(|p| p.display().to_string()),
    }
}
