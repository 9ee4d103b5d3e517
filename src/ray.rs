//! Rays, hits, and the one watertight ray/triangle test every structure uses.

use glam::{DVec3, Vec3};

use crate::math;

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
    /// Which of the six axis permutations the test uses: `2·kz + swap` (see [`PreparedRay::new`]).
    axes: u8,
    org64: [f64; 3],
    sx: f64,
    sy: f64,
    sz: f64,
    org_max: f64,
    /// An upper bound of the near-miss prefilter's `tol2` for every triangle the ray will be tested
    /// against (`+∞` until [`PreparedRay::far_bound`] sets it).
    tol2_hi: f64,
}

/// How far, relative to the magnitude of the triangle's coordinates, a ray may miss it (measured in
/// the triangle's plane) and still hit it: 64 ulps of f32. A ray aimed at a vertex in f32 misses it
/// by about one ulp, and by ten or more in the triangle's plane when the triangle is seen at a
/// grazing angle. Structures must enlarge their cells by more than this.
pub const NEAR_MISS_TOLERANCE: f32 = f32::EPSILON * 64.0;
/// The same allowance per unit of distance between the ray origin and the triangle (16 ulps).
pub const NEAR_MISS_TOLERANCE_PER_DISTANCE: f32 = f32::EPSILON * 16.0;

/// The allowance for near misses: `bary` are the barycentrics of the point where the ray crosses the
/// triangle's plane (at least one negative), `reach` the largest coordinate magnitude of the
/// triangle's vertices relative to the ray origin. Returns the barycentrics of the triangle's nearest
/// point to that crossing when it lies within the tolerance; `None` otherwise. Rare, so kept out of
/// line.
#[inline(never)]
#[cold]
fn near_miss(p: &[Vec3; 3], bary: [f64; 3], reach: f64) -> Option<[f64; 3]> {
    let q = [p[0].as_dvec3(), p[1].as_dvec3(), p[2].as_dvec3()];
    let crossing = bary[0] * q[0] + bary[1] * q[1] + bary[2] * q[2];
    let nearest = closest_point_barycentrics(crossing, &q);
    let point = nearest[0] * q[0] + nearest[1] * q[1] + nearest[2] * q[2];
    let coord_scale = q[0].abs().max(q[1].abs()).max(q[2].abs()).max_element();
    // The caller's rounding of a ray aimed in f32 grows with the coordinates and with the distance
    // from the origin.
    // Capped at 1/16 of the longest edge: far from the origin the coordinate term can exceed a small
    // triangle, and the allowance must stay a rounding rescue, not a halo. Shrunk for slivers by
    // 2·sqrt(area)/longest edge (about 1 for a well-shaped triangle), so that the allowance is also
    // small in barycentric terms, which is how a long thin triangle's error is usually judged.
    let longest = (q[1] - q[0])
        .length()
        .max((q[2] - q[1]).length())
        .max((q[0] - q[2]).length());
    let area = 0.5 * (q[1] - q[0]).cross(q[2] - q[0]).length();
    let sliver = (2.0 * math::sqrt64(area) / longest).min(1.0);
    let tol = ((f64::from(NEAR_MISS_TOLERANCE) * coord_scale
        + f64::from(NEAR_MISS_TOLERANCE_PER_DISTANCE) * reach)
        * sliver)
        .min(longest / 16.0);
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

/// Lane-wise difference.
#[inline(always)]
fn sub2(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// Lane-wise product.
#[inline(always)]
fn mul2(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] * b[0], a[1] * b[1]]
}

/// Lane-wise magnitude.
#[inline(always)]
fn abs2(a: [f64; 2]) -> [f64; 2] {
    [a[0].abs(), a[1].abs()]
}

/// The largest magnitude of nine finite values. `a > b ? a : b` is `f64::max` when neither is NaN
/// (and magnitudes have no signed zeros), without `max`'s NaN handling.
#[inline(always)]
fn max9(x: [f64; 9]) -> f64 {
    let m = |a: f64, b: f64| if a > b { a } else { b };
    let x = x.map(f64::abs);
    m(
        m(m(x[0], x[1]), m(x[2], x[3])),
        m(m(x[4], x[5]), m(m(x[6], x[7]), x[8])),
    )
}

