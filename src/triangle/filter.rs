//! The four-wide f32 filter: rejects triangles whose edge functions certainly have mixed signs,
//! and those whose crossing is certainly outside the ray's window.
//!
//! It computes the same edge functions as the f64 stage, in f32 and four triangles at a time, and a
//! bound on their error that holds for any triangle and ray (derived in docs/design.md): with
//! `u = 2^-24`, `S` the largest sheared `|x|, |y|` and `Z` the largest translated `|z|` of a
//! triangle's vertices, each sheared coordinate is within `e = u·(2S + 4Z) + 2^-148` of its exact
//! value and each edge function within `E = S·(4u·S + 4e) + 2e² + 2^-145`. `S` is the lateral
//! reach of the triangle around the ray and `Z` its distance along it, so `E` grows with the
//! distance but stays small against a triangle the ray misses by more than a few millionths of that
//! distance. A lane is rejected only when one edge function is above `E` and another below `−E`: then
//! the exact ones have mixed signs, and the exact test misses.
//!
//! A block is first checked against the scene's bound: `E` for the largest `S` and `Z` any triangle
//! of the scene can have for this ray (from the distances of the origin to the scene's box), made
//! once per query. It is at least every lane's own `E`, so what it rejects the lanes' bounds reject
//! too; most blocks are settled by it, and only the others compute their lanes' `S`, `Z` and `E`.
//!
//! The bound needs every value to stay finite; preparing the ray for the scene turns the filter
//! off (every lane survives) when coordinates or the origin reach 2^60. Below that no real triangle
//! gives a NaN, so a lane whose edge function is NaN is an unused one (NaN coordinates, the padding
//! of block-aligned lists) and is rejected too.
//!
//! # The window check
//!
//! A lane left after the edge test goes on only if its crossing may be in the window: from the
//! same edge functions, `y = t·d_kz = (U·a_z + V·b_z + W·c_z)/(U + V + W)` with error bounds for the
//! numerator and the determinant from `E`, compared with the window's ends along `kz` moved out by
//! more than one float of `t` (so a crossing certainly beyond one rounds to a `t` beyond the
//! window, which the exact test misses). It spares the f64 stage a bounce ray's own triangle (about half
//! of its calls in a path tracer's rays), triangles behind the origin and beyond `tmax`. Derived
//! in docs/design.md ("The window check"); every constant is zero, normal or infinite, as
//! subnormal operands cost microcode assists.

use glam::{Mat4, Vec3, Vec4};

use super::lanes::Lanes;
use super::PreparedRay;

/// Four triangles side by side (structure of arrays): `v[3·i + k][lane]` is coordinate `k` of
/// vertex `i` of the triangle in `lane`, in the order `a.x, a.y, a.z, b.x, …, c.z`. 144 bytes.
/// An unused lane holds NaN, which the filter rejects.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Block4 {
    /// The nine coordinates of four triangles.
    pub v: [[f32; 4]; 9],
}

impl Default for Block4 {
    /// Four unused lanes.
    fn default() -> Self {
        Block4 {
            v: [[f32::NAN; 4]; 9],
        }
    }
}

impl Block4 {
    /// Puts triangle `tri` in lane `lane` (0..4; other values are ignored).
    #[inline(always)]
    pub fn set(&mut self, lane: usize, tri: &[Vec3; 3]) {
        for (i, p) in tri.iter().enumerate() {
            for (k, &x) in p.to_array().iter().enumerate() {
                if let Some(slot) = self.v[3 * i + k].get_mut(lane) {
                    *slot = x;
                }
            }
        }
    }

    /// The block of the triangles `tris[ids[lane]]`; a lane whose id is out of range (such as
    /// `Hit::INVALID_ID`) is unused (NaN).
    #[inline(always)]
    pub fn gather(tris: &[[Vec3; 3]], ids: [u32; 4]) -> Block4 {
        const UNUSED: [Vec3; 3] = [Vec3::NAN; 3];
        let t = ids.map(|id| tris.get(id as usize).unwrap_or(&UNUSED));
        // Each triangle's first eight coordinates as two rows of four (adjacent floats, so two
        // loads), turned into lanes by a 4×4 transposition each.
        let row = |t: &[Vec3; 3], half: usize| match half {
            0 => Vec4::new(t[0].x, t[0].y, t[0].z, t[1].x),
            _ => Vec4::new(t[1].y, t[1].z, t[2].x, t[2].y),
        };
        let quad = |half: usize| {
            Mat4::from_cols(
                row(t[0], half),
                row(t[1], half),
                row(t[2], half),
                row(t[3], half),
            )
            .transpose()
            .to_cols_array_2d()
        };
        let ([v0, v1, v2, v3], [v4, v5, v6, v7]) = (quad(0), quad(1));
        Block4 {
            v: [v0, v1, v2, v3, v4, v5, v6, v7, t.map(|t| t[2].z)],
        }
    }

