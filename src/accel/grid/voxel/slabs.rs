//! Long thin triangles' cells, slab by slab across the triangle's largest extent, four slabs at a
//! time in f32 lanes: the triangle's piece in each slab (the slab's enlarged range on that axis) is
//! bounded from the piece's corners, and those bounds give the slab's candidate cells on the other
//! two axes — nearly always a single cell or a column of them, which the piece meets everywhere.
//! A slab whose candidates are at least two cells on both other axes tests each candidate against
//! the piece's projection by separating axes. For a thin triangle the work is then proportional to
//! its slabs and cells, where [`Cells::overlapped`] solves rows of the whole footprint (~3.3 row
//! solves a listed cell on slivers) and [`Cells::medium`] masks 64 cells (docs/performance.md,
//! "Stop 40").
//!
//! Exactness: a cell is listed when its enlarged box meets the triangle (up to the rounding
//! slack). Every point of the triangle in a cell's enlarged box lies in the piece of the cell's
//! slab, so within the piece's bounds widened by half an enlarged cell: no overlapped cell is left
//! out. A candidate of a slab whose candidates form a column is met: the (convex) piece lies in the
//! slab and in the column's enlarged cross-section (a neighbouring cross-section, which overlaps
//! it, would otherwise be a candidate too), and reaches every candidate along the column. Since
//! the piece lies in its slab, any other candidate meets the triangle exactly when its
//! cross-section meets the piece's projection onto the other two axes: a convex polygon with
//! edges along the long edge, the cross-section `d` and the other two edges, whose normals and the
//! two axes are all the separating axes there are.
//!
//! Rounding: coordinates are taken in cells from the footprint's corner, within `[−2,`
//! [`MAX_SLAB_CELLS`]`]` ([`slab_axis`]; `M = 130` bounds their magnitudes and differences), and
//! rounded to f32 once (error `u·M`, `u = 2^-24`). A corner (`a + x·slope + λ·d`, `x`, `λ` and the slope from a few differences and products) is
//! then within `16u·M` of the exact piece's corner: below 1/1 000 of a cell for `M = 130`, and a
//! separating axis's dot products within `4u·M` of their size, against the rounding slack of
//! 2^-10 of half an enlarged cell (`ROUNDING_SLACK`): no cell the exact test accepts is dropped,
//! and a cell listed is within twice the slack of the triangle.

use glam::Vec4;

use super::{cross, largest_axis, sub, Cells, Footprint};

/// The farthest a triangle's coordinates may reach from its footprint's corner, in cells, for the
/// slab walk: the f32 rounding bound above holds below it. Longer thin triangles are listed by
/// rows in f64.
pub(super) const MAX_SLAB_CELLS: u32 = 128;

/// The slab lanes' centres from the group's first slab.
const CENTRE: Vec4 = Vec4::new(0.5, 1.5, 2.5, 3.5);

/// The axis to walk a triangle (`q`, in cell units, footprint `fp`) across by [`Cells::slabs`] —
/// that of its largest extent, so that its long edge moves at most a cell across a slab on the
/// other two axes — or `None` when the rows suit it better: a triangle whose height over its
/// longest edge is above a cell (`|(q1 − q0) × (q2 − q0)| > |longest edge|`, both squared; a
/// slab's piece would span many cells across), or one whose coordinates from the footprint's
/// corner leave `[−2, MAX_SLAB_CELLS]` (the rounding bound's range: a nested grid's triangles may
/// hang over its box, so the footprint's length alone does not bound them).
#[inline(always)]
pub(super) fn slab_axis(q: &[[f64; 3]; 3], fp: &Footprint) -> Option<usize> {
    let reach = f64::from(MAX_SLAB_CELLS);
    let mut extent = [0.0; 3];
    for (a, e) in extent.iter_mut().enumerate() {
        let lo = q[0][a].min(q[1][a]).min(q[2][a]) - f64::from(fp.lo[a]);
        let hi = q[0][a].max(q[1][a]).max(q[2][a]) - f64::from(fp.lo[a]);
        if !(lo >= -2.0 && hi <= reach) {
            return None;
        }
        *e = hi - lo;
    }
    let len2 = |v: [f64; 3]| v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    let (e1, e2, e3) = (sub(q[1], q[0]), sub(q[2], q[0]), sub(q[2], q[1]));
    if len2(cross(e1, e2)) > len2(e1).max(len2(e2)).max(len2(e3)) {
        return None;
    }
    Some(largest_axis(extent))
}

