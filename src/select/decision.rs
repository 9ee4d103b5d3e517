//! The decision of Hapala, Karlík, Havran (2011) for a known ray budget, and the online rule for an
//! unknown one. Pure arithmetic on cost estimates; where the estimates come from is the cost model's
//! business.

use super::calibration::Calibration;
use super::model::{Part, SceneFeatures};

/// Cost estimates, in seconds, for one scene whose grid is already built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostEstimate {
    /// Seconds per ray on the grid.
    pub grid_ray_seconds: f64,
    /// Seconds per ray on the kd-tree.
    pub kd_ray_seconds: f64,
    /// Seconds to build the kd-tree.
    pub kd_build_seconds: f64,
}

/// What to do with a known budget (the three outcomes of the paper, and a trial).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decision {
    /// The kd-tree is not faster per ray (or the estimates cannot tell): keep the grid.
    GridFasterPerRay,
    /// Fewer rays than the break-even workload: keep the grid.
    BelowBreakEven,
    /// At least the break-even workload: build the kd-tree.
    AboveBreakEven,
    /// Below the estimated break-even (or no saving estimated), but so many rays that the kd-tree's
    /// build costs at most [`TRIAL_SHARE`] of tracing them on the grid: build it and let the check
    /// after the build ([`kd_tree_confirmed`]) say which structure stays.
    Trial,
}

impl Decision {
    /// True when the decision is to build the kd-tree (outright or as a trial).
    pub fn builds_kd_tree(self) -> bool {
        matches!(self, Decision::AboveBreakEven | Decision::Trial)
    }
}

/// The share of the grid's estimated trace time that the selector spends on a kd-tree the
/// estimates do not favour, to measure it: with at least [`CostEstimate::trial_rays`] rays the
/// kd-tree is built and kept only if the check after the build finds it saves work. The estimate
/// of the kd-tree's cost per ray sees only the grid's statistics and is the model's weakest part
/// (docs/evaluation.md); a trial that loses costs at most this share of the run (more only by the
/// error of the build estimate, which the work limit caps), one that wins can save half of it
/// (sibenik, munich, stadium-1M trace 1.2–2× faster on the kd-tree where the estimate saw no
/// saving). Chosen on the evaluation's measurements ("Trial builds" there): 1/16 until stop 24;
/// 1/32 since stop 25, when the shallower kd-trees and the refitted check left 1/64 and 1/32 with
/// the regret of no trials (geometric mean 1.016–1.017, worst 1.32 in two runs) and 1/16 built a
/// trial on slivers-2k at 3·10⁴ rays whose build the estimate puts at a tenth of its time (worst
/// 1.38). Once the work limit was lowered (below) that trial stops sooner, and in the three runs after
/// it 1/16 and 1/32 had the same worst case (1.30–1.31) and regret within 0.001: 1/32 stayed, the
/// cheaper insurance. 1/16 again since stop 27: in that stop's four evaluation runs its trials
/// reached sphereflake-1M at 10⁷–3·10⁷ rays (the kd-tree 1.3–1.5× faster per ray there, a million
/// triangles whose grid misses the cache, which the estimate does not see), worst regret 1.42, 1.37,
/// 1.40, 1.375 against 1.51, 1.43, 1.41, 1.375 with 1/32, and the geometric mean 0.001 lower in
/// each (1.021–1.023); the trials built 46–52 of 341 budgets against 34–40. In a fifth run, with
/// 1/16 built in, the worst was the same at every share from 0 to 1/16 (tetra-10k 1.39) and 1/16's
/// trial on slivers-2k at 3·10⁴ rays came back (1.29: its build estimated at a tenth).
pub const TRIAL_SHARE: f64 = 1.0 / 16.0;

impl CostEstimate {
    /// True when every estimate is a number ≥ 0 (infinities allowed).
    fn is_valid(&self) -> bool {
        [
            self.grid_ray_seconds,
            self.kd_ray_seconds,
            self.kd_build_seconds,
        ]
        .iter()
        .all(|&x| x >= 0.0)
    }

    /// Per-ray saving of the kd-tree over the grid; ≤ 0 (or NaN) when there is none.
    fn saving_per_ray(&self) -> f64 {
        self.grid_ray_seconds - self.kd_ray_seconds
    }

