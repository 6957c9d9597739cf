//! The view of a running bridge: reads the daemon's [`TapReceiver`] and status, decodes the
//! wire, keeps the last minute of samples, and publishes one frame per state update to any
//! number of pages through a latest-wins channel.

use std::collections::VecDeque;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, PoisonError};

use tokio::sync::watch;

use super::frame::{Frame, HISTORY_S, Sample, StatusView};
use super::tap::TapReceiver;
use super::wire::{LinkMessage, WireWatch};
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
    mut stop: watch::Receiver<bool>,
) -> (LiveShared, impl Future<Output = ()> + Send + 'static) {
    let (publish, latest) = watch::channel(Published::default());
    let history = Arc::new(Mutex::new(History::default()));
    let shared = LiveShared {
        latest,
        history: history.clone(),
    };
    let task = async move {
        let mut wire = WireWatch::new();
        let mut sent_seq = 0;
        let mut messages: Arc<[LinkMessage]> = Arc::from(Vec::new());
        let mut view = StatusView::default();
        loop {
            tokio::select! {
                chunk = tap.chunks.recv() => match chunk {
                    Some(c) => wire.feed(c.t_s, c.link, c.dir, &c.data, |_| {}),
                    None => return,
                },
                changed = tap.state.changed() => {
                    if changed.is_err() {
                        return;
                    }
                    let row = *tap.state.borrow_and_update();
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
                        return;
                    }
                }
            }
        }
    };
    (shared, task)
}
