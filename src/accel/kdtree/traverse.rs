//! Front-to-back traversal with a fixed on-stack stack (Havran's TA_B_rec family), widened so that
//! the traversal's own rounding can never hide a hit.
//!
//! Why the widening is enough: a hit at exact `t` is a point `P` of the ray inside a triangle, and
//! the triangle is referenced by a leaf whose closed box holds `P` (clipping rounds outward). The
//! hit's reported `t` is within half an ulp of the exact one, so it is enough that every node's
//! interval holds the exact split crossings widened by a few ulps. At the root the box's crossings
//! are computed and widened by 8 ulps (`slack`). At a split, `t = (s − o)/d` is bracketed by
//! the two products of `fl(s − o)` with `1/d` rounded and scaled by `1 ± 2^-20` (16 ulps, once per
//! ray): four roundings of relative size `2^-24` each leave the larger product at least 11 ulps
//! beyond the exact `t` and the smaller one as far below (no product overflows: an axis whose box
//! faces' `t` reach `f32::MAX / 4`, or whose `lo − o` overflows, is left unconstrained by
//! `Clip::new`); underflow adds at most half a subnormal unit, covered by `T_FLOOR` on each side. A
//! subtree is skipped only when the best hit so far is strictly before its widened entry, so a
//! nearer hit, or an equally near one with a lower id, is never skipped.

use super::node::{EMPTY_ABOVE, EMPTY_BELOW};
use super::{KdTree, KdWork, MAX_DEPTH};
use crate::accel::{test_refs, Mailbox, Refs};
use crate::mesh::TriMesh;
use crate::ray::{Aabb, Hit, Ray};
use crate::triangle::{TriangleLoop, TriangleTest};
use glam::Vec3A;

/// Room for one pending far child per level of the deepest tree.
const STACK_SIZE: usize = MAX_DEPTH as usize + 4;

/// Relative rounding slack of a computed `t` (8 ulps).
const T_SLACK: f32 = 8.0 * f32::EPSILON;

/// Absolute slack of a computed `t`: four of the smallest subnormal steps, for a `t` that underflows
/// (whose relative error is then not bounded by `T_SLACK`).
const T_FLOOR: f32 = 5.6e-45;

/// The rounding slack of computed `t`s, per lane: `|t|·T_SLACK + T_FLOOR`, capped at `f32::MAX` so
/// that an infinite `t` stays infinite when widened (`−∞ + w` is not NaN); a NaN stays NaN.
#[inline(always)]
fn slack(t: Vec3A) -> Vec3A {
    let w = t.abs() * T_SLACK + Vec3A::splat(T_FLOOR);
    Vec3A::select(w.cmplt(Vec3A::splat(f32::MAX)), w, Vec3A::splat(f32::MAX))
}

/// Relative slack of the split crossings' brackets: `2^-20` (16 ulps of f32), exact in `1 ± SLACK`.
const SPLIT_SLACK: f32 = 1.0 / 1_048_576.0;

/// What a split on one axis needs of the ray, made once per ray.
#[derive(Clone, Copy, Default)]
struct AxisRay {
    org: f32,
    /// `1/d` times `1 − SPLIT_SLACK` and `1 + SPLIT_SLACK`.
    inv_dn: f32,
    inv_up: f32,
    /// The node bit flagging the near child as empty ([`EMPTY_BELOW`] or [`EMPTY_ABOVE`]; the far
    /// child's is the other). Four fields: 16 bytes, so an axis's constants are one shift away.
    near_empty: u32,
}

/// Both children's empty flags: `near_empty ^ BOTH_EMPTY` is the far child's.
const BOTH_EMPTY: u32 = EMPTY_BELOW | EMPTY_ABOVE;

#[derive(Clone, Copy)]
struct Pending {
    node: u32,
    t0: f32,
    t1: f32,
}

/// A ray's interval inside the tree's box and its per-axis constants: what the walk needs before
/// its first node, made before the triangle test's per-ray constants are, so that a ray that misses
/// the box pays for nothing else.
#[derive(Clone, Copy)]
pub(super) struct Clip {
    axes: [AxisRay; 4],
    /// Bit `a` set when the ray runs down axis `a` (its near child there is the upper one): read
    /// from a register by the walk, not from the axis's constants in memory, so that the next
    /// node's index waits for one load (the node's), not two.
    down: u32,
    t0: f32,
    t1: f32,
}

