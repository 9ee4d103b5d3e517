//! The one ray/triangle test every structure uses: exact for the f32 ray and the f32 triangle.
//!
//! Three stages, each deciding what it can prove and passing the rest on (docs/design.md, "Triangle
//! test"):
//! 1. [`filter`]: four triangles at a time in f32 (SSE2, NEON or plain lanes), rejecting the ones
//!    whose edge functions certainly have mixed signs, with an error bound that grows with the
//!    triangle's distance from the ray origin;
//! 2. the scalar test below: Woop, Benthin and Wald's edge functions in f64 with a certified error
//!    bound; it decides every edge whose value is farther from zero than the bound, and rounds `t`
//!    correctly whenever the bound allows;
//! 3. [`exact`]: integer arithmetic on the f32 inputs for the edges and `t` the bound leaves open.
//!
//! The answer is therefore the exact one: the line `org + t·dir` meets the closed triangle (a
//! triangle seen exactly edge-on is missed), `t` is the crossing's exact ray parameter rounded to
//! the nearest f32 (ties to even; `+0.0` for zero), and the hit counts when that `t` is finite and
//! in `[tmin, tmax]`. `u` and `v` are the barycentrics of the second and third vertex, within a few
//! f64 ulps before rounding to f32.

use glam::Vec3;

use crate::ray::{Aabb, Ray};

mod exact;
pub mod filter;
mod lanes;
pub mod packs;

pub use filter::Block4;

pub(crate) use exact::edge_cross_is_zero;
use exact::ExactTriangle;

/// Unit roundoff of f64 (2^-53).
const U64: f64 = f64::EPSILON / 2.0;
/// Relative slack added to every computed error bound so that the rounding of the bound's own
/// arithmetic (a handful of operations on non-negative values) can never make it too small.
const BOUND_SLACK: f64 = 1.0 + 1.0 / 262_144.0;
/// Added to the f64 edge bound: covers underflow in its own arithmetic (the edge functions of f32
/// inputs never come near f64's underflow range, docs/design.md).
const EDGE_BOUND_FLOOR64: f64 = 1e-300;

/// A ray with the per-ray constants of the triangle test computed once. Only
/// [`PreparedRay::new`] (and the queries' in-place form of it) makes one, and it refuses rays that
/// cannot hit anything.
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
    /// The shear in f32, for the four-wide filter.
    sx32: f32,
    sy32: f32,
    /// Whether the f32 filter may run: set when the ray is prepared for a scene (`prepare`) where
    /// no f32 value of the filter can overflow.
    filter_ok: bool,
    /// Per axis, at least the largest distance from the origin to the scene's box (`∞` when the
    /// scene is not known): the filter's per-ray bound on every triangle's edge functions.
    reach: Vec3,
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

/// An exact hit of one triangle: `t`, the barycentrics of the second and third vertex, and whether
/// the ray meets the triangle's front face (the side from which its vertices appear
/// counter-clockwise: `d·((v1 − v0) × (v2 − v0)) < 0`, decided exactly).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct TriHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub front: bool,
}

/// What a query asks of a hit beyond being one: masks, culling, filters. Asked for every exact hit
/// before it competes for the closest (so once per candidate, not per triangle test).
pub(crate) trait Accept {
    /// True when the hit of triangle `prim` counts.
    fn accept(&self, prim: u32, hit: &TriHit) -> bool;
}

