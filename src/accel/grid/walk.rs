//! The walk: an Amanatides–Woo 3D-DDA over the cells a ray crosses inside `[tmin, tmax]`, front
//! to back, testing each cell's list; far origins and extreme directions are walked on a
//! rescaled line without the early exit (docs/design.md, "Uniform grid"). A ray that meets a cell
//! with a nested grid is walked again by `walk_nested`, which walks nested grids in place of their
//! cells' lists (docs/design.md, "Nested grids").

use glam::{Vec3, Vec3A};

use super::blocks::BLOCK;
use super::nested::MAX_DEPTH;
use super::{GridWork, UniformGrid};
use crate::accel::brute::test_all;
use crate::accel::{test_blocks, Mailbox};
use crate::mesh::TriMesh;
use crate::ray::{Hit, Ray};
use crate::triangle::{AnyKernel, PreparedRay, TriangleLoop, TriangleTest};

/// One query's walk of the line `plan` (from [`Plan::entering`] on the same ray, before it was
/// prepared for the triangle test). `COUNT` counts the work; `ANY` stops at the first hit (any-hit query).
pub(super) struct Walk<'a, const COUNT: bool, const ANY: bool> {
    pub grid: &'a UniformGrid,
    pub mesh: &'a TriMesh,
    pub work: &'a mut GridWork,
    pub plan: Plan,
}

/// Origins farther than this many of the smallest cells from the grid are walked by testing every
/// triangle: beyond it the f64 entry point of a far ray may be off its line by more than the margin.
const FAR_WALK_CELLS: f32 = 1.099_511_6e12;

/// 16·2^-149: sixteen times the largest error of a subnormal `t`, per unit of direction. Directions
/// longer than `margin / SUBNORMAL_T_ERROR` are walked scaled (see [`Line::of`]).
const SUBNORMAL_T_ERROR: f64 = 2.242_077_542_919_707_3e-44;

/// The line a ray is walked on, its window, and whether the walk may stop at the first cell
/// whose exit lies beyond the best hit.
#[derive(Clone, Copy)]
pub(super) struct Line {
    pub(super) org: Vec3,
    dir: Vec3,
    pub(super) inv: Vec3,
    pub(super) t0: f32,
    t1: f32,
    early_exit: bool,
}

/// How a ray is answered.
#[derive(Clone, Copy)]
pub(super) enum Plan {
    /// It misses the grid's box.
    Miss,
    /// Its origin is too far for any walk: every triangle is tested.
    TestAll,
    /// Walk this line.
    Walk(Line),
}

impl Plan {
    /// How `grid` answers `ray`, or `None` when the grid is empty or the ray misses its box
    /// ([`Line::of`]). Made from the ray before it is prepared for the triangle test
    /// (`run_clipped_query`); a ray the test refuses (a NaN or infinite component) may get any
    /// plan (every value is a float operation: nothing can panic), and the query refuses it after.
    #[inline(always)]
    pub(super) fn entering(grid: &UniformGrid, ray: &Ray) -> Option<Plan> {
        if grid.offsets.is_empty() {
            return None;
        }
        match Line::of(grid, ray.org, ray.dir, ray.tmin, ray.tmax) {
            Plan::Miss => None,
            plan => Some(plan),
        }
    }
}

