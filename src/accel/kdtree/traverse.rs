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
        let (o, d) = (r.org, r.dir);
        let mut inv = [0.0f32; 3];
        let (mut t0, mut t1) = (r.tmin, r.tmax);
        let (lo, hi) = (tree.bounds.min, tree.bounds.max);
        for a in 0..3 {
            if d[a] == 0.0 {
                // The box is the triangles' exact bounds: a ray outside its slab misses them all.
                if o[a] < lo[a] || o[a] > hi[a] {
                    return best;
                }
                continue;
            }
            // `1/d` may be infinite for a denormal component; the intervals then become NaN or
            // infinite and the min/max below leave them unconstrained: slower, never wrong.
            inv[a] = 1.0 / d[a];
            let ta = (lo[a] - o[a]) * inv[a];
            let tb = (hi[a] - o[a]) * inv[a];
            let (near, far) = (ta.min(tb), ta.max(tb));
            t0 = t0.max(near - T_SLACK * near.abs());
            t1 = t1.min(far + T_SLACK * far.abs());
        }
        if !(t0 <= t1) {
            return best;
        }
        let nodes = &tree.nodes[..];
        let mut stack = [Pending {
            node: 0,
            t0: 0.0,
            t1: 0.0,
        }; STACK_SIZE];
        let mut sp = 0usize;
        let mut index = 0u32;
        loop {
            let Some(&node) = nodes.get(index as usize) else {
                return best;
            };
            if COUNT {
                work.nodes += 1;
            }
            if !node.is_leaf() {
                let a = node.axis() & 3;
                let a = if a == 3 { 2 } else { a };
                let s = node.split();
                let below = index + 1;
                let above = node.above();
                let (near, far, near_t1, far_t0);
                if d[a] == 0.0 {
                    // The ray never crosses the plane: the side holding the origin, and the other
                    // one too when the ray lies in the plane (both closed boxes hold it).
                    let on_below = o[a] < s;
                    (near, far) = if on_below {
                        (below, above)
                    } else {
                        (above, below)
                    };
                    near_t1 = t1;
                    far_t0 = if o[a] == s { t0 } else { f32::INFINITY };
                } else {
                    let ts = (s - o[a]) * inv[a];
                    let w = T_SLACK * ts.abs();
                    (near, far) = if d[a] > 0.0 {
                        (below, above)
                    } else {
                        (above, below)
                    };
                    // `min`/`max` ignore a NaN operand, which leaves the interval whole.
                    near_t1 = t1.min(ts + w);
                    far_t0 = t0.max(ts - w);
                }
                let go_near = near_t1 >= t0;
                let go_far = far_t0 <= t1;
                if go_near {
                    if go_far {
                        // The depth bound (≤ MAX_DEPTH < STACK_SIZE) leaves room: one entry per level.
                        if let Some(slot) = stack.get_mut(sp) {
                            *slot = Pending {
                                node: far,
                                t0: far_t0,
                                t1,
                            };
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
                let p = stack[sp];
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
