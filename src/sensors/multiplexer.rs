//! The PICAXE sonar multiplexer and its two Navman controllers, as a sans-IO state machine
//! (thesis 3.3.2.2, 4.8).
//!
//! The daemon calls [`SonarSystem::select`] when the EyeBot asks for a transducer,
//! [`SonarSystem::update`] after every physics step, and [`SonarSystem::poll`] to collect the
//! events due by `now`; [`SonarSystem::poll_timeout`] says when the next queued one is due.
//! Time is always an argument (simulated seconds).
//!
//! Timing model (defaults in `configs/sensors/*.toml`, reasoning in `docs/sensors.md`):
//! - `select(T, now)` reaches T's slave at `now + command_latency_s`. If T is already
//!   connected the master acknowledges at once; otherwise the relays move for
//!   `relay_switch_s` (no transducer connected meanwhile) and the acknowledgement
//!   ("commitment", thesis 3.3.2.2) reaches the EyeBot `ack_latency_s` after they settle.
//! - Each controller pings every `period_s` (1 Hz) on its own phase (drawn from the
//!   multiplexer's stream). After its transducer changes it spends `reacquire_pings` pings
//!   re-acquiring the echo and reports nothing.
//! - A valid echo becomes a sentence that reaches the EyeBot `sentence_latency_s` later
//!   (the slave's and the master's serial hops). It carries the controller, not the
//!   transducer: a sentence pinged just before a switch can arrive after the
//!   acknowledgement, so the first range after an ack may still be the previous transducer's
//!   (the "which transducer was that?" problem that made programs read T1, T2, T1).
//!   [`SonarEvent::Range::source`] says which one it really was, for tests and logs only.
//! - A ping of a connected transducer without a valid echo (nothing within the beam and
//!   range, the detection draw of thesis table 4.7 failed, a reverberation beyond range, or
//!   the transducer still re-acquiring after a switch) is a [`SonarEvent::NoEcho`], due
//!   when its sentence would have been. The Navman sends nothing for it (thesis 3.3.2: "returns
//!   only a distance value if the return value of the transducer was valid"); the device
//!   emulator's `invalid_echo` setting decides what the master sends. A ping while the relays
//!   move has no transducer at all and gives no event.

use std::collections::VecDeque;

use rand::RngExt;

use super::config::SonarSettings;
use super::rng::{self, SensorRng};
use super::sonar::{RangeSteps, Transducer, detection_probability};
use crate::physics::state::{RayCaster, VehicleState};

/// Something the multiplexer sends to the EyeBot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SonarEvent {
    /// The relays of `transducer`'s controller are in place.
    Ack { transducer: usize, t_s: f64 },
    /// A range sentence from `controller`.
    Range {
        controller: usize,
        range: RangeSteps,
        /// The transducer that produced it (not on the wire).
        source: usize,
        /// The detection probability used for this ping, 0..=1 (for `$PEBHS`).
        p_detect: f64,
        t_s: f64,
    },
    /// A ping of `source` on `controller` gave no valid echo (module doc).
    NoEcho {
        controller: usize,
        source: usize,
        t_s: f64,
    },
}

impl SonarEvent {
    pub fn t_s(&self) -> f64 {
        match self {
            SonarEvent::Ack { t_s, .. }
            | SonarEvent::Range { t_s, .. }
            | SonarEvent::NoEcho { t_s, .. } => *t_s,
        }
    }
}

/// Misuse of the multiplexer API.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MuxError {
    #[error("transducer {index} does not exist (the multiplexer has 0..=3)")]
    NoSuchTransducer { index: usize },
}

#[derive(Debug, Clone, Copy)]
struct Switch {
    target: usize,
    start_s: f64,
    done_s: f64,
}

#[derive(Debug, Clone)]
struct Controller {
    connected: usize,
    switch: Option<Switch>,
    next_ping_s: f64,
    reacquire_left: u32,
}

/// Four transducers, two controllers, one multiplexer.
#[derive(Debug, Clone)]
pub struct SonarSystem {
    s: SonarSettings,
    transducers: Vec<Transducer>,
    controllers: [Controller; 2],
    events: VecDeque<SonarEvent>,
    rng: SensorRng,
}

