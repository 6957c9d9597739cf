//! Behaviour of the vehicle model: the thesis rows, determinism, contacts, the free surface,
//! self-righting, currents, ray casts, and random command schedules that must never blow up.

use std::path::Path;

use eyebot_hil::config::{ConfigError, ConfigSource, Directory, Document, Embedded};
use eyebot_hil::physics::experiment::{self, Experiment};
use eyebot_hil::physics::state::{BOW, PORT, RayCaster, STARBOARD, STERN};
use eyebot_hil::physics::{
    self, DEFAULT_VEHICLE, DEFAULT_WORLD, InitialState, Model, Simulation, ThrusterCommand,
    VehicleConfig, WorldConfig, hdt_command,
};
use eyebot_hil::thesis::{self, Context};
use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};
use proptest::prelude::*;

fn vehicle() -> VehicleConfig {
    physics::load_vehicle(&Embedded, DEFAULT_VEHICLE).expect("embedded vehicle")
}

fn world() -> WorldConfig {
    physics::load_world(&Embedded, DEFAULT_WORLD).expect("embedded world")
}

fn model() -> Model {
    Model::new(vehicle(), world())
}

fn at(north: f64, east: f64, depth: f64) -> InitialState {
    InitialState {
        position_m: Vector3::new(north, east, depth),
        attitude: UnitQuaternion::identity(),
        velocity_body_mps: Vector3::zeros(),
        angular_velocity_body_radps: Vector3::zeros(),
    }
}

fn percent(model: &Model, p: [f64; 4]) -> [ThrusterCommand; 4] {
    std::array::from_fn(|i| hdt_command(&model.vehicle().thrusters[i].hdt_duty, p[i]))
}

fn experiment(name: &str) -> Experiment {
    thesis::physics::load_experiment(&Embedded, name).expect("embedded experiment")
}

/// Every vehicle, world and experiment file in configs/ loads and resolves.
#[test]
fn every_physics_config_file_loads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let dir = Directory::new(&root);
    let mut loaded = 0;
    for kind in ["vehicles", "worlds", "experiments"] {
        for entry in std::fs::read_dir(root.join(kind)).expect("configs folder") {
            let path = entry.expect("dir entry").path();
            if path.extension().is_none_or(|e| e != "toml") {
                continue;
            }
            let name = format!(
                "{kind}/{}",
                path.file_name().expect("file name").to_string_lossy()
            );
            let text = dir.read(&name).expect("readable");
            let doc = Document::new(name.clone(), &text);
            let result = match kind {
                "vehicles" => VehicleConfig::from_document(&doc).map(drop),
                "worlds" => WorldConfig::from_document(&doc).map(drop),
                _ => Experiment::from_document(&doc).map(drop),
            };
            result.unwrap_or_else(|e| panic!("{name}: {e}"));
            loaded += 1;
        }
    }
    assert!(loaded >= 8, "only {loaded} files");
}

