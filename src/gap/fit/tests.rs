use super::*;

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

/// The interval guard: an infinite interval, or an estimate whose confidence region holds
/// 0, names nothing; two correlated parameters whose intervals each hold 0 can still be
/// jointly clear of it.
#[test]
fn interval_guard_needs_finite_intervals_and_a_region_clear_of_zero() {
    let one = |x: f64, sd: f64| {
        let ci = [[x - 1.96 * sd, x + 1.96 * sd]];
        let cov = nalgebra::DMatrix::from_element(1, 1, sd * sd);
        interval_excludes_zero(&ci, &DVector::from_element(1, x), Some(&cov), 1.0)
    };
    assert!(one(0.2, 0.05));
    assert!(one(-0.2, 0.05));
    // The null run's thruster imbalance: -0.03 with [-0.58, 0.52].
    assert!(!one(-0.03, 0.28));
    // A variance factor widens the region.
    let cov = nalgebra::DMatrix::from_element(1, 1, 0.01);
    let x = DVector::from_element(1, 0.25);
    assert!(interval_excludes_zero(&[[0.05, 0.45]], &x, Some(&cov), 1.0));
    assert!(!interval_excludes_zero(
        &[[0.05, 0.45]],
        &x,
        Some(&cov),
        4.0
    ));
    assert!(!interval_excludes_zero(
        &[[f64::NEG_INFINITY, f64::INFINITY]],
        &x,
        Some(&cov),
        1.0
    ));
    // Strongly anti-correlated pair: each marginal holds 0, the pair does not.
    let cov = nalgebra::DMatrix::from_row_slice(2, 2, &[1.0, -0.99, -0.99, 1.0]);
    let x = DVector::from_row_slice(&[1.0, 1.0]);
    assert!(interval_excludes_zero(
        &[[-0.96, 2.96], [-0.96, 2.96]],
        &x,
        Some(&cov),
        1.0
    ));
    let x = DVector::from_row_slice(&[1.0, -1.0]);
    assert!(!interval_excludes_zero(
        &[[-0.96, 2.96], [-2.96, 0.96]],
        &x,
        Some(&cov),
        1.0
    ));
}

#[test]
fn split_alternates_blocks() {
    let s = Split { block_s: 10.0 };
    assert!(s.is_training(0.0));
    assert!(s.is_training(9.99));
    assert!(!s.is_training(10.0));
    assert!(!s.is_training(19.9));
    assert!(s.is_training(20.0));
}
