//! Asking the kernel for prompt wake-ups, for the realtime daemon and timed replay when the
//! user asks: the CPU latency QoS request (`run.cpu_latency_us`, `replay --cpu-latency-us`)
//! and the `SCHED_FIFO` policy (`run.rt_priority`, `replay --rt-priority`).

use std::io;

/// The path of the kernel's CPU latency QoS request (`Documentation/power/pm_qos_interface`).
pub const CPU_LATENCY_QOS: &str = "/dev/cpu_dma_latency";

/// A held CPU latency QoS request: while it lives, the kernel keeps every CPU out of idle
/// states that take longer than the requested latency to leave. With 0 µs an idle CPU polls
/// instead of halting. On a virtual machine a halted vCPU is woken by the host, which can
/// take milliseconds; the kernel's pty delivery runs on a worker thread that is often woken
/// on the other, idle, CPU. `cyclictest` holds the same request for the same reason. The
/// request ends when the value is dropped (the file is closed).
#[derive(Debug)]
pub struct CpuLatencyRequest {
    _file: std::fs::File,
    pub latency_us: u32,
}

impl CpuLatencyRequest {
    /// Opens [`CPU_LATENCY_QOS`] and writes the request (a native-endian 32-bit integer, as
    /// the interface expects). Needs write access to the device, normally root.
    pub fn hold(latency_us: u32) -> io::Result<Self> {
        use std::io::Write as _;
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .open(CPU_LATENCY_QOS)?;
        let value = i32::try_from(latency_us).map_err(|_| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "CPU latency {latency_us} µs is out of range (at most {})",
                    i32::MAX
                ),
            )
        })?;
        file.write_all(&value.to_ne_bytes())?;
        Ok(Self {
            _file: file,
            latency_us,
        })
    }
}

/// Asks for `SCHED_FIFO` at `priority` (1-99) for the calling thread, so its wake-ups are
/// not queued behind other processes' CPU time: on a loaded machine the default scheduler
/// can wake a sleeper one or more scheduler ticks (4 ms at 250 Hz) late. Needs root or
/// `CAP_SYS_NICE` or an `rtprio` limit. Linux's real-time throttling still reserves 5 % of
/// each second for other tasks.
pub fn set_realtime_priority(priority: i32) -> io::Result<()> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: a plain syscall on the calling thread (pid 0) with a valid parameter struct.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// The wake-up requests of a timed run, held together and released together: a CPU latency
/// QoS request ([`CpuLatencyRequest`]) and `SCHED_FIFO` for the thread that acquired the
/// guard ([`set_realtime_priority`]). What the system refuses is listed in
/// [`WakeGuard::refusals`] and the run goes on without it. Dropping the guard ends the
/// latency request and returns that thread (whichever thread drops it) to the default
/// scheduler. The daemon and `replay` both use it; neither needs it when nothing is timed
/// (lockstep, `--pacing fast`).
#[derive(Debug)]
pub struct WakeGuard {
    cpu_latency: Option<CpuLatencyRequest>,
    /// The kernel thread id that runs under `SCHED_FIFO`, if any.
    realtime_tid: Option<libc::pid_t>,
    realtime_priority: Option<i32>,
    refusals: Vec<String>,
}

impl WakeGuard {
    /// Asks for what is given: `cpu_latency_us` (a latency QoS request) and
    /// `realtime_priority` (1-99, for the calling thread). `None` asks for nothing.
    pub fn acquire(cpu_latency_us: Option<u32>, realtime_priority: Option<i32>) -> Self {
        let mut refusals = Vec::new();
        let cpu_latency = cpu_latency_us.and_then(|us| match CpuLatencyRequest::hold(us) {
            Ok(request) => Some(request),
            Err(e) => {
                refusals.push(format!(
                    "no CPU latency request ({CPU_LATENCY_QOS}: {e}): an idle CPU may be slow \
                     to wake"
                ));
                None
            }
        });
        let realtime_tid =
            realtime_priority.and_then(|priority| match set_realtime_priority(priority) {
                // SAFETY: gettid has no preconditions.
                Ok(()) => Some(unsafe { libc::gettid() }),
                Err(e) => {
                    refusals.push(format!(
                        "no SCHED_FIFO at priority {priority} ({e}): wake-ups may wait behind \
                         other processes"
                    ));
                    None
                }
            });
        Self {
            cpu_latency,
            realtime_priority: realtime_tid.and(realtime_priority),
            realtime_tid,
            refusals,
        }
    }

    /// The CPU latency request held, in µs.
    pub fn cpu_latency_us(&self) -> Option<u32> {
        self.cpu_latency.as_ref().map(|r| r.latency_us)
    }

    /// The `SCHED_FIFO` priority the acquiring thread runs at.
    pub fn realtime_priority(&self) -> Option<i32> {
        self.realtime_priority
    }

    /// What the system refused, one sentence each.
    pub fn refusals(&self) -> &[String] {
        &self.refusals
    }
}

impl Drop for WakeGuard {
    fn drop(&mut self) {
        if let Some(tid) = self.realtime_tid {
            let param = libc::sched_param { sched_priority: 0 };
            // SAFETY: a plain syscall with a valid parameter struct; a thread that has ended
            // makes it fail, which is harmless.
            let _ = unsafe { libc::sched_setscheduler(tid, libc::SCHED_OTHER, &param) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy() -> i32 {
        // SAFETY: a plain query of the calling thread's policy.
        unsafe { libc::sched_getscheduler(0) }
    }

    /// The guard raises the acquiring thread and hands it back to the default scheduler when
    /// dropped; without the privilege it says why and leaves the thread as it was.
    #[test]
    fn the_guard_raises_the_thread_and_hands_it_back() {
        let before = policy();
        let guard = WakeGuard::acquire(None, Some(1));
        match guard.realtime_priority() {
            Some(priority) => {
                assert_eq!(priority, 1);
                assert_eq!(policy(), libc::SCHED_FIFO);
                assert!(guard.refusals().is_empty());
            }
            None => {
                assert_eq!(policy(), before);
                assert!(guard.refusals()[0].contains("SCHED_FIFO"), "{guard:?}");
            }
        }
        assert_eq!(guard.cpu_latency_us(), None, "nothing asked, nothing held");
        drop(guard);
        assert_eq!(policy(), libc::SCHED_OTHER);
    }
}