impl Line {
    /// The line to walk for the ray `org + t·dir`, `t` in `[tmin, tmax]`, through `grid`
    /// (non-empty), clipped to the box.
    ///
    /// Four lanes at a time (the fourth unused): every value is the one the scalar arithmetic
    /// gives (the same IEEE operations per lane), and none can be NaN where `min`/`max` meet it —
    /// the box, the origin and the direction are finite, a finite inverse times a finite
    /// difference is never NaN, and the lanes of a non-finite inverse are replaced before they
    /// are compared — so the SSE `min`/`max`, which do not handle NaN, give the same answers.
    #[inline(always)]
    fn of(grid: &UniformGrid, org: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Plan {
        let shape = &grid.shape;
        let (mut o, mut d) = (org, dir);
        let (mut t0, mut t1) = (tmin, tmax);
        let (lo, hi) = (Vec3A::from(shape.bounds.min), Vec3A::from(shape.bounds.max));
        let mut early_exit = true;
        // An origin farther than the margin covers: walk the same line from where it enters the
        // box (found in f64, rounded to f32: off the line by far less than the margin), over the
        // whole box and without the early exit, whose t would be in the wrong frame. Beyond 2^40
        // cells even the f64 entry point may be off by more than the margin: test every triangle.
        let reach = (lo - Vec3A::from(o))
            .abs()
            .max((hi - Vec3A::from(o)).abs())
            .max_element();
        if !(reach <= shape.near_reach) {
            if !(reach <= FAR_WALK_CELLS * shape.min_cell) {
                return Plan::TestAll;
            }
            match entry_point(o, d, shape.bounds.min, shape.bounds.max) {
                Some(p) => o = p,
                None => return Plan::Miss,
            }
            early_exit = false;
            t0 = -f32::INFINITY;
            t1 = f32::INFINITY;
        }
        // Directions whose t would leave the range where f32 keeps 24 bits: a non-zero component too
        // small to invert (below ~3e-39) still moves along that axis over the f32 range of t; one
        // small against the scene's coordinates can make the t of crossing the scene overflow; one
        // so large that t becomes subnormal loses the precision the margin counts on (a subnormal
        // t is off by up to 2^-149 in absolute terms, 2^-149·|d| in space). Walk the same line with
        // the direction scaled by a power of two (no rounding) to a largest component in [1, 2),
        // over the whole box and without the early exit, whose t would be in other units. A
        // component that is still too small to invert is below 2^-126 of the largest, so across
        // the box the ray moves along it by less than 2^-126 of the box's extent, far inside the
        // box's padding and the cells' margin: treating that axis as parallel still covers the line.
        let (o4, mut d4) = (Vec3A::from(o), Vec3A::from(d));
        let mut inv = Vec3A::ONE / d4;
        let largest = d4.abs().max_element();
        let magnitude = lo.abs().max(hi.abs()).max_element() + o4.abs().max_element();
        // A non-zero component whose inverse is ±∞ (d is finite, so the inverse is never NaN).
        let uninvertible = (d4.cmpne(Vec3A::ZERO) & inv.abs().cmpeq(Vec3A::INFINITY)).any();
        let may_overflow = largest * (f32::MAX / 1024.0) < magnitude;
        let subnormal_t =
            f64::from(largest) * SUBNORMAL_T_ERROR > f64::from(shape.margin.min_element());
        if uninvertible || may_overflow || subnormal_t {
            early_exit = false;
            d = unit_scaled(d, largest);
            d4 = Vec3A::from(d);
            inv = Vec3A::ONE / d4;
            t0 = -f32::INFINITY;
            t1 = f32::INFINITY;
        }
        // Axes with a finite inverse bound t by the box's slab; the others (the ray parallel to
        // the slab) miss when the origin is outside it.
        let finite = inv.abs().cmplt(Vec3A::INFINITY);
        if (!finite & (o4.cmplt(lo) | o4.cmpgt(hi))).any() {
            return Plan::Miss;
        }
        let (ta, tb) = ((lo - o4) * inv, (hi - o4) * inv);
        let near = Vec3A::select(finite, ta.min(tb), Vec3A::NEG_INFINITY).max_element();
        let far = Vec3A::select(finite, ta.max(tb), Vec3A::INFINITY).min_element();
        t0 = if near > t0 { near } else { t0 };
        t1 = if far < t1 { far } else { t1 };
        if !(t0 <= t1) {
            return Plan::Miss;
        }
        Plan::Walk(Line {
            org: o,
            dir: d,
            inv: inv.into(),
            t0,
            t1,
            early_exit,
        })
    }
}

/// The DDA's state per axis (a fourth, unused slot lets an index `& 3` go unchecked). A moving axis
/// crosses the plane `lo + k·size` next, at `t_next = (lo + k·size − org)·inv`: computed from the
/// plane's position each time, so no error accumulates (docs/design.md bounds it), and never NaN
/// (a finite difference times a finite inverse; `lo − org` times `inv` and `size·inv` apart could
/// each overflow, and their sum be ∞ − ∞). It may cross planes until `k` reaches `k_end` (the
/// box's face); a non-moving axis has `t_next = ∞` and `k = k_end`.
#[derive(Clone, Copy)]
struct Axes {
    t_next: [f32; 4],
    /// The plane after the next one's t (`plane_t(a, k + step)`), made when `k` moves so that a
    /// step only moves it into `t_next`: the next axis then waits for a copy, not for the plane's
    /// arithmetic (a conversion, two products and two sums on the walk's chain from one
    /// cell's choice of axis to the next). Only read on a moving axis not at `k_end`, where
    /// `k + step` is a plane of the grid.
    t_after: [f32; 4],
    /// The next plane's index (exact: f32 would stop counting at 2^24 planes, and a grid may have
    /// more on one axis).
    k: [u32; 4],
    k_end: [u32; 4],
    /// +1 or −1 (as a wrapping add).
    step: [u32; 4],
    /// The flat index's change per step.
    delta: [usize; 4],
    lo: [f32; 4],
    size: [f32; 4],
    org: [f32; 4],
    inv: [f32; 4],
    /// The start cell's coordinates: no walk visits a cell before them on a moving axis, and a
    /// non-moving axis keeps them.
    start: [u32; 4],
    /// The block index's change per step (as a wrapping add).
    block_delta: [usize; 4],
}

impl Axes {
    /// The t of the plane `k` on `axis` (`k` rounded to f32 above 2^24, a whole cell at most:
    /// such an axis has cells below `u·E` wide, far inside the margin's `16u·E`).
    #[inline(always)]
    fn plane_t(&self, axis: usize, k: u32) -> f32 {
        (self.lo[axis] + k as f32 * self.size[axis] - self.org[axis]) * self.inv[axis]
    }

