//! The simulated Mako behind the devices: the physics and the sensor suite, stepped together.
//!
//! [`MakoPlant`] implements the devices' [`Plant`] (what an ADC read, a compass read, a
//! thruster command or a sonar select does) and the core's [`Model`] (fixed-step advance).
//! After every physics step the sensors sample the new state, so every reading the devices
//! hand out is of a state the physics really passed through.

use firmware_protocol::sensor_link::{
    CalibrationAction, CalibrationState, Direction, ThrusterCommand,
};
use nalgebra::{UnitQuaternion, Vector3};

use super::Model;
use crate::SimNanos;
use crate::devices::{CalibrationProgress, CalibrationRefused, CompassSample, Plant, SonarEvent};
use crate::physics::state::VehicleState;
use crate::physics::{self, InitialState, PhysicsError, Simulation};
use crate::sensors::{self, CompassMode, SensorSuite, SensorsConfig};

/// Physics and sensors of one run.
pub struct MakoPlant {
    sim: Simulation,
    sensors: SensorSuite,
    step_ns: u64,
    resolution_m: f64,
    calibration: CalibrationProgress,
    /// Sonar events taken from the sensor model, not yet due.
    sonar_events: Vec<sensors::SonarEvent>,
    /// Each transducer's controller (sensor-model index order).
    transducer_controller: Vec<usize>,
    /// The controller whose sentences the master forwards: the one that owns the last
    /// acknowledged transducer; `None` from a select until its ack (PROTOCOL.md 1.2).
    forwarding: Option<usize>,
    /// The configured start: position and heading (rad), for a reset from the live view.
    start: (Vector3<f64>, f64),
    /// The sensors' reading state saved for a TIME_STEP's take-back.
    readings_saved: Option<ReadingState>,
}

/// What an ADC or compass read changes in the sensor suite (noise streams, the converter's
/// carry-over, error models sampled on read); the sonar is never touched by a read.
#[derive(Debug, Clone)]
struct ReadingState {
    adc: sensors::AdcBoard,
    depth: sensors::DepthSensor,
    velocity: sensors::PaddleWheel,
    accelerometer: sensors::Accelerometer,
    compass: sensors::Compass,
}

impl std::fmt::Debug for MakoPlant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MakoPlant")
            .field("t_s", &self.sim.t_s())
            .finish_non_exhaustive()
    }
}

fn ns(t_s: f64) -> SimNanos {
    (t_s * 1e9).round().max(0.0) as SimNanos
}

impl MakoPlant {
    /// A plant at rest at `position_m` heading `heading_deg` (its reset pose too), in `model`'s
    /// world, with `sensors_config`'s sensors; `seed` draws every noise stream.
    pub fn at_start(
        model: physics::Model,
        sensors_config: &SensorsConfig,
        position_m: Vector3<f64>,
        heading_deg: f64,
        seed: u64,
    ) -> Self {
        let initial = InitialState {
            position_m,
            attitude: UnitQuaternion::from_euler_angles(0.0, 0.0, heading_deg.to_radians()),
            velocity_body_mps: Vector3::zeros(),
            angular_velocity_body_radps: Vector3::zeros(),
        };
        let mut plant = Self::new(Simulation::new(model, &initial, seed), sensors_config, seed);
        plant.start = (position_m, heading_deg.to_radians());
        plant
    }

    /// A plant from an already built simulation and sensor settings.
    pub fn new(sim: Simulation, sensors_config: &SensorsConfig, seed: u64) -> Self {
        let step_ns = ns(sim.model().step_s());
        let state = sim.state();
        let start = (state.position_m, state.euler_rad().2);
        let mut sensors = SensorSuite::new(sensors_config, seed);
        // The Vector 2X on Mako runs free (master mode, about 2.5 readings a second); the
        // device emulator hands out its latest completed reading.
        sensors.compass.set_mode(CompassMode::Continuous, sim.t_s());
        sensors.update(&sim.state(), sim.ray_caster());
        Self {
            resolution_m: sensors_config.sonar.resolution_m,
            sim,
            sensors,
            step_ns,
            calibration: CalibrationProgress {
                state: CalibrationState::Idle,
                points: 0,
            },
            sonar_events: Vec::new(),
            // At power-up the master forwards (both controllers' sentences) until the first
            // select; `None` only between a select and its acknowledgement (PROTOCOL.md 1.2).
            forwarding: sensors_config
                .sonar
                .transducers
                .first()
                .map(|t| t.controller),
            transducer_controller: sensors_config
                .sonar
                .transducers
                .iter()
                .map(|t| t.controller)
                .collect(),
            start,
            readings_saved: None,
        }
    }