impl SonarSystem {
    pub fn new(s: &SonarSettings, master_seed: u64) -> Self {
        let transducers: Vec<Transducer> = s
            .transducers
            .iter()
            .map(|t| Transducer::new(t, s, master_seed))
            .collect();
        let mut rng = rng::stream(master_seed, "sonar.multiplexer");
        let mut controller = |c: usize| Controller {
            connected: transducers
                .iter()
                .position(|t| t.controller == c)
                .unwrap_or(0),
            switch: None,
            next_ping_s: rng.random_range(0.0..s.timing.period_s),
            reacquire_left: 0,
        };
        let controllers = [controller(0), controller(1)];
        Self {
            s: s.clone(),
            transducers,
            controllers,
            events: VecDeque::new(),
            rng,
        }
    }

    pub fn transducers(&self) -> &[Transducer] {
        &self.transducers
    }

    pub fn settings(&self) -> &SonarSettings {
        &self.s
    }

    /// The transducer currently wired to `controller` (after any switch that has completed
    /// by the last update).
    pub fn connected(&self, controller: usize) -> Option<usize> {
        self.controllers.get(controller).map(|c| c.connected)
    }

    /// The EyeBot selects `transducer` at `now`.
    pub fn select(&mut self, transducer: usize, now_s: f64) -> Result<(), MuxError> {
        let c = self
            .transducers
            .get(transducer)
            .ok_or(MuxError::NoSuchTransducer { index: transducer })?
            .controller;
        let t = &self.s.timing;
        let start_s = now_s + t.command_latency_s;
        let ctl = &mut self.controllers[c];
        let current = ctl.switch.map_or(ctl.connected, |sw| sw.target);
        let ack_s = if current == transducer {
            ctl.switch.map_or(start_s, |sw| sw.done_s.max(start_s)) + t.ack_latency_s
        } else {
            let done_s = start_s + t.relay_switch_s;
            ctl.switch = Some(Switch {
                target: transducer,
                start_s,
                done_s,
            });
            done_s + t.ack_latency_s
        };
        self.push(SonarEvent::Ack {
            transducer,
            t_s: ack_s,
        });
        Ok(())
    }

    fn push(&mut self, e: SonarEvent) {
        let at = self.events.partition_point(|x| x.t_s() <= e.t_s());
        self.events.insert(at, e);
    }

    /// Runs the controllers' pings due by `state.t_s`, using that state and `world`.
    pub fn update(&mut self, state: &VehicleState, world: &dyn RayCaster) {
        for c in 0..2 {
            while self.controllers[c].next_ping_s <= state.t_s {
                let ping_s = self.controllers[c].next_ping_s;
                self.controllers[c].next_ping_s += self.s.timing.period_s;
                if let Some(e) = self.ping(c, ping_s, state, world) {
                    self.push(e);
                }
            }
        }
    }

    fn ping(
        &mut self,
        c: usize,
        ping_s: f64,
        state: &VehicleState,
        world: &dyn RayCaster,
    ) -> Option<SonarEvent> {
        let ctl = &mut self.controllers[c];
        if let Some(sw) = ctl.switch {
            if ping_s >= sw.done_s {
                ctl.connected = sw.target;
                ctl.switch = None;
                ctl.reacquire_left = self.s.timing.reacquire_pings;
            } else if ping_s >= sw.start_s {
                // Relays in motion: nothing connected; the new transducer will re-acquire.
                return None;
            }
        }
        let source = ctl.connected;
        let t_s = ping_s + self.s.timing.sentence_latency_s;
        let no_echo = SonarEvent::NoEcho {
            controller: c,
            source,
            t_s,
        };
        if ctl.reacquire_left > 0 {
            ctl.reacquire_left -= 1;
            return Some(no_echo);
        }
        // Crosstalk: this controller hears the other controller's ping instead of its own.
        let crosstalk = self.s.crosstalk_probability > 0.0
            && self.rng.random_bool(self.s.crosstalk_probability);
        let other = self.controllers[1 - c].connected;
        let (range_m, p) = if crosstalk {
            let me = &self.transducers[source];
            let them = &self.transducers[other];
            let Some(echo) = them.echo(state, world, &self.s) else {
                return Some(no_echo);
            };
            let path = echo.range_m + (echo.hit_m - me.origin_m(state)).norm();
            let r = path / 2.0;
            (r, super::sonar::table_probability(&self.s, r))
        } else {
            let tr = &self.transducers[source];
            let Some(echo) = tr.echo(state, world, &self.s) else {
                return Some(no_echo);
            };
            let p = detection_probability(
                &self.s,
                echo.range_m,
                echo.axis_to_normal_deg,
                tr.speed_mps(state),
            );
            (echo.range_m, p)
        };
        let Some(range) = self.transducers[source].report(range_m, p, &self.s, ping_s) else {
            return Some(no_echo);
        };
        Some(SonarEvent::Range {
            controller: c,
            range,
            source,
            p_detect: p,
            t_s,
        })
    }

