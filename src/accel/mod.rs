//! Acceleration structures and the one query surface they share.

use glam::Vec3;

use crate::mesh::TriMesh;
use crate::ray::{Hit, PreparedRay, Ray, TriangleLoop, TriangleTest};

pub mod brute;
pub mod grid;
pub mod kdtree;

/// An axis-aligned box. [`Aabb::EMPTY`] has `min > max` and contains nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

impl Aabb {
    /// The box that contains nothing; growing it by a point gives that point.
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// The smallest box holding `self` and `p`.
    #[inline]
    pub fn grow(self, p: Vec3) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// True when the box holds no point.
    pub fn is_empty(&self) -> bool {
        !(self.min.x <= self.max.x && self.min.y <= self.max.y && self.min.z <= self.max.z)
    }

    /// Edge lengths (zero for an empty box).
    pub fn extent(&self) -> Vec3 {
        if self.is_empty() {
            Vec3::ZERO
        } else {
            self.max - self.min
        }
    }

    /// The bounds of a triangle.
    #[inline]
    pub fn of_triangle(t: &[Vec3; 3]) -> Aabb {
        Aabb {
            min: t[0].min(t[1]).min(t[2]),
            max: t[0].max(t[1]).max(t[2]),
        }
    }
}

/// The three questions every structure answers, about the mesh it was built from.
///
/// Guarantees shared by every implementation: the same watertight triangle test
/// ([`crate::ray::PreparedRay::intersect_triangle`]) and the same tie rule ([`Hit::beats`]), so the
/// closest hit is bit-identical across structures; `occluded` is true exactly when `intersect` hits;
/// neither allocates nor panics, whatever the ray.
pub trait RayQuery {
    /// A box holding every triangle the structure can report.
    fn bounds(&self) -> Aabb;
    /// The closest hit in `[tmin, tmax]`, ties to the lowest primitive id, or [`Hit::MISS`].
    fn intersect(&self, mesh: &TriMesh, ray: &Ray) -> Hit;
    /// True when any triangle is hit in `[tmin, tmax]`.
    fn occluded(&self, mesh: &TriMesh, ray: &Ray) -> bool;
}

/// Prepares `ray` for the triangles of `mesh` and runs `walk` with the triangle test specialised for
/// the ray's axes: the one entry of every structure's queries. A ray that can hit nothing (see
/// [`PreparedRay::new`]) is a miss without a walk.
#[inline(always)]
pub(crate) fn run_query<L: TriangleLoop<Output = Hit>>(mesh: &TriMesh, ray: &Ray, walk: L) -> Hit {
    match PreparedRay::new(ray) {
        Some(r) => r.far_bound(mesh.coordinate_bound()).dispatch(walk),
        None => Hit::MISS,
    }
}

/// Tests the triangles `prims` (a cell's or a leaf's list) and keeps the best hit in `best` by the
/// shared tie rule ([`Hit::beats`]). With `ANY`, returns the first hit at once.
#[inline(always)]
pub(crate) fn test_prims<T: TriangleTest, const ANY: bool>(
    test: &T,
    mesh: &TriMesh,
    prims: &[u32],
    best: &mut Hit,
) -> Option<Hit> {
    for &prim in prims {
        let Some(tri) = mesh.triangle(prim) else {
            continue;
        };
        if let Some((t, u, v)) = test.test(tri) {
            let h = Hit { t, u, v, prim };
            if ANY {
                return Some(h);
            }
            if h.beats(best) {
                *best = h;
            }
        }
    }
    None
}
