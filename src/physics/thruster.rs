//! The four trolling thrusters (thesis 2.2.1, 4.3): PWM duty with inverted logic plus a
//! direction, a per-motor static curve with reverse weaker than forward, a per-motor gain,
//! first-order lag and a speed fluctuation that grows with speed (thesis fig 4.6).
//!
//! The HDT balancing table that turns a MOTORDrive percentage into a duty is configuration
//! used by the firmware side ([`hdt_command`]); the physics only sees duty and direction.

use rand::{Rng, RngExt};
use rand_distr::StandardNormal;

use crate::physics::config::{ThrusterCommon, ThrusterConfig};

/// Which way the motor driver turns the propeller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Direction {
    #[default]
    Forward,
    Reverse,
}

/// What the motor driver is told: an 8-bit PWM duty with inverted logic (0 = full thrust,
/// 255 = off) and a direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ThrusterCommand {
    pub duty: u8,
    pub direction: Direction,
}

impl ThrusterCommand {
    /// Motor off.
    pub const OFF: Self = Self {
        duty: 0xff,
        direction: Direction::Forward,
    };

    /// PWM on-fraction (0..1): 1 at duty 0 because the logic is inverted (thesis 2.2.1).
    pub fn on_fraction(&self) -> f64 {
        1.0 - f64::from(self.duty) / 255.0
    }

    /// Signed on-fraction (-1..1), negative in reverse.
    pub fn effort(&self) -> f64 {
        match self.direction {
            Direction::Forward => self.on_fraction(),
            Direction::Reverse => -self.on_fraction(),
        }
    }
}

impl Default for ThrusterCommand {
    fn default() -> Self {
        Self::OFF
    }
}

/// The HDT lookup: MOTORDrive's signed percentage (-100..100) to duty and direction, by
/// linear interpolation in the motor's 11-point table (0, 10, ..., 100 %).
pub fn hdt_command(table: &[f64; 11], percent: f64) -> ThrusterCommand {
    let p = if percent.is_finite() {
        percent.clamp(-100.0, 100.0)
    } else {
        0.0
    };
    let x = p.abs() / 10.0;
    let i = (x.floor() as usize).min(9);
    let frac = x - i as f64;
    let duty = table[i] + (table[i + 1] - table[i]) * frac;
    ThrusterCommand {
        duty: duty.round().clamp(0.0, 255.0) as u8,
        direction: if p < 0.0 {
            Direction::Reverse
        } else {
            Direction::Forward
        },
    }
}

/// The static (steady-state) thrust of one motor for a command, in newtons (+ = forward/down).
pub fn static_thrust_n(
    common: &ThrusterCommon,
    motor: &ThrusterConfig,
    cmd: ThrusterCommand,
) -> f64 {
    let on = cmd.on_fraction();
    let deadband = motor.deadband.unwrap_or(common.deadband);
    let x = ((on - deadband) / (1.0 - deadband)).max(0.0);
    let full = common.forward_max_n * motor.gain;
    match cmd.direction {
        Direction::Forward => full * x.powf(common.exponent),
        Direction::Reverse => -full * motor.reverse_ratio * x.powf(common.exponent_reverse),
    }
}

/// Per-step constants of the thruster dynamics, precomputed for one step size.
#[derive(Debug, Clone)]
pub(crate) struct ThrusterDynamics {
    /// Fraction of the gap to the static value closed in one step (exact first-order lag),
    /// while the motor speeds up and while it slows down.
    lag_alpha_up: f64,
    lag_alpha_down: f64,
    /// What lags (`ThrusterCommon::lag_exponent`): 1 the thrust, 2 the propeller speed.
    lag_exponent: f64,
    /// Ornstein-Uhlenbeck decay per step and the matching innovation scale (exact
    /// discretisation, so the fluctuation's variance does not depend on the step).
    ou_decay: f64,
    ou_innovation: f64,
    rel_std: f64,
}

