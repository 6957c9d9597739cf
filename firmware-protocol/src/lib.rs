//! Sans-IO codecs for the wire protocols between an EyeBot MK4 and the Mako devices.
//!
//! The wire specification is `PROTOCOL.md` beside this crate; it is the single source of truth.