    /// The triangle in lane `lane` (`lane & 3`).
    #[inline(always)]
    pub fn get(&self, lane: usize) -> [Vec3; 3] {
        let l = lane & 3;
        let c = |k: usize| self.v[k][l];
        [
            Vec3::new(c(0), c(1), c(2)),
            Vec3::new(c(3), c(4), c(5)),
            Vec3::new(c(6), c(7), c(8)),
        ]
    }
}

/// Unit roundoff of f32 (2^-24).
const U32: f32 = f32::EPSILON / 2.0;
/// Relative slack on the bound's factors, covering the rounding of its own arithmetic: at most ten
/// roundings of non-negative values on any term (the `e²` term: three in `e`, doubled, then the
/// product, the factor and two sums), and `(1 + 2^-18)·(1 − 2^-24)^10 > 1`.
const SLACK32: f32 = 1.0 + 1.0 / 262_144.0;
/// The coefficients of `e = u(2S + 4Z)` and `E = 4u·S² + 4·S·e + 2·e²`, each with the slack.
const E_S: f32 = 2.0 * U32 * SLACK32;
const E_Z: f32 = 4.0 * U32 * SLACK32;
const B_SS: f32 = 4.0 * U32 * SLACK32 * SLACK32;
const B_SE: f32 = 4.0 * SLACK32;
const B_EE: f32 = 2.0 * SLACK32;
/// At least 2^-148 (three subnormal units): what underflow can add to a sheared coordinate.
const COORD_FLOOR: f32 = 4.2e-45;
/// At least 2^-145 (21 subnormal units): what underflow can add to an edge function and to the
/// bound's arithmetic.
const EDGE_FLOOR: f32 = 3e-44;

/// A ray's filter constants in lanes, made once per query so that each block reads them instead of
/// broadcasting them again: the origin in the kernel's axis order (`kx, ky, kz`), the shear, and
/// the bound for the whole scene (`E` of the largest `S` and `Z` any triangle of the scene can
/// have for this ray, and its negative).
#[derive(Clone, Copy)]
pub(crate) struct FilterRay<L> {
    o: [L; 3],
    s: [L; 2],
    scene_bound: L,
    scene_low: L,
    /// The window of `y = t·d_kz` ([`window_along_kz`]).
    y_lo: L,
    y_hi: L,
    /// Whether the window check runs: not for a window `[≤ 0, ∞)`, where it could only drop
    /// crossings behind the origin, which the leaves a ray reaches rarely hold.
    check_window: bool,
}

/// The window `[lo, hi]` of `y = t·d_kz` (the crossing's distance along `kz`) that a hit can have:
/// `fl(τ·d_kz)` for each end `τ` of the ray's window (`d_kz < 0` swaps them), moved out by 2^-20
/// of itself and by `2^-100·max(|d_kz|, 1)`. That is more than the product's rounding (`u` of
/// it, or 2^-150 if it underflows) plus what keeps the end exclusive: a crossing beyond
/// `τ·d_kz ± (2^-23|τ·d_kz| + 2^-149|d_kz|)` is one float beyond `τ` or more, so its rounded `t`
/// is outside the window. Every value is zero, normal or infinite (an operation on a subnormal
/// costs a microcode assist, about 100 cycles on x86: a first version with subnormal floors made
/// every query 35–100 ns slower). An infinite end stays infinite, except for an empty window at
/// infinity (`tmin = tmax = ±∞`), whose moved end is `∞ − ∞`: NaN, which no comparison of the
/// check accepts, so it drops nothing (and the exact test hits nothing there).
#[inline(always)]
fn window_along_kz(tmin: f32, tmax: f32, dz: f32) -> (f32, f32) {
    let (a, b) = (tmin * dz, tmax * dz);
    let (lo, hi) = if dz < 0.0 { (b, a) } else { (a, b) };
    let floor = WINDOW_FLOOR * if dz.abs() > 1.0 { dz.abs() } else { 1.0 };
    (
        lo - (lo.abs() * WINDOW_MARGIN + floor),
        hi + (hi.abs() * WINDOW_MARGIN + floor),
    )
}

