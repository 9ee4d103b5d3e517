//! SAH kd-tree construction after Wald & Havran (2006), "On building fast kd-trees for ray tracing,
//! and on doing that in O(N log N)": each axis keeps one list of split events, sorted once at the
//! root and kept in order through every split, and triangles that straddle a split are clipped to
//! each child box ("perfect splits") so their events describe only the part inside.
//!
//! Every array is charged to the build's [`MemoryBudget`] before it is allocated.

use alloc::vec::Vec;
use glam::Vec3;

use super::node::{KdNode, MAX_NODE_FIELD};
use super::{KdTreeParams, MAX_DEPTH};
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::{Aabb, Hit};
use crate::triangle::packs::TriangleLayout;

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
    /// The leaves' triangle ids (with `Hit::INVALID_ID` padding before block-aligned leaves).
    pub prims: Vec<u32>,
    pub depth: u32,
    pub leaves: u32,
    /// Triangle references held by the leaves (`prims` less its padding).
    pub references: usize,
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

/// Where a node's event lists start in the builder's per-axis event stacks; they run to the top.
type Starts = [usize; 3];

struct Builder<'a> {
    mesh: &'a TriMesh,
    params: KdTreeParams,
    budget: &'a mut MemoryBudget,
    nodes: Vec<KdNode>,
    prims: Vec<u32>,
    side: Vec<u8>,
    /// Per axis, the sorted events of the node being built (on top) and, below them, those of the
    /// upper children waiting for their lower siblings' subtrees: children's lists need no
    /// allocation of their own, and a finished subtree gives its space back by truncation.
    stack: [Vec<Event>; 3],
    /// Scratch reused by every split (each keeps its largest size): the straddling triangles and
    /// their clipped events, per child (lower, upper) and axis.
    straddlers: Vec<u32>,
    clipped: [[Vec<Event>; 3]; 2],
    /// The children's merged lists of a node with at most `scratch_limit` of them.
    merged: Vec<Event>,
    scratch_limit: usize,
    max_depth: u32,
    depth: u32,
    leaves: u32,
    /// Triangle references held by the leaves made so far.
    references: usize,
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
        side: Vec::new(),
        stack: Default::default(),
        straddlers: Vec::new(),
        clipped: Default::default(),
        merged: Vec::new(),
        // A quarter of the root's events per axis: at most 4 bytes per triangle.
        scratch_limit: (live / 2).max(1 << 10),
        max_depth,
        depth: 0,
        leaves: 0,
        references: 0,
        refs: live,
        refs_limit: refs_limit.max(live),
    };
    let result = b
        .root_events(live)
        .and_then(|()| b.node([0; 3], live, root, 0));
    let Builder {
        budget,
        nodes,
        prims,
        side,
        stack,
        straddlers,
        clipped,
        merged,
        depth,
        leaves,
        references,
        ..
    } = b;
    budget.free(side);
    budget.free(straddlers);
    budget.free(merged);
    for list in stack.into_iter().chain(clipped.into_iter().flatten()) {
        budget.free(list);
    }
    match result {
        Ok(()) => Ok(Built {
            nodes,
            prims,
            depth,
            leaves,
            references,
        }),
        Err(e) => {
            budget.free(nodes);
            budget.free(prims);
            Err(e)
        }
    }
}

/// The events of `list` from `from` on (empty when `from` is past the end).
#[inline]
fn tail(list: &[Event], from: usize) -> &[Event] {
    list.get(from..).unwrap_or(&[])
}

/// Makes `v` hold at least `cap` elements, keeping its contents, charging the growth to `budget`
/// before asking the allocator (fallibly). An empty `v` gets an exact new buffer (nothing to copy);
/// a non-empty one grows by at least an eighth, so a stack that creeps up is copied O(log) times.
fn grow<T: Copy>(
    budget: &mut MemoryBudget,
    v: &mut Vec<T>,
    cap: usize,
    what: &'static str,
) -> Result<(), BuildError> {
    if v.capacity() >= cap {
        return Ok(());
    }
    if v.is_empty() {
        budget.free(core::mem::take(v));
        *v = budget.vec(cap, what)?;
        return Ok(());
    }
    let cap = cap.max(v.capacity().saturating_add(v.capacity() / 8));
    let size = core::mem::size_of::<T>();
    let bytes = (cap - v.capacity())
        .checked_mul(size)
        .ok_or(BuildError::OutOfMemory {
            what,
            bytes: usize::MAX,
        })?;
    budget.charge(bytes, what)?;
    let before = v.capacity();
    if v.try_reserve_exact(cap - v.len()).is_err() {
        budget.release(bytes);
        return Err(BuildError::OutOfMemory { what, bytes });
    }
    // The allocator may round up; count what is really held so `free` balances.
    let extra = (v.capacity() - before).saturating_sub(cap - before) * size;
    if extra > 0 {
        budget.charge(extra, what)?;
    }
    Ok(())
}

