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

/// Returns the calling thread to the default scheduler.
pub fn clear_realtime_priority() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: as above; failure leaves the thread as it was, which is harmless.
    let _ = unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &param) };
}
