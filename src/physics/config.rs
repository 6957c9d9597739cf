//! Vehicle and world settings: raw TOML structs (`deny_unknown_fields`) resolved into checked,
//! derived values (centre of mass, inertia tensor, thruster positions about the centre of mass).
//!
//! The loaders take a [`Document`] (text plus its origin), never a path; every range error
//! names the file, the line and the key.

use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

use crate::config::{ConfigError, Document};
use crate::physics::state::{BOW, PORT, STARBOARD, STERN};

mod world;
pub use world::*;

/// Thruster names in index order; the `[[thruster]]` tables must appear in this order.
pub const THRUSTER_NAMES: [&str; 4] = ["port", "starboard", "bow", "stern"];

// ---------------------------------------------------------------------------------------------
// Raw vehicle file
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVehicle {
    body: RawBody,
    #[serde(rename = "mass")]
    masses: Vec<RawMass>,
    hydrostatics: RawHydrostatics,
    added_mass: RawAddedMass,
    damping: RawDamping,
    thrusters: RawThrusters,
    #[serde(rename = "thruster")]
    thruster: Vec<RawThruster>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBody {
    length_m: f64,
    width_m: f64,
    height_m: f64,
}

#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
enum RawMassShape {
    /// A solid box with edges `size_m` along body x, y, z.
    Box,
    /// A solid cylinder along body x: `size_m` = [length, diameter, diameter].
    CylinderX,
    /// A point mass (`size_m` ignored, may be omitted).
    Point,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMass {
    name: String,
    mass_kg: f64,
    shape: RawMassShape,
    centre_m: [f64; 3],
    #[serde(default)]
    size_m: [f64; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHydrostatics {
    displaced_volume_m3: f64,
    centre_of_buoyancy_m: [f64; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAddedMass {
    surge_kg: f64,
    sway_kg: f64,
    heave_kg: f64,
    roll_kgm2: f64,
    pitch_kgm2: f64,
    yaw_kgm2: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDamping {
    linear: [f64; 6],
    quadratic: [f64; 6],
    #[serde(default)]
    sway_yaw: [f64; 2],
    #[serde(default)]
    yaw_uv: f64,
    #[serde(default)]
    yaw_ur: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawThrusters {
    forward_max_n: f64,
    deadband: f64,
    exponent: f64,
    #[serde(default)]
    exponent_reverse: Option<f64>,
    lag_s: f64,
    #[serde(default)]
    lag_down_s: Option<f64>,
    #[serde(default)]
    lag_exponent: Option<f64>,
    fluctuation_rel_std: f64,
    fluctuation_corr_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawThruster {
    name: String,
    position_m: [f64; 3],
    direction: [f64; 3],
    gain: f64,
    reverse_ratio: f64,
    #[serde(default)]
    deadband: Option<f64>,
    hdt_duty: Vec<f64>,
}

// ---------------------------------------------------------------------------------------------
// Resolved vehicle
// ---------------------------------------------------------------------------------------------

/// One thruster, resolved: position relative to the centre of mass.
#[derive(Debug, Clone, PartialEq)]
pub struct ThrusterConfig {
    pub name: String,
    /// Where the thrust acts, body frame, relative to the centre of mass.
    pub position_cg_m: Vector3<f64>,
    /// Unit direction of positive (forward / down) thrust, body frame.
    pub direction: Vector3<f64>,
    /// This motor's forward thrust relative to `forward_max_n` (motors differ, thesis 4.3).
    pub gain: f64,
    /// Reverse thrust at full reverse relative to this motor's full forward thrust.
    pub reverse_ratio: f64,
    /// This motor's own dead band (PWM on-fraction); `ThrusterCommon::deadband` when `None`.
    /// Motors of one type still stand still below different duties.
    pub deadband: Option<f64>,
    /// The HDT balancing table: PWM duty for MOTORDrive 0, 10, ..., 100 %.
    pub hdt_duty: [f64; 11],
}

/// Thruster settings common to all four motors.
#[derive(Debug, Clone, PartialEq)]
pub struct ThrusterCommon {
    pub forward_max_n: f64,
    /// PWM on-fraction below which the propeller does not turn.
    pub deadband: f64,
    /// Shape of the static curve: thrust ~ ((on - deadband) / (1 - deadband))^exponent.
    pub exponent: f64,
    /// Shape of the reverse curve, likewise. A propeller built to push forward loses more
    /// of its thrust at part power in reverse, so the two curves need not share a shape.
    /// Equals `exponent` unless the vehicle file sets `thrusters.exponent_reverse`.
    pub exponent_reverse: f64,
    /// Time constant of the first-order lag while a motor speeds up.
    pub lag_s: f64,
    /// Time constant while it slows down (a propeller coasts down more slowly than its motor
    /// drives it up). Equals `lag_s` unless the vehicle file sets `thrusters.lag_down_s`.
    pub lag_down_s: f64,
    /// What lags: the lagged quantity q is (thrust / full thrust)^(1 / lag_exponent), so 1
    /// lags the thrust itself and 2 lags the propeller's speed of a thrust that grows with
    /// its square. 1 unless the vehicle file sets `thrusters.lag_exponent`.
    pub lag_exponent: f64,
    /// Relative standard deviation of the thrust fluctuation at full speed.
    pub fluctuation_rel_std: f64,
    pub fluctuation_corr_s: f64,
}

/// The vehicle model, resolved. Body frame FRD with its origin at the centre of mass.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleConfig {
    pub mass_kg: f64,
    /// Inertia tensor about the centre of mass, body axes (kg m^2).
    pub inertia_kgm2: Matrix3<f64>,
    /// Centre of mass relative to the centre of the bounding box (body axes).
    pub cg_from_box_centre_m: Vector3<f64>,
    /// Bounding-box half extents (the hull collider).
    pub half_extents_m: Vector3<f64>,
    pub displaced_volume_m3: f64,
    /// Centre of buoyancy relative to the centre of mass.
    pub cb_m: Vector3<f64>,
    /// Added mass, diagonal: surge, sway, heave (kg), roll, pitch, yaw (kg m^2).
    pub added_mass: [f64; 6],
    pub damping_linear: [f64; 6],
    pub damping_quadratic: [f64; 6],
    /// Linear sway-yaw cross damping `[Y_r, N_v]`: the sway force per unit yaw rate (N per
    /// rad/s) and the yaw moment per unit sway speed (N m per m/s), both opposing the motion
    /// with a positive sign, as the diagonal terms do (the off-diagonal sway-yaw entries of Fossen's linear damping
    /// matrix `D`). Zero unless the vehicle file sets `damping.sway_yaw`.
    pub damping_sway_yaw: [f64; 2],
    /// Yaw moment per unit product of surge and sway speed, `N_uv` (N m per (m/s)^2), opposing
    /// with a positive sign: the lift of the hulls and fins that works against the Munk
    /// moment the added masses give (`(a_sway - a_surge) u v`, which the model always has).
    /// Zero unless the vehicle file sets `damping.yaw_uv`.
    pub damping_yaw_uv: f64,
    /// Yaw damping that grows with forward speed, `N_|u|r` (N m per (m/s x rad/s)), opposing
    /// the turn with a positive sign: the yaw moment `N_|u|r |u| r`. Manoeuvring theory writes
    /// the hull's and fins' linear yaw damping as a dimensionless derivative times the speed
    /// through the water (`N_r = N'_r (rho/2) L^4 U`), so a hull turns more sluggishly under
    /// way than on the spot, where only the viscous part acts.
    /// Zero unless the vehicle file sets `damping.yaw_ur`.
    pub damping_yaw_ur: f64,
    /// Waterplane area of the hull's top (m^2): buoyancy lost in proportion to how far the top
    /// of the hull box rises out of the water, `rho g A e`, beside the box's own volume, which
    /// the model spreads like a pair of horizontal cylinders and so loses only slowly near the
    /// top. A deck or superstructure that cuts the surface with some area holds the hull at
    /// its float more stiffly. Zero unless calibrated (`surface_stiffness`).
    pub surface_waterplane_m2: f64,
    /// Heave damping while the top of the hull box is out of the water (N per m/s, along the
    /// world vertical): the waves a hull bobbing at the surface makes. Zero unless calibrated
    /// (`surface_damping`).
    pub surface_damping_nspm: f64,
    pub thruster_common: ThrusterCommon,
    pub thrusters: [ThrusterConfig; 4],
}

impl VehicleConfig {
    /// Parses and resolves a vehicle file.
    pub fn from_document(doc: &Document<'_>) -> Result<Self, ConfigError> {
        let raw: RawVehicle = doc.parse()?;
        resolve_vehicle(doc, raw)
    }
}

fn check3(
    doc: &Document<'_>,
    key: &str,
    v: [f64; 3],
    min: f64,
    max: f64,
    unit: &str,
) -> Result<Vector3<f64>, ConfigError> {
    for (i, x) in v.iter().enumerate() {
        doc.check_range(&format!("{key}.{i}"), *x, min, max, unit)?;
    }
    Ok(Vector3::from(v))
}

fn resolve_vehicle(doc: &Document<'_>, raw: RawVehicle) -> Result<VehicleConfig, ConfigError> {
    let half = resolve_half_extents(doc, &raw.body)?;
    let masses = resolve_mass_distribution(doc, &raw.masses, &half)?;
    let cg = masses.cg;
    let (volume, cb) = resolve_buoyancy(doc, &raw.hydrostatics, &cg)?;
    let added_mass = resolve_added_mass(doc, &raw.added_mass)?;
    let damping = resolve_damping(doc, &raw.damping)?;
    let thruster_common = resolve_thruster_common(doc, &raw.thrusters)?;
    let thrusters = resolve_thrusters(doc, &raw.thruster, &cg)?;

    Ok(VehicleConfig {
        mass_kg: masses.total_kg,
        inertia_kgm2: masses.inertia_kgm2,
        cg_from_box_centre_m: cg,
        half_extents_m: half,
        displaced_volume_m3: volume,
        cb_m: cb,
        added_mass,
        damping_linear: damping.linear,
        damping_quadratic: damping.quadratic,
        damping_sway_yaw: damping.sway_yaw,
        damping_yaw_uv: damping.yaw_uv,
        damping_yaw_ur: damping.yaw_ur,
        surface_waterplane_m2: 0.0,
        surface_damping_nspm: 0.0,
        thruster_common,
        thrusters,
    })
}

/// Checks the body's bounding box and returns its half extents, the hull collider and the
/// limit every mass component's centre must stay within.
fn resolve_half_extents(doc: &Document<'_>, body: &RawBody) -> Result<Vector3<f64>, ConfigError> {
    let length = doc.check_range("body.length_m", body.length_m, 0.1, 10.0, "m")?;
    let width = doc.check_range("body.width_m", body.width_m, 0.1, 10.0, "m")?;
    let height = doc.check_range("body.height_m", body.height_m, 0.1, 10.0, "m")?;
    Ok(Vector3::new(length, width, height) / 2.0)
}

/// Total mass, centre of mass and inertia tensor of the `[[mass]]` components.
struct MassProperties {
    total_kg: f64,
    /// Centre of mass relative to the centre of the bounding box.
    cg: Vector3<f64>,
    /// Inertia about the centre of mass, body axes.
    inertia_kgm2: Matrix3<f64>,
}

/// Checks the `[[mass]]` components and combines them into the vehicle's centre of mass and
/// inertia tensor (each component's own inertia moved to the centre of mass by the
/// parallel-axis theorem).
fn resolve_mass_distribution(
    doc: &Document<'_>,
    masses: &[RawMass],
    half: &Vector3<f64>,
) -> Result<MassProperties, ConfigError> {
    if masses.is_empty() {
        return Err(doc.invalid("mass", "at least one [[mass]] component is required"));
    }
    let mut total = 0.0;
    let mut moment = Vector3::zeros();
    let mut parts = Vec::with_capacity(masses.len());
    for (i, m) in masses.iter().enumerate() {
        let key = format!("mass.{i}");
        let mass = doc.check_range(&format!("{key}.mass_kg"), m.mass_kg, 0.0, 1000.0, "kg")?;
        let c = check3(doc, &format!("{key}.centre_m"), m.centre_m, -5.0, 5.0, "m")?;
        let s = check3(doc, &format!("{key}.size_m"), m.size_m, 0.0, 10.0, "m")?;
        for axis in 0..3 {
            if c[axis].abs() > half[axis] + 1e-9 {
                return Err(doc.invalid(
                    &format!("{key}.centre_m"),
                    format!(
                        "component `{}` lies outside the body's bounding box",
                        m.name
                    ),
                ));
            }
        }
        total += mass;
        moment += c * mass;
        parts.push((mass, c, component_inertia(m.shape, mass, &s)));
    }
    if total <= 0.0 {
        return Err(doc.invalid("mass", "the components' masses sum to zero"));
    }
    let cg = moment / total;
    let mut inertia = Matrix3::zeros();
    for (mass, c, own) in &parts {
        let d = c - cg;
        inertia += own + (Matrix3::identity() * d.dot(&d) - d * d.transpose()) * *mass;
    }
    Ok(MassProperties {
        total_kg: total,
        cg,
        inertia_kgm2: inertia,
    })
}

/// Inertia of one mass component about its own centre, body axes, from its shape and size.
fn component_inertia(shape: RawMassShape, mass: f64, s: &Vector3<f64>) -> Matrix3<f64> {
    match shape {
        RawMassShape::Point => Matrix3::zeros(),
        RawMassShape::Box => Matrix3::from_diagonal(&Vector3::new(
            mass * (s.y * s.y + s.z * s.z) / 12.0,
            mass * (s.x * s.x + s.z * s.z) / 12.0,
            mass * (s.x * s.x + s.y * s.y) / 12.0,
        )),
        RawMassShape::CylinderX => {
            let r = s.y / 2.0;
            let l = s.x;
            let across = mass * (3.0 * r * r + l * l) / 12.0;
            Matrix3::from_diagonal(&Vector3::new(mass * r * r / 2.0, across, across))
        }
    }
}

/// Checks the hydrostatics and returns the displaced volume and the centre of buoyancy
/// relative to the centre of mass `cg`, which must lie above it so the vehicle rights itself.
fn resolve_buoyancy(
    doc: &Document<'_>,
    h: &RawHydrostatics,
    cg: &Vector3<f64>,
) -> Result<(f64, Vector3<f64>), ConfigError> {
    let volume = doc.check_range(
        "hydrostatics.displaced_volume_m3",
        h.displaced_volume_m3,
        1e-4,
        10.0,
        "m^3",
    )?;
    let cb_box = check3(
        doc,
        "hydrostatics.centre_of_buoyancy_m",
        h.centre_of_buoyancy_m,
        -5.0,
        5.0,
        "m",
    )?;
    let cb = cb_box - cg;
    if cb.z >= 0.0 {
        return Err(doc.invalid(
            "hydrostatics.centre_of_buoyancy_m",
            format!(
                "the centre of buoyancy must lie above the centre of mass (it is {:.3} m below); \
                 Mako rights itself (thesis 2.2)",
                cb.z
            ),
        ));
    }
    Ok((volume, cb))
}

/// Checks the diagonal added mass: surge, sway, heave (kg), roll, pitch, yaw (kg m^2).
fn resolve_added_mass(doc: &Document<'_>, am: &RawAddedMass) -> Result<[f64; 6], ConfigError> {
    Ok([
        doc.check_range("added_mass.surge_kg", am.surge_kg, 0.0, 1000.0, "kg")?,
        doc.check_range("added_mass.sway_kg", am.sway_kg, 0.0, 1000.0, "kg")?,
        doc.check_range("added_mass.heave_kg", am.heave_kg, 0.0, 1000.0, "kg")?,
        doc.check_range("added_mass.roll_kgm2", am.roll_kgm2, 0.0, 100.0, "kg m^2")?,
        doc.check_range("added_mass.pitch_kgm2", am.pitch_kgm2, 0.0, 100.0, "kg m^2")?,
        doc.check_range("added_mass.yaw_kgm2", am.yaw_kgm2, 0.0, 100.0, "kg m^2")?,
    ])
}

/// The checked damping coefficients of the `[damping]` table.
struct Damping {
    linear: [f64; 6],
    quadratic: [f64; 6],
    sway_yaw: [f64; 2],
    yaw_uv: f64,
    yaw_ur: f64,
}

/// Checks the damping coefficients, axis by axis, and that every axis is damped at all.
fn resolve_damping(doc: &Document<'_>, raw: &RawDamping) -> Result<Damping, ConfigError> {
    let mut damping_linear = [0.0; 6];
    let mut damping_quadratic = [0.0; 6];
    for i in 0..6 {
        damping_linear[i] = doc.check_range(
            &format!("damping.linear.{i}"),
            raw.linear[i],
            0.0,
            1e4,
            "N/(m/s) or N m/(rad/s)",
        )?;
        damping_quadratic[i] = doc.check_range(
            &format!("damping.quadratic.{i}"),
            raw.quadratic[i],
            0.0,
            1e4,
            "N/(m/s)^2 or N m/(rad/s)^2",
        )?;
    }
    let damping_sway_yaw = [
        doc.check_range(
            "damping.sway_yaw.0",
            raw.sway_yaw[0],
            -1e3,
            1e3,
            "N/(rad/s)",
        )?,
        doc.check_range(
            "damping.sway_yaw.1",
            raw.sway_yaw[1],
            -1e3,
            1e3,
            "N m/(m/s)",
        )?,
    ];
    let yaw_uv = doc.check_range("damping.yaw_uv", raw.yaw_uv, -1e3, 1e3, "N m/(m/s)^2")?;
    let yaw_ur = doc.check_range(
        "damping.yaw_ur",
        raw.yaw_ur,
        -1e3,
        1e3,
        "N m/((m/s) (rad/s))",
    )?;
    if damping_linear
        .iter()
        .zip(&damping_quadratic)
        .any(|(l, q)| *l + *q <= 0.0)
    {
        return Err(doc.invalid(
            "damping",
            "every axis needs some damping (linear or quadratic)",
        ));
    }
    Ok(Damping {
        linear: damping_linear,
        quadratic: damping_quadratic,
        sway_yaw: damping_sway_yaw,
        yaw_uv,
        yaw_ur,
    })
}

/// Checks the `[thrusters]` settings common to all four motors.
fn resolve_thruster_common(
    doc: &Document<'_>,
    t: &RawThrusters,
) -> Result<ThrusterCommon, ConfigError> {
    Ok(ThrusterCommon {
        forward_max_n: doc.check_range(
            "thrusters.forward_max_n",
            t.forward_max_n,
            0.0,
            500.0,
            "N",
        )?,
        deadband: doc.check_range("thrusters.deadband", t.deadband, 0.0, 0.9, "")?,
        exponent: doc.check_range("thrusters.exponent", t.exponent, 0.5, 3.0, "")?,
        exponent_reverse: doc.check_range(
            "thrusters.exponent_reverse",
            t.exponent_reverse.unwrap_or(t.exponent),
            0.5,
            3.0,
            "",
        )?,
        lag_s: doc.check_range("thrusters.lag_s", t.lag_s, 0.0, 10.0, "s")?,
        lag_down_s: doc.check_range(
            "thrusters.lag_down_s",
            t.lag_down_s.unwrap_or(t.lag_s),
            0.0,
            10.0,
            "s",
        )?,
        lag_exponent: doc.check_range(
            "thrusters.lag_exponent",
            t.lag_exponent.unwrap_or(1.0),
            0.5,
            3.0,
            "",
        )?,
        fluctuation_rel_std: doc.check_range(
            "thrusters.fluctuation_rel_std",
            t.fluctuation_rel_std,
            0.0,
            0.5,
            "",
        )?,
        fluctuation_corr_s: doc.check_range(
            "thrusters.fluctuation_corr_s",
            t.fluctuation_corr_s,
            0.001,
            60.0,
            "s",
        )?,
    })
}

/// Resolves the four `[[thruster]]` tables, in [`THRUSTER_NAMES`] order, with positions
/// relative to the centre of mass `cg`, and checks the layout the thesis describes (2.2.1):
/// horizontal port/starboard, vertical bow/stern.
fn resolve_thrusters(
    doc: &Document<'_>,
    raw: &[RawThruster],
    cg: &Vector3<f64>,
) -> Result<[ThrusterConfig; 4], ConfigError> {
    if raw.len() != 4 {
        return Err(doc.invalid(
            "thruster",
            format!(
                "expected exactly four [[thruster]] tables ({}), found {}",
                THRUSTER_NAMES.join(", "),
                raw.len()
            ),
        ));
    }
    let mut thrusters = Vec::with_capacity(4);
    for (i, th) in raw.iter().enumerate() {
        thrusters.push(resolve_thruster(doc, i, th, cg)?);
    }
    let thrusters: [ThrusterConfig; 4] = match thrusters.try_into() {
        Ok(t) => t,
        Err(_) => return Err(doc.invalid("thruster", "expected four thrusters")),
    };
    let horizontal = |i: usize| thrusters[i].direction.z.abs() < 1e-6;
    let vertical = |i: usize| thrusters[i].direction.z.abs() > 1.0 - 1e-6;
    if !(horizontal(PORT) && horizontal(STARBOARD) && vertical(BOW) && vertical(STERN)) {
        return Err(doc.invalid(
            "thruster",
            "port and starboard must push horizontally, bow and stern vertically (thesis 2.2.1)",
        ));
    }
    Ok(thrusters)
}

/// Checks thruster table `i` (its name, position, unit direction, gain, reverse ratio and HDT
/// duty table) and resolves its position relative to the centre of mass `cg`.
fn resolve_thruster(
    doc: &Document<'_>,
    i: usize,
    th: &RawThruster,
    cg: &Vector3<f64>,
) -> Result<ThrusterConfig, ConfigError> {
    let key = format!("thruster.{i}");
    if th.name != THRUSTER_NAMES[i] {
        return Err(doc.invalid(
            &format!("{key}.name"),
            format!(
                "thruster {i} must be `{}` (order: {}), found `{}`",
                THRUSTER_NAMES[i],
                THRUSTER_NAMES.join(", "),
                th.name
            ),
        ));
    }
    let pos = check3(
        doc,
        &format!("{key}.position_m"),
        th.position_m,
        -5.0,
        5.0,
        "m",
    )?;
    let dir = check3(
        doc,
        &format!("{key}.direction"),
        th.direction,
        -1.0,
        1.0,
        "",
    )?;
    let norm = dir.norm();
    if (norm - 1.0).abs() > 1e-6 {
        return Err(doc.invalid(
            &format!("{key}.direction"),
            format!("must be a unit vector (its length is {norm})"),
        ));
    }
    let gain = doc.check_range(&format!("{key}.gain"), th.gain, 0.1, 2.0, "")?;
    let reverse_ratio = doc.check_range(
        &format!("{key}.reverse_ratio"),
        th.reverse_ratio,
        0.0,
        1.0,
        "",
    )?;
    let deadband = th
        .deadband
        .map(|d| doc.check_range(&format!("{key}.deadband"), d, 0.0, 0.9, ""))
        .transpose()?;
    let hdt_duty = resolve_hdt_duty(doc, &key, &th.hdt_duty)?;
    Ok(ThrusterConfig {
        name: th.name.clone(),
        position_cg_m: pos - cg,
        direction: dir,
        gain,
        reverse_ratio,
        deadband,
        hdt_duty,
    })
}

/// Checks a thruster's HDT balancing table: eleven duties that never increase with the
/// command (inverted logic: a larger command must never give a larger duty, i.e. less thrust).
fn resolve_hdt_duty(
    doc: &Document<'_>,
    key: &str,
    duties: &[f64],
) -> Result<[f64; 11], ConfigError> {
    if duties.len() != 11 {
        return Err(doc.invalid(
            &format!("{key}.hdt_duty"),
            format!(
                "expected 11 duties (MOTORDrive 0, 10, ..., 100 %), found {}",
                duties.len()
            ),
        ));
    }
    let mut hdt_duty = [0.0; 11];
    for (j, d) in duties.iter().enumerate() {
        hdt_duty[j] = doc.check_range(&format!("{key}.hdt_duty.{j}"), *d, 0.0, 255.0, "duty")?;
    }
    if hdt_duty.windows(2).any(|w| w[1] > w[0]) {
        return Err(doc.invalid(
            &format!("{key}.hdt_duty"),
            "duties must not increase with the command (duty 0 = full thrust)",
        ));
    }
    Ok(hdt_duty)
}