/// Gives back most of a stack's buffer once it holds under a quarter of it, so the top levels'
/// high-water mark is not held while the tree's own arrays grow. Only when the copy (to twice the
/// length, so its cost is paid by the truncations that emptied the buffer) keeps the budget under
/// its peak so far: shrinking never raises the peak.
fn shrink(budget: &mut MemoryBudget, v: &mut Vec<Event>) {
    let smaller = 2 * v.len();
    if v.capacity() < 1 << 12 || v.len() >= v.capacity() / 4 {
        return;
    }
    let bytes = smaller * core::mem::size_of::<Event>();
    if budget.used().saturating_add(bytes) > budget.peak() {
        return;
    }
    if let Ok(mut buf) = budget.vec(smaller, "kd-tree build events") {
        buf.extend_from_slice(v);
        budget.free(core::mem::replace(v, buf));
    }
}

/// Surface area of a box with edge lengths `e` (f64: small children of large boxes stay exact
/// enough to compare).
#[inline]
fn area(e: [f64; 3]) -> f64 {
    2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
}

impl Builder<'_> {
    /// Puts the root's events on the stacks, sorted, and allocates the per-triangle scratch.
    fn root_events(&mut self, live: usize) -> Result<(), BuildError> {
        for list in self.stack.iter_mut() {
            *list = self.budget.vec(2 * live, "kd-tree build events")?;
        }
        for (i, tri) in self.mesh.triangles().iter().enumerate() {
            if !self.mesh.is_degenerate(i as u32) {
                push_events(&mut self.stack, &Aabb::of_triangle(tri), i as u32);
            }
        }
        for list in self.stack.iter_mut() {
            list.sort_unstable();
        }
        self.side = self
            .budget
            .filled(self.mesh.len(), BOTH, "kd-tree build scratch")?;
        Ok(())
    }

    /// Builds the subtree of a node with `n` triangles whose events are on top of the stacks from
    /// `start`, inside `bbox`, at `depth`; the node goes at the end of `nodes`. On success the
    /// stacks are truncated back to `start`.
    fn node(&mut self, start: Starts, n: usize, bbox: Aabb, depth: u32) -> Result<(), BuildError> {
        let index = self.nodes.len();
        if index > MAX_NODE_FIELD as usize {
            return Err(BuildError::CapacityExceeded {
                what: "kd-tree nodes (at most 2^30)",
            });
        }
        self.budget
            .push(&mut self.nodes, KdNode::leaf(0, 0), "kd-tree nodes")?;
        self.depth = self.depth.max(depth);
        let split = if depth >= self.max_depth || n <= self.params.max_leaf_prims as usize {
            None
        } else {
            self.find_split(start, n, &bbox)
                .filter(|s| (self.refs + s.left + s.right).saturating_sub(n) <= self.refs_limit)
        };
        let Some(split) = split else {
            return self.leaf(index, start);
        };
        let (mut left_box, mut right_box) = (bbox, bbox);
        left_box.max[split.axis] = split.pos;
        right_box.min[split.axis] = split.pos;
        let (left_start, nl, nr) = self.split_events(start, &split, n, &left_box, &right_box)?;
        self.refs = (self.refs + nl + nr).saturating_sub(n);
        self.node(left_start, nl, left_box, depth + 1)?;
        let above = self.nodes.len();
        if above > MAX_NODE_FIELD as usize {
            return Err(BuildError::CapacityExceeded {
                what: "kd-tree nodes (at most 2^30)",
            });
        }
        self.nodes[index] = KdNode::interior(split.axis, split.pos, above as u32);
        self.node(start, nr, right_box, depth + 1)
    }

    /// Makes node `index` a leaf of the triangles whose events start at `start`, and pops them.
    fn leaf(&mut self, index: usize, start: Starts) -> Result<(), BuildError> {
        self.leaves += 1;
        let list = tail(&self.stack[0], start[0]);
        let members = list.iter().filter(|&&e| kind(e) != END).map(|&e| prim(e));
        let count = list.iter().filter(|&&e| kind(e) != END).count();
        // With packed triangles a leaf starts on a block of four, so its triangles fill whole
        // blocks (the gap holds no triangle: id INVALID, NaN in the packs).
        let pad = if self.params.layout == TriangleLayout::Packed && count > 0 {
            self.prims.len().next_multiple_of(4) - self.prims.len()
        } else {
            0
        };
        let offset = self.prims.len() + pad;
        let result = if count > MAX_NODE_FIELD as usize {
            Err(BuildError::CapacityExceeded {
                what: "kd-tree leaf size (at most 2^30)",
            })
        } else if offset + count > u32::MAX as usize {
            Err(BuildError::CapacityExceeded {
                what: "kd-tree references (at most 2^32)",
            })
        } else {
            let padding = core::iter::repeat(Hit::INVALID_ID).take(pad);
            let mut r = Ok(());
            for p in padding.chain(members) {
                r = self
                    .budget
                    .push(&mut self.prims, p, "kd-tree leaf references");
                if r.is_err() {
                    break;
                }
            }
            self.references += count;
            self.nodes[index] = KdNode::leaf(count as u32, offset as u32);
            r
        };
        for (list, &s) in self.stack.iter_mut().zip(&start) {
            list.truncate(s);
            shrink(self.budget, list);
        }
        result
    }

    /// The cheapest split by the surface area heuristic, or `None` when no split is cheaper than a
    /// leaf. Candidates are the event positions strictly inside the box (a plane on the box's face
    /// would make a child of no volume).
    fn find_split(&self, start: Starts, n: usize, bbox: &Aabb) -> Option<Split> {
        let ext = bbox.extent();
        let ext = [f64::from(ext.x), f64::from(ext.y), f64::from(ext.z)];
        let sa = area(ext);
        if !(sa > 0.0) {
            return None;
        }
        let p = &self.params;
        let mut sweep = Sweep {
            n,
            ext,
            sa,
            ct: f64::from(p.traversal_cost),
            ci: f64::from(p.intersection_cost),
            keep: 1.0 - f64::from(p.empty_bonus),
            best_cost: f64::from(p.intersection_cost) * blocks(n),
            best: None,
        };
        // One copy of the sweep per axis, so the box arithmetic has fixed slots.
        sweep.axis::<0>(tail(&self.stack[0], start[0]), bbox.min.x, bbox.max.x);
        sweep.axis::<1>(tail(&self.stack[1], start[1]), bbox.min.y, bbox.max.y);
        sweep.axis::<2>(tail(&self.stack[2], start[2]), bbox.min.z, bbox.max.z);
        sweep.best
    }

    /// Replaces the node's lists (from `start`) by its children's, in order: the upper child's at
    /// `start`, the lower child's on top (returned with both children's triangle counts).
    /// Triangles that straddle the plane are clipped to each child box.
    fn split_events(
        &mut self,
        start: Starts,
        split: &Split,
        n: usize,
        left_box: &Aabb,
        right_box: &Aabb,
    ) -> Result<(Starts, usize, usize), BuildError> {
        let (only_left, only_right) = self.classify(start, split, n)?;
        let (clipped_left, clipped_right) = self.clip_straddlers(left_box, right_box)?;
        let (nl, nr) = (only_left + clipped_left, only_right + clipped_right);
        let mut left_start = start;
        for a in 0..3 {
            let s = start[a];
            let parent = tail(&self.stack[a], s);
            let [cl, cr] = [&self.clipped[0][a], &self.clipped[1][a]];
            // A child holds at most two events per triangle, and at most the parent's events of its
            // triangles plus its clipped ones.
            let room_l = (2 * nl).min(parent.len() + cl.len());
            let room_r = (2 * nr).min(parent.len() + cr.len());
            let room = room_l + room_r;
            // Small nodes merge into the reused scratch; big ones into a buffer of their own, given
            // back right away, so the scratch never holds the top levels' high-water mark.
            let mut merged = if room <= self.scratch_limit {
                let mut m = core::mem::take(&mut self.merged);
                m.clear();
                grow(self.budget, &mut m, room, "kd-tree build events")?;
                m
            } else {
                self.budget.vec(room, "kd-tree build events")?
            };
            merged.resize(room, 0);
            let (lower, upper) = merged.split_at_mut(room_l);
            let (l, r) = merge_split(parent, &self.side, [cl, cr], lower, upper);
            let result = self.install(a, s, &merged, room_l, l, r);
            if room <= self.scratch_limit {
                self.merged = merged;
            } else {
                self.budget.free(merged);
            }
            result?;
            left_start[a] = s + r;
        }
        Ok((left_start, nl, nr))
    }

    /// Replaces axis `a`'s stack from `start` on by the children's merged lists (the lower child's
    /// `l` events at the front of `merged`, the upper's `r` from `room_l`): upper first, then lower.
    fn install(
        &mut self,
        a: usize,
        start: usize,
        merged: &[Event],
        room_l: usize,
        l: usize,
        r: usize,
    ) -> Result<(), BuildError> {
        let (Some(lower), Some(upper)) = (merged.get(..l), merged.get(room_l..room_l + r)) else {
            return Err(BuildError::CapacityExceeded {
                what: "kd-tree child events (internal bound)",
            });
        };
        let list = &mut self.stack[a];
        list.truncate(start);
        grow(self.budget, list, start + r + l, "kd-tree build events")?;
        list.extend_from_slice(upper);
        list.extend_from_slice(lower);
        Ok(())
    }

    /// Marks each of the node's triangles `LEFT`, `RIGHT` or `BOTH` of the split in `side`, in one
    /// walk of the split axis's events, and collects the straddlers (`BOTH`) in `straddlers`.
    /// Returns how many go only left and only right.
    fn classify(
        &mut self,
        start: Starts,
        split: &Split,
        n: usize,
    ) -> Result<(usize, usize), BuildError> {
        let k = split.axis;
        let key = ordered(split.pos);
        let list = tail(&self.stack[k], start[k]);
        let side = &mut self.side;
        let straddlers = &mut self.straddlers;
        straddlers.clear();
        // The sweep's counts give the straddlers exactly; `push` below covers any shortfall.
        let expected = (split.left + split.right).saturating_sub(n);
        grow(self.budget, straddlers, expected, "kd-tree build scratch")?;
        let (mut only_left, mut only_right) = (0, 0);
        for &e in list {
            let id = prim(e);
            let Some(s) = side.get_mut(id as usize) else {
                continue;
            };
            let at = pos_key(e);
            match kind(e) {
                // A triangle's start comes before its end (a flat extent is one planar event), so
                // the end can override what the start said.
                START => {
                    *s = if at >= key {
                        only_right += 1;
                        RIGHT
                    } else {
                        BOTH
                    }
                }
                END => {
                    if at <= key {
                        *s = LEFT;
                        only_left += 1;
                    } else if *s == BOTH {
                        self.budget.push(straddlers, id, "kd-tree build scratch")?;
                    }
                }
                _ => {
                    if at < key || (at == key && split.planar_left) {
                        *s = LEFT;
                        only_left += 1;
                    } else {
                        *s = RIGHT;
                        only_right += 1;
                    }
                }
            }
        }
        Ok((only_left, only_right))
    }

    /// Clips every straddler to both child boxes and puts the events of the parts inside in
    /// `clipped`, sorted. Returns how many straddlers each child keeps.
    fn clip_straddlers(
        &mut self,
        left_box: &Aabb,
        right_box: &Aabb,
    ) -> Result<(usize, usize), BuildError> {
        let room = 2 * self.straddlers.len();
        for list in self.clipped.iter_mut().flatten() {
            list.clear();
            // Room for two events per straddler, so `push_events` never grows them.
            grow(self.budget, list, room, "kd-tree build events")?;
        }
        let tris = self.mesh.triangles();
        let mut kept = [0usize; 2];
        let [to_left, to_right] = &mut self.clipped;
        for &id in &self.straddlers {
            let Some(tri) = tris.get(id as usize) else {
                continue;
            };
            for (c, (b, lists)) in [(left_box, &mut *to_left), (right_box, &mut *to_right)]
                .into_iter()
                .enumerate()
            {
                let cb = clipped_bounds(tri, b);
                if !cb.is_empty() {
                    push_events(lists, &cb, id);
                    kept[c] += 1;
                }
            }
        }
        for list in self.clipped.iter_mut().flatten() {
            list.sort_unstable();
        }
        Ok((kept[0], kept[1]))
    }
}