    /// Puts moving axis `a`'s next plane at `k`: `t_next` and `t_after` from the planes' positions.
    #[inline(always)]
    fn set_next_plane(&mut self, a: usize, k: u32) {
        self.k[a] = k;
        self.t_next[a] = self.plane_t(a, k);
        self.t_after[a] = self.plane_t(a, k.wrapping_add(self.step[a]));
    }

    /// The axis whose boundary comes first (ties to the lower axis), without branches, and its
    /// crossing's t. A non-moving axis has t = ∞ and is chosen only when every axis is at ∞, past
    /// the window.
    #[inline(always)]
    fn next(&self) -> (usize, f32) {
        let (tx, ty, tz) = (self.t_next[0], self.t_next[1], self.t_next[2]);
        let not_x = !((tx <= ty) & (tx <= tz));
        let axis = (usize::from(not_x) * (1 + usize::from(!(ty <= tz)))) & 3;
        (axis, self.t_next[axis])
    }

    /// Whether axis `a` moves (a non-moving one keeps `step = 0`).
    #[inline(always)]
    fn moves(&self, a: usize) -> bool {
        self.step[a] != 0
    }

    /// Whether moving axis `a` moves up (towards the last cell).
    #[inline(always)]
    fn up(&self, a: usize) -> bool {
        self.step[a] == 1
    }

    /// The current cell's coordinate on moving axis `a` (from the next plane's index).
    #[inline(always)]
    fn coordinate(&self, a: usize) -> u32 {
        if self.up(a) {
            self.k[a] - 1
        } else {
            self.k[a]
        }
    }

    /// Entering `block` (the current cell's): nothing to do when it holds a triangle (no block
    /// steps), else [`Axes::skip_empty`].
    #[inline(always)]
    fn enter_block(
        &mut self,
        grid: &UniformGrid,
        block: &mut usize,
        index: &mut usize,
        t_stop: f32,
    ) -> Option<u32> {
        if grid.blocks.occupied(*block) {
            Some(0)
        } else {
            self.skip_empty(grid, block, index, t_stop)
        }
    }

