//! Cross-validation of the cost model: each scene's W* predicted by a calibration fitted on the
//! other scenes (leave-one-out, or k folds as in the paper), the model variants compared, and the
//! relative error every report uses. Shared by `examples/calibrate.rs` and `examples/evaluate`.

use alloc::vec::Vec;

use super::calibration::Calibration;
use super::decision::CostEstimate;
use super::fit::{fit, Observation, Terms};

/// `|estimate / measured − 1|`, with `∞/∞` counting as exact and one infinite (or non-positive
/// measured) side as 100 %.
pub fn relative_error(est: f64, meas: f64) -> f64 {
    match (est.is_finite(), meas.is_finite()) {
        (false, false) => 0.0,
        (true, true) if meas > 0.0 => (est / meas - 1.0).abs(),
        _ => 1.0,
    }
}

/// The median (upper middle for an even count), NaN for no values. Sorts `v`.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// How the grid's per-ray cost is taken from the sample rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridCost {
    /// Counted work times the calibrated per-operation costs (what the library does).
    Counted,
    /// The sample rays timed by the clock ([`Observation::sample_grid_ray_ns`]).
    Clock,
}

/// The estimates for `o` as the selector would make them at run time with `calibration`.
pub fn predicted_estimate(
    calibration: &Calibration,
    o: &Observation,
    grid: GridCost,
) -> CostEstimate {
    let mut e = calibration.estimate(&o.sample);
    if grid == GridCost::Clock {
        e.grid_ray_seconds = o.sample_grid_ray_ns * 1e-9;
    }
    e
}

/// W* for `o` as the selector would estimate it at run time with `calibration`.
pub fn predicted_break_even(calibration: &Calibration, o: &Observation, grid: GridCost) -> f64 {
    predicted_estimate(calibration, o, grid).break_even_rays()
}

/// Each observation's estimates, from a calibration fitted on the others: `folds = 0` leaves one
/// out at a time, otherwise observation `i` is in fold `i % folds`. NaN where no fit was possible.
pub fn cross_validated_estimates(
    obs: &[Observation],
    terms: &Terms,
    folds: usize,
    grid: GridCost,
) -> Vec<CostEstimate> {
    cross_validated_estimates_for(obs, obs, terms, folds, grid)
}

/// [`cross_validated_estimates`] with the calibrations fitted on `fitted` and each scene's
/// estimate made from `seen[i]` (the same scenes, in the same order; for example sample rays other
/// than the ones the calibration was fitted with, as the library sees them for a small budget).
pub fn cross_validated_estimates_for(
    fitted: &[Observation],
    seen: &[Observation],
    terms: &Terms,
    folds: usize,
    grid: GridCost,
) -> Vec<CostEstimate> {
    let fold_of = |i: usize| if folds == 0 { i } else { i % folds };
    let none = CostEstimate {
        grid_ray_seconds: f64::NAN,
        kd_ray_seconds: f64::NAN,
        kd_build_seconds: f64::NAN,
    };
    (0..seen.len().min(fitted.len()))
        .map(|i| {
            let rest: Vec<Observation> = fitted
                .iter()
                .enumerate()
                .filter(|&(j, _)| fold_of(j) != fold_of(i))
                .map(|(_, o)| *o)
                .collect();
            fit(&rest, terms, 0).map_or(none, |c| predicted_estimate(&c, &seen[i], grid))
        })
        .collect()
}

/// Each observation's predicted W* (see [`cross_validated_estimates`]).
pub fn cross_validated_break_even(
    obs: &[Observation],
    terms: &Terms,
    folds: usize,
    grid: GridCost,
) -> Vec<f64> {
    cross_validated_estimates(obs, terms, folds, grid)
        .iter()
        .map(CostEstimate::break_even_rays)
        .collect()
}

/// Each observation's cross-validated W* error (see [`cross_validated_break_even`]).
pub fn cross_validated_errors(
    obs: &[Observation],
    terms: &Terms,
    folds: usize,
    grid: GridCost,
) -> Vec<f64> {
    cross_validated_break_even(obs, terms, folds, grid)
        .iter()
        .zip(obs)
        .map(|(&est, o)| relative_error(est, o.measured_break_even()))
        .collect()
}

const fn terms(grid: [bool; 3], kd_build: [bool; 2], kd_ray: [bool; 3]) -> Terms {
    Terms([
        [true, false, false],
        grid,
        [kd_build[0], kd_build[1], false],
        kd_ray,
    ])
}

const ALL3: [bool; 3] = [true, true, true];

/// The model variants compared, fewest terms first: a term stays only if it lowers the
/// cross-validated error.
pub const VARIANTS: [(&str, Terms); 6] = [
    (
        "kd ray constant",
        terms(ALL3, [true, true], [true, false, false]),
    ),
    (
        "grid tests only",
        terms([false, false, true], [true, true], [false, false, true]),
    ),
    (
        "grid without cells",
        terms([true, false, true], [true, true], [true, false, true]),
    ),
    (
        "kd ray without cells",
        terms(ALL3, [true, true], [true, false, true]),
    ),
    (
        "kd build without grid references",
        terms(ALL3, [true, false], ALL3),
    ),
    ("all terms", Terms::ALL),
];

/// The variant with the lowest leave-one-out median W* error (ties to the earlier, smaller one),
/// with that error.
pub fn best_variant(obs: &[Observation]) -> (&'static str, Terms, f64) {
    let mut best = (VARIANTS[0].0, VARIANTS[0].1, f64::INFINITY);
    for (label, t) in VARIANTS {
        let m = median(&mut cross_validated_errors(obs, &t, 0, GridCost::Counted));
        if m < best.2 {
            best = (label, t, m);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_error_cases() {
        assert_eq!(relative_error(2.0, 1.0), 1.0);
        assert_eq!(relative_error(0.5, 1.0), 0.5);
        assert_eq!(relative_error(f64::INFINITY, f64::INFINITY), 0.0);
        assert_eq!(relative_error(5.0, f64::INFINITY), 1.0);
        assert_eq!(relative_error(f64::INFINITY, 5.0), 1.0);
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert!(median(&mut []).is_nan());
    }
}