/// The shared triangle test for one prepared ray.
pub(crate) trait TriangleTest: Copy {
    /// The ray.
    fn ray(&self) -> &PreparedRay;
    /// Exactly [`PreparedRay::intersect_triangle`] on `tri` (finite coordinates), with the facing.
    fn test(&self, tri: &[Vec3; 3]) -> Option<TriHit>;
    /// [`TriangleTest::test`] on the triangle in lane `lane` of `block` (`lane & 3`), read from the
    /// block itself: a copy of it made by the caller would be stored a float at a time and read
    /// back in wider loads, which the processor cannot forward from the stores (a stall on every
    /// exact test, measured).
    fn test_lane(&self, block: &Block4, lane: usize) -> Option<TriHit>;
    /// Whether the query counts this hit of triangle `prim` (always, for a plain query).
    fn accept(&self, prim: u32, hit: &TriHit) -> bool;
    /// The lanes of `block` that [`TriangleTest::test`] might hit (bit `k` for lane `k`): every lane
    /// it would hit is set; most lanes it would miss are clear.
    fn survivors(&self, block: &Block4) -> u32;
    /// Whether [`TriangleTest::survivors_pair`] filters two blocks in one pass (lists are then
    /// tested two blocks at a time; otherwise one at a time, which keeps one filter per walk).
    const PAIRS: bool = false;
    /// [`TriangleTest::survivors`] of two blocks (bits 0..4 for `a`, 4..8 for `b`).
    #[inline(always)]
    fn survivors_pair(&self, a: &Block4, b: &Block4) -> u32 {
        self.survivors(a) | self.survivors(b) << 4
    }
    /// The same test with its axes chosen at run time.
    fn any_axes(&self) -> AnyKernel<'_>;
}

/// The test specialised for `kz` (the dominant axis of the direction) and `swap` (whether `kx` and
/// `ky` trade places because `dir[kz] < 0`), with the query's conditions on hits (none for a plain
/// query).
#[derive(Clone, Copy)]
pub(crate) struct Kernel<'a, const KZ: usize, const SWAP: bool>(
    &'a PreparedRay,
    Option<&'a dyn Accept>,
    filter::FilterRay<lanes::F4>,
);

impl<'a, const KZ: usize, const SWAP: bool> Kernel<'a, KZ, SWAP> {
    #[inline(always)]
    fn new(ray: &'a PreparedRay, accept: Option<&'a dyn Accept>) -> Self {
        let lanes = filter::FilterRay::new::<KZ, SWAP>(ray);
        Kernel(ray, accept, lanes)
    }
}

impl<const KZ: usize, const SWAP: bool> TriangleTest for Kernel<'_, KZ, SWAP> {
    #[inline(always)]
    fn ray(&self) -> &PreparedRay {
        self.0
    }

    // Out of line: it runs only for the filter's survivors (about one per ray), and one copy per
    // kernel instead of one per walk keeps the library small.
    #[inline(never)]
    fn test(&self, tri: &[Vec3; 3]) -> Option<TriHit> {
        self.0.test_axes::<KZ, SWAP>(*tri)
    }

    #[inline(never)]
    fn test_lane(&self, block: &Block4, lane: usize) -> Option<TriHit> {
        self.0.test_axes::<KZ, SWAP>(block.get(lane))
    }

    #[inline(always)]
    fn accept(&self, prim: u32, hit: &TriHit) -> bool {
        self.1.map_or(true, |a| a.accept(prim, hit))
    }

    #[inline(always)]
    fn survivors(&self, block: &Block4) -> u32 {
        if !self.0.filter_ok {
            return 0b1111;
        }
        filter::survivors::<lanes::F4, KZ, SWAP>(&self.2, block)
    }

    // The filter's values are recomputed rather than copied, so that the walks' loops keep them
    // in registers (a copy on a path out of the loop made the grid's loop keep them in memory).
    #[inline(always)]
    fn any_axes(&self) -> AnyKernel<'_> {
        let ray = self.0;
        let lanes = filter::FilterRay::new::<KZ, SWAP>(ray);
        AnyKernel(ray, self.1, lanes)
    }
}

/// A [`Kernel`] that filters two blocks at a time in eight AVX lanes (the same answer as two calls
/// of [`Kernel::survivors`]); made only inside [`PreparedRay::dispatch_avx`], which is compiled with
/// AVX and runs only where the processor has it.
#[cfg(all(target_arch = "x86_64", feature = "avx"))]
#[derive(Clone, Copy)]
pub(crate) struct KernelAvx<'a, const KZ: usize, const SWAP: bool>(
    Kernel<'a, KZ, SWAP>,
    filter::FilterRay<lanes::avx::Avx>,
);