    /// Steps over empty blocks, from the current cell (in an empty block) on, until the walk
    /// enters a block that holds a triangle: then the axes and `index` are those of the cell the
    /// cell-by-cell walk would be in at that crossing, `block` is its block, and the block steps
    /// taken are returned. `None` when the walk ends first (a crossing at or past `t_stop`, or the
    /// box's face): nothing in the rest of the window is listed.
    ///
    /// The block faces are cell planes, computed as the walk computes them, and taken in the
    /// walk's order (the smallest `t`, ties to the lower axis), so the cells of the block entered
    /// are found by counting, per axis, the planes inside it that the walk would have crossed
    /// before that crossing. A walk never goes back past its start cell, so the count starts
    /// there when it lies in the block.
    #[inline(never)]
    fn skip_empty(
        &mut self,
        grid: &UniformGrid,
        block: &mut usize,
        index: &mut usize,
        t_stop: f32,
    ) -> Option<u32> {
        let (blocks, res) = (&grid.blocks, grid.shape.res);
        // The block face after `face` on moving axis `a` (past the box's face when `face` is it:
        // a plane no walk crosses, whose t, possibly infinite, is never read: an axis is stepped
        // only while its face is not the box's).
        let beyond = |a: usize, face: u32| {
            if self.up(a) {
                (face + BLOCK).min(res[a])
            } else {
                face.wrapping_sub(BLOCK)
            }
        };
        // The next block face per axis and its t (∞ on a non-moving axis, whose k is k_end), and
        // the t of the face after it: a step moves that into place and makes the next one off the
        // chain from one step's choice of axis to the next (as the cell walk's `t_after`). The
        // three next t are kept in registers, not in an array indexed by the axis, whose store
        // and reload were on that chain too.
        let mut face = self.k_end;
        let mut t = [f32::INFINITY; 4];
        let mut t_beyond = [f32::INFINITY; 4];
        for a in 0..3 {
            if self.moves(a) {
                let c = self.coordinate(a) / BLOCK * BLOCK;
                face[a] = if self.up(a) {
                    (c + BLOCK).min(res[a])
                } else {
                    c
                };
                t[a] = if face[a] == self.k[a] {
                    self.t_next[a]
                } else {
                    self.plane_t(a, face[a])
                };
                t_beyond[a] = self.plane_t(a, beyond(a, face[a]));
            }
        }
        let (mut tx, mut ty, mut tz) = (t[0], t[1], t[2]);
        let mut steps = 0;
        loop {
            let not_x = !((tx <= ty) & (tx <= tz));
            let axis = (usize::from(not_x) * (1 + usize::from(!(ty <= tz)))) & 3;
            // The chosen axis's t is the least of the three (none is NaN).
            let t_axis = lesser(tx, lesser(ty, tz));
            if t_axis >= t_stop || face[axis] == self.k_end[axis] {
                return None;
            }
            steps += 1;
            *block = block.wrapping_add(self.block_delta[axis]);
            let crossed = face[axis];
            let next = beyond(axis, crossed);
            face[axis] = next;
            let t_next = t_beyond[axis];
            debug_assert_eq!(t_next.to_bits(), self.plane_t(axis, next).to_bits());
            tx = if axis == 0 { t_next } else { tx };
            ty = if axis == 1 { t_next } else { ty };
            tz = if axis == 2 { t_next } else { tz };
            t_beyond[axis] = self.plane_t(axis, beyond(axis, next));
            debug_assert!(*block < blocks.res.iter().map(|&r| r as usize).product::<usize>());
            if !blocks.occupied(*block) {
                continue;
            }
            // The cell entered on `axis`, and on every other moving axis the cell after the last
            // plane of the block crossed before (t, axis): earlier, or as early on a lower axis.
            let (mut cell, mut stride) = (0usize, 1usize);
            for a in 0..3 {
                let c = if a == axis {
                    if self.up(a) {
                        crossed
                    } else {
                        crossed - 1
                    }
                } else if self.moves(a) {
                    let before = |t: f32| t < t_axis || (t == t_axis && a < axis);
                    let up = self.up(a);
                    // The block's cells on this axis, from the face ahead.
                    let (first, last) = if up {
                        ((face[a] - 1) / BLOCK * BLOCK, face[a] - 1)
                    } else {
                        (face[a], (face[a] + BLOCK).min(res[a]) - 1)
                    };
                    if up {
                        let mut c = first.max(self.start[a]);
                        while c < last && before(self.plane_t(a, c + 1)) {
                            c += 1;
                        }
                        c
                    } else {
                        let mut c = last.min(self.start[a]);
                        while c > first && before(self.plane_t(a, c)) {
                            c -= 1;
                        }
                        c
                    }
                } else {
                    self.start[a]
                };
                if self.moves(a) {
                    self.set_next_plane(a, if self.up(a) { c + 1 } else { c });
                }
                cell += c as usize * stride;
                stride *= res[a] as usize;
            }
            *index = cell;
            return Some(steps);
        }
    }
}

impl<const COUNT: bool, const ANY: bool> TriangleLoop for Walk<'_, COUNT, ANY> {
    type Output = Hit;

