//! The candidate library: effects a model may be missing, each a set of named parameters
//! (0 = "as the model already says"), a model extension (how the parameters change the
//! vehicle, world or sensor configuration in memory) and the channels its residual signature
//! lives in.
//!
//! Every extension changes existing configuration parameters; nothing in `physics` or
//! `sensors` had to change for the library.

use serde::Serialize;

use crate::gap::edit::Edit;
use crate::gap::run::Shooting;
use crate::physics::{VehicleConfig, WorldConfig};
use crate::sensors::SensorsConfig;

/// Everything a re-simulation needs, held in memory so effects can modify it.
#[derive(Debug, Clone, PartialEq)]
pub struct Configs {
    pub vehicle: VehicleConfig,
    pub world: WorldConfig,
    pub sensors: SensorsConfig,
    /// Per-axis analog errors the sensor configuration has no key for.
    pub analog: AnalogErrors,
    /// Where the point the overhead camera tracks (`x_m`, `y_m`) sits in the body frame,
    /// forward and starboard of the centre of mass (m). `[0, 0]` unless calibration fits it:
    /// the measurement format states no marker, and a marker off the centre traces a circle in
    /// every spin that no sway of the hull explains.
    pub camera_marker_body_m: [f64; 2],
    /// How the re-simulation is cut into re-anchored segments.
    pub shooting: Shooting,
}

impl Configs {
    /// The configurations as given: no analog errors, the camera on the centre of mass,
    /// open-loop re-simulation.
    pub fn new(vehicle: VehicleConfig, world: WorldConfig, sensors: SensorsConfig) -> Self {
        Self {
            vehicle,
            world,
            sensors,
            analog: AnalogErrors::default(),
            camera_marker_body_m: [0.0; 2],
            shooting: Shooting::OPEN_LOOP,
        }
    }
}

/// Zero offset and gain error of each accelerometer axis's ADC channel, on top of the sensor
/// configuration (whose zero-g voltage and sensitivity are shared by the three axes). A code
/// reads `code + offset_lsb + gain_scale * (code - zero-g code)`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AnalogErrors {
    pub accel_offset_lsb: [f64; 3],
    pub accel_gain_scale: [f64; 3],
}

impl Configs {
    /// The north and east offsets of the camera's marker from the centre of mass at
    /// `attitude`.
    pub fn camera_marker_ned(&self, attitude: &nalgebra::UnitQuaternion<f64>) -> [f64; 2] {
        let [x, y] = self.camera_marker_body_m;
        let offset = attitude * nalgebra::Vector3::new(x, y, 0.0);
        [offset.x, offset.y]
    }
}

impl AnalogErrors {
    /// The code an accelerometer axis reads for a true `code` whose zero-g code is `zero`.
    pub fn accel_code(&self, axis: usize, code: f64, zero: f64) -> f64 {
        code + self.accel_offset_lsb[axis] + self.accel_gain_scale[axis] * (code - zero)
    }
}

/// How an effect shows itself in the data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Changes the predicted mean of channels (fitted on residuals).
    Mean,
    /// Changes the spread of a channel (fitted on the Gaussian likelihood).
    Variance,
}

/// Which physical behaviour a summary quantity shows: straight-line speed or turning.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Behaviour {
    Speed,
    Turn,
}

