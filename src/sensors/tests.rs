//! Behaviour tests across the sensor models: ideal values with every error source off, and
//! the signature of each error source.

use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};

use super::compass::wrap_deg;
use super::config::{AdcSource, SensorsConfig};
use super::scene::{OpenWater, PlaneWall, at_rest};
use super::sonar::Transducer;
use super::{Compass, SensorSuite};
use crate::config::Embedded;
use crate::physics::state::STERN;

fn config() -> SensorsConfig {
    SensorsConfig::load(&Embedded, "sensors/mako-2008.toml").expect("embedded config loads")
}

fn pos() -> Vector3<f64> {
    Vector3::new(5.0, 5.0, 1.5)
}

fn yaw(deg: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(0.0, 0.0, deg.to_radians())
}

/// The sample standard deviation (n - 1).
fn std_dev(xs: &[f64]) -> f64 {
    statrs::statistics::Statistics::std_dev(xs)
}

#[test]
fn ideal_suite_returns_the_ideal_quantised_values() {
    let cfg = config().ideal();
    let mut suite = SensorSuite::new(&cfg, 9);
    let lsb = suite.adc.lsb_v();
    for (k, depth) in [0.0, 0.37, 1.234, 2.5, 4.99].into_iter().enumerate() {
        let t = k as f64;
        let att = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3);
        let mut st = at_rest(t, Vector3::new(5.0, 5.0, depth), att);
        st.thruster_effort[STERN] = 1.0;
        suite.update(&st, &OpenWater);
        let sensor_depth = st
            .depth_of_m(&Vector3::from(cfg.depth.position_body_m))
            .max(0.0);
        assert_eq!(
            suite.read_source(AdcSource::Depth, t),
            Some(((sensor_depth / lsb).round() as u16).min(1023)),
            "depth {depth}"
        );
        for (axis, src) in [AdcSource::AccelX, AdcSource::AccelY, AdcSource::AccelZ]
            .into_iter()
            .enumerate()
        {
            let f = st.specific_force_body_mps2[axis];
            let v = (1.65 + 0.8 * f / super::accelerometer::G0_MPS2).clamp(0.45, 2.85);
            assert_eq!(
                suite.read_source(src, t),
                Some((v / lsb).round() as u16),
                "axis {axis}"
            );
        }
    }
    // Compass: level, the rounded magnetic heading.
    for psi in [0.0, 12.4, 90.0, 181.6, 359.4] {
        suite.compass.update(&at_rest(10.0, pos(), yaw(psi)));
        let r = suite.compass.convert_now();
        let expected = (psi - cfg.compass.declination_deg)
            .round()
            .rem_euclid(360.0) as u16;
        assert_eq!(r.heading_deg, expected, "psi {psi}");
    }
}

/// An accelerometer mounted 0.2 m ahead of the centre of mass reads a spin's angular
/// acceleration in its sway axis (2 rad/s^2 x 0.2 m = 0.4 m/s^2, about 6.7 codes at 0.8 V/g)
/// and the spin's centripetal acceleration in surge; one at the centre reads neither.
#[test]
fn an_accelerometer_ahead_of_the_centre_reads_the_spin() {
    let mut cfg = config().ideal();
    let code = |cfg: &SensorsConfig, src| {
        let mut suite = SensorSuite::new(cfg, 9);
        let mut st = at_rest(1.0, pos(), yaw(0.0));
        st.angular_velocity_body_radps.z = 1.0;
        st.angular_accel_body_radps2.z = 2.0;
        suite.update(&st, &OpenWater);
        suite.read_source(src, 1.0).map(f64::from)
    };
    let centre_y = code(&cfg, AdcSource::AccelY).expect("a reading");
    let centre_x = code(&cfg, AdcSource::AccelX).expect("a reading");
    cfg.accelerometer.position_body_m = [0.2, 0.0, 0.0];
    let lsb = SensorSuite::new(&cfg, 9).adc.lsb_v();
    let per_mps2 = 0.8 / super::accelerometer::G0_MPS2 / lsb;
    let ahead_y = code(&cfg, AdcSource::AccelY).expect("a reading");
    let ahead_x = code(&cfg, AdcSource::AccelX).expect("a reading");
    assert!(
        (ahead_y - centre_y - 0.4 * per_mps2).abs() <= 1.0,
        "sway {centre_y} -> {ahead_y}, expected +{:.1} codes",
        0.4 * per_mps2
    );
    assert!(
        (ahead_x - centre_x + 0.2 * per_mps2).abs() <= 1.0,
        "surge {centre_x} -> {ahead_x}, expected -{:.1} codes",
        0.2 * per_mps2
    );
}

