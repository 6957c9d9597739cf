//! The physics rows of `eyebot-hil validate`: the thesis's vehicle measurements (chapter 4)
//! next to SubSim 2.4's (chapter 5) and ours, computed now by running the experiments in
//! `configs/experiments/` and reading them the way the thesis read Mako
//! ([`crate::physics::measure`]).

use nalgebra::Vector3;

use crate::config::{ConfigSource, Document};
use crate::physics::experiment::{self, Experiment};
use crate::physics::measure::{self, CAMERA_PERIOD_S, REST_SPEED_MPS, TOP_SPEED_FRACTION};
use crate::physics::state::VehicleState;
use crate::physics::{DEFAULT_VEHICLE, DEFAULT_WORLD, Model, load_model};
use crate::thesis::{Context, Group, Row, ValidateError, Value};

/// The experiment files the rows are computed from (names inside the config source).
pub const ACCELERATION: &str = "experiments/acceleration.toml";
pub const COAST_DOWN: &str = "experiments/coast-down.toml";
pub const TURN_ANTICLOCKWISE: &str = "experiments/spot-turn-anticlockwise.toml";
pub const TURN_CLOCKWISE: &str = "experiments/spot-turn-clockwise.toml";
pub const STRAIGHT: &str = "experiments/straight-equal-commands.toml";

/// The top speed is the mean of the 200 ms samples from this time on (the vehicle has
/// settled; thesis 4.5 reports an average maximum velocity).
pub const TOP_SPEED_AVERAGE_FROM_S: f64 = 25.0;
/// A heading change above this counts as a turn (a compass resolves 1 degree, thesis 3.3.4).
pub const DRIFT_THRESHOLD_DEG: f64 = 1.0;

/// Loads an experiment file by name.
pub fn load_experiment(
    configs: &dyn ConfigSource,
    name: &str,
) -> Result<Experiment, ValidateError> {
    let text = configs.read(name)?;
    Ok(Experiment::from_document(&Document::new(
        configs.describe(name),
        &text,
    ))?)
}

fn run(model: &Model, exp: &Experiment, seed: u64) -> Result<Vec<VehicleState>, ValidateError> {
    experiment::trace(model, exp, seed).map_err(|source| ValidateError::Physics {
        experiment: exp.name.clone(),
        source,
    })
}

fn missing(exp: &Experiment, what: &'static str) -> ValidateError {
    ValidateError::Measurement {
        experiment: exp.name.clone(),
        what,
    }
}

/// The numbers the physics rows report, measured from simulated runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicsFigures {
    pub top_speed_mps: f64,
    pub time_to_top_speed_s: f64,
    pub peak_acceleration_mps2: f64,
    pub coast_to_rest_s: f64,
    pub diameter_anticlockwise_m: f64,
    pub diameter_clockwise_m: f64,
    pub period_anticlockwise_s: f64,
    pub period_clockwise_s: f64,
    /// Heading change over the equal-command run (deg, + = right).
    pub drift_deg: f64,
    pub drift_duration_s: f64,
}

/// Runs the experiments on `model` and measures them. Shared by `validate` and the
/// calibration example.
pub fn figures(
    model: &Model,
    configs: &dyn ConfigSource,
    seed: u64,
) -> Result<PhysicsFigures, ValidateError> {
    let axis = Vector3::x(); // every speed run heads north along the tape on the pool wall

    let acc = load_experiment(configs, ACCELERATION)?;
    let trace = run(model, &acc, seed)?;
    let v = measure::camera_velocities(&trace, &axis, CAMERA_PERIOD_S);
    let top = measure::mean_from(&v, TOP_SPEED_AVERAGE_FROM_S)
        .ok_or_else(|| missing(&acc, "the top speed"))?;
    let rise = measure::time_to_top_speed(&v, top, 0.0)
        .ok_or_else(|| missing(&acc, "the time to top speed"))?;
    let peak =
        measure::peak_acceleration(&v).ok_or_else(|| missing(&acc, "the peak acceleration"))?;

    let coast = load_experiment(configs, COAST_DOWN)?;
    let trace = run(model, &coast, seed)?;
    let v = measure::camera_velocities(&trace, &axis, CAMERA_PERIOD_S);
    let rest = measure::time_to_rest(&v, 0.0).ok_or_else(|| missing(&coast, "the time to rest"))?;

    let acw = load_experiment(configs, TURN_ANTICLOCKWISE)?;
    let t_acw = measure::spot_turn(&run(model, &acw, seed)?)
        .ok_or_else(|| missing(&acw, "two full turns"))?;
    let cw = load_experiment(configs, TURN_CLOCKWISE)?;
    let t_cw = measure::spot_turn(&run(model, &cw, seed)?)
        .ok_or_else(|| missing(&cw, "two full turns"))?;
    if t_acw.sense > 0.0 || t_cw.sense < 0.0 {
        tracing::warn!(
            anticlockwise = t_acw.sense,
            clockwise = t_cw.sense,
            "a spot turn went the wrong way"
        );
    }

    let straight = load_experiment(configs, STRAIGHT)?;
    let drift = measure::heading_change_deg(&run(model, &straight, seed)?)
        .ok_or_else(|| missing(&straight, "the heading drift"))?;

    Ok(PhysicsFigures {
        top_speed_mps: top,
        time_to_top_speed_s: rise,
        peak_acceleration_mps2: peak,
        coast_to_rest_s: rest,
        diameter_anticlockwise_m: t_acw.diameter_m,
        diameter_clockwise_m: t_cw.diameter_m,
        period_anticlockwise_s: t_acw.period_s
            * if t_acw.sense < 0.0 {
                1.0
            } else {
                f64::INFINITY
            },
        period_clockwise_s: t_cw.period_s * if t_cw.sense > 0.0 { 1.0 } else { f64::INFINITY },
        drift_deg: drift,
        drift_duration_s: straight.duration_s,
    })
}

