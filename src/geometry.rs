//! Scenes of several geometries: how rays see each one (masks, face culling, an any-hit filter),
//! the rays and hits that carry geometry ids, and the conditions a query puts on its hits.
//!
//! The hit of a query is the closest candidate that passes the geometry's and the ray's conditions,
//! ties to the lowest `(geometry, triangle)`; every structure gives the same bits (conditions are
//! asked of the exact hits every structure finds, by the one rule of [`crate::Hit::beats`]). A
//! filter may be called for the candidates in any order and more than once for a triangle.

use alloc::boxed::Box;
use glam::Vec3;

use crate::mesh::{MeshSource, TriMesh};
use crate::ray::{Hit, Ray};
use crate::triangle::{Accept, TriHit};

/// Do not report hits on back faces (the side from which a triangle's vertices appear clockwise).
pub const CULL_BACK_FACES: u32 = 1;
/// Do not report hits on front faces (the side from which its vertices appear counter-clockwise).
pub const CULL_FRONT_FACES: u32 = 2;

/// An any-hit filter: called for a candidate hit of its geometry; `false` makes the query ignore
/// the candidate (alpha-tested leaves, glass in shadow rays). Called from any thread that queries,
/// for candidates in any order and possibly more than once per triangle; it must not panic.
pub type Filter = dyn Fn(&RayEx, &HitEx) -> bool + Send + Sync;

/// A ray with the conditions of a scene of several geometries: `mask` (a geometry is seen when
/// `mask & geometry.mask != 0`) and `flags` (`CULL_BACK_FACES`, `CULL_FRONT_FACES`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayEx {
    /// The ray.
    pub ray: Ray,
    /// Which geometries it sees.
    pub mask: u32,
    /// Faces it ignores.
    pub flags: u32,
}

impl RayEx {
    /// `ray` seeing every geometry, culling nothing.
    pub const fn new(ray: Ray) -> RayEx {
        RayEx {
            ray,
            mask: u32::MAX,
            flags: 0,
        }
    }
}

/// A hit in a scene of several geometries: `prim` is the triangle's index in its geometry `geom`;
/// `ng = (v1 − v0) × (v2 − v0)`, not normalized. A miss is [`HitEx::MISS`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitEx {
    /// Ray parameter.
    pub t: f32,
    /// Weight of the triangle's second vertex.
    pub u: f32,
    /// Weight of the third vertex.
    pub v: f32,
    /// The triangle's index in its geometry.
    pub prim: u32,
    /// The geometry's index.
    pub geom: u32,
    /// The geometric normal, `(v1 − v0) × (v2 − v0)`.
    pub ng: Vec3,
}

impl HitEx {
    /// What a query returns when nothing is hit: `t = +∞`, `u = v = 0`, ids `Hit::INVALID_ID`,
    /// `ng = 0`.
    pub const MISS: HitEx = HitEx {
        t: f32::INFINITY,
        u: 0.0,
        v: 0.0,
        prim: Hit::INVALID_ID,
        geom: Hit::INVALID_ID,
        ng: Vec3::ZERO,
    };

    /// True when this is a hit.
    pub fn is_hit(&self) -> bool {
        self.prim != Hit::INVALID_ID
    }

    /// The hit `h` of `mesh` (a global triangle id) with its geometry, local id and normal.
    pub fn of(mesh: &TriMesh, h: &Hit) -> HitEx {
        let (Some((geom, prim)), Some(tri)) = (mesh.geometry_of(h.prim), mesh.triangle(h.prim))
        else {
            return HitEx::MISS;
        };
        HitEx {
            t: h.t,
            u: h.u,
            v: h.v,
            prim,
            geom,
            ng: (tri[1] - tri[0]).cross(tri[2] - tri[0]),
        }
    }
}

/// One geometry of a scene: a mesh of the caller's and how rays see it.
pub struct Geometry<'a> {
    /// The triangles (copied at build).
    pub mesh: &'a dyn MeshSource,
    /// Seen by rays with `ray.mask & mask != 0`; default `u32::MAX`.
    pub mask: u32,
    /// Faces no ray reports (`CULL_BACK_FACES`, `CULL_FRONT_FACES`); default 0.
    pub flags: u32,
    /// Called for each candidate hit; default none (every candidate counts).
    pub filter: Option<Box<Filter>>,
}

impl<'a> Geometry<'a> {
    /// `mesh`, seen by every ray, both faces, no filter.
    pub fn new(mesh: &'a dyn MeshSource) -> Geometry<'a> {
        Geometry {
            mesh,
            mask: u32::MAX,
            flags: 0,
            filter: None,
        }
    }
}

impl core::fmt::Debug for Geometry<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Geometry")
            .field("triangles", &self.mesh.triangle_count())
            .field("mask", &self.mask)
            .field("flags", &self.flags)
            .field("filter", &self.filter.is_some())
            .finish()
    }
}

/// What a scene keeps of a geometry besides its triangles.
pub(crate) struct Visibility {
    pub mask: u32,
    pub flags: u32,
    pub filter: Option<Box<Filter>>,
}

impl Visibility {
    /// True when this geometry puts no condition on any ray (every ray sees it, both faces, no
    /// filter): a scene of such geometries answers plain queries without asking.
    pub fn is_plain(&self) -> bool {
        self.mask == u32::MAX && self.flags == 0 && self.filter.is_none()
    }
}

impl core::fmt::Debug for Visibility {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Visibility")
            .field("mask", &self.mask)
            .field("flags", &self.flags)
            .field("filter", &self.filter.is_some())
            .finish()
    }
}

/// The conditions of one query: the ray's mask and flags against each geometry's, then its filter.
pub(crate) struct Conditions<'a> {
    pub mesh: &'a TriMesh,
    pub geometries: &'a [Visibility],
    pub ray: &'a RayEx,
}

impl Accept for Conditions<'_> {
    fn accept(&self, prim: u32, hit: &TriHit) -> bool {
        let Some((g, local)) = self.mesh.geometry_of(prim) else {
            return false;
        };
        // A scene of one mesh keeps no conditions: its geometry has every mask bit and no culling.
        let (mask, flags, filter) = match self.geometries.get(g as usize) {
            Some(vis) => (vis.mask, vis.flags, vis.filter.as_ref()),
            None => (u32::MAX, 0, None),
        };
        if self.ray.mask & mask == 0 {
            return false;
        }
        let cull = self.ray.flags | flags;
        let culled = if hit.front {
            CULL_FRONT_FACES
        } else {
            CULL_BACK_FACES
        };
        if cull & culled != 0 {
            return false;
        }
        match filter {
            None => true,
            Some(filter) => {
                let ng = self
                    .mesh
                    .triangle(prim)
                    .map_or(Vec3::ZERO, |t| (t[1] - t[0]).cross(t[2] - t[0]));
                let candidate = HitEx {
                    t: hit.t,
                    u: hit.u,
                    v: hit.v,
                    prim: local,
                    geom: g,
                    ng,
                };
                filter(self.ray, &candidate)
            }
        }
    }
}