    pub fn simulation(&self) -> &Simulation {
        &self.sim
    }

    pub fn sensors(&self) -> &SensorSuite {
        &self.sensors
    }

    fn t_s(now: SimNanos) -> f64 {
        now as f64 * 1e-9
    }

    fn pull_sonar(&mut self) {
        let due = self.sensors.sonar.poll(f64::INFINITY);
        self.sonar_events.extend(due);
    }
}

impl Plant for MakoPlant {
    fn readings_checkpoint(&mut self) {
        let s = &self.sensors;
        self.readings_saved = Some(ReadingState {
            adc: s.adc.clone(),
            depth: s.depth.clone(),
            velocity: s.velocity.clone(),
            accelerometer: s.accelerometer.clone(),
            compass: s.compass.clone(),
        });
    }

    fn readings_restore(&mut self) {
        if let Some(saved) = self.readings_saved.take() {
            let s = &mut self.sensors;
            s.adc = saved.adc;
            s.depth = saved.depth;
            s.velocity = saved.velocity;
            s.accelerometer = saved.accelerometer;
            s.compass = saved.compass;
        }
    }

    fn adc(&mut self, channel: u8, now: SimNanos) -> u16 {
        self.sensors.read_adc(channel, Self::t_s(now)).unwrap_or(0)
    }

    fn compass(&mut self, _now: SimNanos) -> CompassSample {
        let reading = match self.sensors.compass.latest() {
            Some((_, r)) => r,
            None => self.sensors.compass.convert_now(),
        };
        CompassSample {
            heading_deg: reading.heading_deg,
            raw_x: reading.raw_x,
            raw_y: reading.raw_y,
        }
    }

    fn compass_calibrate(
        &mut self,
        action: CalibrationAction,
        _now: SimNanos,
    ) -> Result<CalibrationProgress, CalibrationRefused> {
        let c = self.calibration;
        let refused = CalibrationRefused {
            action,
            state: c.state,
            points: c.points,
        };
        self.calibration = match action {
            CalibrationAction::Start => {
                self.sensors.compass.calibration_reset();
                CalibrationProgress {
                    state: CalibrationState::Collecting,
                    points: 0,
                }
            }
            CalibrationAction::TakePoint if c.state == CalibrationState::Collecting => {
                self.sensors.compass.calibration_reading();
                let points = c.points + 1;
                CalibrationProgress {
                    state: if points == 2 {
                        CalibrationState::ReadyToFinish
                    } else {
                        CalibrationState::Collecting
                    },
                    points,
                }
            }
            CalibrationAction::Finish if c.state == CalibrationState::ReadyToFinish => {
                CalibrationProgress {
                    state: CalibrationState::Idle,
                    points: 2,
                }
            }
            CalibrationAction::Clear => {
                self.sensors.compass.calibration_reset();
                CalibrationProgress {
                    state: CalibrationState::Idle,
                    points: 0,
                }
            }
            _ => return Err(refused),
        };
        Ok(self.calibration)
    }

    fn compass_reset(&mut self, now: SimNanos) {
        // A finished calibration is kept (the Vector 2X holds it in EEPROM, PROTOCOL.md 2.6).
        self.sensors
            .compass
            .set_mode(CompassMode::Continuous, Self::t_s(now));
        if self.calibration.state != CalibrationState::Idle {
            self.calibration = CalibrationProgress {
                state: CalibrationState::Idle,
                points: 0,
            };
        }
    }

    fn set_thrusters(&mut self, commands: [ThrusterCommand; 4], _now: SimNanos) {
        self.sim
            .set_commands(commands.map(|c| physics::ThrusterCommand {
                duty: c.duty,
                direction: match c.direction {
                    Direction::Forward => physics::Direction::Forward,
                    Direction::Reverse => physics::Direction::Reverse,
                },
            }));
    }