/// The test cost of a leaf of `n` triangles in units of one block test: the list test takes them
/// four at a time (a leaf's list starts on a block), so one to four cost the same.
#[inline(always)]
fn blocks(n: usize) -> f64 {
    n.div_ceil(4) as f64
}

/// The SAH sweep of one node: its constants and the best split so far.
struct Sweep {
    n: usize,
    ext: [f64; 3],
    sa: f64,
    ct: f64,
    ci: f64,
    /// `1 − empty_bonus`.
    keep: f64,
    /// A leaf's cost until a split beats it.
    best_cost: f64,
    best: Option<Split>,
}

impl Sweep {
    /// Tries every event position of axis `K` strictly inside `(lo, hi)`, keeping the cheapest
    /// split (the first of equal ones, axes in order).
    #[inline]
    fn axis<const K: usize>(&mut self, list: &[Event], lo: f32, hi: f32) {
        if !(lo < hi) {
            return;
        }
        let (mut nl, mut nr) = (0usize, self.n);
        // One group per position; sorting put its ends, then planars, then starts together.
        for group in list.chunk_by(|a, b| pos_key(*a) == pos_key(*b)) {
            let Some(&first) = group.first() else {
                continue;
            };
            let mut counts = [0usize; 4];
            for &e in group {
                counts[kind(e) as usize] += 1;
            }
            let (ends, planars, starts) = (
                counts[END as usize],
                counts[PLANAR as usize],
                counts[START as usize],
            );
            nr -= planars + ends;
            let pos = unordered(pos_key(first));
            if lo < pos && pos < hi {
                self.candidate::<K>(pos, lo, hi, nl, nr, planars);
            }
            nl += starts + planars;
        }
    }

