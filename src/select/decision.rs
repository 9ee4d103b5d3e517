//! The decision of Hapala, Karlík, Havran (2011) for a known ray budget, and the online rule for an
//! unknown one. Pure arithmetic on cost estimates; where the estimates come from is the cost model's
//! business.

use super::calibration::Calibration;
use super::model::SceneFeatures;

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

/// What to do with a known budget (mirrors the three outcomes of the paper).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decision {
    /// The kd-tree is not faster per ray (or the estimates cannot tell): keep the grid.
    GridFasterPerRay,
    /// Fewer rays than the break-even workload: keep the grid.
    BelowBreakEven,
    /// At least the break-even workload: build the kd-tree.
    AboveBreakEven,
}

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
        // An infinite saving (the grid is hopeless) makes W* = 0; an infinite build makes it ∞.
        self.kd_build_seconds / saving
    }

    /// The decision for `expected_rays` (> 0): build the kd-tree exactly when `expected_rays ≥ W*`.
    /// Estimates that cannot tell keep the grid (`GridFasterPerRay`): the grid is already paid for.
    pub fn decide(&self, expected_rays: u64) -> Decision {
        let w = self.break_even_rays();
        if !(w < f64::INFINITY) {
            // +∞ or NaN.
            return Decision::GridFasterPerRay;
        }
        if expected_rays as f64 >= w {
            Decision::AboveBreakEven
        } else {
            Decision::BelowBreakEven
        }
    }
}

/// What a kd-tree node visit costs relative to a grid cell step in [`kd_tree_confirmed`]: a cell step
/// also reads the cell's reference range and touches its triangles, a node visit is a few compares
/// on 8 bytes.
pub const KD_NODE_PER_CELL_STEP: f64 = 0.35;

/// What a triangle the kd-tree tests costs relative to one the grid tests in [`kd_tree_confirmed`]:
/// more, because kd leaves hold a few triangles each, so every counted test carries a share of a
/// leaf's overhead (stack, list setup, a block of four lanes for one to four triangles), while a
/// grid cell's longer list spreads its overhead, and the grid's count includes the triangles its
/// mailbox skips for almost nothing. Fitted with the node price on 31 scenes (the evaluation's set;
/// the library's sample rays' counted work on both structures against the measured per-ray times of
/// the evaluation's workload, thread CPU, one quiet run; docs/design.md, "Selector"). Refitted at
/// stop 19 for the kd-trees whose costs were chosen by time (bigger leaves, fewer nodes): with 0.35
/// and 1.4 the check keeps the faster structure on 29 of 31 scenes (leave-one-out 28), wrong only on
/// rocker_arm (the two equally fast) and stadium-1M (the kd-tree 1.7× faster there: its grid's time
/// per ray is set by cache misses the counts do not see); the earlier 0.5 and 2 dropped seven
/// kd-trees 6–40 % faster than the grid with these trees. With the tests priced alike it keeps the
/// slower structure on slivers.
pub const KD_TEST_PER_GRID_TEST: f64 = 1.4;

/// The check after a kd-tree was built on an estimate: keep it only if its counted work on the
/// sample rays costs less than the grid's did on the same rays (`grid` and `kd` from
/// [`crate::select::sample::sample_grid`] and [`crate::select::sample::sample_kdtree`]), both priced
/// with the calibration's grid constants: a node visit costs [`KD_NODE_PER_CELL_STEP`] of a cell
/// step and a kd-tree's triangle test [`KD_TEST_PER_GRID_TEST`] of the grid's. Where the kd-tree
/// does not save work (long slivers it cannot separate, soups of overlapping triangles, scenes that
/// are nearly empty space for the grid), it is slower per ray whatever the estimate said, and the
/// grid stays. No kd samples confirm nothing to the contrary.
pub fn kd_tree_confirmed(
    calibration: &Calibration,
    grid: &SceneFeatures,
    kd: &SceneFeatures,
) -> bool {
    let (cell, test) = (calibration.value(2), calibration.value(3));
    let grid_cost = cell * grid.cells_per_ray() + test * grid.tests_per_ray();
    let kd_cost = KD_NODE_PER_CELL_STEP * cell * kd.cells_per_ray()
        + KD_TEST_PER_GRID_TEST * test * kd.tests_per_ray();
    kd.rays == 0 || kd_cost < grid_cost
}