    /// The break-even workload W* = T_build / (t_grid − t_kd): `+∞` when the kd-tree is not faster
    /// per ray, NaN when the estimates are not valid (NaN or negative), 0 when the build is free.
    pub fn break_even_rays(&self) -> f64 {
        if !self.is_valid() {
            return f64::NAN;
        }
        let saving = self.saving_per_ray();
        if !(saving > 0.0) {
            return f64::INFINITY;
        }
        if self.kd_build_seconds == 0.0 {
            return 0.0;
        }
        // An infinite build makes W* = ∞ (also against an infinite saving, whose quotient is NaN);
        // an infinite saving (the grid is hopeless) with a finite build makes it 0.
        if self.kd_build_seconds == f64::INFINITY {
            return f64::INFINITY;
        }
        self.kd_build_seconds / saving
    }

    /// The workload from which the kd-tree's build costs at most `share` of tracing on the grid,
    /// `T_build / (share · t_grid)`: NaN when the estimates (or `share`) are not valid, `+∞` for a
    /// share ≤ 0 (no trials), a free grid ray or an infinite build, 0 for a free build.
    pub fn trial_rays_at(&self, share: f64) -> f64 {
        if !self.is_valid() || share.is_nan() {
            return f64::NAN;
        }
        if !(share > 0.0) {
            // No trials.
            return f64::INFINITY;
        }
        if self.kd_build_seconds == 0.0 {
            return 0.0;
        }
        let paid = share * self.grid_ray_seconds;
        if !(paid > 0.0) || self.kd_build_seconds == f64::INFINITY {
            return f64::INFINITY;
        }
        self.kd_build_seconds / paid
    }

    /// [`CostEstimate::trial_rays_at`] for [`TRIAL_SHARE`].
    pub fn trial_rays(&self) -> f64 {
        self.trial_rays_at(TRIAL_SHARE)
    }

    /// The workload from which the selector builds the kd-tree: the smaller of W* and the trial
    /// workload at `share` (NaN when the estimates are not valid).
    pub fn build_rays_at(&self, share: f64) -> f64 {
        let (w, trial) = (self.break_even_rays(), self.trial_rays_at(share));
        if w.is_nan() || trial.is_nan() {
            return f64::NAN;
        }
        w.min(trial)
    }

    /// [`CostEstimate::build_rays_at`] for [`TRIAL_SHARE`].
    pub fn build_rays(&self) -> f64 {
        self.build_rays_at(TRIAL_SHARE)
    }

    /// The decision for `expected_rays` (> 0): build the kd-tree when `expected_rays ≥ W*`, or as a
    /// trial when `expected_rays` reaches [`CostEstimate::trial_rays`] first. Estimates that cannot
    /// tell keep the grid (`GridFasterPerRay`): the grid is already paid for.
    pub fn decide(&self, expected_rays: u64) -> Decision {
        let r = expected_rays as f64;
        let w = self.break_even_rays();
        if w.is_nan() {
            return Decision::GridFasterPerRay;
        }
        if r >= w {
            return Decision::AboveBreakEven;
        }
        if r >= self.trial_rays() {
            return Decision::Trial;
        }
        if w == f64::INFINITY {
            Decision::GridFasterPerRay
        } else {
            Decision::BelowBreakEven
        }
    }
}

/// The prices with which the check after a kd-tree build ([`kd_tree_confirmed`]) turns the counted
/// work of its sample rays into time per ray, relative to the calibration's grid constants (so that
/// they follow the machine): the grid's ray is priced as the calibration's grid model prices it
/// (its fixed cost per ray, a cost per cell step and one per triangle test), the kd-tree's as a
/// share of that fixed cost plus its node visits at a share of a cell step and its tests at a
/// multiple of a grid test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckPrices {
    /// A kd-tree ray's fixed cost (set-up, the exact test of its hit) as a share of the grid's.
    pub fixed_per_grid_fixed: f64,
    /// A node visit as a share of a grid cell step.
    pub node_per_cell_step: f64,
    /// A kd-tree triangle test as a multiple of a grid test.
    pub test_per_grid_test: f64,
}

