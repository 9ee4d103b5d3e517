//! The selector's sample rays: traced through the grid that is already built, counting the work, so
//! that the cost model sees what rays do in this scene. Nothing is allocated.

use crate::accel::grid::{GridWork, UniformGrid};
use crate::accel::kdtree::{KdTree, KdWork};
use crate::accel::RayQuery;
use crate::mesh::TriMesh;
use crate::ray::{Hit, Ray};
use crate::workload::{bounce, bounce_offset, Camera, SplitMix64};

use super::clock::Clock;
use super::model::SceneFeatures;

/// Rays a caller offers as representative of its workload.
pub trait RaySource {
    /// How many rays there are.
    fn ray_count(&self) -> usize;
    /// Ray `i` (`i < ray_count()`).
    fn ray(&self, i: usize) -> Ray;
}

impl RaySource for &[Ray] {
    fn ray_count(&self) -> usize {
        self.len()
    }
    fn ray(&self, i: usize) -> Ray {
        self.get(i)
            .copied()
            .unwrap_or(Ray::new(glam::Vec3::ZERO, glam::Vec3::ZERO))
    }
}

impl RaySource for alloc::vec::Vec<Ray> {
    fn ray_count(&self) -> usize {
        self.len()
    }
    fn ray(&self, i: usize) -> Ray {
        self.as_slice().ray(i)
    }
}

/// How many sample rays the library makes when the caller gives none: a `side × side` camera image
/// of the whole scene (the view of [`Camera::looking_at`]) plus one diffuse bounce per hit — the shape
/// of a path tracer's first two bounces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleParams {
    /// Camera image side; `side²` primary rays. 0 = no sampling (the estimates are then NaN). The
    /// selector caps it by the budget ([`SampleParams::for_budget`]).
    pub camera_side: u32,
    /// Seed of the pixel jitter and the bounce directions (the samples are deterministic).
    pub seed: u64,
}

impl SampleParams {
    /// 24 × 24 camera rays and their bounces: at most 1 152 rays (781 on the evaluation's median
    /// scene, where many camera rays miss).
    pub const DEFAULT: SampleParams = SampleParams {
        camera_side: 24,
        seed: 0x5a3b_1e5d,
    };
}

/// The largest camera side of the library's samples when the budget is unknown (`expected_rays
/// = 0`): 8 × 8 camera rays and their bounces, at most 128 rays (88 on the evaluation's median
/// scene). The samples are traced at the build, before any ray, and with no budget to cap them the
/// default 24 × 24 (781 rays on the median scene) cost a small job nearly as much as its own rays:
/// the online switch's worst regret was a thousand rays on the smallest scenes (sphereflake-1k,
/// spd_teapot: 1.71–1.92 against the goal of 1.8). Measured by docs/evaluation.md's "Sample
/// rays" table, which prices every side on one run's measurements (five runs at stop 31): the
/// unknown budget's regret, geometric mean over 31 scenes × 10³..10⁸ rays, rises with the side —
/// 1.028–1.032 at 2, 1.034–1.038 at 8, 1.044–1.047 at 12, 1.051–1.054 at 16, 1.075–1.079 at 24,
/// 1.17 at 48 — while its worst at every side up to 16 is an estimate's error that more samples do
/// not fix (stadium-1M, tetra-10k or slivers-2k, 1.40–1.76). The renderer's own tapped rays replace
/// the samples' estimate at `Scene::update` once 256 are held.
pub const UNKNOWN_BUDGET_SIDE: u32 = 8;

impl SampleParams {
    /// These parameters for a known budget of `expected_rays` (0 = unknown): the library's sample
    /// rays (about `2·side²`) are capped at 1/64 of the budget, with a floor of a 2 × 2 image, so
    /// that sampling never costs a small budget more than about 1.5 % of its rays; an unknown
    /// budget's side is capped at [`UNKNOWN_BUDGET_SIDE`].
    pub fn for_budget(&self, expected_rays: u64) -> SampleParams {
        if expected_rays == 0 {
            return SampleParams {
                camera_side: self.camera_side.min(UNKNOWN_BUDGET_SIDE),
                ..*self
            };
        }
        let cap = (expected_rays / 128) as f64;
        let side = (crate::math::sqrt64(cap) as u32).clamp(2, self.camera_side.max(2));
        SampleParams {
            camera_side: side.min(self.camera_side),
            ..*self
        }
    }
}

impl Default for SampleParams {
    fn default() -> Self {
        SampleParams::DEFAULT
    }
}

