//! What the daemon offers whoever watches a run (the CLI connects the live view and Foxglove
//! to it): the bytes that cross the links and the vehicle's state, handed over without ever
//! waiting, and a control channel coming back.
//!
//! [`Daemon::observe`](super::Daemon::observe) returns the watcher's end, an [`Observation`].
//! While something watches ([`Watchers`]), the loop copies each chunk of bytes that crosses a
//! link into a bounded channel with `try_send` (a full channel drops the chunk and counts it);
//! while nothing does, it only counts the chunk as skipped, so nobody pays for decoding what
//! nobody sees. Every [`OBSERVER_PERIOD`] it puts the vehicle's true state into a
//! latest-wins `watch`. Controls come back the other way as [`ControlRequest`]s, each
//! answered once the loop has applied or refused it.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Duration;

use bytes::Bytes;
use serde::{Deserialize, Serialize};
use tokio::sync::{mpsc, oneshot, watch};

use crate::record::{Direction, StateRow};

/// How often the loop publishes the vehicle's state to an observer (20 Hz).
pub const OBSERVER_PERIOD: Duration = Duration::from_millis(50);

/// Chunks of link bytes that may wait for the observer before new ones are dropped.
pub const TAP_CHUNKS: usize = 1024;

/// Controls that may wait for the loop before the watcher is told the bridge is busy.
pub const CONTROL_QUEUE: usize = 8;

/// Counts what watches the run (open pages, connected Foxglove clients): the loop hands link
/// bytes over only while it is above zero.
#[derive(Debug, Clone, Default)]
pub struct Watchers(Arc<AtomicUsize>);

impl Watchers {
    pub fn any(&self) -> bool {
        self.0.load(Ordering::Relaxed) > 0
    }

    pub fn count(&self) -> usize {
        self.0.load(Ordering::Relaxed)
    }

    pub fn join(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }

    pub fn leave(&self) {
        let _ = self
            .0
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1));
    }

    /// Counts one watcher until the guard is dropped.
    pub fn guard(&self) -> WatchGuard {
        self.join();
        WatchGuard(self.clone())
    }
}

/// One watcher, for as long as it lives.
#[derive(Debug)]
pub struct WatchGuard(Watchers);

impl Drop for WatchGuard {
    fn drop(&mut self) {
        self.0.leave();
    }
}

/// The watcher's end of the observer: the tap and where to send controls.
#[derive(Debug)]
pub struct Observation {
    pub tap: TapReceiver,
    pub controls: mpsc::Sender<ControlRequest>,
}

/// The loop's end of the observer.
#[derive(Debug)]
pub(super) struct ObserverEnd {
    pub tap: Tap,
    pub controls: mpsc::Receiver<ControlRequest>,
    pub next_state: tokio::time::Instant,
}

/// A connected pair of ends.
pub(super) fn observer() -> (ObserverEnd, Observation) {
    let (tap, tap_rx) = tap();
    let (controls_tx, controls) = mpsc::channel(CONTROL_QUEUE);
    (
        ObserverEnd {
            tap,
            controls,
            next_state: tokio::time::Instant::now(),
        },
        Observation {
            tap: tap_rx,
            controls: controls_tx,
        },
    )
}

/// Bytes that crossed a link.
#[derive(Debug, Clone)]
pub struct TapChunk {
    pub t_s: f64,
    pub link: &'static str,
    pub dir: Direction,
    pub data: Bytes,
}

/// Held by the daemon's loop.
#[derive(Debug)]
pub struct Tap {
    chunks: mpsc::Sender<TapChunk>,
    dropped: Arc<AtomicU64>,
    skipped: Arc<AtomicU64>,
    watchers: Watchers,
    state: watch::Sender<StateRow>,
    settings: watch::Sender<Settings>,
}

/// What the page's controls last set, for pages that open later.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Settings {
    /// Realtime is paused.
    pub paused: bool,
    /// The water current set from the page (north, east, m/s); `None`: the world file's.
    pub current_mps: Option<[f64; 2]>,
}