#[test]
fn depth_clamps_at_the_surface() {
    let cfg = config().ideal();
    let mut suite = SensorSuite::new(&cfg, 1);
    suite.update(
        &at_rest(0.0, Vector3::new(5.0, 5.0, -1.0), yaw(0.0)),
        &OpenWater,
    );
    assert_eq!(suite.read_source(AdcSource::Depth, 0.0), Some(0));
}

/// Thesis 4.1: the stern motor's PWM adds noise that grows with its duty.
#[test]
fn depth_emi_variance_grows_with_stern_duty_and_the_filter_cuts_it() {
    let run = |duty: f64, filtered: bool| {
        let mut cfg = config();
        cfg.adc.noise_v_rms = 0.0;
        if !filtered {
            cfg.depth.low_pass_cutoff_hz = None;
        }
        let mut suite = SensorSuite::new(&cfg, 4);
        let codes: Vec<f64> = (0..2000)
            .map(|k| {
                let t = f64::from(k) * 0.01;
                let mut st = at_rest(t, Vector3::new(5.0, 5.0, 2.0), yaw(0.0));
                st.thruster_effort[STERN] = -duty;
                suite.update(&st, &OpenWater);
                f64::from(suite.read_source(AdcSource::Depth, t).unwrap())
            })
            .collect();
        std_dev(&codes)
    };
    let (s0, s5, s10) = (run(0.0, false), run(0.5, false), run(1.0, false));
    // 50 mV rms at full duty = 10.2 LSB; half duty 5.1 LSB; none: the 2 mV sensor noise.
    assert!(s0 < 1.0, "{s0}");
    assert!((s5 - 5.2).abs() < 0.5, "{s5}");
    assert!((s10 - 10.3).abs() < 0.8, "{s10}");
    let filtered = run(1.0, true);
    assert!(filtered < s10 / 4.0, "{filtered} vs {s10}");
}

/// Thesis 4.2: a 5 deg tilt gives a once-per-turn error whose size follows from the inclination.
#[test]
fn compass_tilt_error_follows_the_inclination_and_heading() {
    let cfg = config().ideal().compass;
    let mut compass = Compass::new(&cfg, 0);
    let tilt = 5f64.to_radians();
    let tan_i = cfg.inclination_deg.to_radians().tan();
    for k in 0..72 {
        let psi = f64::from(k) * 5.0;
        let att = yaw(psi) * UnitQuaternion::from_euler_angles(0.0, tilt, 0.0);
        compass.update(&at_rest(0.0, pos(), att));
        let r = compass.convert_now();
        let delta = (psi - cfg.declination_deg).to_radians();
        // Pitched nose-up by theta: m = (H cos(theta) cos(delta) - Z sin(theta), -H sin(delta)).
        let predicted = delta
            .sin()
            .atan2(tilt.cos() * delta.cos() - tan_i * tilt.sin())
            .to_degrees();
        let err = wrap_deg(f64::from(r.heading_deg) - predicted);
        assert!(
            err.abs() <= 0.5 + 1e-9,
            "psi {psi}: {} vs {predicted}",
            r.heading_deg
        );
    }
}