#[test]
fn vehicle_errors_point_at_the_key() {
    let text = Embedded.read(DEFAULT_VEHICLE).unwrap();
    let bad = text.replace("lag_s = 0.25", "lag_s = -1.0");
    let err = VehicleConfig::from_document(&Document::new("v.toml", &bad)).unwrap_err();
    let line = bad.lines().position(|l| l.starts_with("lag_s")).unwrap() + 1;
    assert!(
        matches!(&err, ConfigError::Invalid { key, line: Some(l), .. } if key == "thrusters.lag_s" && *l == line),
        "{err}"
    );
    let bad = text.replace("gain = 0.97", "gian = 0.97");
    let err = VehicleConfig::from_document(&Document::new("v.toml", &bad)).unwrap_err();
    assert!(err.to_string().contains("gian"), "{err}");
    // CB below CG would capsize: rejected.
    let bad = text.replace(
        "centre_of_buoyancy_m = [0.0, 0.0, -0.02]",
        "centre_of_buoyancy_m = [0.0, 0.0, 0.2]",
    );
    let err = VehicleConfig::from_document(&Document::new("v.toml", &bad)).unwrap_err();
    assert!(
        err.to_string().contains("above the centre of mass"),
        "{err}"
    );
    // The optional N_uv: read when given, refused out of range with its key.
    let set = text.replace("# yaw_uv = 0.0", "yaw_uv = 12.5");
    assert_ne!(set, text, "mako.toml documents yaw_uv");
    let v = VehicleConfig::from_document(&Document::new("v.toml", &set)).unwrap();
    assert_eq!(v.damping_yaw_uv, 12.5);
    let bad = text.replace("# yaw_uv = 0.0", "yaw_uv = 5000.0");
    let err = VehicleConfig::from_document(&Document::new("v.toml", &bad)).unwrap_err();
    assert!(
        matches!(&err, ConfigError::Invalid { key, .. } if key == "damping.yaw_uv"),
        "{err}"
    );
    // The optional N_|u|r likewise.
    let set = text.replace("# yaw_ur = 0.0", "yaw_ur = 3.5");
    assert_ne!(set, text, "mako.toml documents yaw_ur");
    let v = VehicleConfig::from_document(&Document::new("v.toml", &set)).unwrap();
    assert_eq!(v.damping_yaw_ur, 3.5);
    let bad = text.replace("# yaw_ur = 0.0", "yaw_ur = -2000.0");
    let err = VehicleConfig::from_document(&Document::new("v.toml", &bad)).unwrap_err();
    assert!(
        matches!(&err, ConfigError::Invalid { key, .. } if key == "damping.yaw_ur"),
        "{err}"
    );
    // The reverse curve's exponent is the forward one unless given.
    let v = VehicleConfig::from_document(&Document::new("v.toml", &text)).unwrap();
    assert_eq!(
        v.thruster_common.exponent_reverse,
        v.thruster_common.exponent
    );
    let set = text.replace("# exponent_reverse = 1.0", "exponent_reverse = 1.4");
    assert_ne!(set, text, "mako.toml documents exponent_reverse");
    let v = VehicleConfig::from_document(&Document::new("v.toml", &set)).unwrap();
    assert_eq!(v.thruster_common.exponent_reverse, 1.4);
    let bad = text.replace("# exponent_reverse = 1.0", "exponent_reverse = 0.1");
    let err = VehicleConfig::from_document(&Document::new("v.toml", &bad)).unwrap_err();
    assert!(
        matches!(&err, ConfigError::Invalid { key, .. } if key == "thrusters.exponent_reverse"),
        "{err}"
    );
    // A motor's own dead band: none unless given, checked where it is.
    assert!(v.thrusters.iter().all(|t| t.deadband.is_none()));
    let stern = |d: &str| {
        text.replacen(
            "name = \"stern\"",
            &format!("name = \"stern\"\ndeadband = {d}"),
            1,
        )
    };
    let v = VehicleConfig::from_document(&Document::new("v.toml", &stern("0.05"))).unwrap();
    assert_eq!(v.thrusters[3].deadband, Some(0.05));
    assert!(v.thrusters[..3].iter().all(|t| t.deadband.is_none()));
    let err = VehicleConfig::from_document(&Document::new("v.toml", &stern("1.5"))).unwrap_err();
    assert!(
        matches!(&err, ConfigError::Invalid { key, .. } if key == "thruster.3.deadband"),
        "{err}"
    );
}

/// The mass distribution gives the thesis's 35 kg, a CG below the box centre (batteries in
/// the lower hull) and a positive-definite inertia.
#[test]
fn mass_distribution_is_mako() {
    let v = vehicle();
    assert!((v.mass_kg - 35.0).abs() < 1e-9);
    assert!(v.cg_from_box_centre_m.z > 0.0, "CG should sit low");
    assert!(
        v.cb_m.z < -0.03,
        "CB {:?} must be well above the CG",
        v.cb_m
    );
    let eig = v.inertia_kgm2.symmetric_eigenvalues();
    assert!(eig.iter().all(|&e| e > 0.1), "{eig:?}");
}