impl CheckPrices {
    /// The library's prices: a kd-tree ray's fixed cost equal to the grid's (the two cancel), a
    /// node at 0.05 of a cell step, a test at 1.75 grid tests (fitted at stop 25 on the evaluation's
    /// 31 scenes, docs/design.md, "The check after the kd-tree is built").
    ///
    /// Not the prices that fit the evaluation best. Least squares of the measured kd-tree − grid
    /// time per ray ([`crate::select::fit::fit_check_prices`], docs/evaluation.md fits them on
    /// every run) gave at stop 27 a fixed cost 0.62 of the grid's, a node 0.53 of a cell step and a
    /// test 1.47 grid tests, close to the times measured apart (`raycost floor`; stop 25's
    /// regression on the workload's own counts): they kept the faster structure on 29 of 31 scenes
    /// in the run that fitted them and 24–27 in the seven runs after (these prices: 21–23), and in
    /// the one run that used them in the library the regret's geometric mean was 1.016 (1.020–1.024
    /// in the runs with these). But they drop sibenik's kd-tree, 7 % slower from the evaluation's
    /// outside view, which issue 14's interior case (the camera in the nave, the library's default
    /// samples) needs: AUTO / better went 1.009 → 1.154 (4 occlusion rays a hit) and 1.003 → 1.052
    /// (16), the grid traced the primary rays and `rq_scene_update` built the kd-tree again. Sample
    /// rays from inside the box (uniform origins, or origins on the surface by area with cosine
    /// directions) price sibenik's kd-tree 1.06–1.15× the grid's too, so they do not tell the
    /// interior apart, and a margin for kd-trees the estimate chose (kept up to 1.15× the grid's)
    /// kept stadium-10k's (priced 1.146, measured 1.37× slower: regret 1.43): sibenik at 1.133 and
    /// stadium-10k at 1.146 leave no margin between them. These prices, which favour the kd-tree
    /// where the two are close, stay until the samples can see an interior.
    pub const LIBRARY: CheckPrices = CheckPrices {
        fixed_per_grid_fixed: 1.0,
        node_per_cell_step: 0.05,
        test_per_grid_test: 1.75,
    };
}

/// The check after a kd-tree was built on an estimate: keep it only if its time per ray on the
/// sample rays, priced from their counted work ([`priced_work`] with [`CheckPrices::LIBRARY`]), is
/// below the grid's on the same rays (`grid` and `kd` from [`crate::select::sample::sample_grid`]
/// and [`crate::select::sample::sample_kdtree`]). Where the kd-tree does not save work (long slivers
/// it cannot separate, soups of overlapping triangles, scenes that are nearly empty space for the
/// grid), it is slower per ray whatever the estimate said, and the grid stays. No kd samples
/// confirm nothing to the contrary. A grid with a heavy cell ([`SceneFeatures::has_heavy_cell`])
/// never drops the kd-tree: the samples, a view of the whole box, rarely enter that cell, but a
/// renderer's rays go where the detail is, and each that enters it tests all its triangles (the
/// million-triangle stadium: one workload ray in 23 000 entered its cell of 227 000 triangles and
/// took 1.6 ms, and the counts said the grid was the cheaper while it was 4× slower per ray).
pub fn kd_tree_confirmed(
    calibration: &Calibration,
    grid: &SceneFeatures,
    kd: &SceneFeatures,
) -> bool {
    kd_tree_confirmed_at(calibration, grid, kd, &CheckPrices::LIBRARY)
}

/// The check after a kd-tree build when the scene has a clock: keep the kd-tree only if the sample
/// rays took it less time (`kd_ns`) than they took the grid (`grid_ns`, measured on the same rays
/// as plain queries, [`crate::select::sample::time_samples`]), or if `grid`'s counts (from those
/// rays) show a heavy cell, which the samples rarely enter (see [`kd_tree_confirmed`]); no samples
/// confirm nothing to the contrary. Time sees what counted work does not: a node or a test costs
/// more on rays that start on a surface in a random direction than on a camera's (with a sixteenth
/// of the evaluation's bounces as samples, the counts priced as [`kd_tree_confirmed`] prices them
/// keep the faster structure on 9 of 31 scenes, the clock on 27–30; docs/design.md, "The check
/// after the kd-tree is built").
pub fn kd_tree_confirmed_timed(grid: &SceneFeatures, grid_ns: u64, kd_ns: u64) -> bool {
    grid.rays == 0 || kd_ns < grid_ns || grid.has_heavy_cell()
}

/// [`kd_tree_confirmed`] with other prices, for the evaluation that fits them.
pub fn kd_tree_confirmed_at(
    calibration: &Calibration,
    grid: &SceneFeatures,
    kd: &SceneFeatures,
    prices: &CheckPrices,
) -> bool {
    let [grid_cost, kd_cost] = priced_parts(calibration, grid, kd, prices);
    // The fixed costs' difference apart from the work's: with equal fixed costs it is exactly 0,
    // and the verdict is the comparison of the work alone, rounded as before they were priced.
    let fixed = kd_cost[0] - grid_cost[0];
    let work = kd_cost[1] - grid_cost[1];
    kd.rays == 0 || fixed + work < 0.0 || grid.has_heavy_cell()
}

