//! The selector's sample rays: traced through the grid that is already built, counting the work, so
//! that the cost model sees what rays do in this scene. Nothing is allocated.

use crate::accel::grid::{GridWork, UniformGrid};
use crate::accel::kdtree::{KdTree, KdWork};
use crate::mesh::TriMesh;
use crate::ray::{Hit, Ray};
use crate::workload::{bounce, bounce_offset, Camera, SplitMix64};

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
    /// Camera image side; `side²` primary rays. 0 = no sampling (the estimates are then NaN).
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

impl SampleParams {
    /// These parameters for a known budget of `expected_rays` (0 = unknown): the library's sample
    /// rays (about `2·side²`) are capped at 1/64 of the budget, with a floor of a 2 × 2 image, so
    /// that sampling never costs a small budget more than about 1.5 % of its rays.
    pub fn for_budget(&self, expected_rays: u64) -> SampleParams {
        if expected_rays == 0 {
            return *self;
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
    let run = |ray: &Ray, f: &mut SceneFeatures| {
        let (hit, steps, tests) = trace(ray);
        f.add_ray(hit.is_hit(), steps, tests);
        hit
    };
    if let Some(source) = rays {
        for i in 0..source.ray_count() {
            run(&source.ray(i), &mut f);
        }
        return f;
    }
    let side = params.camera_side as usize;
    let camera = Camera::looking_at(&mesh.bounds(), side);
    let offset = bounce_offset(mesh);
    let mut rng = SplitMix64::new(params.seed);
    for j in 0..side {
        for i in 0..side {
            let primary = camera.ray(i, j, &mut rng);
            let hit = run(&primary, &mut f);
            if let Some(b) = bounce(mesh, &primary, &hit, offset, &mut rng) {
                run(&b, &mut f);
            }
        }
    }
    f
}
