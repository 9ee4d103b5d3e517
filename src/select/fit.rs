//! Fitting a calibration to measurements: per part of the cost model, least squares on relative
//! error over the observed scenes, with coefficients that would be negative dropped (set to 0) and
//! the rest refitted. Pure arithmetic: works in `no_std`, so a renderer can calibrate in-process.

use super::calibration::{Calibration, CONSTANTS, CONSTANT_COUNT};
use super::decision::{grid_ray_constants, priced_work, CheckPrices, CostEstimate};
use super::model::{Part, SceneFeatures, MAX_TERMS};
use alloc::vec::Vec;

/// What was measured on one scene.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Observation {
    /// What the measured workload did on the grid (the fit's inputs).
    pub workload: SceneFeatures,
    /// What the selector's sample rays did on the grid (what a prediction sees at run time).
    pub sample: SceneFeatures,
    /// Grid build, nanoseconds.
    pub grid_build_ns: f64,
    /// kd-tree build, nanoseconds.
    pub kd_build_ns: f64,
    /// Grid time per workload ray, nanoseconds.
    pub grid_ray_ns: f64,
    /// kd-tree time per workload ray, nanoseconds.
    pub kd_ray_ns: f64,
    /// The sample rays' grid time per ray by the clock, nanoseconds: what a clock-based selector
    /// would use instead of counted work (compared in `examples/calibrate.rs`).
    pub sample_grid_ray_ns: f64,
}

impl Observation {
    /// The measured value that `part` predicts.
    pub fn measured(&self, part: Part) -> f64 {
        match part {
            Part::GridBuild => self.grid_build_ns,
            Part::GridRay => self.grid_ray_ns,
            Part::KdBuild => self.kd_build_ns,
            Part::KdRay => self.kd_ray_ns,
        }
    }

    /// The measured break-even workload (`+∞` when the kd-tree is not faster per ray).
    pub fn measured_break_even(&self) -> f64 {
        CostEstimate {
            grid_ray_seconds: self.grid_ray_ns * 1e-9,
            kd_ray_seconds: self.kd_ray_ns * 1e-9,
            kd_build_seconds: self.kd_build_ns * 1e-9,
        }
        .break_even_rays()
    }
}

/// Which terms of each part the fit may use (the others are fixed at 0), in [`Part::ALL`] order:
/// a term earns its place only if it lowers the cross-validated error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Terms(pub [[bool; MAX_TERMS]; 4]);

impl Terms {
    /// Every term of the model.
    pub const ALL: Terms = Terms([[true; MAX_TERMS]; 4]);

    fn of(&self, part: Part) -> [bool; MAX_TERMS] {
        let i = Part::ALL.iter().position(|&p| p == part).unwrap_or(0);
        let mut m = self.0[i];
        for (k, slot) in m.iter_mut().enumerate() {
            *slot &= k < part.constants().len();
        }
        m
    }
}

/// Why a fit failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitError {
    /// No usable observation (each needs positive, finite measurements).
    NoObservations,
}

/// Fits every part of the model to `observations`; constants the model does not use are 0.
/// Observations with a non-finite or non-positive measurement are left out of that part's fit.
pub fn fit(
    observations: &[Observation],
    terms: &Terms,
    machine: u64,
) -> Result<Calibration, FitError> {
    let mut values = [0.0; CONSTANT_COUNT];
    for part in Part::ALL {
        let coef = fit_part(observations, part, terms.of(part)).ok_or(FitError::NoObservations)?;
        for (i, c) in part.constants().zip(coef) {
            values[i] = c.clamp(CONSTANTS[i].min, CONSTANTS[i].max);
        }
    }
    Calibration::new(machine, values).map_err(|_| FitError::NoObservations)
}

/// True when `o`'s measurement of `part` can be fitted (finite, positive).
fn usable(o: &Observation, part: Part) -> bool {
    let y = o.measured(part);
    y.is_finite() && y > 0.0
}

