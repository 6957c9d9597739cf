//! The simulated Mako: a fixed-step 6-DOF rigid-body model in a rapier3d pool.
//!
//! Frames (Fossen's conventions): the world frame is NED, x north, y east, z down, with its
//! origin at a pool corner on the water surface, so `z` is depth and yaw is compass heading.
//! The body frame is x forward, y starboard, z down, with its origin at the centre of mass.

pub mod state;
