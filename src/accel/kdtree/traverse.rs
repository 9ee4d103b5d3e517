//! Front-to-back traversal with a fixed on-stack stack (Havran's TA_B_rec family), widened so that
//! the traversal's own rounding can never hide a hit.
//!
//! Why the widening is enough: a hit at exact `t` is a point `P` of the ray inside a triangle, and
//! the triangle is referenced by a leaf whose closed box holds `P` (clipping rounds outward). Each
//! split's `t = (s − o)·(1/d)` is computed with a relative error below 3 f32 roundings, and the hit's
//! reported `t` is within half an ulp of the exact one; widening every node's interval by 8 ulps of
//! its ends therefore keeps the reported `t` inside the interval of every node on the way to that
//! leaf. A subtree is skipped only when the best hit so far is strictly before its widened entry, so
//! a nearer hit, or an equally near one with a lower id, is never skipped.

use super::{KdTree, KdWork, MAX_DEPTH};
use crate::accel::{test_refs, Mailbox, Refs};
use crate::mesh::TriMesh;
use crate::ray::Hit;
use crate::triangle::{TriangleLoop, TriangleTest};

/// Room for one pending far child per level of the deepest tree.
const STACK_SIZE: usize = MAX_DEPTH as usize + 4;

/// Relative rounding slack of a computed `t` (8 ulps).
const T_SLACK: f32 = 8.0 * f32::EPSILON;

/// Absolute slack of a computed `t`: four of the smallest subnormal steps, for a `t` that underflows
/// (whose relative error is then not bounded by `T_SLACK`).
const T_FLOOR: f32 = 5.6e-45;

/// `t` widened by its rounding slack: `(t − w, t + w)`. An infinite `t` stays infinite (the slack is
/// capped at `f32::MAX`, so `−∞ + w` is not NaN); a NaN stays NaN, which the callers read as "no
/// constraint".
#[inline(always)]
fn widened(t: f32) -> (f32, f32) {
    let w = t.abs() * T_SLACK + T_FLOOR;
    let w = if w < f32::MAX { w } else { f32::MAX };
    (t - w, t + w)
}

#[derive(Clone, Copy)]
struct Pending {
    node: u32,
    t0: f32,
    t1: f32,
}

/// One query's walk. `COUNT` counts the work; `ANY` stops at the first hit.
pub(super) struct Walk<'a, const COUNT: bool, const ANY: bool> {
    pub tree: &'a KdTree,
    pub mesh: &'a TriMesh,
    pub work: &'a mut KdWork,
}

impl<const COUNT: bool, const ANY: bool> TriangleLoop for Walk<'_, COUNT, ANY> {
    type Output = Hit;

    #[inline(always)]
    fn run<T: TriangleTest>(self, test: T) -> Hit {
        let Walk { tree, mesh, work } = self;
        let r = test.ray();
        let mut best = Hit::MISS;
        let mut mailbox = Mailbox::new();
        if tree.bounds.is_empty() {
            return best;
        }
        // Per ray, per axis: the origin, `1/d`, and whether the ray runs downwards (its near child
        // is the upper one). `1/d` is `±∞` for a zero component, which makes every split `t` on
        // that axis `±∞` (the ray never crosses the plane: the near child holds the origin when `t`
        // is `+∞`, the far one when `−∞`) or NaN when the origin is on the plane (both children:
        // the ray lies in the plane, which both closed boxes hold). A component whose inverse
        // overflows, or underflows (so its relative error is unbounded), gets NaN: no constraint on
        // that axis, every split visits both sides. Arrays of four, indexed `& 3`, need no checks.
        let (o, d) = (r.org, r.dir);
        let mut org = [0.0f32; 4];
        let mut inv = [0.0f32; 4];
        let mut down = [0u32; 4];
        let (mut t0, mut t1) = (r.tmin, r.tmax);
        let (lo, hi) = (tree.bounds.min, tree.bounds.max);
        for a in 0..3 {
            org[a] = o[a];
            down[a] = u32::from(d[a].is_sign_negative());
            if d[a] == 0.0 {
                // The box is the triangles' exact bounds: a ray outside its slab misses them all.
                if o[a] < lo[a] || o[a] > hi[a] {
                    return best;
                }
                inv[a] = 1.0 / d[a];
                continue;
            }
            let ia = 1.0 / d[a];
            if !(ia.is_finite() && ia.abs() >= f32::MIN_POSITIVE) {
                inv[a] = f32::NAN;
                continue;
            }
            inv[a] = ia;
            let (ta, tb) = ((lo[a] - o[a]) * ia, (hi[a] - o[a]) * ia);
            let (near, far) = if ta < tb { (ta, tb) } else { (tb, ta) };
            let (near, _) = widened(near);
            let (_, far) = widened(far);
            t0 = if near > t0 { near } else { t0 };
            t1 = if far < t1 { far } else { t1 };
        }
        if !(t0 <= t1) {
            return best;
        }
        let nodes = &tree.nodes[..];
        // Entries are written before they are read (`sp` counts the written ones), so the array
        // needs no initialisation.
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
                let a = node.axis() & 3;
                // Near and far children (the near one is the upper for a ray running down the axis),
                // and whether each is an empty leaf (not worth a visit).
                let flip = down[a];
                let near = node.children() + flip;
                let far = node.children() + (flip ^ 1);
                let empty = node.empty_children();
                let near_empty = (empty >> flip) & 1 != 0;
                let far_empty = (empty >> (flip ^ 1)) & 1 != 0;
                let (ts_lo, ts_hi) = widened((node.split() - org[a]) * inv[a]);
                // Comparisons, not `min`/`max`: a NaN bound compares false and leaves the interval
                // whole, which is what an axis without constraint needs.
                let near_t1 = if ts_hi < t1 { ts_hi } else { t1 };
                let far_t0 = if ts_lo > t0 { ts_lo } else { t0 };
                let go_near = !near_empty && near_t1 >= t0;
                let go_far = !far_empty && far_t0 <= t1;
                if go_near {
                    if go_far {
                        // The depth bound (≤ MAX_DEPTH < STACK_SIZE) leaves room: one entry per level.
                        debug_assert!(sp < STACK_SIZE);
                        if let Some(slot) = stack.get_mut(sp) {
                            slot.write(Pending {
                                node: far,
                                t0: far_t0,
                                t1,
                            });
                            sp += 1;
                        }
                    }
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
