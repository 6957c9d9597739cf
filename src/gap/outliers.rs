//! Isolated gross outliers in a measured channel: a reading far from its neighbours while
//! they agree with each other (a compass's first conversion before its field was read, a
//! camera that took a reflection for the marker for one frame).
//!
//! No effect of the library makes a single reading jump and come back, so such a reading is
//! disagreement no fit can take; left in, its square dominates its channel's chi-square,
//! inflates the residual variance every fit is judged against and dilutes every
//! correlation the signature tests read. It is set aside before the analysis and the report
//! names it ([`set_aside`]); the data file is never changed.
//!
//! The test is the Hampel identifier (Hampel 1974; Pearson 2002, "Outliers in process
//! modeling and identification") with a robust line in place of the median: a reading is an
//! outlier when it lies more than [`THRESHOLD`] robust sigmas from the Theil-Sen line through
//! the [`HALF_WINDOW`] readings either side of it ([`deviations`]). A line through six
//! neighbours follows a turn, a dive or a climb to the first and last reading of a run, and
//! any feature four readings wide (the acceleration of a thrust step) spreads the neighbours
//! about it so far that nothing stands out: only features of one to three readings can.
//! Compass headings are unwrapped first.

use statrs::statistics::{Data, Median};

use crate::gap::format::Channel;

/// Readings either side of a reading whose line it is compared with.
pub const HALF_WINDOW: usize = 3;
/// Robust sigmas from the neighbours' line beyond which a reading is an outlier: far outside
/// anything noise gives (a Gaussian reading lies 10 sigmas out once in 10^23).
pub const THRESHOLD: f64 = 10.0;
/// A channel where more than this share of the readings stand out (and more than one) holds
/// no isolated outliers but noise of another kind: nothing is set aside and a notice says so.
pub const MAX_SHARE: f64 = 0.01;
/// MAD to sigma for Gaussian data.
const MAD_TO_SIGMA: f64 = 1.4826;

fn median(v: Vec<f64>) -> f64 {
    Data::new(v).median()
}

/// Each reading's distance from what its neighbours predict, in units of how far the
/// neighbours themselves lie from that prediction.
///
/// The prediction is the Theil-Sen line (the median of the pairwise slopes, then the median
/// intercept; Sen 1968) through the [`HALF_WINDOW`] readings either side, the window shifted
/// inwards at the ends of the run so that a reading always has twice as many neighbours: a
/// turn, a dive or a climb under way at the first or last reading is predicted as well as in
/// the middle. The scale is 1.4826 times the neighbours' median absolute deviation from the
/// line, at least the median of that scale over the whole channel (six neighbours that
/// happen to lie close to their line do not make an ordinary reading stand out) and at least
/// the channel's resolution (the smallest step between successive readings: quantised
/// readings resting on one value do not make a one-step change an outlier). Near a turn's
/// reversal or a thrust step the neighbours stray from any line, the scale grows with them,
/// and nothing stands out.
fn deviations(channel: &Channel) -> Vec<f64> {
    let wrap = channel.name == "compass_deg";
    let mut values: Vec<f64> = Vec::with_capacity(channel.samples.len());
    for (_, v) in &channel.samples {
        let next = match values.last() {
            Some(prev) if wrap => prev + crate::gap::anchor::wrap_deg(v - prev),
            _ => *v,
        };
        values.push(next);
    }
    let times: Vec<f64> = channel.samples.iter().map(|(t, _)| *t).collect();
    let resolution = values
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let floor = if resolution.is_finite() {
        resolution
    } else {
        0.0
    };
    let n = values.len();
    let width = 2 * HALF_WINDOW + 1;
    let local: Vec<(f64, f64)> = (0..n)
        .map(|k| {
            let lo = k.saturating_sub(HALF_WINDOW).min(n - width);
            let near: Vec<usize> = (lo..lo + width).filter(|j| *j != k).collect();
            let mut slopes = Vec::with_capacity(near.len() * near.len() / 2);
            for (a, i) in near.iter().enumerate() {
                for j in &near[a + 1..] {
                    let dt = times[*j] - times[*i];
                    if dt > 0.0 {
                        slopes.push((values[*j] - values[*i]) / dt);
                    }
                }
            }
            let slope = if slopes.is_empty() {
                0.0
            } else {
                median(slopes)
            };
            let intercept = median(
                near.iter()
                    .map(|j| values[*j] - slope * times[*j])
                    .collect(),
            );
            let line = |j: usize| intercept + slope * times[j];
            let scale =
                MAD_TO_SIGMA * median(near.iter().map(|j| (values[*j] - line(*j)).abs()).collect());
            (values[k] - line(k), scale)
        })
        .collect();
    let typical = median(local.iter().map(|(_, s)| *s).collect()).max(floor);
    local
        .into_iter()
        .map(|(d, s)| {
            let scale = s.max(typical);
            if scale > 0.0 { d / scale } else { 0.0 }
        })
        .collect()
}