#[cfg(all(target_arch = "x86_64", feature = "avx"))]
impl<const KZ: usize, const SWAP: bool> TriangleTest for KernelAvx<'_, KZ, SWAP> {
    const PAIRS: bool = true;
    #[inline(always)]
    fn ray(&self) -> &PreparedRay {
        self.0.ray()
    }
    #[inline(always)]
    fn test(&self, tri: &[Vec3; 3]) -> Option<TriHit> {
        self.0.test(tri)
    }
    #[inline(always)]
    fn test_lane(&self, block: &Block4, lane: usize) -> Option<TriHit> {
        self.0.test_lane(block, lane)
    }
    #[inline(always)]
    fn accept(&self, prim: u32, hit: &TriHit) -> bool {
        self.0.accept(prim, hit)
    }
    #[inline(always)]
    fn survivors(&self, block: &Block4) -> u32 {
        self.0.survivors(block)
    }
    #[inline(always)]
    fn survivors_pair(&self, a: &Block4, b: &Block4) -> u32 {
        // As `Kernel::survivors`: every lane survives where the filter may not run.
        if !self.ray().filter_ok {
            return 0xff;
        }
        filter::survivors_pair::<KZ, SWAP>(&self.1, a, b)
    }
    #[inline(always)]
    fn any_axes(&self) -> AnyKernel<'_> {
        self.0.any_axes()
    }
}

/// A [`Kernel`] whose axes are chosen per call from the ray's (a branch per call), for walks too
/// rare to be worth a copy per kernel: one copy serves the six.
#[derive(Clone, Copy)]
pub(crate) struct AnyKernel<'a>(
    &'a PreparedRay,
    Option<&'a dyn Accept>,
    filter::FilterRay<lanes::F4>,
);

/// `$body!(KZ, SWAP)` for the ray's axes: the one mapping from `PreparedRay::axes` to a kernel.
macro_rules! with_axes {
    ($ray:expr, $body:ident) => {
        match $ray.axes {
            0 => $body!(0, false),
            1 => $body!(0, true),
            2 => $body!(1, false),
            3 => $body!(1, true),
            4 => $body!(2, false),
            _ => $body!(2, true),
        }
    };
}

impl TriangleTest for AnyKernel<'_> {
    #[inline(always)]
    fn ray(&self) -> &PreparedRay {
        self.0
    }

    // The kernels' own out-of-line tests, not copies of them.
    #[inline(never)]
    fn test(&self, tri: &[Vec3; 3]) -> Option<TriHit> {
        macro_rules! test {
            ($kz:expr, $swap:expr) => {
                Kernel::<$kz, $swap>(self.0, self.1, self.2).test(tri)
            };
        }
        with_axes!(self.0, test)
    }

    #[inline(never)]
    fn test_lane(&self, block: &Block4, lane: usize) -> Option<TriHit> {
        macro_rules! test_lane {
            ($kz:expr, $swap:expr) => {
                Kernel::<$kz, $swap>(self.0, self.1, self.2).test_lane(block, lane)
            };
        }
        with_axes!(self.0, test_lane)
    }

    #[inline(always)]
    fn accept(&self, prim: u32, hit: &TriHit) -> bool {
        self.1.map_or(true, |a| a.accept(prim, hit))
    }

    // The kernels' own filters (inlined here), so the unfiltered case is decided in one place.
    #[inline(never)]
    fn survivors(&self, block: &Block4) -> u32 {
        macro_rules! survivors {
            ($kz:expr, $swap:expr) => {
                Kernel::<$kz, $swap>(self.0, self.1, self.2).survivors(block)
            };
        }
        with_axes!(self.0, survivors)
    }

    #[inline(always)]
    fn any_axes(&self) -> AnyKernel<'_> {
        *self
    }
}

/// One triangle, for [`PreparedRay::intersect_triangle`].
struct Single<'a>(&'a [Vec3; 3]);

