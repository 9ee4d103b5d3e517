//! SAH kd-tree construction after Wald & Havran (2006), "On building fast kd-trees for ray tracing,
//! and on doing that in O(N log N)": each axis keeps one list of split events, sorted once at the
//! root and kept in order through every split, and triangles that straddle a split are clipped to
//! each child box ("perfect splits") so their events describe only the part inside.
//!
//! Every array is charged to the build's [`MemoryBudget`] before it is allocated.

use alloc::vec::Vec;
use glam::{DVec3, Vec3};

use super::node::{KdNode, MAX_NODE_FIELD};
use super::{KdTreeParams, MAX_DEPTH};
use crate::accel::Aabb;
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;

/// A split event: the position (as order-preserving bits) in the high word, the kind in the top two
/// bits of the low word and the triangle in the other 30, so that sorting the raw `u64` orders events
/// by position, then end < planar < start, then triangle id.
type Event = u64;

const END: u32 = 0;
const PLANAR: u32 = 1;
const START: u32 = 2;
/// The largest triangle id an event can carry.
const PRIM_MASK: u32 = (1 << 30) - 1;

/// Which side of a split a triangle goes to (scratch, per triangle).
const BOTH: u8 = 0;
const LEFT: u8 = 1;
const RIGHT: u8 = 2;

/// Maps a finite f32 to bits whose unsigned order is the number's order (`-0.0` counts as `0.0`).
#[inline]
fn ordered(x: f32) -> u32 {
    let b = (x + 0.0).to_bits();
    if b >> 31 == 1 {
        !b
    } else {
        b | 0x8000_0000
    }
}

#[inline]
fn unordered(u: u32) -> f32 {
    f32::from_bits(if u >> 31 == 1 { u & 0x7fff_ffff } else { !u })
}

#[inline]
fn event(pos: f32, kind: u32, prim: u32) -> Event {
    (u64::from(ordered(pos)) << 32) | u64::from((kind << 30) | prim)
}

#[inline]
fn pos_key(e: Event) -> u32 {
    (e >> 32) as u32
}

#[inline]
fn kind(e: Event) -> u32 {
    (e as u32) >> 30
}

#[inline]
fn prim(e: Event) -> u32 {
    e as u32 & PRIM_MASK
}

/// The events of a triangle whose part inside the node is `b`, one or two per axis.
fn push_events(lists: &mut [Vec<Event>; 3], b: &Aabb, p: u32) {
    for (k, list) in lists.iter_mut().enumerate() {
        if b.min[k] == b.max[k] {
            list.push(event(b.min[k], PLANAR, p));
        } else {
            list.push(event(b.min[k], START, p));
            list.push(event(b.max[k], END, p));
        }
    }
}

/// What the builder returns.
pub(super) struct Built {
    pub nodes: Vec<KdNode>,
    pub prims: Vec<u32>,
    pub depth: u32,
    pub leaves: u32,
}

/// The chosen split of a node.
#[derive(Clone, Copy, Debug)]
struct Split {
    axis: usize,
    pos: f32,
    /// Triangles lying in the split plane go to the lower child.
    planar_left: bool,
    /// Triangles each child gets, as the sweep counted them (clipping can only lower them).
    left: usize,
    right: usize,
}

struct Builder<'a> {
    mesh: &'a TriMesh,
    params: KdTreeParams,
    budget: &'a mut MemoryBudget,
    nodes: Vec<KdNode>,
    prims: Vec<u32>,
    side: Vec<u8>,
    max_depth: u32,
    depth: u32,
    leaves: u32,
    /// References held by the leaves made so far plus the nodes still to be built.
    refs: usize,
    refs_limit: usize,
}

/// The depth limit for `live` triangles: `8 + 1.3·log2 N` (as pbrt), at most [`MAX_DEPTH`].
pub(super) fn auto_depth(live: usize) -> u32 {
    let log2 = usize::BITS - live.max(1).leading_zeros() - 1;
    (8 + 13 * log2 / 10).min(MAX_DEPTH)
}