/// `eyebot-hil validate`'s physics rows, computed the same way, all pass.
#[test]
fn validate_physics_rows_pass() {
    let rows = thesis::physics::rows(&Context {
        configs: &Embedded,
        seed: 1,
    })
    .expect("rows");
    assert_eq!(rows.len(), 8);
    let failed: Vec<_> = rows.iter().filter(|r| !r.pass).collect();
    assert!(
        failed.is_empty(),
        "failing rows:\n{}",
        thesis::render_table(&rows)
    );
}

#[test]
fn same_experiment_twice_is_bit_identical() {
    let m = model();
    let e = experiment(thesis::physics::TURN_ANTICLOCKWISE);
    let a = experiment::trace(&m, &e, 7).unwrap();
    let b = experiment::trace(&m, &e, 7).unwrap();
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x, y);
        assert_eq!(x.position_m.x.to_bits(), y.position_m.x.to_bits());
    }
    // A different seed changes the fluctuation, hence the trajectory.
    let c = experiment::trace(&m, &e, 8).unwrap();
    assert_ne!(a.last(), c.last());
}

/// Stepping in one call or one step per call, with the same command changes, ends in the
/// same state bit for bit (RNG included).
#[test]
fn split_stepping_equals_one_long_run() {
    let cmds = |k: u64, m: &Model| {
        let p = match (k / 300) % 3 {
            0 => [100.0, 100.0, 40.0, 40.0],
            1 => [-100.0, 100.0, 0.0, -20.0],
            _ => [30.0, -60.0, 100.0, 100.0],
        };
        percent(m, p)
    };
    let mut long = Simulation::new(model(), &at(5.0, 6.0, 0.5), 3);
    let mut short = Simulation::new(model(), &at(5.0, 6.0, 0.5), 3);
    for chunk in 0..6 {
        long.set_commands(cmds(chunk * 300, long.model()));
        long.step_n(300).unwrap();
    }
    for k in 0..1800 {
        if k % 300 == 0 {
            short.set_commands(cmds(k, short.model()));
        }
        short.step().unwrap();
    }
    assert_eq!(long.sim_state(), short.sim_state());
    assert_eq!(long.state(), short.state());
    assert!((long.t_s() - 18.0).abs() < 1e-9);
}

/// The sensors' view of a state remembers the state's rates for the next step. Reading it
/// after every step or never gives the same trajectory bit for bit, and a state whose rates
/// one model remembered steps under another model as if nothing were remembered.
#[test]
fn reading_the_state_between_steps_changes_nothing() {
    let m = model();
    let bits = |s: &physics::SimState, m: &Model| {
        let v = m.vehicle_state(s);
        let mut b: Vec<u64> = v.position_m.iter().map(|x| x.to_bits()).collect();
        b.extend(v.attitude.coords.iter().map(|x| x.to_bits()));
        b.extend(v.velocity_body_mps.iter().map(|x| x.to_bits()));
        b.extend(v.specific_force_body_mps2.iter().map(|x| x.to_bits()));
        b
    };
    let mut read = m.initial_state(&at(5.0, 6.0, 0.5), 3);
    let mut unread = read.clone();
    for k in 0..900 {
        let c = percent(&m, [100.0, (k % 200) as f64 - 100.0, 40.0, -30.0]);
        m.vehicle_state(&read);
        m.step(&mut read, &c).unwrap();
        m.step(&mut unread, &c).unwrap();
    }
    assert_eq!(bits(&read, &m), bits(&unread, &m));

    // `read` now remembers its rates under `m`; a model with another drag must not use them.
    let mut draggy = vehicle();
    draggy.damping_linear[0] *= 3.0;
    draggy.damping_linear[5] *= 3.0;
    let other = Model::new(draggy, world());
    let mut forgotten = read.clone();
    other.reanchor(&mut forgotten, &physics::Anchor::default());
    let c = percent(&m, [100.0, 100.0, 0.0, 0.0]);
    for _ in 0..50 {
        other.step(&mut read, &c).unwrap();
        other.step(&mut forgotten, &c).unwrap();
    }
    assert_eq!(bits(&read, &other), bits(&forgotten, &other));
}