/// A loop over triangles that wants the triangle test specialised for the ray's axis permutation:
/// [`PreparedRay::dispatch`] calls `run` with one of six monomorphised testers, so the per-test code
/// reads fixed coordinates instead of indexing vectors with run-time axes.
pub(crate) trait TriangleLoop {
    /// What the loop returns.
    type Output;
    /// Runs the loop with `test`.
    fn run<T: TriangleTest>(self, test: T) -> Self::Output;
}

/// The shared triangle test for one prepared ray (see [`PreparedRay::intersect_triangle`]).
pub(crate) trait TriangleTest: Copy {
    /// The ray.
    fn ray(&self) -> &PreparedRay;
    /// Exactly [`PreparedRay::intersect_triangle`] on `tri`.
    fn test(&self, tri: &[Vec3; 3]) -> Option<(f32, f32, f32)>;
}

/// The test specialised for `kz` (the dominant axis of the direction) and `swap` (whether `kx` and
/// `ky` trade places because `dir[kz] < 0`).
#[derive(Clone, Copy)]
pub(crate) struct Kernel<'a, const KZ: usize, const SWAP: bool>(&'a PreparedRay);

impl<const KZ: usize, const SWAP: bool> TriangleTest for Kernel<'_, KZ, SWAP> {
    #[inline(always)]
    fn ray(&self) -> &PreparedRay {
        self.0
    }

    #[inline(always)]
    fn test(&self, tri: &[Vec3; 3]) -> Option<(f32, f32, f32)> {
        self.0.test_axes::<KZ, SWAP>(tri)
    }
}

/// One triangle, for [`PreparedRay::intersect_triangle`].
struct Single<'a>(&'a [Vec3; 3]);

