//! The bridge daemon (`eyebot-hil run`): links, device emulators, the time model, recording
//! and the process life cycle around the simulation.

pub mod clock;
pub mod config;
pub mod core;
pub mod link;
pub mod status;