/// The 10 ms step is converged: a 2 ms step changes the top speed and the turn by far less
/// than the thesis's tolerances. The thrust fluctuation is switched off for this comparison:
/// its noise is drawn per step, so different steps would see different noise paths.
#[test]
fn ten_ms_step_agrees_with_two_ms() {
    let fine_world = WorldConfig {
        step_s: 0.002,
        ..world()
    };
    let mut quiet = vehicle();
    quiet.thruster_common.fluctuation_rel_std = 0.0;
    let coarse = Model::new(quiet.clone(), world());
    let fine = Model::new(quiet, fine_world);
    let run = |m: &Model, p: [f64; 4], secs: f64| {
        let mut sim = Simulation::new(
            Model::new(m.vehicle().clone(), m.world().clone()),
            &at(3.0, 6.25, 0.5),
            1,
        );
        sim.set_commands(percent(m, p));
        sim.step_n((secs / m.step_s()).round() as u64).unwrap();
        sim.state()
    };
    // Depth hold is not needed: at 0.5 m the buoyancy is constant and the vertical motion slow.
    let a = run(&coarse, [100.0, 100.0, 0.0, 0.0], 10.0);
    let b = run(&fine, [100.0, 100.0, 0.0, 0.0], 10.0);
    let rel = (a.velocity_body_mps.x - b.velocity_body_mps.x).abs() / b.velocity_body_mps.x;
    assert!(rel < 0.01, "surge speed differs by {:.3} %", rel * 100.0);
    let a = run(&coarse, [-100.0, 100.0, 0.0, 0.0], 20.0);
    let b = run(&fine, [-100.0, 100.0, 0.0, 0.0], 20.0);
    let (ya, yb) = (a.euler_rad().2, b.euler_rad().2);
    assert!((ya - yb).abs() < 0.02, "heading after 20 s: {ya} vs {yb}");
}

#[test]
fn rest_reads_minus_g_and_surge_reads_thrust() {
    let m = model();
    let depth = m.floating_depth_m();
    let mut sim = Simulation::new(model(), &at(12.0, 6.0, depth), 1);
    sim.step_n(200).unwrap();
    let s = sim.state();
    let g = m.world().gravity_mps2;
    assert!(
        (s.specific_force_body_mps2 - Vector3::new(0.0, 0.0, -g)).norm() < 1e-3,
        "{:?}",
        s.specific_force_body_mps2
    );
    // Under full thrust the x reading is the surge acceleration (positive, at most ~10 cm/s^2).
    sim.set_commands(percent(&m, [100.0, 100.0, 0.0, 0.0]));
    sim.step_n(100).unwrap();
    let fx = sim.state().specific_force_body_mps2.x;
    assert!(fx > 0.02 && fx < 0.12, "{fx}");
}

/// Floating at the surface: slightly positive, almost fully submerged, and released deep it
/// rises, overshoots a little and settles without leaving the water.
#[test]
fn free_surface_floats_almost_submerged() {
    let m = model();
    let depth = m.floating_depth_m();
    let v = m.vehicle();
    let top = depth - v.half_extents_m.z - v.cg_from_box_centre_m.z;
    assert!(
        top < 0.0 && top > -0.05,
        "top of hull {top} m above the surface"
    );
    let mut sim = Simulation::new(model(), &at(12.0, 6.0, 1.5), 1);
    let mut highest = f64::INFINITY;
    for _ in 0..6000 {
        sim.step().unwrap();
        highest = highest.min(sim.state().position_m.z);
    }
    assert!(
        highest > depth - 0.1,
        "rose to {highest}, floating depth {depth}"
    );
    assert!((sim.state().position_m.z - depth).abs() < 0.01);
}

#[test]
fn roll_and_pitch_right_themselves() {
    let mut start = at(12.0, 6.0, 1.0);
    start.attitude = UnitQuaternion::from_euler_angles(0.5, -0.3, 1.0);
    let mut sim = Simulation::new(model(), &start, 1);
    sim.step_n(3000).unwrap();
    let s = sim.state();
    let (roll, pitch, _) = s.euler_rad();
    assert!(roll.abs() < 0.02 && pitch.abs() < 0.02, "{roll} {pitch}");
    assert!(
        s.angular_velocity_body_radps.norm() < 0.01,
        "still turning: {:?}",
        s.angular_velocity_body_radps
    );
}