    #[inline(always)]
    fn run<T: TriangleTest>(self, test: T) -> Hit {
        let Walk {
            grid,
            mesh,
            work,
            plan,
        } = self;
        let mut best = Hit::MISS;
        // The work before this query, for a start over in the nested walk.
        let counted_before = *work;
        let mut axes = Axes::none();
        let Cursor {
            mut index,
            mut block,
            mut t_stop,
            no_exit,
        } = match axes.start_on(grid, plan, best.t, work, COUNT) {
            Start::Walk(at) => at,
            Start::Nothing => return best,
            Start::TooFar => return test_all::<T, ANY>(&test, mesh),
        };
        let mut mailbox = Mailbox::new();
        loop {
            // The axis the walk leaves this cell by (chosen before the cell's test, which does not
            // change it).
            let (axis, t_axis) = axes.next();
            if COUNT {
                work.cells += 1;
            }
            let (first, end, slab) = grid.cell(index);
            let span = (first, end);
            // The plain walk of a line from the ray's own origin passes over a cell whose content
            // the line cannot reach in its window (content.rs; the line is read from memory only
            // for a flagged cell). The counted walk tests it, so the work it counts, which the
            // calibration prices, is what it was.
            let passed = !COUNT
                && slab
                && match plan {
                    // SAFETY: the cell is flagged (`slab`).
                    Plan::Walk(l) => {
                        l.early_exit && unsafe { grid.content.misses(index, &l, t_stop) }
                    }
                    _ => false,
                };
            #[cfg(all(test, feature = "std"))]
            if passed {
                super::content::PASSED.with(|n| n.set(n.get() + 1));
            }
            if span.0 != span.1 && !passed {
                // Only a list at least `nested_span` long may have a nested grid (usize::MAX when
                // none has): the query then starts over in the nested walk, out of this loop. (Going
                // on from here instead kept the position's values alive for the exit, and cost 10 %
                // on hair, which has no nested grid: measured.) A long list without a nested grid is
                // tested there.
                if span.1 - span.0 >= grid.nested_span {
                    if COUNT {
                        *work = counted_before;
                    }
                    return walk_nested::<ANY>(grid, test.any_axes(), mesh, work, COUNT);
                }
                if COUNT {
                    work.tests += grid.listed(index);
                }
                if let Some(h) =
                    grid.test_span::<T, ANY>(&test, mesh, span, &mut best, &mut mailbox)
                {
                    return h;
                }
                t_stop = lesser(t_stop, greater(best.t, no_exit));
            }
            if !step(
                grid, &mut axes, axis, t_axis, &mut index, &mut block, t_stop, work, COUNT,
            ) {
                return best;
            }
        }
    }
}

