//! Warnings rate-limited per kind, so a flood of bad input costs counters, not gigabytes of
//! log: at most [`BURST`] warnings of one kind per [`WINDOW`]; the rest are counted, and the
//! next warning of that kind after the window (or [`flush`] at shutdown) logs one
//! "suppressed N" line first. Kinds are string literals, so the table is bounded by the code.
//! The clock here only paces log lines; nothing the model computes depends on it.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The length of one rate-limit window.
pub const WINDOW: Duration = Duration::from_secs(1);
/// Warnings of one kind logged per window.
pub const BURST: u32 = 5;

#[derive(Debug)]
struct Kind {
    window_start: Instant,
    shown: u32,
    suppressed: u64,
}

static KINDS: Mutex<Option<HashMap<&'static str, Kind>>> = Mutex::new(None);

fn report(kind: &'static str, k: &Kind, now: Instant) {
    if k.suppressed > 0 {
        tracing::warn!(
            kind,
            suppressed = k.suppressed,
            "suppressed {} more `{kind}` warnings in the last {:.1} s",
            k.suppressed,
            now.duration_since(k.window_start).as_secs_f64()
        );
    }
}

/// Whether a warning of `kind` may be logged now; counts it as suppressed if not.
pub fn allow(kind: &'static str) -> bool {
    let now = Instant::now();
    let Ok(mut guard) = KINDS.lock() else {
        return true;
    };
    let k = guard
        .get_or_insert_with(HashMap::new)
        .entry(kind)
        .or_insert(Kind {
            window_start: now,
            shown: 0,
            suppressed: 0,
        });
    if now.duration_since(k.window_start) >= WINDOW {
        report(kind, k, now);
        *k = Kind {
            window_start: now,
            shown: 0,
            suppressed: 0,
        };
    }
    if k.shown < BURST {
        k.shown += 1;
        true
    } else {
        k.suppressed += 1;
        false
    }
}

/// Logs the "suppressed N" lines still pending (the daemon calls it when it finishes).
pub fn flush() {
    let now = Instant::now();
    let Ok(mut guard) = KINDS.lock() else {
        return;
    };
    for (kind, k) in guard.iter_mut().flat_map(|m| m.iter_mut()) {
        report(kind, k, now);
        k.suppressed = 0;
    }
}

/// `tracing::warn!` for `kind`, rate-limited by [`allow`].
#[macro_export]
macro_rules! warn_limited {
    ($kind:literal, $($arg:tt)+) => {
        if $crate::daemon::warn_limit::allow($kind) {
            tracing::warn!($($arg)+);
        }
    };
}

#[cfg(test)]
mod tests {
    use std::io::Write;
    use std::sync::{Arc, Mutex as StdMutex};

    use super::*;

    #[derive(Clone, Default)]
    struct Captured(Arc<StdMutex<Vec<u8>>>);
    impl Write for Captured {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// A flood of 100 000 warnings of one kind logs [`BURST`] lines and one "suppressed"
    /// line with the exact count.
    #[test]
    fn a_flood_logs_a_burst_and_one_suppressed_line() {
        let out = Captured::default();
        let writer = out.clone();
        let subscriber = tracing_subscriber::fmt()
            .with_writer(move || writer.clone())
            .with_ansi(false)
            .finish();
        tracing::subscriber::with_default(subscriber, || {
            for i in 0..100_000 {
                crate::warn_limited!("test flood", i, "bad byte");
            }
            flush();
        });
        let text = String::from_utf8(out.0.lock().unwrap().clone()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), BURST as usize + 1, "{text}");
        assert!(
            lines[BURST as usize]
                .contains(&format!("suppressed {} more `test flood`", 100_000 - BURST)),
            "{text}"
        );
    }
}
