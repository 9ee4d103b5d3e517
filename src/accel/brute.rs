//! The reference structure: every triangle, in id order, through the shared test.

use crate::accel::{Aabb, RayQuery};
use crate::mesh::TriMesh;
use crate::ray::{Hit, PreparedRay, Ray};

/// Tests every non-degenerate triangle. Slow and obviously right: the other structures are checked
/// against it bit for bit.
#[derive(Clone, Copy, Debug)]
pub struct BruteForce {
    bounds: Aabb,
}

impl BruteForce {
    /// The reference for `mesh`; it holds nothing but the mesh's bounds.
    pub fn new(mesh: &TriMesh) -> Self {
        BruteForce {
            bounds: mesh.bounds(),
        }
    }
}

impl RayQuery for BruteForce {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn intersect(&self, mesh: &TriMesh, ray: &Ray) -> Hit {
        let Some(r) = PreparedRay::new(ray) else {
            return Hit::MISS;
        };
        let mut best = Hit::MISS;
        for (i, t) in mesh.triangles().iter().enumerate() {
            if mesh.is_degenerate(i as u32) {
                continue;
            }
            if let Some((t, u, v)) = r.intersect_triangle(t[0], t[1], t[2]) {
                let h = Hit {
                    t,
                    u,
                    v,
                    prim: i as u32,
                };
                if h.beats(&best) {
                    best = h;
                }
            }
        }
        best
    }

    fn occluded(&self, mesh: &TriMesh, ray: &Ray) -> bool {
        self.intersect(mesh, ray).is_hit()
    }
}