    fn sonar_select(&mut self, transducer: u8, now: SimNanos) {
        // The wire numbers transducers 1..=4, the sensor model 0..=3.
        let index = usize::from(transducer.saturating_sub(1));
        if let Err(e) = self.sensors.sonar.select(index, Self::t_s(now)) {
            crate::warn_limited!("sonar select refused", error = %e, "sonar select refused");
        }
        self.pull_sonar();
        // PROTOCOL.md 1.2: on a select the master stops forwarding until it acknowledges.
        // Sentences already due at `now` were released by earlier polls.
        self.forwarding = None;
    }

    fn sonar_poll(&mut self, now: SimNanos, out: &mut Vec<(SimNanos, SonarEvent)>) {
        self.pull_sonar();
        self.sonar_events
            .sort_by(|a, b| a.t_s().total_cmp(&b.t_s()));
        let due = self.sonar_events.partition_point(|e| ns(e.t_s()) <= now);
        for event in self.sonar_events.drain(..due) {
            let at = ns(event.t_s());
            out.push(match event {
                sensors::SonarEvent::Ack { transducer, .. } => {
                    self.forwarding = self.transducer_controller.get(transducer).copied();
                    (
                        at,
                        SonarEvent::Switched {
                            transducer: transducer as u8 + 1,
                        },
                    )
                }
                // Until the first acknowledgement after a select, the master forwards
                // nothing (PROTOCOL.md 1.2); after it, both controllers' sentences, which
                // do not say which transducer they came from (thesis 4.8).
                sensors::SonarEvent::Range { .. } | sensors::SonarEvent::NoEcho { .. }
                    if self.forwarding.is_none() =>
                {
                    continue;
                }
                sensors::SonarEvent::Range {
                    range,
                    source,
                    p_detect,
                    ..
                } => (
                    at,
                    SonarEvent::Reading {
                        transducer: source as u8 + 1,
                        range_m: Some(f64::from(range.0) * self.resolution_m),
                        quality_pct: (p_detect * 100.0).round().clamp(0.0, 100.0) as u8,
                    },
                ),
                // A ping without a valid echo: the multiplexer's `invalid_echo` setting
                // decides whether the EyeBot hears of it (PROTOCOL.md 1.3, "Invalid echo").
                sensors::SonarEvent::NoEcho { source, .. } => (
                    at,
                    SonarEvent::Reading {
                        transducer: source as u8 + 1,
                        range_m: None,
                        quality_pct: 0,
                    },
                ),
            });
        }
    }

    fn sonar_timeout(&self) -> Option<SimNanos> {
        let queued = self.sonar_events.iter().map(|e| ns(e.t_s())).min();
        let model = self.sensors.sonar.poll_timeout().map(ns);
        // A ping's sentence is only known after the physics step that covers the ping, and
        // is due `sentence_latency_s` later. Without this deadline a realtime bridge with no
        // other traffic stepped only on its idle wake (20 ms wall = 200 ms simulated at speed
        // 10), found sentences already past due and sent them in one burst.
        let ping = ns(self.sensors.sonar.next_ping_s());
        let covering_step = ping.div_ceil(self.step_ns.max(1)) * self.step_ns.max(1);
        queued.into_iter().chain(model).chain([covering_step]).min()
    }
}

impl Model for MakoPlant {
    type Error = PhysicsError;

    fn advance_to(&mut self, t: SimNanos) -> Result<(), PhysicsError> {
        let mut steps = (t / self.step_ns).saturating_sub(self.sim.sim_state().steps());
        while steps > 0 {
            self.sim.step()?;
            self.sensors
                .update(&self.sim.state(), self.sim.ray_caster());
            steps -= 1;
        }
        Ok(())
    }

    fn state(&self) -> VehicleState {
        self.sim.state()
    }

    fn contacts(&self) -> u64 {
        self.sim.contact_count()
    }

    fn place(&mut self, p: &super::Placement) -> Result<(), String> {
        let pool = self.sim.model().world().pool_m;
        for (name, value, max) in [
            ("x_m", p.x_m, pool.x),
            ("y_m", p.y_m, pool.y),
            ("depth_m", p.depth_m, pool.z),
        ] {
            if !(value.is_finite() && (0.0..=max).contains(&value)) {
                return Err(format!("{name} {value}: outside the pool (0 to {max} m)"));
            }
        }
        if !p.heading_deg.is_finite() {
            return Err(format!(
                "heading_deg {}: expected a number of degrees",
                p.heading_deg
            ));
        }
        self.sim.place(
            Vector3::new(p.x_m, p.y_m, p.depth_m),
            p.heading_deg.to_radians(),
        );
        self.sensors
            .update(&self.sim.state(), self.sim.ray_caster());
        Ok(())
    }