    /// Prices the plane at `pos` on axis `K` with `nl` triangles only below, `nr` above and
    /// `planars` in it (sent to the cheaper side).
    #[inline]
    fn candidate<const K: usize>(
        &mut self,
        pos: f32,
        lo: f32,
        hi: f32,
        nl: usize,
        nr: usize,
        planars: usize,
    ) {
        let mut le = self.ext;
        le[K] = f64::from(pos) - f64::from(lo);
        let mut re = self.ext;
        re[K] = f64::from(hi) - f64::from(pos);
        let (pl, pr) = (area(le) / self.sa, area(re) / self.sa);
        let (ct, ci, keep) = (self.ct, self.ci, self.keep);
        let cost = |l: usize, r: usize| {
            let c = ct + ci * (pl * blocks(l) + pr * blocks(r));
            if l == 0 || r == 0 {
                c * keep
            } else {
                c
            }
        };
        let (c_left, c_right) = (cost(nl + planars, nr), cost(nl, nr + planars));
        let planar_left = c_left <= c_right;
        let c = c_left.min(c_right);
        if c < self.best_cost {
            self.best_cost = c;
            self.best = Some(Split {
                axis: K,
                pos,
                planar_left,
                left: nl + if planar_left { planars } else { 0 },
                right: nr + if planar_left { 0 } else { planars },
            });
        }
    }
}