/// The window's relative margin along `kz` (2^-20).
const WINDOW_MARGIN: f32 = 1.0 / 1_048_576.0;
/// The window's absolute margin along `kz` for `|d_kz| ≤ 1` (2^-100).
const WINDOW_FLOOR: f32 = 7.888_609e-31;
/// 2^-126, the smallest normal f32: the absolute slack of a lane's `y`, far above what underflow
/// can take from it (a few units of 2^-149).
const Y_FLOOR: f32 = f32::MIN_POSITIVE;
/// 2^-80: the absolute slack of a lane's numerator `N` (before the division by `D`), far above
/// what underflow can take from it and from its bound (a few units of 2^-149), and far above
/// 2^-126 so that its quotient by `D` stays normal for `|D| < 2^46`. With 2^-126 here the
/// quotient was subnormal whenever `N` and its bound were zero and `|D| > 2.1`, which a bounce ray
/// from an axis-aligned floor meets on every coplanar triangle (the translated `z` all exactly
/// zero): a microcode assist of ~100 cycles each time (docs/performance.md, "Stop 29").
const N_FLOOR: f32 = 8.271_806e-25;

/// Relative slack of the per-ray `S` and `Z`. Not needed by the argument (see `FilterRay::new`:
/// rounding is monotone, so the per-ray values computed with the filter's own operations already
/// bound the lanes'); kept as insurance against a later change of either computation.
const SCENE_SLACK: f32 = 1.0 + 1.0 / 1_048_576.0;
/// Absolute slack of the per-ray `S` and `Z` (2^-140, far above an underflow's 2^-149), for the
/// same reason.
const SCENE_FLOOR: f32 = 7.2e-43;

impl<L: Lanes> FilterRay<L> {
    /// The constants of a ray from `org` with shear `sx, sy`, for the kernel of `KZ`, `SWAP`, for
    /// triangles inside a box whose farther face along each axis `a` is `reach[a]` from the origin
    /// (`reach[a] = max(|lo_a − o_a|, |hi_a − o_a|)`, computed in f32).
    ///
    /// The scene's bound is at least every lane's, because every step rounds monotonically: a
    /// vertex `p` in `[lo, hi]` has `fl(p_a − o_a)` between `fl(lo_a − o_a)` and `fl(hi_a − o_a)`,
    /// so `|ẑ| ≤ reach[kz]`; then `|fl(ŝ·ẑ)| ≤ fl(|ŝ|·reach[kz])` and
    /// `|x̂| ≤ fl(reach[kx] + fl(|ŝ|·reach[kz]))`, the operations below (underflow included: a
    /// rounding to a subnormal is monotone too); and `bound` is monotone in `S` and `Z`. The slack
    /// on top is insurance, not part of the argument.
    ///
    /// The window's ends along `kz` come from [`window_along_kz`]; the check is off for a window
    /// `[≤ 0, ∞)`.
    #[inline(always)]
    pub(crate) fn new<const KZ: usize, const SWAP: bool>(ray: &PreparedRay) -> Self {
        let (org, sx, sy, reach) = (ray.org, ray.sx32, ray.sy32, ray.reach);
        let (y_lo, y_hi) = window_along_kz(ray.tmin, ray.tmax, ray.dir.to_array()[KZ]);
        let [kx, ky] = axes::<KZ, SWAP>();
        let (o, r) = (org.to_array(), reach.to_array());
        let z = r[KZ] * SCENE_SLACK + SCENE_FLOOR;
        let s =
            (r[kx] + sx.abs() * r[KZ]).max(r[ky] + sy.abs() * r[KZ]) * SCENE_SLACK + SCENE_FLOOR;
        // A NaN (an infinite reach times a zero shear) would reject everything: no bound instead.
        let finite_or_inf = |x: f32| if x <= f32::MAX { x } else { f32::INFINITY };
        let scene_bound = bound(L::splat(finite_or_inf(s)), L::splat(finite_or_inf(z)));
        FilterRay {
            o: [L::splat(o[kx]), L::splat(o[ky]), L::splat(o[KZ])],
            s: [L::splat(sx), L::splat(sy)],
            scene_bound,
            scene_low: scene_bound.neg(),
            y_lo: L::splat(y_lo),
            y_hi: L::splat(y_hi),
            check_window: !(ray.tmin <= 0.0 && ray.tmax == f32::INFINITY),
        }
    }
}

