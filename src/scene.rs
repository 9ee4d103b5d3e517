//! A built scene: the validated mesh, the structure in use, and the report of how it was chosen.

use crate::accel::grid::{GridParams, UniformGrid};
use crate::accel::kdtree::{KdTree, KdTreeParams};
use crate::accel::RayQuery;
use crate::budget::{MemoryBudget, MemoryMonitor};
use crate::error::BuildError;
use crate::mesh::{MeshSource, TriMesh};
use crate::ray::{Hit, Ray};
use crate::select::calibration::Calibration;
use crate::select::decision::{kd_tree_confirmed, CostEstimate, Decision, OnlineSwitch};
use crate::select::model::SceneFeatures;
use crate::select::sample::{sample_grid, sample_kdtree, RaySource, SampleParams};

/// Which structure a scene should use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Structure {
    /// Let the selector decide from the expected ray count.
    Auto,
    /// The uniform grid.
    Grid,
    /// The SAH kd-tree.
    KdTree,
}

/// Why the scene uses the structure it uses (the C enum `rq_outcome` mirrors these numbers).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The caller chose the structure.
    Forced,
    /// The grid is at least as fast per ray: the kd-tree never pays.
    GridFasterPerRay,
    /// Fewer rays expected than the break-even workload: the grid was kept.
    BelowBreakEven,
    /// At least the break-even workload expected: the kd-tree was built.
    AboveBreakEven,
    /// Budget unknown and the grid is still in use.
    OnlineOnGrid,
    /// Budget unknown and the scene has switched to the kd-tree.
    OnlineSwitched,
}

/// How to build a scene. `BuildOptions::DEFAULT` documents every default.
#[derive(Clone, Copy, Debug)]
pub struct BuildOptions {
    /// Which structure; default [`Structure::Auto`].
    pub structure: Structure,
    /// Rays the caller expects to trace; 0 = unknown (default).
    pub expected_rays: u64,
    /// Memory limit in bytes for everything the scene holds during and after the build; 0 = none.
    pub memory_limit: usize,
    /// Grid parameters; default [`GridParams::DEFAULT`].
    pub grid: GridParams,
    /// kd-tree parameters; default [`KdTreeParams::DEFAULT`].
    pub kdtree: KdTreeParams,
    /// The sample rays the selector makes when the caller gives none (`Auto` only).
    pub samples: SampleParams,
    /// Told the bytes the build would hold before each allocation of a build (including the one in
    /// [`Scene::update`]); a refusal fails it with [`BuildError::Cancelled`]. Default none.
    pub memory_monitor: Option<MemoryMonitor>,
}

impl BuildOptions {
    /// Auto structure, unknown budget, no memory limit, default grid.
    pub const DEFAULT: BuildOptions = BuildOptions {
        structure: Structure::Auto,
        expected_rays: 0,
        memory_limit: 0,
        grid: GridParams::DEFAULT,
        kdtree: KdTreeParams::DEFAULT,
        samples: SampleParams::DEFAULT,
        memory_monitor: None,
    };
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions::DEFAULT
    }
}

/// The structure a scene answers with.
#[derive(Debug)]
pub enum Accel {
    /// A uniform grid.
    Grid(UniformGrid),
    /// A SAH kd-tree.
    KdTree(KdTree),
}

impl Accel {
    fn query(&self) -> &dyn RayQuery {
        match self {
            Accel::Grid(g) => g,
            Accel::KdTree(k) => k,
        }
    }

    /// Which structure this is.
    pub fn structure(&self) -> Structure {
        match self {
            Accel::Grid(_) => Structure::Grid,
            Accel::KdTree(_) => Structure::KdTree,
        }
    }

    /// Bytes the structure holds.
    pub fn memory_bytes(&self) -> usize {
        match self {
            Accel::Grid(g) => g.memory_bytes(),
            Accel::KdTree(k) => k.memory_bytes(),
        }
    }

    /// Triangle references the structure holds.
    pub fn reference_count(&self) -> usize {
        match self {
            Accel::Grid(g) => g.reference_count(),
            Accel::KdTree(k) => k.reference_count(),
        }
    }

    /// Builds `structure` (`Grid` or `KdTree`) over `mesh`.
    fn build(
        structure: Structure,
        mesh: &TriMesh,
        options: &BuildOptions,
        budget: &mut MemoryBudget,
    ) -> Result<Accel, BuildError> {
        Ok(match structure {
            Structure::KdTree => Accel::KdTree(KdTree::build(mesh, &options.kdtree, budget)?),
            _ => Accel::Grid(UniformGrid::build(mesh, &options.grid, budget)?),
        })
    }
}

