//! The library's entries, one value per effect: every effect `gap` can name here, every
//! discrepancy term calibration fits and every structural rival in [`super::structural`]
//! ([`Effect`] says what each field means). Adding an effect is adding an entry to one of
//! the two, its row in `docs/gap/effects.md` and, when the benchmarks hide it, its name in
//! the independent model.

use super::{Behaviour, Calibration, Effect, Hiding, Kind, structural};
use crate::gap::edit::{Change, File::*, edit};
use crate::physics::VehicleConfig;
use crate::physics::state::{PORT, STARBOARD};
use crate::sensors::config::DepthSettings;

/// Parameter `i` of `params`, 0 ("no change") where it is missing.
pub(super) fn at(params: &[f64], i: usize) -> f64 {
    params.get(i).copied().unwrap_or(0.0)
}

/// Where a change common to every thruster shows: the track, speed, heading, depth and every
/// accelerometer axis.
pub(super) const ALL_THRUSTERS: [&str; 9] = [
    "x_m",
    "y_m",
    "surge_mps",
    "paddle_speed_mps",
    "compass_deg",
    "depth_adc",
    "accel_x_adc",
    "accel_y_adc",
    "accel_z_adc",
];

/// Candidates and structural terms of one form on a pool's runs: each pair differs only by a
/// state most runs hold fixed, so the two make much the same change of the residuals. A yaw
/// moment in sway, `N_v v` (`sway_yaw_coupling`), and the Munk moment in surge times sway,
/// `N_uv u v` (`munk_moment`), differ by the surge speed, and the turns under way of a run
/// are mostly made at the speed its programme cruises at. A depth sensor's offset
/// (`depth_offset`) and the height the hull floats at (`float_depth`) differ by whether the
/// hull is afloat, and most of a run is spent afloat (cosine 0.9999 on the simulator
/// benchmark's manoeuvre; on structure 462421, seed 407999, case 38, 1982.1 against 1982.1).
///
/// The calibration sets the base model's share of the two jointly. A change of either after
/// it is the candidate's to name, first or later: its twin refuses a later name as its
/// structural rival only where the data prefer the twin's form, by more than the delta-BIC
/// margin (`fit::structural_rival`). A tie would otherwise refuse every later name of the
/// form while the same form is named first.
pub const FORM_TWINS: &[(&str, &str)] = &[
    ("sway_yaw_coupling", "munk_moment"),
    ("depth_offset", "float_depth"),
];

/// Physics effects that leave the hull's motion through the water as it was: a steady,
/// uniform current carries the hull with the water. The model integrates the velocity
/// through the water (exact for an irrotational, constant current: `physics::model`) and the
/// re-simulation replays the recorded commands, so the speeds and turn rates the structure's
/// terms act on stay where the baseline runs pinned them; only the ground track moves.
pub const WITH_THE_WATER: &[&str] = &["water_current"];

/// Effects whose two parameters are the components of one vector in a plane: a water current
/// (north and east), a hard-iron field (forward and starboard) and a soft-iron error (the
/// cosine and sine of twice the heading). On runs with nothing new the stray vector such an
/// effect takes up points wherever the run's headings and drift put it, so its between-run
/// spread is the same in every direction: the calibration pools the two components' mean
/// squares ([`crate::gap::calibrate`]). Read per component, three runs that happen to
/// stray east give a north spread a few times too small; on structure 450367 thirty runs of
/// one programme strayed 0.0089 m/s north and east alike (RMS), its three spread runs
/// 0.0027 north and 0.0087 east.
pub const PLANE_VECTORS: &[&str] = &["water_current", "compass_hard_iron", "compass_soft_iron"];

/// The library: the candidates, then the calibration's structural terms
/// ([`structural::TERMS`]). Its order is the order candidates are fitted and reported in.
pub const LIBRARY: [Effect; 45] = concat(CANDIDATES, structural::TERMS);

/// `a` then `b`, in a constant.
const fn concat<const A: usize, const B: usize, const C: usize>(
    a: [Effect; A],
    b: [Effect; B],
) -> [Effect; C] {
    assert!(
        A > 0 && A + B == C,
        "the library's length is its two parts' together"
    );
    let mut out = [a[0]; C];
    let mut i = 0;
    while i < C {
        out[i] = if i < A { a[i] } else { b[i - A] };
        i += 1;
    }
    out
}

