//! SAH kd-tree construction.
//!
//! - **Splits**: nodes of more than `exact_below` triangles choose their plane by min-max binning
//!   (n/4 bins, 4 to 32, per axis over the tight bounds of the node's items, all three axes in one
//!   pass, each triangle's part counted in the bins of its lower and upper bound: Shevtsov et al.
//!   2007, as Mitsuba's `SAHKDTree3D` does above 65 536); smaller nodes by the exact SAH over every
//!   event position: up to 16 triangles by counting each candidate's sides ([`counted_split`]),
//!   above by sorting the events per node (Wald & Havran's sweep, with end < planar < start at
//!   equal positions). Candidates are priced in f32, relative to the node's area. Either way, the
//!   triangles that straddle the plane are clipped at it ("perfect splits", [`split_bounds`]), so a
//!   child holds only triangles that really enter it and bounds of their parts.
//! - **Cost**: `C_t + C_i·(P_L·⌈N_L/4⌉ + P_R·⌈N_R/4⌉)` (times `1 − empty_bonus` when a child is
//!   empty): the list test takes a leaf's triangles four at a time, so one to four cost the same.
//! - **Termination** (after pbrt's): a split no better than a leaf is still taken, as a "bad refine",
//!   when the path from the root had fewer than three and the node has more than 64 triangles, or
//!   more than 8 and the split costs at most 1.05 times the leaf; after both children are built, a
//!   subtree no cheaper than a leaf of its node's triangles is retracted into that leaf (Mitsuba).
//! - **References**: a subtree may hold at most its share of the root's budget
//!   (`max_references_per_triangle · N`), the share of a child proportional to its triangles, so no
//!   subtree can spend another's; a node that would exceed its share becomes a leaf and is counted
//!   (`Built::budget_leaves`).
//! - **Order**: a node's two children side by side at an even index (an unused slot follows the
//!   root), allocated when it is split; subtrees depth first. Each level is linear in its
//!   triangles (binning, partition) or `n log n` in a node of at most `exact_below` (the sort), so the
//!   whole build is O(N log N).
//!
//! Every array is charged to the build's [`MemoryBudget`] before it is allocated.

use alloc::vec::Vec;

use super::clip::split_bounds;
use super::node::{KdNode, MAX_CHILD_INDEX, MAX_NODE_FIELD};
use super::{KdTreeParams, MAX_DEPTH};
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::{Aabb, Hit};
use crate::triangle::packs::TriangleLayout;

/// A triangle's part inside the node being built: the triangle and the bounds of that part.
#[derive(Clone, Copy, Debug)]
struct Item {
    lo: [f32; 3],
    hi: [f32; 3],
    prim: u32,
}

/// Bins per axis of the binned SAH.
const BINS: usize = 32;

/// A node of at most this many triangles (two blocks of the list test) whose best split is no
/// cheaper than a leaf becomes that leaf: below it, the subtree of a bad refine was nearly always
/// torn down again after being built (docs/performance.md, "A faster kd-tree build (issue 12, branch
/// hkd)", step 4).
const NO_BAD_REFINE: usize = 8;

/// A node of at most this many triangles takes a bad refine only when its best split costs at most
/// [`NEAR_TIE`] times a leaf. The subtrees of worse bad refines there were nearly always built and
/// torn down again: with bad refines down to 9 triangles, the work in retracted subtrees was 7 % of
/// bunny's build, 14 % of sibenik's, 27 % of spd_teapot's, 38 % of gears-10k's, 36 % of hair-50k's,
/// and of the small nodes' bad refines that were kept, none cost 40 % more than a leaf and more of
/// them cost within 5 % than in any other 5 % bin. Near ties keep the trees that need them (the
/// Sierpinski tetrahedron's is unchanged:
/// without any bad refine below 64 it tests 2.6× the triangles a ray). Measured against every bad
/// refine (29 scenes, docs/performance.md, "Stop 24"): the builds take 0.43–0.93× the time
/// (geometric mean 0.67) for 0.98× the time per ray, the trees a little smaller (bunny 2.13 → 1.97
/// references per triangle), though 0–1.5 % more instructions per ray. Kept bad refines that would
/// have paid at 1.05–1.4 times a leaf are lost (a sphere at a 10⁷ offset, whose few distinct
/// triangles made leaves of 12, is one leaf of 48: 0.7× the rays per second, docs/robustness.md).
/// The threshold is relative to the costs it was measured with (`KdTreeParams::DEFAULT`): with a
/// cheaper test (`C_i` = 0.35) the tetrahedron's splits no longer come within it. Larger nodes
/// keep every bad refine: triangles spanning the box at all angles (slivers) need several splits
/// before any one pays, and without a bad refine at the root their scene is one leaf (3.2× the
/// time per ray).
const SMALL_NODE: usize = 64;

/// See [`SMALL_NODE`].
const NEAR_TIE: f64 = 1.05;

/// Nodes of more than this many triangles are not made leaves by the automatic depth limit.
const DEEP_NODE: usize = 48;

/// Nodes of at most this many triangles are split by counting, for every candidate plane, the
/// triangles on each side ([`counted_split`]) instead of sorting events: the same candidates and
/// costs, quadratic in the triangles but branch-free and vectorised, so cheaper than a sort for so few.
const COUNTED: usize = 16;

/// Bad refines allowed on a path from the root (pbrt, Mitsuba).
const MAX_BAD_REFINES: u32 = 3;

/// The sides of a split, as indices of a level's two item lists.
const LOWER: usize = 0;
const UPPER: usize = 1;

/// What the builder returns.
pub(super) struct Built {
    pub nodes: Vec<KdNode>,
    /// The leaves' triangle ids (with `Hit::INVALID_ID` padding before block-aligned leaves).
    pub prims: Vec<u32>,
    pub depth: u32,
    pub leaves: u32,
    /// Triangle references held by the leaves (`prims` less its padding).
    pub references: usize,
    /// Items the build's nodes held, summed over every node it split or made a leaf (its work).
    pub work: u64,
    /// Leaves made because their subtree's reference share ran out, and the largest of them.
    pub budget_leaves: usize,
    pub largest_budget_leaf: usize,
}

/// The builder's counts before a subtree's build ([`Builder::mark`]).
#[derive(Clone, Copy)]
struct Mark {
    prims: usize,
    leaves: u32,
    references: usize,
    depth: u32,
    budget_leaves: usize,
    largest_budget_leaf: usize,
}

/// Why a build stopped before its tree was done.
pub(super) enum Stop {
    /// An allocation, the memory limit, the monitor or a capacity refused.
    Failed(BuildError),
    /// The nodes held more items in all than the caller's work limit.
    OverWork,
}

impl From<BuildError> for Stop {
    fn from(e: BuildError) -> Stop {
        Stop::Failed(e)
    }
}

/// The chosen split of a node.
#[derive(Clone, Copy, Debug)]
struct Split {
    axis: usize,
    pos: f32,
    /// Triangles lying in the split plane go to the lower child.
    planar_left: bool,
    /// Triangles each child gets, as counted before clipping (clipping can only lower them).
    left: usize,
    right: usize,
    cost: f64,
}