/// Traces the sample rays (the caller's, or the library's per `params`) through `grid`, counting
/// cells, triangle tests and hits; the features also carry the grid's reference count.
pub fn sample_grid(
    grid: &UniformGrid,
    mesh: &TriMesh,
    rays: Option<&dyn RaySource>,
    params: &SampleParams,
) -> SceneFeatures {
    let mut f = sample_with(mesh, rays, params, |ray| {
        let mut work = GridWork::default();
        let hit = grid.intersect_counted(mesh, ray, &mut work);
        (hit, work.cells, work.tests)
    });
    f.grid_references = grid.reference_count() as u64;
    f.grid_largest_cell = grid.largest_cell() as u64;
    f
}

/// The same sample rays as [`sample_grid`] (the kd-tree's hits are the grid's, so the bounces are
/// the same too) through `tree`: `cells` counts the nodes visited.
pub fn sample_kdtree(
    tree: &KdTree,
    mesh: &TriMesh,
    rays: Option<&dyn RaySource>,
    params: &SampleParams,
) -> SceneFeatures {
    sample_with(mesh, rays, params, |ray| {
        let mut work = KdWork::default();
        let hit = tree.intersect_counted(mesh, ray, &mut work);
        (hit, work.nodes, work.tests)
    })
}

/// Runs `trace` (hit, steps, tests) on every sample ray and adds up the work.
fn sample_with(
    mesh: &TriMesh,
    rays: Option<&dyn RaySource>,
    params: &SampleParams,
    trace: impl Fn(&Ray) -> (Hit, u32, u32),
) -> SceneFeatures {
    let mut f = SceneFeatures {
        triangles: mesh.len() - mesh.degenerate_count(),
        ..SceneFeatures::default()
    };
    for_each_sample(mesh, rays, params, |ray| {
        let (hit, steps, tests) = trace(ray);
        f.add_ray(hit.is_hit(), steps, tests);
        hit
    });
    f
}

/// Calls `trace` on every sample ray in order: the caller's, or the library's per `params` (each
/// camera ray, then its bounce from the hit `trace` returned).
fn for_each_sample(
    mesh: &TriMesh,
    rays: Option<&dyn RaySource>,
    params: &SampleParams,
    mut trace: impl FnMut(&Ray) -> Hit,
) {
    if let Some(source) = rays {
        for i in 0..source.ray_count() {
            trace(&source.ray(i));
        }
        return;
    }
    let side = params.camera_side as usize;
    let camera = Camera::looking_at(&mesh.bounds(), side);
    let offset = bounce_offset(mesh);
    let mut rng = SplitMix64::new(params.seed);
    for j in 0..side {
        for i in 0..side {
            let primary = camera.ray(i, j, &mut rng);
            let hit = trace(&primary);
            if let Some(b) = bounce(mesh, &primary, &hit, offset, &mut rng) {
                trace(&b);
            }
        }
    }
}

/// The nanoseconds `clock` says the same sample rays as [`sample_grid`] take as plain queries
/// through `query` (the grid or the kd-tree: their hits, and so the bounces, are the same), for
/// the check after a kd-tree build to compare the two structures by time. Nothing is allocated.
pub fn time_samples(
    query: &dyn RayQuery,
    mesh: &TriMesh,
    rays: Option<&dyn RaySource>,
    params: &SampleParams,
    clock: &Clock,
) -> u64 {
    clock
        .time(|| for_each_sample(mesh, rays, params, |ray| query.intersect(mesh, ray)))
        .0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An unknown budget samples at most an 8 × 8 image (a smaller side asked for is kept); a known
    /// budget's cap is 1/64 of it, unchanged by the unknown budget's.
    #[test]
    fn the_sample_image_follows_the_budget() {
        let side = |p: SampleParams, rays: u64| p.for_budget(rays).camera_side;
        let d = SampleParams::DEFAULT;
        assert_eq!(side(d, 0), UNKNOWN_BUDGET_SIDE);
        let small = SampleParams {
            camera_side: 5,
            ..d
        };
        assert_eq!(side(small, 0), 5);
        // 128·side² rays buy the side: 24 from 73 728 rays, 12 from 18 432, the floor 2 below.
        assert_eq!(side(d, 73_728), 24);
        assert_eq!(side(d, u64::MAX), 24);
        assert_eq!(side(d, 18_432), 12);
        assert_eq!(side(d, 18_431), 11);
        assert_eq!(side(d, 1), 2);
        assert_eq!(d.for_budget(0).seed, d.seed);
    }
}