/// Least squares of relative error for one part, dropping terms whose coefficient comes out
/// negative until none does. `None` when no observation is usable.
fn fit_part(
    observations: &[Observation],
    part: Part,
    mut mask: [bool; MAX_TERMS],
) -> Option<[f64; MAX_TERMS]> {
    let usable = |o: &&Observation| usable(o, part);
    if !observations.iter().any(|o| usable(&o)) {
        return None;
    }
    loop {
        let active: usize = mask.iter().map(|&m| usize::from(m)).sum();
        if active == 1 {
            return Some(median_ratio(observations, part, &mask));
        }
        let Some(c) = least_squares(observations, part, &mut mask) else {
            continue;
        };
        return Some(c);
    }
}

/// One coefficient (the one term `mask` leaves, from the start or after the others were
/// dropped): the median of measured / term, which a few scenes whose cost has another cause (a
/// kd-tree that never splits builds almost for free) cannot drag away, where least squares of
/// relative error would pull it towards the cheapest scenes.
fn median_ratio(
    observations: &[Observation],
    part: Part,
    mask: &[bool; MAX_TERMS],
) -> [f64; MAX_TERMS] {
    let usable = |o: &&Observation| usable(o, part);
    {
        let k = mask.iter().position(|&m| m).unwrap_or(0);
        let mut ratios: Vec<f64> = observations
            .iter()
            .filter(usable)
            .map(|o| o.measured(part) / part.terms(&o.workload)[k])
            .filter(|r| r.is_finite() && *r >= 0.0)
            .collect();
        if ratios.is_empty() {
            return [0.0; MAX_TERMS];
        }
        ratios.sort_by(f64::total_cmp);
        let mut c = [0.0; MAX_TERMS];
        c[k] = ratios[ratios.len() / 2];
        c
    }
}

/// Least squares of relative error over the terms `mask` leaves: the coefficients when none is
/// negative; otherwise the most negative term (or, for a singular system, the last one still in)
/// is dropped from `mask` and `None` returned, for the caller to fit again (all dropped: zeros).
fn least_squares(
    observations: &[Observation],
    part: Part,
    mask: &mut [bool; MAX_TERMS],
) -> Option<[f64; MAX_TERMS]> {
    let usable = |o: &&Observation| usable(o, part);
    {
        // Normal equations of Σ ((terms·c − y) / y)².
        let mut a = [[0.0f64; MAX_TERMS]; MAX_TERMS];
        let mut b = [0.0f64; MAX_TERMS];
        for o in observations.iter().filter(usable) {
            let y = o.measured(part);
            let t = part.terms(&o.workload).map(|x| x / y);
            for i in 0..MAX_TERMS {
                if !mask[i] {
                    continue;
                }
                b[i] += t[i];
                for j in 0..MAX_TERMS {
                    if mask[j] {
                        a[i][j] += t[i] * t[j];
                    }
                }
            }
        }
        for i in 0..MAX_TERMS {
            if !mask[i] {
                a[i] = [0.0; MAX_TERMS];
                a[i][i] = 1.0;
                b[i] = 0.0;
            }
        }
        // Drop the most negative coefficient and refit; when the data cannot tell the terms apart
        // (a singular system: a constant or repeated column), drop the last term still in.
        let worst = match solve(a, b) {
            Some(c) => {
                let worst = (0..MAX_TERMS)
                    .filter(|&i| mask[i] && !(c[i] >= 0.0))
                    .min_by(|&i, &j| {
                        c[i].partial_cmp(&c[j])
                            .unwrap_or(core::cmp::Ordering::Equal)
                    });
                if worst.is_none() {
                    return Some(c);
                }
                worst
            }
            None => (0..MAX_TERMS).rev().find(|&i| mask[i]),
        };
        if let Some(i) = worst {
            mask[i] = false;
        }
        if !mask.iter().any(|&m| m) {
            return Some([0.0; MAX_TERMS]);
        }
        None
    }
}

/// One scene's evidence for the prices of the check after a kd-tree build: what the selector's
/// sample rays did on each structure, and the measured time per ray of a workload on each.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CheckObservation {
    /// The sample rays' work on the grid.
    pub grid: SceneFeatures,
    /// The same rays' work on the kd-tree (`cells` are nodes).
    pub kd: SceneFeatures,
    /// Grid time per workload ray, nanoseconds.
    pub grid_ray_ns: f64,
    /// kd-tree time per workload ray, nanoseconds.
    pub kd_ray_ns: f64,
}

