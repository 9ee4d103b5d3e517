//! The part of a triangle inside a box: Sutherland–Hodgman clipping in f64 against the planes the
//! triangle's bounds cross, with the bounds rounded outward to f32 ("perfect splits").

use glam::Vec3;

use crate::ray::Aabb;

/// The largest f32 not above `x`.
#[inline]
fn round_down(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) > x {
        next_toward_neg_inf(f)
    } else {
        f
    }
}

/// The smallest f32 not below `x`.
#[inline]
fn round_up(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) < x {
        -next_toward_neg_inf(-f)
    } else {
        f
    }
}

/// The next f32 below a finite `f`.
fn next_toward_neg_inf(f: f32) -> f32 {
    if f == 0.0 {
        -f32::from_bits(1)
    } else if f > 0.0 {
        f32::from_bits(f.to_bits() - 1)
    } else {
        f32::from_bits(f.to_bits() + 1)
    }
}

/// Most vertices a clipped polygon may have (a triangle clipped by six planes has at most nine).
const CAP: usize = 16;

/// A clipped polygon: its vertices in f64, in order.
type Poly = [[f64; 3]; CAP];

/// Bounds of the part of `tri` inside `b` (Sutherland–Hodgman against the six planes, in f64,
/// rounded outward to f32 and clamped to `b`), or [`Aabb::EMPTY`] when it misses `b`.
///
/// Guarantees: the result contains every point of `tri` that lies in `b` (when rounding leaves the
/// clipped polygon empty or odd, it falls back to the triangle's bounds clamped to `b`, which is
/// larger and still right).
pub(super) fn clipped_bounds(tri: &[Vec3; 3], b: &Aabb) -> Aabb {
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

#[cfg(test)]
mod tests {
    use super::*;

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
