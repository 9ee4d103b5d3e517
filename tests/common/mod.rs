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