/// The time per ray of the same rays on the grid (`grid`) and on the kd-tree (`kd`, whose `cells`
/// are nodes), priced from their counted work as the check after a kd-tree build prices it
/// ([`kd_tree_confirmed_at`]): the grid by the calibration's grid model (fixed cost, cell steps,
/// tests), the kd-tree by `prices` relative to those constants. Nanoseconds per ray:
/// `(grid, kd)`.
pub fn priced_work(
    calibration: &Calibration,
    grid: &SceneFeatures,
    kd: &SceneFeatures,
    prices: &CheckPrices,
) -> (f64, f64) {
    let [grid_cost, kd_cost] = priced_parts(calibration, grid, kd, prices);
    (grid_cost[0] + grid_cost[1], kd_cost[0] + kd_cost[1])
}

/// The calibration's grid model per ray, in its term order: the fixed cost, a cell step, a test
/// (nanoseconds); the constants the check's prices are relative to.
pub(crate) fn grid_ray_constants(calibration: &Calibration) -> [f64; 3] {
    let first = Part::GridRay.constants().start;
    [0, 1, 2].map(|k| calibration.value(first + k))
}

/// [`priced_work`]'s two structures, each as its fixed cost per ray and its counted work.
fn priced_parts(
    calibration: &Calibration,
    grid: &SceneFeatures,
    kd: &SceneFeatures,
    prices: &CheckPrices,
) -> [[f64; 2]; 2] {
    let [fixed, cell, test] = grid_ray_constants(calibration);
    let grid_work = cell * grid.cells_per_ray() + test * grid.tests_per_ray();
    let kd_work = prices.node_per_cell_step * cell * kd.cells_per_ray()
        + prices.test_per_grid_test * test * kd.tests_per_ray();
    [
        [fixed, grid_work],
        [prices.fixed_per_grid_fixed * fixed, kd_work],
    ]
}

/// How much work [`kd_tree_work_limit`] lets a kd-tree build do, per `N·log2 N`, before the
/// selector abandons it. Measured on the evaluation's 31 scenes (`KdTree::build_work`): 1.3–3.9 on
/// every scene whose kd-tree is worth having (spd_teapot and gears the highest), 6.8 on hair and
/// 15 on slivers, whose kd-trees duplicate triangles at every level and trace 2× slower than the
/// grid. 5 stops those builds at 35–75 % of their work with room above the rest. Re-measured at
/// stop 19 with the costs chosen by time: 1.2–2.7 on the worthwhile trees, 3.6 on hair (whose build
/// now completes and is dropped by the check after it), 10–15 on slivers. Re-measured at stop 25
/// (the build without most bad refines, the smaller empty-space bonus; `raycost kdbuild`): 0.99–2.01
/// on the 31 scenes of the evaluation but slivers-2k (8.2), hair-50k the highest (stadium-1M 1.56,
/// sphereflake-1M 1.37); 3 leaves 1.5× room and stops
/// a sliver build at 37–45 % of its work instead of 61–71 % (less lost on a trial that the estimate
/// thought cheap).
pub const KD_WORK_PER_N_LOG_N: f64 = 3.0;

/// The floor of [`kd_tree_work_limit`] per triangle, so that tiny scenes (where `log2 N` is near 0)
/// are never abandoned: more than any measured scene's work per triangle but slivers' (stop 25:
/// 13–31 on the others, hair-50k's 31.3 the most; 64 until then).
pub const KD_WORK_FLOOR_PER_TRIANGLE: f64 = 40.0;

/// The work (items held by the build's nodes, summed) after which the selector abandons a kd-tree
/// it builds on an estimate, for `triangles` non-degenerate triangles: such a build is one whose
/// straddlers multiply without end, and its tree would be slower than the grid anyway; stopping
/// early bounds what the wrong estimate costs (the check after the build would drop it, but only
/// after the whole build).
pub fn kd_tree_work_limit(triangles: usize) -> u64 {
    let n = triangles as f64;
    let limit = (KD_WORK_PER_N_LOG_N * n * crate::math::log2_64(n.max(1.0)))
        .max(KD_WORK_FLOOR_PER_TRIANGLE * n);
    limit as u64
}