impl Clip {
    /// The clip of `ray` to `bounds` (the tree's box), or `None` when the ray misses it (or the
    /// box is empty). A ray the triangle test refuses (a NaN or infinite component) may get either;
    /// the query refuses it after.
    ///
    /// Per axis: the origin, `1/d` scaled down and up by the slack and the node bit that flags its
    /// near child as empty; and a bit per axis saying whether the ray runs downwards (its near
    /// child is the upper one). `1/d` is `±∞` for a zero component, which makes every split `t` on
    /// that axis `±∞` (the ray never crosses the plane: the near child holds the origin when `t` is
    /// `+∞`, the far one when `−∞`) or NaN when the origin is on the plane (both children: the ray
    /// lies in the plane, which both closed boxes hold). A component whose inverse overflows, or
    /// underflows (so its relative error is unbounded), or whose box faces' `t` are not safely
    /// finite, gets NaN: no constraint on that axis, every split visits both sides. An array of
    /// four, indexed by the node's 2-bit axis, needs no checks.
    #[inline(always)]
    pub(super) fn new(ray: &Ray, bounds: &Aabb) -> Option<Clip> {
        if bounds.is_empty() {
            return None;
        }
        // The three axes at once (the fourth lane unused): per lane the same IEEE operations as
        // one axis alone, and the SSE `min`/`max` meet no NaN where it matters — a bounded
        // inverse times a finite difference is never NaN (at most ±∞ where the difference
        // overflows), and the other lanes are replaced before they are compared (a ray with a
        // non-finite origin is refused after, whatever its clip).
        let (o, d) = (Vec3A::from(ray.org), Vec3A::from(ray.dir));
        let (lo, hi) = (Vec3A::from(bounds.min), Vec3A::from(bounds.max));
        let zero = d.cmpeq(Vec3A::ZERO);
        // The box is the triangles' exact bounds: a ray parallel to a slab it is outside of
        // misses them all.
        if (zero & (o.cmplt(lo) | o.cmpgt(hi))).any() {
            return None;
        }
        let inv = Vec3A::ONE / d;
        let magnitude = inv.abs();
        let bounded =
            magnitude.cmplt(Vec3A::INFINITY) & magnitude.cmpge(Vec3A::splat(f32::MIN_POSITIVE));
        let (ta, tb) = ((lo - o) * inv, (hi - o) * inv);
        // An axis whose face `t` is not safely finite (`lo − o` itself may overflow f32 when the
        // coordinates do not: an origin at −3·10³⁸ and a box at 10³⁸) bounds nothing: no
        // constraint there, every split on it visits both sides. Below `f32::MAX / 4` every split's
        // bracket is finite too: a split lies in `[lo, hi]`, so (rounding being monotone)
        // `|fl(s − o)·inv|` is at most the larger face's `|t|`, and the bracket's slack is tiny.
        // (Without this the box's entry could be +∞ or its exit −∞, and a hit at a finite `t` was
        // lost: a review's rays from −3.4·10³⁸, 248 of 268 hits.)
        let safe = ta.abs().max(tb.abs()).cmplt(Vec3A::splat(f32::MAX * 0.25));
        let bounded = bounded & safe;
        let inv = Vec3A::select(bounded | zero, inv, Vec3A::NAN);
        let (near, far) = (ta.min(tb), ta.max(tb));
        let near = near - slack(near);
        let far = far + slack(far);
        let near = Vec3A::select(bounded, near, Vec3A::NEG_INFINITY).max_element();
        let far = Vec3A::select(bounded, far, Vec3A::INFINITY).min_element();
        let t0 = if near > ray.tmin { near } else { ray.tmin };
        let t1 = if far < ray.tmax { far } else { ray.tmax };
        if !(t0 <= t1) {
            return None;
        }
        let org = o.to_array();
        let dn = (inv * (1.0 - SPLIT_SLACK)).to_array();
        let up = (inv * (1.0 + SPLIT_SLACK)).to_array();
        let signs = d.is_negative_bitmask();
        let mut axes = [AxisRay::default(); 4];
        for (a, axis) in axes.iter_mut().take(3).enumerate() {
            let down = (signs >> a) & 1;
            *axis = AxisRay {
                org: org[a],
                inv_dn: dn[a],
                inv_up: up[a],
                near_empty: EMPTY_BELOW << down,
            };
        }
        Some(Clip {
            axes,
            down: signs & 7,
            t0,
            t1,
        })
    }
}