    /// The events due by `now`, in time order.
    pub fn poll(&mut self, now_s: f64) -> Vec<SonarEvent> {
        let n = self.events.partition_point(|e| e.t_s() <= now_s);
        self.events.drain(..n).collect()
    }

    /// When the next queued event is due. Pings are only known after the physics step that
    /// covers them, so call this after [`Self::update`].
    pub fn poll_timeout(&self) -> Option<f64> {
        self.events.front().map(SonarEvent::t_s)
    }

    /// When the next ping of either controller falls.
    pub fn next_ping_s(&self) -> f64 {
        self.controllers[0]
            .next_ping_s
            .min(self.controllers[1].next_ping_s)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Unit, UnitQuaternion, Vector3};

    use super::*;
    use crate::config::Embedded;
    use crate::sensors::SensorsConfig;
    use crate::sensors::scene::{OpenWater, PlaneWall, at_rest};

    fn events(world: &dyn RayCaster, seed: u64, seconds: f64) -> Vec<SonarEvent> {
        let cfg = SensorsConfig::load(&Embedded, "sensors/mako-2008.toml").unwrap();
        let mut mux = SonarSystem::new(&cfg.sonar, seed);
        let mut out = Vec::new();
        let mut t = 0.0;
        while t < seconds {
            t += 0.01;
            let st = at_rest(t, Vector3::new(5.0, 5.0, 1.5), UnitQuaternion::identity());
            mux.update(&st, world);
            out.extend(mux.poll(t));
        }
        out
    }

    /// In open water every ping of both controllers is a ping without a valid echo, one per
    /// controller per period: the multiplexer's `invalid_echo = "empty"` depends on it.
    #[test]
    fn pings_without_an_echo_are_reported() {
        let events = events(&OpenWater, 3, 10.0);
        let no_echo = |c| {
            events
                .iter()
                .filter(|e| matches!(e, SonarEvent::NoEcho { controller, .. } if *controller == c))
                .count()
        };
        assert!(
            events
                .iter()
                .all(|e| matches!(e, SonarEvent::NoEcho { .. })),
            "{events:?}"
        );
        // 1 Hz over 10 s less the sentence latency: 9 or 10 pings each.
        assert!((9..=10).contains(&no_echo(0)), "{events:?}");
        assert!((9..=10).contains(&no_echo(1)), "{events:?}");
    }

    /// At the edge of the detection table (3.9 m: about 15 %) a wall gives both valid ranges
    /// and failed detections, and a run is a function of the seed, invalid pings included.
    #[test]
    fn a_wall_at_the_edge_of_the_table_gives_ranges_and_invalid_echoes_deterministically() {
        // 3.9 m in front of transducer 0.
        let st = at_rest(0.0, Vector3::new(5.0, 5.0, 1.5), UnitQuaternion::identity());
        let cfg = SensorsConfig::load(&Embedded, "sensors/mako-2008.toml").unwrap();
        let mux = SonarSystem::new(&cfg.sonar, 0);
        let tr = &mux.transducers()[0];
        let axis = tr.axis_world(&st).into_inner();
        let wall = PlaneWall {
            point_m: tr.origin_m(&st) + axis * 3.9,
            normal: Unit::new_normalize(-axis),
        };
        let all = events(&wall, 11, 60.0);
        let ranges: Vec<_> = all
            .iter()
            .filter(|e| matches!(e, SonarEvent::Range { .. }))
            .collect();
        let invalid = all.len() - ranges.len();
        assert!(!ranges.is_empty() && invalid > ranges.len(), "{all:?}");
        // Same seed again: identical, including the invalid ones' times.
        assert_eq!(all, events(&wall, 11, 60.0));
    }
}