/// Builds the tree over the non-degenerate triangles of `mesh` inside `root`.
pub(super) fn build(
    mesh: &TriMesh,
    params: &KdTreeParams,
    root: Aabb,
    budget: &mut MemoryBudget,
) -> Result<Built, BuildError> {
    let live = mesh.len() - mesh.degenerate_count();
    if mesh.len() > PRIM_MASK as usize {
        return Err(BuildError::CapacityExceeded {
            what: "kd-tree triangle ids (at most 2^30 triangles)",
        });
    }
    let mut lists = [Vec::new(), Vec::new(), Vec::new()];
    for list in lists.iter_mut() {
        *list = match budget.vec(2 * live, "kd-tree build events") {
            Ok(v) => v,
            Err(e) => {
                free_lists(budget, core::mem::take(&mut lists));
                return Err(e);
            }
        };
    }
    for (i, tri) in mesh.triangles().iter().enumerate() {
        if !mesh.is_degenerate(i as u32) {
            push_events(&mut lists, &Aabb::of_triangle(tri), i as u32);
        }
    }
    for list in lists.iter_mut() {
        list.sort_unstable();
    }
    let side = match budget.filled(mesh.len(), BOTH, "kd-tree build scratch") {
        Ok(s) => s,
        Err(e) => {
            free_lists(budget, lists);
            return Err(e);
        }
    };
    let max_depth = if params.max_depth == 0 {
        auto_depth(live)
    } else {
        params.max_depth.min(MAX_DEPTH)
    };
    let refs_limit = (f64::from(params.max_references_per_triangle) * live as f64) as usize;
    let mut b = Builder {
        mesh,
        params: *params,
        budget,
        nodes: Vec::new(),
        prims: Vec::new(),
        side,
        max_depth,
        depth: 0,
        leaves: 0,
        refs: live,
        refs_limit: refs_limit.max(live),
    };
    let result = b.node(lists, live, root, 0);
    let Builder {
        budget,
        nodes,
        prims,
        side,
        depth,
        leaves,
        ..
    } = b;
    budget.free(side);
    match result {
        Ok(()) => Ok(Built {
            nodes,
            prims,
            depth,
            leaves,
        }),
        Err(e) => {
            budget.free(nodes);
            budget.free(prims);
            Err(e)
        }
    }
}

fn free_lists(budget: &mut MemoryBudget, lists: [Vec<Event>; 3]) {
    for l in lists {
        budget.free(l);
    }
}

/// Surface area of a box with edge lengths `e` (f64: small children of large boxes stay exact
/// enough to compare).
#[inline]
fn area(e: [f64; 3]) -> f64 {
    2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
}