/// `1/x`, or `f32::MAX` where that is not finite (an edge of no extent on the slab axis): its
/// products with the non-negative distances along the axis are then never NaN (`λ`, below, is
/// clamped to `[0, 1]` in every lane, the unused ones too).
#[inline(always)]
fn finite_inverse(x: f32) -> f32 {
    let i = 1.0 / x;
    if i.is_finite() {
        i
    } else {
        f32::MAX
    }
}

/// The cells `c` (from 0 to `last`) whose centres `c + 0.5` lie in `[lo, hi]`, per lane, as the
/// first and the last (from −1 to `last + 1`); empty lanes have `first > last`.
///
/// Both ends are taken to non-negative values below 2^23 before truncation, so truncation is
/// floor: `ceil(x) = trunc(x) + (trunc(x) < x)`, and `floor(y) = trunc(y + 1) − 1` for `y ≥ −1`
/// (the `+ 1` may round a `y` just below 0 up to 1, which keeps one more cell: never fewer).
#[inline(always)]
fn centres_in(lo: Vec4, hi: Vec4, last: f32) -> ([i32; 4], [i32; 4]) {
    let x = (lo - 0.5).max(Vec4::ZERO).min(Vec4::splat(last + 1.0));
    let y = ((hi - 0.5).min(Vec4::splat(last)) + 1.0).max(Vec4::ZERO);
    ceil_floor(x, y)
}

/// `(ceil(x), trunc(y) − 1)` lane by lane, for values in `[0, 2^23)`: `cvttps2dq` on SSE2 (part of
/// x86-64's baseline), where a conversion a lane with Rust's saturating `as` cost ~6 instructions.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn ceil_floor(x: Vec4, y: Vec4) -> ([i32; 4], [i32; 4]) {
    use core::arch::x86_64::{
        _mm_castps_si128, _mm_cmplt_ps, _mm_cvtepi32_ps, _mm_cvttps_epi32, _mm_loadu_ps,
        _mm_set1_epi32, _mm_storeu_si128, _mm_sub_epi32,
    };
    let (x, y) = (x.to_array(), y.to_array());
    let (mut first, mut last) = ([0i32; 4], [0i32; 4]);
    // SAFETY: SSE2 is always present on x86-64, and every intrinsic here is SSE2 or SSE; the loads
    // read and the stores write 16 bytes of local arrays of four 4-byte values. (Loaded from
    // arrays: glam's `Vec4` is an `__m128` only with its SSE2 backend.)
    unsafe {
        let (x, y) = (_mm_loadu_ps(x.as_ptr()), _mm_loadu_ps(y.as_ptr()));
        let t = _mm_cvttps_epi32(x);
        // A lane below `x` is all ones, −1: subtracting it adds one.
        let below = _mm_castps_si128(_mm_cmplt_ps(_mm_cvtepi32_ps(t), x));
        _mm_storeu_si128(first.as_mut_ptr().cast(), _mm_sub_epi32(t, below));
        let u = _mm_sub_epi32(_mm_cvttps_epi32(y), _mm_set1_epi32(1));
        _mm_storeu_si128(last.as_mut_ptr().cast(), u);
    }
    (first, last)
}

