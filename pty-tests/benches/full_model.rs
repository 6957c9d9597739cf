//! The full model the daemon runs: physics plus every sensor, on one thread.
//!
//! `cargo bench -p pty-tests --bench full_model`
//!
//! Both cases run in the same process, best of three:
//! - **full model**: [`MakoPlant`] (physics + sensor suite, sensors updated after every
//!   physics step) on a spot turn in the default pool, with the reads a Mako program makes:
//!   five ADC channels every 10 ms (depth, paddle wheel, accelerometer x/y/z), the compass
//!   every 100 ms, and a sonar select every 3 s with its events polled;
//! - **baseline**: the same physics alone ([`Simulation::step`]), same commands.
//!
//! Target: the full model at or above 5,000x real time.

use std::hint::black_box;
use std::time::Instant;

use eyebot_hil::config::{ConfigSource, DEFAULT_CONFIG, Document, Embedded};
use eyebot_hil::daemon::config::DaemonConfig;
use eyebot_hil::daemon::plant::MakoPlant;
use eyebot_hil::devices::Plant;
use eyebot_hil::engine::Model as _;
use eyebot_hil::physics::{InitialState, Simulation, load_model};
use firmware_protocol::sensor_link::{Direction, ThrusterCommand};
use nalgebra::{UnitQuaternion, Vector3};

const SIM_S: u64 = 2_000;
const MS: u64 = 1_000_000;

fn config() -> DaemonConfig {
    let text = Embedded.read(DEFAULT_CONFIG).expect("embedded default");
    DaemonConfig::resolve(&Document::new("default", &text)).expect("default resolves")
}

fn spot_turn() -> [ThrusterCommand; 4] {
    let full = |direction| ThrusterCommand { duty: 0, direction };
    [
        full(Direction::Forward),
        full(Direction::Reverse),
        ThrusterCommand {
            duty: 255,
            direction: Direction::Forward,
        },
        ThrusterCommand {
            duty: 255,
            direction: Direction::Forward,
        },
    ]
}

fn full_model(config: &DaemonConfig) -> f64 {
    let mut plant = MakoPlant::from_config(&Embedded, config).expect("plant builds");
    plant.set_thrusters(spot_turn(), 0);
    let mut events = Vec::new();
    let mut reads = 0u64;
    let t = Instant::now();
    for tick in 1..=SIM_S * 100 {
        let now = tick * 10 * MS;
        plant.advance_to(now).expect("no divergence");
        for channel in 0..5 {
            reads += u64::from(black_box(plant.adc(channel, now)));
        }
        if tick % 10 == 0 {
            reads += u64::from(plant.compass(now).heading_deg);
        }
        if tick % 300 == 0 {
            plant.sonar_select((tick / 300 % 4) as u8 + 1, now);
        }
        events.clear();
        plant.sonar_poll(now, &mut events);
    }
    black_box(reads);
    t.elapsed().as_secs_f64()
}

fn physics_only(config: &DaemonConfig) -> f64 {
    let model = load_model(&Embedded, &config.vehicle, &config.world).expect("model loads");
    let step_s = model.step_s();
    let cmds = spot_turn().map(to_physics);
    let initial = InitialState {
        position_m: config.start.position_m,
        attitude: UnitQuaternion::identity(),
        velocity_body_mps: Vector3::zeros(),
        angular_velocity_body_radps: Vector3::zeros(),
    };
    let mut sim = Simulation::new(model, &initial, config.seed);
    sim.set_commands(cmds);
    let steps = (SIM_S as f64 / step_s).round() as u64;
    let t = Instant::now();
    sim.step_n(steps).expect("no divergence");
    black_box(sim.state());
    t.elapsed().as_secs_f64()
}

fn to_physics(c: ThrusterCommand) -> eyebot_hil::physics::ThrusterCommand {
    eyebot_hil::physics::ThrusterCommand {
        duty: c.duty,
        direction: match c.direction {
            Direction::Forward => eyebot_hil::physics::Direction::Forward,
            Direction::Reverse => eyebot_hil::physics::Direction::Reverse,
        },
    }
}

fn best_of_three(mut f: impl FnMut() -> f64) -> f64 {
    (0..3).map(|_| f()).fold(f64::INFINITY, f64::min)
}

fn main() {
    let config = config();
    let full = best_of_three(|| full_model(&config));
    let base = best_of_three(|| physics_only(&config));
    let us_per_sim_s = |wall: f64| wall / SIM_S as f64 * 1e6;
    println!("full model bench: {SIM_S} simulated s per case, best of 3, one thread");
    println!(
        "{:<46} {:>9.1} us per simulated s {:>9.0} x real time",
        "baseline: physics alone",
        us_per_sim_s(base),
        SIM_S as f64 / base
    );
    println!(
        "{:<46} {:>9.1} us per simulated s {:>9.0} x real time",
        "full model: physics + sensors + device reads",
        us_per_sim_s(full),
        SIM_S as f64 / full
    );
    println!(
        "sensors and reads add {:.1} us per simulated s ({:.2}x the baseline); goal >= 5000x real time: {}",
        us_per_sim_s(full - base),
        full / base,
        if SIM_S as f64 / full >= 5000.0 {
            "met"
        } else {
            "NOT met"
        }
    );
}