impl TriangleLoop for Single<'_> {
    type Output = Option<TriHit>;
    #[inline(always)]
    fn run<T: TriangleTest>(self, test: T) -> Self::Output {
        test.test(self.0)
    }
}

/// The larger of two magnitudes: `f64::max` when neither is NaN (and magnitudes have no signed
/// zeros), without `max`'s NaN handling.
#[inline(always)]
fn max2(a: f64, b: f64) -> f64 {
    if a > b {
        a
    } else {
        b
    }
}

/// The largest magnitude of six values, as a tree of maxima (depth 3, not a chain of 6: the bound
/// that needs it is on the hit path's longest chain). `max` is exact, so the order never changes
/// the value.
#[inline(always)]
fn max_abs6(x: [f64; 6]) -> f64 {
    let x = x.map(f64::abs);
    max2(max2(max2(x[0], x[1]), max2(x[2], x[3])), max2(x[4], x[5]))
}

/// The largest magnitude of three values.
#[inline(always)]
fn max_abs3(x: [f64; 3]) -> f64 {
    max2(max2(x[0].abs(), x[1].abs()), x[2].abs())
}

/// `U64·σ` and `4·U64·σ` (σ = `BOUND_SLACK`): the coefficients of the derived bound
/// `σ·(S·(4u·S + 4e) + 2e²)` with `e = u·(2S + 4Z)`, each factor rounded up ([`derived_bound`]).
const K1: f64 = U64 * BOUND_SLACK;
const K2: f64 = 4.0 * U64 * BOUND_SLACK;
/// Relative margin of [`edge_bound`]'s coefficients over the expanded derivation's: covers the
/// rounding of both forms (at most ten roundings each, `2^-52 ≪ 2^-30`).
const EXPANDED_MARGIN: f64 = 1.0 + 1.0 / 1_073_741_824.0;
/// The derived bound multiplied out: `σ·((K2 + 8K1 + 8K1²)·S² + (16K1 + 32K1²)·S·Z + 32K1²·Z²)`,
/// each coefficient with the margin.
const BOUND_SS: f64 = BOUND_SLACK * (K2 + 8.0 * K1 + 8.0 * K1 * K1) * EXPANDED_MARGIN;
const BOUND_SZ: f64 = BOUND_SLACK * (16.0 * K1 + 32.0 * K1 * K1) * EXPANDED_MARGIN;
const BOUND_ZZ: f64 = BOUND_SLACK * (32.0 * K1 * K1) * EXPANDED_MARGIN;

/// The bound on the error of the f64 edge functions of a triangle whose largest sheared `|x|, |y|`
/// is `s` and largest translated `|z|` is `zmax` ([`PreparedRay::test_axes`] derives it): the
/// derivation's polynomial multiplied out, four dependent operations after `s` instead of eight
/// (the hit's longest chain runs through it, as `finish`'s slack needs it).
///
/// It is at least the derivation's factored form computed in f64 ([`derived_bound`], the bound
/// until stop 27): that form is the polynomial `P` of the constants above with at most ten
/// roundings of non-negative values, so at most `(1 + 2^-53)^10·P` plus its floor `F` (1e-300)
/// rounded once, plus what underflow adds (at most 2^-1075 an operation, and only to products so
/// small that later factors cannot enlarge them: under 1e-322 in all); this one is `P·(1 + 2^-30)`
/// with at most seven roundings on any term (four at run time, three in its constant), so at least
/// `(1 − 2^-53)^7·(1 + 2^-30)·P`, plus `2F` rounded twice, less the same underflow allowance —
/// larger, as `(1 − 2^-53)^7·(1 + 2^-30) > (1 + 2^-53)^10` (the margin would cover millions)
/// and `2F·(1 − 2^-53)² − 1e-322 > F·(1 + 2^-53) + 1e-322`. Nothing overflows (`S, Z < 2^131` for
/// f32 inputs). The tests check it on values of every magnitude.
#[inline(always)]
fn edge_bound(s: f64, zmax: f64) -> f64 {
    s * (BOUND_SS * s + BOUND_SZ * zmax) + (BOUND_ZZ * (zmax * zmax) + 2.0 * EDGE_BOUND_FLOOR64)
}

