//! Simulated seconds per wall second of the vehicle model on one thread.
//!
//! `cargo bench -p pty-tests --bench physics`
//!
//! Cases, all measured in the same run:
//! - full model in open water (spot turn: thrusters, lag, fluctuation RNG, hydrodynamics,
//!   broad-phase contact query every step, divergence guard);
//! - full model pressed against a wall (narrow-phase contact and impulse every step);
//! - baseline: the rigid-body RK4 step alone (no thrusters, no contact query, no guard).
//!
//! Target: at least 5,000x real time for the full model.

use std::hint::black_box;
use std::time::Instant;

use eyebot_hil::config::Embedded;
use eyebot_hil::physics::{
    DEFAULT_VEHICLE, DEFAULT_WORLD, InitialState, Model, ThrusterCommand, hdt_command, load_model,
};
use nalgebra::{UnitQuaternion, Vector3};

const STEPS: u64 = 2_000_000;

fn model() -> Model {
    load_model(&Embedded, DEFAULT_VEHICLE, DEFAULT_WORLD).expect("embedded configs load")
}

fn start(north: f64) -> InitialState {
    InitialState {
        position_m: Vector3::new(north, 6.25, 0.5),
        attitude: UnitQuaternion::identity(),
        velocity_body_mps: Vector3::zeros(),
        angular_velocity_body_radps: Vector3::zeros(),
    }
}

fn commands(m: &Model, p: [f64; 4]) -> [ThrusterCommand; 4] {
    std::array::from_fn(|i| hdt_command(&m.vehicle().thrusters[i].hdt_duty, p[i]))
}

/// Best of three timings of `STEPS` steps, in seconds.
fn time(mut run: impl FnMut()) -> f64 {
    (0..3)
        .map(|_| {
            let t = Instant::now();
            run();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn report(name: &str, dt_s: f64, wall_s: f64) -> f64 {
    let ns = wall_s / STEPS as f64 * 1e9;
    let factor = STEPS as f64 * dt_s / wall_s;
    println!("{name:<44} {ns:>8.1} ns/step {factor:>12.0} x real time");
    factor
}

fn main() {
    let m = model();
    let dt = m.step_s();
    println!(
        "physics bench: step {} ms, {STEPS} steps per case, best of 3, one thread",
        dt * 1e3
    );

    let open_water = commands(&m, [-100.0, 100.0, 30.0, 30.0]);
    let full = time(|| {
        let mut s = m.initial_state(&start(12.5), 1);
        for _ in 0..STEPS {
            if m.step(&mut s, &open_water).is_err() {
                panic!("open-water run diverged");
            }
        }
        black_box(&s);
    });
    let full_x = report("full model, open water (spot turn)", dt, full);

    let into_wall = commands(&m, [100.0, 100.0, 100.0, 100.0]);
    let wall = time(|| {
        // Starts against the north wall, diving: contacts with the wall (and later the floor).
        let mut s = m.initial_state(&start(24.3), 1);
        for _ in 0..STEPS {
            if m.step(&mut s, &into_wall).is_err() {
                panic!("wall run diverged");
            }
        }
        assert!(
            s.contact_steps() > STEPS / 2,
            "the wall case must be in contact"
        );
        black_box(&s);
    });
    report("full model, pressed against wall and floor", dt, wall);

    let bare = time(|| {
        let mut s = m.initial_state(&start(12.5), 1);
        for _ in 0..STEPS {
            m.step_rigid_body_only(&mut s);
        }
        black_box(&s);
    });
    let bare_x = report("baseline: rigid-body RK4 only", dt, bare);

    println!(
        "full model costs {:.2}x the baseline step; goal >= 5000x real time: {}",
        bare_x / full_x,
        if full_x >= 5000.0 { "met" } else { "NOT met" }
    );
}
