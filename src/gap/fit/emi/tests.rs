//! The depth EMI candidate's tests: its signature on local variance, its range, and that
//! what it takes is white.

use super::*;
use crate::gap::effects::{Configs, Kind};
use crate::gap::fit::{Split, setup};

/// The EMI signature on squared differences drawn with a variance that follows the duty
/// (0 for 20 s, 0.4 for 40 s, 1 for 10 s, as a surfacing, a hold and a dive give; EMI
/// variance a sixth of the other noise's at the hold, equal to it at full duty): one
/// draw per sample correlates below the 0.2 bar although the EMI is there, the 1 s
/// window means correlate far above it, and with no EMI they stay below it.
#[test]
fn emi_signature_correlates_local_variance_not_single_draws() {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let times: Vec<f64> = (0..7000).map(|i| i as f64 * 0.01).collect();
    let duty = |t: f64| -> f64 {
        match t {
            t if t < 20.0 => 0.0,
            t if t < 60.0 => 0.4,
            _ => 1.0,
        }
    };
    let gain: Vec<f64> = times.iter().map(|t| (duty(*t) * 1.0).powi(2)).collect();
    let draw = |rng: &mut rand_chacha::ChaCha8Rng, var: f64| {
        let z: f64 = rng.sample(rand_distr::StandardNormal);
        var * z * z
    };
    let with: Vec<f64> = gain.iter().map(|g| draw(&mut rng, 1.0 + g)).collect();
    let without: Vec<f64> = gain.iter().map(|_| draw(&mut rng, 1.0)).collect();
    let single = crate::gap::residuals::pearson(&with, &gain);
    assert!(single < SIGNATURE_MIN_CORRELATION, "single draws: {single}");
    let (a, b) = window_means(&times, &with, &gain, EMI_WINDOW_S);
    assert_eq!(a.len(), 70);
    let windowed = crate::gap::residuals::pearson(&a, &b);
    assert!(windowed > 0.6, "windows: {windowed}");
    let (a, b) = window_means(&times, &without, &gain, EMI_WINDOW_S);
    let null = crate::gap::residuals::pearson(&a, &b);
    assert!(null.abs() < SIGNATURE_MIN_CORRELATION, "no EMI: {null}");
}

/// The library's noise source fitted on manoeuvre 23 of a vehicle whose depth EMI is 1.5 V
/// rms above the model's at full stern duty.
fn strong_emi_fitted() -> Candidate {
    let emi = effects::LIBRARY
        .iter()
        .find(|e| e.kind == Kind::Variance)
        .expect("the library has a noise source");
    let (_, c, m) = crate::gap::resim::tests::manoeuvre_of(23, |t: &mut Configs| {
        t.sensors.depth.emi_v_rms_full_duty += 1.5;
    });
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let setup = setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap();
    fit_emi(&setup, emi).expect("the depth channel is measured")
}

/// A depth EMI the low-pass passes at 0.13 V rms (1.5 V before it, at full stern duty) is
/// inside the library's range: fitted beyond 1 V with every guard passed. The range is the
/// sensor configuration's, before the filter; with a range of 1 V there the fit ended on its
/// bound, and an EMI of 20 LSB at the ADC could never be named.
#[test]
fn a_strong_depth_emi_is_fitted_inside_its_range() {
    let fitted = strong_emi_fitted();
    let value = fitted.parameters[0].1;
    assert!(fitted.guards.all(), "{:?}", fitted.guards);
    assert!(
        value > 1.0,
        "fitted {value:.3} {:?}, hidden 1.5",
        fitted.ci95[0].1
    );
}

/// What grows with the duty in a depth EMI fit must be white. A thruster lag rocks a depth
/// hold behind the stern duty, so the depth residuals' spread grows with the duty as an EMI's
/// does, but the rocking changes smoothly from sample to sample. Here a duty-scaled 0.4 Hz
/// rocking sampled at 10 Hz beside the floor's white noise reads no white growth and no
/// white successive differences, a white floor the model has too low reads no growth either,
/// and duty-scaled white noise reads far beyond the limits, its growth also beside the
/// rocking (a true EMI on a hull whose dynamics the model misses); on the simulator an EMI's
/// fit passes its signature.
#[test]
fn a_smooth_error_that_follows_the_stern_duty_is_no_emi() {
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let duty: Vec<f64> = (0..1800)
        .map(|i| if (i / 300) % 2 == 0 { 0.9 } else { 0.2 })
        .collect();
    let gain: Vec<f64> = duty.iter().map(|u| u * u).collect();
    let mut white = || -> f64 { rand::RngExt::sample(&mut rng, rand_distr::StandardNormal) };
    let floor = 0.1;
    let floor_noise: Vec<f64> = duty.iter().map(|_| floor * white()).collect();
    let noise: Vec<f64> = duty
        .iter()
        .zip(&floor_noise)
        .map(|(u, f)| u * white() + f)
        .collect();
    let rocking: Vec<f64> = duty
        .iter()
        .zip(&floor_noise)
        .enumerate()
        .map(|(i, (u, f))| u * (std::f64::consts::TAU * 0.4 * i as f64 * 0.1).sin() + f)
        .collect();
    let both: Vec<f64> = noise.iter().zip(&rocking).map(|(a, b)| a + b).collect();
    let w = vec![floor * floor; duty.len()];
    let of_noise = white_growth_z(&noise, &w, &gain);
    assert!(of_noise > 3.0 * EMI_WHITE_MIN_Z, "{of_noise}");
    let of_rocking = white_growth_z(&rocking, &w, &gain);
    assert!(of_rocking < EMI_WHITE_MIN_Z, "{of_rocking}");
    // Neither sign of whiteness: the successive differences at high duty correlate above the
    // limit too, where white noise's read near -0.5.
    let diffs = |r: &[f64]| -> Vec<f64> { r.windows(2).map(|w| w[1] - w[0]).collect() };
    let rocking_corr = successive_correlation(&diffs(&rocking), &gain[1..]);
    assert!(rocking_corr > EMI_WHITE_MAX_CORRELATION, "{rocking_corr}");
    let noise_corr = successive_correlation(&diffs(&noise), &gain[1..]);
    assert!(noise_corr < -0.4, "{noise_corr}");
    let of_both = white_growth_z(&both, &w, &gain);
    assert!(of_both > EMI_WHITE_MIN_Z, "{of_both}");
    let too_low_a_floor: Vec<f64> = duty.iter().map(|_| 0.5 * white()).collect();
    let of_floor = white_growth_z(&too_low_a_floor, &w, &gain);
    assert!(of_floor.abs() < EMI_WHITE_MIN_Z, "{of_floor}");

    let fitted = strong_emi_fitted();
    assert!(fitted.guards.signature, "{}", fitted.signature);
    assert!(
        fitted.signature.contains("from low to high duty = "),
        "{}",
        fitted.signature
    );
}
