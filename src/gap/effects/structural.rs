//! The base model's structural terms: the calibration's discrepancy terms (the vehicle's own
//! coefficients a hull of another structure has differently, fitted by `gap calibrate` and
//! never named) and the structural rivals (tried only against an effect named after others).
//! They follow the candidates in [`super::LIBRARY`].

use super::library::{ALL_THRUSTERS, at, scale_damping};
use super::{Behaviour, Calibration, Effect, Kind};

/// What a structural term of the base model (a calibration discrepancy term or a
/// structural rival) has unless its entry says otherwise: a mean-type physics effect that
/// moves no anchor, has no summary behaviour and is never hidden by the benchmarks.
const STRUCTURAL: Effect = Effect {
    name: "",
    parameters: &[],
    scales: &[],
    bounds: &[],
    signature: "",
    channels: &[],
    also_moves: &[],
    kind: Kind::Mean,
    physics: true,
    extend: |_, _| {},
    moves_anchors: false,
    summary: &[],
    calibration: Calibration::Rival,
    positive: false,
    parameter_error_target: false,
    submerged_only: false,
    hidden: None,
};

/// The structural terms, in the order they are calibrated and reported after the candidates.
pub(super) const TERMS: [Effect; 18] = [
    Effect {
        name: "sway_damping",
        parameters: &["scale"],
        scales: &[0.2],
        bounds: &[(-0.9, 5.0)],
        signature: "the hull slides sideways in turns more or less than modelled: track \
                    curvature and heading rate off together while turning under way",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        extend: |p, c| scale_damping(&mut c.vehicle, 1, 1.0 + at(p, 0), 1.0 + at(p, 0)),
        summary: &[Behaviour::Turn],
        calibration: Calibration::Discrepancy(21),
        ..STRUCTURAL
    },
    Effect {
        name: "sway_added_mass",
        parameters: &["added_kg"],
        scales: &[5.0],
        bounds: &[(-30.0, 100.0)],
        signature: "sideways slip lags or leads after each turn command",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        extend: |p, c| {
            c.vehicle.added_mass[1] = (c.vehicle.added_mass[1] + at(p, 0)).max(0.0);
        },
        summary: &[Behaviour::Turn],
        calibration: Calibration::Discrepancy(22),
        ..STRUCTURAL
    },
    Effect {
        name: "yaw_added_inertia",
        parameters: &["added_kgm2"],
        scales: &[0.5],
        bounds: &[(-2.5, 10.0)],
        signature: "turn rate builds up and dies away faster or slower than modelled; steady \
                    spins match",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        extend: |p, c| {
            c.vehicle.added_mass[5] = (c.vehicle.added_mass[5] + at(p, 0)).max(0.0);
        },
        summary: &[Behaviour::Turn],
        calibration: Calibration::Discrepancy(23),
        ..STRUCTURAL
    },
    Effect {
        name: "sway_from_yaw",
        parameters: &["y_r_n_s"],
        scales: &[1.0],
        bounds: &[(-20.0, 20.0)],
        signature: "a turn pushes the hull sideways: track drifts out of or into spot turns",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        extend: |p, c| c.vehicle.damping_sway_yaw[0] += at(p, 0),
        summary: &[Behaviour::Turn],
        // Not calibrated: in a spin, the sway it makes moves the tracked marker as a marker
        // ahead of the centre of mass does, so baseline runs set it against the marker's
        // position and not against the hull's sway, and a calibrated `Y_r` gives the base
        // model a sway in turns the hull does not have (the sway-yaw coupling then fits with
        // another shape than the hull's).
        calibration: Calibration::Rival,
        ..STRUCTURAL
    },
    Effect {
        name: "heave_damping",
        parameters: &["scale"],
        scales: &[0.2],
        bounds: &[(-0.9, 5.0)],
        signature: "depth changes faster or slower than modelled for the same vertical thrust",
        channels: &["depth_adc", "accel_z_adc"],
        extend: |p, c| scale_damping(&mut c.vehicle, 2, 1.0 + at(p, 0), 1.0 + at(p, 0)),
        calibration: Calibration::Discrepancy(25),
        submerged_only: true,
        ..STRUCTURAL
    },
    Effect {
        name: "net_buoyancy",
        parameters: &["extra_n"],
        scales: &[0.5],
        bounds: &[(-10.0, 10.0)],
        signature: "the vehicle rises or sinks between depth commands more than modelled: a \
                    depth drift of one sign whenever the vertical thrusters are idle",
        channels: &["depth_adc"],
        extend: |p, c| {
            let weight_per_m3 = c.world.water_density_kgpm3 * c.world.gravity_mps2;
            let v = &mut c.vehicle.displaced_volume_m3;
            *v = (*v + at(p, 0) / weight_per_m3).max(1e-4);
        },
        calibration: Calibration::Discrepancy(26),
        submerged_only: true,
        ..STRUCTURAL
    },
    Effect {
        name: "munk_moment",
        parameters: &["n_uv_nm_per_mps2"],
        scales: &[5.0],
        bounds: &[(-80.0, 80.0)],
        signature: "turns under way tighten or open with speed more than spot turns predict: \
                    the yaw moment that grows with surge times sway (the Munk moment less the \
                    hull's lift) is off",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        extend: |p, c| c.vehicle.damping_yaw_uv += at(p, 0),
        summary: &[Behaviour::Turn],
        calibration: Calibration::Discrepancy(28),
        ..STRUCTURAL
    },
    Effect {
        name: "camera_marker_position",
        parameters: &["forward_m", "starboard_m"],
        scales: &[0.05, 0.05],
        bounds: &[(-0.3, 0.3), (-0.3, 0.3)],
        signature: "the tracked position circles in every spin, by the same radius at any \
                    speed: the camera follows a marker away from the centre of mass",
        channels: &["x_m", "y_m"],
        physics: false,
        extend: |p, c| {
            c.camera_marker_body_m[0] += at(p, 0);
            c.camera_marker_body_m[1] += at(p, 1);
        },
        moves_anchors: true,
        // From the marker as stated and 0.1 m ahead of it and behind it: the marker and the
        // hull's sway in spins trade off, and one start can end in the other's minimum.
        calibration: Calibration::DiscrepancyStarts(29, &[0.1, -0.1]),
        ..STRUCTURAL
    },
    Effect {
        name: "float_depth",
        parameters: &["deeper_m"],
        scales: &[0.02],
        bounds: &[(-0.15, 0.15)],
        signature: "at the surface the vehicle floats deeper or higher than modelled while \
                    submerged depths match: the hull's top sits another height above the \
                    centre of mass",
        channels: &["depth_adc"],
        extend: |p, c| c.vehicle.cg_from_box_centre_m.z += at(p, 0),
        calibration: Calibration::Discrepancy(34),
        ..STRUCTURAL
    },
    Effect {
        name: "surface_stiffness",
        parameters: &["waterplane_m2"],
        scales: &[0.01],
        bounds: &[(0.0, 0.3)],
        signature: "afloat the hull bobs faster and settles sooner, or plunges deeper when \
                    released above its float, than modelled: its top cuts the surface with \
                    another area",
        channels: &["depth_adc"],
        // Bobbing heaves and pitches the hull: the heave and surge accelerometers feel it.
        also_moves: &["accel_x_adc", "accel_z_adc"],
        extend: |p, c| {
            let a = &mut c.vehicle.surface_waterplane_m2;
            *a = (*a + at(p, 0)).max(0.0);
        },
        calibration: Calibration::Discrepancy(35),
        ..STRUCTURAL
    },
    Effect {
        name: "surface_damping",
        parameters: &["n_s_per_m"],
        scales: &[20.0],
        bounds: &[(0.0, 500.0)],
        signature: "afloat the hull's bobbing dies out sooner or later than modelled, while \
                    submerged climbs and dives match",
        channels: &["depth_adc"],
        // Bobbing heaves and pitches the hull: the heave and surge accelerometers feel it.
        also_moves: &["accel_x_adc", "accel_z_adc"],
        extend: |p, c| {
            let d = &mut c.vehicle.surface_damping_nspm;
            *d = (*d + at(p, 0)).max(0.0);
        },
        calibration: Calibration::Discrepancy(36),
        ..STRUCTURAL
    },
    Effect {
        name: "depth_port_position",
        parameters: &["forward_m"],
        scales: &[0.1],
        bounds: &[(-0.7, 0.7)],
        signature: "depth readings follow the pitch: a port away from the centre of mass reads \
                    deeper when its end dips",
        channels: &["depth_adc"],
        // The depth it anchors each segment at moves the hull's heave and pitch there, and
        // with them the surge and heave accelerometers.
        also_moves: &["accel_x_adc", "accel_z_adc"],
        physics: false,
        extend: |p, c| c.sensors.depth.position_body_m[0] += at(p, 0),
        moves_anchors: true,
        calibration: Calibration::Discrepancy(27),
        ..STRUCTURAL
    },
    Effect {
        name: "accel_position",
        parameters: &["forward_m"],
        scales: &[0.05],
        bounds: &[(-0.4, 0.4)],
        signature: "the sway accelerometer swings with every change of turn rate, the heave one \
                    with every change of pitch rate, and the surge one dips in fast spins: the \
                    part sits ahead of or behind the centre of mass",
        channels: &["accel_x_adc", "accel_y_adc", "accel_z_adc"],
        physics: false,
        extend: |p, c| c.sensors.accelerometer.position_body_m[0] += at(p, 0),
        calibration: Calibration::Discrepancy(33),
        ..STRUCTURAL
    },
    Effect {
        name: "vertical_thrust_gain",
        parameters: &["gain_scale"],
        scales: &[0.1],
        bounds: &[(-0.5, 1.0)],
        signature: "the vertical pair pushes harder or softer than the stern pair: depth \
                    responds to the vertical commands off in proportion, while speed and turns \
                    match",
        channels: &["depth_adc", "accel_z_adc"],
        extend: |p, c| {
            for t in c.vehicle.thrusters.iter_mut() {
                if t.direction.z.abs() > 0.5 {
                    t.gain = (t.gain * (1.0 + at(p, 0))).max(1e-3);
                }
            }
        },
        calibration: Calibration::Discrepancy(30),
        submerged_only: true,
        ..STRUCTURAL
    },
    Effect {
        name: "yaw_damping_under_way",
        parameters: &["n_ur_nm_s_per_m"],
        scales: &[1.0],
        bounds: &[(-5.0, 30.0)],
        signature: "turns under way are damped more or less than spot turns predict: the yaw \
                    damping that grows with forward speed is off",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        extend: |p, c| c.vehicle.damping_yaw_ur += at(p, 0),
        summary: &[Behaviour::Turn],
        calibration: Calibration::Discrepancy(31),
        ..STRUCTURAL
    },
    Effect {
        name: "reverse_thrust_curve",
        parameters: &["exponent_scale"],
        scales: &[0.2],
        bounds: &[(-0.5, 2.0)],
        signature: "reverse thrust off in a proportion that changes with the command, forward \
                    thrust not: part-power reversing (turns, braking, rising) disagrees more or \
                    less than full reverse",
        channels: &ALL_THRUSTERS,
        extend: |p, c| {
            let e = &mut c.vehicle.thruster_common.exponent_reverse;
            *e = (*e * (1.0 + at(p, 0))).max(0.1);
        },
        calibration: Calibration::Discrepancy(32),
        ..STRUCTURAL
    },
    Effect {
        name: "thruster_spin_down",
        parameters: &["lag_down_s"],
        scales: &[0.2],
        bounds: &[(-1.0, 3.0)],
        signature: "thrust falls off more slowly or quickly than it builds up: the error after \
                    a command is cut or reversed decays on its own time constant",
        channels: &ALL_THRUSTERS,
        extend: |p, c| {
            let t = &mut c.vehicle.thruster_common;
            t.lag_down_s = (t.lag_down_s + at(p, 0)).max(0.0);
        },
        calibration: Calibration::Rival,
        ..STRUCTURAL
    },
    Effect {
        name: "thruster_lag_shape",
        parameters: &["lag_exponent"],
        scales: &[0.3],
        bounds: &[(-0.5, 1.5)],
        signature: "the lag acts on the propeller's speed rather than on its thrust: thrust \
                    builds up late and falls off early, and a command that flickers gives \
                    less mean thrust than the static curve",
        channels: &ALL_THRUSTERS,
        extend: |p, c| {
            let t = &mut c.vehicle.thruster_common;
            t.lag_exponent = (t.lag_exponent + at(p, 0)).clamp(0.5, 3.0);
        },
        calibration: Calibration::Rival,
        ..STRUCTURAL
    },
];