/// What a scene reports about itself.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneReport {
    /// The structure in use (never `Auto`).
    pub structure: Structure,
    /// Why.
    pub outcome: Outcome,
    /// Triangles in the mesh (degenerate ones included).
    pub triangle_count: usize,
    /// Bytes the scene holds (mesh copy plus structure).
    pub memory_bytes: usize,
    /// Grid cells per axis (zero when no grid is held).
    pub grid_resolution: [u32; 3],
    /// Estimated seconds per ray on the grid (NaN until the selector estimates it).
    pub grid_ray_seconds: f64,
    /// Estimated seconds per ray on the kd-tree (NaN until the selector estimates it).
    pub kd_ray_seconds: f64,
    /// Estimated kd-tree build time in seconds (NaN until the selector estimates it).
    pub kd_build_seconds: f64,
    /// Estimated break-even workload W* (+∞ when the kd-tree is not faster per ray; NaN when unknown).
    pub break_even_rays: f64,
    /// The ray budget the scene was built for (0 = unknown).
    pub expected_rays: u64,
    /// References per non-degenerate triangle held by the structure.
    pub references_per_triangle: f64,
    /// kd-tree nodes, interior and leaves (zero when no kd-tree is held).
    pub kd_node_count: usize,
    /// Depth of the kd-tree's deepest leaf (zero when no kd-tree is held).
    pub kd_depth: u32,
}

/// An immutable scene: safe to query from many threads at once.
///
/// Guarantees: queries never allocate and never panic; every structure it may hold returns the same
/// bit-identical hits, so a switch of structure never changes an answer.
#[derive(Debug)]
pub struct Scene {
    mesh: TriMesh,
    accel: Accel,
    report: SceneReport,
    rays_traced: u64,
    options: BuildOptions,
    /// The unknown-budget rule while the scene is on the grid with `Auto` (None otherwise).
    online: Option<OnlineSwitch>,
    /// What the library's sample rays did on the grid, for the check of a kd-tree built later in
    /// [`Scene::update`] (None when the caller gave the samples: they are not kept).
    grid_samples: Option<SceneFeatures>,
    /// The calibration's constants the check prices work with.
    calibration: Calibration,
}

/// The report's estimate fields: NaN where nothing was estimated.
fn estimate_fields(e: Option<&CostEstimate>) -> [f64; 4] {
    match e {
        Some(e) => [
            e.grid_ray_seconds,
            e.kd_ray_seconds,
            e.kd_build_seconds,
            e.break_even_rays(),
        ],
        None => [f64::NAN; 4],
    }
}

impl Scene {
    /// Validates the mesh and builds the requested structure. `Auto` builds the grid, traces the
    /// selector's sample rays through it, estimates the costs with `calibration`, and then: with a
    /// known `expected_rays`, keeps the grid or replaces it by the kd-tree (the grid is released
    /// first, so the memory limit must hold the mesh and the kd-tree); with an unknown budget, stays
    /// on the grid and lets [`Scene::update`] switch.
    pub fn build(
        src: &impl MeshSource,
        options: &BuildOptions,
        calibration: &Calibration,
    ) -> Result<Scene, BuildError> {
        Scene::build_with_samples(src, options, calibration, None)
    }

    /// [`Scene::build`] with the caller's representative rays as the selector's samples (`None`:
    /// the library makes them, see [`SampleParams`]).
    pub fn build_with_samples(
        src: &impl MeshSource,
        options: &BuildOptions,
        calibration: &Calibration,
        samples: Option<&dyn RaySource>,
    ) -> Result<Scene, BuildError> {
        let mut budget =
            MemoryBudget::new(options.memory_limit).with_monitor(options.memory_monitor);
        let mesh = TriMesh::from_source(src, &mut budget)?;
        let first = match options.structure {
            Structure::KdTree => Structure::KdTree,
            _ => Structure::Grid,
        };
        let mut accel = match Accel::build(first, &mesh, options, &mut budget) {
            Ok(a) => a,
            Err(e) => {
                mesh.release(&mut budget);
                return Err(e);
            }
        };
        let mut outcome = Outcome::Forced;
        let mut estimate = None;
        let mut online = None;
        let mut grid_samples = None;
        let sample_params = options.samples.for_budget(options.expected_rays);
        if let (Structure::Auto, Accel::Grid(grid)) = (options.structure, &accel) {
            let features = sample_grid(grid, &mesh, samples, &sample_params);
            let e = calibration.estimate(&features);
            estimate = Some(e);
            if options.expected_rays == 0 {
                outcome = Outcome::OnlineOnGrid;
                online = Some(OnlineSwitch::new(e));
            } else {
                outcome = match e.decide(options.expected_rays) {
                    Decision::GridFasterPerRay => Outcome::GridFasterPerRay,
                    Decision::BelowBreakEven => Outcome::BelowBreakEven,
                    Decision::AboveBreakEven => Outcome::AboveBreakEven,
                };
            }
            if outcome == Outcome::AboveBreakEven {
                // The grid goes first, so the limit need hold only the mesh and the kd-tree.
                if let Accel::Grid(g) = accel {
                    g.release(&mut budget);
                }
                accel = match Accel::build(Structure::KdTree, &mesh, options, &mut budget) {
                    Ok(a) => a,
                    Err(e) => {
                        mesh.release(&mut budget);
                        return Err(e);
                    }
                };
                // The check (see `kd_tree_confirmed`): a kd-tree that does not save work on the
                // same sample rays goes, and the grid (linear, quick) is built again.
                if let Accel::KdTree(tree) = &accel {
                    let kd = sample_kdtree(tree, &mesh, samples, &sample_params);
                    if !kd_tree_confirmed(calibration, &features, &kd) {
                        if let Accel::KdTree(t) = accel {
                            t.release(&mut budget);
                        }
                        outcome = Outcome::GridFasterPerRay;
                        accel = match Accel::build(Structure::Grid, &mesh, options, &mut budget) {
                            Ok(a) => a,
                            Err(e) => {
                                mesh.release(&mut budget);
                                return Err(e);
                            }
                        };
                    }
                }
            }
            if samples.is_none() {
                grid_samples = Some(features);
            }
        }
        let [grid_ray_seconds, kd_ray_seconds, kd_build_seconds, break_even_rays] =
            estimate_fields(estimate.as_ref());
        let mut scene = Scene {
            mesh,
            accel,
            report: SceneReport {
                structure: Structure::Grid,
                outcome,
                triangle_count: 0,
                memory_bytes: 0,
                grid_resolution: [0; 3],
                grid_ray_seconds,
                kd_ray_seconds,
                kd_build_seconds,
                break_even_rays,
                expected_rays: options.expected_rays,
                references_per_triangle: 0.0,
                kd_node_count: 0,
                kd_depth: 0,
            },
            rays_traced: 0,
            options: *options,
            online,
            grid_samples,
            calibration: *calibration,
        };
        scene.refresh_report();
        Ok(scene)
    }