/// The SAH's constants.
#[derive(Clone, Copy, Debug)]
struct Costs {
    ct: f64,
    ci: f64,
    /// `1 − empty_bonus`.
    keep: f64,
}

/// The test cost of a leaf of `n` triangles in units of one block test: the list test takes them
/// four at a time (a leaf's list starts on a block), so one to four cost the same.
#[inline(always)]
fn blocks(n: usize) -> f64 {
    n.div_ceil(4) as f64
}

impl Costs {
    fn leaf(&self, n: usize) -> f64 {
        self.ci * blocks(n)
    }

    /// A split whose children (hit with probabilities `pl`, `pr`) cost `cl`, `cr` and hold `nl`, `nr`.
    #[inline(always)]
    fn interior(&self, pl: f64, pr: f64, cl: f64, cr: f64, nl: usize, nr: usize) -> f64 {
        let c = self.ct + pl * cl + pr * cr;
        if nl == 0 || nr == 0 {
            c * self.keep
        } else {
            c
        }
    }
}

/// Surface area of a box with edge lengths `e` (f64: small children of large boxes stay exact
/// enough to compare).
#[inline]
fn area(e: [f64; 3]) -> f64 {
    2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
}

/// The chances that a ray through `bbox` meets each side of the plane `pos` on `axis`.
#[inline]
fn probabilities(bbox: &Aabb, axis: usize, pos: f32) -> (f64, f64) {
    let ext = bbox.extent().to_array().map(f64::from);
    let sa = area(ext);
    let (mut le, mut re) = (ext, ext);
    le[axis] = f64::from(pos) - f64::from(bbox.min[axis]);
    re[axis] = f64::from(bbox.max[axis]) - f64::from(pos);
    (area(le) / sa, area(re) / sa)
}

/// The children's areas along one axis as linear functions of the plane's distance `x` from the
/// box's lower face: `area(x) = a0 + a1·x` below, `a0 + a1·(extent − x)` above; so pricing a
/// candidate plane takes two multiply-adds, not two box areas. In f32, with the areas divided by
/// the square of the box's longest edge (so they lie in `[0, 6]` whatever the scene's scale).
#[derive(Clone, Copy)]
struct Sides {
    a0: f32,
    a1: f32,
    extent: f32,
    lo: f32,
}

impl Sides {
    /// `scale` is `1 / longest edge` of `bbox` (see [`Pricer::new`]).
    fn new(bbox: &Aabb, axis: usize, scale: f64) -> Sides {
        let e = bbox.extent().to_array().map(|x| f64::from(x) * scale);
        let (b, c) = (e[(axis + 1) % 3], e[(axis + 2) % 3]);
        Sides {
            a0: (2.0 * b * c) as f32,
            a1: (2.0 * (b + c) * scale) as f32,
            extent: bbox.max[axis] - bbox.min[axis],
            lo: bbox.min[axis],
        }
    }

    /// The children's (scaled) areas for the plane at `pos`.
    #[inline(always)]
    fn at(&self, pos: f32) -> (f32, f32) {
        let x = pos - self.lo;
        (self.a0 + self.a1 * x, self.a0 + self.a1 * (self.extent - x))
    }
}

/// Prices a node's candidate planes in f32, in units of the node's (scaled) area: a candidate's
/// price is its SAH cost times that area, so comparing prices compares costs and no division is
/// needed per candidate.
#[derive(Clone, Copy)]
struct Pricer {
    /// `C_t · area(box)`.
    ct_sa: f32,
    ci: f32,
    keep: f32,
    /// `1 / longest edge`, the scale of every [`Sides`] of this node.
    scale: f64,
    /// `1 / area(box)` (scaled), to turn the best price back into a cost.
    inv_sa: f64,
}

impl Pricer {
    fn new(costs: &Costs, bbox: &Aabb) -> Pricer {
        let e = bbox.extent().to_array().map(f64::from);
        let longest = e[0].max(e[1]).max(e[2]);
        let scale = if longest > 0.0 { 1.0 / longest } else { 1.0 };
        let sa = area(e.map(|x| x * scale));
        Pricer {
            ct_sa: (costs.ct * sa) as f32,
            ci: costs.ci as f32,
            keep: costs.keep as f32,
            scale,
            inv_sa: 1.0 / sa,
        }
    }

    /// The price of a split whose children have (scaled) areas `al`, `ar` and hold `nl`, `nr`:
    /// [`Costs::interior`] with leaf children ([`Costs::leaf`]) times the node's scaled area, in f32
    /// (the test below keeps the two the same).
    #[inline(always)]
    fn price(&self, al: f32, ar: f32, nl: usize, nr: usize) -> f32 {
        let c = self.ct_sa + self.ci * (al * blocks32(nl) + ar * blocks32(nr));
        if nl == 0 || nr == 0 {
            c * self.keep
        } else {
            c
        }
    }
}

/// [`blocks`] in f32, for the sweep.
#[inline(always)]
fn blocks32(n: usize) -> f32 {
    n.div_ceil(4) as f32
}

/// The cheapest candidate so far of a node's split search.
#[derive(Clone, Copy)]
struct Best {
    /// Its price ([`Pricer::price`]); infinite while there is none.
    price: f32,
    axis: usize,
    pos: f32,
    planar_left: bool,
    left: usize,
    right: usize,
}

impl Best {
    const NONE: Best = Best {
        price: f32::INFINITY,
        axis: 0,
        pos: 0.0,
        planar_left: true,
        left: 0,
        right: 0,
    };

    #[inline(always)]
    fn offer(
        &mut self,
        price: f32,
        axis: usize,
        pos: f32,
        planar_left: bool,
        nl: usize,
        nr: usize,
    ) {
        if price < self.price {
            *self = Best {
                price,
                axis,
                pos,
                planar_left,
                left: nl,
                right: nr,
            };
        }
    }

    /// Offers the plane at `pos` on `axis` with `nl` items below it, `nr` above and `np` in it
    /// (children of scaled areas `al`, `ar`): the planar items go to the cheaper side, the lower
    /// one on a tie.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn offer_plane(
        &mut self,
        pricer: &Pricer,
        (al, ar): (f32, f32),
        axis: usize,
        pos: f32,
        nl: usize,
        nr: usize,
        np: usize,
    ) {
        let below = pricer.price(al, ar, nl + np, nr);
        if np == 0 {
            self.offer(below, axis, pos, true, nl, nr);
            return;
        }
        let above = pricer.price(al, ar, nl, nr + np);
        if below <= above {
            self.offer(below, axis, pos, true, nl + np, nr);
        } else {
            self.offer(above, axis, pos, false, nl, nr + np);
        }
    }

    fn split(&self, pricer: &Pricer) -> Option<Split> {
        (self.price < f32::INFINITY).then(|| Split {
            axis: self.axis,
            pos: self.pos,
            planar_left: self.planar_left,
            left: self.left,
            right: self.right,
            cost: f64::from(self.price) * pricer.inv_sa,
        })
    }
}