    fn set_current(&mut self, north_mps: f64, east_mps: f64) -> Result<(), String> {
        for (name, value) in [("north_mps", north_mps), ("east_mps", east_mps)] {
            if !(value.is_finite() && value.abs() <= MAX_CURRENT_MPS) {
                return Err(format!(
                    "{name} {value}: expected -{MAX_CURRENT_MPS} to {MAX_CURRENT_MPS} m/s"
                ));
            }
        }
        self.sim.set_current(Vector3::new(north_mps, east_mps, 0.0));
        Ok(())
    }

    fn reset_pose(&mut self) -> Result<(), String> {
        let (position, heading) = self.start;
        self.sim.place(position, heading);
        self.sensors
            .update(&self.sim.state(), self.sim.ray_caster());
        Ok(())
    }
}

/// The strongest water current the live view may set (a pool has none near it).
pub const MAX_CURRENT_MPS: f64 = 2.0;

#[cfg(test)]
mod tests {
    use firmware_protocol::sensor_link::{AdcChannel, Message, Reading, Readings};

    use super::*;
    use crate::config::{ConfigSource, DEFAULT_CONFIG, Document, Embedded};
    use crate::daemon::config::DaemonConfig;
    use crate::daemon::plant::devices;
    use crate::engine::{Carries, Engine, LineSpec};
    use crate::transport::LineSettings;

    /// Regression: a ping's sentence is known only after the physics step that covers the
    /// ping, and no deadline announced that step. A realtime bridge with no other traffic
    /// stepped only on its idle wake (200 ms simulated at speed 10), found each sentence
    /// already past due and wrote all its bytes at once instead of one per character time.
    #[test]
    fn sonar_sentences_leave_byte_by_byte_when_the_bridge_steps_only_to_its_deadlines() {
        let text = Embedded.read(DEFAULT_CONFIG).unwrap();
        let mut config = DaemonConfig::resolve(&Document::new("default", &text)).unwrap();
        // 1.5 m off the west wall: the port transducers see it.
        config.start.position_m = nalgebra::Vector3::new(3.0, 1.5, 0.5);
        let plant = MakoPlant::from_config(&Embedded, &config).unwrap();
        let (board, mux) = devices(&config);
        let lines = [LineSpec {
            name: "sonar",
            carries: Carries::SONAR,
            settings: LineSettings::n81(4800),
            tx_queue_bytes: 4096,
            release_quantum_ns: 1_000_000,
        }];
        let mut core = Engine::new(plant, board, mux, &lines, false);
        core.receive(0, b"@S1\r").unwrap();
        // The daemon's realtime loop at speed 10: wake at the next deadline, or after the
        // idle wake of 20 ms wall = 200 ms simulated.
        let (mut sentences, mut largest_chunk) = (0, 0);
        while core.now() < 20_000_000_000 {
            let idle = core.now() + 200_000_000;
            core.advance_to(core.next_deadline().map_or(idle, |d| d.min(idle)))
                .unwrap();
            if let Some(out) = core.take_output(0) {
                if out.starts_with(b"@A") {
                    continue;
                }
                largest_chunk = largest_chunk.max(out.len());
                sentences += out.iter().filter(|&&b| b == b'\n').count();
            }
        }
        assert!(sentences >= 2, "the wall gave {sentences} sentences");
        assert_eq!(largest_chunk, 1, "sentence bytes were released in bursts");
    }

    /// A lockstep engine on the real plant with a sonar and a sensor line.
    fn lockstep_core() -> Engine<MakoPlant> {
        let text = Embedded.read(DEFAULT_CONFIG).unwrap();
        let mut config = DaemonConfig::resolve(&Document::new("default", &text)).unwrap();
        config.time_mode = crate::daemon::clock::TimeMode::Lockstep;
        let plant = MakoPlant::from_config(&Embedded, &config).unwrap();
        let (board, mux) = devices(&config);
        let line = |name, carries, baud| LineSpec {
            name,
            carries,
            settings: LineSettings::n81(baud),
            tx_queue_bytes: 4096,
            release_quantum_ns: 1_000_000,
        };
        let lines = [
            line("sonar", Carries::SONAR, 4800),
            line("sensor", Carries::SENSOR, 115_200),
        ];
        Engine::new(plant, board, mux, &lines, true)
    }

