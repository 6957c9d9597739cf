//! Readiness by polling with a timeout, never a fixed sleep.

use std::time::{Duration, Instant};

/// How often [`wait_for`] polls.
pub const POLL_EVERY: Duration = Duration::from_millis(5);

/// Polls `ready` every [`POLL_EVERY`] until it returns `Some`, or panics after `timeout`
/// naming `what`.
pub fn wait_for<T>(what: &str, timeout: Duration, mut ready: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(v) = ready() {
            return v;
        }
        assert!(
            Instant::now() < deadline,
            "timed out after {timeout:?} waiting for {what}"
        );
        std::thread::sleep(POLL_EVERY);
    }
}
