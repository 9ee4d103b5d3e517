//! A built scene: the validated mesh, the structure in use, and the report of how it was chosen.

use alloc::vec::Vec;

use crate::accel::grid::{GridParams, UniformGrid};
use crate::accel::kdtree::{KdTree, KdTreeParams};
use crate::accel::{AcceptingQuery, RayQuery};
use crate::budget::{bytes_of, MemoryBudget, MemoryMonitor};
use crate::error::BuildError;
use crate::geometry::{Conditions, Geometry, HitEx, RayEx, Visibility};
use crate::mesh::{MeshSource, TriMesh};
use crate::ray::{Hit, Ray};
use crate::select::calibration::Calibration;
use crate::select::clock::Clock;
use crate::select::decision::{kd_tree_work_limit, CostEstimate, OnlineSwitch, TRIAL_SHARE};
use crate::select::model::Part;
use crate::select::model::SceneFeatures;
use crate::select::sample::{sample_grid, sample_kdtree, time_samples, RaySource, SampleParams};

mod choose;
mod tap;

use choose::{choose, keeps_kd_tree};
pub use tap::TAP_RAYS;
use tap::{QueryTap, TAP_MIN_RAYS};

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
    /// The grid is at least as fast per ray: the kd-tree never pays (estimated; or measured, when a
    /// kd-tree built on the library's samples took the renderer's tapped queries longer than a
    /// grid built again: [`Scene::update`]).
    GridFasterPerRay,
    /// Fewer rays expected than the break-even workload: the grid was kept.
    BelowBreakEven,
    /// At least the break-even workload expected: the kd-tree was built.
    AboveBreakEven,
    /// Budget unknown and the grid is still in use.
    OnlineOnGrid,
    /// The scene switched to the kd-tree in [`Scene::update`] (budget unknown or an upper bound,
    /// or its own tapped queries showed that the kd-tree pays for the rays remaining).
    OnlineSwitched,
}

/// What [`BuildOptions::expected_rays`] means when it is not 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BudgetKind {
    /// The rays the caller will trace (default): the selector decides at the build, on its sample
    /// rays; a scene left on the grid may still switch at [`Scene::update`] once the renderer's
    /// own tapped rays put W* at or below the rays remaining.
    #[default]
    Expected,
    /// An upper bound (a renderer that may stop early, adaptive sampling): below the estimated
    /// break-even the scene stays on the grid unless a later [`Scene::update`] is told a
    /// `rays_remaining` at or above the W* the renderer's own tapped rays give (with
    /// `rays_remaining` 0 it stays); above it the scene starts on the grid and switches as with an
    /// unknown budget, but never once the rays that may still come are fewer than W*.
    AtMost,
}

/// Say this as `rays_remaining` to [`Scene::update`] when no rays remain (the last batch was
/// traced, or the next one is the last and its size is not worth telling): the scene never
/// switches again. `0` means "unknown" instead.
pub const RAYS_REMAINING_NONE: u64 = u64::MAX;