impl ThrusterDynamics {
    pub(crate) fn new(common: &ThrusterCommon, dt_s: f64) -> Self {
        let alpha = |tau_s: f64| {
            if tau_s > 0.0 {
                1.0 - (-dt_s / tau_s).exp()
            } else {
                1.0
            }
        };
        let ou_decay = (-dt_s / common.fluctuation_corr_s).exp();
        Self {
            lag_alpha_up: alpha(common.lag_s),
            lag_alpha_down: alpha(common.lag_down_s),
            lag_exponent: common.lag_exponent,
            ou_decay,
            ou_innovation: (1.0 - ou_decay * ou_decay).sqrt(),
            rel_std: common.fluctuation_rel_std,
        }
    }

    /// The lag's fraction for one step from `now` toward `target`: the spin-up one while the
    /// motor speeds up in the direction it turns, the spin-down one while it slows down (a
    /// reversal slows down to standstill first).
    fn alpha(&self, now: f64, target: f64) -> f64 {
        if now * target >= 0.0 && target.abs() > now.abs() {
            self.lag_alpha_up
        } else {
            self.lag_alpha_down
        }
    }

    /// Advances one motor: the lagged thrust moves toward `target_n`, the unit fluctuation
    /// process takes one step. Returns the thrust delivered now.
    ///
    /// The lag acts on q = sign(T) (|T| / `full_n`)^(1 / lag_exponent), with the spin-up
    /// time constant while |q| grows toward its target and the spin-down one otherwise; the
    /// thrust is `full_n` sign(q) |q|^lag_exponent. With exponent 1 the thrust itself lags.
    pub(crate) fn step<R: Rng>(
        &self,
        lagged_n: &mut f64,
        fluctuation: &mut f64,
        target_n: f64,
        full_n: f64,
        rng: &mut R,
    ) -> f64 {
        if self.lag_exponent == 1.0 || full_n <= 0.0 {
            *lagged_n += (target_n - *lagged_n) * self.alpha(*lagged_n, target_n);
        } else {
            let root = |t: f64| t.signum() * (t.abs() / full_n).powf(1.0 / self.lag_exponent);
            let (target_q, mut q) = (root(target_n), root(*lagged_n));
            q += (target_q - q) * self.alpha(q, target_q);
            *lagged_n = full_n * q.signum() * q.abs().powf(self.lag_exponent);
        }
        if self.rel_std == 0.0 {
            // Without fluctuation the process would only be drawn to be multiplied by 0.
            return *lagged_n;
        }
        let z: f64 = rng.sample(StandardNormal);
        *fluctuation = *fluctuation * self.ou_decay + self.ou_innovation * z;
        // Relative fluctuation grows with speed (thesis fig 4.6): zero at rest, rel_std at full.
        let speed = if full_n > 0.0 {
            (lagged_n.abs() / full_n).min(1.0)
        } else {
            0.0
        };
        let factor = (1.0 + self.rel_std * speed * *fluctuation).max(0.0);
        *lagged_n * factor
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn common() -> ThrusterCommon {
        ThrusterCommon {
            forward_max_n: 10.0,
            deadband: 0.1,
            exponent: 1.0,
            exponent_reverse: 1.0,
            lag_s: 0.25,
            lag_down_s: 0.25,
            lag_exponent: 1.0,
            fluctuation_rel_std: 0.03,
            fluctuation_corr_s: 0.3,
        }
    }

    fn motor() -> ThrusterConfig {
        ThrusterConfig {
            name: "port".into(),
            position_cg_m: Vector3::zeros(),
            direction: Vector3::x(),
            gain: 1.0,
            reverse_ratio: 0.5,
            deadband: None,
            hdt_duty: [
                255.0, 207.0, 184.0, 161.0, 138.0, 115.0, 92.0, 69.0, 46.0, 23.0, 0.0,
            ],
        }
    }

    #[test]
    fn duty_zero_is_full_thrust_and_255_is_off() {
        let c = common();
        let m = motor();
        let full = ThrusterCommand {
            duty: 0,
            direction: Direction::Forward,
        };
        assert_eq!(static_thrust_n(&c, &m, full), 10.0);
        assert_eq!(static_thrust_n(&c, &m, ThrusterCommand::OFF), 0.0);
        let rev = ThrusterCommand {
            duty: 0,
            direction: Direction::Reverse,
        };
        assert_eq!(static_thrust_n(&c, &m, rev), -5.0);
        // Inside the deadband the propeller does not turn.
        let slow = ThrusterCommand {
            duty: 240,
            direction: Direction::Forward,
        };
        assert_eq!(static_thrust_n(&c, &m, slow), 0.0);
    }

    /// The reverse curve has its own shape: at part power forward thrust follows `exponent`,
    /// reverse thrust `exponent_reverse`, and both meet their full-power values.
    #[test]
    fn forward_and_reverse_curves_have_their_own_exponents() {
        let c = ThrusterCommon {
            exponent: 1.2,
            exponent_reverse: 1.6,
            ..common()
        };
        let m = motor();
        // On-fraction 0.55: halfway between the deadband 0.1 and full power.
        let half = |direction| ThrusterCommand {
            duty: (255.0 * 0.45f64).round() as u8,
            direction,
        };
        let x = (half(Direction::Forward).on_fraction() - 0.1) / 0.9;
        let fwd = static_thrust_n(&c, &m, half(Direction::Forward));
        let rev = static_thrust_n(&c, &m, half(Direction::Reverse));
        assert!((fwd - 10.0 * x.powf(1.2)).abs() < 1e-12, "{fwd}");
        assert!((rev + 5.0 * x.powf(1.6)).abs() < 1e-12, "{rev}");
        let full = |direction| ThrusterCommand { duty: 0, direction };
        assert_eq!(static_thrust_n(&c, &m, full(Direction::Reverse)), -5.0);
        assert_eq!(static_thrust_n(&c, &m, full(Direction::Forward)), 10.0);
    }

    /// A motor with its own dead band stands still below it and reaches full thrust at full
    /// duty, whatever the common dead band says.
    #[test]
    fn a_motor_s_own_dead_band_overrides_the_common_one() {
        let c = common();
        let own = ThrusterConfig {
            deadband: Some(0.3),
            ..motor()
        };
        let at = |on: f64| ThrusterCommand {
            duty: (255.0 * (1.0 - on)).round() as u8,
            direction: Direction::Forward,
        };
        assert!(
            static_thrust_n(&c, &motor(), at(0.25)) > 0.0,
            "common dead band 0.1"
        );
        assert_eq!(static_thrust_n(&c, &own, at(0.25)), 0.0);
        let on = at(0.65).on_fraction();
        let expected = 10.0 * (on - 0.3) / 0.7;
        assert!((static_thrust_n(&c, &own, at(0.65)) - expected).abs() < 1e-12);
        assert_eq!(static_thrust_n(&c, &own, at(1.0)), 10.0);
    }

    #[test]
    fn hdt_maps_percent_to_duty_and_direction() {
        let t = motor().hdt_duty;
        assert_eq!(hdt_command(&t, 100.0).duty, 0);
        assert_eq!(hdt_command(&t, 0.0), ThrusterCommand::OFF);
        let r = hdt_command(&t, -50.0);
        assert_eq!(r.direction, Direction::Reverse);
        assert_eq!(r.duty, 115);
        assert_eq!(hdt_command(&t, 55.0).duty, 104);
        assert_eq!(hdt_command(&t, f64::NAN), ThrusterCommand::OFF);
        assert_eq!(hdt_command(&t, 250.0).duty, 0);
    }

    #[test]
    fn lag_reaches_63_percent_after_one_time_constant() {
        let out = lagged(common(), 0.0, 10.0, 25);
        assert!((out - 10.0 * (1.0 - (-1.0f64).exp())).abs() < 1e-9, "{out}");
    }

    /// Thrust after `steps` steps of 10 ms from `start_n` toward `target_n`, without the
    /// fluctuation.
    fn lagged(c: ThrusterCommon, start_n: f64, target_n: f64, steps: usize) -> f64 {
        let dyn_ = ThrusterDynamics::new(
            &ThrusterCommon {
                fluctuation_rel_std: 0.0,
                ..c
            },
            0.01,
        );
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64_for_test(1);
        let (mut lag, mut f) = (start_n, 0.0);
        let mut out = start_n;
        for _ in 0..steps {
            out = dyn_.step(&mut lag, &mut f, target_n, 10.0, &mut rng);
        }
        out
    }

    /// A motor that coasts down more slowly than it spins up: slowing down follows
    /// `lag_down_s`, speeding up `lag_s`, in either direction of thrust.
    #[test]
    fn spin_down_follows_its_own_time_constant() {
        let c = ThrusterCommon {
            lag_s: 0.25,
            lag_down_s: 0.5,
            ..common()
        };
        let e = (-1.0f64).exp();
        let down = lagged(c.clone(), 10.0, 0.0, 50);
        assert!((down - 10.0 * e).abs() < 1e-9, "{down}");
        let up = lagged(c.clone(), 0.0, -5.0, 25);
        assert!((up + 5.0 * (1.0 - e)).abs() < 1e-9, "{up}");
        // From full reverse to full forward: the slowing half takes the longer constant.
        let mut through_zero = 0;
        let dyn_ = ThrusterDynamics::new(&c, 0.01);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64_for_test(1);
        let (mut lag, mut f) = (-10.0, 0.0);
        while lag < 0.0 && through_zero < 1000 {
            dyn_.step(&mut lag, &mut f, 10.0, 10.0, &mut rng);
            through_zero += 1;
        }
        // -10 + 20 (1 - exp(-t / 0.5)) = 0 at t = 0.5 ln 2 = 0.347 s.
        assert!((34..=36).contains(&through_zero), "{through_zero}");
    }

    /// With `lag_exponent` 2 the propeller's speed lags and the thrust is its square: from
    /// rest, one time constant gives (1 - 1/e)^2 of the thrust, and the way down is as slow.
    #[test]
    fn a_lagged_propeller_speed_gives_thrust_by_its_square() {
        let c = ThrusterCommon {
            lag_exponent: 2.0,
            ..common()
        };
        let e = (-1.0f64).exp();
        let up = lagged(c.clone(), 0.0, 10.0, 25);
        assert!((up - 10.0 * (1.0 - e).powi(2)).abs() < 1e-9, "{up}");
        let down = lagged(c.clone(), -10.0, 0.0, 25);
        assert!((down + 10.0 * e * e).abs() < 1e-9, "{down}");
        // The steady state is the static thrust whatever lags.
        let steady = lagged(c, 0.0, 4.0, 1000);
        assert!((steady - 4.0).abs() < 1e-9, "{steady}");
    }

    trait SeedForTest {
        fn seed_from_u64_for_test(seed: u64) -> Self;
    }
    impl SeedForTest for rand_chacha::ChaCha8Rng {
        fn seed_from_u64_for_test(seed: u64) -> Self {
            use rand::SeedableRng;
            rand_chacha::ChaCha8Rng::seed_from_u64(seed)
        }
    }

    #[test]
    fn fluctuation_grows_with_speed() {
        let c = common();
        let dyn_ = ThrusterDynamics::new(
            &ThrusterCommon {
                lag_s: 0.0,
                lag_down_s: 0.0,
                fluctuation_rel_std: 0.1,
                ..c
            },
            0.01,
        );
        let spread = |target: f64| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64_for_test(7);
            let (mut f, mut n) = (0.0, 0.0);
            let xs: Vec<f64> = (0..20_000)
                .map(|_| dyn_.step(&mut f, &mut n, target, 10.0, &mut rng) / target)
                .collect();
            let mean = xs.iter().sum::<f64>() / xs.len() as f64;
            (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64).sqrt()
        };
        let slow = spread(3.0);
        let fast = spread(10.0);
        assert!(
            fast > 2.5 * slow,
            "relative spread slow {slow}, fast {fast}"
        );
        assert!((fast - 0.1).abs() < 0.02, "{fast}");
    }
}