/// The query's walk of `grid` (not empty) when it meets a cell with a nested grid: walks a cell's
/// nested grid in place of its list (and so on, up to `MAX_DEPTH` deep). Entering one saves the
/// outer walk's position, which is taken up again when the nested walk ends.
///
/// A hit of one of the cell's triangles at a point inside the cell's enlarged box lies inside the
/// nested grid's box, where the nested walk finds it as the outer walk finds hits in its cells; a
/// hit elsewhere is found in the cell holding its point, as without nesting (docs/design.md,
/// "Nested grids"). The nested walk's early exit starts bounded by the best hit so far.
///
/// Out of line and cold, with the test's axes chosen per call: one copy for the six kernels.
#[cold]
#[inline(never)]
fn walk_nested<const ANY: bool>(
    grid: &UniformGrid,
    test: AnyKernel<'_>,
    mesh: &TriMesh,
    work: &mut GridWork,
    count: bool,
) -> Hit {
    let ray = test.ray();
    let mut best = Hit::MISS;
    let mut axes = Axes::none();
    let mut at = match axes.start(grid, ray, best.t, work, count) {
        Start::Walk(at) => at,
        Start::Nothing => return best,
        Start::TooFar => return test_all::<_, ANY>(&test, mesh),
    };
    let mut mailbox = Mailbox::new();
    // The grid walked, and the outer walks' places while nested grids are walked.
    let mut walked = grid;
    let mut outer: [Option<(&UniformGrid, Axes, Cursor)>; MAX_DEPTH] = [None; MAX_DEPTH];
    let mut depth = 0;
    loop {
        let (axis, t_axis) = axes.next();
        if count {
            work.cells += 1;
        }
        let span = walked.span(at.index);
        if span.0 != span.1 {
            // A list whose nested grid cannot take the ray is tested whole.
            let mut whole = true;
            // (A grid at the deepest level has none: its `nested_span` is usize::MAX.)
            if span.1 - span.0 >= walked.nested_span {
                if let Some(nested) = walked.nested_at(at.index) {
                    // The cell's triangles larger than the cell first, then its nested grid.
                    let ids = &nested.large_ids;
                    let id = |b: usize, lane: usize| {
                        ids.get(b).map_or(Hit::INVALID_ID, |four| four[lane & 3])
                    };
                    if let Some(h) =
                        test_blocks::<_, ANY>(&test, &nested.large, id, &mut best, &mut mailbox)
                    {
                        return h;
                    }
                    let sub = &nested.grid;
                    let mut inner = Axes::none();
                    let start = inner.start(sub, ray, best.t, work, count);
                    if count && !matches!(start, Start::TooFar) {
                        // (On TooFar the whole list, large triangles included, is counted below.)
                        work.tests += nested.large_count;
                    }
                    match start {
                        // A slot is free, as nested grids go no deeper than MAX_DEPTH (without one
                        // the whole list is tested).
                        Start::Walk(inner_at) => {
                            if let Some(slot) = outer.get_mut(depth) {
                                *slot = Some((walked, core::mem::replace(&mut axes, inner), at));
                                depth += 1;
                                (walked, at) = (sub, inner_at);
                                continue;
                            }
                        }
                        Start::Nothing => whole = false,
                        Start::TooFar => {}
                    }
                }
            }
            if whole {
                if count {
                    work.tests += walked.listed(at.index);
                }
                if let Some(h) =
                    walked.test_span::<_, ANY>(&test, mesh, span, &mut best, &mut mailbox)
                {
                    return h;
                }
            }
            at.t_stop = lesser(at.t_stop, greater(best.t, at.no_exit));
        }
        // The next cell, of this walk or, when it ends, of the outer one.
        let (mut axis, mut t_axis) = (axis, t_axis);
        while !step(
            walked,
            &mut axes,
            axis,
            t_axis,
            &mut at.index,
            &mut at.block,
            at.t_stop,
            work,
            count,
        ) {
            let Some((grid, outer_axes, outer_at)) = depth
                .checked_sub(1)
                .and_then(|d| outer.get_mut(d))
                .and_then(Option::take)
            else {
                return best;
            };
            depth -= 1;
            (walked, axes, at) = (grid, outer_axes, outer_at);
            at.t_stop = lesser(at.t_stop, greater(best.t, at.no_exit));
            (axis, t_axis) = axes.next();
        }
    }
}

/// Where a walk is, besides its axes: the cell, its block, and when to stop.
#[derive(Clone, Copy)]
struct Cursor {
    /// The current cell's flat index (below the grid's cell count).
    index: usize,
    /// The current cell's block.
    block: usize,
    /// The walk ends at the first cell whose exit `t_axis` reaches `t_stop`: past the window
    /// (`t_axis > t1`, i.e. `t_axis ≥ next_up(t1)`), or, with the early exit, at or past the best
    /// hit (a triangle not yet tested lies beyond the current cell by the insertion margin, so a
    /// hit before the cell's exit cannot be beaten).
    t_stop: f32,
    /// −∞ with the early exit, else +∞: `t_stop = min(t_stop, max(best.t, no_exit))` keeps `t_stop`
    /// at the window's end when the early exit is off.
    no_exit: f32,
}

/// How a walk starts.
enum Start {
    /// At this cell (its axes written), in a block that holds triangles.
    Walk(Cursor),
    /// No cell with triangles lies in the ray's window before `limit` (with the early exit).
    Nothing,
    /// The ray's origin is too far for any walk of this grid: its triangles must be tested whole.
    TooFar,
}

impl Axes {
    /// Axes that move on no axis, for [`Axes::start`] to fill. (A function, not a constant: the
    /// constant was copied whole per ray, the literal's stores that `start` overwrites are
    /// dropped.)
    #[inline(always)]
    fn none() -> Axes {
        Axes {
            t_next: [f32::INFINITY; 4],
            t_after: [f32::INFINITY; 4],
            k: [0; 4],
            k_end: [0; 4],
            step: [0; 4],
            delta: [0; 4],
            lo: [0.0; 4],
            size: [0.0; 4],
            org: [0.0; 4],
            inv: [0.0; 4],
            start: [0; 4],
            block_delta: [0; 4],
        }
    }