/// The indices of `channel`'s isolated gross outliers (none when it has too few readings to
/// tell), with every reading's scaled distance from its neighbours' line.
fn find(channel: &Channel) -> (Vec<usize>, Vec<f64>) {
    if crate::gap::sonar::index(&channel.name).is_some()
        || channel.samples.len() < 2 * HALF_WINDOW + 1
    {
        return (Vec::new(), Vec::new());
    }
    let dev = deviations(channel);
    let out = (0..dev.len())
        .filter(|k| dev[*k].abs() > THRESHOLD)
        .collect();
    (out, dev)
}

/// Sets aside every isolated gross outlier of `channels` (sonar channels excepted: an echo
/// that comes and goes is their signal), pushing one notice per reading onto `notices`:
/// where it was read (`origin`), the channel, the time, the value and how far it lay from its
/// neighbours. A channel with more than [`MAX_SHARE`] of its readings standing out keeps them
/// all, with a notice.
pub fn set_aside(origin: &str, channels: &mut [Channel], notices: &mut Vec<String>) {
    for ch in channels.iter_mut() {
        let (found, dev) = find(ch);
        if found.is_empty() {
            continue;
        }
        if found.len() as f64 > (MAX_SHARE * ch.samples.len() as f64).max(1.0) {
            notices.push(format!(
                "{origin}: {} has {} of {} readings more than {THRESHOLD} robust sigmas from \
                 the line through their neighbours: too many to be isolated outliers; all kept",
                ch.name,
                found.len(),
                ch.samples.len()
            ));
            continue;
        }
        for k in &found {
            let (t, v) = ch.samples[*k];
            notices.push(format!(
                "{origin}: {} at {t:.3} s reads {v}, {:.1} robust sigmas from the line through \
                 the {} readings around it: an isolated outlier, set aside from the analysis",
                ch.name,
                dev[*k].abs(),
                2 * HALF_WINDOW
            ));
        }
        let mut k = 0;
        ch.samples.retain(|_| {
            let keep = !found.contains(&k);
            k += 1;
            keep
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel(name: &str, values: &[f64], dt: f64) -> Channel {
        Channel {
            name: name.into(),
            samples: values
                .iter()
                .enumerate()
                .map(|(i, v)| (i as f64 * dt, *v))
                .collect(),
        }
    }

    /// A compass at rest reading whole degrees with a one-degree jitter, its first reading
    /// 100 degrees off; then a spin at 12 degrees a reading that crosses north, a stop and a
    /// spin back. Only the first reading is set aside, and the notice names it.
    #[test]
    fn a_lone_compass_reading_is_set_aside_and_turns_across_north_are_not() {
        let mut v: Vec<f64> = vec![77.0];
        v.extend((0..20).map(|i| 177.0 + f64::from(i % 3) - 1.0));
        let mut h: f64 = 177.0;
        for _ in 0..30 {
            h = (h + 12.0) % 360.0;
            v.push(h.round());
        }
        v.extend(std::iter::repeat_n(h.round(), 10));
        for _ in 0..15 {
            h = (h - 12.0).rem_euclid(360.0);
            v.push(h.round());
        }
        let mut chans = vec![channel("compass_deg", &v, 0.4)];
        let n = v.len();
        let mut notices = Vec::new();
        set_aside("m.csv", &mut chans, &mut notices);
        assert_eq!(chans[0].samples.len(), n - 1, "{notices:?}");
        assert_eq!(chans[0].samples[0], (0.4, 176.0));
        assert_eq!(notices.len(), 1);
        assert!(
            notices[0].contains("compass_deg at 0.000 s reads 77"),
            "{notices:?}"
        );
    }

    /// Features four readings wide or wider stay: an accelerometer's thrust-step plateau of
    /// four readings 20 codes up over a jitter of one code, a depth ramp; and a channel whose
    /// noise is heavy-tailed everywhere (more than 1 % standing out) keeps every reading,
    /// with a notice.
    #[test]
    fn plateaus_ramps_and_heavy_tails_are_kept() {
        let mut accel: Vec<f64> = (0..40).map(|i| 512.0 + f64::from(i % 2)).collect();
        for x in &mut accel[20..24] {
            *x += 20.0;
        }
        let depth: Vec<f64> = (0..60)
            .map(|i| {
                if i < 20 {
                    80.0
                } else {
                    80.0 + f64::from(i - 20) * 6.0
                }
            })
            .collect();
        let mut heavy: Vec<f64> = (0..200).map(|i| f64::from(i % 2)).collect();
        for k in (5..200).step_by(40) {
            heavy[k] += 50.0;
        }
        let mut chans = vec![
            channel("accel_x_adc", &accel, 0.1),
            channel("depth_adc", &depth, 0.1),
            channel("accel_y_adc", &heavy, 0.1),
        ];
        let mut notices = Vec::new();
        set_aside("m.csv", &mut chans, &mut notices);
        assert_eq!(chans[0].samples.len(), 40, "{notices:?}");
        assert_eq!(chans[1].samples.len(), 60, "{notices:?}");
        assert_eq!(chans[2].samples.len(), 200, "{notices:?}");
        assert_eq!(notices.len(), 1, "{notices:?}");
        assert!(notices[0].contains("too many"), "{notices:?}");
    }
}
