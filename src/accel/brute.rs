//! The reference structure: every triangle, in id order, through the shared test.

use crate::accel::{counted_hit, run_query, Aabb, AcceptingQuery, RayQuery};
use crate::mesh::TriMesh;
use crate::ray::{Hit, Ray};
use crate::triangle::{Accept, TriangleLoop, TriangleTest};

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

/// The loop over every triangle, run with the test specialised for the ray's axes.
struct AllTriangles<'a, const ANY: bool> {
    mesh: &'a TriMesh,
}

impl<const ANY: bool> TriangleLoop for AllTriangles<'_, ANY> {
    type Output = Hit;

    #[inline(always)]
    fn run<T: TriangleTest>(self, test: T) -> Hit {
        test_all::<T, ANY>(&test, self.mesh)
    }
}

/// Every non-degenerate triangle of `mesh` through the scalar exact test (no filter), in id order
/// (out of line: the grid calls it for rays from beyond its reach, and one copy per kernel serves):
/// the closest hit by the shared tie rule, or with `ANY` the first hit found.
#[inline(never)]
pub(crate) fn test_all<T: TriangleTest, const ANY: bool>(test: &T, mesh: &TriMesh) -> Hit {
    let mut best = Hit::MISS;
    let tris = mesh.triangles();
    let bits = mesh.degenerate_bits();
    // 32 triangles per word of degenerate flags; the last chunk may be shorter.
    for (chunk_index, (chunk, &flags)) in tris.chunks(32).zip(bits).enumerate() {
        let base = chunk_index * 32;
        for (k, tri) in chunk.iter().enumerate() {
            if flags & (1 << k) != 0 {
                continue;
            }
            let prim = (base + k) as u32;
            if let Some(h) = counted_hit(test, prim, tri) {
                if h.beats(&best) {
                    best = h;
                    if ANY {
                        return best;
                    }
                }
            }
        }
    }
    best
}

impl RayQuery for BruteForce {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn intersect(&self, mesh: &TriMesh, ray: &Ray) -> Hit {
        self.intersect_accepting(mesh, ray, None)
    }

    fn occluded(&self, mesh: &TriMesh, ray: &Ray) -> bool {
        self.occluded_accepting(mesh, ray, None)
    }
}

impl AcceptingQuery for BruteForce {
    fn intersect_accepting(&self, mesh: &TriMesh, ray: &Ray, accept: Option<&dyn Accept>) -> Hit {
        run_query(
            mesh,
            Aabb::EMPTY,
            ray,
            accept,
            AllTriangles::<false> { mesh },
        )
    }

    fn occluded_accepting(&self, mesh: &TriMesh, ray: &Ray, accept: Option<&dyn Accept>) -> bool {
        run_query(
            mesh,
            Aabb::EMPTY,
            ray,
            accept,
            AllTriangles::<true> { mesh },
        )
        .is_hit()
    }
}