/// A binned node's per-axis bins over the tight bounds of its items, and the items' lower and
/// upper bounds counted in them.
struct BinCounts {
    /// The items counted.
    n: usize,
    tlo: [f32; 3],
    thi: [f32; 3],
    /// Bins per axis; `scale[a]` maps `x − tlo[a]` to a bin, 0 (every item in bin 0, no candidate
    /// priced) where the axis has no inner bin plane.
    bins: usize,
    scale: [f32; 3],
    starts: [[u32; BINS]; 3],
    ends: [[u32; BINS]; 3],
}

impl BinCounts {
    const EMPTY: BinCounts = BinCounts {
        n: 0,
        tlo: [0.0; 3],
        thi: [0.0; 3],
        bins: 8,
        scale: [0.0; 3],
        starts: [[0; BINS]; 3],
        ends: [[0; BINS]; 3],
    };

    /// Bins `items` (all three axes in one pass).
    fn count(&mut self, items: &[Item]) {
        let n = items.len();
        let (tlo, thi) = tight_bounds(items);
        // Fewer bins for smaller nodes: pricing a candidate costs about what binning an item does.
        // At least 4 (stop 20; it was 8): 6–10 % fewer build instructions for +0.1 % per ray on
        // most scenes (soup-10k +1.4 %, hair-50k +0.7 %; docs/performance.md).
        let bins = (n / 4).clamp(4, BINS);
        let top = (bins - 1) as f32;
        let mut scale = [0.0f32; 3];
        for a in 0..3 {
            let s = bins as f32 / (thi[a] - tlo[a]);
            if tlo[a] < thi[a] && s.is_finite() {
                scale[a] = s;
            }
        }
        let (mut starts, mut ends) = ([[0u32; BINS]; 3], [[0u32; BINS]; 3]);
        count_bins(items, tlo, scale, top, &mut starts, &mut ends);
        *self = BinCounts {
            n,
            tlo,
            thi,
            bins,
            scale,
            starts,
            ends,
        };
    }
}

/// The smallest lower and largest upper bound of `items` per axis (`+∞`, `−∞` for none).
fn tight_bounds(items: &[Item]) -> ([f32; 3], [f32; 3]) {
    #[cfg(target_arch = "x86_64")]
    return tight_bounds_sse2(items);
    #[cfg(not(target_arch = "x86_64"))]
    return tight_bounds_portable(items);
}

/// [`tight_bounds`] in plain f32: the reference (tested against the SSE2 version) and the version
/// for other targets.
#[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
fn tight_bounds_portable(items: &[Item]) -> ([f32; 3], [f32; 3]) {
    let (mut tlo, mut thi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for it in items {
        for a in 0..3 {
            tlo[a] = if it.lo[a] < tlo[a] { it.lo[a] } else { tlo[a] };
            thi[a] = if it.hi[a] > thi[a] { it.hi[a] } else { thi[a] };
        }
    }
    (tlo, thi)
}

/// [`tight_bounds`] on SSE2, the three axes in one register (`minps(x, t)` is `x < t ? x : t`, as
/// the portable version compares).
#[cfg(target_arch = "x86_64")]
fn tight_bounds_sse2(items: &[Item]) -> ([f32; 3], [f32; 3]) {
    use core::arch::x86_64::{_mm_max_ps, _mm_min_ps, _mm_set1_ps, _mm_set_ps, _mm_storeu_ps};
    // SAFETY: SSE2 is always present on x86-64; the stores write 16 bytes into local `[f32; 4]`s.
    unsafe {
        let (mut lo, mut hi) = (_mm_set1_ps(f32::INFINITY), _mm_set1_ps(f32::NEG_INFINITY));
        for it in items {
            let l = _mm_set_ps(0.0, it.lo[2], it.lo[1], it.lo[0]);
            let h = _mm_set_ps(0.0, it.hi[2], it.hi[1], it.hi[0]);
            lo = _mm_min_ps(l, lo);
            hi = _mm_max_ps(h, hi);
        }
        let (mut l4, mut h4) = ([0.0f32; 4], [0.0f32; 4]);
        _mm_storeu_ps(l4.as_mut_ptr(), lo);
        _mm_storeu_ps(h4.as_mut_ptr(), hi);
        ([l4[0], l4[1], l4[2]], [h4[0], h4[1], h4[2]])
    }
}

/// Counts each item's lower and upper bound in its bin per axis (see [`bins_portable`]).
fn count_bins(
    items: &[Item],
    tlo: [f32; 3],
    scale: [f32; 3],
    top: f32,
    starts: &mut [[u32; BINS]; 3],
    ends: &mut [[u32; BINS]; 3],
) {
    #[cfg(target_arch = "x86_64")]
    let bins = |x: &[f32; 3]| bins_sse2(x, tlo, scale, top);
    #[cfg(not(target_arch = "x86_64"))]
    let bins = |x: &[f32; 3]| bins_portable(x, tlo, scale, top);
    for it in items {
        let (l, h) = (bins(&it.lo), bins(&it.hi));
        for a in 0..3 {
            // In [0, bins − 1] (see `bins_portable`), so the mask changes nothing; it spares the
            // bounds check.
            starts[a][l[a] & (BINS - 1)] += 1;
            ends[a][h[a] & (BINS - 1)] += 1;
        }
    }
}

/// The bin of `x` per axis: `⌊(x − tlo)·scale⌋`, at most `top`. Every item's bounds lie in the
/// tight bounds `[tlo, thi]`, so `x − tlo` is in `[0, thi − tlo]` (rounding is monotonic) and
/// `(x − tlo)·scale` in `[0, bins·(1 + ε)]` (`scale` is finite and not negative), or NaN
/// (`∞ · 0` where `thi − tlo` overflows), which the comparison with `top` turns into `top`; a bin
/// is therefore in `[0, bins − 1]`, below [`BINS`]. The reference (tested against the SSE2
/// version) and the version for other targets.
#[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
#[inline(always)]
fn bins_portable(x: &[f32; 3], tlo: [f32; 3], scale: [f32; 3], top: f32) -> [usize; 3] {
    core::array::from_fn(|a| {
        let b = (x[a] - tlo[a]) * scale[a];
        let b = if b < top { b } else { top };
        // SAFETY: `b` is in [0, bins − 1] (above), where the conversion is exact.
        unsafe { b.to_int_unchecked::<u32>() as usize }
    })
}

/// [`bins_portable`] on SSE2 (part of x86-64's baseline), the three axes in one register: the
/// same operations lane by lane (`minps(b, top)` is `b < top ? b : top`, NaN to `top`;
/// `cvttps2dq` truncates as `to_int_unchecked` does in range), so the same bins.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn bins_sse2(x: &[f32; 3], tlo: [f32; 3], scale: [f32; 3], top: f32) -> [usize; 3] {
    use core::arch::x86_64::{
        _mm_cvttps_epi32, _mm_min_ps, _mm_mul_ps, _mm_set1_ps, _mm_set_ps, _mm_storeu_si128,
        _mm_sub_ps,
    };
    // SAFETY: SSE2 is always present on x86-64, and every intrinsic here is SSE2 or SSE; the one
    // store writes 16 bytes into a local `[i32; 4]`.
    let out = unsafe {
        let v = _mm_set_ps(0.0, x[2], x[1], x[0]);
        let lo = _mm_set_ps(0.0, tlo[2], tlo[1], tlo[0]);
        let sc = _mm_set_ps(0.0, scale[2], scale[1], scale[0]);
        let b = _mm_cvttps_epi32(_mm_min_ps(
            _mm_mul_ps(_mm_sub_ps(v, lo), sc),
            _mm_set1_ps(top),
        ));
        let mut out = [0i32; 4];
        _mm_storeu_si128(out.as_mut_ptr().cast(), b);
        out
    };
    [out[0] as usize, out[1] as usize, out[2] as usize]
}

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