/// One query's walk of a ray already clipped to the tree's box (`clip`, from the same ray). `COUNT`
/// counts the work; `ANY` stops at the first hit.
pub(super) struct Walk<'a, const COUNT: bool, const ANY: bool> {
    pub tree: &'a KdTree,
    pub mesh: &'a TriMesh,
    pub work: &'a mut KdWork,
    pub clip: Clip,
}

impl<const COUNT: bool, const ANY: bool> TriangleLoop for Walk<'_, COUNT, ANY> {
    type Output = Hit;

    #[inline(always)]
    fn run<T: TriangleTest>(self, test: T) -> Hit {
        let Walk {
            tree,
            mesh,
            work,
            clip,
        } = self;
        let mut best = Hit::MISS;
        let mut mailbox = Mailbox::new();
        let Clip {
            axes,
            down,
            mut t0,
            mut t1,
        } = clip;
        let nodes = &tree.nodes[..];
        // Entries are written before they are read (the entries below `sp` are the pushed ones,
        // each written; the slot at `sp` may hold a write that was not pushed), so the array needs
        // no initialisation.
        let mut stack = [core::mem::MaybeUninit::<Pending>::uninit(); STACK_SIZE];
        let mut sp = 0usize;
        let mut index = 0u32;
        loop {
            debug_assert!((index as usize) < nodes.len());
            // SAFETY: `index` is 0 (the root; a built tree has at least one node) or a child index
            // the builder wrote (`children` or `children + 1` of an interior node, both allocated
            // when it was split), all below `nodes.len()`.
            let node = unsafe { *nodes.get_unchecked(index as usize) };
            if COUNT {
                work.nodes += 1;
            }
            if !node.is_leaf() {
                let ax = &axes[node.axis() & 3];
                let bits = node.bits();
                // The split's crossing, bracketed (module docs). Comparisons, not `min`/`max`: a
                // NaN compares false and leaves the interval whole, which is what an axis without
                // constraint needs.
                let diff = node.split() - ax.org;
                let (p, q) = (diff * ax.inv_dn, diff * ax.inv_up);
                let (ts_lo, ts_hi) = if p < q { (p, q) } else { (q, p) };
                let (ts_lo, ts_hi) = (ts_lo - T_FLOOR, ts_hi + T_FLOOR);
                let near_t1 = if ts_hi < t1 { ts_hi } else { t1 };
                let far_t0 = if ts_lo > t0 { ts_lo } else { t0 };
                // Children pairs start at even indices, so the far child is the near one's sibling.
                let near = node.children() + ((down >> node.axis()) & 1);
                let far = near ^ 1;
                let go_near = bits & ax.near_empty == 0 && near_t1 >= t0;
                let go_far = (bits & (ax.near_empty ^ BOTH_EMPTY) == 0) & (far_t0 <= t1);
                // The far child is written whether or not it is pushed, and `sp` moves by a
                // flag: whether a ray crosses the split inside its interval is what a predictor
                // cannot learn, so a branch on it mispredicts about half the time (hence `&`, not
                // `&&`, in `go_far`: a short circuit is a branch too). Whether it enters the near
                // child at all is a branch: a select there would make the next node's load wait
                // for the float compares.
                // `sp` never exceeds the current node's depth (one entry per ancestor at most), and
                // an interior node's depth is below MAX_DEPTH < STACK_SIZE: the slot exists.
                debug_assert!(sp < STACK_SIZE);
                // SAFETY: as just said, `sp < STACK_SIZE`.
                unsafe { stack.get_unchecked_mut(sp) }.write(Pending {
                    node: far,
                    t0: far_t0,
                    t1,
                });
                if go_near {
                    sp += go_far as usize;
                    index = near;
                    t1 = near_t1;
                    continue;
                }
                if go_far {
                    index = far;
                    t0 = far_t0;
                    continue;
                }
            } else {
                let start = node.offset() as usize;
                let end = start + node.count() as usize;
                if COUNT {
                    work.leaves += 1;
                    work.tests += node.count();
                }
                let refs = Refs {
                    ids: &tree.prims,
                    packs: &tree.packs,
                };
                if let Some(h) =
                    test_refs::<T, ANY>(&test, mesh, refs, (start, end), &mut best, &mut mailbox)
                {
                    return h;
                }
            }
            // Next pending subtree that may still hold a hit at or before the best one.
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                // SAFETY: entries below `sp` were written by the push above.
                let p = unsafe { stack.get_unchecked(sp).assume_init() };
                if !(best.t < p.t0) {
                    index = p.node;
                    t0 = p.t0;
                    t1 = p.t1;
                    break;
                }
            }
        }
    }
}