/// One candidate effect: everything the workflow and the benchmarks know of it. Every other
/// module iterates over [`LIBRARY`]; none names an effect.
#[derive(Debug, Clone, Copy)]
pub struct Effect {
    pub name: &'static str,
    pub parameters: &'static [&'static str],
    /// Scale of each parameter for the fit and the starting step (a typical size).
    pub scales: &'static [f64],
    /// Physical bounds of each parameter (the change, in the parameter's unit): the fit never
    /// leaves them, and an effect whose fit ends on a bound is not named.
    pub bounds: &'static [(f64, f64)],
    pub signature: &'static str,
    /// Channels the signature lives in: the effect's pattern is tested against the
    /// disagreement there.
    pub channels: &'static [&'static str],
    /// Further channels the effect moves at first order without a pattern of its own there
    /// (a thruster imbalance's spot turn creeps ahead or astern): its gain there counts as
    /// gain in its signature channels, its correlation is not read there.
    pub also_moves: &'static [&'static str],
    pub kind: Kind,
    /// True when the extension changes the physics (the trajectory must be re-run).
    pub physics: bool,
    /// The model extension: how the parameters (in `parameters` order; a missing one is 0)
    /// change the configurations. Scale parameters multiply by `1 + p`, offsets add; results
    /// stay in each configured value's physical range. Called through [`apply`].
    pub extend: fn(&[f64], &mut Configs),
    /// True when the effect changes what a re-anchored re-simulation anchors to (the compass
    /// or the depth sensor), so its fit re-runs the physics even though it is a sensor's.
    pub moves_anchors: bool,
    /// The behaviours its physics changes, for summary observations (empty for a sensor).
    pub summary: &'static [Behaviour],
    /// Whether and how `gap calibrate` fits it (when the data hold one of its channels).
    pub calibration: Calibration,
    /// True when its one parameter only makes sense with one sign (a delay, an amplitude).
    pub positive: bool,
    /// True for a gain, an offset or the water current: the effects whose parameter error the
    /// simulator benchmark's target covers.
    pub parameter_error_target: bool,
    /// True for a term of the submerged vertical dynamics (the buoyancy, the heave damping,
    /// the vertical pair's thrust): afloat, a change of it moves only the height the hull
    /// floats at and how it bobs and dips, which the surface terms set too, so `gap
    /// calibrate` fits it only where the baseline runs dive
    /// ([`crate::gap::calibrate::SUBMERGED_MIN_S`]).
    pub submerged_only: bool,
    /// How the calibrated benchmarks' truth sources hide it (`None`: they do not).
    pub hidden: Option<Hiding>,
}

/// Whether and how `gap calibrate` fits an effect into the base model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Calibration {
    /// Left to `gap`, to be found as new.
    No,
    /// Fitted jointly with the other calibrated effects on the baseline runs' residuals, at
    /// this place in the joint fit's parameter vector (a bounded fit of twenty-odd parameters
    /// from two starts can end elsewhere when its columns are permuted, so the order is kept).
    Joint(u8),
    /// As `Joint`, and the joint fit also starts from this value of its first parameter (an
    /// effect that trades off against another, so that one start can stop short).
    JointTwoStarts(u8, f64),
    /// A noise level (a variance effect): fitted on each baseline run of the jointly
    /// calibrated model, its mean over the runs enters the model.
    NoiseLevel,
    /// A structural term of the base model, fitted jointly as `Joint` at this place and never
    /// a candidate `gap` names: the parametric model discrepancy of the calibration (the
    /// vehicle's own coefficients a different hull has differently), so that what a vehicle
    /// of another structure does differently lands here and not in the named effects' values.
    Discrepancy(u8),
    /// As `Discrepancy`, and the joint fit also starts from each of these values of its first
    /// parameter: a term that trades off against another, so that the start from the model as
    /// given can stop in the other's minimum (a camera marker ahead of the centre moves
    /// sideways in a spin as a hull that sways in spins does).
    DiscrepancyStarts(u8, &'static [f64]),
    /// A structural term of the base model that the calibration leaves as given and `gap`
    /// never names: tried only as a rival of an effect named after others
    /// ([`structural_rivals`]). Baseline runs seldom tell it (a lag's shape shows only after
    /// commands far faster or lags far longer than a calibration run's), so calibrated it would
    /// only take up other terms' share.
    Rival,
}

impl Calibration {
    /// Its place in `gap calibrate`'s joint fit, if it is fitted there.
    pub fn joint_place(&self) -> Option<u8> {
        match *self {
            Calibration::Joint(k)
            | Calibration::JointTwoStarts(k, _)
            | Calibration::Discrepancy(k)
            | Calibration::DiscrepancyStarts(k, _) => Some(k),
            Calibration::No | Calibration::NoiseLevel | Calibration::Rival => None,
        }
    }

    /// True when `gap calibrate` fits it jointly with the others.
    pub fn is_jointly_fitted(&self) -> bool {
        self.joint_place().is_some()
    }
}

impl Effect {
    /// True for an effect `gap` may name as new (every effect but the calibration's
    /// discrepancy terms and the structural rivals).
    pub fn candidate(&self) -> bool {
        !matches!(
            self.calibration,
            Calibration::Discrepancy(_) | Calibration::DiscrepancyStarts(..) | Calibration::Rival
        )
    }
}

/// The effects `gap` may name, in library order.
pub fn candidates() -> impl Iterator<Item = &'static Effect> {
    LIBRARY.iter().filter(|e| e.candidate())
}