/// A sweep event: the position as order-preserving bits above the kind, so that sorting the raw
/// `u64` orders events by position, then end < planar < start.
type Event = u64;
const END: u64 = 0;
const PLANAR: u64 = 1;
const START: u64 = 2;

/// The depth limit for `live` triangles: `8 + 1.3·log2 N` (as pbrt), at most [`MAX_DEPTH`].
pub(super) fn auto_depth(live: usize) -> u32 {
    let log2 = usize::BITS - live.max(1).leading_zeros() - 1;
    (8 + 13 * log2 / 10).min(MAX_DEPTH)
}

/// Makes `v` hold at least `cap` elements, keeping its contents, charged to `budget`
/// ([`MemoryBudget::reserve_to`]); grows by at least an eighth so a creeping stack is copied
/// O(log) times.
fn grow<T: Copy>(
    budget: &mut MemoryBudget,
    v: &mut Vec<T>,
    cap: usize,
    what: &'static str,
) -> Result<(), BuildError> {
    if v.capacity() >= cap {
        return Ok(());
    }
    let cap = cap.max(v.capacity().saturating_add(v.capacity() / 8));
    budget.reserve_to(v, cap, what)
}

/// Replaces `v` by a copy in a block of its length when its spare room is more than a sixteenth of
/// it: the tree keeps what it holds, and the arrays grew ahead (by half, or doubling) so as not to
/// be copied often while they were built. Where the memory limit has no room for the copy, `v`
/// stays as it is (it fits the limit already); an allocator that refuses the copy fails the build,
/// as any refusal does (`v` is then the caller's to release).
fn fit<T: Copy>(
    budget: &mut MemoryBudget,
    v: &mut Vec<T>,
    what: &'static str,
) -> Result<(), BuildError> {
    if v.capacity() - v.len() <= v.len() / 16 {
        return Ok(());
    }
    match budget.vec(v.len(), what) {
        Ok(mut exact) => {
            exact.extend_from_slice(v);
            budget.free(core::mem::replace(v, exact));
            Ok(())
        }
        Err(BuildError::MemoryLimit { .. }) => Ok(()),
        Err(e) => Err(e),
    }
}

struct Builder<'a> {
    mesh: &'a TriMesh,
    params: KdTreeParams,
    budget: &'a mut MemoryBudget,
    costs: Costs,
    nodes: Vec<KdNode>,
    prims: Vec<u32>,
    /// Per depth, the items of the two children of the node being split at the depth above:
    /// a node at depth `d` reads its items from a slot `levels[level][side]` (`level ≤ d`) and
    /// writes its children's into `levels[d + 1]`. The upper child's items wait there while the
    /// lower child's subtree is built (its nodes only write deeper levels), so every item is
    /// written once per level and never moved. A split that sends every item to one side hands
    /// that child the node's own slot (see [`Builder::partition`]).
    levels: Vec<[Vec<Item>; 2]>,
    /// One axis's events of a node that is split by the exact sweep.
    events: Vec<Event>,
    /// The bins of the last binned node.
    bins: BinCounts,
    /// Triangle ids of a leaf being made.
    ids: Vec<u32>,
    max_depth: u32,
    depth: u32,
    leaves: u32,
    references: usize,
    budget_leaves: usize,
    largest_budget_leaf: usize,
    /// Items held by the nodes visited so far, and the most allowed.
    work: u64,
    work_limit: u64,
}

/// Builds the tree over the non-degenerate triangles of `mesh` inside `root`, stopping with
/// [`Stop::OverWork`] once its nodes have held more than `work_limit` items in all.
pub(super) fn build(
    mesh: &TriMesh,
    params: &KdTreeParams,
    root: Aabb,
    budget: &mut MemoryBudget,
    work_limit: u64,
) -> Result<Built, Stop> {
    let live = mesh.len() - mesh.degenerate_count();
    if mesh.len() > u32::MAX as usize {
        return Err(Stop::Failed(BuildError::CapacityExceeded {
            what: "kd-tree triangle ids",
        }));
    }
    let max_depth = if params.max_depth == 0 {
        auto_depth(live)
    } else {
        params.max_depth.min(MAX_DEPTH)
    };
    let refs_allowed = (f64::from(params.max_references_per_triangle) * live as f64) as usize;
    let mut b = Builder {
        mesh,
        params: *params,
        budget,
        costs: Costs {
            ct: f64::from(params.traversal_cost),
            ci: f64::from(params.intersection_cost),
            keep: 1.0 - f64::from(params.empty_bonus),
        },
        nodes: Vec::new(),
        prims: Vec::new(),
        levels: Vec::new(),
        events: Vec::new(),
        bins: BinCounts::EMPTY,
        ids: Vec::new(),
        max_depth,
        depth: 0,
        leaves: 0,
        references: 0,
        budget_leaves: 0,
        largest_budget_leaf: 0,
        work: 0,
        work_limit,
    };
    let result = b.root_items(live).map_err(Stop::from).and_then(|()| {
        // The root, then an unused slot, so that every pair of children (pushed two at a time)
        // starts at an even index: the traversal finds the far child as `near ^ 1`, and a pair
        // (16 bytes, 16-aligned) never straddles a cache line.
        for _ in 0..2 {
            b.budget
                .push(&mut b.nodes, KdNode::leaf(0, 0), "kd-tree nodes")?;
        }
        b.node(0, 0, (0, LOWER), root, refs_allowed.max(live), 0, false)
    });
    let Builder {
        budget,
        mut nodes,
        mut prims,
        levels,
        events,
        ids,
        depth,
        leaves,
        references,
        budget_leaves,
        largest_budget_leaf,
        work,
        ..
    } = b;
    let mut levels = levels;
    for level in levels.iter_mut() {
        for side in level.iter_mut() {
            budget.free(core::mem::take(side));
        }
    }
    budget.free(levels);
    budget.free(events);
    budget.free(ids);
    let result = result.and_then(|_| {
        fit(budget, &mut nodes, "kd-tree nodes")?;
        Ok(fit(budget, &mut prims, "kd-tree leaf references")?)
    });
    match result {
        Ok(()) => Ok(Built {
            nodes,
            prims,
            depth,
            leaves,
            references,
            budget_leaves,
            largest_budget_leaf,
            work,
        }),
        Err(e) => {
            budget.free(nodes);
            budget.free(prims);
            Err(e)
        }
    }
}