/// The derivation's bound in its factored form, `S·(4u·S + 4e) + 2e²` with `e = u·(2S + 4Z)`,
/// each factor rounded up, and the floor: what [`edge_bound`] must never be below.
#[cfg(test)]
fn derived_bound(s: f64, zmax: f64) -> f64 {
    let e = (s + s + 4.0 * zmax) * K1;
    (s * (K2 * s + 4.0 * e) + 2.0 * (e * e)) * BOUND_SLACK + EDGE_BOUND_FLOOR64
}

/// What the f64 stage could not settle about `t`: the exact stage rounds it.
struct Undecided;

/// How often the exact stage ran (tests check that their pairs reach it).
#[cfg(test)]
static COLD_EDGES: core::sync::atomic::AtomicUsize = core::sync::atomic::AtomicUsize::new(0);
#[cfg(test)]
static COLD_T: core::sync::atomic::AtomicUsize = core::sync::atomic::AtomicUsize::new(0);

impl PreparedRay {
    /// Prepares `ray`, or `None` when it can hit nothing: a NaN or infinite component, a zero
    /// direction, a NaN bound, or `tmin > tmax`.
    #[inline]
    pub fn new(ray: &Ray) -> Option<PreparedRay> {
        // An unbounded scene leaves the filter off (the queries turn it on for their scene).
        let everywhere = Aabb {
            min: Vec3::NEG_INFINITY,
            max: Vec3::INFINITY,
        };
        Self::prepare(ray, &everywhere)
    }

