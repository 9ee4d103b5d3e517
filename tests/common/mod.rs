//! Helpers shared by the integration tests: scenes, ray sets, and the bit-for-bit comparison.
#![allow(dead_code)]

use rayq::accel::RayQuery;
use rayq::mesh::MeshData;
use rayq::workload::{adversarial_rays, bounce_rays, camera_rays, SplitMix64};
use rayq::{BruteForce, Hit, MemoryBudget, Ray, TriMesh};

/// A committed scene from `scenes/`.
pub fn bundled(name: &str) -> MeshData {
    let path = format!("{}/scenes/{name}.obj", env!("CARGO_MANIFEST_DIR"));
    rayq::obj::load_obj(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Validates `data` into a mesh with no memory limit.
pub fn mesh_of(data: &MeshData) -> TriMesh {
    TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).expect("valid mesh")
}

/// Camera rays, their diffuse bounces, and adversarial rays: the mix every agreement test uses.
pub fn test_rays(mesh: &TriMesh, side: usize, adversarial: usize, seed: u64) -> Vec<Ray> {
    let mut rng = SplitMix64::new(seed);
    let reference = BruteForce::new(mesh);
    let mut rays = camera_rays(&mesh.bounds(), side, &mut rng);
    let hits: Vec<Hit> = rays.iter().map(|r| reference.intersect(mesh, r)).collect();
    let bounces = bounce_rays(mesh, &rays, &hits, &mut rng);
    rays.extend(bounces);
    rays.extend(adversarial_rays(mesh, adversarial, &mut rng));
    rays
}

/// The brute-force answers for `rays`, computed once and compared against every structure.
pub fn reference_hits(mesh: &TriMesh, rays: &[Ray]) -> Vec<Hit> {
    let reference = BruteForce::new(mesh);
    rays.iter().map(|r| reference.intersect(mesh, r)).collect()
}

/// Asserts that `accel` returns exactly the reference hit on every ray (t, u, v, prim bit for bit)
/// and that `occluded` agrees with `intersect`. Returns how many rays hit.
pub fn assert_agrees(
    name: &str,
    mesh: &TriMesh,
    accel: &dyn RayQuery,
    rays: &[Ray],
    want: &[Hit],
) -> usize {
    let mut hits = 0;
    for (i, (r, want)) in rays.iter().zip(want).enumerate() {
        let got = accel.intersect(mesh, r);
        assert!(
            got.same_bits(want),
            "{name}: ray {i} {r:?}: got {got:?}, brute force {want:?}"
        );
        assert_eq!(
            accel.occluded(mesh, r),
            want.is_hit(),
            "{name}: ray {i} {r:?}: occluded disagrees with intersect"
        );
        hits += usize::from(want.is_hit());
    }
    hits
}

/// Rays that break tracers, for `mesh` and the cell planes of a grid with `cell_planes` (per axis,
/// the coordinates of its cell boundaries; may be empty): axis-parallel directions, −0.0
/// components, denormal and huge direction components, origins exactly on cell boundaries and on
/// vertex coordinates (where a kd-tree's perfect splits lie), origins on vertices, `tmin == tmax`,
/// infinite and finite `tmax`. Deterministic from `seed`; about `count` rays.
pub fn hostile_rays(
    mesh: &TriMesh,
    cell_planes: &[Vec<f32>; 3],
    count: usize,
    seed: u64,
) -> Vec<Ray> {
    use glam::Vec3;
    let mut rng = SplitMix64::new(seed);
    let b = mesh.bounds();
    let (lo, ext) = (b.min, b.extent());
    let point = |rng: &mut SplitMix64| {
        lo + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * ext * 1.2 - 0.1 * ext
    };
    let vertex = |rng: &mut SplitMix64| {
        let tris = mesh.triangles();
        if tris.is_empty() {
            return Vec3::ZERO;
        }
        tris[rng.below(tris.len())][rng.below(3)]
    };
    // A direction with a hostile component on one random axis and ordinary ones elsewhere.
    let hostile_dir = |rng: &mut SplitMix64| {
        let mut d = rng.unit_vector();
        let odd = ODD_COMPONENTS;
        let a = rng.below(3);
        d[a] = odd[rng.below(odd.len())];
        if rng.next_f32() < 0.3 {
            // Two hostile axes: the ray is axis-parallel or nearly so.
            d[(a + 1) % 3] = odd[rng.below(odd.len())];
        }
        d
    };
    let mut rays = Vec::with_capacity(count);
    for k in 0..count {
        let mut org = point(&mut rng);
        match k % 5 {
            0 => {
                let a = rng.below(3);
                if let Some(p) = cell_planes[a].get(rng.below(cell_planes[a].len().max(1))) {
                    org[a] = *p;
                }
            }
            1 => {
                let a = rng.below(3);
                org[a] = vertex(&mut rng)[a];
            }
            2 => org = vertex(&mut rng),
            _ => {}
        }
        let dir = match rng.below(3) {
            0 => {
                let mut d = Vec3::splat(if rng.next_f32() < 0.5 { -0.0 } else { 0.0 });
                d[rng.below(3)] = if rng.next_f32() < 0.5 { -1.0 } else { 1.0 };
                d
            }
            1 => hostile_dir(&mut rng),
            _ => vertex(&mut rng) - org,
        };
        let ray = match rng.below(4) {
            0 => Ray::segment(org, dir, 0.5, 0.5),
            1 => Ray::segment(org, dir, 0.0, 1.0),
            2 => Ray::segment(org, dir, -f32::INFINITY, f32::INFINITY),
            _ => Ray::new(org, dir),
        };
        rays.push(ray);
    }
    rays
}

/// Copies of `ray` with NaN in each of its eight fields in turn: every one must miss.
pub fn nan_rays(ray: &Ray) -> Vec<Ray> {
    (0..8)
        .map(|i| {
            let mut r = *ray;
            match i {
                0..=2 => r.org[i] = f32::NAN,
                3..=5 => r.dir[i - 3] = f32::NAN,
                6 => r.tmin = f32::NAN,
                _ => r.tmax = f32::NAN,
            }
            r
        })
        .collect()
}

/// The coordinates of a grid's cell boundaries per axis (`res[a] + 1` planes over `bounds`), as
/// the grid computes them (`min + i · cell size`, in f32).
pub fn grid_planes(grid: &rayq::UniformGrid) -> [Vec<f32>; 3] {
    let b = rayq::RayQuery::bounds(grid);
    let res = grid.resolution();
    [0, 1, 2].map(|a| {
        if res[a] == 0 {
            return Vec::new();
        }
        let size = (b.max[a] - b.min[a]) / res[a] as f32;
        (0..=res[a]).map(|i| b.min[a] + i as f32 * size).collect()
    })
}

/// Rays from outside `mesh`'s box aimed exactly (in f32) at each vertex and each edge midpoint of
/// up to `limit` triangles, from a direction chosen from `seed`. On a closed mesh every one must
/// hit: the target lies on the surface.
pub fn aimed_rays(mesh: &TriMesh, limit: usize, seed: u64) -> Vec<Ray> {
    let mut rng = SplitMix64::new(seed);
    let b = mesh.bounds();
    let diag = b.extent().length();
    let mut rays = Vec::new();
    for tri in mesh.triangles().iter().take(limit) {
        for i in 0..3 {
            for target in [tri[i], 0.5 * (tri[i] + tri[(i + 1) % 3])] {
                let org = target + rng.unit_vector() * (2.0 * diag);
                rays.push(Ray::new(org, target - org));
            }
        }
    }
    rays
}

/// Direction components that break direction handling: signed zeros, denormals, tiny, huge.
pub const ODD_COMPONENTS: [f32; 8] = [
    0.0,
    -0.0,
    1e-40,
    -1e-45,
    1e-30,
    1e30,
    -f32::MAX,
    f32::MIN_POSITIVE,
];