/// [`ceil_floor`] lane by lane: the version for other targets, and the reference the SSE2 one is
/// tested against.
#[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
#[inline(always)]
fn ceil_floor_portable(x: Vec4, y: Vec4) -> ([i32; 4], [i32; 4]) {
    // SAFETY: values in [0, 2^23) (the caller), where the conversion is exact.
    let trunc = |v: f32| unsafe { v.to_int_unchecked::<i32>() };
    let (x, y) = (x.to_array(), y.to_array());
    (
        x.map(|v| trunc(v) + i32::from((trunc(v) as f32) < v)),
        y.map(|v| trunc(v) - 1),
    )
}

#[cfg(not(target_arch = "x86_64"))]
use ceil_floor_portable as ceil_floor;

/// Four slabs' pieces: the corners at both ends and the bounds on the other two axes (`[v, w]`).
struct Pieces {
    p0: [Vec4; 2],
    p1: [Vec4; 2],
    q0: [Vec4; 2],
    q1: [Vec4; 2],
    lo: [Vec4; 2],
    hi: [Vec4; 2],
}

impl Cells {
    /// The cells of `fp` the triangle (`q`, in cell units) overlaps, slab by slab along `s`, for a
    /// triangle and axis [`slab_axis`] accepts (see the module's comment). Each cell of `fp` at
    /// most once, none outside it — what [`Cells::for_each_large`] promises its callers.
    #[inline(never)]
    pub(super) fn slabs(
        &self,
        q: &[[f64; 3]; 3],
        fp: &Footprint,
        s: usize,
        emit: &mut impl FnMut(u32),
    ) {
        debug_assert_eq!(slab_axis(q, fp), Some(s));
        let (v, w) = ((s + 1) % 3, (s + 2) % 3);
        let local = |p: [f64; 3]| [s, v, w].map(|a| (p[a] - f64::from(fp.lo[a])) as f32);
        // The vertices in order along `s`: the piece of a slab lies between the long edge `a c`
        // and the path `a b c`.
        let [a, b, c] = {
            let mut t = q.map(local);
            if t[0][0] > t[1][0] {
                t.swap(0, 1);
            }
            if t[1][0] > t[2][0] {
                t.swap(1, 2);
            }
            if t[0][0] > t[1][0] {
                t.swap(0, 1);
            }
            t
        };
        // The piece at `t` on `s` is the segment from the long edge's point `a + (t − a_s)·slope`
        // to that plus `λ(t)·d`, where `d` runs from the long edge to `b` at `b`'s position and
        // `λ` rises linearly from 0 at `a` to 1 at `b` and falls back to 0 at `c`.
        let inv_long = finite_inverse(c[0] - a[0]);
        let slope = [(c[1] - a[1]) * inv_long, (c[2] - a[2]) * inv_long];
        let d = [1, 2].map(|k| b[k] - (a[k] + (b[0] - a[0]) * slope[k - 1]));
        let (inv_up, inv_down) = (finite_inverse(b[0] - a[0]), finite_inverse(c[0] - b[0]));
        let half = self.half.map(|h| h as f32);
        let (hs, hv, hw) = (half[s], half[v], half[w]);
        let last = [fp.len(v) - 1, fp.len(w) - 1].map(|l| l as f32);
        let splat = Vec4::splat;
        let pieces = |g: u32| {
            let cs = splat(g as f32) + CENTRE;
            let t0 = (cs - hs).max(splat(a[0]));
            let t1 = (cs + hs).min(splat(c[0]));
            let (x0, x1) = (t0 - a[0], t1 - a[0]);
            // Clamped below too: in a lane past the triangle `c_s − t` is negative, and times
            // `f32::MAX` −∞, whose product with a zero `d` would be NaN.
            let lambda = |x: Vec4, t: Vec4| {
                (x * inv_up)
                    .min((c[0] - t) * inv_down)
                    .clamp(Vec4::ZERO, Vec4::ONE)
            };
            let (l0, l1) = (lambda(x0, t0), lambda(x1, t1));
            let kink = t0.cmple(splat(b[0])) & splat(b[0]).cmple(t1);
            // A slab of the footprint whose enlarged range meets the triangle's.
            let live = t0.cmple(t1) & cs.cmplt(splat(fp.len(s) as f32));
            let mut p = Pieces {
                p0: [Vec4::ZERO; 2],
                p1: [Vec4::ZERO; 2],
                q0: [Vec4::ZERO; 2],
                q1: [Vec4::ZERO; 2],
                lo: [Vec4::ZERO; 2],
                hi: [Vec4::ZERO; 2],
            };
            for k in 0..2 {
                let (p0, p1) = (a[k + 1] + x0 * slope[k], a[k + 1] + x1 * slope[k]);
                let (q0, q1) = (p0 + l0 * d[k], p1 + l1 * d[k]);
                let lo = p0.min(p1).min(q0).min(q1);
                let hi = p0.max(p1).max(q0).max(q1);
                p.lo[k] = Vec4::select(kink, lo.min(splat(b[k + 1])), lo);
                p.hi[k] = Vec4::select(kink, hi.max(splat(b[k + 1])), hi);
                debug_assert!(!p.lo[k].is_nan() && !p.hi[k].is_nan());
                (p.p0[k], p.p1[k], p.q0[k], p.q1[k]) = (p0, p1, q0, q1);
            }
            (p, live, kink)
        };
        let mut axes: Option<PieceAxes> = None;
        let slabs = fp.len(s);
        let mut g = 0;
        while g < slabs {
            let (p, live, kink) = pieces(g);
            let (j0, j1) = centres_in(p.lo[0] - hv, p.hi[0] + hv, last[0]);
            let (k0, k1) = centres_in(p.lo[1] - hw, p.hi[1] + hw, last[1]);
            let mut lanes = live.bitmask();
            while lanes != 0 {
                let lane = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                let [j0, j1, k0, k1] = [j0, j1, k0, k1].map(|x| x[lane]);
                if j0 > j1 || k0 > k1 {
                    continue;
                }
                let slab = (fp.lo[s] + g + lane as u32) as usize * self.stride[s];
                let cell = |j: i32, k: i32| {
                    slab + (fp.lo[v] as usize + j as usize) * self.stride[v]
                        + (fp.lo[w] as usize + k as usize) * self.stride[w]
                };
                if j0 == j1 || k0 == k1 {
                    for j in j0..=j1 {
                        for k in k0..=k1 {
                            emit(cell(j, k) as u32);
                        }
                    }
                    continue;
                }
                let axes = axes.get_or_insert_with(|| PieceAxes::new(slope, d, &a, &b, &c, hv, hw));
                let lane_of = |x: [Vec4; 2]| [x[0].to_array()[lane], x[1].to_array()[lane]];
                let corners = [
                    lane_of(p.p0),
                    lane_of(p.p1),
                    lane_of(p.q0),
                    lane_of(p.q1),
                    if (kink.bitmask() >> lane) & 1 != 0 {
                        [b[1], b[2]]
                    } else {
                        lane_of(p.p0)
                    },
                ];
                let (lo, hi) = axes.reach(&corners);
                for j in j0..=j1 {
                    for k in k0..=k1 {
                        let at = axes.n[0] * (j as f32 + 0.5) + axes.n[1] * (k as f32 + 0.5);
                        if (at.cmpge(lo) & at.cmple(hi)).all() {
                            emit(cell(j, k) as u32);
                        }
                    }
                }
            }
            g += 4;
        }
    }
}

