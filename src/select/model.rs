//! The cost model: what a scene's features and the calibration predict.
//!
//! Each part predicts one cost (nanoseconds) as the dot product of its terms with a run of the
//! calibration's constants. The fit ([`crate::select::fit`]) uses the same terms, so the model is
//! defined once, here.

use core::ops::Range;

use super::calibration::Calibration;
use super::decision::CostEstimate;
use crate::math;

/// The fewest triangles in one grid cell that [`SceneFeatures::has_heavy_cell`] counts as heavy
/// (with a sixteenth of the scene): a ray through such a cell costs as much as a few dozen ordinary
/// rays. Over the evaluation's 31 scenes the largest cell holds at most 364 triangles on 25, 1 264–1 370
/// on engine_2cyl and sibenik (1–2 % of their triangles), and 2 318–227 012 on munich and the three
/// stadiums (11–57 %).
pub const HEAVY_CELL_MIN: u64 = 1024;

/// What the selector knows of a scene: its size, its grid's reference count, and what a set of rays
/// did on the grid.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SceneFeatures {
    /// Non-degenerate triangles.
    pub triangles: usize,
    /// Rays traced.
    pub rays: u64,
    /// Rays that hit something.
    pub hits: u64,
    /// Grid cells visited, summed over the rays.
    pub cells: u64,
    /// Triangle tests on the grid, summed over the rays.
    pub tests: u64,
    /// References in the grid's cell lists (0: not known): long or overlapping triangles, which
    /// the kd-tree must clip at every level, show here as many references per triangle.
    pub grid_references: u64,
    /// The most triangles one grid cell lists (0: not known). A cell holding a large share of the
    /// scene (a detailed object in a big empty box: the teapot in a stadium) makes every ray that
    /// enters it test them all, and sample rays from afar rarely do (see
    /// [`SceneFeatures::has_heavy_cell`]).
    pub grid_largest_cell: u64,
}

impl SceneFeatures {
    fn per_ray(&self, x: u64) -> f64 {
        if self.rays == 0 {
            0.0
        } else {
            x as f64 / self.rays as f64
        }
    }

    /// Fraction of the rays that hit (0 without rays).
    pub fn hit_fraction(&self) -> f64 {
        self.per_ray(self.hits)
    }

    /// Whether one grid cell lists at least [`HEAVY_CELL_MIN`] triangles and a sixteenth of the
    /// scene's.
    pub fn has_heavy_cell(&self) -> bool {
        self.grid_largest_cell >= HEAVY_CELL_MIN.max(self.triangles as u64 / 16)
    }

    /// Grid cells visited per ray.
    pub fn cells_per_ray(&self) -> f64 {
        self.per_ray(self.cells)
    }

    /// Grid triangle tests per ray.
    pub fn tests_per_ray(&self) -> f64 {
        self.per_ray(self.tests)
    }

    /// The grid's references per triangle (0 when not known or without triangles).
    pub fn grid_references_per_triangle(&self) -> f64 {
        if self.triangles == 0 {
            0.0
        } else {
            self.grid_references as f64 / self.triangles as f64
        }
    }

    /// `log2 N` (0 for N ≤ 1).
    pub fn log2_triangles(&self) -> f64 {
        math::log2_64(self.triangles.max(1) as f64)
    }

    /// Adds the work of one ray.
    pub fn add_ray(&mut self, hit: bool, cells: u32, tests: u32) {
        self.rays += 1;
        self.hits += u64::from(hit);
        self.cells += u64::from(cells);
        self.tests += u64::from(tests);
    }
}

/// The most terms a part has.
pub const MAX_TERMS: usize = 3;

/// One predicted cost.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// Grid build: `c·N`.
    GridBuild,
    /// Grid time per ray: `c₀ + c₁·cells + c₂·tests` (per ray, counted on the grid).
    GridRay,
    /// kd-tree build: `N·log2 N·(c₀ + c₁·g)`, `g` the grid's references per triangle.
    KdBuild,
    /// kd-tree time per ray: `c₀ + c₁·cells + c₂·tests`, priced on what the same rays did on the
    /// grid: both structures' work grows with the geometry a ray passes near, so the estimate
    /// follows the workload (a camera inside the scene, long or short rays) as the grid's does.
    KdRay,
}

impl Part {
    /// Every part, in calibration order.
    pub const ALL: [Part; 4] = [Part::GridBuild, Part::GridRay, Part::KdBuild, Part::KdRay];

    /// Which constants of the calibration are this part's coefficients, in term order.
    pub fn constants(self) -> Range<usize> {
        match self {
            Part::GridBuild => 0..1,
            Part::GridRay => 1..4,
            Part::KdBuild => 4..6,
            Part::KdRay => 6..9,
        }
    }

    /// The part's terms for a scene (unused slots are 0).
    pub fn terms(self, f: &SceneFeatures) -> [f64; MAX_TERMS] {
        let n = f.triangles as f64;
        match self {
            Part::GridBuild => [n, 0.0, 0.0],
            Part::KdBuild => {
                let nlogn = n * f.log2_triangles();
                [nlogn, nlogn * f.grid_references_per_triangle(), 0.0]
            }
            Part::GridRay | Part::KdRay => [1.0, f.cells_per_ray(), f.tests_per_ray()],
        }
    }

    /// The predicted cost in nanoseconds.
    pub fn predict(self, calibration: &Calibration, f: &SceneFeatures) -> f64 {
        let terms = self.terms(f);
        self.constants()
            .zip(terms)
            .map(|(i, t)| calibration.value(i) * t)
            .sum()
    }
}

impl Calibration {
    /// The selector's estimates for a scene (seconds).
    pub fn estimate(&self, f: &SceneFeatures) -> CostEstimate {
        CostEstimate {
            grid_ray_seconds: Part::GridRay.predict(self, f) * 1e-9,
            kd_ray_seconds: Part::KdRay.predict(self, f) * 1e-9,
            kd_build_seconds: Part::KdBuild.predict(self, f) * 1e-9,
        }
    }
}
