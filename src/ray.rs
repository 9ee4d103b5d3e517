//! Rays, hits, and the one watertight ray/triangle test every structure uses.

use glam::Vec3;

/// A ray `org + t·dir` restricted to `tmin ≤ t ≤ tmax`. `dir` need not be normalized.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin.
    pub org: Vec3,
    /// Smallest accepted `t`.
    pub tmin: f32,
    /// Direction (any length except zero).
    pub dir: Vec3,
    /// Largest accepted `t`; may be `f32::INFINITY`.
    pub tmax: f32,
}

impl Ray {
    /// A ray over `[0, ∞]`.
    pub fn new(org: Vec3, dir: Vec3) -> Self {
        Ray { org, tmin: 0.0, dir, tmax: f32::INFINITY }
    }

    /// A ray with an explicit `[tmin, tmax]` window.
    pub fn segment(org: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray { org, tmin, dir, tmax }
    }
}

/// The answer to a closest-hit query.
///
/// `u` and `v` are the barycentric weights of the triangle's second and third vertex. A miss is
/// [`Hit::MISS`]: `t = +∞`, `u = v = 0`, `prim = Hit::INVALID_ID`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Weight of the second vertex.
    pub u: f32,
    /// Weight of the third vertex.
    pub v: f32,
    /// Index of the triangle in the mesh.
    pub prim: u32,
}

impl Hit {
    /// The primitive id of a miss.
    pub const INVALID_ID: u32 = u32::MAX;
    /// What a query returns when nothing is hit.
    pub const MISS: Hit = Hit { t: f32::INFINITY, u: 0.0, v: 0.0, prim: Hit::INVALID_ID };

    /// True when this is a hit.
    pub fn is_hit(&self) -> bool {
        self.prim != Hit::INVALID_ID
    }

    /// True when `self` should replace `best`: nearer, or as near with a lower primitive id.
    /// This is the tie rule every structure shares.
    #[inline(always)]
    pub fn beats(&self, best: &Hit) -> bool {
        self.t < best.t || (self.t == best.t && self.prim < best.prim)
    }

    /// Bit-level equality (distinguishes -0.0 from 0.0), the agreement tests' notion of "the same hit".
    pub fn same_bits(&self, other: &Hit) -> bool {
        self.t.to_bits() == other.t.to_bits()
            && self.u.to_bits() == other.u.to_bits()
            && self.v.to_bits() == other.v.to_bits()
            && self.prim == other.prim
    }
}

/// A ray with the per-ray constants of the watertight triangle test (Woop, Benthin, Wald 2013)
/// computed once. Only [`PreparedRay::new`] makes one, and it refuses rays that cannot hit anything.
///
/// Guarantees: origin and direction are finite, the direction is not zero, `tmin ≤ tmax`, and neither
/// is NaN.
#[derive(Clone, Copy, Debug)]
pub struct PreparedRay {
    /// Origin.
    pub org: Vec3,
    /// Direction.
    pub dir: Vec3,
    /// Window start.
    pub tmin: f32,
    /// Window end.
    pub tmax: f32,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl PreparedRay {
    /// Prepares `ray`, or `None` when it can hit nothing: a NaN or infinite component, a zero
    /// direction, a NaN bound, or `tmin > tmax`.
    #[inline]
    pub fn new(ray: &Ray) -> Option<PreparedRay> {
        let (o, d) = (ray.org, ray.dir);
        if !(o.is_finite() && d.is_finite()) || d == Vec3::ZERO {
            return None;
        }
        // NaN fails both comparisons; an infinite tmin is allowed only as an empty window.
        if !(ray.tmin <= ray.tmax) {
            return None;
        }
        let a = d.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding so that the sign of the edge functions does not depend on the ray's sense.
        if d[kz] < 0.0 {
            core::mem::swap(&mut kx, &mut ky);
        }
        Some(PreparedRay {
            org: o,
            dir: d,
            tmin: ray.tmin,
            tmax: ray.tmax,
            kx,
            ky,
            kz,
            sx: d[kx] / d[kz],
            sy: d[ky] / d[kz],
            sz: 1.0 / d[kz],
        })
    }

    /// The watertight test against triangle `(p0, p1, p2)`: `Some((t, u, v))` when the ray passes
    /// through the closed triangle with `tmin ≤ t ≤ tmax`. Rays through a shared edge or vertex of two
    /// triangles hit at least one of them; a triangle seen edge-on (zero projected area) is missed.
    #[inline(always)]
    pub fn intersect_triangle(&self, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<(f32, f32, f32)> {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let a = p0 - self.org;
        let b = p1 - self.org;
        let c = p2 - self.org;
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        // A zero edge function may be a rounding artefact; products of f32 are exact in f64, so the
        // recomputation gives the exact sign and shared edges stay consistent between neighbours.
        if u == 0.0 || v == 0.0 || w == 0.0 {
            u = (cx as f64 * by as f64 - cy as f64 * bx as f64) as f32;
            v = (ax as f64 * cy as f64 - ay as f64 * cx as f64) as f32;
            w = (bx as f64 * ay as f64 - by as f64 * ax as f64) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t_scaled = u * az + v * bz + w * cz;
        let rcp = 1.0 / det;
        let t = t_scaled * rcp;
        if !(t >= self.tmin && t <= self.tmax) {
            return None;
        }
        Some((t, v * rcp, w * rcp))
    }
}