/// How much work [`kd_tree_work_limit`] lets a kd-tree build do, per `N·log2 N`, before the
/// selector abandons it. Measured on the evaluation's 31 scenes (`KdTree::build_work`): 1.3–3.9 on
/// every scene whose kd-tree is worth having (spd_teapot and gears the highest), 6.8 on hair and
/// 15 on slivers, whose kd-trees duplicate triangles at every level and trace 2× slower than the
/// grid. 5 stops those builds at 35–75 % of their work with room above the rest. Re-measured at
/// stop 19 with the costs chosen by time: 1.2–2.7 on the worthwhile trees, 3.6 on hair (whose build
/// now completes and is dropped by the check after it), 10–15 on slivers.
pub const KD_WORK_PER_N_LOG_N: f64 = 5.0;

/// The floor of [`kd_tree_work_limit`] per triangle, so that tiny scenes (where `log2 N` is near 0)
/// are never abandoned: more than any measured scene's work per triangle but slivers' and hair's.
pub const KD_WORK_FLOOR_PER_TRIANGLE: f64 = 64.0;

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
/// excess.
///
/// With an upper bound on the budget ([`OnlineSwitch::at_most`]) the rule also never switches when
/// the rays that may still come are fewer than W*: then the kd-tree cannot pay back its build
/// whatever the renderer does, and the bound only removes switches that lose.
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

    /// True when the rays that may still come could pay back the kd-tree's build (always without a
    /// bound; never for estimates that cannot tell).
    pub fn may_pay_back(&self) -> bool {
        let w = self.estimate.break_even_rays();
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

    /// True when the excess paid has reached the build cost and the rays that may still come could
    /// pay it back (never for a kd-tree that is not faster per ray, or for estimates that cannot
    /// tell).
    pub fn should_switch(&self) -> bool {
        self.may_pay_back() && self.rays_on_grid as f64 >= self.estimate.break_even_rays()
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

    #[test]
    fn each_outcome_and_the_boundary() {
        let e = est(3.0, 1.0, 2000.0); // W* = 1000, exactly in binary
        assert_eq!(e.break_even_rays(), 1000.0);
        assert_eq!(e.decide(999), Decision::BelowBreakEven);
        assert_eq!(e.decide(1000), Decision::AboveBreakEven);
        assert_eq!(e.decide(u64::MAX), Decision::AboveBreakEven);
        assert_eq!(
            est(1e-6, 1e-6, 1e-3).decide(u64::MAX),
            Decision::GridFasterPerRay
        );
        assert_eq!(
            est(1e-6, 2e-6, 0.0).decide(u64::MAX),
            Decision::GridFasterPerRay
        );
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
        // Both infinite per ray: no saving to speak of.
        assert_eq!(
            est(f64::INFINITY, f64::INFINITY, 1.0).decide(u64::MAX),
            Decision::GridFasterPerRay
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

    /// Total seconds for `total` rays under the online rule, in batches of `batch`.
    fn online_total(e: &CostEstimate, total: u64, batch: u64) -> f64 {
        let mut rule = OnlineSwitch::new(*e);
        let mut cost = 0.0;
        let mut done = 0;
        while done < total {
            let n = batch.min(total - done);
            cost += n as f64 * e.grid_ray_seconds;
            done += n;
            if rule.record(n) {
                // Switched: the rest runs on the kd-tree.
                return cost + e.kd_build_seconds + (total - done) as f64 * e.kd_ray_seconds;
            }
            if !e.break_even_rays().is_finite() {
                // It never switches: the rest stays on the grid.
                return cost + (total - done) as f64 * e.grid_ray_seconds;
            }
        }
        cost
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
            };
            let w = e.break_even_rays();
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