/// The check's prices ([`CheckPrices`]) that fit `observations` best: least squares of the
/// measured kd-tree − grid time per ray against the priced difference
/// ([`crate::select::decision::priced_work`]), the grid's side priced by `calibration`. Observations
/// without sample rays on both structures or with a non-finite time are left out; `None` when the
/// rest cannot tell the three prices apart (fewer than three, or a singular system).
pub fn fit_check_prices(
    observations: &[CheckObservation],
    calibration: &Calibration,
) -> Option<CheckPrices> {
    let [fixed, cell, test] = grid_ray_constants(calibration);
    let usable = |o: &&CheckObservation| {
        o.grid.rays > 0
            && o.kd.rays > 0
            && (o.kd_ray_ns - o.grid_ray_ns).is_finite()
            && o.grid_ray_ns.is_finite()
    };
    if observations.iter().filter(usable).count() < MAX_TERMS {
        return None;
    }
    // The kd-tree's priced time is `prices · terms`; it should equal the grid's priced time plus
    // the measured difference.
    let mut a = [[0.0f64; MAX_TERMS]; MAX_TERMS];
    let mut b = [0.0f64; MAX_TERMS];
    for o in observations.iter().filter(usable) {
        let terms = [
            fixed,
            cell * o.kd.cells_per_ray(),
            test * o.kd.tests_per_ray(),
        ];
        // The grid's side, which no price of the kd-tree's changes.
        let (grid_priced, _) = priced_work(calibration, &o.grid, &o.kd, &CheckPrices::LIBRARY);
        let y = grid_priced + (o.kd_ray_ns - o.grid_ray_ns);
        for i in 0..MAX_TERMS {
            b[i] += terms[i] * y;
            for j in 0..MAX_TERMS {
                a[i][j] += terms[i] * terms[j];
            }
        }
    }
    let [fixed_per_grid_fixed, node_per_cell_step, test_per_grid_test] = solve(a, b)?;
    Some(CheckPrices {
        fixed_per_grid_fixed,
        node_per_cell_step,
        test_per_grid_test,
    })
}

