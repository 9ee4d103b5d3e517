//! A built scene: the validated mesh, the structure in use, and the report of how it was chosen.

use crate::accel::grid::{GridParams, UniformGrid};
use crate::accel::kdtree::{KdTree, KdTreeParams};
use crate::accel::RayQuery;
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::{MeshSource, TriMesh};
use crate::ray::{Hit, Ray};
use crate::select::calibration::Calibration;

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
}

impl BuildOptions {
    /// Auto structure, unknown budget, no memory limit, default grid.
    pub const DEFAULT: BuildOptions = BuildOptions {
        structure: Structure::Auto,
        expected_rays: 0,
        memory_limit: 0,
        grid: GridParams::DEFAULT,
        kdtree: KdTreeParams::DEFAULT,
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
/// bit-identical hits.
#[derive(Debug)]
pub struct Scene {
    mesh: TriMesh,
    accel: Accel,
    report: SceneReport,
    rays_traced: u64,
}

impl Scene {
    /// Validates the mesh and builds the requested structure. Until the selector lands, `Auto` is
    /// served by the grid (outcome `OnlineOnGrid` for an unknown budget, `Forced` otherwise,
    /// estimates NaN).
    pub fn build(
        src: &impl MeshSource,
        options: &BuildOptions,
        _calibration: &Calibration,
    ) -> Result<Scene, BuildError> {
        let (structure, outcome) = match options.structure {
            Structure::Grid => (Structure::Grid, Outcome::Forced),
            Structure::KdTree => (Structure::KdTree, Outcome::Forced),
            Structure::Auto if options.expected_rays == 0 => {
                (Structure::Grid, Outcome::OnlineOnGrid)
            }
            Structure::Auto => (Structure::Grid, Outcome::Forced),
        };
        let mut budget = MemoryBudget::new(options.memory_limit);
        let mesh = TriMesh::from_source(src, &mut budget)?;
        let accel = match Accel::build(structure, &mesh, options, &mut budget) {
            Ok(a) => a,
            Err(e) => {
                mesh.release(&mut budget);
                return Err(e);
            }
        };
        let live = mesh.len() - mesh.degenerate_count();
        let (grid_resolution, kd_node_count, kd_depth) = match &accel {
            Accel::Grid(g) => (g.resolution(), 0, 0),
            Accel::KdTree(k) => ([0; 3], k.node_count(), k.depth()),
        };
        let report = SceneReport {
            structure: accel.structure(),
            outcome,
            triangle_count: mesh.len(),
            memory_bytes: mesh.memory_bytes() + accel.memory_bytes(),
            grid_resolution,
            grid_ray_seconds: f64::NAN,
            kd_ray_seconds: f64::NAN,
            kd_build_seconds: f64::NAN,
            break_even_rays: f64::NAN,
            expected_rays: options.expected_rays,
            references_per_triangle: if live == 0 {
                0.0
            } else {
                accel.reference_count() as f64 / live as f64
            },
            kd_node_count,
            kd_depth,
        };
        Ok(Scene {
            mesh,
            accel,
            report,
            rays_traced: 0,
        })
    }

    /// Records rays traced since the last call and rays still expected (0 = unknown), between batches.
    /// The selector will use this to switch structures; until the kd-tree exists the scene stays on
    /// the grid and only the count changes.
    pub fn update(&mut self, rays_traced: u64, _rays_remaining: u64) {
        self.rays_traced = self.rays_traced.saturating_add(rays_traced);
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