    /// Starts the walk of `grid` (not empty) for `r`, its early exit bounded by `limit` (the best
    /// hit's t so far), at its first cell in a block that holds triangles, writing its axes over
    /// `self` ([`Axes::none`]); `count` counts the blocks stepped over.
    #[inline(always)]
    fn start(
        &mut self,
        grid: &UniformGrid,
        r: &PreparedRay,
        limit: f32,
        work: &mut GridWork,
        count: bool,
    ) -> Start {
        let plan = Line::of(grid, r.org, r.dir, r.tmin, r.tmax);
        self.start_on(grid, plan, limit, work, count)
    }

    /// [`Axes::start`] on the line `plan` (made from the same ray).
    #[inline(always)]
    fn start_on(
        &mut self,
        grid: &UniformGrid,
        plan: Plan,
        limit: f32,
        work: &mut GridWork,
        count: bool,
    ) -> Start {
        let axes = self;
        let line = match plan {
            Plan::Walk(line) => line,
            Plan::Miss => return Start::Nothing,
            Plan::TestAll => return Start::TooFar,
        };
        let shape = &grid.shape;
        let t_start = line.t0.clamp(-f32::MAX, f32::MAX);
        let mut index = 0usize;
        let mut block = 0usize;
        let mut stride = 1usize;
        let mut block_stride = 1usize;
        for a in 0..3 {
            let res = shape.res[a];
            // The cell of the entry point, in f64 so that the index keeps its accuracy on grids of
            // many cells (an f32 inverse cell size is off by 2^-23 relative, a whole cell at 2^23
            // cells); truncation is floor for non-negative values and the rest clamps to 0
            // either way (NaN too).
            let p = line.org[a] + t_start * line.dir[a];
            let f = (f64::from(p) - f64::from(shape.bounds.min[a])) * grid.inv_cell64[a];
            let cell = if f >= 0.0 { (f as u32).min(res - 1) } else { 0 };
            index += cell as usize * stride;
            block += (cell / BLOCK) as usize * block_stride;
            axes.start[a] = cell;
            let inv = line.inv[a];
            let up = line.dir[a] > 0.0;
            if inv.is_finite() {
                axes.block_delta[a] = if up {
                    block_stride
                } else {
                    block_stride.wrapping_neg()
                };
                axes.k_end[a] = if up { res } else { 0 };
                axes.step[a] = if up { 1 } else { u32::MAX };
                axes.delta[a] = if up { stride } else { stride.wrapping_neg() };
                axes.lo[a] = shape.bounds.min[a];
                axes.size[a] = shape.cell_size[a];
                axes.org[a] = line.org[a];
                axes.inv[a] = inv;
                axes.set_next_plane(a, cell + u32::from(up));
            }
            stride *= res as usize;
            block_stride *= grid.blocks.res[a] as usize;
        }
        let no_exit = if line.early_exit {
            f32::NEG_INFINITY
        } else {
            f32::INFINITY
        };
        let t_stop = lesser(next_up(line.t1), greater(limit, no_exit));
        let Some(steps) = axes.enter_block(grid, &mut block, &mut index, t_stop) else {
            return Start::Nothing;
        };
        if count {
            work.cells += steps;
        }
        Start::Walk(Cursor {
            index,
            block,
            t_stop,
            no_exit,
        })
    }
}

/// Steps `axes` along `axis` (from [`Axes::next`], its crossing at `t_axis`) from cell `index`
/// (in block `block`) of `grid` to the next cell that holds triangles; false when the walk ends
/// first (see [`Cursor::t_stop`]).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn step(
    grid: &UniformGrid,
    axes: &mut Axes,
    axis: usize,
    t_axis: f32,
    index: &mut usize,
    block: &mut usize,
    t_stop: f32,
    work: &mut GridWork,
    count: bool,
) -> bool {
    if t_axis >= t_stop || axes.k[axis] == axes.k_end[axis] {
        return false;
    }
    // Stepping `axis` keeps every coordinate of the cell in [0, res): `k` starts at the cell's
    // far plane on that side and stops at the box's face.
    *index = index.wrapping_add(axes.delta[axis]);
    let crossed = axes.k[axis];
    let k = crossed.wrapping_add(axes.step[axis]);
    axes.k[axis] = k;
    // `plane_t(axis, k)`, made when `k` was `crossed`.
    axes.t_next[axis] = axes.t_after[axis];
    debug_assert_eq!(axes.t_next[axis].to_bits(), axes.plane_t(axis, k).to_bits());
    axes.t_after[axis] = axes.plane_t(axis, k.wrapping_add(axes.step[axis]));
    debug_assert!(*index < grid.cell_count());
    // A block's face: the next cell is in the neighbouring block, which may be empty.
    if crossed & grid.blocks.faces == 0 {
        *block = block.wrapping_add(axes.block_delta[axis]);
        let Some(steps) = axes.enter_block(grid, block, index, t_stop) else {
            return false;
        };
        if count {
            work.cells += steps;
        }
    }
    true
}

