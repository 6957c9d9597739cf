//! Byte transports for the links: pseudo-terminals created in-process, real serial devices,
//! and loopback TCP; plus the line settings that pace every byte at the configured baud.

pub mod latency;
pub mod line;
pub mod pacer;
pub mod pty;
pub mod serial;
pub mod symlink;
pub mod timer;

pub use latency::{CPU_LATENCY_QOS, CpuLatencyRequest, WakeGuard, set_realtime_priority};
pub use line::{FlowControl, LineSettings, Parity};
pub use timer::PreciseTimer;
