//! Fits the free vehicle parameters to the thesis's measurements and draws the calibration
//! plots of docs/calibration.md.
//!
//! ```text
//! cargo run --release -p pty-tests --example calibrate            # fit, print the numbers for mako.toml, plot
//! cargo run --release -p pty-tests --example calibrate -- --plot  # only plot the model in configs/
//! ```
//!
//! Fitted (Levenberg-Marquardt, residuals scaled by each measurement's tolerance; parameters
//! in log space so they stay positive): surge linear and quadratic damping, full forward
//! thrust, the two horizontal motors' reverse ratios, sway linear damping and yaw linear
//! damping. Targets: top speed 0.44 m/s, coast-down 32 s, time to top speed 6 s, peak
//! acceleration below 9.5 cm/s^2 (a one-sided penalty above 9.0), spot-turn circle 0.8 m and
//! 23.17 s / 23.5 s per turn (thesis 4.5-4.7). Starting point: configs/vehicles/mako.toml.

use std::path::{Path, PathBuf};

use eyebot_hil::config::Directory;
use eyebot_hil::physics::experiment::{self, Experiment};
use eyebot_hil::physics::measure::{self, CAMERA_PERIOD_S, REST_SPEED_MPS, TOP_SPEED_FRACTION};
use eyebot_hil::physics::state::{PORT, STARBOARD, VehicleState};
use eyebot_hil::physics::{
    self, DEFAULT_VEHICLE, DEFAULT_WORLD, Model, VehicleConfig, WorldConfig,
};
use eyebot_hil::thesis::physics::{
    ACCELERATION, COAST_DOWN, TOP_SPEED_AVERAGE_FROM_S, TURN_ANTICLOCKWISE, TURN_CLOCKWISE,
    figures, load_experiment, rows_from,
};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned, Vector3};
use plotters::prelude::*;

const SEED: u64 = 1;
const NAMES: [&str; 7] = [
    "damping.linear[0] (surge, N/(m/s))",
    "damping.quadratic[0] (surge, N/(m/s)^2)",
    "thrusters.forward_max_n (N)",
    "thruster port reverse_ratio",
    "thruster starboard reverse_ratio",
    "damping.linear[1] (sway, N/(m/s))",
    "damping.linear[5] (yaw, N m/(rad/s))",
];

fn get(v: &VehicleConfig) -> [f64; 7] {
    [
        v.damping_linear[0],
        v.damping_quadratic[0],
        v.thruster_common.forward_max_n,
        v.thrusters[PORT].reverse_ratio,
        v.thrusters[STARBOARD].reverse_ratio,
        v.damping_linear[1],
        v.damping_linear[5],
    ]
}

fn set(v: &mut VehicleConfig, p: &[f64]) {
    v.damping_linear[0] = p[0];
    v.damping_quadratic[0] = p[1];
    v.thruster_common.forward_max_n = p[2];
    v.thrusters[PORT].reverse_ratio = p[3].min(1.0);
    v.thrusters[STARBOARD].reverse_ratio = p[4].min(1.0);
    v.damping_linear[1] = p[5];
    v.damping_linear[5] = p[6];
}

struct Experiments {
    acc: Experiment,
    coast: Experiment,
    acw: Experiment,
    cw: Experiment,
}

/// Linear interpolation of the time a sampled signal first crosses `level` (smooth in the
/// parameters, unlike the 200 ms sample time validate reports).
fn crossing(samples: &[(f64, f64)], level: f64, rising: bool) -> Option<f64> {
    samples.windows(2).find_map(|w| {
        let (t0, v0) = w[0];
        let (t1, v1) = w[1];
        let crossed = if rising {
            v0 < level && v1 >= level
        } else {
            v0 >= level && v1 < level
        };
        crossed.then(|| t0 + (t1 - t0) * (level - v0) / (v1 - v0))
    })
}

fn trace(model: &Model, exp: &Experiment) -> Vec<VehicleState> {
    experiment::trace(model, exp, SEED).unwrap_or_default()
}

/// Residuals scaled by the tolerance of each target, or None when a run fails.
fn residuals(vehicle: &VehicleConfig, world: &WorldConfig, e: &Experiments) -> Option<Vec<f64>> {
    let model = Model::new(vehicle.clone(), world.clone());
    let axis = Vector3::x();
    let v = measure::camera_velocities(&trace(&model, &e.acc), &axis, CAMERA_PERIOD_S);
    let top = measure::mean_from(&v, TOP_SPEED_AVERAGE_FROM_S)?;
    let rise = crossing(&v, TOP_SPEED_FRACTION * top, true)?;
    let peak = measure::peak_acceleration(&v)?;
    let c = measure::camera_velocities(&trace(&model, &e.coast), &axis, CAMERA_PERIOD_S);
    let rest = crossing(&c, REST_SPEED_MPS, false)?;
    let acw = measure::spot_turn(&trace(&model, &e.acw))?;
    let cw = measure::spot_turn(&trace(&model, &e.cw))?;
    Some(vec![
        (top - 0.44) / 0.022,
        (rest - 32.0) / 3.0,
        (rise - 6.0) / 1.5,
        (peak - 0.090).max(0.0) / 0.005,
        (acw.diameter_m - 0.8) / 0.1,
        (cw.diameter_m - 0.8) / 0.1,
        (acw.period_s - 23.17) / 1.0,
        (cw.period_s - 23.5) / 1.0,
    ])
}

