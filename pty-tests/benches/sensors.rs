//! Cost of the whole sensor suite per simulated second, next to a baseline measured in the
//! same run. `cargo bench -p pty-tests --bench sensors`.
//!
//! Scenario: Mako (mako-2008 sensors) in a 25 x 10 x 3 m box pool, circling slowly, physics
//! step 1 ms (1000 updates per simulated second). Each simulated second: 1000 `update`s,
//! the EyeBot reading depth + velocity + 3 accelerometer channels every 10 ms (500 ADC
//! reads), compass in continuous mode (2.5 readings), both sonar controllers pinging at 1 Hz
//! with 19-ray cones, events polled every step.
//! Baseline: the same loop building the same `VehicleState` copies without sensors.

use std::hint::black_box;
use std::time::Instant;

use eyebot_hil::config::Embedded;
use eyebot_hil::physics::state::VehicleState;
use eyebot_hil::sensors::config::AdcSource;
use eyebot_hil::sensors::scene::{BoxPool, at_rest};
use eyebot_hil::sensors::{SensorSuite, SensorsConfig};
use nalgebra::{UnitQuaternion, Vector3};

const DT_S: f64 = 0.001;

fn state(t: f64) -> VehicleState {
    let yaw = 0.1 * t;
    let mut s = at_rest(
        t,
        Vector3::new(12.5 + 3.0 * yaw.sin(), 5.0 - 3.0 * yaw.cos(), 1.2),
        UnitQuaternion::from_euler_angles(0.0, 0.02, yaw),
    );
    s.velocity_body_mps.x = 0.3;
    s.velocity_water_body_mps.x = 0.3;
    s.thruster_effort = [0.6, 0.5, 0.1, 0.3];
    s
}

fn main() {
    let config = SensorsConfig::load(&Embedded, "sensors/mako-2008.toml").expect("config loads");
    let pool = BoxPool::new(25.0, 10.0, 3.0);
    let sim_s = 200.0;
    let steps = (sim_s / DT_S) as u64;

    // Baseline: iterate the state copies.
    let t0 = Instant::now();
    let mut acc = 0.0;
    for k in 0..steps {
        let s = black_box(state(k as f64 * DT_S));
        acc += s.position_m.x;
    }
    black_box(acc);
    let baseline = t0.elapsed().as_secs_f64();

    let (full, events) = run(&config, &pool, steps, 1);
    let (full10, _) = run(&config, &pool, steps, 10);

    let per_sim_s_us = |secs: f64| secs / sim_s * 1e6;
    println!("simulated {sim_s} s at dt = {DT_S} s ({steps} steps), {events} compass+sonar events");
    println!(
        "baseline (state copies only):       {:8.2} us per simulated second",
        per_sim_s_us(baseline)
    );
    for (label, secs) in [("every 1 ms step", full), ("every 10 ms", full10)] {
        println!(
            "sensors updated {label:<16} {:8.2} us per simulated second incl. copies ({:.1}x baseline); sensors alone {:8.2} us ({:.1} % of the 200 us budget of 5000x real time)",
            per_sim_s_us(secs),
            secs / baseline,
            per_sim_s_us(secs - baseline),
            per_sim_s_us(secs - baseline) / 200.0 * 100.0
        );
    }
}

/// Runs the scenario, updating the sensors every `every` physics steps; returns the elapsed
/// seconds and the number of events.
fn run(config: &SensorsConfig, pool: &BoxPool, steps: u64, every: u64) -> (f64, usize) {
    let mut suite = SensorSuite::new(config, 1);
    let sources = [
        AdcSource::Depth,
        AdcSource::Velocity,
        AdcSource::AccelX,
        AdcSource::AccelY,
        AdcSource::AccelZ,
    ];
    let mut events = 0usize;
    let mut codes = 0u64;
    let t0 = Instant::now();
    for k in 0..steps {
        let t = k as f64 * DT_S;
        let s = black_box(state(t));
        if k % every == 0 {
            suite.update(&s, pool);
        }
        if k % 10 == 0 {
            for src in sources {
                codes += u64::from(suite.read_source(src, t).unwrap_or(0));
            }
        }
        if suite.compass.poll().is_some() {
            events += 1;
        }
        events += suite.sonar.poll(t).len();
    }
    black_box((codes, events));
    (t0.elapsed().as_secs_f64(), events)
}
