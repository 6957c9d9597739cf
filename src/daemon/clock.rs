//! How simulated time relates to the wall clock.
//!
//! The model never reads a clock: it advances in fixed steps to a target simulated time it
//! is given. This module decides that target.
//!
//! - **Lockstep**: simulated time moves only when the client sends a time-advance frame. No
//!   wall clock is involved at all, so a run is a pure function of seed and client bytes.
//! - **Realtime**: simulated time follows `speed x` elapsed wall time from an anchor.
//!
//! **Overrun policy (realtime).** If the loop falls more than `max_lag` of simulated time
//! behind its target (the machine was suspended, a debugger stopped it, the model is too slow
//! at this speed factor), the bridge does *not* burst through the missed steps to catch up:
//! it re-anchors, so simulated time slips against the wall clock by the missed amount, and
//! counts the overrun. Physics is unaffected either way (it always takes the same fixed
//! steps); only the wall-clock moment at which the client sees a given simulated time moves.
//! A burst would instead deliver seconds of sensor data at once, which no real device does.

use std::time::Duration;

use crate::SimNanos;

/// The selected time mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeMode {
    /// Follow the wall clock scaled by `speed` (>= 0.1).
    Realtime { speed: f64 },
    /// Advance only on the client's time frames.
    Lockstep,
}

impl TimeMode {
    pub fn name(&self) -> &'static str {
        match self {
            TimeMode::Realtime { .. } => "realtime",
            TimeMode::Lockstep => "lockstep",
        }
    }

    /// The realtime speed factor; 1 in lockstep.
    pub fn speed(&self) -> f64 {
        match self {
            TimeMode::Realtime { speed } => *speed,
            TimeMode::Lockstep => 1.0,
        }
    }
}

/// Maps wall time elapsed since the daemon started to the simulated time to reach.
#[derive(Debug, Clone)]
pub struct RealtimeMap {
    speed: f64,
    anchor_wall: Duration,
    anchor_sim_ns: SimNanos,
    max_lag_ns: SimNanos,
    overruns: u64,
    slipped_ns: SimNanos,
    /// While paused: the speed to resume at.
    paused: Option<f64>,
}

impl RealtimeMap {
    /// `speed` is simulated seconds per wall second; `max_lag` is the largest backlog (in
    /// simulated time) worked off by stepping rather than by slipping.
    pub fn new(speed: f64, max_lag: Duration) -> Self {
        Self {
            speed,
            anchor_wall: Duration::ZERO,
            anchor_sim_ns: 0,
            max_lag_ns: u64::try_from(max_lag.as_nanos()).unwrap_or(u64::MAX),
            overruns: 0,
            slipped_ns: 0,
            paused: None,
        }
    }

    /// The speed factor (0 while paused).
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The simulated time due at `wall` (wall time since the daemon started).
    pub fn target(&self, wall: Duration) -> SimNanos {
        let elapsed = wall.saturating_sub(self.anchor_wall).as_nanos() as f64;
        self.anchor_sim_ns + (elapsed * self.speed) as SimNanos
    }

    /// The wall time at which simulated time `sim_ns` is due (never, while paused).
    pub fn wall_at(&self, sim_ns: SimNanos) -> Duration {
        if self.speed <= 0.0 {
            return Duration::MAX;
        }
        let ahead = sim_ns.saturating_sub(self.anchor_sim_ns) as f64 / self.speed;
        self.anchor_wall + Duration::from_nanos(ahead as u64)
    }

    /// From `wall` on, simulated time runs at `speed` (a paused map stays paused and
    /// resumes at `speed`).
    pub fn set_speed(&mut self, speed: f64, wall: Duration) {
        if self.paused.is_some() {
            self.paused = Some(speed);
            return;
        }
        self.anchor_sim_ns = self.target(wall);
        self.anchor_wall = wall;
        self.speed = speed;
    }

    /// Holds simulated time where it is at `wall` until [`resume`](Self::resume).
    pub fn pause(&mut self, wall: Duration) {
        if self.paused.is_none() {
            let speed = self.speed;
            self.set_speed(0.0, wall);
            self.paused = Some(speed);
        }
    }

    /// Simulated time follows the wall clock again from `wall`, at the speed before the pause.
    pub fn resume(&mut self, wall: Duration) {
        if let Some(speed) = self.paused.take() {
            self.set_speed(speed, wall);
        }
    }

    pub fn is_paused(&self) -> bool {
        self.paused.is_some()
    }

    /// Tells the map the loop has reached `reached` at `wall`. If that is more than `max_lag`
    /// behind the target, re-anchors (see the module doc) and returns the slip.
    pub fn settle(&mut self, reached: SimNanos, wall: Duration) -> Option<SimNanos> {
        let target = self.target(wall);
        let behind = target.saturating_sub(reached);
        if behind <= self.max_lag_ns {
            return None;
        }
        self.anchor_wall = wall;
        self.anchor_sim_ns = reached;
        self.overruns += 1;
        self.slipped_ns += behind;
        Some(behind)
    }

    /// How often the loop slipped.
    pub fn overruns(&self) -> u64 {
        self.overruns
    }

    /// Total simulated time given up to slips.
    pub fn slipped_ns(&self) -> SimNanos {
        self.slipped_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn speed_scales_elapsed_wall_time() {
        let map = RealtimeMap::new(10.0, Duration::from_millis(100));
        assert_eq!(map.target(Duration::from_millis(250)), 2_500 * MS);
        assert_eq!(map.wall_at(2_500 * MS), Duration::from_millis(250));
    }

    /// Paused, simulated time holds; resumed, it goes on from there at the old speed; a
    /// speed change takes effect from the moment it is made, without a jump.
    #[test]
    fn pause_holds_time_and_speed_changes_do_not_jump() {
        let mut map = RealtimeMap::new(2.0, Duration::from_millis(100));
        map.pause(Duration::from_secs(1));
        assert!(map.is_paused());
        assert_eq!(map.target(Duration::from_secs(5)), 2_000 * MS);
        assert_eq!(map.wall_at(3_000 * MS), Duration::MAX);
        map.resume(Duration::from_secs(5));
        assert_eq!(map.target(Duration::from_secs(6)), 4_000 * MS);
        map.set_speed(10.0, Duration::from_secs(6));
        assert_eq!(map.target(Duration::from_millis(6_100)), 5_000 * MS);
    }

    #[test]
    fn a_small_backlog_is_stepped_off_not_slipped() {
        let mut map = RealtimeMap::new(1.0, Duration::from_millis(100));
        assert_eq!(map.settle(950 * MS, Duration::from_secs(1)), None);
        assert_eq!(map.overruns(), 0);
    }

    #[test]
    fn a_large_backlog_slips_and_is_counted() {
        let mut map = RealtimeMap::new(1.0, Duration::from_millis(100));
        // Suspended for 5 s of wall time after reaching 1 s of simulated time.
        let slip = map.settle(1_000 * MS, Duration::from_secs(6));
        assert_eq!(slip, Some(5_000 * MS));
        assert_eq!(map.overruns(), 1);
        // From there on, simulated time follows the wall clock again without a burst.
        assert_eq!(map.target(Duration::from_secs(6)), 1_000 * MS);
        assert_eq!(map.target(Duration::from_millis(6_500)), 1_500 * MS);
    }
}