/// One child's output of [`merge_split`]: its buffer, how much is written, and its clipped events
/// still to merge.
struct Child<'a> {
    buf: &'a mut [Event],
    len: usize,
    clipped: &'a [Event],
    next: usize,
}

impl Child<'_> {
    /// Appends `e` (counted but dropped when the buffer is full, which the caller reports).
    #[inline]
    fn put(&mut self, e: Event) {
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = e;
        }
        self.len += 1;
    }

    /// Appends the clipped events before `e`, then `e`.
    #[inline]
    fn take(&mut self, e: Event) {
        while let Some(&c) = self.clipped.get(self.next) {
            if c >= e {
                break;
            }
            self.put(c);
            self.next += 1;
        }
        self.put(e);
    }

    /// Appends the clipped events left; returns the length.
    fn finish(mut self) -> usize {
        while let Some(&c) = self.clipped.get(self.next) {
            self.put(c);
            self.next += 1;
        }
        self.len
    }
}

/// Distributes the sorted `parent` events over the children by their triangle's `side`, merging
/// each child's sorted `clipped` events in, in one walk: `lower` and `upper` get sorted lists, and
/// the lengths are returned (a length beyond its buffer means the buffer was too small).
fn merge_split(
    parent: &[Event],
    side: &[u8],
    clipped: [&[Event]; 2],
    lower: &mut [Event],
    upper: &mut [Event],
) -> (usize, usize) {
    let [cl, cr] = clipped;
    let mut left = Child {
        buf: lower,
        len: 0,
        clipped: cl,
        next: 0,
    };
    let mut right = Child {
        buf: upper,
        len: 0,
        clipped: cr,
        next: 0,
    };
    for &e in parent {
        match side.get(prim(e) as usize) {
            Some(&LEFT) => left.take(e),
            Some(&RIGHT) => right.take(e),
            _ => {}
        }
    }
    (left.finish(), right.finish())
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
