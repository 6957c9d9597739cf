//! eyebot-hil: a hardware-in-the-loop bridge between an EyeBot MK4 controller and a simulated
//! Mako AUV.
//!
//! What flows where (see `docs/ARCHITECTURE.md` for the full picture):
//!
//! ```text
//!  serial port / pty ──bytes──▶ firmware-protocol (frames) ──▶ devices (emulators)
//!                                                               │  thruster commands
//!                                                               ▼
//!                                       physics (fixed-step 6-DOF model + rapier3d pool)
//!                                                               │  vehicle state
//!                                                               ▼
//!  serial port / pty ◀──bytes── firmware-protocol ◀── devices ◀── sensors (error models)
//! ```
//!
//! `main.rs` only parses arguments, installs the tracing subscriber and calls [`cli::main`].

pub mod cli;
pub mod config;
pub mod daemon;
pub mod devices;
pub mod engine;
pub mod gap;
pub mod physics;
pub mod probe;
pub mod record;
pub mod replay;
#[cfg(test)]
mod scratch;
pub mod sensors;
pub mod thesis;
pub mod transcript;
pub mod transport;
pub mod view;

/// Simulated time in nanoseconds since the start of a run. Integer, so the same inputs give
/// the same times bit for bit at any speed.
pub type SimNanos = u64;