struct Fit<'a> {
    base: VehicleConfig,
    world: &'a WorldConfig,
    experiments: &'a Experiments,
    log_p: DVector<f64>,
}

impl Fit<'_> {
    fn vehicle(&self, log_p: &DVector<f64>) -> VehicleConfig {
        let mut v = self.base.clone();
        let p: Vec<f64> = log_p.iter().map(|x| x.exp()).collect();
        set(&mut v, &p);
        v
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Fit<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.log_p.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.log_p.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        residuals(&self.vehicle(&self.log_p), self.world, self.experiments).map(DVector::from_vec)
    }

    /// Central differences in log space (1 % steps: big enough to move the 10 ms-quantised
    /// turn times, small against the parameters' uncertainty).
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let n = self.log_p.len();
        let mut cols = Vec::with_capacity(n);
        for j in 0..n {
            let h = 0.01;
            let mut plus = self.log_p.clone();
            plus[j] += h;
            let mut minus = self.log_p.clone();
            minus[j] -= h;
            let rp = residuals(&self.vehicle(&plus), self.world, self.experiments)?;
            let rm = residuals(&self.vehicle(&minus), self.world, self.experiments)?;
            cols.push(DVector::from_iterator(
                rp.len(),
                rp.iter().zip(&rm).map(|(a, b)| (a - b) / (2.0 * h)),
            ));
        }
        Some(DMatrix::from_columns(&cols))
    }
}

fn configs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let plot_only = std::env::args().any(|a| a == "--plot");
    let configs = Directory::new(configs_dir());
    let vehicle = physics::load_vehicle(&configs, DEFAULT_VEHICLE)?;
    let world = physics::load_world(&configs, DEFAULT_WORLD)?;
    let experiments = Experiments {
        acc: load_experiment(&configs, ACCELERATION)?,
        coast: load_experiment(&configs, COAST_DOWN)?,
        acw: load_experiment(&configs, TURN_ANTICLOCKWISE)?,
        cw: load_experiment(&configs, TURN_CLOCKWISE)?,
    };

    if !plot_only {
        let start = get(&vehicle);
        let fit = Fit {
            base: vehicle.clone(),
            world: &world,
            experiments: &experiments,
            log_p: DVector::from_iterator(7, start.iter().map(|x| x.ln())),
        };
        let r0 = fit
            .residuals()
            .ok_or("the starting model fails an experiment")?;
        println!("start residuals (in tolerances): {:.3?}", r0.as_slice());
        let (fit, report) = LevenbergMarquardt::new().with_patience(20).minimize(fit);
        println!(
            "levenberg-marquardt: {:?}, {} evaluations, objective {:.4}",
            report.termination, report.number_of_evaluations, report.objective_function
        );
        let r = fit
            .residuals()
            .ok_or("the fitted model fails an experiment")?;
        println!("fitted residuals (in tolerances): {:.3?}", r.as_slice());
        println!("\nfitted parameters (copy into configs/vehicles/mako.toml):");
        for (name, (old, new)) in NAMES.iter().zip(start.iter().zip(fit.log_p.iter())) {
            println!("  {name:<42} {old:>9.4} -> {:>9.4}", new.exp());
        }
        let fitted = fit.vehicle(&fit.log_p);
        let f = figures(&Model::new(fitted, world.clone()), &configs, SEED)?;
        println!("\nvalidate rows with the fitted parameters:");
        print!("{}", eyebot_hil::thesis::render_table(&rows_from(&f)));
    }

    // Plots of the model as configured (run again after copying the fitted numbers).
    let model = Model::new(vehicle, world);
    plot_speed_runs(&model, &experiments)?;
    plot_turns(&model, &experiments)?;
    println!("\nplots of configs/vehicles/mako.toml written to docs/calibration-*.svg");
    Ok(())
}

fn docs(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../docs")
        .join(name)
}

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// Draws `points` as a line in `style` with a legend entry: a plain `colour` line and `label`.
fn labelled_line(
    chart: &mut Chart<'_, '_>,
    points: impl IntoIterator<Item = (f64, f64)>,
    style: impl Into<ShapeStyle>,
    colour: RGBColor,
    label: impl Into<String>,
) -> Result<(), Box<dyn std::error::Error>> {
    chart
        .draw_series(LineSeries::new(points, style))?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
    Ok(())
}

/// The legend of `chart`'s labelled series, at `position` (plotters' default if `None`).
fn draw_legend<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    position: Option<SeriesLabelPosition>,
) -> Result<(), Box<dyn std::error::Error>> {
    let mut legend = chart.configure_series_labels();
    legend.background_style(WHITE.mix(0.8)).border_style(BLACK);
    if let Some(position) = position {
        legend.position(position);
    }
    legend.draw()?;
    Ok(())
}