fn error_curve(cfg: &super::config::CompassSettings) -> Vec<f64> {
    let mut compass = Compass::new(cfg, 0);
    (0..360)
        .map(|k| {
            let psi = f64::from(k);
            compass.update(&at_rest(0.0, pos(), yaw(psi)));
            let m = compass.convert_now();
            wrap_deg(f64::from(m.heading_deg) - (psi - cfg.declination_deg))
        })
        .collect()
}

/// Fourier amplitude of harmonic `n` of an error curve sampled at 1 deg.
fn harmonic(errors: &[f64], n: f64) -> f64 {
    let (mut c, mut s) = (0.0, 0.0);
    for (k, e) in errors.iter().enumerate() {
        let a = n * (k as f64).to_radians();
        c += e * a.cos();
        s += e * a.sin();
    }
    2.0 * (c * c + s * s).sqrt() / errors.len() as f64
}

#[test]
fn hard_iron_is_once_per_turn_and_calibration_removes_it() {
    let mut cfg = config().ideal().compass;
    cfg.hard_iron_ut = [4.0, -3.0];
    let e = error_curve(&cfg);
    let (h1, h2) = (harmonic(&e, 1.0), harmonic(&e, 2.0));
    // |h| / H = 5 / 23.6 -> ~12 deg once per turn.
    assert!(h1 > 10.0 && h2 < h1 / 5.0, "h1 {h1} h2 {h2}");
    let mut compass = Compass::new(&cfg, 0);
    compass.update(&at_rest(0.0, pos(), yaw(37.0)));
    compass.calibration_reading();
    compass.update(&at_rest(0.0, pos(), yaw(217.0)));
    assert!(matches!(
        compass.calibration_reading(),
        super::Calibration::Done { .. }
    ));
    for k in 0..36 {
        let psi = f64::from(k) * 10.0;
        compass.update(&at_rest(0.0, pos(), yaw(psi)));
        let err =
            wrap_deg(f64::from(compass.convert_now().heading_deg) - (psi - cfg.declination_deg));
        assert!(err.abs() <= 0.5 + 1e-9, "after calibration at {psi}: {err}");
    }
}

#[test]
fn soft_iron_is_twice_per_turn_and_survives_calibration() {
    let mut cfg = config().ideal().compass;
    cfg.soft_iron = [[1.1, 0.0], [0.0, 0.9]];
    let e = error_curve(&cfg);
    let (h1, h2) = (harmonic(&e, 1.0), harmonic(&e, 2.0));
    assert!(h2 > 4.0 && h1 < h2 / 5.0, "h1 {h1} h2 {h2}");
}

/// Thesis 4.8 fig 4.15a: turned away from the wall normal the range grows, then the echo is lost.
#[test]
fn sonar_range_grows_with_angle_to_the_wall_and_is_lost_beyond_the_beam() {
    let cfg = config().ideal();
    let s = &cfg.sonar;
    let tr = Transducer::new(&s.transducers[3], s, 0);
    let wall = PlaneWall {
        point_m: Point3::new(8.0, 0.0, 0.0),
        normal: Unit::new_normalize(Vector3::new(-1.0, 0.0, 0.0)),
    };
    let mut last = 0.0;
    let mut lost_at = None;
    for k in 0..40 {
        let beta = f64::from(k);
        // bow-starboard points 15 deg to starboard: yaw so the axis is beta off the wall normal.
        let st = at_rest(0.0, Vector3::new(5.0, 5.0, 1.0), yaw(-15.0 + beta));
        match tr.echo(&st, &wall, s) {
            Some(e) => {
                assert!(lost_at.is_none(), "echo came back at {beta} deg");
                if beta <= 5.0 {
                    // Inside the beam a ray near the normal sees the perpendicular distance.
                    assert!(e.range_m < 2.33 * 1.01, "{beta}: {}", e.range_m);
                } else {
                    assert!(e.range_m >= last - 1e-9, "{beta}: {} < {last}", e.range_m);
                }
                last = e.range_m;
            }
            None => lost_at = lost_at.or(Some(beta)),
        }
    }
    let lost_at = lost_at.expect("echo is lost eventually");
    // Half the beam (5) plus the maximum incidence (20) deg.
    assert!((24.0..=26.0).contains(&lost_at), "{lost_at}");
    assert!(last > 2.3, "range grew from ~2.3 m to {last}");
}

