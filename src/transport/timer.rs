//! A sleep with microsecond precision for the daemon's loop.

use tokio::time::Instant;

/// Sleeps until a deadline with the precision of a Linux timerfd.
///
/// tokio's timer wheel rounds every deadline up to the next millisecond, so a paced byte
/// (86.8 us at 115200 baud) would leave up to 1 ms after its wire time and an ADC reply
/// would take about 1.2 ms instead of 0.87 ms. The timerfd wakes within microseconds. tokio's
/// sleep still runs alongside, so a test that pauses tokio's clock wakes as before, and
/// if the timerfd cannot be created or armed it falls back to tokio's timer alone.
/// Create it inside a tokio runtime with I/O enabled.
pub struct PreciseTimer {
    fd: Option<tokio::io::unix::AsyncFd<TimerFd>>,
}

struct TimerFd(nix::sys::timerfd::TimerFd);

impl std::os::fd::AsRawFd for TimerFd {
    fn as_raw_fd(&self) -> std::os::fd::RawFd {
        use std::os::fd::AsFd;
        self.0.as_fd().as_raw_fd()
    }
}

impl PreciseTimer {
    pub fn new() -> Self {
        use nix::sys::timerfd::{ClockId, TimerFlags};
        let fd = nix::sys::timerfd::TimerFd::new(
            ClockId::CLOCK_MONOTONIC,
            TimerFlags::TFD_NONBLOCK | TimerFlags::TFD_CLOEXEC,
        )
        .map_err(std::io::Error::from)
        .and_then(|fd| {
            // SAFETY: the timerfd is a valid open descriptor owned by the `TimerFd`, which
            // returns the same descriptor from `as_raw_fd` for as long as the `AsyncFd` owns it.
            unsafe {
                tokio::io::unix::AsyncFd::register_with_interest(
                    TimerFd(fd),
                    tokio::io::Interest::READABLE,
                )
            }
            .map_err(std::io::Error::from)
        });
        match fd {
            Ok(fd) => Self { fd: Some(fd) },
            Err(error) => {
                tracing::warn!(%error, "no timerfd; timing falls back to tokio's 1 ms timer");
                Self { fd: None }
            }
        }
    }

    /// Returns at `deadline` (or at once if it has passed).
    pub async fn sleep_until(&self, deadline: Instant) {
        use nix::sys::time::TimeSpec;
        use nix::sys::timerfd::{Expiration, TimerSetTimeFlags};
        let coarse = tokio::time::sleep_until(deadline);
        let Some(fd) = &self.fd else {
            return coarse.await;
        };
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            // Already due: still take part in tokio's cooperative budget, as tokio's own
            // sleep does, so a loop that keeps running late cannot starve the link tasks.
            tokio::task::consume_budget().await;
            return;
        }
        let armed = fd.get_ref().0.set(
            Expiration::OneShot(TimeSpec::from_duration(left)),
            TimerSetTimeFlags::empty(),
        );
        if armed.is_err() {
            return coarse.await;
        }
        let fine = async {
            loop {
                let Ok(mut guard) = fd.readable().await else {
                    return std::future::pending::<()>().await;
                };
                let mut expirations = [0u8; 8];
                match guard.try_io(|f| {
                    nix::unistd::read(&f.get_ref().0, &mut expirations)
                        .map_err(std::io::Error::from)
                }) {
                    // Expired (an expiry left over from an earlier, abandoned sleep only
                    // makes the loop wake once early, which it tolerates).
                    Ok(_) => return,
                    Err(_would_block) => continue,
                }
            }
        };
        tokio::select! {
            _ = fine => {}
            _ = coarse => {}
        }
    }
}

impl Default for PreciseTimer {
    fn default() -> Self {
        Self::new()
    }
}