    /// Sends `message` on the sensor line and returns the reply (pushes skipped).
    fn ask(core: &mut Engine<MakoPlant>, seq: u8, message: Message) -> Message {
        let mut client = firmware_protocol::EyeBotClient::new();
        let mut buf = bytes::BytesMut::new();
        client.encode_request_as(seq, message, &mut buf);
        core.receive(1, &buf).unwrap();
        client.receive(&core.take_output(1).expect("a lockstep reply at once"));
        match client.take_reply(seq) {
            Some(Ok(reply)) => reply,
            other => panic!("the reply to the request: {other:?}"),
        }
    }

    fn adc(core: &mut Engine<MakoPlant>, seq: u8, channel: u8) -> u16 {
        match ask(
            core,
            seq,
            Message::AdcRead {
                channel: AdcChannel::new(channel).unwrap(),
            },
        ) {
            Message::AdcValue { value, .. } => value.get(),
            other => panic!("{other:?}"),
        }
    }

    fn step(
        core: &mut Engine<MakoPlant>,
        seq: u8,
        used: u8,
        ticks: u32,
        thrusters: Option<[ThrusterCommand; 4]>,
        channels: &[u8],
    ) -> Vec<u16> {
        let readings = Readings::new(
            channels
                .iter()
                .map(|&c| Reading::Adc(AdcChannel::new(c).unwrap())),
        )
        .unwrap();
        match ask(
            core,
            seq,
            Message::TimeStep {
                used,
                stop_on_sonar: false,
                ticks,
                thrusters,
                readings,
            },
        ) {
            Message::Step { values, .. } => values.as_slice().to_vec(),
            other => panic!("{other:?}"),
        }
    }

    /// TIME_STEP's readings are the conversions ADC_READs at the same moments would have
    /// made, and values the client did not use are taken back: every later conversion is
    /// what it would have been (the converter's noise and channel carry-over included).
    /// Thrusters set in the step before the advance act as a THRUSTER_SET_ALL would.
    #[test]
    fn step_readings_equal_adc_reads_and_unused_ones_are_taken_back() {
        let full = ThrusterCommand {
            duty: 0,
            direction: Direction::Forward,
        };
        let thrusters = [full, full, ThrusterCommand::OFF, full];
        // One request per conversion.
        let mut bus = lockstep_core();
        let mut seq = 0u8;
        let mut next = || {
            seq = seq.wrapping_add(1);
            seq
        };
        let _ = ask(
            &mut bus,
            next(),
            Message::ThrusterSetAll {
                commands: thrusters,
            },
        );
        let _ = ask(&mut bus, next(), Message::TimeAdvance { ticks: 30 });
        let first: Vec<u16> = [0, 1, 0]
            .iter()
            .map(|&c| adc(&mut bus, next(), c))
            .collect();
        let _ = ask(&mut bus, next(), Message::TimeAdvance { ticks: 2 });
        let second: Vec<u16> = [1, 1, 2, 0]
            .iter()
            .map(|&c| adc(&mut bus, next(), c))
            .collect();
        // The same through TIME_STEP: five readings asked for, three used.
        let mut stepped = lockstep_core();
        let got = step(&mut stepped, 1, 0, 30, Some(thrusters), &[0, 1, 0, 1, 1]);
        assert_eq!(
            &got[..3],
            &first[..],
            "readings made as ADC_READs would make them"
        );
        let got = step(&mut stepped, 2, 3, 2, None, &[1, 1, 2, 0]);
        assert_eq!(got, second, "the two unused readings were taken back");
        assert_eq!(stepped.board().taken_back(), 2);
        // Without the take-back (the client claims it used all five) they differ.
        let mut unfair = lockstep_core();
        let _ = step(&mut unfair, 1, 0, 30, Some(thrusters), &[0, 1, 0, 1, 1]);
        let got = step(&mut unfair, 2, 5, 2, None, &[1, 1, 2, 0]);
        assert_ne!(got, second, "extra conversions change later values");
        // The vehicle is where the bus run left it: same thrusters, same time.
        assert_eq!(stepped.now(), bus.now());
        assert_eq!(
            stepped.model().state().position_m,
            bus.model().state().position_m
        );
    }
}