impl Builder<'_> {
    /// Builds the subtree of a node with `n` triangles described by `lists`, inside `bbox`, at
    /// `depth`; the node goes at the end of `nodes`.
    fn node(
        &mut self,
        lists: [Vec<Event>; 3],
        n: usize,
        bbox: Aabb,
        depth: u32,
    ) -> Result<(), BuildError> {
        let index = self.nodes.len();
        if index > MAX_NODE_FIELD as usize {
            free_lists(self.budget, lists);
            return Err(BuildError::CapacityExceeded {
                what: "kd-tree nodes (at most 2^30)",
            });
        }
        if let Err(e) = self
            .budget
            .push(&mut self.nodes, KdNode::leaf(0, 0), "kd-tree nodes")
        {
            free_lists(self.budget, lists);
            return Err(e);
        }
        self.depth = self.depth.max(depth);
        let split = if depth >= self.max_depth || n <= self.params.max_leaf_prims as usize {
            None
        } else {
            self.find_split(&lists, n, &bbox)
                .filter(|s| (self.refs + s.left + s.right).saturating_sub(n) <= self.refs_limit)
        };
        let Some(split) = split else {
            return self.leaf(index, lists);
        };
        let (mut left_box, mut right_box) = (bbox, bbox);
        left_box.max[split.axis] = split.pos;
        right_box.min[split.axis] = split.pos;
        let (left, nl, right, nr) = self.split_events(lists, &split, &left_box, &right_box)?;
        self.refs = (self.refs + nl + nr).saturating_sub(n);
        if let Err(e) = self.node(left, nl, left_box, depth + 1) {
            free_lists(self.budget, right);
            return Err(e);
        }
        let above = self.nodes.len();
        if above > MAX_NODE_FIELD as usize {
            free_lists(self.budget, right);
            return Err(BuildError::CapacityExceeded {
                what: "kd-tree nodes (at most 2^30)",
            });
        }
        self.nodes[index] = KdNode::interior(split.axis, split.pos, above as u32);
        self.node(right, nr, right_box, depth + 1)
    }

    /// Makes node `index` a leaf of the triangles in `lists`.
    fn leaf(&mut self, index: usize, lists: [Vec<Event>; 3]) -> Result<(), BuildError> {
        self.leaves += 1;
        let mut members = lists[0]
            .iter()
            .filter(|&&e| kind(e) != END)
            .map(|&e| prim(e));
        let count = lists[0].iter().filter(|&&e| kind(e) != END).count();
        let result = if count > MAX_NODE_FIELD as usize {
            Err(BuildError::CapacityExceeded {
                what: "kd-tree leaf size (at most 2^30)",
            })
        } else if count == 1 {
            self.nodes[index] = KdNode::leaf(1, members.next().unwrap_or(0));
            Ok(())
        } else {
            let offset = self.prims.len();
            if offset + count > u32::MAX as usize {
                Err(BuildError::CapacityExceeded {
                    what: "kd-tree references (at most 2^32)",
                })
            } else {
                let mut r = Ok(());
                for p in members {
                    r = self
                        .budget
                        .push(&mut self.prims, p, "kd-tree leaf references");
                    if r.is_err() {
                        break;
                    }
                }
                self.nodes[index] = KdNode::leaf(count as u32, offset as u32);
                r
            }
        };
        free_lists(self.budget, lists);
        result
    }

    /// The cheapest split by the surface area heuristic, or `None` when no split is cheaper than a
    /// leaf. Candidates are the event positions strictly inside the box (a plane on the box's face
    /// would make a child of no volume).
    fn find_split(&self, lists: &[Vec<Event>; 3], n: usize, bbox: &Aabb) -> Option<Split> {
        let ext = bbox.extent();
        let ext = [f64::from(ext.x), f64::from(ext.y), f64::from(ext.z)];
        let sa = area(ext);
        if !(sa > 0.0) {
            return None;
        }
        let p = &self.params;
        let (ct, ci) = (f64::from(p.traversal_cost), f64::from(p.intersection_cost));
        let keep = 1.0 - f64::from(p.empty_bonus);
        let mut best_cost = ci * n as f64;
        let mut best = None;
        for (k, list) in lists.iter().enumerate() {
            let (lo, hi) = (bbox.min[k], bbox.max[k]);
            if !(lo < hi) {
                continue;
            }
            let (mut nl, mut nr) = (0usize, n);
            let mut i = 0;
            while i < list.len() {
                let key = pos_key(list[i]);
                let count = |i: &mut usize, want: u32| {
                    let start = *i;
                    while *i < list.len() && pos_key(list[*i]) == key && kind(list[*i]) == want {
                        *i += 1;
                    }
                    *i - start
                };
                let ends = count(&mut i, END);
                let planars = count(&mut i, PLANAR);
                let starts = count(&mut i, START);
                nr -= planars + ends;
                let pos = unordered(key);
                if lo < pos && pos < hi {
                    let mut le = ext;
                    le[k] = f64::from(pos) - f64::from(lo);
                    let mut re = ext;
                    re[k] = f64::from(hi) - f64::from(pos);
                    let (pl, pr) = (area(le) / sa, area(re) / sa);
                    let cost = |l: usize, r: usize| {
                        let c = ct + ci * (pl * l as f64 + pr * r as f64);
                        if l == 0 || r == 0 {
                            c * keep
                        } else {
                            c
                        }
                    };
                    let (c_left, c_right) = (cost(nl + planars, nr), cost(nl, nr + planars));
                    let planar_left = c_left <= c_right;
                    let c = c_left.min(c_right);
                    if c < best_cost {
                        best_cost = c;
                        best = Some(Split {
                            axis: k,
                            pos,
                            planar_left,
                            left: nl + if planar_left { planars } else { 0 },
                            right: nr + if planar_left { 0 } else { planars },
                        });
                    }
                }
                nl += starts + planars;
            }
        }
        best
    }

    /// Splits the parent's event lists into the children's, in order, clipping the triangles that
    /// straddle the plane to each child box. Frees the parent's lists.
    #[allow(clippy::type_complexity)]
    fn split_events(
        &mut self,
        lists: [Vec<Event>; 3],
        split: &Split,
        left_box: &Aabb,
        right_box: &Aabb,
    ) -> Result<([Vec<Event>; 3], usize, [Vec<Event>; 3], usize), BuildError> {
        let (k, p) = (split.axis, split.pos);
        let side = &mut self.side;
        for &e in &lists[k] {
            side[prim(e) as usize] = BOTH;
        }
        let mut straddlers = 0usize;
        let (mut only_left, mut only_right) = (0usize, 0usize);
        for &e in &lists[k] {
            let pos = unordered(pos_key(e));
            let s = &mut side[prim(e) as usize];
            match kind(e) {
                END if pos <= p => *s = LEFT,
                START if pos >= p => *s = RIGHT,
                PLANAR => {
                    *s = if pos < p || (pos == p && split.planar_left) {
                        LEFT
                    } else {
                        RIGHT
                    }
                }
                _ => {}
            }
        }
        for &e in &lists[k] {
            if kind(e) != END {
                match side[prim(e) as usize] {
                    LEFT => only_left += 1,
                    RIGHT => only_right += 1,
                    _ => straddlers += 1,
                }
            }
        }
        // The clipped events of the straddling triangles, per side and axis, sorted.
        let mut new_left = [Vec::new(), Vec::new(), Vec::new()];
        let mut new_right = [Vec::new(), Vec::new(), Vec::new()];
        let (mut nl, mut nr) = (only_left, only_right);
        let r = (|| {
            for a in 0..3 {
                new_left[a] = self.budget.vec(2 * straddlers, "kd-tree build events")?;
                new_right[a] = self.budget.vec(2 * straddlers, "kd-tree build events")?;
            }
            Ok::<(), BuildError>(())
        })();
        if let Err(e) = r {
            free_lists(self.budget, lists);
            free_lists(self.budget, new_left);
            free_lists(self.budget, new_right);
            return Err(e);
        }
        let tris = self.mesh.triangles();
        for &e in &lists[k] {
            let id = prim(e);
            if kind(e) != START || self.side[id as usize] != BOTH {
                continue;
            }
            let Some(tri) = tris.get(id as usize) else {
                continue;
            };
            let lb = clipped_bounds(tri, left_box);
            if !lb.is_empty() {
                push_events(&mut new_left, &lb, id);
                nl += 1;
            }
            let rb = clipped_bounds(tri, right_box);
            if !rb.is_empty() {
                push_events(&mut new_right, &rb, id);
                nr += 1;
            }
        }
        for a in 0..3 {
            new_left[a].sort_unstable();
            new_right[a].sort_unstable();
        }
        let mut left = [Vec::new(), Vec::new(), Vec::new()];
        let mut right = [Vec::new(), Vec::new(), Vec::new()];
        let mut failed = None;
        for a in 0..3 {
            let mut cl = 0;
            let mut cr = 0;
            for &e in &lists[a] {
                match self.side[prim(e) as usize] {
                    LEFT => cl += 1,
                    RIGHT => cr += 1,
                    _ => {}
                }
            }
            let l = self
                .budget
                .vec(cl + new_left[a].len(), "kd-tree build events");
            let r = self
                .budget
                .vec(cr + new_right[a].len(), "kd-tree build events");
            match (l, r) {
                (Ok(l), Ok(r)) => {
                    left[a] = l;
                    right[a] = r;
                }
                (l, r) => {
                    failed = l.as_ref().err().or(r.as_ref().err()).copied();
                    for v in [l, r].into_iter().flatten() {
                        self.budget.free(v);
                    }
                    break;
                }
            }
            let side = &self.side;
            merge(
                &mut left[a],
                lists[a]
                    .iter()
                    .copied()
                    .filter(|&e| side[prim(e) as usize] == LEFT),
                &new_left[a],
            );
            merge(
                &mut right[a],
                lists[a]
                    .iter()
                    .copied()
                    .filter(|&e| side[prim(e) as usize] == RIGHT),
                &new_right[a],
            );
        }
        free_lists(self.budget, lists);
        free_lists(self.budget, new_left);
        free_lists(self.budget, new_right);
        if let Some(e) = failed {
            free_lists(self.budget, left);
            free_lists(self.budget, right);
            return Err(e);
        }
        Ok((left, nl, right, nr))
    }
}