/// How to build a scene. `BuildOptions::DEFAULT` documents every default.
#[derive(Clone, Copy, Debug)]
pub struct BuildOptions {
    /// Which structure; default [`Structure::Auto`].
    pub structure: Structure,
    /// Rays the caller expects to trace; 0 = unknown (default).
    pub expected_rays: u64,
    /// Whether `expected_rays` is the count or an upper bound; default [`BudgetKind::Expected`].
    pub budget_kind: BudgetKind,
    /// Memory limit in bytes for everything the scene holds during and after the build; 0 = none.
    pub memory_limit: usize,
    /// Grid parameters; default [`GridParams::DEFAULT`].
    pub grid: GridParams,
    /// kd-tree parameters; default [`KdTreeParams::DEFAULT`].
    pub kdtree: KdTreeParams,
    /// The sample rays the selector makes when the caller gives none (`Auto` only), at most this
    /// image, less for a small or unknown budget ([`SampleParams::for_budget`]).
    pub samples: SampleParams,
    /// Told the bytes the build would hold before each allocation of a build (including the one in
    /// [`Scene::update`]); a refusal fails it with [`BuildError::Cancelled`]. Default none.
    pub memory_monitor: Option<MemoryMonitor>,
    /// The clock by which the check after a kd-tree build (`Auto` only) times the caller's rays on
    /// both structures ([`crate::select::decision::kd_tree_confirmed_timed`]): the sample rays
    /// given to [`Scene::build_with_samples`], and the tapped queries in [`Scene::update`]. The
    /// library's own samples are always priced from their counted work, by prices fitted to them
    /// ([`crate::select::decision::CheckPrices::LIBRARY`]); for other rays no prices are known to
    /// hold (on diffuse bounces they keep a slower kd-tree on most scenes), so they are timed.
    /// `None` prices every check, deterministically. With a clock a kd-tree kept on the library's
    /// samples is also checked once more on the tapped queries ([`Scene::update`]). Default
    /// [`Clock::DEFAULT`]: this thread's CPU time on Linux (monotonic wall time elsewhere) in `std`
    /// builds, none without.
    pub clock: Option<Clock>,
}

impl BuildOptions {
    /// Auto structure, unknown budget, no memory limit, default grid.
    pub const DEFAULT: BuildOptions = BuildOptions {
        structure: Structure::Auto,
        expected_rays: 0,
        budget_kind: BudgetKind::Expected,
        memory_limit: 0,
        grid: GridParams::DEFAULT,
        kdtree: KdTreeParams::DEFAULT,
        samples: SampleParams::DEFAULT,
        memory_monitor: None,
        clock: Clock::DEFAULT,
    };
}

impl BuildOptions {
    /// A budget with these options' limit and monitor.
    fn budget(&self) -> MemoryBudget {
        MemoryBudget::new(self.memory_limit).with_monitor(self.memory_monitor)
    }
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

    fn accepting(&self) -> &dyn AcceptingQuery {
        match self {
            Accel::Grid(g) => g,
            Accel::KdTree(k) => k,
        }
    }