/// The unknown-budget rule: stay on the grid and switch once the excess already paid on the grid,
/// `(t_grid − t_kd)·rays`, reaches the kd-tree's build cost (ski rental with a discount). With the
/// switch at exactly W*, the total is never more than `(2 − t_kd/t_grid)×` the better of the two
/// fixed choices made knowing the budget; switching at the end of a batch adds at most that batch's
/// excess. It also switches, as a trial, once the grid has cost [`TRIAL_SHARE`]`⁻¹` times the
/// kd-tree's estimated build, whatever W* says; the check after the build keeps the faster
/// structure, so that with exact estimates and check the total stays within
/// `max(2 − t_kd/t_grid, 1 + TRIAL_SHARE)×` the better fixed choice.
///
/// With an upper bound on the budget ([`OnlineSwitch::at_most`]) the rule also never switches when
/// the rays that may still come are fewer than the workload it would switch at: then the kd-tree
/// cannot pay back its build (or be worth a trial) whatever the renderer does, and the bound only
/// removes switches that lose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OnlineSwitch {
    estimate: CostEstimate,
    rays_on_grid: u64,
    /// At most this many rays in all (`u64::MAX`: no bound).
    max_rays: u64,
}

impl OnlineSwitch {
    /// A rule for a scene with these estimates and no rays traced yet.
    pub fn new(estimate: CostEstimate) -> Self {
        Self::at_most(estimate, u64::MAX)
    }

    /// A rule for a scene that will trace at most `max_rays` rays in all.
    pub fn at_most(estimate: CostEstimate, max_rays: u64) -> Self {
        OnlineSwitch {
            estimate,
            rays_on_grid: 0,
            max_rays,
        }
    }

    /// The same rule with better estimates (the rays traced so far and the bound unchanged).
    pub fn set_estimate(&mut self, estimate: CostEstimate) {
        self.estimate = estimate;
    }

    /// The most rays that may still come (`u64::MAX` without a bound).
    pub fn rays_that_may_remain(&self) -> u64 {
        if self.max_rays == u64::MAX {
            u64::MAX
        } else {
            self.max_rays.saturating_sub(self.rays_on_grid)
        }
    }

    /// True when the rays that may still come could pay back the kd-tree's build, or reach its
    /// trial workload ([`CostEstimate::build_rays`]; always without a bound; never for estimates
    /// that cannot tell).
    pub fn may_pay_back(&self) -> bool {
        let w = self.estimate.build_rays();
        w < f64::INFINITY && (self.max_rays == u64::MAX || self.rays_that_may_remain() as f64 >= w)
    }

    /// Rays traced on the grid so far.
    pub fn rays_on_grid(&self) -> u64 {
        self.rays_on_grid
    }

    /// Seconds paid so far beyond what the kd-tree would have cost for the same rays.
    pub fn excess_paid(&self) -> f64 {
        let saving = self.estimate.saving_per_ray();
        if saving > 0.0 {
            saving * self.rays_on_grid as f64
        } else {
            0.0
        }
    }

    /// Records `rays` more traced on the grid; true when it is now time to switch.
    pub fn record(&mut self, rays: u64) -> bool {
        self.rays_on_grid = self.rays_on_grid.saturating_add(rays);
        self.should_switch()
    }

