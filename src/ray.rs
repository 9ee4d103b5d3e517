//! Rays, hits, and the one watertight ray/triangle test every structure uses.

use glam::{DVec3, Vec3};

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
        Ray {
            org,
            tmin: 0.0,
            dir,
            tmax: f32::INFINITY,
        }
    }

    /// A ray with an explicit `[tmin, tmax]` window.
    pub fn segment(org: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray {
            org,
            tmin,
            dir,
            tmax,
        }
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
    pub const MISS: Hit = Hit {
        t: f32::INFINITY,
        u: 0.0,
        v: 0.0,
        prim: Hit::INVALID_ID,
    };

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
    org64: DVec3,
    sx: f64,
    sy: f64,
    sz: f64,
}

/// How far, relative to the magnitude of the triangle's coordinates, a ray may miss it (measured in
/// the triangle's plane) and still hit it: 16 ulps of f32, a few times the rounding a caller makes
/// when it aims a ray at a vertex in f32. Structures must enlarge their cells by more than this.
pub const NEAR_MISS_TOLERANCE: f32 = f32::EPSILON * 16.0;
/// The same allowance per unit of distance between the ray origin and the triangle (8 ulps).
pub const NEAR_MISS_TOLERANCE_PER_DISTANCE: f32 = f32::EPSILON * 8.0;

/// The allowance for near misses: `bary` are the barycentrics of the point where the ray crosses the
/// triangle's plane (at least one negative). Returns the barycentrics of the triangle's nearest
/// point to that crossing when it lies within the tolerance; `None` otherwise. Rare, so kept out of
/// line.
#[inline(never)]
#[cold]
fn near_miss(p: &[Vec3; 3], bary: [f64; 3], rel: [DVec3; 3]) -> Option<[f64; 3]> {
    let q = [p[0].as_dvec3(), p[1].as_dvec3(), p[2].as_dvec3()];
    let crossing = bary[0] * q[0] + bary[1] * q[1] + bary[2] * q[2];
    let nearest = closest_point_barycentrics(crossing, &q);
    let point = nearest[0] * q[0] + nearest[1] * q[1] + nearest[2] * q[2];
    let coord_scale = q[0].abs().max(q[1].abs()).max(q[2].abs()).max_element();
    let dist_scale = rel[0]
        .abs()
        .max(rel[1].abs())
        .max(rel[2].abs())
        .max_element();
    // The caller's rounding of a ray aimed in f32 grows with the coordinates and with the distance
    // from the origin.
    let tol = f64::from(NEAR_MISS_TOLERANCE) * coord_scale
        + f64::from(NEAR_MISS_TOLERANCE_PER_DISTANCE) * dist_scale;
    if (point - crossing).length() <= tol {
        Some(nearest)
    } else {
        None
    }
}

/// Barycentrics of the point of triangle `q` nearest to `x`, a point in the triangle's plane (the
/// Voronoi-region walk of Ericson, Real-Time Collision Detection, 5.1.5).
fn closest_point_barycentrics(x: DVec3, q: &[DVec3; 3]) -> [f64; 3] {
    let ab = q[1] - q[0];
    let ac = q[2] - q[0];
    let ap = x - q[0];
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = x - q[1];
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = x - q[2];
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    [1.0 - v - w, v, w]
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
            org64: o.as_dvec3(),
            sx: f64::from(d[kx]) / f64::from(d[kz]),
            sy: f64::from(d[ky]) / f64::from(d[kz]),
            sz: 1.0 / f64::from(d[kz]),
        })
    }

    /// The watertight test against triangle `(p0, p1, p2)`: `Some((t, u, v))` when the ray passes
    /// through the closed triangle with `tmin ≤ t ≤ tmax`.
    ///
    /// Guarantees: the decision is made in f64 from the f32 inputs (the translation to the ray origin
    /// is exact and the shear nearly so), so it is the exact answer for the f32 ray except within
    /// ~1e-15 of an edge; rays through a shared edge or vertex of two triangles hit at least one of
    /// them; a triangle seen exactly edge-on is missed. A ray that misses a triangle by at most a few
    /// ulps of the coordinates, measured in the triangle's plane, still hits it at the nearest point
    /// of the triangle, so rays aimed at a vertex or along a silhouette of a closed mesh never slip
    /// out through rounding, while grazing triangles (whose plane the ray crosses far away) are not
    /// hit by this allowance.
    #[inline(always)]
    pub fn intersect_triangle(&self, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<(f32, f32, f32)> {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let a = p0.as_dvec3() - self.org64;
        let b = p1.as_dvec3() - self.org64;
        let c = p2.as_dvec3() - self.org64;
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        let mut det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        // Orient so that an inside point has three non-negative edge functions.
        let s = if det > 0.0 { 1.0 } else { -1.0 };
        if u * s < 0.0 || v * s < 0.0 || w * s < 0.0 {
            let [bu, bv, bw] = near_miss(&[p0, p1, p2], [u / det, v / det, w / det], [a, b, c])?;
            (u, v, w, det) = (bu, bv, bw, 1.0);
        }
        let t = (u * a[kz] + v * b[kz] + w * c[kz]) * self.sz / det;
        let t = t as f32;
        if !(t >= self.tmin && t <= self.tmax) {
            return None;
        }
        Some((t, (v / det) as f32, (w / det) as f32))
    }
}