/// The sheared axes `kx, ky` of the kernel for `KZ`, `SWAP`.
#[inline(always)]
const fn axes<const KZ: usize, const SWAP: bool>() -> [usize; 2] {
    if SWAP {
        [(KZ + 2) % 3, (KZ + 1) % 3]
    } else {
        [(KZ + 1) % 3, (KZ + 2) % 3]
    }
}

/// The lanes of `block` the exact test might hit for `ray` (made by `FilterRay::new` with the same
/// `KZ`, `SWAP`) (bit `k` for lane `k`, of four).
#[inline(always)]
pub(crate) fn survivors<L: Lanes, const KZ: usize, const SWAP: bool>(
    ray: &FilterRay<L>,
    block: &Block4,
) -> u32 {
    survivors_of::<L, KZ, SWAP>(ray, &OneBlock(block), 0b1111)
}

/// [`survivors`] of two blocks at once in eight AVX lanes (bits 0..4 for `a`, 4..8 for `b`): the
/// same operations lane by lane, so the same answer as two calls.
#[cfg(all(target_arch = "x86_64", feature = "avx"))]
#[inline(always)]
pub(crate) fn survivors_pair<const KZ: usize, const SWAP: bool>(
    ray: &FilterRay<super::lanes::avx::Avx>,
    a: &Block4,
    b: &Block4,
) -> u32 {
    survivors_of::<super::lanes::avx::Avx, KZ, SWAP>(ray, &TwoBlocks(a, b), 0xff)
}

/// Where the filter reads its lanes: row `k` is coordinate `k % 3` of vertex `k / 3`. A trait
/// rather than a closure so that every read is forced inline (in the AVX walks a closure stayed
/// out of line).
trait Rows<L> {
    fn row(&self, k: usize) -> L;
}

/// One block's four lanes.
struct OneBlock<'a>(&'a Block4);

impl<L: Lanes> Rows<L> for OneBlock<'_> {
    #[inline(always)]
    fn row(&self, k: usize) -> L {
        L::load(&self.0.v[k])
    }
}

/// Two blocks' eight lanes.
#[cfg(all(target_arch = "x86_64", feature = "avx"))]
struct TwoBlocks<'a>(&'a Block4, &'a Block4);

#[cfg(all(target_arch = "x86_64", feature = "avx"))]
impl Rows<super::lanes::avx::Avx> for TwoBlocks<'_> {
    #[inline(always)]
    fn row(&self, k: usize) -> super::lanes::avx::Avx {
        super::lanes::avx::Avx::load_pair(&self.0.v[k], &self.1.v[k])
    }
}

/// The filter on the lanes `row(k)` gives for coordinate row `k` (`a.x, a.y, a.z, b.x, …`), all of
/// whose lanes are `full`.
#[inline(always)]
fn survivors_of<L: Lanes, const KZ: usize, const SWAP: bool>(
    ray: &FilterRay<L>,
    row: &impl Rows<L>,
    full: u32,
) -> u32 {
    let [kx, ky] = axes::<KZ, SWAP>();
    let k = [kx, ky, KZ];
    let (ax, ay, az) = sheared(row, 0, k, ray.o, ray.s);
    let (bx, by, bz) = sheared(row, 3, k, ray.o, ray.s);
    let (cx, cy, cz) = sheared(row, 6, k, ray.o, ray.s);
    let u = cx.mul(by).sub(cy.mul(bx));
    let v = ax.mul(cy).sub(ay.mul(cx));
    let w = bx.mul(ay).sub(by.mul(ax));
    // One edge function above the bound and another below its negative: as the bound is positive,
    // that is the largest above it and the smallest below its negative. The comparisons are negated
    // ones, so that an unused lane (NaN everywhere) is rejected by the same test.
    let (most, least) = (u.max(v).max(w), u.min(v).min(w));
    // First against the scene's bound (at least every lane's): most blocks are settled here,
    // without their own bounds.
    if L::all(rejected_lanes(most, least, ray.scene_bound, ray.scene_low)) {
        return 0;
    }
    let s = ax
        .abs()
        .max(ay.abs())
        .max(bx.abs())
        .max(by.abs())
        .max(cx.abs().max(cy.abs()));
    let z = az.abs().max(bz.abs()).max(cz.abs());
    let bound = bound(s, z);
    let live = !L::bits(rejected_lanes(most, least, bound, bound.neg())) & full;
    if live == 0 || !ray.check_window {
        return live;
    }
    live & !outside_window(ray, [u, v, w], [az, bz, cz], z, bound)
}