/// Whether `effect`'s parameters are the components of one vector in a plane
/// ([`PLANE_VECTORS`]).
pub fn plane_vector(effect: &Effect) -> bool {
    PLANE_VECTORS.contains(&effect.name)
}

/// Whether `effect` changes the physics yet leaves the hull's motion through the water as
/// it was ([`WITH_THE_WATER`]).
pub fn with_the_water(effect: &Effect) -> bool {
    WITH_THE_WATER.contains(&effect.name)
}

/// Whether `a` and `b` are twins of one form ([`FORM_TWINS`]).
pub fn twins(a: &Effect, b: &Effect) -> bool {
    FORM_TWINS
        .iter()
        .any(|&(x, y)| (a.name, b.name) == (x, y) || (a.name, b.name) == (y, x))
}

/// The structural terms (the calibration's discrepancy terms and the rivals) that act on a
/// channel of `effect`'s signature: the structure of the base model that could explain what
/// `effect` would.
pub fn structural_rivals(effect: &Effect) -> Vec<&'static Effect> {
    LIBRARY
        .iter()
        .filter(|e| !e.candidate() && e.channels.iter().any(|c| effect.channels.contains(c)))
        .collect()
}

/// How the bridge and the independent model hide an effect.
#[derive(Debug, Clone, Copy)]
pub struct Hiding {
    /// The bridge's default size, in the library effect's parameters (a factor where
    /// `factor`). The same sizes as the independent model's where it has the effect; the lag
    /// is smaller, because the library's bound is 2 s.
    pub bridge_size: &'static [f64],
    /// The edits of the bridge's configuration files that hide `size` (the bridge's units).
    pub bridge: fn(&[f64]) -> Vec<Edit>,
    /// The independent model's name for it (`mako_independent.py --list`).
    pub independent: &'static str,
    /// The sources' size is a factor (no effect at 1; the library parameter is `size - 1`).
    pub factor: bool,
}

impl PartialEq for Effect {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name
    }
}

mod library;
mod structural;
pub use library::{FORM_TWINS, LIBRARY, PLANE_VECTORS, WITH_THE_WATER};

/// Looks an effect up by name.
pub fn by_name(name: &str) -> Option<&'static Effect> {
    LIBRARY.iter().find(|e| e.name == name)
}

/// Applies `effect` with `params` (same order as `effect.parameters`) to `c`.
pub fn apply(effect: &Effect, params: &[f64], c: &mut Configs) {
    (effect.extend)(params, c);
}

/// The parameter scales and bounds of `chosen` jointly fitted, in the joint parameter order
/// (each effect's parameters in turn).
pub fn joint_scales_and_bounds(chosen: &[&'static Effect]) -> (Vec<f64>, Vec<(f64, f64)>) {
    chosen
        .iter()
        .flat_map(|e| e.scales.iter().copied().zip(e.bounds.iter().copied()))
        .unzip()
}

/// Each of `chosen`'s values at the joint point `x` (in units of the scales).
pub fn joint_values(chosen: &[&'static Effect], x: &nalgebra::DVector<f64>) -> Vec<Vec<f64>> {
    let mut k = 0;
    chosen
        .iter()
        .map(|e| {
            let values = e
                .scales
                .iter()
                .enumerate()
                .map(|(j, s)| x[k + j] * s)
                .collect();
            k += e.parameters.len();
            values
        })
        .collect()
}

/// `base` with `chosen` applied at the joint point `x` (in units of the scales).
pub fn apply_joint(
    base: &Configs,
    chosen: &[&'static Effect],
    x: &nalgebra::DVector<f64>,
) -> Configs {
    let mut c = base.clone();
    for (e, values) in chosen.iter().zip(joint_values(chosen, x)) {
        apply(e, &values, &mut c);
    }
    c
}

/// True when `values` lie strictly inside `effect`'s bounds (an end on a bound is not a fit).
pub fn inside_bounds(effect: &Effect, values: &[f64]) -> bool {
    effect.bounds.iter().zip(values).all(|((lo, hi), v)| {
        let margin = 1e-6 * (hi - lo);
        *v > lo + margin && *v < hi - margin
    })
}

/// `values` clamped into `effect`'s bounds.
pub fn clamp_to_bounds(effect: &Effect, values: &mut [f64]) {
    for ((lo, hi), v) in effect.bounds.iter().zip(values.iter_mut()) {
        *v = v.clamp(*lo, *hi);
    }
}

#[cfg(test)]
mod tests;
