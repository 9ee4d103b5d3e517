//! The selection: which structure a scene builds over its validated mesh, and why (used by the
//! build and again when vertices move).

use super::{Accel, BudgetKind, BuildOptions, Outcome, Structure};
use crate::accel::kdtree::KdTree;
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::select::calibration::Calibration;
use crate::select::clock::Clock;
use crate::select::decision::{
    kd_tree_confirmed, kd_tree_confirmed_timed, kd_tree_work_limit, CostEstimate, Decision,
    OnlineSwitch,
};
use crate::select::model::SceneFeatures;
use crate::select::sample::{sample_grid, sample_kdtree, time_samples, RaySource, SampleParams};

/// What the selection built and what it learnt on the way.
pub(super) struct Choice {
    /// The structure to answer with.
    pub accel: Accel,
    /// Why.
    pub outcome: Outcome,
    /// The selector's estimate (`Auto` only).
    pub estimate: Option<CostEstimate>,
    /// The unknown-budget rule, while on the grid with `Auto` and no budget.
    pub online: Option<OnlineSwitch>,
    /// The library's sample rays on the grid (`Auto` with library-made samples only).
    pub grid_samples: Option<SceneFeatures>,
}

/// Builds the structure `options` ask for over `mesh`. `Auto` builds the grid, traces the sample
/// rays (`samples`, or the library's) through it, estimates the costs with `calibration`, and then:
/// with a known `expected_rays`, keeps the grid or replaces it by the kd-tree (at W*, or as a trial
/// where the build is cheap against the grid's time: see `Decision::Trial`; the grid is released
/// first, so the memory limit must hold the mesh and the kd-tree) and keeps that kd-tree only if
/// it is faster on the same samples (see `keeps_kd_tree`); with an unknown budget, stays on the
/// grid. What it built is
/// released on failure; `mesh` is the caller's.
pub(super) fn choose(
    mesh: &TriMesh,
    options: &BuildOptions,
    calibration: &Calibration,
    samples: Option<&dyn RaySource>,
    budget: &mut MemoryBudget,
) -> Result<Choice, BuildError> {
    let first = match options.structure {
        Structure::KdTree => Structure::KdTree,
        _ => Structure::Grid,
    };
    let mut accel = Accel::build(first, mesh, options, budget)?;
    let grid = match (&accel, options.structure) {
        (Accel::Grid(grid), Structure::Auto) => grid,
        _ => {
            return Ok(Choice {
                accel,
                outcome: Outcome::Forced,
                estimate: None,
                online: None,
                grid_samples: None,
            })
        }
    };
    let sample_params = options.samples.for_budget(options.expected_rays);
    let features = sample_grid(grid, mesh, samples, &sample_params);
    // No sample ray (none asked for, or an empty set given): nothing to estimate from, so the
    // estimates are NaN (`SampleParams::camera_side`'s promise) and the grid stays; the calibration
    // alone would price a scene it never saw a ray of (a review's finding: a kd-tree built as a
    // trial and kept by a check on no rays).
    let estimate = if features.rays == 0 {
        CostEstimate {
            grid_ray_seconds: f64::NAN,
            kd_ray_seconds: f64::NAN,
            kd_build_seconds: f64::NAN,
        }
    } else {
        calibration.estimate(&features)
    };
    let mut outcome = match options.expected_rays {
        0 => Outcome::OnlineOnGrid,
        budget_rays => match (estimate.decide(budget_rays), options.budget_kind) {
            (Decision::GridFasterPerRay, _) => Outcome::GridFasterPerRay,
            (Decision::BelowBreakEven, _) => Outcome::BelowBreakEven,
            // A trial that the check keeps is reported as above the break-even: the kd-tree was
            // built and measured to save work (the report's W* says which it was).
            (Decision::AboveBreakEven | Decision::Trial, BudgetKind::Expected) => {
                Outcome::AboveBreakEven
            }
            // An upper bound above W* (or the trial workload) may still end below it: pay for the
            // kd-tree only once the rays traced say so.
            (Decision::AboveBreakEven | Decision::Trial, BudgetKind::AtMost) => {
                Outcome::OnlineOnGrid
            }
        },
    };
    let max_rays = match (options.expected_rays, options.budget_kind) {
        (0, _) | (_, BudgetKind::Expected) => u64::MAX,
        (bound, BudgetKind::AtMost) => bound,
    };
    if outcome == Outcome::AboveBreakEven {
        // With a clock and the caller's samples, the grid's time on them for the check, while it
        // is warm from them (the library's own samples are priced: see `BuildOptions::clock`).
        let clock = options.clock.as_ref().filter(|_| samples.is_some());
        let grid_ns = clock.map(|c| time_samples(grid, mesh, samples, &sample_params, c));
        // The grid goes first, so the limit need hold only the mesh and the kd-tree.
        accel.release(budget);
        let limit = kd_tree_work_limit(features.triangles);
        let kept = match KdTree::build_within(mesh, &options.kdtree, budget, limit)? {
            // The check: a kd-tree that is not faster on the same sample rays goes.
            Some(tree) => {
                let timed = clock.zip(grid_ns);
                if keeps_kd_tree(
                    &tree,
                    mesh,
                    calibration,
                    &features,
                    timed,
                    samples,
                    &sample_params,
                ) {
                    Some(tree)
                } else {
                    Accel::KdTree(tree).release(budget);
                    None
                }
            }
            // Abandoned: its straddlers multiplied past any worthwhile tree's work.
            None => None,
        };
        accel = match kept {
            Some(tree) => Accel::KdTree(tree),
            None => {
                // The grid (linear, quick) is built again.
                outcome = Outcome::GridFasterPerRay;
                Accel::build(Structure::Grid, mesh, options, budget)?
            }
        };
    }
    Ok(Choice {
        accel,
        outcome,
        estimate: Some(estimate),
        online: (outcome == Outcome::OnlineOnGrid)
            .then(|| OnlineSwitch::at_most(estimate, max_rays)),
        grid_samples: samples.is_none().then_some(features),
    })
}

/// The check after a kd-tree build, on the sample rays `rays` (or the library's per `params`) that
/// gave `grid` on the grid: with `timed` (the scene's clock and the grid's time on those rays by
/// it, taken right after a counted pass of them), the kd-tree is kept only if they take it less
/// time ([`kd_tree_confirmed_timed`]), timed likewise right after a counted pass, so that neither
/// structure is timed cold (a kd-tree's first pass after its build took 1.3–3× its second in a
/// review's measurement); without, or when the clock did not move over a pass (one too coarse
/// for them says nothing), only if their counted work on it, priced, is below the grid's
/// ([`kd_tree_confirmed`]).
pub(super) fn keeps_kd_tree(
    tree: &KdTree,
    mesh: &TriMesh,
    calibration: &Calibration,
    grid: &SceneFeatures,
    timed: Option<(&Clock, u64)>,
    rays: Option<&dyn RaySource>,
    params: &SampleParams,
) -> bool {
    let kd = sample_kdtree(tree, mesh, rays, params);
    // The same rays on both structures, whose answers are the same.
    debug_assert_eq!((kd.rays, kd.hits), (grid.rays, grid.hits));
    if let Some((clock, grid_ns)) = timed.filter(|&(_, grid_ns)| grid_ns > 0) {
        let kd_ns = time_samples(tree, mesh, rays, params, clock);
        if kd_ns > 0 {
            return kd_tree_confirmed_timed(grid, grid_ns, kd_ns);
        }
    }
    kd_tree_confirmed(calibration, grid, &kd)
}