impl Builder<'_> {
    /// The root's items (the lower side of depth 0): every non-degenerate triangle with its bounds.
    fn root_items(&mut self, live: usize) -> Result<(), BuildError> {
        // Room for the deepest level a node may reach (see `node`: past the automatic limit).
        let deepest = if self.params.max_depth == 0 {
            MAX_DEPTH
        } else {
            self.max_depth
        };
        self.levels = self
            .budget
            .vec(deepest as usize + 2, "kd-tree build levels")?;
        self.levels
            .resize_with(deepest as usize + 2, Default::default);
        let mut items = self.budget.vec(live, "kd-tree build triangles")?;
        for (i, tri) in self.mesh.triangles().iter().enumerate() {
            if self.mesh.is_degenerate(i as u32) {
                continue;
            }
            let b = Aabb::of_triangle(tri);
            items.push(Item {
                lo: b.min.to_array(),
                hi: b.max.to_array(),
                prim: i as u32,
            });
        }
        self.levels[0][LOWER] = items;
        Ok(())
    }

    /// The items in the slot `levels[level][side]`.
    #[inline]
    fn items(&self, level: u32, side: usize) -> &[Item] {
        self.levels
            .get(level as usize)
            .map_or(&[][..], |l| &l[side & 1][..])
    }

    /// Builds the subtree of the node at `depth` whose items are in the slot `levels[level][side]`
    /// into node `index` (already in the array), in `bbox`, allowed `refs_allowed` references,
    /// with `bad` bad refines above it; returns its SAH cost. `reuse_bins`: the last binned node's bins are this node's (see
    /// [`Builder::binned_split`]).
    #[allow(clippy::too_many_arguments)]
    fn node(
        &mut self,
        index: usize,
        depth: u32,
        (level, side): (u32, usize),
        bbox: Aabb,
        refs_allowed: usize,
        mut bad: u32,
        reuse_bins: bool,
    ) -> Result<f64, Stop> {
        let n = self.items(level, side).len();
        self.work = self.work.saturating_add(n as u64);
        if self.work > self.work_limit {
            return Err(Stop::OverWork);
        }
        self.depth = self.depth.max(depth);
        let leaf_cost = self.costs.leaf(n);
        // The automatic limit is a safety net for the SAH, not a leaf size: a node of more than a few
        // dozen triangles there may go on to MAX_DEPTH (a caller's explicit limit holds).
        let limit = if self.params.max_depth == 0 && n > DEEP_NODE {
            MAX_DEPTH
        } else {
            self.max_depth
        };
        let binned = n > self.params.exact_below as usize;
        let split = if depth >= limit || n <= self.params.max_leaf_prims as usize {
            None
        } else if binned {
            self.binned_split(level, side, &bbox, reuse_bins)
        } else {
            self.exact_split(level, side, &bbox)?
        };
        let Some(split) = split else {
            return Ok(self.leaf(index, level, side).map(|()| leaf_cost)?);
        };
        if !(split.cost < leaf_cost) {
            if bad >= MAX_BAD_REFINES
                || n <= NO_BAD_REFINE
                || (n <= SMALL_NODE && split.cost > NEAR_TIE * leaf_cost)
            {
                return Ok(self.leaf(index, level, side).map(|()| leaf_cost)?);
            }
            bad += 1;
        }
        if split.left + split.right > refs_allowed {
            self.budget_leaves += 1;
            self.largest_budget_leaf = self.largest_budget_leaf.max(n);
            return Ok(self.leaf(index, level, side).map(|()| leaf_cost)?);
        }
        let (mut left_box, mut right_box) = (bbox, bbox);
        left_box.max[split.axis] = split.pos;
        right_box.min[split.axis] = split.pos;
        let mark = self.mark();
        // The children side by side, after every node made so far (an even index: see the root).
        let children = self.nodes.len();
        debug_assert!(children % 2 == 0);
        if children > MAX_CHILD_INDEX as usize {
            return Err(Stop::Failed(BuildError::CapacityExceeded {
                what: "kd-tree nodes (at most 2^28)",
            }));
        }
        for _ in 0..2 {
            self.budget
                .push(&mut self.nodes, KdNode::leaf(0, 0), "kd-tree nodes")?;
        }
        let (nl, nr, handed) = self.partition(depth, (level, side), &split)?;
        // The children's slots: the node's own for a child handed all its items (the other's,
        // cleared by `partition`, is empty).
        let next = depth + 1;
        let (slot_l, slot_r) = match (handed, nr == 0) {
            (true, true) => ((level, side), (next, UPPER)),
            (true, false) => ((next, LOWER), (level, side)),
            (false, _) => ((next, LOWER), (next, UPPER)),
        };
        // The child handed the node's items is built next (the other child, empty, is a leaf at
        // once), so the bins just counted are still there.
        let reuse = binned && handed;
        let total = (nl + nr).max(1);
        let share_l = ((refs_allowed as u128 * nl as u128) / total as u128) as usize;
        let share_r = refs_allowed.saturating_sub(share_l);
        let cost_l = self.node(
            children,
            next,
            slot_l,
            left_box,
            share_l.max(nl),
            bad,
            reuse && nr == 0,
        )?;
        let cost_r = self.node(
            children + 1,
            next,
            slot_r,
            right_box,
            share_r.max(nr),
            bad,
            reuse && nl == 0,
        )?;
        let empty = |node: KdNode| node.is_leaf() && node.count() == 0;
        let empties = (empty(self.nodes[children]), empty(self.nodes[children + 1]));
        self.nodes[index] = KdNode::interior(split.axis, split.pos, children as u32, empties);
        let (pl, pr) = probabilities(&bbox, split.axis, split.pos);
        let cost = self.costs.interior(pl, pr, cost_l, cost_r, nl, nr);
        if cost >= leaf_cost {
            return Ok(self.retract(index, children, mark).map(|()| leaf_cost)?);
        }
        Ok(cost)
    }

    /// Makes node `index` a leaf of the items in the slot `levels[level][side]`.
    fn leaf(&mut self, index: usize, level: u32, side: usize) -> Result<(), BuildError> {
        let mut ids = core::mem::take(&mut self.ids);
        ids.clear();
        let count = self.items(level, side).len();
        let result = grow(self.budget, &mut ids, count, "kd-tree build ids").and_then(|()| {
            ids.extend(self.items(level, side).iter().map(|it| it.prim));
            self.push_leaf(index, &ids)
        });
        self.ids = ids;
        result
    }

    /// Makes node `index` a leaf of the triangles `members`, block-aligned for the packed layout.
    fn push_leaf(&mut self, index: usize, members: &[u32]) -> Result<(), BuildError> {
        let count = members.len();
        if count > MAX_NODE_FIELD as usize {
            return Err(BuildError::CapacityExceeded {
                what: "kd-tree leaf size (at most 2^30)",
            });
        }
        // With packed triangles a leaf starts on a block of four, so its triangles fill whole
        // blocks (the gap holds no triangle: id INVALID, NaN in the packs).
        let pad = if self.params.layout == TriangleLayout::Packed && count > 0 {
            self.prims.len().next_multiple_of(4) - self.prims.len()
        } else {
            0
        };
        let offset = self.prims.len() + pad;
        if offset + count > u32::MAX as usize {
            return Err(BuildError::CapacityExceeded {
                what: "kd-tree references (at most 2^32)",
            });
        }
        // By half again, not `grow`'s eighth: the array only grows, and each growth may copy it
        // whole into fresh pages (at an eighth, ~8 times its final size in all: a quarter of a
        // million-triangle build's page faults, docs/performance.md, "Stop 48").
        let (need, cap) = (offset + count, self.prims.capacity());
        if need > cap {
            grow(
                self.budget,
                &mut self.prims,
                need.max(cap.saturating_add(cap / 2)),
                "kd-tree leaf references",
            )?;
        }
        self.prims
            .extend(core::iter::repeat(Hit::INVALID_ID).take(pad));
        self.prims.extend_from_slice(members);
        self.leaves += 1;
        self.references += count;
        self.nodes[index] = KdNode::leaf(count as u32, offset as u32);
        Ok(())
    }

    /// What a subtree's build changes of the builder's counts, taken before it starts, so that a
    /// retraction can put them back.
    fn mark(&self) -> Mark {
        Mark {
            prims: self.prims.len(),
            leaves: self.leaves,
            references: self.references,
            depth: self.depth,
            budget_leaves: self.budget_leaves,
            largest_budget_leaf: self.largest_budget_leaf,
        }
    }

    /// Tears the subtree of node `index` down into one leaf of its triangles (each once): its
    /// nodes (from `children` on) and the references made since `mark` go, and the counts are
    /// those at `mark` (the deepest leaf and the budget's leaves included: the subtree's are gone,
    /// and `mark` was taken after the node's own depth was counted).
    fn retract(&mut self, index: usize, children: usize, mark: Mark) -> Result<(), BuildError> {
        let prims_len = mark.prims;
        self.nodes.truncate(children);
        self.depth = mark.depth;
        self.budget_leaves = mark.budget_leaves;
        self.largest_budget_leaf = mark.largest_budget_leaf;
        let mut ids = core::mem::take(&mut self.ids);
        ids.clear();
        let held = self.prims.len() - prims_len;
        let result = grow(self.budget, &mut ids, held, "kd-tree build ids").and_then(|()| {
            ids.extend(
                self.prims[prims_len..]
                    .iter()
                    .copied()
                    .filter(|&p| p != Hit::INVALID_ID),
            );
            ids.sort_unstable();
            ids.dedup();
            self.prims.truncate(prims_len);
            self.leaves = mark.leaves;
            self.references = mark.references;
            self.push_leaf(index, &ids)
        });
        self.ids = ids;
        result
    }

    /// The best split of `items` by min-max binning, `None` when no candidate plane lies strictly
    /// inside the box.
    ///
    /// Bins span the items' tight bounds, not the node's box, and the two faces of those bounds are
    /// candidates too (cutting off the empty space around the triangles): planes at arbitrary bin
    /// positions in empty space would cut it again and again, a flat floor's box halving along its
    /// thin axis down to the depth limit.
    ///
    /// With `reuse`, the bin counts left by the last binned node are this node's: its parent cut
    /// off empty space and handed it its items unchanged ([`Builder::partition`]), so the tight
    /// bounds, the bins and their counts are the same; only the box, so the prices, differ.
    fn binned_split(&mut self, level: u32, side: usize, bbox: &Aabb, reuse: bool) -> Option<Split> {
        let items = self
            .levels
            .get(level as usize)
            .map_or(&[][..], |l| &l[side & 1][..]);
        let n = items.len();
        if !(reuse && self.bins.n == n) {
            self.bins.count(items);
        }
        let BinCounts {
            tlo,
            thi,
            scale,
            bins,
            ref starts,
            ref ends,
            ..
        } = self.bins;
        let pricer = Pricer::new(&self.costs, bbox);
        let mut best = Best::NONE;
        for axis in 0..3 {
            let (blo, bhi) = (bbox.min[axis], bbox.max[axis]);
            if !(blo < bhi) {
                continue;
            }
            let sides = Sides::new(bbox, axis, pricer.scale);
            let mut consider = |pos: f32, nl: usize, nr: usize| {
                if blo < pos && pos < bhi {
                    let (al, ar) = sides.at(pos);
                    best.offer(pricer.price(al, ar, nl, nr), axis, pos, true, nl, nr);
                }
            };
            let (lo, hi) = (tlo[axis], thi[axis]);
            // The empty space below and above the triangles.
            consider(lo, 0, n);
            consider(hi, n, 0);
            if scale[axis] == 0.0 {
                continue;
            }
            let (mut nl, mut nr) = (0usize, n);
            for k in 1..bins {
                nl += starts[axis][k - 1] as usize;
                nr -= ends[axis][k - 1] as usize;
                let pos = lo + (hi - lo) * (k as f32 / bins as f32);
                if lo < pos && pos < hi {
                    consider(pos, nl, nr);
                }
            }
        }
        best.split(&pricer)
    }

    /// The best split over every event position strictly inside the box (planar triangles to the
    /// cheaper side), `None` when there is no such position.
    fn exact_split(
        &mut self,
        level: u32,
        side: usize,
        bbox: &Aabb,
    ) -> Result<Option<Split>, BuildError> {
        let n = self.items(level, side).len();
        let mut events = core::mem::take(&mut self.events);
        let r = grow(self.budget, &mut events, 2 * n, "kd-tree build events");
        let pricer = Pricer::new(&self.costs, bbox);
        let mut best = Best::NONE;
        if n <= COUNTED {
            self.events = events;
            counted_split(self.items(level, side), bbox, &pricer, &mut best);
            return r.map(|()| best.split(&pricer));
        }
        if r.is_ok() {
            for axis in 0..3 {
                let (lo, hi) = (bbox.min[axis], bbox.max[axis]);
                if !(lo < hi) {
                    continue;
                }
                events.clear();
                for it in self.items(level, side) {
                    let (a, b) = (it.lo[axis], it.hi[axis]);
                    if a == b {
                        events.push((u64::from(ordered(a)) << 2) | PLANAR);
                    } else {
                        events.push((u64::from(ordered(a)) << 2) | START);
                        events.push((u64::from(ordered(b)) << 2) | END);
                    }
                }
                events.sort_unstable();
                sweep(&events, bbox, axis, n, &pricer, &mut best);
            }
        }
        self.events = events;
        r.map(|()| best.split(&pricer))
    }

    /// Writes the children's items of the node at `depth` whose items are in the slot
    /// `levels[level][side]` into `levels[depth + 1]` (lower, upper), cleared first. Straddlers are
    /// cut at the plane; a part that turns out empty is dropped. Returns the children's counts
    /// `(lower, upper)` and whether one child was handed the node's items unchanged (left in the
    /// node's slot, not written; the other is empty).
    fn partition(
        &mut self,
        depth: u32,
        (level, side): (u32, usize),
        split: &Split,
    ) -> Result<(usize, usize, bool), BuildError> {
        let (axis, pos) = (split.axis, split.pos);
        let d = depth as usize;
        let (above, below) = self.levels.split_at_mut(d + 1);
        let (Some(parent), Some([left, right])) =
            (above.get_mut(level as usize), below.first_mut())
        else {
            return Err(BuildError::CapacityExceeded {
                what: "kd-tree depth",
            });
        };
        let items = &mut parent[side & 1];
        left.clear();
        right.clear();
        // The sides an item goes to (lower, upper).
        let sides = |it: &Item| {
            let (a, b) = (it.lo[axis], it.hi[axis]);
            let planar = a == b && a == pos;
            let to_left = if planar { split.planar_left } else { a < pos };
            let to_right = if planar { !split.planar_left } else { b > pos };
            (to_left, to_right)
        };
        // A split that leaves one side empty (cutting off empty space) hands the node's items to the
        // other child as they are, in the node's own slot (`handed`): the node never reads them
        // again, and the slot, at a level no deeper than the node, is rewritten only by a node
        // above it, after this subtree. (Swapping the slot's buffer into the child's level, as
        // before stop 48, moved large buffers between levels, which then grew again by copying.)
        if items.iter().all(|it| sides(it) == (true, false)) {
            return Ok((items.len(), 0, true));
        }
        if items.iter().all(|it| sides(it) == (false, true)) {
            return Ok((0, items.len(), true));
        }
        let what = "kd-tree build triangles";
        // One slot more than the split's counts: room for the write that an item going the other
        // way leaves behind (below). And a margin: a binned split's counts are its bins' (the
        // root of a million-triangle sphereflake sent 10 more items left than counted, and a
        // child past its room doubled by `push`, copying 12 MB into fresh pages; small nodes
        // differ by a few), so a child's room is its count and a sixty-fourth, plus eight.
        let room = |count: usize| count + count / 64 + 8;
        grow(self.budget, left, room(split.left), what)?;
        grow(self.budget, right, room(split.right), what)?;
        // An item that goes one way is written to both children's next slot, and only the side it
        // goes to counts it: no branch on the side, which is mispredicted about as often as not.
        // The pointers, capacities and lengths stay in locals while items take this path; the
        // vectors' own lengths are set before any other (a straddler, or a child without room).
        let ends = |v: &mut Vec<Item>| (v.as_mut_ptr(), v.capacity(), v.len());
        let ((mut lp, mut lcap, mut nl), (mut rp, mut rcap, mut nr)) = (ends(left), ends(right));
        for it in items.iter() {
            let (to_left, to_right) = sides(it);
            if to_left != to_right && nl < lcap && nr < rcap {
                // SAFETY: both slots are within the capacities (checked), and a count grows by one
                // only over the slot just written, so every element below it was written; an
                // item is `Copy`.
                unsafe {
                    lp.add(nl).write(*it);
                    rp.add(nr).write(*it);
                }
                nl += usize::from(to_left);
                nr += usize::from(to_right);
                continue;
            }
            // SAFETY: as above: the elements below each count were written.
            unsafe {
                left.set_len(nl);
                right.set_len(nr);
            }
            if to_left && to_right {
                if let Some(tri) = self.mesh.triangle(it.prim) {
                    let part = Aabb {
                        min: glam::Vec3::from(it.lo),
                        max: glam::Vec3::from(it.hi),
                    };
                    let (lower, upper) = split_bounds(tri, &part, axis, pos);
                    for (c, child) in [(lower, &mut *left), (upper, &mut *right)] {
                        if !c.is_empty() {
                            let part = Item {
                                lo: c.min.to_array(),
                                hi: c.max.to_array(),
                                prim: it.prim,
                            };
                            self.budget.push(child, part, what)?;
                        }
                    }
                }
            } else if to_left {
                self.budget.push(left, *it, what)?;
            } else {
                self.budget.push(right, *it, what)?;
            }
            ((lp, lcap, nl), (rp, rcap, nr)) = (ends(left), ends(right));
        }
        // SAFETY: as above.
        unsafe {
            left.set_len(nl);
            right.set_len(nr);
        }
        Ok((left.len(), right.len(), false))
    }
}