impl TriangleLoop for Single<'_> {
    type Output = Option<(f32, f32, f32)>;
    #[inline(always)]
    fn run<T: TriangleTest>(self, test: T) -> Self::Output {
        test.test(self.0)
    }
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
        let swap = d[kz] < 0.0;
        if swap {
            core::mem::swap(&mut kx, &mut ky);
        }
        Some(PreparedRay {
            org: o,
            dir: d,
            tmin: ray.tmin,
            tmax: ray.tmax,
            axes: (2 * kz + usize::from(swap)) as u8,
            org64: [f64::from(o.x), f64::from(o.y), f64::from(o.z)],
            sx: f64::from(d[kx]) / f64::from(d[kz]),
            sy: f64::from(d[ky]) / f64::from(d[kz]),
            sz: 1.0 / f64::from(d[kz]),
            org_max: f64::from(o.abs().max_element()),
            tol2_hi: f64::INFINITY,
        })
    }

    /// Tells the test that every triangle it will be given has coordinates of magnitude at most
    /// `scale`, so that it can reject most misses with a per-ray bound instead of measuring each
    /// triangle. The answers do not change (see `test_axes`) as long as that promise holds; a
    /// non-finite or negative `scale` leaves the bound off.
    ///
    /// Why `tol2_hi` bounds `tol2`: `reach` is the largest `|fl(p_k − o_k)|` over the triangle's
    /// coordinates. Since `|p_k − o_k| ≤ |p_k| + |o_k| ≤ scale + org_max` exactly and rounding to
    /// nearest is monotone and symmetric, `reach ≤ fl(scale + org_max) = reach_hi`. `tol2` is built
    /// from `reach` with additions and multiplications of non-negative numbers only, each of them
    /// monotone after rounding, so the same expression of `reach_hi` is an upper bound.
    #[inline]
    pub(crate) fn far_bound(mut self, scale: f32) -> Self {
        if scale.is_finite() && scale >= 0.0 {
            let reach_hi = f64::from(scale) + self.org_max;
            self.tol2_hi = 2.0
                * (f64::from(NEAR_MISS_TOLERANCE) * (self.org_max + reach_hi)
                    + f64::from(NEAR_MISS_TOLERANCE_PER_DISTANCE) * reach_hi);
        }
        self
    }

    /// Runs `lp` with the triangle test specialised for this ray's axes.
    #[inline(always)]
    pub(crate) fn dispatch<L: TriangleLoop>(&self, lp: L) -> L::Output {
        match self.axes {
            0 => lp.run(Kernel::<0, false>(self)),
            1 => lp.run(Kernel::<0, true>(self)),
            2 => lp.run(Kernel::<1, false>(self)),
            3 => lp.run(Kernel::<1, true>(self)),
            4 => lp.run(Kernel::<2, false>(self)),
            _ => lp.run(Kernel::<2, true>(self)),
        }
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
    #[inline]
    pub fn intersect_triangle(&self, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<(f32, f32, f32)> {
        // A non-finite coordinate makes a sheared coordinate infinite or NaN, and with it the
        // determinant (each vertex enters two of the three edge functions, whose sum then has an
        // infinite or NaN term that nothing finite can cancel): the test's answer is `None`.
        if !(p0.is_finite() && p1.is_finite() && p2.is_finite()) {
            return None;
        }
        self.dispatch(Single(&[p0, p1, p2]))
    }

    /// The test with the axes fixed at compile time. Every floating-point operation below is the one
    /// the straightforward formulation performs (kept as `reference` in the tests), on the same
    /// operands and in the same order, so the results are identical bit for bit; only the selection of
    /// coordinates (`a[kx]`) is resolved at compile time instead of at run time.
    #[inline(always)]
    fn test_axes<const KZ: usize, const SWAP: bool>(
        &self,
        tri: &[Vec3; 3],
    ) -> Option<(f32, f32, f32)> {
        let kx = if SWAP { (KZ + 2) % 3 } else { (KZ + 1) % 3 };
        let ky = if SWAP { (KZ + 1) % 3 } else { (KZ + 2) % 3 };
        let o = &self.org64;
        let o_xy = [o[kx], o[ky]];
        let shear = [self.sx, self.sy];
        // Translate to the ray origin (f32 → f64 and the difference of two f32 values), then shear so
        // that the ray runs along +z: `x = (p[kx] − o[kx]) − sx·(p[kz] − o[kz])`, likewise `y`. The
        // (x, y) pairs are computed lane by lane, which is how SSE2 likes them.
        let rel = |p: &Vec3| {
            let p = p.to_array();
            let xy = sub2([f64::from(p[kx]), f64::from(p[ky])], o_xy);
            let z = f64::from(p[KZ]) - o[KZ];
            (xy, z, sub2(xy, mul2(shear, [z, z])))
        };
        let (a_xy, a_z, a) = rel(&tri[0]);
        let (b_xy, b_z, b) = rel(&tri[1]);
        let (c_xy, c_z, c) = rel(&tri[2]);
        let [ax, ay] = a;
        let [bx, by] = b;
        let [cx, cy] = c;
        // u = cx·by − cy·bx, v = ax·cy − ay·cx, w = bx·ay − by·ax.
        let [u, v] = sub2(mul2([cx, ax], [by, cy]), mul2([cy, ay], [bx, cx]));
        let w = bx * ay - by * ax;
        let det = u + v + w;
        // The formulation also returns `None` when `det` is not finite. With finite vertices (every
        // caller checks them: `TriMesh` by validation, `intersect_triangle` explicitly) and a
        // prepared ray (finite origin, |sx|, |sy| ≤ 1 because `kz` is the dominant axis), every
        // coordinate above is below 2·3.5e38 in magnitude, every product below 1e79, so `det` is
        // finite and `det == 0` is the whole test.
        if det == 0.0 {
            return None;
        }
        // Orient so that an inside point has three non-negative edge functions. (`|` instead of `||`
        // below: the same truth value, as the operands have no side effects, with fewer branches.)
        let s = if det > 0.0 { 1.0 } else { -1.0 };
        let [us, vs] = mul2([u, v], [s, s]);
        let ws = w * s;
        if (us < 0.0) | (vs < 0.0) | (ws < 0.0) {
            // Most misses are far: reject them before the exact near-miss measure. The ray passes
            // within `tol` of the triangle only if, in the sheared plane (which stretches distances
            // by less than 2), it lies within 2·tol of every edge line it is outside of.
            // lu = |cx − bx| + |cy − by|, lv = |ax − cx| + |ay − cy|, lw = |bx − ax| + |by − ay|.
            let [lu0, lu1] = abs2(sub2(c, b));
            let [lv0, lv1] = abs2(sub2(a, c));
            let [lw0, lw1] = abs2(sub2(b, a));
            let (lu, lv, lw) = (lu0 + lu1, lv0 + lv1, lw0 + lw1);
            // First with the per-ray upper bound of `tol2` (see `far_bound`): `e·s < -tol2_hi·L`
            // implies `e·s < -tol2·L`, since rounding is monotone and `tol2 ≤ tol2_hi`, so this
            // rejects exactly what the test below would, just without computing `reach`.
            let q = -self.tol2_hi;
            if (us < q * lu) | (vs < q * lv) | (ws < q * lw) {
                return None;
            }
            let [a_x, a_y] = a_xy;
            let [b_x, b_y] = b_xy;
            let [c_x, c_y] = c_xy;
            let reach = max9([a_x, a_y, a_z, b_x, b_y, b_z, c_x, c_y, c_z]);
            let tol2 = 2.0
                * (f64::from(NEAR_MISS_TOLERANCE) * (self.org_max + reach)
                    + f64::from(NEAR_MISS_TOLERANCE_PER_DISTANCE) * reach);
            if (us < -tol2 * lu) | (vs < -tol2 * lv) | (ws < -tol2 * lw) {
                return None;
            }
            let [_, bv, bw] = near_miss(tri, [u / det, v / det, w / det], reach)?;
            // The ray is where it crosses the triangle's plane: keep that t (so a near miss never
            // reports a point the ray does not reach) and report the nearest point's barycentrics.
            let t = ((u * a_z + v * b_z + w * c_z) * self.sz / det) as f32;
            if !(t >= self.tmin && t <= self.tmax) {
                return None;
            }
            return Some((t, bv as f32, bw as f32));
        }
        let t = (u * a_z + v * b_z + w * c_z) * self.sz / det;
        let t = t as f32;
        if !(t >= self.tmin && t <= self.tmax) {
            return None;
        }
        Some((t, (v / det) as f32, (w / det) as f32))
    }
}

/// The straightforward formulation of the triangle test, exactly as it was before the specialised
/// kernel: the definition the kernel must reproduce bit for bit.
#[cfg(test)]
#[allow(clippy::all, missing_docs, dead_code)]
mod reference {
    use super::{Ray, NEAR_MISS_TOLERANCE, NEAR_MISS_TOLERANCE_PER_DISTANCE};
    use glam::{DVec3, Vec3};

    /// A ray with the per-ray constants of the watertight triangle test (Woop, Benthin, Wald 2013)
    /// computed once. Only [`PreparedRay::new`] makes one, and it refuses rays that cannot hit anything.
    ///
    /// Guarantees: origin and direction are finite, the direction is not zero, `tmin ≤ tmax`, and neither
    /// is NaN.
    #[derive(Clone, Copy, Debug)]
    pub struct RefRay {
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
        org_max: f64,
    }

    /// The near-miss allowance has one definition (`super::near_miss`); the reference only measures
    /// the distance scale its own way.
    fn near_miss(p: &[Vec3; 3], bary: [f64; 3], rel: [DVec3; 3]) -> Option<[f64; 3]> {
        let dist_scale = rel[0]
            .abs()
            .max(rel[1].abs())
            .max(rel[2].abs())
            .max_element();
        super::near_miss(p, bary, dist_scale)
    }

    impl RefRay {
        /// Prepares `ray`, or `None` when it can hit nothing: a NaN or infinite component, a zero
        /// direction, a NaN bound, or `tmin > tmax`.
        #[inline]
        pub fn new(ray: &Ray) -> Option<RefRay> {
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
            Some(RefRay {
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
                org_max: f64::from(o.abs().max_element()),
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
            let u = cx * by - cy * bx;
            let v = ax * cy - ay * cx;
            let w = bx * ay - by * ax;
            let det = u + v + w;
            if det == 0.0 || !det.is_finite() {
                return None;
            }
            // Orient so that an inside point has three non-negative edge functions.
            let s = if det > 0.0 { 1.0 } else { -1.0 };
            if u * s < 0.0 || v * s < 0.0 || w * s < 0.0 {
                // Most misses are far: reject them before the exact near-miss measure. The ray passes
                // within `tol` of the triangle only if, in the sheared plane (which stretches distances
                // by less than 2), it lies within 2·tol of every edge line it is outside of.
                let reach = a.abs().max(b.abs()).max(c.abs()).max_element();
                let tol2 = 2.0
                    * (f64::from(NEAR_MISS_TOLERANCE) * (self.org_max + reach)
                        + f64::from(NEAR_MISS_TOLERANCE_PER_DISTANCE) * reach);
                let far = |e: f64, (x0, y0): (f64, f64), (x1, y1): (f64, f64)| {
                    e * s < -tol2 * ((x1 - x0).abs() + (y1 - y0).abs())
                };
                if far(u, (bx, by), (cx, cy))
                    || far(v, (cx, cy), (ax, ay))
                    || far(w, (ax, ay), (bx, by))
                {
                    return None;
                }
                let [_, bv, bw] = near_miss(&[p0, p1, p2], [u / det, v / det, w / det], [a, b, c])?;
                let t = ((u * a[kz] + v * b[kz] + w * c[kz]) * self.sz / det) as f32;
                if !(t >= self.tmin && t <= self.tmax) {
                    return None;
                }
                return Some((t, bv as f32, bw as f32));
            }
            let t = (u * a[kz] + v * b[kz] + w * c[kz]) * self.sz / det;
            let t = t as f32;
            if !(t >= self.tmin && t <= self.tmax) {
                return None;
            }
            Some((t, (v / det) as f32, (w / det) as f32))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::reference::RefRay;
    use super::*;
    use crate::workload::SplitMix64;

    type Answer = Option<(u32, u32, u32)>;

    fn bits(a: Option<(f32, f32, f32)>) -> Answer {
        a.map(|(t, u, v)| (t.to_bits(), u.to_bits(), v.to_bits()))
    }

    /// Both formulations on one ray and triangle; panics on the first difference. Returns the answer.
    fn compare(ray: &Ray, tri: &[Vec3; 3]) -> Answer {
        let want = RefRay::new(ray).and_then(|r| r.intersect_triangle(tri[0], tri[1], tri[2]));
        let want = bits(want);
        let prepared = PreparedRay::new(ray);
        assert_eq!(prepared.is_some(), RefRay::new(ray).is_some(), "{ray:?}");
        let Some(r) = prepared else {
            return want;
        };
        let scale = tri.iter().fold(0.0f32, |m, p| m.max(p.abs().max_element()));
        for (label, got) in [
            ("unbounded", r.intersect_triangle(tri[0], tri[1], tri[2])),
            (
                "bounded",
                r.far_bound(scale)
                    .intersect_triangle(tri[0], tri[1], tri[2]),
            ),
            (
                "loosely bounded",
                r.far_bound(scale * 4.0 + 1.0)
                    .intersect_triangle(tri[0], tri[1], tri[2]),
            ),
        ] {
            assert_eq!(
                bits(got),
                want,
                "{label}: ray {ray:?} triangle {tri:?}: got {got:?}"
            );
        }
        want
    }

    fn signed(rng: &mut SplitMix64) -> f32 {
        2.0 * rng.next_f32() - 1.0
    }

    fn point(rng: &mut SplitMix64) -> Vec3 {
        Vec3::new(signed(rng), signed(rng), signed(rng))
    }

    /// A log-uniform magnitude in `[10^lo, 10^hi]`.
    fn log_uniform(rng: &mut SplitMix64, lo: f32, hi: f32) -> f32 {
        // 10^x = 2^(x·log2 10), with 2^frac roughly 1 + frac: a log-uniform-ish spread is all we need.
        let e = (lo + (hi - lo) * rng.next_f32()) * core::f32::consts::LOG2_10;
        let k = crate::math::floor(e);
        let pow2 = f32::from_bits((((k as i32).clamp(-126, 127) + 127) as u32) << 23);
        pow2 * (1.0 + (e - k))
    }

    /// A triangle of one of several awkward kinds, before scaling.
    fn triangle(rng: &mut SplitMix64) -> [Vec3; 3] {
        let p0 = point(rng);
        match rng.below(8) {
            // Degenerate: collinear or repeated vertices.
            0 => {
                let p1 = point(rng);
                let k = [0.0, 0.5, 2.0, -1.0][rng.below(4)];
                [p0, p1, p0 + k * (p1 - p0)]
            }
            // Sliver: third vertex a tiny distance off the first edge.
            1 => {
                let p1 = point(rng);
                let off = point(rng) * log_uniform(rng, -7.0, -2.0);
                [p0, p1, 0.5 * (p0 + p1) + off]
            }
            // Axis-aligned (a shared coordinate).
            2 => {
                let (mut p1, mut p2) = (point(rng), point(rng));
                let a = rng.below(3);
                p1[a] = p0[a];
                p2[a] = p0[a];
                [p0, p1, p2]
            }
            // Small triangle.
            3 => {
                let s = log_uniform(rng, -4.0, -1.0);
                [p0, p0 + s * point(rng), p0 + s * point(rng)]
            }
            _ => [p0, point(rng), point(rng)],
        }
    }

    /// A point of the triangle's plane near a vertex, an edge, or inside, given by barycentrics that
    /// may be slightly negative.
    fn target(rng: &mut SplitMix64, tri: &[Vec3; 3]) -> Vec3 {
        let mut b = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
        match rng.below(6) {
            0 => {
                // A vertex, exactly or nearly.
                b = [0.0; 3];
                b[rng.below(3)] = 1.0;
            }
            1 | 2 => {
                // On or near an edge.
                b[rng.below(3)] = 0.0;
            }
            _ => {}
        }
        let sum = b[0] + b[1] + b[2];
        if sum > 0.0 {
            b = b.map(|x| x / sum);
        } else {
            b = [1.0, 0.0, 0.0];
        }
        if rng.below(2) == 0 {
            // Push one weight past zero by a log-uniform amount around the near-miss tolerance.
            let k = rng.below(3);
            let d = log_uniform(rng, -9.0, -2.0);
            b[k] -= d;
            b[(k + 1) % 3] += d;
        }
        if rng.below(4) == 0 {
            // Exactly representable midpoint of an edge.
            let k = rng.below(3);
            return 0.5 * (tri[k] + tri[(k + 1) % 3]);
        }
        b[0] * tri[0] + b[1] * tri[1] + b[2] * tri[2]
    }

    /// A direction with the awkward cases of the axis choice: exact ties between components,
    /// axis-parallel directions and −0.0 components.
    fn awkward_direction(rng: &mut SplitMix64, d: Vec3) -> Vec3 {
        match rng.below(10) {
            0 => {
                let mut e = Vec3::splat(if rng.below(2) == 0 { 0.0 } else { -0.0 });
                e[rng.below(3)] = if rng.below(2) == 0 { 1.0 } else { -1.0 };
                e
            }
            1 => {
                // Two components of equal magnitude.
                let mut e = d;
                let (i, j) = (rng.below(3), rng.below(3));
                e[i] = e[j].abs() * if rng.below(2) == 0 { 1.0 } else { -1.0 };
                e
            }
            2 => {
                Vec3::splat(1.0) * Vec3::new(1.0, -1.0, if rng.below(2) == 0 { 1.0 } else { -1.0 })
            }
            _ => d,
        }
    }

    #[test]
    fn specialised_test_matches_the_reference_bit_for_bit() {
        let mut rng = SplitMix64::new(0x7e57);
        let (mut hits, mut misses, mut windows) = (0usize, 0usize, 0usize);
        let scales: [(f32, Vec3); 7] = [
            (1.0, Vec3::ZERO),
            (1e-20, Vec3::ZERO),
            (1e-38, Vec3::ZERO),
            (1e30, Vec3::ZERO),
            (1e-2, Vec3::new(1e4, -2e4, 3e4)),
            (1.0, Vec3::new(3e6, 0.0, -1e6)),
            (1e5, Vec3::new(-1e3, 1e3, 0.5)),
        ];
        for case in 0..400_000 {
            let (scale, offset) = scales[case % scales.len()];
            let tri = triangle(&mut rng).map(|p| p * scale + offset);
            let aim = target(&mut rng, &tri);
            // Origin: from near to far, sometimes almost in the triangle's plane (grazing).
            let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
            let mut dir_out = point(&mut rng).normalize_or(Vec3::X);
            if rng.below(5) == 0 && n.length() > 0.0 && n.is_finite() {
                let n = n.normalize();
                dir_out = (dir_out - n * dir_out.dot(n)).normalize_or(Vec3::X)
                    + n * log_uniform(&mut rng, -7.0, -1.0);
            }
            let dist = scale * log_uniform(&mut rng, -3.0, 3.0);
            let org = aim + dir_out * dist;
            let dir = match rng.below(8) {
                0 => point(&mut rng),
                1 => awkward_direction(&mut rng, aim - org),
                _ => (aim - org) * log_uniform(&mut rng, -3.0, 3.0),
            };
            let ray = Ray::new(org, dir);
            let answer = compare(&ray, &tri);
            match answer {
                Some((t, _, _)) => {
                    hits += 1;
                    // The same ray with windows that start or end exactly at the hit, or just past it.
                    let t = f32::from_bits(t);
                    for (lo, hi) in [
                        (t, t),
                        (t, f32::INFINITY),
                        (0.0, t),
                        (f32::from_bits(t.to_bits() + 1), f32::INFINITY),
                        (-f32::INFINITY, t * 0.999_999_9),
                    ] {
                        compare(&Ray::segment(org, dir, lo, hi), &tri);
                        windows += 1;
                    }
                }
                None => misses += 1,
            }
        }
        // Plain random rays against random triangles: almost all misses, most of them far.
        for _ in 0..100_000 {
            let tri = [point(&mut rng), point(&mut rng), point(&mut rng)];
            let ray = Ray::new(point(&mut rng) * 2.0, point(&mut rng));
            compare(&ray, &tri);
        }
        assert!(
            hits > 50_000 && misses > 50_000 && windows > 0,
            "{hits} hits, {misses} misses"
        );
    }

    #[test]
    fn rays_that_cannot_hit_are_refused_alike() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        for ray in [
            Ray::new(Vec3::new(0.2, 0.2, 1.0), Vec3::ZERO),
            Ray::new(Vec3::new(f32::NAN, 0.2, 1.0), -Vec3::Z),
            Ray::new(
                Vec3::new(0.2, 0.2, 1.0),
                Vec3::new(0.0, f32::INFINITY, -1.0),
            ),
            Ray::segment(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 2.0, 1.0),
            Ray::segment(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, f32::NAN, 1.0),
            Ray::segment(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 1.0, 1.0),
            Ray::segment(
                Vec3::new(0.2, 0.2, 1.0),
                -Vec3::Z,
                f32::INFINITY,
                f32::INFINITY,
            ),
        ] {
            compare(&ray, &tri);
        }
        // Non-finite triangles through the public test.
        let r = Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z);
        for bad in [f32::NAN, f32::INFINITY, f32::MAX] {
            compare(&r, &[Vec3::ZERO, Vec3::new(bad, 0.0, 0.0), Vec3::Y]);
            compare(&r, &[Vec3::ZERO, Vec3::X, Vec3::new(0.0, bad, bad)]);
        }
    }
}