    /// Brings the report's structure fields up to date with the structure held.
    fn refresh_report(&mut self) {
        let (mesh, accel, r) = (&self.mesh, &self.accel, &mut self.report);
        let live = mesh.len() - mesh.degenerate_count();
        (r.grid_resolution, r.kd_node_count, r.kd_depth) = match accel {
            Accel::Grid(g) => (g.resolution(), 0, 0),
            Accel::KdTree(k) => ([0; 3], k.node_count(), k.depth()),
        };
        r.structure = accel.structure();
        r.triangle_count = mesh.len();
        r.memory_bytes = mesh.memory_bytes() + accel.memory_bytes();
        r.references_per_triangle = if live == 0 {
            0.0
        } else {
            accel.reference_count() as f64 / live as f64
        };
    }

    /// Between batches (never during queries): `rays_traced` since the last call and
    /// `rays_remaining` still expected (0 = unknown). A scene built with `Auto` and an unknown budget
    /// that is still on the grid switches to the kd-tree when the remaining budget is at least W*,
    /// or, with the budget still unknown, once the excess paid on the grid reaches the kd-tree's
    /// build cost. The kd-tree is built while the grid is still held (the memory limit must hold
    /// both); if that fails the scene stays on the grid, unchanged, and the error is returned.
    pub fn update(&mut self, rays_traced: u64, rays_remaining: u64) -> Result<(), BuildError> {
        self.rays_traced = self.rays_traced.saturating_add(rays_traced);
        let Some(rule) = self.online.as_mut() else {
            return Ok(());
        };
        let due = rule.record(rays_traced);
        let switch = if rays_remaining > 0 {
            let estimate = self.report_estimate();
            estimate.decide(rays_remaining) == Decision::AboveBreakEven
        } else {
            due
        };
        if !switch {
            return Ok(());
        }
        let mut budget =
            MemoryBudget::new(self.options.memory_limit).with_monitor(self.options.memory_monitor);
        budget.charge(
            self.mesh.memory_bytes() + self.accel.memory_bytes(),
            "the scene's mesh and grid",
        )?;
        let tree = KdTree::build(&self.mesh, &self.options.kdtree, &mut budget)?;
        if let Some(grid) = &self.grid_samples {
            let kd = sample_kdtree(&tree, &self.mesh, None, &self.options.samples);
            if !kd_tree_confirmed(&self.calibration, grid, &kd) {
                // Not worth it after all: keep the grid and stop considering the switch.
                self.online = None;
                return Ok(());
            }
        }
        self.accel = Accel::KdTree(tree);
        self.online = None;
        self.report.outcome = Outcome::OnlineSwitched;
        self.refresh_report();
        Ok(())
    }

    fn report_estimate(&self) -> CostEstimate {
        CostEstimate {
            grid_ray_seconds: self.report.grid_ray_seconds,
            kd_ray_seconds: self.report.kd_ray_seconds,
            kd_build_seconds: self.report.kd_build_seconds,
        }
    }

    /// Rays reported through [`Scene::update`] so far.
    pub fn rays_traced(&self) -> u64 {
        self.rays_traced
    }

    /// The closest hit in `[tmin, tmax]` (ties to the lowest primitive id), or [`Hit::MISS`].
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Hit {
        self.accel.query().intersect(&self.mesh, ray)
    }

    /// True when anything is hit in `[tmin, tmax]`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.accel.query().occluded(&self.mesh, ray)
    }

    /// The validated mesh.
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }

    /// The structure in use.
    pub fn accel(&self) -> &Accel {
        &self.accel
    }

    /// What the scene reports about itself.
    pub fn report(&self) -> SceneReport {
        self.report
    }
}