#[test]
fn current_carries_the_vehicle() {
    let w = WorldConfig {
        current_mps: Vector3::new(0.1, 0.0, 0.0),
        ..world()
    };
    let mut sim = Simulation::new(Model::new(vehicle(), w), &at(5.0, 6.0, 1.0), 1);
    sim.step_n(6000).unwrap();
    let s = sim.state();
    assert!(
        (s.velocity_body_mps.x - 0.1).abs() < 0.005,
        "{:?}",
        s.velocity_body_mps
    );
    assert!(s.velocity_water_body_mps.norm() < 0.005);
    assert!(s.position_m.x > 8.0);
}

/// Full speed into the north wall: stops at the wall, counts one contact, never passes it.
#[test]
fn wall_stops_the_vehicle_and_is_counted() {
    let m = model();
    let mut sim = Simulation::new(model(), &at(20.0, 6.25, m.floating_depth_m()), 1);
    sim.set_commands(percent(&m, [100.0, 100.0, 0.0, 0.0]));
    let front = m.vehicle().half_extents_m.x + m.vehicle().cg_from_box_centre_m.x;
    let mut touched = false;
    let mut max_x = 0.0f64;
    for _ in 0..6000 {
        sim.step().unwrap();
        let s = sim.state();
        touched |= s.in_contact;
        max_x = max_x.max(s.position_m.x + front * s.attitude.transform_vector(&Vector3::x()).x);
    }
    assert!(touched);
    assert!(sim.contact_count() >= 1);
    assert!(max_x < 25.0 + 0.01, "bow reached {max_x}");
    assert!(sim.state().velocity_body_mps.x.abs() < 0.05);
}

/// A step that trips a divergence guard leaves the state as it was, the thrust noise's
/// stream too: the next step is the one a state that never tried the failed one takes.
#[test]
fn a_failed_step_leaves_the_state_as_it_was() {
    let mut w = world();
    w.max_speed_mps = 0.2;
    let m = Model::new(vehicle(), w);
    let mut state = m.initial_state(&at(12.0, 6.0, 0.5), 7);
    let full = percent(&m, [100.0, 100.0, 0.0, 0.0]);
    let mut failed = None;
    for _ in 0..5000 {
        let before = state.clone();
        if let Err(e) = m.step(&mut state, &full) {
            assert_eq!(state, before, "after {e}");
            failed = Some(before);
            break;
        }
    }
    let untried = failed.expect("full thrust passes 0.2 m/s");
    // On from there under the shipped speed limit, the same step as from a copy.
    let free = model();
    let mut a = untried.clone();
    free.step(&mut a, &full).expect("under the shipped limit");
    free.step(&mut state, &full)
        .expect("under the shipped limit");
    assert_eq!(state, a);
}

#[test]
fn dive_and_hold_reaches_the_target() {
    let m = model();
    let e = experiment("experiments/dive-and-hold.toml");
    let t = experiment::trace(&m, &e, 1).unwrap();
    let last = t.last().unwrap();
    assert!(
        (last.position_m.z - 1.0).abs() < 0.1,
        "{}",
        last.position_m.z
    );
    // Positive buoyancy: holding needs a steady downward thrust.
    assert!(last.thruster_force_n[BOW] > 0.1 && last.thruster_force_n[STERN] > 0.1);
}