/// The effects `gap` may name, in the order they are fitted and reported.
const CANDIDATES: [Effect; 27] = [
    Effect {
        name: "thruster_imbalance",
        parameters: &["differential_gain"],
        scales: &[0.05],
        bounds: &[(-0.5, 0.5)],
        signature: "yaw bias that grows with thrust: heading and track curve the same way at \
                    every heading",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        // A spot turn's opposed thrusts no longer cancel: it creeps ahead or astern.
        also_moves: &["paddle_speed_mps", "accel_x_adc"],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| {
            c.vehicle.thrusters[PORT].gain =
                (c.vehicle.thrusters[PORT].gain * (1.0 + at(p, 0) / 2.0)).clamp(0.1, 2.0);
            c.vehicle.thrusters[STARBOARD].gain =
                (c.vehicle.thrusters[STARBOARD].gain * (1.0 - at(p, 0) / 2.0)).clamp(0.1, 2.0);
        },
        moves_anchors: false,
        summary: &[Behaviour::Turn],
        calibration: Calibration::Joint(3),
        positive: false,
        parameter_error_target: true,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[0.08],
            bridge: |p| {
                vec![
                    edit(
                        Vehicle,
                        "thruster[0].gain",
                        Change::Scale(1.0 + at(p, 0) / 2.0),
                    ),
                    edit(
                        Vehicle,
                        "thruster[1].gain",
                        Change::Scale(1.0 - at(p, 0) / 2.0),
                    ),
                ]
            },
            independent: "thruster_imbalance",
            factor: false,
        }),
    },
    Effect {
        name: "reverse_thrust_asymmetry",
        parameters: &["reverse_ratio_scale"],
        scales: &[0.1],
        bounds: &[(-1.0, 2.0)],
        signature: "track and heading disagree only while a horizontal thruster runs in reverse",
        channels: &["x_m", "y_m", "compass_deg", "accel_x_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| {
            for i in [PORT, STARBOARD] {
                let t = &mut c.vehicle.thrusters[i];
                t.reverse_ratio = (t.reverse_ratio * (1.0 + at(p, 0))).clamp(0.0, 1.0);
            }
        },
        moves_anchors: false,
        summary: &[Behaviour::Turn],
        calibration: Calibration::Joint(2),
        positive: false,
        parameter_error_target: true,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "drag_mismatch",
        parameters: &["surge_linear_scale", "surge_quadratic_scale"],
        scales: &[0.2, 0.2],
        bounds: &[(-0.9, 5.0), (-0.9, 5.0)],
        signature: "speed error that grows with speed; along-track position error",
        channels: &["x_m", "y_m", "paddle_speed_mps", "surge_mps", "accel_x_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| scale_damping(&mut c.vehicle, 0, 1.0 + at(p, 0), 1.0 + at(p, 1)),
        moves_anchors: false,
        summary: &[Behaviour::Speed],
        calibration: Calibration::Joint(4),
        positive: false,
        parameter_error_target: true,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "added_mass",
        parameters: &["surge_added_kg"],
        scales: &[5.0],
        bounds: &[(-30.0, 100.0)],
        signature: "along-track error only after thrust steps (acceleration), none at steady speed",
        channels: &["x_m", "y_m", "paddle_speed_mps", "surge_mps", "accel_x_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| {
            c.vehicle.added_mass[0] = (c.vehicle.added_mass[0] + at(p, 0)).max(0.0);
        },
        moves_anchors: false,
        summary: &[Behaviour::Speed],
        calibration: Calibration::Joint(5),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "thruster_lag",
        parameters: &["lag_s"],
        scales: &[0.2],
        bounds: &[(-1.0, 3.0)],
        signature: "error right after command changes, decaying with a time constant",
        channels: &[
            "x_m",
            "y_m",
            "compass_deg",
            "accel_x_adc",
            "accel_y_adc",
            "depth_adc",
        ],
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| {
            let t = &mut c.vehicle.thruster_common;
            t.lag_s = (t.lag_s + at(p, 0)).max(0.0);
            t.lag_down_s = (t.lag_down_s + at(p, 0)).max(0.0);
        },
        moves_anchors: false,
        summary: &[Behaviour::Speed],
        calibration: Calibration::Joint(6),
        positive: true,
        parameter_error_target: false,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[0.25],
            bridge: |p| vec![edit(Vehicle, "thrusters.lag_s", Change::Add(at(p, 0)))],
            independent: "thruster_lag",
            factor: false,
        }),
    },
    Effect {
        name: "water_current",
        parameters: &["north_mps", "east_mps"],
        scales: &[0.01, 0.01],
        bounds: &[(-0.3, 0.3), (-0.3, 0.3)],
        signature: "drift fixed to the world, independent of heading",
        channels: &["x_m", "y_m"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| {
            c.world.current_mps.x += at(p, 0);
            c.world.current_mps.y += at(p, 1);
        },
        moves_anchors: false,
        summary: &[Behaviour::Speed, Behaviour::Turn],
        calibration: Calibration::No,
        positive: false,
        parameter_error_target: true,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[0.02, -0.015],
            bridge: |p| {
                vec![
                    edit(World, "water.current_mps[0]", Change::Add(at(p, 0))),
                    edit(World, "water.current_mps[1]", Change::Add(at(p, 1))),
                ]
            },
            independent: "water_current",
            factor: false,
        }),
    },
    Effect {
        name: "compass_hard_iron",
        parameters: &["x_ut", "y_ut"],
        scales: &[1.0, 1.0],
        bounds: &[(-50.0, 50.0), (-50.0, 50.0)],
        signature: "compass error once per turn (first harmonic of heading)",
        channels: &["compass_deg", "x_m", "y_m"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| {
            c.sensors.compass.hard_iron_ut[0] += at(p, 0);
            c.sensors.compass.hard_iron_ut[1] += at(p, 1);
        },
        moves_anchors: true,
        summary: &[],
        calibration: Calibration::Joint(11),
        positive: false,
        parameter_error_target: true,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[3.0, 2.0],
            bridge: |p| {
                vec![
                    edit(Sensors, "compass.hard_iron_ut[0]", Change::Add(at(p, 0))),
                    edit(Sensors, "compass.hard_iron_ut[1]", Change::Add(at(p, 1))),
                ]
            },
            independent: "compass_hard_iron",
            factor: false,
        }),
    },
    Effect {
        name: "compass_soft_iron",
        parameters: &["diagonal_difference", "off_diagonal"],
        scales: &[0.02, 0.02],
        bounds: &[(-0.3, 0.3), (-0.3, 0.3)],
        signature: "compass error twice per turn (second harmonic of heading)",
        channels: &["compass_deg", "x_m", "y_m"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| {
            let s = &mut c.sensors.compass.soft_iron;
            s[0][0] += at(p, 0) / 2.0;
            s[1][1] -= at(p, 0) / 2.0;
            s[0][1] += at(p, 1);
            s[1][0] += at(p, 1);
        },
        moves_anchors: true,
        summary: &[],
        calibration: Calibration::No,
        positive: false,
        parameter_error_target: true,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "compass_tilt",
        parameters: &["inclination_deg"],
        scales: &[2.0],
        bounds: &[(-45.0, 45.0)],
        signature: "compass error only while tilted, depending on heading",
        channels: &["compass_deg", "x_m", "y_m"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| {
            let i = &mut c.sensors.compass.inclination_deg;
            *i = (*i + at(p, 0)).clamp(-90.0, 90.0);
        },
        moves_anchors: true,
        summary: &[],
        calibration: Calibration::No,
        positive: true,
        parameter_error_target: true,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "sensor_latency",
        parameters: &["compass_latency_s"],
        scales: &[0.1],
        bounds: &[(-1.0, 2.0)],
        signature: "compass error proportional to the turn rate",
        channels: &["compass_deg", "x_m", "y_m"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| {
            let l = &mut c.sensors.compass.errors.latency_s;
            *l = (*l + at(p, 0)).max(0.0);
        },
        moves_anchors: true,
        summary: &[],
        calibration: Calibration::No,
        positive: true,
        parameter_error_target: false,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[0.4],
            bridge: |p| {
                vec![edit(
                    Sensors,
                    "compass.errors.latency_s",
                    Change::Add(at(p, 0)),
                )]
            },
            independent: "compass_latency",
            factor: false,
        }),
    },
    Effect {
        name: "depth_pwm_emi",
        parameters: &["emi_v_rms_full_duty"],
        scales: &[0.05],
        // The range the sensor configuration accepts (`depth.emi_v_rms_full_duty`): the level
        // is before the depth front end's low-pass, which passes 0.089 of it at the shipped
        // 10 Hz cutoff (2 kHz switching band), so 1 V there is 0.09 V (18 LSB) at the ADC.
        bounds: &[(0.0, DepthSettings::EMI_V_RMS_FULL_DUTY_MAX)],
        signature: "depth variance grows with the stern motor's duty",
        channels: &["depth_adc"],
        also_moves: &[],
        kind: Kind::Variance,
        physics: false,
        extend: |p, c| {
            let e = &mut c.sensors.depth.emi_v_rms_full_duty;
            *e = (*e + at(p, 0)).max(0.0);
        },
        moves_anchors: false,
        summary: &[],
        calibration: Calibration::NoiseLevel,
        positive: true,
        parameter_error_target: false,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[0.03],
            bridge: |p| {
                vec![edit(
                    Sensors,
                    "depth.emi_v_rms_full_duty",
                    Change::Add(at(p, 0)),
                )]
            },
            independent: "depth_emi",
            factor: false,
        }),
    },
    Effect {
        name: "velocity_sensor_scale",
        parameters: &["scale_factor"],
        scales: &[0.1],
        bounds: &[(-0.9, 5.0)],
        signature: "paddle speed off by a constant factor at every speed",
        channels: &["paddle_speed_mps"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| {
            let s = &mut c.sensors.velocity.firmware_scale;
            *s = (*s * (1.0 + at(p, 0))).max(0.01);
        },
        moves_anchors: false,
        summary: &[],
        calibration: Calibration::Joint(20),
        positive: false,
        parameter_error_target: true,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[0.25],
            bridge: |p| {
                vec![edit(
                    Sensors,
                    "velocity.pulses_per_metre",
                    Change::Scale(1.0 + at(p, 0)),
                )]
            },
            independent: "velocity_sensor_scale",
            factor: false,
        }),
    },
    Effect {
        name: "sonar_incidence_dropout",
        parameters: &["max_incidence_deg"],
        scales: &[5.0],
        bounds: &[(-90.0, 90.0)],
        signature: "sonar readings missing when the wall is seen obliquely",
        channels: &["sonar1_m", "sonar2_m", "sonar3_m", "sonar4_m"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| {
            let m = &mut c.sensors.sonar.max_incidence_deg;
            *m = (*m + at(p, 0)).clamp(0.0, 90.0);
        },
        moves_anchors: false,
        summary: &[],
        calibration: Calibration::No,
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    // SubSim's lumped thrust constant was wrong by a factor (thesis 5.1, 5.4), which no
    // per-motor difference can express. `forward_max_n` is shared by all four thrusters, so
    // the vertical pair (depth, heave force) and every thrust step (surge acceleration) show
    // it as much as the track does.
    Effect {
        name: "thrust_gain",
        parameters: &["gain_scale"],
        scales: &[0.2],
        bounds: &[(-0.9, 5.0)],
        signature: "every motor stronger or weaker alike, the vertical pair too: speed, turn rate, \
                    acceleration at thrust steps and depth response off in proportion to thrust",
        channels: &ALL_THRUSTERS,
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| {
            let f = &mut c.vehicle.thruster_common.forward_max_n;
            *f = (*f * (1.0 + at(p, 0))).max(1e-3);
        },
        moves_anchors: false,
        summary: &[Behaviour::Speed, Behaviour::Turn],
        calibration: Calibration::Joint(0),
        positive: false,
        parameter_error_target: true,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[-0.2],
            bridge: |p| {
                vec![edit(
                    Vehicle,
                    "thrusters.forward_max_n",
                    Change::Scale(1.0 + at(p, 0)),
                )]
            },
            independent: "thrust_gain",
            factor: false,
        }),
    },
    // The static curve's shape: thrust ~ ((on - deadband) / (1 - deadband))^exponent. A
    // propeller's thrust grows with rpm|rpm|, and rpm less than linearly with duty, so the
    // exponent of a real motor is rarely the model's 1: a depth hold near half power, a cruise
    // leg and a full-power spin are then off in different proportions, which no common gain
    // can express.
    Effect {
        name: "thrust_curve",
        parameters: &["exponent_scale"],
        scales: &[0.2],
        bounds: &[(-0.5, 2.0)],
        signature: "thrust off in a proportion that changes with the command: part-power legs and \
                    depth holds disagree more or less than full-power spins and dives",
        channels: &ALL_THRUSTERS,
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| {
            let t = &mut c.vehicle.thruster_common;
            t.exponent = (t.exponent * (1.0 + at(p, 0))).max(0.1);
            t.exponent_reverse = (t.exponent_reverse * (1.0 + at(p, 0))).max(0.1);
        },
        moves_anchors: false,
        summary: &[Behaviour::Speed, Behaviour::Turn],
        calibration: Calibration::JointTwoStarts(1, 0.3),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "compass_offset",
        parameters: &["offset_deg"],
        scales: &[1.0],
        bounds: &[(-30.0, 30.0)],
        signature: "compass reads a constant angle off at every heading: the track runs at that \
                    angle to the heading the compass reports, and the surface heading is off",
        channels: &["compass_deg", "x_m", "y_m"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| c.sensors.compass.errors.bias += at(p, 0),
        moves_anchors: true,
        summary: &[],
        calibration: Calibration::Joint(10),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[6.0],
            bridge: |p| vec![edit(Sensors, "compass.errors.bias", Change::Add(at(p, 0)))],
            independent: "compass_offset",
            factor: false,
        }),
    },
    Effect {
        name: "depth_offset",
        parameters: &["offset_m"],
        scales: &[0.02],
        bounds: &[(-0.5, 0.5)],
        signature: "depth reads a constant distance off: visible where the vehicle floats at the \
                    surface, whose depth the buoyancy fixes",
        channels: &["depth_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| c.sensors.depth.errors.bias += at(p, 0),
        moves_anchors: true,
        summary: &[],
        calibration: Calibration::Joint(12),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[0.08],
            bridge: |p| vec![edit(Sensors, "depth.errors.bias", Change::Add(at(p, 0)))],
            independent: "depth_offset",
            factor: false,
        }),
    },
    Effect {
        name: "depth_gain",
        parameters: &["scale_factor"],
        scales: &[0.05],
        bounds: &[(-0.5, 0.5)],
        signature: "depth changes read too large or too small in proportion: dives and climbs \
                    off by a constant factor",
        channels: &["depth_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| {
            let g = &mut c.sensors.depth.volts_per_m;
            *g = (*g * (1.0 + at(p, 0))).max(1e-3);
        },
        moves_anchors: true,
        summary: &[],
        calibration: Calibration::Joint(13),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[0.1],
            bridge: |p| {
                vec![edit(
                    Sensors,
                    "depth.volts_per_m",
                    Change::Scale(1.0 + at(p, 0)),
                )]
            },
            independent: "depth_gain",
            factor: false,
        }),
    },
    Effect {
        name: "accel_x_offset",
        parameters: &["offset_lsb"],
        scales: &[2.0],
        bounds: &[(-200.0, 200.0)],
        signature: "surge accelerometer code off by a constant at every speed and thrust",
        channels: &["accel_x_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| c.analog.accel_offset_lsb[0] += at(p, 0),
        moves_anchors: false,
        summary: &[],
        calibration: Calibration::Joint(14),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "accel_y_offset",
        parameters: &["offset_lsb"],
        scales: &[2.0],
        bounds: &[(-200.0, 200.0)],
        signature: "sway accelerometer code off by a constant in straight runs and turns alike",
        channels: &["accel_y_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| c.analog.accel_offset_lsb[1] += at(p, 0),
        moves_anchors: false,
        summary: &[],
        calibration: Calibration::Joint(15),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "accel_z_offset",
        parameters: &["offset_lsb"],
        scales: &[2.0],
        bounds: &[(-200.0, 200.0)],
        signature: "heave accelerometer code off by a constant (the 1 g reading shifted)",
        channels: &["accel_z_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| c.analog.accel_offset_lsb[2] += at(p, 0),
        moves_anchors: false,
        summary: &[],
        calibration: Calibration::Joint(16),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "accel_x_gain",
        parameters: &["scale_factor"],
        scales: &[0.05],
        bounds: &[(-0.5, 0.5)],
        signature: "surge accelerometer swings too large or small around its zero-g code",
        channels: &["accel_x_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| c.analog.accel_gain_scale[0] += at(p, 0),
        moves_anchors: false,
        summary: &[],
        calibration: Calibration::Joint(17),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "accel_y_gain",
        parameters: &["scale_factor"],
        scales: &[0.05],
        bounds: &[(-0.5, 0.5)],
        signature: "sway accelerometer swings too large or small around its zero-g code",
        channels: &["accel_y_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| c.analog.accel_gain_scale[1] += at(p, 0),
        moves_anchors: false,
        summary: &[],
        calibration: Calibration::Joint(18),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "accel_z_gain",
        parameters: &["scale_factor"],
        scales: &[0.05],
        bounds: &[(-0.5, 0.5)],
        signature: "heave accelerometer's 1 g reading too far from or near its zero-g code",
        channels: &["accel_z_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: false,
        extend: |p, c| c.analog.accel_gain_scale[2] += at(p, 0),
        moves_anchors: false,
        summary: &[],
        calibration: Calibration::Joint(19),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "yaw_damping",
        parameters: &["scale"],
        scales: &[0.2],
        bounds: &[(-0.9, 5.0)],
        signature: "turn rate off for a given thrust couple: spins too fast or slow, heading \
                    overshoots or lags after a turn command",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| scale_damping(&mut c.vehicle, 5, 1.0 + at(p, 0), 1.0 + at(p, 0)),
        moves_anchors: false,
        summary: &[Behaviour::Turn],
        calibration: Calibration::Joint(7),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[1.5],
            bridge: |p| {
                vec![
                    edit(Vehicle, "damping.linear[5]", Change::Scale(at(p, 0))),
                    edit(Vehicle, "damping.quadratic[5]", Change::Scale(at(p, 0))),
                ]
            },
            independent: "yaw_damping",
            factor: true,
        }),
    },
    Effect {
        name: "yaw_damping_quadratic",
        parameters: &["scale"],
        scales: &[0.2],
        bounds: &[(-0.9, 5.0)],
        signature: "fast spins too fast or slow while gentle turns match: the part of the yaw \
                    damping that grows with the turn rate is off",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| scale_damping(&mut c.vehicle, 5, 1.0, 1.0 + at(p, 0)),
        moves_anchors: false,
        summary: &[Behaviour::Turn],
        calibration: Calibration::Joint(8),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: None,
    },
    Effect {
        name: "sway_yaw_coupling",
        parameters: &["n_v_nm_per_mps"],
        scales: &[2.0],
        bounds: &[(-30.0, 30.0)],
        signature: "turns made while moving are tighter or wider than spot turns predict: the \
                    hull's sway in a turn adds a yaw moment, so heading and track disagree only \
                    when turn and speed come together",
        channels: &["compass_deg", "x_m", "y_m", "accel_y_adc"],
        also_moves: &[],
        kind: Kind::Mean,
        physics: true,
        extend: |p, c| c.vehicle.damping_sway_yaw[1] += at(p, 0),
        moves_anchors: false,
        summary: &[Behaviour::Turn],
        calibration: Calibration::Joint(9),
        positive: false,
        parameter_error_target: false,
        submerged_only: false,
        hidden: Some(Hiding {
            bridge_size: &[5.0],
            bridge: |p| vec![edit(Vehicle, "damping.sway_yaw[1]", Change::Add(at(p, 0)))],
            independent: "sway_yaw_coupling",
            factor: false,
        }),
    },
];

/// Scales `axis`'s linear and quadratic damping by `linear` and `quadratic` (each kept >= 0),
/// leaving a little linear damping when both would vanish: every axis stays damped, as the
/// vehicle configuration requires.
pub(super) fn scale_damping(v: &mut VehicleConfig, axis: usize, linear: f64, quadratic: f64) {
    v.damping_linear[axis] = (v.damping_linear[axis] * linear).max(0.0);
    v.damping_quadratic[axis] = (v.damping_quadratic[axis] * quadratic).max(0.0);
    if v.damping_linear[axis] + v.damping_quadratic[axis] <= 0.0 {
        v.damping_linear[axis] = 1e-3;
    }
}
