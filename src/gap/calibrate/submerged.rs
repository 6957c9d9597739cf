//! The submerged vertical dynamics (`Effect::submerged_only`): fitted only where the baseline
//! runs dive.

use super::Unidentified;
use crate::gap::effects::{Configs, Effect};
use crate::gap::format::Measurement;

/// How far below its run's shallowest depth reading a sample lies to count as submerged (m).
/// The surface programmes of structures 490499 and 502519 (wall runs, spins) spend 0 to 4 s
/// per run more than 0.10 m below their shallowest reading, 0 to 3.4 s more than 0.15 m.
pub const SUBMERGED_MARGIN_M: f64 = 0.15;

/// The time below the surface ([`SUBMERGED_MARGIN_M`]) the baseline runs need, together, for
/// an effect of the submerged vertical dynamics ([`Effect::submerged_only`]) to be fitted (s).
/// Structure 490499's three surface runs (a wall run, two spins) set the net buoyancy to
/// +0.70 N [0.20, 1.19], and a depth hold then read 410 chi-square per sample in depth
/// against 248 with the model as given; with the buoyancy held alone, the heave damping took
/// its place (685). A surface programme dips below it for a few
/// seconds at most ([`SUBMERGED_MARGIN_M`]); the depth holds and dives of the same
/// structures stay there for 164 to 170 s of their 180.
pub const SUBMERGED_MIN_S: f64 = 20.0;

/// The time `m`'s depth readings spend more than [`SUBMERGED_MARGIN_M`] below its shallowest
/// reading (s), read through the depth sensor of `c`; 0 without a depth channel.
pub(super) fn submerged_s(c: &Configs, m: &Measurement) -> f64 {
    let Some(ch) = m.channel("depth_adc").filter(|ch| ch.samples.len() > 1) else {
        return 0.0;
    };
    let d = &c.sensors.depth;
    if d.volts_per_m <= 0.0 {
        return 0.0;
    }
    let lsb = crate::sensors::AdcBoard::new(&c.sensors.adc, 0).lsb_v();
    let depth = |code: f64| (code - c.sensors.adc.offset_lsb) * lsb / d.volts_per_m;
    let shallowest = ch
        .samples
        .iter()
        .map(|(_, code)| depth(*code))
        .fold(f64::INFINITY, f64::min);
    let (first, last) = (ch.samples[0].0, ch.samples[ch.samples.len() - 1].0);
    let dt = (last - first) / (ch.samples.len() - 1) as f64;
    let below = ch
        .samples
        .iter()
        .filter(|(_, code)| depth(*code) > shallowest + SUBMERGED_MARGIN_M)
        .count();
    below as f64 * dt
}

/// `chosen` less the effects of the submerged vertical dynamics ([`Effect::submerged_only`]) when the baseline runs spent `below_s`
/// seconds submerged, under [`SUBMERGED_MIN_S`]; those are returned with why.
pub(super) fn hold_submerged_only(
    chosen: Vec<&'static Effect>,
    below_s: f64,
) -> (Vec<&'static Effect>, Vec<Unidentified>) {
    if below_s >= SUBMERGED_MIN_S {
        return (chosen, Vec::new());
    }
    let (held, kept): (Vec<&'static Effect>, Vec<&'static Effect>) =
        chosen.into_iter().partition(|e| e.submerged_only);
    let why = format!(
        "the baseline runs spend {below_s:.1} s more than {SUBMERGED_MARGIN_M} m below their \
         shallowest depth reading, under {SUBMERGED_MIN_S:.0} s: afloat, a change of buoyancy \
         moves only the height the hull floats at and its heave only how it bobs, which the \
         surface terms set too; calibrate on a run that dives to measure it"
    );
    let held = held
        .into_iter()
        .map(|e| Unidentified {
            effect: e.name.to_string(),
            why: why.clone(),
        })
        .collect();
    (kept, held)
}
