//! The parts of a triangle on either side of a split plane ("perfect splits"), with their bounds
//! rounded outward to f32; and, for the tests, the part inside a box by Sutherland–Hodgman clipping.

use glam::{Vec3, Vec3A};

use crate::ray::Aabb;

/// The largest f32 not above `x` (`x` not NaN).
///
/// Without branches: whether `x as f32` rounded up is a coin toss for the crossings the build
/// rounds, four per crossing, and as branches they were mispredicted half the time.
#[inline]
fn round_down(x: f64) -> f32 {
    let f = x as f32;
    // The f32 below `f`: one unit down in magnitude for a positive `f` (`+∞` goes to `f32::MAX`),
    // one up for a negative one, which gives the negative smallest subnormal for −0. It is taken
    // only when `f` rounded up, so never for +0 (an `x` that rounds to +0 is not negative).
    let bits = f.to_bits();
    let below = bits.wrapping_add((bits >> 31) << 1).wrapping_sub(1);
    let rounded_up = 0u32.wrapping_sub(u32::from(f64::from(f) > x));
    f32::from_bits((below & rounded_up) | (bits & !rounded_up))
}

/// The smallest f32 not below `x` (`x` not NaN): the mirror of [`round_down`], as rounding to
/// nearest is symmetric.
#[inline]
fn round_up(x: f64) -> f32 {
    -round_down(-x)
}

/// [`round_down`] and [`round_up`] as branches (the reference the tests hold them to).
#[cfg(test)]
fn round_down_ref(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) > x {
        next_toward_neg_inf(f)
    } else {
        f
    }
}

#[cfg(test)]
fn round_up_ref(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) < x {
        -next_toward_neg_inf(-f)
    } else {
        f
    }
}

/// The next f32 below a finite `f`.
#[cfg(test)]
fn next_toward_neg_inf(f: f32) -> f32 {
    if f == 0.0 {
        -f32::from_bits(1)
    } else if f > 0.0 {
        f32::from_bits(f.to_bits() - 1)
    } else {
        f32::from_bits(f.to_bits() + 1)
    }
}

#[cfg(test)]
/// Most vertices a clipped polygon may have (a triangle clipped by six planes has at most nine).
const CAP: usize = 16;

#[cfg(test)]
/// A clipped polygon: its vertices in f64, in order.
type Poly = [[f64; 3]; CAP];

/// Bounds of the part of `tri` inside `b` (Sutherland–Hodgman against the six planes, in f64,
/// rounded outward to f32 and clamped to `b`), or [`Aabb::EMPTY`] when it misses `b`.
///
/// Guarantees, at the scales the tests use: the result contains every point of `tri` that lies in
/// `b` (when rounding leaves the clipped polygon empty or odd, it falls back to the triangle's
/// bounds clamped to `b`, which is larger and still right). Its crossings are not widened as
/// [`split_bounds`]' are, so a box far smaller than the triangle's vertices may lose a sliver: a
/// test oracle for ordinary scenes, not part of the build.
#[cfg(test)]
fn clipped_bounds(tri: &[Vec3; 3], b: &Aabb) -> Aabb {
    let tb = Aabb::of_triangle(tri);
    let fallback = || {
        let c = Aabb {
            min: tb.min.max(b.min),
            max: tb.max.min(b.max),
        };
        if c.is_empty() {
            Aabb::EMPTY
        } else {
            c
        }
    };
    // Two buffers used in turn, so a clip copies no more than the vertices it keeps.
    let mut buf = [[[0.0f64; 3]; CAP]; 2];
    for (slot, v) in buf[0].iter_mut().zip(tri) {
        *slot = [f64::from(v.x), f64::from(v.y), f64::from(v.z)];
    }
    let mut state = Some((0usize, 3usize));
    // One copy per axis, so the coordinate picked is a fixed slot.
    state =
        state.and_then(|s| clip_axis::<0>(&mut buf, s, (tb.min.x, tb.max.x), (b.min.x, b.max.x)));
    state =
        state.and_then(|s| clip_axis::<1>(&mut buf, s, (tb.min.y, tb.max.y), (b.min.y, b.max.y)));
    state =
        state.and_then(|s| clip_axis::<2>(&mut buf, s, (tb.min.z, tb.max.z), (b.min.z, b.max.z)));
    let Some((from, n)) = state else {
        return fallback();
    };
    let poly = buf[from & 1].get(..n).unwrap_or(&[]);
    let Some(&first) = poly.first() else {
        return fallback();
    };
    let (mut lo, mut hi) = (first, first);
    for p in poly {
        for i in 0..3 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }
    let c = Aabb {
        min: Vec3::new(round_down(lo[0]), round_down(lo[1]), round_down(lo[2])).max(b.min),
        max: Vec3::new(round_up(hi[0]), round_up(hi[1]), round_up(hi[2])).min(b.max),
    };
    if c.is_empty() {
        fallback()
    } else {
        c
    }
}