/// The separating axes of a slab's piece projected onto the two other axes, beside those axes:
/// the normals of the long edge, of the cross-section `d` and of the two other edges, in lanes
/// (`n[0]` their first coordinate, `n[1]` their second), with a cell's projected half extent.
struct PieceAxes {
    n: [Vec4; 2],
    r: Vec4,
}

impl PieceAxes {
    fn new(
        slope: [f32; 2],
        d: [f32; 2],
        a: &[f32; 3],
        b: &[f32; 3],
        c: &[f32; 3],
        hv: f32,
        hw: f32,
    ) -> PieceAxes {
        let dir = [
            slope,
            d,
            [b[1] - a[1], b[2] - a[2]],
            [c[1] - b[1], c[2] - b[2]],
        ];
        let n = [
            Vec4::from_array(dir.map(|e| -e[1])),
            Vec4::from_array(dir.map(|e| e[0])),
        ];
        PieceAxes {
            r: n[0].abs() * hv + n[1].abs() * hw,
            n,
        }
    }

    /// The polygon's projection onto each axis, widened by a cell's: a cell centre's projection
    /// outside it separates the cell from the polygon.
    #[inline(always)]
    fn reach(&self, corners: &[[f32; 2]; 5]) -> (Vec4, Vec4) {
        let dot = |p: [f32; 2]| self.n[0] * p[0] + self.n[1] * p[1];
        let first = dot(corners[0]);
        let (lo, hi) = corners[1..].iter().fold((first, first), |(lo, hi), &p| {
            let x = dot(p);
            (lo.min(x), hi.max(x))
        });
        (lo - self.r, hi + self.r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::grid::layout::Shape;
    use crate::accel::grid::tests::assert_listed_exactly;
    use crate::ray::Aabb;
    use crate::workload::SplitMix64;
    use alloc::vec::Vec;
    use glam::Vec3;

    /// The slab walk alone against the 13-axis oracle, on triangles chosen to stress it: long thin
    /// ones at all angles and widths up to the thinness limit, strips lying on cell planes, two
    /// vertices sharing their coordinate on the slab axis (first two, last two), the middle vertex
    /// on the long edge, on slab ends, and collinear ones — on a grid near the origin and one far
    /// from it (whose margin is several cells). Each cell of the footprint at most once, none
    /// outside it, every overlapped cell listed and none missed by more than the slack; and the
    /// separating axes of ambiguous slabs are reached.
    #[test]
    fn slabs_list_exactly_the_overlapped_cells() {
        let mut rng = SplitMix64::new(0x51ab);
        for origin in [Vec3::ZERO, Vec3::new(1e7, -1e7, 3e6)] {
            let tight = Aabb {
                min: origin,
                max: origin + Vec3::splat(24.0),
            };
            let shape = Shape::new(tight, 13_824, 1.0).unwrap();
            let cells = Cells::new(&shape);
            let plane = |a: usize, k: f32| shape.bounds.min[a] + k * shape.cell_size[a];
            let at = |p: [f32; 3]| Vec3::from_array([0, 1, 2].map(|a| plane(a, p[a])));
            let mut tris: Vec<[Vec3; 3]> = Vec::new();
            for _ in 0..600 {
                // In cell coordinates: a long edge, the third vertex off it by up to a cell.
                let a = rng.next_vec3() * 22.0 + Vec3::ONE;
                let b = rng.next_vec3() * 22.0 + Vec3::ONE;
                let m = a.lerp(b, rng.next_f32());
                let off = (rng.next_vec3() - Vec3::splat(0.5)) * (2.0 * rng.next_f32());
                tris.push([a, b, m + off].map(|p| at(p.to_array())));
            }
            for k in 1..20 {
                let k = k as f32;
                // Strips on the plane z = k, with the last two or the first two vertices sharing x.
                tris.push([[1.3, 2.0, k], [k + 3.0, 3.0, k], [k + 3.0, 2.4, k]].map(at));
                tris.push([[2.0, 1.5, k], [2.0, 2.5, k], [k + 4.0, 7.0, k]].map(at));
                // The middle vertex on the long edge, on cell planes, and a collinear one.
                tris.push([[1.0, 1.0, 1.0], [k, k, k], [21.0, 21.0, 21.0]].map(at));
                tris.push([[1.0, k, 2.0], [11.0, k, 7.0], [21.0, k, 12.0]].map(at));
                tris.push([[1.5, 2.5, 3.5], [k + 0.5, 3.5, 4.5], [k + 0.5, 3.5, 4.5]].map(at));
                tris.push([[1.0, 1.0, 1.0], [k, 1.0, 1.0], [k, k * 0.5, 2.0]].map(at));
            }
            let (mut walked, mut ambiguous) = (0, 0);
            for tri in &tris {
                let fp = cells.footprint(tri);
                if (0..3).any(|a| fp.len(a) < 2) {
                    continue;
                }
                let q = tri.map(|p| [0, 1, 2].map(|a| cells.local(p[a], a)));
                let Some(s) = slab_axis(&q, &fp) else {
                    continue;
                };
                let mut got = Vec::new();
                cells.slabs(&q, &fp, s, &mut |c| got.push(c as usize));
                let mut sorted = got.clone();
                sorted.sort_unstable();
                sorted.dedup();
                assert_eq!(sorted.len(), got.len(), "{tri:?}: a cell twice");
                let coords = |c: usize| {
                    let r = shape.res.map(|r| r as usize);
                    [c % r[0], c / r[0] % r[1], c / (r[0] * r[1])]
                };
                for &c in &sorted {
                    let c = coords(c);
                    let inside = (0..3).all(|a| (fp.lo[a]..=fp.hi[a]).contains(&(c[a] as u32)));
                    assert!(inside, "{tri:?}: {c:?} outside {fp:?}");
                }
                let what = alloc::format!("slabs at {origin:?}");
                assert_listed_exactly(&shape, &cells, tri, &sorted, &what);
                walked += 1;
                // A slab with two cells or more on both other axes: the separating axes decided.
                let (v, w) = ((s + 1) % 3, (s + 2) % 3);
                let slab_of = |c: usize| coords(c)[s];
                ambiguous += usize::from((fp.lo[s]..=fp.hi[s]).any(|i| {
                    let cs: Vec<[usize; 3]> = sorted
                        .iter()
                        .filter(|&&c| slab_of(c) == i as usize)
                        .map(|&c| coords(c))
                        .collect();
                    let span = |k: usize| {
                        let lo = cs.iter().map(|c| c[k]).min().unwrap_or(0);
                        let hi = cs.iter().map(|c| c[k]).max().unwrap_or(0);
                        hi - lo
                    };
                    span(v) >= 1 && span(w) >= 1
                }));
            }
            assert!(walked > 400, "only {walked} triangles walked at {origin:?}");
            assert!(
                ambiguous > 100,
                "only {ambiguous} with ambiguous slabs at {origin:?}"
            );
        }
    }

    /// The SSE2 conversion (on x86-64) gives the reference's cells: integers, halves, values just
    /// above and below integers, zero and the largest cell counts.
    #[test]
    fn ceil_floor_matches_the_reference() {
        let mut values = alloc::vec![0.0f32, 0.5, 1.0, 127.0, 129.5, 8_388_607.0];
        for k in 0..300 {
            let x = k as f32 * 0.37;
            let (up, down) = (
                f32::from_bits(x.to_bits() + 1),
                f32::from_bits(x.to_bits().saturating_sub(1)),
            );
            values.extend([x, up, down, x.floor(), x.ceil()]);
        }
        for four in values.chunks_exact(4) {
            let x = Vec4::from_slice(four);
            let y = Vec4::from_slice(four).map(|v| (v * 0.5).floor() + v.fract());
            let (first, last) = ceil_floor(x, y);
            assert_eq!((first, last), ceil_floor_portable(x, y), "{x:?} {y:?}");
            for lane in 0..4 {
                assert_eq!(first[lane] as f32, four[lane].ceil(), "{x:?}");
                assert_eq!(last[lane] as f32, y.to_array()[lane].floor() - 1.0, "{y:?}");
            }
        }
    }
}