    /// [`PreparedRay::new`] with the filter allowed for triangles inside `scene` (see `for_scene`),
    /// always inline: the queries' one entry ([`crate::accel::run_query`]) then builds the ray
    /// once, in place, instead of returning it through memory and copying it.
    ///
    /// The direction is read in the rotated order `(d[kz], d[kz+1], d[kz+2])` chosen once, not
    /// indexed by run-time axes for each constant (which compiled to a chain of selects per read).
    #[inline(always)]
    pub(crate) fn prepare(ray: &Ray, scene: &Aabb) -> Option<PreparedRay> {
        let (o, d) = (ray.org, ray.dir);
        // `x − x` is +0 for a finite `x` and NaN for ±∞ and NaN, so the sum is 0 exactly when all
        // six components are finite. NaN bounds fail `<=`; an infinite tmin is allowed only as an
        // empty window.
        #[allow(clippy::eq_op)] // `x − x` on purpose: it is the finiteness test.
        let finite = (o - o) + (d - d);
        if !((finite.x + finite.y + finite.z == 0.0) & (ray.tmin <= ray.tmax)) {
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
        // `d[kz]` has the largest magnitude, so it is zero exactly when the direction is.
        let (dz, d1, d2) = match kz {
            0 => (d.x, d.y, d.z),
            1 => (d.y, d.z, d.x),
            _ => (d.z, d.x, d.y),
        };
        if dz == 0.0 {
            return None;
        }
        // Keep the winding so that the sign of the edge functions does not depend on the ray's
        // sense: `kx, ky = kz + 2, kz + 1` when `d[kz] < 0`, `kz + 1, kz + 2` otherwise.
        let swap = dz < 0.0;
        let (dx, dy) = if swap { (d2, d1) } else { (d1, d2) };
        Some(PreparedRay {
            org: o,
            dir: d,
            tmin: ray.tmin,
            tmax: ray.tmax,
            axes: (2 * kz + usize::from(swap)) as u8,
            org64: [f64::from(o.x), f64::from(o.y), f64::from(o.z)],
            sx: f64::from(dx) / f64::from(dz),
            sy: f64::from(dy) / f64::from(dz),
            sz: 1.0 / f64::from(dz),
            sx32: dx / dz,
            sy32: dy / dz,
            filter_ok: Self::filter_may_run(o, scene.min.abs().max(scene.max.abs()).max_element()),
            reach: (scene.min - o).abs().max((scene.max - o).abs()),
        })
    }

    /// Tells the test that every triangle it will be given has coordinates of magnitude at most
    /// `scale`, which lets the four-wide f32 filter run when no value it computes can overflow
    /// (`scale + |org|` below 2^60). Answers never depend on it: the filter only rejects what the
    /// exact test rejects.
    #[cfg(test)]
    pub(crate) fn for_scene(mut self, scale: f32) -> Self {
        self.filter_ok = Self::filter_may_run(self.org, scale);
        // The box `[−scale, scale]³`, seen from the origin (rounded up).
        self.reach = (self.org.abs() + Vec3::splat(scale)) * (1.0 + f32::EPSILON);
        self
    }

    /// Whether no f32 value of the filter can overflow for coordinates of magnitude at most
    /// `scale` and the origin `org`: `scale + |org|` below 2^60 (false for NaN or ∞).
    #[inline(always)]
    fn filter_may_run(org: Vec3, scale: f32) -> bool {
        let reach = f64::from(scale) + f64::from(org.abs().max_element());
        reach < 1.152_921_504_606_847e18
    }

    /// Runs `lp` with the triangle test specialised for this ray's axes.
    #[inline(always)]
    pub(crate) fn dispatch<L: TriangleLoop>(&self, lp: L) -> L::Output {
        self.dispatch_accepting(None, lp)
    }

    /// [`PreparedRay::dispatch`] for a query whose hits must also pass `accept`.
    #[inline(always)]
    pub(crate) fn dispatch_accepting<L: TriangleLoop>(
        &self,
        accept: Option<&dyn Accept>,
        lp: L,
    ) -> L::Output {
        #[cfg(all(target_arch = "x86_64", feature = "avx"))]
        if lanes::avx::available() {
            // SAFETY: the processor runs AVX (just asked).
            return unsafe { self.dispatch_avx(accept, lp) };
        }
        self.dispatch_plain(accept, lp)
    }

    /// [`PreparedRay::dispatch_accepting`] with the four-lane kernels, whatever the processor (the
    /// only path without the `avx` feature, on other architectures, or on a processor without AVX).
    #[inline(always)]
    pub(crate) fn dispatch_plain<L: TriangleLoop>(
        &self,
        accept: Option<&dyn Accept>,
        lp: L,
    ) -> L::Output {
        macro_rules! run {
            ($kz:expr, $swap:expr) => {
                lp.run(Kernel::<$kz, $swap>::new(self, accept))
            };
        }
        with_axes!(self, run)
    }

    /// [`PreparedRay::dispatch_accepting`] compiled with AVX: the whole walk is inlined here, so
    /// its kernels ([`KernelAvx`]) filter blocks in pairs in eight lanes, and every other
    /// operation is the one the plain walk performs (VEX-encoded, the same IEEE results).
    ///
    /// # Safety
    /// The processor must run AVX ([`lanes::avx::available`]).
    #[cfg(all(target_arch = "x86_64", feature = "avx"))]
    #[target_feature(enable = "avx")]
    unsafe fn dispatch_avx<L: TriangleLoop>(
        &self,
        accept: Option<&dyn Accept>,
        lp: L,
    ) -> L::Output {
        macro_rules! run {
            ($kz:expr, $swap:expr) => {
                lp.run(KernelAvx::<$kz, $swap>(
                    Kernel::<$kz, $swap>::new(self, accept),
                    filter::FilterRay::new::<$kz, $swap>(self),
                ))
            };
        }
        with_axes!(self, run)
    }

    /// The exact test against triangle `(p0, p1, p2)`: `Some((t, u, v))` when the line meets the
    /// closed triangle and the crossing's `t`, rounded to the nearest f32, is finite and in
    /// `[tmin, tmax]` (module docs). Rays through a shared edge or vertex of a closed mesh hit at
    /// least one of the triangles there; a triangle seen exactly edge-on, or degenerate, is missed;
    /// a non-finite coordinate is a miss.
    #[inline]
    pub fn intersect_triangle(&self, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<(f32, f32, f32)> {
        if !(p0.is_finite() && p1.is_finite() && p2.is_finite()) {
            return None;
        }
        self.dispatch(Single(&[p0, p1, p2]))
            .map(|h| (h.t, h.u, h.v))
    }

    /// The test with the axes fixed at compile time.
    ///
    /// Edge functions (Woop, Benthin, Wald 2013): translate to the origin (`p − o` in f64, exact
    /// for most inputs and within one rounding always), shear so the ray runs along `+z`
    /// (`x = (p[kx] − o[kx]) − sx·(p[kz] − o[kz])`, likewise `y`), then `U = cx·by − cy·bx`,
    /// `V = ax·cy − ay·cx`, `W = bx·ay − by·ax`. Each equals `d·(c×b)/|d_kz|` (and so on) for the
    /// exact translated vertices, up to the error bound `bound`, derived in docs/design.md:
    /// with `S` the largest sheared `|x|, |y|` and `Z` the largest translated `|z|` of the three
    /// vertices, every sheared coordinate is within `e = u·(2S + 4Z)` of its exact value and every
    /// edge function within `S·(4u·S + 4e) + 2e²` (`u = 2^-53`, each factor rounded up).
    ///
    /// `tri` is taken by value so that it stays in registers: only the cold stages, which take it
    /// by value too, store it (at their call).
    #[inline(always)]
    fn test_axes<const KZ: usize, const SWAP: bool>(&self, tri: [Vec3; 3]) -> Option<TriHit> {
        let kx = if SWAP { (KZ + 2) % 3 } else { (KZ + 1) % 3 };
        let ky = if SWAP { (KZ + 1) % 3 } else { (KZ + 2) % 3 };
        let o = &self.org64;
        let rel = |p: &Vec3| {
            let p = p.to_array();
            let z = f64::from(p[KZ]) - o[KZ];
            let x = (f64::from(p[kx]) - o[kx]) - self.sx * z;
            let y = (f64::from(p[ky]) - o[ky]) - self.sy * z;
            (x, y, z)
        };
        let (ax, ay, az) = rel(&tri[0]);
        let (bx, by, bz) = rel(&tri[1]);
        let (cx, cy, cz) = rel(&tri[2]);
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let s = max_abs6([ax, ay, bx, by, cx, cy]);
        let zmax = max_abs3([az, bz, cz]);
        let bound = edge_bound(s, zmax);
        // `|` instead of `||`: the same truth value (no side effects), fewer branches.
        let pos = (u > bound) | (v > bound) | (w > bound);
        let neg = (u < -bound) | (v < -bound) | (w < -bound);
        if pos & neg {
            return None;
        }
        let z = [az, bz, cz];
        let decided = (u.abs() > bound) & (v.abs() > bound) & (w.abs() > bound);
        if !decided {
            return self.decide_exactly(tri, [u, v, w], bound, z, zmax);
        }
        // One sign, and `U + V + W > 0` exactly when the ray meets the front face.
        let front = u > 0.0;
        match self.finish([u, v, w], bound, z, zmax, front) {
            Ok(hit) => hit,
            Err(Undecided) => self.round_exactly(tri, front),
        }
    }

    /// `t`, the window and the barycentrics from edge functions of one sign (or zero, not all),
    /// each within `err` of its exact value: the f64 stage's `t` when its error bound shows which
    /// f32 it rounds to, [`Undecided`] otherwise.
    ///
    /// With `r = 6·err/|det|` (the relative error of the determinant) at most 1/4, the computed
    /// `t` is within `2·(|t| + Z/|d_kz|)·(8u + 2r)` of the exact crossing (docs/design.md); when
    /// both ends of that interval round to the same f32, so does the exact `t`.
    #[inline(always)]
    fn finish(
        &self,
        edges: [f64; 3],
        err: f64,
        z: [f64; 3],
        zmax: f64,
        front: bool,
    ) -> Result<Option<TriHit>, Undecided> {
        let [u, v, w] = edges;
        let det = u + v + w;
        let inv = 1.0 / det;
        let t64 = (u * z[0] + v * z[1] + w * z[2]) * self.sz * inv;
        let slack = 2.0
            * (8.0 * U64 * det.abs() + 12.0 * err)
            * (t64.abs() + zmax * self.sz.abs())
            * inv.abs()
            * BOUND_SLACK;
        let (lo, hi) = ((t64 - slack) as f32, (t64 + slack) as f32);
        // NaN or infinite slack fails `<=`; a tiny determinant fails the first test.
        if !((48.0 * err <= det.abs()) & (slack <= f64::MAX)) {
            return Err(Undecided);
        }
        // Rounding is monotone: when the whole interval rounds outside the window, so does the
        // exact `t` (a bounce ray's own triangle, at t ≈ 0 below its tmin, ends here).
        if hi < self.tmin || lo > self.tmax {
            return Ok(None);
        }
        if lo.to_bits() != hi.to_bits() {
            return Err(Undecided);
        }
        let t = if lo == 0.0 { 0.0 } else { lo };
        if !(t >= self.tmin && t <= self.tmax && t.is_finite()) {
            return Ok(None);
        }
        Ok(Some(TriHit {
            t,
            u: (v * inv) as f32,
            v: (w * inv) as f32,
            front,
        }))
    }

    /// The edges the f64 bound left open, decided in exact integers; then `t` as in
    /// [`PreparedRay::finish`]. Rare (an edge within ~1e-15 of the ray), so kept out of line.
    #[cold]
    #[inline(never)]
    fn decide_exactly(
        &self,
        tri: [Vec3; 3],
        mut edges: [f64; 3],
        bound: f64,
        z: [f64; 3],
        zmax: f64,
    ) -> Option<TriHit> {
        #[cfg(test)]
        COLD_EDGES.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
        let exact = ExactTriangle::new(self.org, self.dir, &tri);
        let mut signs = [0i8; 3];
        for (k, (value, sign)) in edges.iter_mut().zip(signs.iter_mut()).enumerate() {
            if value.abs() > bound {
                *sign = if *value > 0.0 { 1 } else { -1 };
            } else {
                *sign = exact.edge_sign(k);
                // A value of the wrong sign (or an exact zero) is replaced by zero: still within
                // twice the bound of the exact value, and no longer of the wrong sign.
                if (*value > 0.0 && *sign <= 0) || (*value < 0.0 && *sign >= 0) || *sign == 0 {
                    *value = 0.0;
                }
            }
        }
        let pos = signs.iter().any(|&s| s > 0);
        let neg = signs.iter().any(|&s| s < 0);
        if pos == neg {
            // Mixed signs: the line passes outside. All zero: the triangle is seen edge-on.
            return None;
        }
        match self.finish(edges, 2.0 * bound, z, zmax, pos) {
            Ok(hit) => hit,
            Err(Undecided) => self.finish_exactly(&exact, pos),
        }
    }

    /// [`PreparedRay::finish_exactly`] on `tri`.
    #[cold]
    #[inline(never)]
    fn round_exactly(&self, tri: [Vec3; 3], front: bool) -> Option<TriHit> {
        self.finish_exactly(&ExactTriangle::new(self.org, self.dir, &tri), front)
    }

    /// `t` rounded exactly, then the window, for a line known to meet the triangle.
    #[cold]
    #[inline(never)]
    fn finish_exactly(&self, exact: &ExactTriangle, front: bool) -> Option<TriHit> {
        #[cfg(test)]
        COLD_T.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
        let t = exact.rounded_t()?;
        if !(t >= self.tmin && t <= self.tmax && t.is_finite()) {
            return None;
        }
        let (u, v) = exact.barycentrics();
        Some(TriHit { t, u, v, front })
    }
}

#[cfg(test)]
pub(crate) mod testgen;
#[cfg(test)]
mod tests;