/// The lanes where `most` is above `bound` and `least` below `low` (or NaN). A function rather than
/// a closure so that it is forced inline (in the AVX walks a closure stayed out of line).
#[inline(always)]
fn rejected_lanes<L: Lanes>(most: L, least: L, bound: L, low: L) -> L::Mask {
    L::and(most.nle(bound), least.nge(low))
}

/// The lanes whose crossing is certainly outside the ray's window (module docs, "The window
/// check"), given the lanes' edge functions `e`, translated `z`, their largest `|z|` and the
/// edge functions' error bound.
#[inline(always)]
fn outside_window<L: Lanes>(ray: &FilterRay<L>, e: [L; 3], z: [L; 3], zmax: L, bound: L) -> u32 {
    let [u, v, w] = e;
    let sum_abs = u.abs().add(v.abs()).add(w.abs());
    let det = u.add(v).add(w);
    let num = u.mul(z[0]).add(v.mul(z[1])).add(w.mul(z[2]));
    let err_det = L::splat(4.0).mul(bound.add(L::splat(U32).mul(sum_abs)));
    let err_num = zmax.mul(
        L::splat(4.0)
            .mul(bound)
            .add(L::splat(5.0 * U32).mul(sum_abs)),
    );
    let inv = L::splat(1.0).div(det);
    let y = num.mul(inv);
    let err_y = crossing_error(y, det, err_det, err_num, inv);
    // Where `|det|` is at most twice its error the crossing is not bounded: such lanes stay.
    let bounded = det.abs().gt(L::splat(2.0).mul(err_det));
    let before = y.add(err_y).lt(ray.y_lo);
    let after = y.sub(err_y).gt(ray.y_hi);
    L::bits(L::and(bounded, before)) | L::bits(L::and(bounded, after))
}

/// The bound on the error of a lane's crossing `ŷ = N̂·fl(1/D̂)` (`inv`), given the bounds on
/// the error of `D̂` (`det`) and `N̂` (docs/design.md, "The window check"). Normal (at least 2^-125)
/// for `|D̂| < 2^46` whatever `ŷ` and the bounds are, so that the check costs no microcode assist.
#[inline(always)]
fn crossing_error<L: Lanes>(y: L, det: L, err_det: L, err_num: L, inv: L) -> L {
    y.abs()
        .mul(
            L::splat(2.1)
                .mul(err_det)
                .add(L::splat(3.0 * U32).mul(det.abs())),
        )
        // The floor inside the quotient covers what underflow takes from the numerator's three
        // products (2^-150 each) and from `err_num` itself, which `|D̂|` down to 2^-125 can
        // magnify (a review found hits dropped without it: triangles of 1e-13 near the origin).
        .add(L::splat(2.1).mul(err_num.add(L::splat(N_FLOOR))))
        .mul(inv.abs())
        .add(L::splat(Y_FLOOR))
}

/// The bound `E` on the error of the edge functions of triangles whose sheared `|x|, |y|` are at
/// most `s` and translated `|z|` at most `z` (module docs), with the slack for its own rounding.
#[inline(always)]
fn bound<L: Lanes>(s: L, z: L) -> L {
    let e = s
        .mul(L::splat(E_S))
        .add(z.mul(L::splat(E_Z)))
        .add(L::splat(COORD_FLOOR));
    s.mul(L::splat(B_SS).mul(s).add(L::splat(B_SE).mul(e)))
        .add(L::splat(B_EE).mul(e.mul(e)))
        .add(L::splat(EDGE_FLOOR))
}

/// One vertex's lanes (rows `first..first + 3` of `row`: its x, y, z) translated by `o` and sheared
/// by `s` along the axes `k = [kx, ky, kz]`. A function rather than a closure so that it can be
/// forced inline: as a closure it stayed out of line in the kd-tree's walk (three calls per block,
/// measured).
#[inline(always)]
fn sheared<L: Lanes>(
    row: &impl Rows<L>,
    first: usize,
    k: [usize; 3],
    o: [L; 3],
    s: [L; 2],
) -> (L, L, L) {
    let z = row.row(first + k[2]).sub(o[2]);
    let x = row.row(first + k[0]).sub(o[0]).sub(s[0].mul(z));
    let y = row.row(first + k[1]).sub(o[1]).sub(s[1].mul(z));
    (x, y, z)
}