/// The smaller of `a` and `b`, neither NaN (a hit's t, a window's end, ±∞): one comparison, where
/// `f32::min` also handles NaN (several instructions, and this runs once per cell with triangles).
#[inline(always)]
fn lesser(a: f32, b: f32) -> f32 {
    if b < a {
        b
    } else {
        a
    }
}

/// The larger of `a` and `b`, neither NaN (see [`lesser`]).
#[inline(always)]
fn greater(a: f32, b: f32) -> f32 {
    if b > a {
        b
    } else {
        a
    }
}

/// The smallest f32 above `x` (`x` itself for NaN and +∞).
fn next_up(x: f32) -> f32 {
    if x.is_nan() || x == f32::INFINITY {
        x
    } else if x == 0.0 {
        f32::from_bits(1)
    } else if x > 0.0 {
        f32::from_bits(x.to_bits() + 1)
    } else {
        f32::from_bits(x.to_bits() - 1)
    }
}

/// `d` times the power of two that brings its largest component `largest` (finite, not zero) into
/// `[1, 2)`: the same line, with a direction whose t keeps f32's precision. In two steps, so each
/// factor is a normal f32.
fn unit_scaled(d: Vec3, largest: f32) -> Vec3 {
    let bits = largest.to_bits() & 0x7fff_ffff;
    let e = (bits >> 23) as i32;
    // A subnormal largest component (biased exponent 0) is `bits·2^-149`, its leading bit at
    // `31 − leading_zeros`: the factor is counted from that bit, not from 2^-126 (a fixed 2^149
    // left it between 1 and 2^23, whose t then came out subnormal: a fuzzing helper's finding).
    let k = if e == 0 {
        149 - (31 - bits.leading_zeros() as i32)
    } else {
        127 - e
    };
    let (k1, k2) = (k / 2, k - k / 2);
    let pow2 = |k: i32| f32::from_bits(((k + 127) as u32) << 23);
    d * pow2(k1) * pow2(k2)
}

/// Where the line `o + t·d` enters the box `[lo, hi]`, computed in f64 and rounded to f32, or
/// `None` when the line misses the box. For origins at most 2^40 cells away the f64 error is below
/// 1/2048 of a cell, less than the box's padding, so a line that meets a triangle is never refused.
fn entry_point(o: Vec3, d: Vec3, lo: Vec3, hi: Vec3) -> Option<Vec3> {
    let (mut enter, mut leave) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        let (oa, da) = (f64::from(o[a]), f64::from(d[a]));
        if da == 0.0 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
            continue;
        }
        let ta = (f64::from(lo[a]) - oa) / da;
        let tb = (f64::from(hi[a]) - oa) / da;
        enter = enter.max(ta.min(tb));
        leave = leave.min(ta.max(tb));
    }
    if !(enter <= leave) {
        return None;
    }
    let p = |a: usize| (f64::from(o[a]) + enter * f64::from(d[a])) as f32;
    Some(Vec3::new(p(0), p(1), p(2)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;

    /// The scaled direction's largest component is in [1, 2) and the others are scaled by the
    /// same power of two, for largest components across f32's range, subnormal ones included.
    #[test]
    fn unit_scaled_brings_the_largest_component_into_one_to_two() {
        let mut cases = vec![f32::MAX, 3.0e38, 1.5, 1.0, 0.75, 1e-30, f32::MIN_POSITIVE];
        cases.extend((0..23).map(|b| f32::from_bits(1 << b)));
        cases.extend([f32::from_bits(0x007f_ffff), f32::from_bits(0x0000_0003)]);
        for largest in cases {
            let d = Vec3::new(-largest, largest * 0.5, 0.0);
            let s = unit_scaled(d, largest);
            let m = s.abs().max_element();
            assert!((1.0..2.0).contains(&m), "{largest:e}: {s:?}");
            // A power of two: exact for the largest component, and the ratio is kept.
            assert_eq!(s.x, -m, "{largest:e}: {s:?}");
        }
    }
}
