//! Measuring a scene for the calibration (std only: it needs a clock). The path-tracer-like
//! workload is camera rays plus one diffuse bounce per hit; times are medians of repeated runs, on
//! the thread's CPU clock where Linux offers one (a shared VM's stolen time is then not counted).

use std::vec::Vec;

use super::fit::Observation;
use super::model::SceneFeatures;
use super::sample::{sample_grid, SampleParams};
use crate::accel::grid::{GridParams, GridWork, UniformGrid};
use crate::accel::kdtree::{KdTree, KdTreeParams};
use crate::accel::RayQuery;
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::{Hit, Ray};
use crate::workload::{bounce_rays, camera_rays, SplitMix64};

/// How to measure.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasureParams {
    /// Camera image side of the workload (`side²` primary rays plus their bounces).
    pub workload_side: u32,
    /// Repetitions of each timing (the median is kept).
    pub repeats: u32,
    /// Grid parameters.
    pub grid: GridParams,
    /// kd-tree parameters.
    pub kdtree: KdTreeParams,
    /// The selector's sample rays, recorded as [`Observation::sample`].
    pub samples: SampleParams,
    /// Seed of the workload (a different one from the samples' so they are not the same rays).
    pub seed: u64,
}

impl MeasureParams {
    /// 128² camera rays and bounces, 3 repeats, default structures and samples.
    pub const DEFAULT: MeasureParams = MeasureParams {
        workload_side: 128,
        repeats: 3,
        grid: GridParams::DEFAULT,
        kdtree: KdTreeParams::DEFAULT,
        samples: SampleParams::DEFAULT,
        seed: 0xca11_b0a7,
    };
}

/// Seconds this thread has run on a CPU (`CLOCK_THREAD_CPUTIME_ID`, so time stolen by a shared VM
/// or spent in other threads does not count), or wall time where that clock is missing: the
/// reading of [`super::clock::Clock::THREAD`].
pub fn thread_seconds() -> f64 {
    super::clock::thread_nanos() as f64 * 1e-9
}

/// A timing over repeats: median, fastest and slowest, nanoseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timing {
    /// Median.
    pub median: f64,
    /// Fastest repeat.
    pub min: f64,
    /// Slowest repeat.
    pub max: f64,
}

/// `repeats` timings of `f` (at least one), and the last result.
pub fn time_ns<T>(repeats: u32, mut f: impl FnMut() -> T) -> (Timing, T) {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..repeats.max(1) {
        let t = thread_seconds();
        let r = f();
        times.push((thread_seconds() - t) * 1e9);
        last = Some(r);
    }
    times.sort_by(f64::total_cmp);
    let r = last.expect("at least one run");
    let timing = Timing {
        median: times[times.len() / 2],
        min: times[0],
        max: times[times.len() - 1],
    };
    (timing, r)
}

/// The median of `repeats` timings of `f`, in nanoseconds, and the last result.
pub fn median_ns<T>(repeats: u32, f: impl FnMut() -> T) -> (f64, T) {
    let (t, r) = time_ns(repeats, f);
    (t.median, r)
}

/// The spread of an observation's timings (per-ray ones per ray).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Spread {
    /// Grid build.
    pub grid_build: Timing,
    /// kd-tree build.
    pub kd_build: Timing,
    /// Grid, per workload ray.
    pub grid_ray: Timing,
    /// kd-tree, per workload ray.
    pub kd_ray: Timing,
}

/// The workload rays for `mesh`: `side²` camera rays, then one diffuse bounce per hit after them
/// (the evaluation times the two kinds apart by that order).
pub fn workload(mesh: &TriMesh, side: u32, seed: u64) -> Vec<Ray> {
    let mut rng = SplitMix64::new(seed);
    let mut rays = camera_rays(&mesh.bounds(), side as usize, &mut rng);
    let reference = crate::accel::brute::BruteForce::new(mesh);
    let grid = UniformGrid::build(mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0));
    let hits: Vec<Hit> = match &grid {
        Ok(g) => rays.iter().map(|r| g.intersect(mesh, r)).collect(),
        Err(_) => rays.iter().map(|r| reference.intersect(mesh, r)).collect(),
    };
    let bounces = bounce_rays(mesh, &rays, &hits, &mut rng);
    rays.extend(bounces);
    rays
}

/// Traces `rays` through `accel` for their closest hits, returning a checksum of the hit ids (so
/// that the work cannot be optimised away): what every timing of a workload times.
pub fn trace(accel: &dyn RayQuery, mesh: &TriMesh, rays: &[Ray]) -> u32 {
    rays.iter().fold(0u32, |acc, r| {
        acc.wrapping_add(accel.intersect(mesh, r).prim)
    })
}

/// Builds both structures on `mesh`, times the builds and the workload on each, and records what the
/// workload and the selector's sample rays did on the grid.
pub fn observe(mesh: &TriMesh, params: &MeasureParams) -> Result<Observation, BuildError> {
    observe_with_spread(mesh, params).map(|(o, _)| o)
}

/// [`observe`], also returning the spread of the repeated timings.
pub fn observe_with_spread(
    mesh: &TriMesh,
    params: &MeasureParams,
) -> Result<(Observation, Spread), BuildError> {
    let rays = workload(mesh, params.workload_side, params.seed);
    observe_rays(mesh, &rays, params)
}

/// [`observe_with_spread`] on the caller's workload rays.
pub fn observe_rays(
    mesh: &TriMesh,
    rays: &[Ray],
    params: &MeasureParams,
) -> Result<(Observation, Spread), BuildError> {
    let (grid_build, grid) = time_ns(params.repeats, || {
        UniformGrid::build(mesh, &params.grid, &mut MemoryBudget::new(0))
    });
    let grid = grid?;
    let (kd_build, tree) = time_ns(params.repeats, || {
        KdTree::build(mesh, &params.kdtree, &mut MemoryBudget::new(0))
    });
    let tree = tree?;
    let mut work = SceneFeatures {
        triangles: mesh.len() - mesh.degenerate_count(),
        grid_references: grid.reference_count() as u64,
        ..SceneFeatures::default()
    };
    for r in rays {
        let mut w = GridWork::default();
        let h = grid.intersect_counted(mesh, r, &mut w);
        work.add_ray(h.is_hit(), w.cells, w.tests);
    }
    let n = rays.len().max(1) as f64;
    let per_ray = |t: Timing| Timing {
        median: t.median / n,
        min: t.min / n,
        max: t.max / n,
    };
    let (grid_ray, _) = time_ns(params.repeats, || trace(&grid, mesh, rays));
    let (kd_ray, _) = time_ns(params.repeats, || trace(&tree, mesh, rays));
    let (sample_ns, sample) = median_ns(params.repeats, || {
        sample_grid(&grid, mesh, None, &params.samples)
    });
    let spread = Spread {
        grid_build,
        kd_build,
        grid_ray: per_ray(grid_ray),
        kd_ray: per_ray(kd_ray),
    };
    let o = Observation {
        workload: work,
        sample,
        sample_grid_ray_ns: sample_ns / sample.rays.max(1) as f64,
        grid_build_ns: grid_build.median,
        kd_build_ns: kd_build.median,
        grid_ray_ns: spread.grid_ray.median,
        kd_ray_ns: spread.kd_ray.median,
    };
    Ok((o, spread))
}