fn plot_speed_runs(model: &Model, e: &Experiments) -> Result<(), Box<dyn std::error::Error>> {
    let axis = Vector3::x();
    let acc = measure::camera_velocities(&trace(model, &e.acc), &axis, CAMERA_PERIOD_S);
    let coast = measure::camera_velocities(&trace(model, &e.coast), &axis, CAMERA_PERIOD_S);
    let top = measure::mean_from(&acc, TOP_SPEED_AVERAGE_FROM_S).unwrap_or(0.0);

    let path = docs("calibration-speed.svg");
    let root = SVGBackend::new(&path, (900, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let (upper, lower) = root.split_vertically(350);

    let mut chart = ChartBuilder::on(&upper)
        .caption(
            "Full-thrust acceleration from rest (200 ms camera samples)",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..20.0, 0.0..0.5)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("surge speed (m/s)")
        .draw()?;
    labelled_line(
        &mut chart,
        acc.iter().copied().filter(|(t, _)| *t <= 20.0),
        BLUE,
        BLUE,
        "eyebot-hil",
    )?;
    labelled_line(
        &mut chart,
        vec![(0.0, 0.44), (20.0, 0.44)],
        RED.stroke_width(2),
        RED,
        "Mako top speed 0.44 m/s (thesis 4.5)",
    )?;
    labelled_line(
        &mut chart,
        vec![
            (0.0, TOP_SPEED_FRACTION * top),
            (20.0, TOP_SPEED_FRACTION * top),
        ],
        BLACK.stroke_width(1),
        BLACK,
        "85 % of simulated top speed (\"reached\")",
    )?;
    labelled_line(
        &mut chart,
        vec![(6.0, 0.0), (6.0, 0.5)],
        RED.stroke_width(2),
        RED,
        "Mako reaches top speed after 6 s (thesis 4.5)",
    )?;
    labelled_line(
        &mut chart,
        vec![(0.0, 0.0), (4.63, 0.44)],
        GREEN.stroke_width(1),
        GREEN,
        "9.5 cm/s^2 from rest (thesis 4.6, upper bound)",
    )?;
    draw_legend(&mut chart, Some(SeriesLabelPosition::LowerRight))?;

    let mut chart = ChartBuilder::on(&lower)
        .caption("Coast-down from 0.44 m/s, motors off", ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..45.0, 0.0..0.5)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("surge speed (m/s)")
        .draw()?;
    labelled_line(&mut chart, coast.iter().copied(), BLUE, BLUE, "eyebot-hil")?;
    labelled_line(
        &mut chart,
        vec![(32.0, 0.0), (32.0, 0.5)],
        RED.stroke_width(2),
        RED,
        "Mako at rest after 32 s (thesis 4.5)",
    )?;
    labelled_line(
        &mut chart,
        vec![(0.0, REST_SPEED_MPS), (45.0, REST_SPEED_MPS)],
        BLACK.stroke_width(1),
        BLACK,
        "1.5 cm/s (\"at rest\")",
    )?;
    draw_legend(&mut chart, None)?;
    root.present()?;
    Ok(())
}

fn plot_turns(model: &Model, e: &Experiments) -> Result<(), Box<dyn std::error::Error>> {
    let path = docs("calibration-spot-turn.svg");
    let root = SVGBackend::new(&path, (700, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let centre = (12.5, 6.25);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Spot turns, path of the centre (north up)",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(-1.2..1.2, -1.2..1.2)?;
    chart
        .configure_mesh()
        .x_desc("east from start (m)")
        .y_desc("north from start (m)")
        .draw()?;
    for (exp, colour, label) in [
        (&e.acw, BLUE, "anticlockwise: starboard fwd, port rev"),
        (&e.cw, MAGENTA, "clockwise: port fwd, starboard rev"),
    ] {
        let t = trace(model, exp);
        let m = measure::spot_turn(&t);
        let label = match m {
            Some(m) => format!("{label}: {:.2} m, {:.2} s/turn", m.diameter_m, m.period_s),
            None => label.to_string(),
        };
        labelled_line(
            &mut chart,
            t.iter()
                .step_by(10)
                .map(|s| (s.position_m.y - centre.1, s.position_m.x - centre.0)),
            colour,
            colour,
            label,
        )?;
    }
    // A 0.8 m circle for scale (thesis 4.7), drawn through the start point.
    let circle: Vec<(f64, f64)> = (0..=100)
        .map(|k| {
            let a = k as f64 / 100.0 * std::f64::consts::TAU;
            (-0.4 + 0.4 * a.cos(), 0.4 * a.sin())
        })
        .collect();
    labelled_line(
        &mut chart,
        circle,
        RED.stroke_width(2),
        RED,
        "0.8 m circle (Mako, thesis 4.7)",
    )?;
    draw_legend(&mut chart, Some(SeriesLabelPosition::LowerLeft))?;
    root.present()?;
    Ok(())
}