/// Solves `a·x = b` by Gaussian elimination with partial pivoting; `None` when singular.
// Row operations read one row while writing another: indices say that most plainly.
#[allow(clippy::needless_range_loop)]
fn solve(
    mut a: [[f64; MAX_TERMS]; MAX_TERMS],
    mut b: [f64; MAX_TERMS],
) -> Option<[f64; MAX_TERMS]> {
    for col in 0..MAX_TERMS {
        let pivot = (col..MAX_TERMS).max_by(|&i, &j| {
            a[i][col]
                .abs()
                .partial_cmp(&a[j][col].abs())
                .unwrap_or(core::cmp::Ordering::Equal)
        })?;
        if !(a[pivot][col].abs() > 1e-300) {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..MAX_TERMS {
            let f = a[row][col] / a[col][col];
            for k in col..MAX_TERMS {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; MAX_TERMS];
    for row in (0..MAX_TERMS).rev() {
        let mut s = b[row];
        for k in row + 1..MAX_TERMS {
            s -= a[row][k] * x[k];
        }
        x[row] = s / a[row][row];
    }
    if x.iter().all(|v| v.is_finite()) {
        Some(x)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn features(n: usize, h: f64, cells: f64, tests: f64) -> SceneFeatures {
        let rays = 1000;
        SceneFeatures {
            triangles: n,
            rays,
            hits: (h * rays as f64) as u64,
            cells: (cells * rays as f64) as u64,
            tests: (tests * rays as f64) as u64,
            grid_references: (n as f64 * (1.5 + h)) as u64,
            grid_largest_cell: 0,
        }
    }

    #[test]
    fn recovers_the_constants_of_a_model_it_can_express() {
        let truth =
            Calibration::new(0, [20.0, 50.0, 4.0, 30.0, 90.0, 7.0, 40.0, 2.0, 12.0]).unwrap();
        let obs: Vec<Observation> = [
            (1_000, 0.9, 10.0, 5.0),
            (20_000, 0.5, 40.0, 20.0),
            (300_000, 0.7, 25.0, 60.0),
            (80_000, 0.2, 70.0, 12.0),
            (5_000, 1.0, 15.0, 30.0),
        ]
        .iter()
        .map(|&(n, h, c, t)| {
            let f = features(n, h, c, t);
            Observation {
                workload: f,
                sample: f,
                grid_build_ns: Part::GridBuild.predict(&truth, &f),
                kd_build_ns: Part::KdBuild.predict(&truth, &f),
                grid_ray_ns: Part::GridRay.predict(&truth, &f),
                kd_ray_ns: Part::KdRay.predict(&truth, &f),
                sample_grid_ray_ns: 0.0,
            }
        })
        .collect();
        let got = fit(&obs, &Terms::ALL, 0).unwrap();
        for (i, (g, t)) in got.values().iter().zip(truth.values()).enumerate() {
            assert!(
                (g - t).abs() <= 1e-6 * t.abs().max(1.0),
                "constant {i}: {g} vs {t}"
            );
        }
        let w = obs[1].measured_break_even();
        assert!(w.is_finite(), "{w}");
        assert!((w - got.estimate(&obs[1].sample).break_even_rays()).abs() < 1e-3);
    }

    #[test]
    fn negative_coefficients_are_dropped_and_masked_terms_are_zero() {
        // Grid time falls with cells here (nonsense physically): the fit must not go negative.
        let obs: Vec<Observation> = [
            (1_000, 10.0, 100.0),
            (2_000, 20.0, 80.0),
            (3_000, 30.0, 60.0),
        ]
        .iter()
        .map(|&(n, c, y)| Observation {
            workload: features(n, 1.0, c, 1.0),
            grid_build_ns: 1.0,
            kd_build_ns: 1.0,
            grid_ray_ns: y,
            kd_ray_ns: 1.0,
            ..Observation::default()
        })
        .collect();
        let got = fit(&obs, &Terms::ALL, 0).unwrap();
        assert!(got.values().iter().all(|&v| v >= 0.0), "{:?}", got.values());
        let mut only_intercept = Terms::ALL;
        only_intercept.0[1] = [true, false, false];
        let got = fit(&obs, &only_intercept, 0).unwrap();
        assert_eq!((got.value(2), got.value(3)), (0.0, 0.0));
        assert!(got.value(1) > 0.0);
    }

    #[test]
    fn check_prices_are_recovered_from_times_they_explain() {
        let cal = Calibration::builtin();
        let truth = CheckPrices {
            fixed_per_grid_fixed: 0.6,
            node_per_cell_step: 0.5,
            test_per_grid_test: 1.5,
        };
        let obs: Vec<CheckObservation> = [
            (5.0, 40.0, 20.0, 10.0),
            (9.0, 60.0, 18.0, 14.0),
            (3.0, 20.0, 25.0, 30.0),
            (7.0, 70.0, 12.0, 8.0),
        ]
        .iter()
        .map(|&(cells, tests, nodes, kd_tests)| {
            let (grid, kd) = (
                features(1000, 0.5, cells, tests),
                features(1000, 0.5, nodes, kd_tests),
            );
            let (g, k) = crate::select::decision::priced_work(cal, &grid, &kd, &truth);
            CheckObservation {
                grid,
                kd,
                // Any grid time: only the difference is fitted.
                grid_ray_ns: 2.0 * g,
                kd_ray_ns: 2.0 * g + (k - g),
            }
        })
        .collect();
        let got = fit_check_prices(&obs, cal).unwrap();
        for (g, t) in [
            (got.fixed_per_grid_fixed, truth.fixed_per_grid_fixed),
            (got.node_per_cell_step, truth.node_per_cell_step),
            (got.test_per_grid_test, truth.test_per_grid_test),
        ] {
            assert!((g - t).abs() < 1e-9, "{got:?}");
        }
        // Too few usable scenes (a NaN time, no kd samples) cannot tell three prices apart.
        let mut few = obs[..3].to_vec();
        few[0].kd_ray_ns = f64::NAN;
        assert_eq!(fit_check_prices(&few, cal), None);
        few[0] = CheckObservation {
            kd: SceneFeatures::default(),
            ..obs[0]
        };
        assert_eq!(fit_check_prices(&few, cal), None);
    }

    #[test]
    fn nothing_usable_is_an_error() {
        let bad = Observation {
            grid_ray_ns: f64::NAN,
            ..Observation::default()
        };
        assert_eq!(fit(&[bad], &Terms::ALL, 0), Err(FitError::NoObservations));
        assert_eq!(fit(&[], &Terms::ALL, 0), Err(FitError::NoObservations));
    }
}