    /// True when the excess paid has reached the build cost, or the grid has cost the build
    /// [`TRIAL_SHARE`]`⁻¹` times over (a trial, for a kd-tree the estimates do not favour), and the
    /// rays that may still come could pay it back (never for estimates that cannot tell).
    pub fn should_switch(&self) -> bool {
        self.may_pay_back() && self.rays_on_grid as f64 >= self.estimate.build_rays()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn est(g: f64, k: f64, b: f64) -> CostEstimate {
        CostEstimate {
            grid_ray_seconds: g,
            kd_ray_seconds: k,
            kd_build_seconds: b,
        }
    }

    /// 100 rays' features: `cells` and `tests` a ray, the grid's largest cell `largest`.
    fn feature(triangles: usize, cells: u64, tests: u64, largest: u64) -> SceneFeatures {
        SceneFeatures {
            triangles,
            rays: 100,
            cells: 100 * cells,
            tests: 100 * tests,
            grid_largest_cell: largest,
            ..SceneFeatures::default()
        }
    }

    /// The check keeps a kd-tree that its counts say is the dearer when the grid has a heavy
    /// cell: at least 1 024 triangles and a sixteenth of the scene's, not one less.
    #[test]
    fn a_heavy_cell_keeps_the_kd_tree() {
        let calibration = Calibration::builtin();
        // Counts like the stadium's (stop 19: 2 cells and 8 tests against 10 nodes and 16 tests),
        // with a few more kd tests, so that the grid looks cheaper at any of the fitted prices.
        let kd = feature(1_000_000, 10, 24, 0);
        for (triangles, largest, kept) in [
            (1_000_000, 227_012, true),
            (1_000_000, 62_500, true),
            (1_000_000, 62_499, false),
            (10_000, 1024, true),
            (10_000, 1023, false),
            (1_000_000, 0, false),
        ] {
            let grid = feature(triangles, 2, 8, largest);
            assert_eq!(
                kd_tree_confirmed(calibration, &grid, &kd),
                kept,
                "{triangles} triangles, largest cell {largest}"
            );
        }
    }

    /// The check prices the grid's ray with the calibration's grid model (fixed 50, a cell 4, a
    /// test 2 here) and the kd-tree's with its prices relative to those constants, and with equal
    /// fixed costs the verdict is the comparison of the work alone, even at a tie.
    #[test]
    fn the_check_prices_both_rays_from_the_grid_model() {
        let cal = Calibration::new(0, [1.0, 50.0, 4.0, 2.0, 1.0, 0.0, 1.0, 0.0, 0.0]).unwrap();
        let grid = SceneFeatures {
            triangles: 1000,
            rays: 10,
            cells: 30,
            tests: 200,
            ..SceneFeatures::default()
        };
        let kd = SceneFeatures {
            cells: 100,
            tests: 80,
            ..grid
        };
        let prices = CheckPrices {
            fixed_per_grid_fixed: 0.5,
            node_per_cell_step: 0.25,
            test_per_grid_test: 1.5,
        };
        // Grid: 50 + 4·3 + 2·20 = 102; kd-tree: 25 + 0.25·4·10 + 1.5·2·8 = 59.
        assert_eq!(priced_work(&cal, &grid, &kd, &prices), (102.0, 59.0));
        assert!(kd_tree_confirmed_at(&cal, &grid, &kd, &prices));
        // Equal fixed costs and equal work: a tie keeps the grid.
        let tie = CheckPrices {
            fixed_per_grid_fixed: 1.0,
            node_per_cell_step: 0.0,
            test_per_grid_test: 1.0,
        };
        let same_tests = SceneFeatures {
            cells: 0,
            tests: 260,
            ..grid
        };
        // Grid work 4·3 + 2·20 = 52; kd-tree work 2·26 = 52.
        assert!(!kd_tree_confirmed_at(&cal, &grid, &same_tests, &tie));
    }

    /// The timed check keeps the kd-tree when it took strictly less time than the grid on the same
    /// samples, when there were no samples, and whenever the grid has a heavy cell.
    #[test]
    fn the_timed_check_keeps_the_faster_unless_a_cell_is_heavy() {
        let grid = feature(10_000, 2, 8, 0);
        assert!(kd_tree_confirmed_timed(&grid, 1000, 999));
        assert!(!kd_tree_confirmed_timed(&grid, 1000, 1000));
        assert!(!kd_tree_confirmed_timed(&grid, 1000, 5000));
        let heavy = feature(10_000, 2, 8, 1024);
        assert!(kd_tree_confirmed_timed(&heavy, 1000, 5000));
        let none = SceneFeatures { rays: 0, ..grid };
        assert!(kd_tree_confirmed_timed(&none, 0, 0));
    }

    #[test]
    fn each_outcome_and_the_boundary() {
        let e = est(3.0, 1.0, 2000.0); // W* = 1000, exactly in binary
        assert_eq!(e.break_even_rays(), 1000.0);
        assert_eq!(e.decide(999), Decision::BelowBreakEven);
        assert_eq!(e.decide(1000), Decision::AboveBreakEven);
        assert_eq!(e.decide(u64::MAX), Decision::AboveBreakEven);
        // No saving: the grid, until the build is a sixteenth of the grid's time (16 000 rays).
        assert_eq!(TRIAL_SHARE, 1.0 / 16.0);
        assert_eq!(
            est(1e-6, 1e-6, 1e-3).decide(15_999),
            Decision::GridFasterPerRay
        );
        // (1e-3 / (1e-6 / 16) may round a hair above 16 000.)
        assert_eq!(est(1e-6, 1e-6, 1e-3).decide(16_001), Decision::Trial);
        assert_eq!(est(1e-6, 1e-6, 1e-3).decide(u64::MAX), Decision::Trial);
        // A free build is always worth a trial.
        assert_eq!(est(1e-6, 2e-6, 0.0).decide(1), Decision::Trial);
        assert_eq!(est(1e-6, 2e-6, 0.0).break_even_rays(), f64::INFINITY);
    }

    #[test]
    fn infinities_and_nan() {
        // A hopeless grid: W* = 0, any budget builds the kd-tree.
        assert_eq!(est(f64::INFINITY, 1e-6, 1.0).break_even_rays(), 0.0);
        assert_eq!(
            est(f64::INFINITY, 1e-6, 1.0).decide(1),
            Decision::AboveBreakEven
        );
        // An endless build: never.
        assert_eq!(
            est(2e-6, 1e-6, f64::INFINITY).break_even_rays(),
            f64::INFINITY
        );
        assert_eq!(
            est(2e-6, 1e-6, f64::INFINITY).decide(u64::MAX),
            Decision::GridFasterPerRay
        );
        // Both infinite per ray: no saving to speak of, but any build is cheap against the grid.
        assert_eq!(
            est(f64::INFINITY, f64::INFINITY, 1.0).break_even_rays(),
            f64::INFINITY
        );
        assert_eq!(
            est(f64::INFINITY, f64::INFINITY, 1.0).decide(1),
            Decision::Trial
        );
        // A free build pays at once.
        assert_eq!(est(2e-6, 1e-6, 0.0).decide(1), Decision::AboveBreakEven);
        for bad in [
            est(f64::NAN, 1e-6, 1.0),
            est(2e-6, f64::NAN, 1.0),
            est(2e-6, 1e-6, f64::NAN),
            est(2e-6, -1e-6, 1.0),
        ] {
            assert!(bad.break_even_rays().is_nan(), "{bad:?}");
            assert_eq!(bad.decide(u64::MAX), Decision::GridFasterPerRay, "{bad:?}");
            assert!(!OnlineSwitch::new(bad).record(u64::MAX));
        }
    }

    /// Total seconds for `total` rays under the online rule, in batches of `batch`, with an exact
    /// check after the build (the faster structure traces the rest).
    fn online_total(e: &CostEstimate, total: u64, batch: u64) -> f64 {
        let mut rule = OnlineSwitch::new(*e);
        let mut cost = 0.0;
        let mut done = 0;
        while done < total {
            let n = batch.min(total - done);
            cost += n as f64 * e.grid_ray_seconds;
            done += n;
            if rule.record(n) {
                let rest = e.kd_ray_seconds.min(e.grid_ray_seconds);
                return cost + e.kd_build_seconds + (total - done) as f64 * rest;
            }
        }
        cost
    }

    #[test]
    fn a_trial_comes_where_the_build_is_cheap_against_the_grid() {
        // No saving estimated: W* = ∞, the trial at 16·2000/1 = 32 000 rays.
        assert_eq!(TRIAL_SHARE, 1.0 / 16.0);
        let e = est(1.0, 2.0, 2000.0);
        assert_eq!(e.break_even_rays(), f64::INFINITY);
        assert_eq!(e.trial_rays(), 32_000.0);
        assert_eq!(e.build_rays(), 32_000.0);
        assert_eq!(e.decide(31_999), Decision::GridFasterPerRay);
        assert_eq!(e.decide(32_000), Decision::Trial);
        // A small saving: W* = 20 000 before the trial's 32 000.
        let small = est(1.0, 0.9, 2000.0);
        assert_eq!(small.trial_rays(), 32_000.0);
        let w = small.break_even_rays();
        assert!((w - 20_000.0).abs() < 1e-6, "{w}");
        assert_eq!(small.decide(19_000), Decision::BelowBreakEven);
        assert_eq!(small.decide(20_001), Decision::AboveBreakEven);
        let smaller = est(1.0, 0.99, 2000.0);
        assert_eq!(smaller.decide(31_999), Decision::BelowBreakEven);
        assert_eq!(smaller.decide(32_000), Decision::Trial);
        // A big saving: W* comes first and the trial never matters.
        let big = est(3.0, 1.0, 2000.0);
        assert_eq!(big.build_rays(), 1000.0);
        // An infinite build against an infinite grid cost: never worth it (not ∞/∞ = NaN).
        let hopeless = est(f64::INFINITY, 1e-6, f64::INFINITY);
        assert_eq!(hopeless.break_even_rays(), f64::INFINITY);
        assert_eq!(hopeless.trial_rays(), f64::INFINITY);
        // Estimates that cannot tell: no trial either.
        assert!(est(f64::NAN, 1.0, 1.0).build_rays().is_nan());
        assert_eq!(
            est(f64::NAN, 1.0, 1.0).decide(u64::MAX),
            Decision::GridFasterPerRay
        );
        assert_eq!(est(0.0, 1.0, 1.0).trial_rays(), f64::INFINITY);
        assert_eq!(est(1.0, 2.0, 0.0).trial_rays(), 0.0);
        // The online rule switches at the trial too.
        let mut rule = OnlineSwitch::new(e);
        assert!(!rule.record(31_999));
        assert!(rule.record(1));
        // An upper bound below the trial workload: never.
        assert!(!OnlineSwitch::at_most(e, 31_999).may_pay_back());
    }

    #[test]
    fn online_rule_is_within_its_competitive_bound() {
        let scenes = [
            est(2e-6, 1e-6, 1e-3),
            est(5e-6, 1e-6, 0.5),
            est(1.1e-6, 1e-6, 0.02),
            est(1e-6, 2e-6, 0.01),
            est(3e-7, 1e-7, 2.0),
        ];
        for e in scenes {
            let bound = if e.grid_ray_seconds > e.kd_ray_seconds {
                2.0 - e.kd_ray_seconds / e.grid_ray_seconds
            } else {
                1.0
            }
            .max(1.0 + TRIAL_SHARE);
            let w = e.build_rays();
            for exp in 0..=12 {
                for mantissa in [1u64, 3] {
                    let total = mantissa * 10u64.pow(exp);
                    // Batches small against W*, as between passes of a renderer.
                    let batch = if w.is_finite() {
                        ((w / 64.0) as u64).max(1)
                    } else {
                        1000
                    };
                    let online = online_total(&e, total, batch);
                    let oracle = (total as f64 * e.grid_ray_seconds)
                        .min(e.kd_build_seconds + total as f64 * e.kd_ray_seconds);
                    let slack = 1.0 + 1.0 / 32.0; // at most one batch of excess past W*
                    assert!(
                        online <= oracle * bound * slack + 1e-15,
                        "{e:?}, {total} rays: online {online}, oracle {oracle}, bound {bound}"
                    );
                }
            }
        }
    }

    #[test]
    fn an_upper_bound_only_removes_switches_that_cannot_pay() {
        let e = est(3.0, 1.0, 2000.0); // W* = 1000
                                       // At most 1999 rays: after the 1000th only 999 may remain, fewer than W*.
        let mut capped = OnlineSwitch::at_most(e, 1999);
        assert!(capped.may_pay_back());
        assert!(!capped.record(1000));
        assert_eq!(capped.rays_that_may_remain(), 999);
        assert!(!capped.may_pay_back());
        // At most 2000: exactly W* may remain at the switch, which pays (ties build).
        let mut enough = OnlineSwitch::at_most(e, 2000);
        assert!(enough.record(1000));
        // A bound below W* from the start: never.
        assert!(!OnlineSwitch::at_most(e, 999).may_pay_back());
        // Without a bound the rule is the plain one.
        let mut plain = OnlineSwitch::new(e);
        assert_eq!(plain.rays_that_may_remain(), u64::MAX);
        assert!(plain.record(1000));
        // Over any true total up to the bound, the capped rule never costs more than the plain one.
        for total in [500u64, 1000, 1500, 1999] {
            let cost = |rule: OnlineSwitch| {
                let mut rule = rule;
                let mut c = 0.0;
                for done in 1..=total {
                    c += e.grid_ray_seconds;
                    if rule.record(1) {
                        return c + e.kd_build_seconds + (total - done) as f64 * e.kd_ray_seconds;
                    }
                }
                c
            };
            assert!(
                cost(OnlineSwitch::at_most(e, 1999)) <= cost(OnlineSwitch::new(e)),
                "{total}"
            );
        }
    }

    #[test]
    fn switch_happens_exactly_at_the_break_even() {
        let mut rule = OnlineSwitch::new(est(3.0, 1.0, 2000.0));
        assert!(!rule.record(999));
        assert_eq!(rule.excess_paid(), 1998.0);
        assert!(rule.record(1));
        assert_eq!(rule.rays_on_grid(), 1000);
    }
}