/// Held by the watcher.
#[derive(Debug)]
pub struct TapReceiver {
    pub chunks: mpsc::Receiver<TapChunk>,
    /// Chunks the loop dropped because the watcher had not taken the earlier ones.
    pub dropped: Arc<AtomicU64>,
    /// Chunks the loop did not hand over because nothing watched.
    pub skipped: Arc<AtomicU64>,
    /// Open pages and connected Foxglove clients.
    pub watchers: Watchers,
    pub state: watch::Receiver<StateRow>,
    pub settings: watch::Receiver<Settings>,
}

/// A connected pair.
pub fn tap() -> (Tap, TapReceiver) {
    let (chunks_tx, chunks) = mpsc::channel(TAP_CHUNKS);
    let dropped = Arc::new(AtomicU64::new(0));
    let skipped = Arc::new(AtomicU64::new(0));
    let watchers = Watchers::default();
    let (state_tx, state) = watch::channel(StateRow::default());
    let (settings_tx, settings) = watch::channel(Settings::default());
    (
        Tap {
            chunks: chunks_tx,
            dropped: dropped.clone(),
            skipped: skipped.clone(),
            watchers: watchers.clone(),
            state: state_tx,
            settings: settings_tx,
        },
        TapReceiver {
            chunks,
            dropped,
            skipped,
            watchers,
            state,
            settings,
        },
    )
}

impl Tap {
    /// Offers a chunk; drops and counts it when the watcher is behind, skips and counts it
    /// when nothing watches. Never waits.
    pub fn bytes(&self, t_s: f64, link: &'static str, dir: Direction, data: Bytes) {
        if data.is_empty() {
            return;
        }
        if !self.watchers.any() {
            self.skipped.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let chunk = TapChunk {
            t_s,
            link,
            dir,
            data,
        };
        if self.chunks.try_send(chunk).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Publishes the latest state (the watcher reads whichever is newest).
    pub fn state(&self, row: StateRow) {
        self.state.send_replace(row);
    }

    pub fn paused(&self, paused: bool) {
        self.settings.send_modify(|s| s.paused = paused);
    }

    pub fn current(&self, north_mps: f64, east_mps: f64) {
        self.settings
            .send_modify(|s| s.current_mps = Some([north_mps, east_mps]));
    }
}

/// A change the page's owner asks for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "action", rename_all = "snake_case", deny_unknown_fields)]
pub enum Control {
    /// Stop realtime simulated time (the links stay open).
    Pause,
    Resume,
    /// Realtime speed factor.
    Speed {
        factor: f64,
    },
    /// Put the vehicle at rest at this pose.
    Pose {
        x_m: f64,
        y_m: f64,
        depth_m: f64,
        heading_deg: f64,
    },
    /// The steady water current, world frame (north, east, down), m/s.
    Current {
        north_mps: f64,
        east_mps: f64,
    },
    /// Back to the configured start pose, at rest.
    Reset,
}

impl Control {
    /// The event's name in the recording (`events.tsv`).
    pub fn name(&self) -> &'static str {
        match self {
            Control::Pause => "pause",
            Control::Resume => "resume",
            Control::Speed { .. } => "speed",
            Control::Pose { .. } => "pose",
            Control::Current { .. } => "current",
            Control::Reset => "reset",
        }
    }
}

impl Control {
    /// The control's values as `key=value` pairs for `events.tsv` (empty for none).
    pub fn detail(&self) -> String {
        match self {
            Control::Pause | Control::Resume | Control::Reset => String::new(),
            Control::Speed { factor } => format!("factor={factor}"),
            Control::Pose {
                x_m,
                y_m,
                depth_m,
                heading_deg,
            } => format!("x_m={x_m} y_m={y_m} depth_m={depth_m} heading_deg={heading_deg}"),
            Control::Current {
                north_mps,
                east_mps,
            } => format!("north_mps={north_mps} east_mps={east_mps}"),
        }
    }
}

/// A control with the way to answer it: `Ok` with what was done, or `Err` with why not.
#[derive(Debug)]
pub struct ControlRequest {
    pub control: Control,
    pub reply: oneshot::Sender<Result<String, String>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn watchers_count_guards_and_never_go_below_zero() {
        let w = Watchers::default();
        assert!(!w.any());
        let a = w.guard();
        let b = w.guard();
        assert_eq!(w.count(), 2);
        drop(a);
        drop(b);
        assert!(!w.any());
        w.leave();
        assert_eq!(w.count(), 0);
    }
}