/// Appends the merge of two sorted sequences to `out` (which has room for both).
fn merge(out: &mut Vec<Event>, a: impl Iterator<Item = Event>, b: &[Event]) {
    let mut b = b.iter().copied().peekable();
    for x in a {
        while let Some(&y) = b.peek() {
            if y < x {
                out.push(y);
                b.next();
            } else {
                break;
            }
        }
        out.push(x);
    }
    out.extend(b);
}

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

/// Bounds of the part of `tri` inside `b` (Sutherland–Hodgman against the six planes, in f64,
/// rounded outward to f32 and clamped to `b`), or [`Aabb::EMPTY`] when it misses `b`.
///
/// Guarantees: the result contains every point of `tri` that lies in `b` (when rounding leaves the
/// clipped polygon empty or odd, it falls back to the triangle's bounds clamped to `b`, which is
/// larger and still right).
fn clipped_bounds(tri: &[Vec3; 3], b: &Aabb) -> Aabb {
    let fallback = || {
        let t = Aabb::of_triangle(tri);
        let c = Aabb {
            min: t.min.max(b.min),
            max: t.max.min(b.max),
        };
        if c.is_empty() {
            Aabb::EMPTY
        } else {
            c
        }
    };
    const CAP: usize = 16;
    let tb = Aabb::of_triangle(tri);
    // Two buffers used in turn, so a clip copies no more than the vertices it keeps.
    let mut buf = [[DVec3::ZERO; CAP]; 2];
    for (slot, v) in buf[0].iter_mut().zip(tri) {
        *slot = v.as_dvec3();
    }
    let (mut from, mut n) = (0usize, 3usize);
    for axis in 0..3 {
        for keep_above in [true, false] {
            // A plane the triangle's bounds do not cross clips nothing.
            let bound = if keep_above {
                if tb.min[axis] >= b.min[axis] {
                    continue;
                }
                f64::from(b.min[axis])
            } else {
                if tb.max[axis] <= b.max[axis] {
                    continue;
                }
                f64::from(b.max[axis])
            };
            let inside = |p: &DVec3| {
                if keep_above {
                    p[axis] >= bound
                } else {
                    p[axis] <= bound
                }
            };
            let (src, dst) = if from == 0 {
                let (x, y) = buf.split_at_mut(1);
                (&x[0], &mut y[0])
            } else {
                let (x, y) = buf.split_at_mut(1);
                (&y[0], &mut x[0])
            };
            let mut m = 0;
            for i in 0..n {
                let cur = src[i];
                let nxt = src[if i + 1 == n { 0 } else { i + 1 }];
                let (ci, ni) = (inside(&cur), inside(&nxt));
                if ci {
                    if m == CAP {
                        return fallback();
                    }
                    dst[m] = cur;
                    m += 1;
                }
                if ci != ni {
                    if m == CAP {
                        return fallback();
                    }
                    let t = (bound - cur[axis]) / (nxt[axis] - cur[axis]);
                    let mut x = cur + (nxt - cur) * t;
                    x[axis] = bound;
                    dst[m] = x;
                    m += 1;
                }
            }
            from = 1 - from;
            n = m;
            if n == 0 {
                return fallback();
            }
        }
    }
    let poly = &buf[from];
    let mut lo = poly[0];
    let mut hi = poly[0];
    for p in &poly[1..n] {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let c = Aabb {
        min: Vec3::new(round_down(lo.x), round_down(lo.y), round_down(lo.z)).max(b.min),
        max: Vec3::new(round_up(hi.x), round_up(hi.y), round_up(hi.z)).min(b.max),
    };
    if c.is_empty() {
        fallback()
    } else {
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ordered_bits_sort_like_numbers() {
        let xs = [-3.0e38f32, -1.0, -1e-40, -0.0, 0.0, 1e-40, 1.0, 3.0e38];
        for w in xs.windows(2) {
            assert!(ordered(w[0]) <= ordered(w[1]), "{w:?}");
            assert_eq!(unordered(ordered(w[1])), w[1]);
        }
        assert_eq!(ordered(-0.0), ordered(0.0));
        let e = event(2.5, PLANAR, 12345);
        assert_eq!(
            (unordered(pos_key(e)), kind(e), prim(e)),
            (2.5, PLANAR, 12345)
        );
        assert!(event(1.0, END, 9) < event(1.0, PLANAR, 0));
        assert!(event(1.0, PLANAR, 9) < event(1.0, START, 0));
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