#[cfg(test)]
/// Clips the polygon `buf[from]` (`n` vertices) against the planes of axis `A` its bounds `t`
/// cross (of the box's `(min, max)` on that axis), alternating buffers. `None` when the polygon
/// vanishes or overflows (the caller falls back to the clamped triangle bounds).
#[inline]
fn clip_axis<const A: usize>(
    buf: &mut [Poly; 2],
    (mut from, mut n): (usize, usize),
    t: (f32, f32),
    b: (f32, f32),
) -> Option<(usize, usize)> {
    // A plane the triangle's bounds do not cross clips nothing.
    for (keep_above, crosses, bound) in [(true, t.0 < b.0, b.0), (false, t.1 > b.1, b.1)] {
        if !crosses {
            continue;
        }
        let [first, second] = buf;
        let (src, dst) = if from & 1 == 0 {
            (&*first, second)
        } else {
            (&*second, first)
        };
        n = clip_plane::<A>(src.get(..n)?, dst, f64::from(bound), keep_above)?;
        from ^= 1;
        if n == 0 {
            return None;
        }
    }
    Some((from, n))
}

#[cfg(test)]
/// Clips the polygon `src` against the plane `x[A] = bound`, keeping the side above it or below,
/// into `dst`; returns the vertex count, or `None` when `dst` overflows.
#[inline]
fn clip_plane<const A: usize>(
    src: &[[f64; 3]],
    dst: &mut Poly,
    bound: f64,
    keep_above: bool,
) -> Option<usize> {
    let inside = |p: &[f64; 3]| {
        if keep_above {
            p[A] >= bound
        } else {
            p[A] <= bound
        }
    };
    let mut m = 0;
    let next = src.iter().skip(1).chain(src.first());
    for (cur, nxt) in src.iter().zip(next) {
        let (ci, ni) = (inside(cur), inside(nxt));
        if ci {
            *dst.get_mut(m)? = *cur;
            m += 1;
        }
        if ci != ni {
            let t = (bound - cur[A]) / (nxt[A] - cur[A]);
            let mut x = [0.0; 3];
            for i in 0..3 {
                x[i] = cur[i] + (nxt[i] - cur[i]) * t;
            }
            x[A] = bound;
            *dst.get_mut(m)? = x;
            m += 1;
        }
    }
    Some(m)
}

/// The bounds of the parts of `tri` on either side of the plane `x[axis] = pos`, each intersected
/// with `part` (the bounds of the triangle's part in the node being split) and with its side: the
/// vertices on each side and the points where the edges cross the plane (in f64, widened by their
/// rounding error and rounded outward to f32). One plane instead of the child box's six: the result
/// contains the exact part of the triangle in each child (a subset of both the part in the node and
/// the part on that side of the plane), and is at most the box [`clipped_bounds`] gives plus what
/// the node's box already cut and the crossings' widening.
/// A side the triangle does not reach is [`Aabb::EMPTY`].
///
/// The vertices are f32 already, so only the edge crossings are computed (in f64) and rounded; the
/// crossing's coordinate on `axis` is `pos` itself.
pub(super) fn split_bounds(tri: &[Vec3; 3], part: &Aabb, axis: usize, pos: f32) -> (Aabb, Aabb) {
    // One copy per axis, so that the other two axes are fixed slots (a loop over `k != axis` with
    // a run-time axis kept the bounds in memory).
    match axis {
        0 => split_bounds_on::<0>(tri, part, pos),
        1 => split_bounds_on::<1>(tri, part, pos),
        _ => split_bounds_on::<2>(tri, part, pos),
    }
}