    /// Gives the structure's bytes back to `budget` and drops it.
    fn release(self, budget: &mut MemoryBudget) {
        match self {
            Accel::Grid(g) => g.release(budget),
            Accel::KdTree(k) => k.release(budget),
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
    /// Geometries in the scene (1 for a scene of one mesh).
    pub geometry_count: usize,
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
    /// The caller said no rays remain ([`RAYS_REMAINING_NONE`]): nothing switches again, and a
    /// later [`Scene::set_vertices`] builds for no more rays.
    rays_ended: bool,
    options: BuildOptions,
    /// The unknown-budget rule while the scene is on the grid with `Auto` (None otherwise).
    online: Option<OnlineSwitch>,
    /// What the library's sample rays did on the grid, for the check of a kd-tree built later in
    /// [`Scene::update`] (None when the caller gave the samples: they are not kept).
    grid_samples: Option<SceneFeatures>,
    /// The calibration's constants the check prices work with.
    calibration: Calibration,
    /// How rays see each geometry (empty for a scene built from one mesh).
    geometries: Vec<Visibility>,
    /// True when no geometry puts a condition on rays: plain queries skip the conditions.
    plain: bool,
    /// About one query in 64, kept while `Auto` holds the grid, so that [`Scene::update`] can
    /// judge the decision on the renderer's own rays (None otherwise).
    tap: Option<QueryTap>,
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
        let mut budget = options.budget();
        let mesh = TriMesh::from_source(src, &mut budget)?;
        Scene::select(mesh, Vec::new(), options, calibration, samples, &mut budget)
    }

    /// A scene of several geometries, numbered in the order given: their triangles, how rays see
    /// each (mask, culled faces, filter: see [`crate::geometry`]), one structure over all of them
    /// chosen as [`Scene::build`] chooses. A refused mesh is [`BuildError::InvalidGeometry`] naming
    /// the geometry. Hits of [`Scene::intersect`] then name triangles by their index across all
    /// geometries (the first geometry's, then the second's, …); [`Scene::intersect_ex`] gives the
    /// geometry and the index within it.
    pub fn build_geometries(
        geometries: Vec<Geometry<'_>>,
        options: &BuildOptions,
        calibration: &Calibration,
        samples: Option<&dyn RaySource>,
    ) -> Result<Scene, BuildError> {
        let mut budget = options.budget();
        let mut sources: Vec<&dyn MeshSource> = budget.vec(geometries.len(), "geometry list")?;
        sources.extend(geometries.iter().map(|g| g.mesh));
        let mesh = TriMesh::from_sources(&sources, &mut budget);
        budget.free(sources);
        let mesh = mesh?;
        let mut seen: Vec<Visibility> = match budget.vec(geometries.len(), "geometries") {
            Ok(v) => v,
            Err(e) => {
                mesh.release(&mut budget);
                return Err(e);
            }
        };
        seen.extend(geometries.into_iter().map(|g| Visibility {
            mask: g.mask,
            flags: g.flags,
            filter: g.filter,
        }));
        Scene::select(mesh, seen, options, calibration, samples, &mut budget)
    }

    /// The scene over `mesh` (already charged to `budget`) with the structure the selection
    /// chooses; the mesh is released if that fails.
    fn select(
        mesh: TriMesh,
        geometries: Vec<Visibility>,
        options: &BuildOptions,
        calibration: &Calibration,
        samples: Option<&dyn RaySource>,
        budget: &mut MemoryBudget,
    ) -> Result<Scene, BuildError> {
        let choice = match choose(&mesh, options, calibration, samples, budget) {
            Ok(c) => c,
            Err(e) => {
                mesh.release(budget);
                return Err(e);
            }
        };
        let plain = geometries.iter().all(Visibility::is_plain);
        let mut scene = Scene {
            mesh,
            accel: choice.accel,
            report: SceneReport {
                structure: Structure::Grid,
                outcome: Outcome::Forced,
                triangle_count: 0,
                memory_bytes: 0,
                grid_resolution: [0; 3],
                grid_ray_seconds: f64::NAN,
                kd_ray_seconds: f64::NAN,
                kd_build_seconds: f64::NAN,
                break_even_rays: f64::NAN,
                expected_rays: options.expected_rays,
                references_per_triangle: 0.0,
                kd_node_count: 0,
                kd_depth: 0,
                geometry_count: 0,
            },
            rays_traced: 0,
            rays_ended: false,
            options: *options,
            online: None,
            grid_samples: None,
            calibration: *calibration,
            geometries,
            plain,
            tap: None,
        };
        scene.take_choice_facts(
            choice.outcome,
            choice.estimate,
            choice.online,
            choice.grid_samples,
        );
        scene.refresh_tap(budget)?;
        scene.refresh_report();
        Ok(scene)
    }

    /// Whether the scene holds a kd-tree that `Auto` kept on the library's own samples, priced, and
    /// has a clock to time the renderer's tapped queries on it and on a grid built again
    /// ([`Scene::update`]).
    fn rechecks_kd_tree(&self) -> bool {
        matches!(self.accel, Accel::KdTree(_))
            && self.report.outcome == Outcome::AboveBreakEven
            && self.grid_samples.is_some()
            && self.options.clock.is_some()
    }

    /// [`Scene::update`] on a kd-tree [`Scene::rechecks_kd_tree`] says to check again: once the
    /// tap holds [`TAP_MIN_RAYS`], and when a grid's build could be repaid by the rays that may
    /// remain (it costs at most [`TRIAL_SHARE`] of their time on the grid, by the estimate; an
    /// unknown remainder always may), the tapped rays are timed on the kd-tree, a grid is built
    /// and they are timed on it too; the grid replaces the kd-tree if they took it less time and it
    /// has no heavy cell ([`SceneFeatures::has_heavy_cell`]). Once only: the tap goes either way.
    fn recheck_kd_tree(&mut self, rays_remaining: u64) -> Result<(), BuildError> {
        let Some(clock) = self.options.clock else {
            return Ok(());
        };
        if self.tap.as_mut().map_or(0, QueryTap::taken) < TAP_MIN_RAYS {
            return Ok(());
        }
        let live = SceneFeatures {
            triangles: self.mesh.len() - self.mesh.degenerate_count(),
            ..SceneFeatures::default()
        };
        let grid_build = Part::GridBuild.predict(&self.calibration, &live) * 1e-9;
        let remaining_on_grid = rays_remaining as f64 * self.report.grid_ray_seconds;
        if rays_remaining != 0 && !(grid_build <= TRIAL_SHARE * remaining_on_grid) {
            self.tap = None;
            return Ok(());
        }
        // Once only: the tap goes whatever happens below. Both structures are held while the grid
        // is built, so the memory limit must hold them (and the tap, until this call ends); a
        // refusal is the call's error, and the kd-tree stays.
        let (Some(mut tap), Accel::KdTree(tree)) = (self.tap.take(), &self.accel) else {
            return Ok(());
        };
        let params = self.options.samples;
        // Each structure timed right after a counted pass of the same rays, as at the check
        // after a build (`keeps_kd_tree`): neither is timed cold.
        sample_kdtree(tree, &self.mesh, Some(&tap.rays()), &params);
        let kd_ns = time_samples(tree, &self.mesh, Some(&tap.rays()), &params, &clock);
        let mut budget = self.options.budget();
        // A refusal is the call's error; the tap is gone either way (`update` refreshes the report).
        let grid = budget
            .charge(
                self.memory_bytes() + tap.memory_bytes(),
                "the scene's mesh, kd-tree and tap",
            )
            .and_then(|()| UniformGrid::build(&self.mesh, &self.options.grid, &mut budget))?;
        let features = sample_grid(&grid, &self.mesh, Some(&tap.rays()), &params);
        let grid_ns = time_samples(&grid, &self.mesh, Some(&tap.rays()), &params, &clock);
        if grid_ns > 0 && grid_ns < kd_ns && !features.has_heavy_cell() {
            let tree = core::mem::replace(&mut self.accel, Accel::Grid(grid));
            tree.release(&mut budget);
            self.report.outcome = Outcome::GridFasterPerRay;
            self.take_estimate(Some(&self.calibration.estimate(&features)));
        } else {
            grid.release(&mut budget);
        }
        Ok(())
    }

    /// Records what a selection found (everything of a [`Choice`] but its structure).
    fn take_choice_facts(
        &mut self,
        outcome: Outcome,
        estimate: Option<CostEstimate>,
        online: Option<OnlineSwitch>,
        grid_samples: Option<SceneFeatures>,
    ) {
        self.report.outcome = outcome;
        self.take_estimate(estimate.as_ref());
        self.online = online;
        self.grid_samples = grid_samples;
    }

    /// The report's estimate fields from `estimate` (NaN where there is none).
    fn take_estimate(&mut self, estimate: Option<&CostEstimate>) {
        let r = &mut self.report;
        [
            r.grid_ray_seconds,
            r.kd_ray_seconds,
            r.kd_build_seconds,
            r.break_even_rays,
        ] = estimate_fields(estimate);
    }

    /// A tap while `Auto` holds the grid over some triangles, or a kd-tree it will check again on
    /// the renderer's rays ([`Scene::rechecks_kd_tree`]) (emptied if there was one), none
    /// otherwise. The tap's buffer is charged to `budget`: one the memory limit has no room for is
    /// simply not taken (it only improves a later decision); a refusal by the monitor or the
    /// allocator is the build's error, as for any other allocation.
    fn refresh_tap(&mut self, budget: &mut MemoryBudget) -> Result<(), BuildError> {
        let wanted = self.options.structure == Structure::Auto
            && (matches!(self.accel, Accel::Grid(_)) || self.rechecks_kd_tree())
            && self.report.outcome != Outcome::Forced
            && self.mesh.len() > self.mesh.degenerate_count();
        match (&mut self.tap, wanted) {
            (Some(tap), true) => tap.clear(),
            (None, true) => {
                self.tap = match QueryTap::new(budget) {
                    Ok(tap) => tap,
                    Err(BuildError::MemoryLimit { .. }) => None,
                    Err(e) => return Err(e),
                }
            }
            (_, false) => self.tap = None,
        }
        Ok(())
    }

    /// New positions for the vertices of geometry `g` (`vertex(i)` for each of its vertices; same
    /// count and topology; a scene of one mesh is geometry 0), then the structure rebuilt as a new
    /// build would choose it: the grid (linear time) when the scene was built for the grid, the
    /// kd-tree when built for it, and with `Auto` the selection run again on the moved mesh with
    /// the library's sample rays and the scene's budget, so a kd-tree is built only when the
    /// selector says it pays. The new structure is built while the old one is held (the memory
    /// limit must hold both, and a copy of the geometry's old triangles). On any failure (a
    /// non-finite coordinate, no such geometry, the memory limit, the monitor) the scene is as it
    /// was and the error is returned. The report then describes what the scene holds.
    pub fn set_vertices(
        &mut self,
        g: usize,
        vertex: &dyn Fn(usize) -> [f32; 3],
    ) -> Result<(), BuildError> {
        if g >= self.mesh.geometry_count() {
            return Err(BuildError::InvalidArgument {
                what: "no such geometry",
            });
        }
        let mut budget = self.options.budget();
        budget.charge(self.memory_bytes(), "the scene as it is")?;
        let range = self.mesh.geometry_start(g) as usize..self.mesh.geometry_start(g + 1) as usize;
        let mut saved = budget.vec(range.len(), "the geometry's old triangles")?;
        saved.extend_from_slice(&self.mesh.triangles()[range]);
        if let Err(e) = self.mesh.set_vertices(g, vertex) {
            self.mesh.restore_triangles(g, &saved);
            return Err(e);
        }
        // The choice again, for the rays still to come: a known budget less the rays traced (at
        // least one: 0 would read as unknown), none after the caller said so.
        let options = BuildOptions {
            expected_rays: match (self.rays_ended, self.options.expected_rays) {
                (true, _) => 1,
                (false, 0) => 0,
                (false, budget) => budget.saturating_sub(self.rays_traced).max(1),
            },
            ..self.options
        };
        match choose(&self.mesh, &options, &self.calibration, None, &mut budget) {
            Ok(choice) => {
                self.accel = choice.accel;
                self.take_choice_facts(
                    choice.outcome,
                    choice.estimate,
                    choice.online,
                    choice.grid_samples,
                );
                if self.rays_ended {
                    // Nothing switches again (`update`'s promise): no rule, no tap.
                    self.online = None;
                    self.tap = None;
                } else if self.refresh_tap(&mut budget).is_err() {
                    // The moved scene stands even without a tap (it only improves a later decision).
                    self.tap = None;
                }
                self.refresh_report();
                Ok(())
            }
            Err(e) => {
                self.mesh.restore_triangles(g, &saved);
                Err(e)
            }
        }
    }

    /// Bytes the scene holds (mesh, structure, geometries' conditions).
    fn memory_bytes(&self) -> usize {
        self.mesh.memory_bytes()
            + self.accel.memory_bytes()
            + bytes_of(&self.geometries)
            + self.tap.as_ref().map_or(0, QueryTap::memory_bytes)
    }

    /// Brings the report's structure fields up to date with the structure held.
    fn refresh_report(&mut self) {
        self.report.memory_bytes = self.memory_bytes();
        let (mesh, accel, r) = (&self.mesh, &self.accel, &mut self.report);
        let live = mesh.len() - mesh.degenerate_count();
        (r.grid_resolution, r.kd_node_count, r.kd_depth) = match accel {
            Accel::Grid(g) => (g.resolution(), 0, 0),
            Accel::KdTree(k) => ([0; 3], k.node_count(), k.depth()),
        };
        r.structure = accel.structure();
        r.triangle_count = mesh.len();
        r.geometry_count = mesh.geometry_count();
        r.references_per_triangle = if live == 0 {
            0.0
        } else {
            accel.reference_count() as f64 / live as f64
        };
    }

    /// Between batches (never during queries): `rays_traced` since the last call and
    /// `rays_remaining` still expected (0 = unknown, [`RAYS_REMAINING_NONE`] = none). A scene built
    /// with `Auto` and an unknown budget (or an upper bound above W*) that is still on the grid
    /// switches to the kd-tree when the remaining budget is at least W* (or the trial workload,
    /// where the build costs at most `select::decision::TRIAL_SHARE` of tracing those rays on the
    /// grid), or, with the budget still unknown, once the excess paid on the grid reaches the
    /// kd-tree's build cost (or the grid has cost that build `TRIAL_SHARE⁻¹` times over) (and, under an
    /// upper bound, the rays that may still come are at least W*). After [`RAYS_REMAINING_NONE`]
    /// it never switches.
    ///
    /// While `Auto` holds the grid the scene also keeps about one query in 64 (chosen by a hash of
    /// the ray; up to 1 024). Once it holds 256, this call estimates the costs again from those
    /// rays instead of the library's samples (the report's estimates change, and W* with them),
    /// and a scene built with a known budget on the grid switches too when `rays_remaining` is at
    /// least the new W* (or the new trial workload, `select::decision::Decision::Trial`): the
    /// renderer's own rays correct a decision made on samples that did not look like them (a camera
    /// inside the scene, short occlusion rays). From the first batch measured so, every switch
    /// waits for a batch's tapped rays to agree: each measured batch starts the tap over, and the
    /// switch comes at the first call whose batch's tapped rays (256 or more) ask for it after a
    /// batch that asked too; a batch that does not ask cancels it. A kd-tree built then is kept
    /// only if that batch's tapped rays took it less time than the grid (with a clock; without,
    /// only if their counted work on it, priced, is the smaller).
    ///
    /// The kd-tree is built while the grid is still held (the memory limit must hold both); if
    /// that fails the scene stays on the grid, unchanged, and the error is returned.
    ///
    /// A kd-tree `Auto` built on its own samples (priced: they may not look like the renderer's
    /// rays) is checked once more when the scene has a clock: the scene taps its queries on the
    /// kd-tree too, and the first call that finds 256 of them (with rays that may remain enough to
    /// repay a grid's build: [`crate::select::decision::TRIAL_SHARE`] of their time on it, or an
    /// unknown remainder) times them on the kd-tree, builds a grid (both held: the memory limit
    /// must hold them; a refusal is the call's error and ends the re-check), times them on it, and
    /// keeps whichever took less (outcome [`Outcome::GridFasterPerRay`] for the grid). Once only.
    pub fn update(&mut self, rays_traced: u64, rays_remaining: u64) -> Result<(), BuildError> {
        let result = self.update_held(rays_traced, rays_remaining);
        // Whatever the call let go (the tap, a structure), the report's bytes and fields say so.
        self.refresh_report();
        result
    }

    /// [`Scene::update`] but for the report's refresh.
    fn update_held(&mut self, rays_traced: u64, rays_remaining: u64) -> Result<(), BuildError> {
        self.rays_traced = self.rays_traced.saturating_add(rays_traced);
        if rays_remaining == RAYS_REMAINING_NONE {
            self.rays_ended = true;
            self.online = None;
            self.tap = None;
            return Ok(());
        }
        if matches!(self.accel, Accel::KdTree(_)) {
            return self.recheck_kd_tree(rays_remaining);
        }
        let tapped = self.estimate_from_tap();
        let switch = match self.online.as_mut() {
            Some(rule) => {
                let due = rule.record(rays_traced);
                if rays_remaining > 0 {
                    self.report_estimate()
                        .decide(rays_remaining)
                        .builds_kd_tree()
                } else {
                    due
                }
            }
            None => {
                tapped.is_some()
                    && rays_remaining > 0
                    && self
                        .report_estimate()
                        .decide(rays_remaining)
                        .builds_kd_tree()
            }
        };
        // A switch the tapped rays ask for waits for the next batch to ask too: one batch may be
        // unlike the rays that follow it (a renderer's primary rays across a nave, then short
        // occlusion rays, for which the kd-tree saves far less: issue 14's interior case switched
        // on its primary rays and paid a build the occlusion rays did not repay). Each measured
        // batch starts the tap over, so that every batch is heard on its own rays.
        if let Some(tap) = self.tap.as_mut() {
            match (tapped.is_some(), switch) {
                (true, true) if !tap.asked => {
                    tap.asked = true;
                    tap.next_batch();
                    return Ok(());
                }
                (true, false) => {
                    tap.asked = false;
                    tap.next_batch();
                }
                // Too few of the next batch's rays tapped yet to agree or not: the estimate is a
                // batch's already heard, and no switch comes from it alone.
                (false, _) if tap.asked || tap.heard => return Ok(()),
                _ => {}
            }
        }
        if !switch {
            return Ok(());
        }
        let clock = self.options.clock;
        // With a clock, the grid's time on the tapped rays the check will use, taken before the
        // kd-tree's build takes the caches (right after they were traced through it). The
        // library's own samples are priced (see `BuildOptions::clock`).
        let grid_ns = match (clock.as_ref(), &self.accel, &tapped, &mut self.tap) {
            (Some(c), Accel::Grid(g), Some(_), Some(tap)) => Some(time_samples(
                g,
                &self.mesh,
                Some(&tap.rays()),
                &self.options.samples,
                c,
            )),
            _ => None,
        };
        let mut budget = self.options.budget();
        budget.charge(self.memory_bytes(), "the scene's mesh and grid")?;
        let limit = kd_tree_work_limit(self.mesh.len() - self.mesh.degenerate_count());
        let Some(tree) =
            KdTree::build_within(&self.mesh, &self.options.kdtree, &mut budget, limit)?
        else {
            // Abandoned (see `kd_tree_work_limit`): keep the grid and stop considering the switch.
            self.online = None;
            self.tap = None;
            return Ok(());
        };
        // The check on the rays the estimate came from: the tapped ones (timed, with a clock), or
        // the library's (the same as the grid's at the build: the budget's image side).
        let checked = match (&tapped, &mut self.tap, &self.grid_samples) {
            (Some(grid), Some(tap), _) => keeps_kd_tree(
                &tree,
                &self.mesh,
                &self.calibration,
                grid,
                clock.as_ref().zip(grid_ns),
                Some(&tap.rays()),
                &self.options.samples,
            ),
            (_, _, Some(grid)) => keeps_kd_tree(
                &tree,
                &self.mesh,
                &self.calibration,
                grid,
                None,
                None,
                &self.options.samples.for_budget(self.options.expected_rays),
            ),
            _ => true,
        };
        if !checked {
            // Not worth it after all: keep the grid and stop considering the switch.
            self.online = None;
            self.tap = None;
            return Ok(());
        }
        self.accel = Accel::KdTree(tree);
        self.online = None;
        self.tap = None;
        self.report.outcome = Outcome::OnlineSwitched;
        Ok(())
    }

    /// With enough tapped queries on the grid, the estimate from them: the report's estimates and
    /// the online rule's take it, and the rays' features on the grid are returned (for the check
    /// of a kd-tree built on it). The tapped rays stay for that check; they are traced again only
    /// when more have come since.
    fn estimate_from_tap(&mut self) -> Option<SceneFeatures> {
        let (Some(tap), Accel::Grid(grid)) = (&mut self.tap, &self.accel) else {
            return None;
        };
        let taken = tap.taken();
        if taken < TAP_MIN_RAYS {
            return None;
        }
        if let Some((n, features)) = tap.measured {
            if n == taken {
                return Some(features);
            }
        }
        let features = sample_grid(grid, &self.mesh, Some(&tap.rays()), &self.options.samples);
        tap.measured = Some((taken, features));
        tap.heard = true;
        let estimate = self.calibration.estimate(&features);
        self.take_estimate(Some(&estimate));
        if let Some(rule) = self.online.as_mut() {
            rule.set_estimate(estimate);
        }
        Some(features)
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

    /// The closest hit in `[tmin, tmax]` (ties to the lowest primitive id), or [`Hit::MISS`]: in a
    /// scene of several geometries, the closest one their conditions accept for a ray that sees
    /// every mask and culls nothing itself, `prim` counting across geometries.
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Hit {
        self.offer(ray);
        if self.plain {
            self.accel.query().intersect(&self.mesh, ray)
        } else {
            self.intersect_accepted(&RayEx::new(*ray))
        }
    }

    /// True when anything is hit in `[tmin, tmax]` (anything the geometries' conditions accept).
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.offer(ray);
        if self.plain {
            self.accel.query().occluded(&self.mesh, ray)
        } else {
            self.occluded_accepted(&RayEx::new(*ray))
        }
    }

    /// The closest hit in `[tmin, tmax]` that passes the ray's mask and culling and the geometry's
    /// mask, culling and filter, ties to the lowest `(geom, prim)`, with its geometry, its index in
    /// the geometry and its normal; [`HitEx::MISS`] when there is none. Bit-identical on every
    /// structure. Conditions cost time only per candidate hit, not per triangle tested.
    #[inline]
    pub fn intersect_ex(&self, ray: &RayEx) -> HitEx {
        self.offer(&ray.ray);
        let hit = if self.sees_plainly(ray) {
            self.accel.query().intersect(&self.mesh, &ray.ray)
        } else {
            self.intersect_accepted(ray)
        };
        HitEx::of(&self.mesh, &hit)
    }

    /// True when [`Scene::intersect_ex`] would hit (it stops at the first accepted hit, so a filter
    /// is called for fewer candidates).
    #[inline]
    pub fn occluded_ex(&self, ray: &RayEx) -> bool {
        self.offer(&ray.ray);
        if self.sees_plainly(ray) {
            self.accel.query().occluded(&self.mesh, &ray.ray)
        } else {
            self.occluded_accepted(ray)
        }
    }

    /// Hands `ray` to the tap, if there is one (see [`QueryTap::offer`]).
    #[inline(always)]
    fn offer(&self, ray: &Ray) {
        if let Some(tap) = &self.tap {
            tap.offer(ray);
        }
    }

    /// True when no condition can refuse a hit of `ray`.
    #[inline(always)]
    fn sees_plainly(&self, ray: &RayEx) -> bool {
        // A plain scene's geometries have every mask bit, so any nonzero mask sees them all.
        self.plain && ray.flags == 0 && ray.mask != 0
    }

    fn intersect_accepted(&self, ray: &RayEx) -> Hit {
        self.accel.accepting().intersect_accepting(
            &self.mesh,
            &ray.ray,
            Some(&self.conditions(ray)),
        )
    }

    fn occluded_accepted(&self, ray: &RayEx) -> bool {
        self.accel
            .accepting()
            .occluded_accepting(&self.mesh, &ray.ray, Some(&self.conditions(ray)))
    }

    /// What `ray` and the geometries ask of a hit.
    fn conditions<'a>(&'a self, ray: &'a RayEx) -> Conditions<'a> {
        Conditions {
            mesh: &self.mesh,
            geometries: &self.geometries,
            ray,
        }
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