/// Prices every event position of one axis's sorted `events` (Wald & Havran's sweep: at each
/// position the ends, then the planar triangles, then the starts).
fn sweep(events: &[Event], bbox: &Aabb, axis: usize, n: usize, pricer: &Pricer, best: &mut Best) {
    let (lo, hi) = (bbox.min[axis], bbox.max[axis]);
    let sides = Sides::new(bbox, axis, pricer.scale);
    let (mut nl, mut nr) = (0usize, n);
    let mut i = 0;
    while let Some(&first) = events.get(i) {
        let key = first & !3;
        let start = i;
        let mut count = |kind: u64| {
            let from = i;
            while events.get(i) == Some(&(key | kind)) {
                i += 1;
            }
            i - from
        };
        let ends = count(END);
        let planars = count(PLANAR);
        let starts = count(START);
        if i == start {
            // No other kind is made; never stall whatever the input.
            i += 1;
            continue;
        }
        nr -= planars + ends;
        let pos = unordered((key >> 2) as u32);
        if lo < pos && pos < hi {
            best.offer_plane(pricer, sides.at(pos), axis, pos, nl, nr, planars);
        }
        nl += starts + planars;
    }
}

/// The exact SAH over every event position strictly inside the box, as [`sweep`] prices it (the
/// planar triangles at a position to the cheaper side), for a node of at most [`COUNTED`] items: for
/// each candidate (every item's lower and upper bound) the items below, above and in the plane
/// are counted over fixed-size arrays (padding that counts nowhere), in the order of the items.
fn counted_split(items: &[Item], bbox: &Aabb, pricer: &Pricer, best: &mut Best) {
    let n = items.len();
    if n > COUNTED {
        return;
    }
    for axis in 0..3 {
        let (blo, bhi) = (bbox.min[axis], bbox.max[axis]);
        if !(blo < bhi) {
            continue;
        }
        let sides = Sides::new(bbox, axis, pricer.scale);
        // Padding: `lo < p`, `hi > p` and `lo == p == hi` are false for every finite `p`.
        let (mut lo, mut hi) = ([f32::INFINITY; COUNTED], [f32::NEG_INFINITY; COUNTED]);
        for ((l, h), it) in lo.iter_mut().zip(hi.iter_mut()).zip(items) {
            *l = it.lo[axis];
            *h = it.hi[axis];
        }
        let m = n.next_multiple_of(4).min(COUNTED);
        for &p in lo.iter().take(n).chain(hi.iter().take(n)) {
            if !(blo < p && p < bhi) {
                continue;
            }
            let (mut below, mut above, mut planar) = ([0u32; 4], [0u32; 4], [0u32; 4]);
            for (l4, h4) in lo[..m].chunks_exact(4).zip(hi[..m].chunks_exact(4)) {
                for k in 0..4 {
                    below[k] += u32::from(l4[k] < p);
                    above[k] += u32::from(h4[k] > p);
                    planar[k] += u32::from((l4[k] == p) & (h4[k] == p));
                }
            }
            let sum = |c: [u32; 4]| (c[0] + c[1] + c[2] + c[3]) as usize;
            let (nl, nr, np) = (sum(below), sum(above), sum(planar));
            best.offer_plane(pricer, sides.at(p), axis, p, nl, nr, np);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workload::SplitMix64;

    /// A finished array with much spare room is copied into a block of its length, its contents
    /// and the budget's count kept; one with little spare room, or where the limit has no room for
    /// the copy, stays as it is.
    #[test]
    fn the_finished_arrays_are_fitted_where_the_limit_allows() {
        let size = core::mem::size_of::<u32>();
        let mut budget = MemoryBudget::new(0);
        let mut v: Vec<u32> = budget.vec(100, "test").unwrap();
        v.extend(0..10);
        fit(&mut budget, &mut v, "test").unwrap();
        assert_eq!((v.len(), v.capacity()), (10, 10));
        assert_eq!(v, (0..10).collect::<Vec<u32>>());
        assert_eq!(budget.used(), 10 * size);
        let mut tight: Vec<u32> = budget.vec(17, "test").unwrap();
        tight.extend(0..16);
        fit(&mut budget, &mut tight, "test").unwrap();
        assert_eq!(tight.capacity(), 17, "a sixteenth spare is kept");
        // A limit that holds the array but not a copy beside it.
        let mut limited = MemoryBudget::new(100 * size + 5 * size);
        let mut w: Vec<u32> = limited.vec(100, "test").unwrap();
        w.extend(0..10);
        fit(&mut limited, &mut w, "test").unwrap();
        assert_eq!((w.len(), w.capacity()), (10, 100));
        assert_eq!(limited.used(), 100 * size);
    }

    /// The vector binning is the plain one: same tight bounds and the same bin of every bound, on random
    /// boxes over many magnitudes, with equal, huge and degenerate (flat) extents, and bins of 8 to
    /// 32 as the builder uses them.
    #[test]
    fn vector_binning_matches_the_plain_one() {
        let mut rng = SplitMix64::new(11);
        for case in 0..200 {
            let n = 1 + case % 97;
            let scale = [1e-30f32, 1e-3, 1.0, 7.0, 1e6, 1e30][case % 6];
            let items: Vec<Item> = (0..n)
                .map(|i| {
                    let mut lo = [0.0f32; 3];
                    let mut hi = [0.0f32; 3];
                    for a in 0..3 {
                        let x = (rng.next_f32() * 2.0 - 1.0) * scale;
                        let w = if (case + a) % 5 == 0 {
                            0.0
                        } else {
                            rng.next_f32() * scale
                        };
                        lo[a] = x;
                        hi[a] = if case % 7 == 0 { f32::MAX } else { x + w };
                    }
                    Item {
                        lo,
                        hi,
                        prim: i as u32,
                    }
                })
                .collect();
            let (tlo, thi) = tight_bounds(&items);
            assert_eq!((tlo, thi), tight_bounds_portable(&items), "case {case}");
            let bins = (n / 4).clamp(4, BINS);
            let top = (bins - 1) as f32;
            let mut sc = [0.0f32; 3];
            for a in 0..3 {
                let v = bins as f32 / (thi[a] - tlo[a]);
                if tlo[a] < thi[a] && v.is_finite() {
                    sc[a] = v;
                }
            }
            for it in &items {
                for x in [&it.lo, &it.hi] {
                    let want = bins_portable(x, tlo, sc, top);
                    assert!(want.iter().all(|&b| b < bins), "case {case}: {want:?}");
                    #[cfg(target_arch = "x86_64")]
                    assert_eq!(bins_sse2(x, tlo, sc, top), want, "case {case}");
                }
            }
        }
    }

    /// The f32 candidate price is the cost model's split cost with leaf children, scaled by the
    /// node's area: one SAH, at two precisions (relative error below 1e-5 on boxes from 1e-20 to
    /// 1e20, both sides empty or not).
    #[test]
    fn candidate_price_is_the_cost_model() {
        let costs = Costs {
            ct: 1.0,
            ci: 0.5,
            keep: 0.5,
        };
        let mut rng = SplitMix64::new(9);
        for i in 0..20_000 {
            let scale = 10f32.powi((i % 41) - 20);
            let a = rng.next_vec3() * scale;
            let b = a + (rng.next_vec3() + glam::Vec3::splat(0.01)) * scale;
            let bbox = Aabb { min: a, max: b };
            let axis = i as usize % 3;
            let pos = a[axis] + rng.next_f32() * (b[axis] - a[axis]);
            let (nl, nr) = (rng.below(40), rng.below(40));
            let pricer = Pricer::new(&costs, &bbox);
            let sides = Sides::new(&bbox, axis, pricer.scale);
            let (al, ar) = sides.at(pos);
            let price = f64::from(pricer.price(al, ar, nl, nr)) * pricer.inv_sa;
            let (pl, pr) = probabilities(&bbox, axis, pos);
            let cost = costs.interior(pl, pr, costs.leaf(nl), costs.leaf(nr), nl, nr);
            assert!(
                (price - cost).abs() <= 1e-5 * cost,
                "{bbox:?} axis {axis} at {pos}: price {price} cost {cost}"
            );
        }
    }

    /// Bad refines where they pay: slivers spanning the box need them at the root (without, the
    /// tree is one leaf of every triangle), the Sierpinski tetrahedron needs its near ties in small
    /// nodes (without, leaves of 32 triangles), and the small nodes' other bad refines are not
    /// taken (the build does less work).
    #[test]
    fn bad_refines_where_they_pay() {
        use crate::accel::kdtree::{KdTree, KdTreeParams};
        use crate::budget::MemoryBudget;
        let tree = |data: &crate::mesh::MeshData| {
            let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
            KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap()
        };
        let slivers = tree(&crate::procedural::random_slivers(2000, 5));
        assert!(
            slivers.largest_leaf() <= 128 && slivers.leaf_count() > 100,
            "slivers: {} leaves, the largest {}",
            slivers.leaf_count(),
            slivers.largest_leaf()
        );
        // At `C_i = 0.5` (the default until stop 34), where leaves of 32 cost more than the near
        // ties' splits; the default's cheaper tests make those leaves worth keeping.
        let mesh = TriMesh::from_source(
            &crate::procedural::tetra(5).as_source(),
            &mut MemoryBudget::new(0),
        )
        .unwrap();
        let params = KdTreeParams {
            intersection_cost: 0.5,
            ..KdTreeParams::DEFAULT
        };
        let tetra = KdTree::build(&mesh, &params, &mut MemoryBudget::new(0)).unwrap();
        assert_eq!(tetra.reference_count(), 4096);
        assert!(tetra.largest_leaf() <= 16, "{}", tetra.largest_leaf());
        // Every bad refine: 30.3 items per triangle (measured); near ties only: 19.2.
        let gears = tree(&crate::procedural::by_name("gears", 5000).unwrap());
        assert!(
            gears.build_work() < 25 * 5040,
            "gears: work {}",
            gears.build_work()
        );
    }
}