/// [`split_bounds`] for the plane `x[A] = pos`.
#[inline(always)]
fn split_bounds_on<const A: usize>(tri: &[Vec3; 3], part: &Aabb, pos: f32) -> (Aabb, Aabb) {
    let v = tri.map(|v| v.to_array());
    // Each side's bounds in lanes. On x86-64 `min`/`max` are the SSE ones, `q < lo ? q : lo` and
    // `q > hi ? q : hi`: the comparisons a scalar version makes, so the same bounds bit for bit
    // (elsewhere the same values, but for the sign of a zero bound; nothing here is NaN).
    let mut lo = [Vec3A::INFINITY; 2];
    let mut hi = [Vec3A::NEG_INFINITY; 2];
    for i in 0..3 {
        let (a, b) = (&v[i], &v[(i + 1) % 3]);
        let p = Vec3A::from(*a);
        if a[A] <= pos {
            (lo[0], hi[0]) = (p.min(lo[0]), p.max(hi[0]));
        }
        if a[A] >= pos {
            (lo[1], hi[1]) = (p.min(lo[1]), p.max(hi[1]));
        }
        if (a[A] < pos) != (b[A] < pos) && a[A] != pos && b[A] != pos {
            let (xl, xh) = crossing(a, b, A, pos);
            let (ql, qh) = (Vec3A::from(xl), Vec3A::from(xh));
            for s in 0..2 {
                (lo[s], hi[s]) = (ql.min(lo[s]), qh.max(hi[s]));
            }
        }
    }
    (
        side_bounds(lo[0].into(), hi[0].into(), part, A, pos, false),
        side_bounds(lo[1].into(), hi[1].into(), part, A, pos, true),
    )
}

/// Where the edge `a`–`b`, which crosses the plane `x[axis] = pos` strictly between its ends,
/// meets it: the crossing's bounds rounded outward to f32 (`pos` itself on `axis`). With `axis` a
/// constant of the caller, the two other axes are fixed slots.
#[inline(always)]
fn crossing(a: &[f32; 3], b: &[f32; 3], axis: usize, pos: f32) -> ([f32; 3], [f32; 3]) {
    let (a, b) = (a.map(f64::from), b.map(f64::from));
    let t = (f64::from(pos) - a[axis]) / (b[axis] - a[axis]);
    let (mut xl, mut xh) = ([pos; 3], [pos; 3]);
    for k in [(axis + 1) % 3, (axis + 2) % 3] {
        let x = a[k] + (b[k] - a[k]) * t;
        // The f64 crossing is off by at most about 6u·(|a_k| + |b_k|) (u = 2^-53: one rounding
        // each in the three differences, the quotient, the product and the sum, with t in
        // [0, 1]), and `x ± err` rounds once more; widened by 16u before rounding outward.
        // Without it a crossing far smaller than the vertices (a plane at 1e-21 through a unit
        // triangle) lost a sliver of its part: a fuzzing helper's finding.
        let err = 8.0 * f64::EPSILON * (a[k].abs() + b[k].abs());
        xl[k] = round_down(x - err);
        xh[k] = round_up(x + err);
    }
    (xl, xh)
}

/// One side's box from the bounds of its vertices and crossings (`lo > hi` when it has none):
/// intersected with the node's part and with its half-space of the plane `x[axis] = pos` (the
/// upper one when `upper`), or [`Aabb::EMPTY`].
#[inline(always)]
fn side_bounds(lo: Vec3, hi: Vec3, part: &Aabb, axis: usize, pos: f32, upper: bool) -> Aabb {
    if !(lo.x <= hi.x) {
        return Aabb::EMPTY;
    }
    let mut b = Aabb {
        min: lo.max(part.min),
        max: hi.min(part.max),
    };
    if upper {
        b.min[axis] = b.min[axis].max(pos);
    } else {
        b.max[axis] = b.max[axis].min(pos);
    }
    if b.is_empty() {
        Aabb::EMPTY
    } else {
        b
    }
}