#[test]
fn sonar_detection_falls_with_speed() {
    let cfg = config();
    let s = &cfg.sonar;
    let rate = |speed: f64| {
        let mut tr = Transducer::new(&s.transducers[0], s, 5);
        let mut st = at_rest(0.0, Vector3::new(5.0, 5.0, 1.0), yaw(0.0));
        st.velocity_body_mps.x = speed;
        let axis = tr.axis_world(&st).into_inner();
        let wall = PlaneWall {
            point_m: tr.origin_m(&st) + axis * 2.5,
            normal: Unit::new_normalize(-axis),
        };
        (0..2000)
            .filter(|k| tr.ping(&st, &wall, s, f64::from(*k)).is_some())
            .count() as f64
            / 2000.0
    };
    let (still, half) = (rate(0.0), rate(s.speed_half_mps));
    assert!(still > 0.97, "{still}");
    assert!((half - still / 2.0).abs() < 0.04, "{half} vs {still}");
}

/// Adding or removing a sensor never changes another's noise.
#[test]
fn each_sensor_has_its_own_stream() {
    let cfg = config();
    let depth_codes = |with_others: bool| {
        let mut suite = SensorSuite::new(&cfg, 77);
        (0..200)
            .map(|k| {
                let t = f64::from(k) * 0.01;
                let mut st = at_rest(t, Vector3::new(5.0, 5.0, 2.0), yaw(0.0));
                st.thruster_effort[STERN] = 0.8;
                suite.update(&st, &OpenWater);
                if with_others {
                    suite.read_source(AdcSource::AccelX, t);
                    suite.compass.convert_now();
                }
                suite.depth.voltage(t)
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(depth_codes(false), depth_codes(true));
    // And the sonar transducers: a stream per name.
    let s = &cfg.sonar;
    let a = Transducer::new(&s.transducers[0], s, 3);
    let mut renamed = s.transducers[0].clone();
    renamed.name = "another".into();
    let b = Transducer::new(&renamed, s, 3);
    let st = at_rest(0.0, pos(), yaw(0.0));
    let axis = a.axis_world(&st).into_inner();
    let wall = PlaneWall {
        point_m: a.origin_m(&st) + axis * 3.8,
        normal: Unit::new_normalize(-axis),
    };
    let pings = |mut tr: Transducer| {
        (0..100)
            .map(|k| tr.ping(&st, &wall, s, f64::from(k)))
            .collect::<Vec<_>>()
    };
    assert_eq!(pings(a.clone()), pings(a.clone()));
    assert_ne!(pings(a), pings(b));
}

/// Same seed, same inputs: bit-identical outputs.
#[test]
fn a_run_repeats_bit_for_bit() {
    let cfg = config();
    let run = || {
        let mut suite = SensorSuite::new(&cfg, 11);
        let pool = super::scene::BoxPool::new(25.0, 10.0, 3.0);
        let mut out = Vec::new();
        for k in 0..3000 {
            let t = f64::from(k) * 0.01;
            let mut st = at_rest(t, Vector3::new(12.0, 4.0, 1.0), yaw(f64::from(k) * 0.05));
            st.velocity_water_body_mps.x = 0.3;
            suite.update(&st, &pool);
            if k == 100 {
                suite.sonar.select(1, t).unwrap();
            }
            for src in AdcSource::ALL {
                out.push(format!("{:?}", suite.read_source(src, t)));
            }
            out.push(format!(
                "{:?} {:?}",
                suite.compass.poll(),
                suite.sonar.poll(t)
            ));
        }
        out
    };
    assert_eq!(run(), run());
}

/// Thesis 3.3.2.2 / 4.8: after a select the ack comes once the relays have switched, and a
/// range pinged just before the switch can still arrive after the ack.
#[test]
fn multiplexer_acks_after_switching_and_can_deliver_a_stale_range() {
    let cfg = config();
    for seed in 0..10 {
        let mut mux = super::SonarSystem::new(&cfg.sonar, seed);
        let st0 = at_rest(0.0, pos(), yaw(0.0));
        let tr = &mux.transducers()[0];
        let axis = tr.axis_world(&st0).into_inner();
        let wall = PlaneWall {
            point_m: tr.origin_m(&st0) + axis * 2.0,
            normal: Unit::new_normalize(-axis),
        };
        // Let controller 0 ping once to learn its phase, then select just before its next ping.
        let mut t = 0.0;
        let mut first_ping = None;
        while first_ping.is_none() {
            t += 0.001;
            mux.update(&at_rest(t, pos(), yaw(0.0)), &wall);
            first_ping = mux.poll(t + 1.0).iter().find_map(|e| match e {
                super::SonarEvent::Range {
                    controller: 0, t_s, ..
                } => Some(*t_s - cfg.sonar.timing.sentence_latency_s),
                _ => None,
            });
        }
        let next_ping = first_ping.unwrap() + cfg.sonar.timing.period_s;
        // The command reaches the slave 5..15 ms after that ping; the ping's sentence (100 ms
        // on the wire) then lands after the ack (relays 50 ms + ack 10 ms).
        let select_at =
            next_ping - cfg.sonar.timing.command_latency_s + 0.005 + (seed % 3) as f64 * 0.005;
        while t + 0.001 < select_at {
            t += 0.001;
            mux.update(&at_rest(t, pos(), yaw(0.0)), &wall);
        }
        mux.select(1, select_at).unwrap();
        let mut acked_at = None;
        let mut after_ack = None;
        while after_ack.is_none() && t < select_at + 5.0 {
            t += 0.001;
            mux.update(&at_rest(t, pos(), yaw(0.0)), &wall);
            for e in mux.poll(t) {
                match e {
                    super::SonarEvent::Ack { transducer: 1, t_s } => acked_at = Some(t_s),
                    super::SonarEvent::Range {
                        controller: 0,
                        source,
                        ..
                    } if acked_at.is_some() && after_ack.is_none() => after_ack = Some(source),
                    _ => {}
                }
            }
        }
        let t = &cfg.sonar.timing;
        let ack = acked_at.expect("acknowledged");
        assert!(
            (ack - (select_at + t.command_latency_s + t.relay_switch_s + t.ack_latency_s)).abs()
                < 1e-9
        );
        assert_eq!(
            after_ack,
            Some(0),
            "seed {seed}: the first range after the ack is T0's"
        );
    }
}

#[test]
fn paddle_wheel_fault_on_12_v_lifts_the_other_channels() {
    let mut cfg = config().ideal();
    cfg.adc.overvoltage_coupling = 0.05;
    cfg.velocity.high_v = 12.0;
    let mut suite = SensorSuite::new(&cfg, 2);
    let st = at_rest(0.0, Vector3::new(5.0, 5.0, 2.0), yaw(0.0));
    suite.update(&st, &OpenWater);
    assert!(suite.velocity.is_high(), "paddle starts on a pulse");
    let with_fault = suite.read_source(AdcSource::Depth, 0.0).unwrap();
    let clean = suite
        .adc
        .ideal_code(st.depth_of_m(&Vector3::from(cfg.depth.position_body_m)));
    // 7 V over the reference * 0.05 = 0.35 V = 72 LSB.
    assert_eq!(with_fault, clean + 72);
    assert_eq!(suite.read_source(AdcSource::Velocity, 0.0), Some(1023));
}
