//! The view of a running bridge: reads the daemon's [`TapReceiver`] and status, decodes the
//! wire, keeps the last minute of samples, and publishes one frame per state update to any
//! number of pages through a latest-wins channel, and to Foxglove's clients when it serves
//! them.

use std::collections::VecDeque;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, PoisonError};

use tokio::sync::watch;

use super::foxglove::LiveFoxglove;
use super::frame::{Frame, HISTORY_S, Sample, StatusView};
use super::wire::{LinkMessage, WireWatch};
use crate::daemon::observer::{TapReceiver, Watchers};
use crate::daemon::status::StatusSnapshot;

/// One published update: the frame as JSON (serialised once for every page) and the
/// newest link messages.
#[derive(Debug, Clone, Default)]
pub struct Published {
    pub frame_json: Arc<str>,
    /// The last messages, oldest first; each page sends only those it has not sent.
    pub messages: Arc<[LinkMessage]>,
}

/// What a page is sent when it connects.
#[derive(Debug, Clone, Default)]
pub struct History {
    pub samples: VecDeque<Sample>,
}

/// The live side shared with the HTTP handlers.
#[derive(Debug, Clone)]
pub struct LiveShared {
    pub latest: watch::Receiver<Published>,
    pub history: Arc<Mutex<History>>,
    /// Each open event stream counts as a watcher while it lives.
    pub watchers: Watchers,
}

impl LiveShared {
    /// The samples of the last minute (a copy, so the lock is held only to copy).
    pub fn history(&self) -> Vec<Sample> {
        let history = self.history.lock().unwrap_or_else(PoisonError::into_inner);
        history.samples.iter().copied().collect()
    }
}

/// Starts nothing: returns the service future and the handle the server reads.
pub fn service(
    mut tap: TapReceiver,
    mut status: watch::Receiver<StatusSnapshot>,
    mut fox: Option<LiveFoxglove>,
    mut stop: watch::Receiver<bool>,
) -> (LiveShared, impl Future<Output = ()> + Send + 'static) {
    let (publish, latest) = watch::channel(Published::default());
    let history = Arc::new(Mutex::new(History::default()));
    let shared = LiveShared {
        latest,
        history: history.clone(),
        watchers: tap.watchers.clone(),
    };
    let task = async move {
        let mut wire = WireWatch::new();
        // Chunks the loop skipped or dropped so far: when they grow, the wire has a gap.
        let mut missed = 0u64;
        let mut sent_seq = 0;
        let mut messages: Arc<[LinkMessage]> = Arc::from(Vec::new());
        let mut view = StatusView::default();
        loop {
            tokio::select! {
                chunk = tap.chunks.recv() => match chunk {
                    Some(c) => {
                        note_gap(&tap, &mut missed, &mut wire);
                        match &fox {
                            Some(f) => wire.feed(c.t_s, c.link, c.dir, &c.data, |m| f.channels.message(m)),
                            None => wire.feed(c.t_s, c.link, c.dir, &c.data, |_| {}),
                        }
                    }
                    None => break,
                },
                changed = tap.state.changed() => {
                    if changed.is_err() {
                        break;
                    }
                    let row = *tap.state.borrow_and_update();
                    note_gap(&tap, &mut missed, &mut wire);
                    let sample = Sample::new(&row, wire.readings());
                    {
                        let mut h = history.lock().unwrap_or_else(PoisonError::into_inner);
                        while h.samples.front().is_some_and(|s| s.t_s < row.t_s - HISTORY_S || s.t_s > row.t_s) {
                            h.samples.pop_front();
                        }
                        h.samples.push_back(sample);
                    }
                    {
                        let s = status.borrow_and_update();
                        view.time_mode.clone_from(&s.time_mode);
                        view.speed = s.speed;
                        view.overruns = s.overruns;
                        view.links.clone_from(&s.links);
                    }
                    view.sim_time_s = row.t_s;
                    let settings = *tap.settings.borrow();
                    view.paused = settings.paused;
                    view.current_mps = settings.current_mps;
                    view.view_dropped = tap.dropped.load(Ordering::Relaxed);
                    if wire.seq() != sent_seq {
                        sent_seq = wire.seq();
                        messages = wire.recent().iter().cloned().collect();
                    }
                    if let Some(f) = fox.as_mut() {
                        f.time(row.t_s);
                        f.channels.state(&sample, wire.readings());
                    }
                    let frame = Frame { sample: &sample, readings: wire.readings(), status: &view };
                    match serde_json::to_string(&frame) {
                        Ok(json) => {
                            publish.send_replace(Published { frame_json: json.into(), messages: messages.clone() });
                        }
                        Err(e) => tracing::error!(error = %e, "cannot serialise a view frame"),
                    }
                }
                changed = stop.changed() => {
                    if changed.is_err() || *stop.borrow() {
                        break;
                    }
                }
            }
        }
        if let Some(f) = fox {
            f.stop().await;
        }
    };
    (shared, task)
}

/// Tells `wire` of a gap when the loop skipped or dropped chunks since the last look.
fn note_gap(tap: &TapReceiver, missed: &mut u64, wire: &mut WireWatch) {
    let now = tap.skipped.load(Ordering::Relaxed) + tap.dropped.load(Ordering::Relaxed);
    if now != *missed {
        *missed = now;
        wire.gap();
    }
}