fn number_row(
    quantity: &str,
    measured: f64,
    subsim: Option<Value>,
    simulated: f64,
    tolerance: String,
    unit: &str,
    pass: bool,
) -> Row {
    Row {
        quantity: quantity.to_string(),
        measured: Value::Number(measured),
        subsim,
        simulated: Value::Number(simulated),
        tolerance,
        unit: unit.to_string(),
        pass,
        group: Group::Physics,
    }
}

/// The physics rows, computed by running the thesis experiments on the default vehicle and
/// world of `ctx.configs`.
pub fn rows(ctx: &Context<'_>) -> Result<Vec<Row>, ValidateError> {
    let model = load_model(ctx.configs, DEFAULT_VEHICLE, DEFAULT_WORLD)?;
    let f = figures(&model, ctx.configs, ctx.seed)?;
    Ok(rows_from(&f))
}

/// The rows for measured figures: the thesis's value, SubSim 2.4's, ours, and the tolerance
/// each row is judged by.
pub fn rows_from(f: &PhysicsFigures) -> Vec<Row> {
    let within = |x: f64, target: f64, tol: f64| (x - target).abs() <= tol;
    let drift_text = if f.drift_deg > DRIFT_THRESHOLD_DEG {
        "turns right"
    } else if f.drift_deg < -DRIFT_THRESHOLD_DEG {
        "turns left"
    } else {
        "straight"
    };
    vec![
        number_row(
            "top surge speed at 100 %",
            0.44,
            Some(Value::Number(0.09)),
            f.top_speed_mps,
            "+-5 %".into(),
            "m/s",
            within(f.top_speed_mps, 0.44, 0.05 * 0.44),
        ),
        number_row(
            "time to reach top speed",
            6.0,
            None,
            f.time_to_top_speed_s,
            format!(
                "+-1.5 s (first 200 ms sample >= {:.0} % of top)",
                TOP_SPEED_FRACTION * 100.0
            ),
            "s",
            within(f.time_to_top_speed_s, 6.0, 1.5),
        ),
        number_row(
            "coast-down from top speed to rest",
            32.0,
            None,
            f.coast_to_rest_s,
            format!(
                "+-3 s (first 200 ms sample < {:.1} cm/s)",
                REST_SPEED_MPS * 100.0
            ),
            "s",
            within(f.coast_to_rest_s, 32.0, 3.0),
        ),
        number_row(
            "peak surge acceleration",
            9.5,
            None,
            f.peak_acceleration_mps2 * 100.0,
            "<= 9.5 (an upper bound)".into(),
            "cm/s^2",
            f.peak_acceleration_mps2 * 100.0 <= 9.5,
        ),
        number_row(
            "spot-turn circle diameter",
            0.8,
            Some(Value::Number(1.3)),
            f.diameter_anticlockwise_m,
            "+-0.1 m".into(),
            "m",
            within(f.diameter_anticlockwise_m, 0.8, 0.1),
        ),
        number_row(
            "time per turn, anticlockwise",
            23.17,
            Some(Value::Text("38.5 / 40 / 70 s (speed 5 / 15 / 30)".into())),
            f.period_anticlockwise_s,
            "+-1 s".into(),
            "s",
            within(f.period_anticlockwise_s, 23.17, 1.0),
        ),
        number_row(
            "time per turn, clockwise",
            23.5,
            None,
            f.period_clockwise_s,
            "+-1 s".into(),
            "s",
            within(f.period_clockwise_s, 23.5, 1.0),
        ),
        Row {
            quantity: "heading drift with equal commands".into(),
            measured: Value::Text("turns right".into()),
            subsim: None,
            simulated: Value::Text(format!(
                "{drift_text} ({:+.1} deg in {:.0} s)",
                f.drift_deg, f.drift_duration_s
            )),
            tolerance: format!("turns right (> {DRIFT_THRESHOLD_DEG:.0} deg)"),
            unit: String::new(),
            pass: f.drift_deg > DRIFT_THRESHOLD_DEG,
            group: Group::Physics,
        },
    ]
}