/// The version with the axis chosen at run time, kept as the reference the tests hold
/// [`split_bounds`] to.
#[cfg(test)]
fn split_bounds_ref(tri: &[Vec3; 3], part: &Aabb, axis: usize, pos: f32) -> (Aabb, Aabb) {
    let v = tri.map(|v| v.to_array());
    let mut lo = [[f32::INFINITY; 3]; 2];
    let mut hi = [[f32::NEG_INFINITY; 3]; 2];
    let add = |lo: &mut [f32; 3], hi: &mut [f32; 3], ql: &[f32; 3], qh: &[f32; 3]| {
        for k in 0..3 {
            lo[k] = if ql[k] < lo[k] { ql[k] } else { lo[k] };
            hi[k] = if qh[k] > hi[k] { qh[k] } else { hi[k] };
        }
    };
    let ([lo0, lo1], [hi0, hi1]) = (&mut lo, &mut hi);
    for i in 0..3 {
        let (a, b) = (&v[i], &v[(i + 1) % 3]);
        if a[axis] <= pos {
            add(lo0, hi0, a, a);
        }
        if a[axis] >= pos {
            add(lo1, hi1, a, a);
        }
        if (a[axis] < pos) != (b[axis] < pos) && a[axis] != pos && b[axis] != pos {
            let (xl, xh) = crossing(a, b, axis, pos);
            add(lo0, hi0, &xl, &xh);
            add(lo1, hi1, &xl, &xh);
        }
    }
    let side = |s: usize| side_bounds(lo[s].into(), hi[s].into(), part, axis, pos, s == 1);
    (side(0), side(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The branch-free roundings give the branches' answers bit for bit: zeros of both signs,
    /// subnormals, the f32 range's ends and beyond, every f32 of a spread of magnitudes and the
    /// f64 values just beside it, and random f64 bits.
    #[test]
    fn roundings_match_the_reference() {
        use alloc::{vec, vec::Vec};
        // The f64 values one unit away from `x` (toward +∞ and toward −∞).
        let beside = |x: f64| {
            let b = x.to_bits();
            let (up, down) = if x > 0.0 {
                (b + 1, b - 1)
            } else {
                (b - 1, b + 1)
            };
            [f64::from_bits(up), f64::from_bits(down)]
        };
        let mut xs: Vec<f64> = vec![
            0.0,
            -0.0,
            1e300,
            -1e300,
            f64::MAX,
            f64::MIN,
            1e-320,
            -1e-320,
        ];
        let edges = [
            f32::MAX,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            1.0,
            0.1,
            3.0e38,
            1.0e-40,
        ];
        for e in edges.iter().flat_map(|&e| [e, -e]) {
            let x = f64::from(e);
            xs.extend([x, x * (1.0 + 1e-9), x * (1.0 - 1e-9)]);
            xs.extend(beside(x));
        }
        let mut rng = crate::workload::SplitMix64::new(17);
        for _ in 0..100_000 {
            let x = f64::from_bits(rng.next_u64());
            if !x.is_nan() {
                xs.push(x);
            }
            let f = f32::from_bits(rng.next_u64() as u32);
            if f.is_finite() && f != 0.0 {
                xs.extend(beside(f64::from(f)));
            }
        }
        for x in xs {
            assert_eq!(
                round_down(x).to_bits(),
                round_down_ref(x).to_bits(),
                "down {x:e}"
            );
            assert_eq!(round_up(x).to_bits(), round_up_ref(x).to_bits(), "up {x:e}");
        }
    }

    #[test]
    fn clipping_keeps_the_part_inside() {
        let tri = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(0.0, 4.0, 0.0),
        ];
        let b = Aabb {
            min: Vec3::new(3.0, -1.0, -1.0),
            max: Vec3::new(5.0, 5.0, 1.0),
        };
        let c = clipped_bounds(&tri, &b);
        assert_eq!(c.min, Vec3::new(3.0, 0.0, 0.0));
        assert!(c.max.y >= 1.0 && c.max.y <= 1.0 + 1e-6, "{c:?}");
        assert_eq!(c.max.x, 4.0);
        let far = Aabb {
            min: Vec3::splat(10.0),
            max: Vec3::splat(11.0),
        };
        assert!(clipped_bounds(&tri, &far).is_empty());
    }

    /// The split's sides contain every point of the triangle inside the node's part on their side
    /// (sampled), lie inside that part and their half-space, and are within the box clipping
    /// gives for the child box.
    #[test]
    fn split_sides_hold_the_triangle_parts() {
        let mut rng = crate::workload::SplitMix64::new(4);
        for _ in 0..5_000 {
            let tri =
                [rng.next_vec3(), rng.next_vec3(), rng.next_vec3()].map(|v| v * 2.0 - Vec3::ONE);
            let node = Aabb {
                min: rng.next_vec3() * 0.8 - Vec3::ONE,
                max: rng.next_vec3() * 0.8 + Vec3::splat(0.2),
            };
            let part = clipped_bounds(&tri, &node);
            if part.is_empty() {
                continue;
            }
            let axis = rng.below(3);
            let pos = node.min[axis] + (node.max[axis] - node.min[axis]) * rng.next_f32();
            let (lower, upper) = split_bounds(&tri, &part, axis, pos);
            let (mut lbox, mut ubox) = (node, node);
            lbox.max[axis] = pos;
            ubox.min[axis] = pos;
            for _ in 0..64 {
                let (u, v) = (rng.next_f32(), rng.next_f32());
                let (u, v) = if u + v > 1.0 {
                    (1.0 - u, 1.0 - v)
                } else {
                    (u, v)
                };
                let q = tri[0] + u * (tri[1] - tri[0]) + v * (tri[2] - tri[0]);
                let inside = |b: &Aabb| q.cmpge(b.min).all() && q.cmple(b.max).all();
                // A point strictly inside (rounding of q aside) a child must be in that side's box.
                let shrunk = |b: &Aabb| Aabb {
                    min: b.min + Vec3::splat(1e-5),
                    max: b.max - Vec3::splat(1e-5),
                };
                if inside(&shrunk(&lbox)) {
                    assert!(
                        inside(&lower),
                        "{q:?} of {tri:?} missing below {pos} on {axis}: {lower:?}"
                    );
                }
                if inside(&shrunk(&ubox)) {
                    assert!(
                        inside(&upper),
                        "{q:?} of {tri:?} missing above {pos} on {axis}: {upper:?}"
                    );
                }
            }
            for (b, child) in [(lower, lbox), (upper, ubox)] {
                if !b.is_empty() {
                    assert!(b.min.cmpge(part.min).all() && b.max.cmple(part.max).all());
                    assert!(b.min.cmpge(child.min).all() && b.max.cmple(child.max).all());
                }
            }
        }
    }

    /// The per-axis copies give the run-time-axis version's bounds (bit for bit on x86-64): random
    /// triangles and parts at several scales, planes through vertices, on edges parallel to the
    /// plane, at signed zeros and far from the triangle.
    #[test]
    fn per_axis_copies_match_the_reference() {
        let mut rng = crate::workload::SplitMix64::new(38);
        let bits = |b: &Aabb| [b.min.to_array(), b.max.to_array()].map(|v| v.map(f32::to_bits));
        for case in 0..60_000 {
            let scale = [1e-20f32, 1e-3, 1.0, 3e4, 1e18][case % 5];
            let mut tri = [rng.next_vec3(), rng.next_vec3(), rng.next_vec3()]
                .map(|v| (v * 2.0 - Vec3::ONE) * scale);
            let axis = rng.below(3);
            // Some triangles with an edge parallel to the plane or a vertex at -0 (any of the
            // three, so that a crossing meets a stored -0 bound).
            if case % 7 == 0 {
                tri[1][axis] = tri[0][axis];
            }
            if case % 11 == 0 {
                tri[case % 3][axis] = -0.0;
            }
            let node = Aabb::of_triangle(&tri);
            let pos = match case % 4 {
                0 => tri[rng.below(3)][axis],
                1 => 0.0,
                2 => node.min[axis] + (node.max[axis] - node.min[axis]) * rng.next_f32(),
                _ => node.max[axis] + scale,
            };
            let part = if case % 3 == 0 {
                node
            } else {
                clipped_bounds(
                    &tri,
                    &Aabb {
                        min: node.min + (node.max - node.min) * 0.1 * rng.next_f32(),
                        max: node.max - (node.max - node.min) * 0.1 * rng.next_f32(),
                    },
                )
            };
            let (l, u) = split_bounds(&tri, &part, axis, pos);
            let (lr, ur) = split_bounds_ref(&tri, &part, axis, pos);
            // Bit for bit with SSE's `min`/`max`; other targets' may order two zeros otherwise.
            if cfg!(target_arch = "x86_64") {
                assert_eq!(
                    (bits(&l), bits(&u)),
                    (bits(&lr), bits(&ur)),
                    "{tri:?} {part:?} {axis} {pos}"
                );
            } else {
                assert_eq!((l, u), (lr, ur), "{tri:?} {part:?} {axis} {pos}");
            }
        }
    }

    #[test]
    fn outward_rounding_brackets() {
        for x in [0.1f64, -0.1, 1e-30, -1e-30, 3.0, 0.0] {
            assert!(
                f64::from(round_down(x)) <= x && f64::from(round_up(x)) >= x,
                "{x}"
            );
        }
    }
}