#[test]
fn ray_casts_hit_walls_and_floor() {
    let m = model();
    let pool = m.pool();
    let o = Point3::new(12.5, 6.25, 1.0);
    let north = pool
        .cast_ray(&o, &Unit::new_normalize(Vector3::x()), 30.0)
        .unwrap();
    assert!((north.distance_m - 12.5).abs() < 1e-3);
    assert!((north.normal.into_inner() - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-3);
    let down = pool
        .cast_ray(&o, &Unit::new_normalize(Vector3::z()), 30.0)
        .unwrap();
    assert!((down.distance_m - 1.0).abs() < 1e-3);
    assert!(
        pool.cast_ray(&o, &Unit::new_normalize(Vector3::x()), 5.0)
            .is_none()
    );
    let slant = pool
        .cast_ray(&o, &Unit::new_normalize(Vector3::new(0.0, 1.0, 0.0)), 30.0)
        .unwrap();
    assert!((slant.distance_m - 6.25).abs() < 1e-3);
}

#[test]
fn equal_commands_turn_right_and_spot_turns_go_their_way() {
    let m = model();
    let mut sim = Simulation::new(model(), &at(3.0, 6.25, m.floating_depth_m()), 1);
    sim.set_commands(percent(&m, [100.0, 100.0, 0.0, 0.0]));
    sim.step_n(1000).unwrap();
    assert!(sim.state().euler_rad().2 > 0.0);
    for (p, sign) in [([-100.0, 100.0], -1.0), ([100.0, -100.0], 1.0)] {
        let mut sim = Simulation::new(model(), &at(12.0, 6.25, m.floating_depth_m()), 1);
        sim.set_commands(percent(&m, [p[0], p[1], 0.0, 0.0]));
        sim.step_n(300).unwrap();
        assert!(sim.state().angular_velocity_body_radps.z * sign > 0.0);
    }
}

#[test]
fn set_command_rejects_a_fifth_thruster() {
    let mut sim = Simulation::new(model(), &at(5.0, 5.0, 1.0), 1);
    assert!(sim.set_command(4, ThrusterCommand::OFF).is_err());
    assert!(sim.set_command(PORT, ThrusterCommand::OFF).is_ok());
    assert!(sim.set_command(STARBOARD, ThrusterCommand::OFF).is_ok());
}

fn arb_percent() -> impl Strategy<Value = f64> {
    prop_oneof![Just(100.0), Just(-100.0), Just(0.0), -100.0..100.0f64]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Random schedules (full reverse, rapid reversals, starts next to walls and the floor):
    /// never an error, never NaN, never outside the pool, never out of the water.
    #[test]
    fn random_schedules_never_blow_up(
        start in (0.7..24.3f64, 0.7..11.8f64, 0.0..1.7f64, -3.2..3.2f64),
        schedule in prop::collection::vec(
            (1u64..400, [arb_percent(), arb_percent(), arb_percent(), arb_percent()]),
            1..30,
        ),
    ) {
        let m = model();
        let mut init = at(start.0, start.1, start.2);
        init.attitude = UnitQuaternion::from_euler_angles(0.0, 0.0, start.3);
        let mut sim = Simulation::new(model(), &init, 5);
        let v = m.vehicle().clone();
        let size = m.world().pool_m;
        for (steps, p) in schedule {
            sim.set_commands(percent(&m, p));
            for _ in 0..steps {
                sim.step().map_err(|e| TestCaseError::fail(e.to_string()))?;
                let s = sim.state();
                prop_assert!(s.position_m.iter().all(|x| x.is_finite()));
                prop_assert!(s.specific_force_body_mps2.iter().all(|x| x.is_finite()));
                // The CG stays inside the pool walls and above the floor.
                prop_assert!(s.position_m.x > 0.0 && s.position_m.x < size.x, "{:?}", s.position_m);
                prop_assert!(s.position_m.y > 0.0 && s.position_m.y < size.y, "{:?}", s.position_m);
                prop_assert!(s.position_m.z < size.z, "{:?}", s.position_m);
                // Never out of the water: the CG stays below the hull's half height above it.
                prop_assert!(s.position_m.z > -v.half_extents_m.z, "flew out: {:?}", s.position_m);
                prop_assert!(s.velocity_body_mps.norm() < 2.0);
            }
        }
    }
}

/// The added mass is inside the solver's mass matrix: the first surge acceleration under
/// thrust is thrust / (m + X_udot), not thrust / m.
#[test]
fn surge_acceleration_uses_the_added_mass() {
    let m = model();
    let mut sim = Simulation::new(model(), &at(12.0, 6.0, 1.0), 1);
    sim.set_commands(percent(&m, [100.0, 100.0, 0.0, 0.0]));
    sim.step().unwrap();
    let s = sim.state();
    let thrust = s.thruster_force_n[PORT] + s.thruster_force_n[STARBOARD];
    let effective = m.vehicle().mass_kg + m.vehicle().added_mass[0];
    let expected = thrust / effective;
    let fx = s.specific_force_body_mps2.x;
    assert!(
        (fx - expected).abs() < 0.01 * expected,
        "{fx} vs {expected}"
    );
    assert!((fx - thrust / m.vehicle().mass_kg).abs() > 0.05 * expected);
}

/// The yaw moment of surge times sway is the Munk moment of the added masses,
/// `(a_sway - a_surge) u v`, less the lift term `damping.yaw_uv` (`N_uv`): a vehicle sliding
/// sideways under way starts to turn at that moment over its yaw inertia, and an `N_uv` equal
/// and opposite to the Munk coefficient leaves it without a turn.
#[test]
fn surge_times_sway_turns_by_the_munk_moment_less_n_uv() {
    let (u, v) = (0.3, 0.1);
    let yaw_rate_after = |n_uv: f64| {
        let mut vehicle = vehicle();
        vehicle.damping_yaw_uv = n_uv;
        let m = Model::new(vehicle, world());
        let mut start = at(12.0, 6.0, 1.0);
        start.velocity_body_mps = Vector3::new(u, v, 0.0);
        let mut sim = Simulation::new(m, &start, 1);
        sim.step().unwrap();
        sim.state().angular_velocity_body_radps.z
    };
    let v0 = vehicle();
    let munk = v0.added_mass[1] - v0.added_mass[0];
    let i_zz = v0.inertia_kgm2[(2, 2)] + v0.added_mass[5];
    let dt = world().step_s;
    for n_uv in [0.0, 20.0, -15.0] {
        let expected = -(munk + n_uv) * u * v / i_zz * dt;
        let got = yaw_rate_after(n_uv);
        assert!(
            (got - expected).abs() < 0.02 * expected.abs(),
            "N_uv {n_uv}: yaw rate {got} after one step, expected {expected}"
        );
    }
    let cancelled = yaw_rate_after(-munk);
    assert!(
        cancelled.abs() < 0.02 * (munk * u * v / i_zz * dt).abs(),
        "N_uv = -(a_sway - a_surge) cancels the Munk moment: {cancelled}"
    );
}

/// `damping.yaw_ur` (`N_|u|r`) damps a turn in proportion to the forward speed, ahead or
/// astern alike: a vehicle turning at `r` while moving at `u` loses `N_|u|r |u| r / I_zz` of yaw
/// rate per second more than without it, and a vehicle turning on the spot loses nothing more.
#[test]
fn yaw_damping_under_way_grows_with_forward_speed() {
    let r = 0.4;
    let yaw_rate_after = |u: f64, n_ur: f64| {
        let mut vehicle = vehicle();
        vehicle.damping_yaw_ur = n_ur;
        let m = Model::new(vehicle, world());
        let mut start = at(12.0, 6.0, 1.0);
        start.velocity_body_mps = Vector3::new(u, 0.0, 0.0);
        start.angular_velocity_body_radps = Vector3::new(0.0, 0.0, r);
        let mut sim = Simulation::new(m, &start, 1);
        sim.step().unwrap();
        sim.state().angular_velocity_body_radps.z
    };
    let v0 = vehicle();
    let i_zz = v0.inertia_kgm2[(2, 2)] + v0.added_mass[5];
    let dt = world().step_s;
    let n_ur = 6.0;
    for u in [0.3f64, -0.2] {
        let expected = -n_ur * u.abs() * r / i_zz * dt;
        let got = yaw_rate_after(u, n_ur) - yaw_rate_after(u, 0.0);
        assert!(
            (got - expected).abs() < 0.02 * expected.abs(),
            "u {u}: extra yaw-rate change {got} in one step, expected {expected}"
        );
    }
    let on_the_spot = yaw_rate_after(0.0, n_ur) - yaw_rate_after(0.0, 0.0);
    assert!(
        on_the_spot.abs() < 1e-12,
        "no extra damping at rest: {on_the_spot}"
    );
}
