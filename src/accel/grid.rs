//! The uniform grid: a linear-time build (count, prefix sum, fill) into two flat arrays, and a 3D-DDA
//! traversal that visits cells front to back.

use alloc::vec::Vec;
use glam::Vec3;

use crate::accel::brute::test_all;
use crate::accel::{run_query, test_refs, Aabb, AcceptingQuery, Mailbox, RayQuery, Refs};
use crate::budget::{bytes_of, MemoryBudget};
use crate::error::BuildError;
use crate::math;
use crate::mesh::TriMesh;
use crate::ray::{Hit, Ray};
use crate::triangle::packs::{TriangleLayout, TrianglePacks};
use crate::triangle::Accept;
use crate::triangle::{TriangleLoop, TriangleTest};

/// Unit roundoff of f32 (2^-24), the unit of the walk's rounding errors.
const U32: f32 = f32::EPSILON / 2.0;

/// The grid's knobs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridParams {
    /// Cells per non-degenerate triangle (λ): the grid has about λ·N cells, split between the axes in
    /// proportion to the box's shape. Must be finite and positive.
    pub density: f32,
    /// Insert a triangle only into the cells it really overlaps (separating-axis test) when its bounds
    /// span more than one cell in two or more axes; otherwise every cell of its bounds.
    pub exact_overlap: bool,
    /// How the cells' triangles are stored for the test (packed copies or ids only).
    pub layout: TriangleLayout,
}

impl GridParams {
    /// The default: λ = 2 with exact overlap, a good all-round setting on the bundled scenes
    /// (docs/design.md records the measurement).
    pub const DEFAULT: GridParams = GridParams {
        density: 2.0,
        exact_overlap: true,
        layout: TriangleLayout::Packed,
    };
    /// Fewer cells (λ = 0.5): less memory and a faster build, slower rays.
    pub const COARSE: GridParams = GridParams {
        density: 0.5,
        exact_overlap: true,
        layout: TriangleLayout::Packed,
    };
    /// More cells (λ = 8): faster rays on clustered scenes, more memory.
    pub const FINE: GridParams = GridParams {
        density: 8.0,
        exact_overlap: true,
        layout: TriangleLayout::Packed,
    };
}

impl Default for GridParams {
    fn default() -> Self {
        GridParams::DEFAULT
    }
}

/// A uniform grid over a [`TriMesh`].
///
/// # Guarantees
/// - every non-degenerate triangle is listed in every cell it overlaps, where "overlaps" is tested
///   against the cell enlarged by a margin of 1/64 of a cell plus 16 f32 roundings of the grid's
///   coordinates and of its extent; that covers the walk's rounding for ray origins within
///   [`UniformGrid::near_reach`] of the grid, and farther rays are walked from a point at the
///   grid's entry (docs/design.md, "Uniform grid"), so the walk never skips a triangle the exact
///   test would hit;
/// - each cell's list is sorted by primitive id; with the packed layout it starts at a multiple of
///   4, and `refs` between two lists holds `Hit::INVALID_ID`;
/// - `offsets.len() == cells + 1`, `offsets` is non-decreasing and ends at `refs.len()`;
/// - `packs` holds the triangles of `refs` in its order (or nothing, for the indexed layout).
#[derive(Debug)]
pub struct UniformGrid {
    bounds: Aabb,
    res: [u32; 3],
    cell_size: Vec3,
    inv_cell_size: Vec3,
    margin: Vec3,
    /// The largest distance (per axis, from the ray origin to the farthest point of the box) at
    /// which the margin covers the walk's rounding (docs/design.md).
    near_reach: f32,
    /// The smallest cell side: with `near_reach`, what decides how a far ray is walked.
    min_cell: f32,
    offsets: Vec<u32>,
    refs: Vec<u32>,
    /// Triangle references over all cells (`refs` less its padding).
    references: usize,
    packs: TrianglePacks,
}

/// What one query did, for the selector's deterministic cost model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GridWork {
    /// Cells visited.
    pub cells: u32,
    /// Triangle tests run.
    pub tests: u32,
}

impl UniformGrid {
    /// Builds the grid over `mesh`, charging its arrays to `budget`. Time and memory are linear in
    /// the number of triangles plus cells plus references.
    pub fn build(
        mesh: &TriMesh,
        params: &GridParams,
        budget: &mut MemoryBudget,
    ) -> Result<UniformGrid, BuildError> {
        if !(params.density.is_finite() && params.density > 0.0) {
            return Err(BuildError::InvalidArgument {
                what: "grid density must be finite and positive",
            });
        }
        let live = mesh.len() - mesh.degenerate_count();
        let tight = mesh.bounds();
        if live == 0 || tight.is_empty() {
            return Ok(UniformGrid {
                bounds: Aabb::EMPTY,
                res: [0; 3],
                cell_size: Vec3::ZERO,
                inv_cell_size: Vec3::ZERO,
                margin: Vec3::ZERO,
                near_reach: 0.0,
                min_cell: 0.0,
                offsets: Vec::new(),
                refs: Vec::new(),
                references: 0,
                packs: TrianglePacks::default(),
            });
        }
        let (bounds, res) = layout(tight, live, params.density)?;
        let cells = res[0] as usize * res[1] as usize * res[2] as usize;
        let resf = Vec3::new(res[0] as f32, res[1] as f32, res[2] as f32);
        let cell_size = (bounds.max - bounds.min) / resf;
        let inv_cell_size = resf / (bounds.max - bounds.min);
        let abs_scale = bounds.min.abs().max(bounds.max.abs()).max_element();
        let extent = (bounds.max - bounds.min).max_element();
        // The walk's rounding moves a cell boundary by at most 4u·(D + 2A) (D the origin's distance,
        // A the coordinates' magnitude); a margin of twice that covers it. 16u·A covers the A part,
        // 16u·extent lets every origin within two extents of the grid qualify, and 1/64 of a cell
        // extends that to 32768 cells.
        let margin = cell_size * (1.0 / 64.0) + Vec3::splat(16.0 * U32 * (abs_scale + extent));
        let near_reach = margin.min_element() / (8.0 * U32) - 2.0 * abs_scale;
        let mut grid = UniformGrid {
            bounds,
            res,
            cell_size,
            inv_cell_size,
            margin,
            near_reach,
            min_cell: cell_size.min_element(),
            offsets: Vec::new(),
            refs: Vec::new(),
            references: 0,
            packs: TrianglePacks::default(),
        };

        let geometry = grid.geometry();
        let mut counts = budget.filled(cells + 1, 0u32, "grid cell offsets")?;
        // Per triangle, what the fill pass needs to repeat the count pass without recomputing it:
        // the first cell of its footprint and, for footprints of at most 3 cells per axis and 24
        // cells, which of them it overlaps plus the footprint's shape (see `pack`). 8 bytes per
        // triangle, given back before returning.
        let mut records = match budget.filled(mesh.len(), [0u32; 2], "grid build scratch") {
            Ok(m) => m,
            Err(e) => {
                budget.free(counts);
                return Err(e);
            }
        };
        let exact = params.exact_overlap;
        let tris = mesh.triangles();
        let degenerate = mesh.degenerate_bits();
        let live = |prim: usize| {
            degenerate
                .get(prim / 32)
                .is_some_and(|w| w & (1 << (prim % 32)) == 0)
        };
        let (rx, rxy) = (res[0] as usize, res[0] as usize * res[1] as usize);
        let mut overflow = false;
        let mut count = |cell: usize| {
            if let Some(n) = counts.get_mut(cell) {
                *n = n.wrapping_add(1);
                overflow |= *n == 0;
            }
        };
        for (prim, (tri, record)) in tris.iter().zip(records.iter_mut()).enumerate() {
            if !live(prim) {
                continue;
            }
            let fp = Footprint::of(&geometry, tri);
            let base = fp.lo[0] as usize + fp.lo[1] as usize * rx + fp.lo[2] as usize * rxy;
            if let Some(shape) = fp.shape() {
                let mask = footprint_mask(&geometry, tri, &fp, exact);
                for_cells(base, fp.n, rx, rxy, |bit, cell| {
                    if mask & (1 << bit) != 0 {
                        count(cell);
                    }
                });
                *record = [base as u32, mask | shape];
            } else {
                *record = [0, RECOMPUTE];
                let filter = Filter::new(&geometry, tri, &fp, exact);
                if walks(&geometry, tri, &fp, &filter) {
                    walk_overlapped(&geometry, tri, &fp, &filter, &mut count);
                } else {
                    fp.for_each(&geometry, |cell, x, y, z| {
                        if filter.overlaps(&geometry, x, y, z) {
                            count(cell);
                        }
                    });
                }
            }
        }
        // Prefix sums: counts[c] becomes the end of cell c's list. With packed triangles each list
        // starts on a block of four (the gap holds no triangle: id INVALID, NaN in the packs), so
        // a cell's triangles fill whole blocks and no block serves two cells.
        let align: u64 = if params.layout == TriangleLayout::Packed {
            4
        } else {
            1
        };
        let (mut total, mut references): (u64, u64) = (0, 0);
        for n in counts.iter_mut().take(cells) {
            // Aligned at every cell, so an empty cell's list is empty (not the gap before the next).
            total = total.div_ceil(align) * align;
            total += u64::from(*n);
            references += u64::from(*n);
            if overflow || total.div_ceil(align) * align > u64::from(u32::MAX) {
                budget.free(counts);
                budget.free(records);
                return Err(BuildError::CapacityExceeded {
                    what: "grid references",
                });
            }
            *n = total as u32;
        }
        let total = total.div_ceil(align) * align;
        if let Some(end) = counts.get_mut(cells) {
            *end = total as u32;
        }
        grid.references = references as usize;
        let mut refs = match budget.filled(total as usize, Hit::INVALID_ID, "grid references") {
            Ok(r) => r,
            Err(e) => {
                budget.free(counts);
                budget.free(records);
                return Err(e);
            }
        };
        // Filling backwards leaves each list sorted by primitive id and counts[c] at its start. The
        // fill visits exactly the cells the count did: from the record when it has the mask, by the
        // same overlap tests otherwise.
        let mut fill = |cell: usize, prim: usize| {
            if let Some(n) = counts.get_mut(cell) {
                *n = n.wrapping_sub(1);
                if let Some(r) = refs.get_mut(*n as usize) {
                    *r = prim as u32;
                }
            }
        };
        for (prim, (tri, &[base, packed])) in tris.iter().zip(records.iter()).enumerate().rev() {
            if !live(prim) {
                continue;
            }
            if packed & RECOMPUTE == 0 {
                for_cells(base as usize, unpack_shape(packed), rx, rxy, |bit, cell| {
                    if packed & (1 << bit) != 0 {
                        fill(cell, prim);
                    }
                });
            } else {
                let fp = Footprint::of(&geometry, tri);
                let filter = Filter::new(&geometry, tri, &fp, exact);
                if walks(&geometry, tri, &fp, &filter) {
                    walk_overlapped(&geometry, tri, &fp, &filter, &mut |cell| fill(cell, prim));
                } else {
                    fp.for_each(&geometry, |cell, x, y, z| {
                        if filter.overlaps(&geometry, x, y, z) {
                            fill(cell, prim);
                        }
                    });
                }
            }
        }
        budget.free(records);
        let packs = match TrianglePacks::build(mesh, &refs, params.layout, budget) {
            Ok(p) => p,
            Err(e) => {
                budget.free(counts);
                budget.free(refs);
                return Err(e);
            }
        };
        grid.refs = refs;
        grid.offsets = counts;
        grid.packs = packs;
        Ok(grid)
    }

    /// Cells per axis (zero for an empty scene).
    pub fn resolution(&self) -> [u32; 3] {
        self.res
    }

    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Number of triangle references over all cells.
    pub fn reference_count(&self) -> usize {
        self.references
    }

    /// Bytes the grid holds (offsets, references and their triangle packs).
    pub fn memory_bytes(&self) -> usize {
        bytes_of(&self.offsets) + bytes_of(&self.refs) + self.packs.memory_bytes()
    }

    /// Bytes of the triangle packs alone (zero for the indexed layout).
    pub fn pack_bytes(&self) -> usize {
        self.packs.memory_bytes()
    }

    /// The largest distance of a ray origin from the grid (per axis, to the box's far side) that
    /// the cells' margin covers; farther rays are walked from their entry point (docs/design.md).
    pub fn near_reach(&self) -> f32 {
        self.near_reach
    }

    /// Gives the grid's bytes back to the budget it was charged to and drops it.
    pub fn release(self, budget: &mut MemoryBudget) {
        budget.free(self.offsets);
        budget.free(self.refs);
        self.packs.release(budget);
    }

    /// The closest hit, also counting the work done.
    pub fn intersect_counted(&self, mesh: &TriMesh, ray: &Ray, work: &mut GridWork) -> Hit {
        run_query(
            mesh,
            ray,
            None,
            Walk::<true, false> {
                grid: self,
                mesh,
                work,
            },
        )
    }

    fn geometry(&self) -> Geometry {
        let min = self.bounds.min;
        let size = self.cell_size;
        // The enlarged cell's half extent as the overlap test has always taken it (rounded in f32).
        let half = 0.5 * size + self.margin;
        Geometry {
            min,
            res: self.res,
            inv: self.inv_cell_size,
            margin: self.margin,
            min64: [min.x, min.y, min.z].map(f64::from),
            size64: [size.x, size.y, size.z].map(f64::from),
            half64: [half.x, half.y, half.z].map(f64::from),
        }
    }

    /// The reference list with its packs, for the list test.
    #[inline(always)]
    fn refs(&self) -> Refs<'_> {
        Refs {
            ids: &self.refs,
            packs: &self.packs,
        }
    }

    /// The part of `refs` that lists cell `index`'s triangles (empty for an index outside the grid).
    #[inline(always)]
    fn cell_span(&self, index: i64) -> (usize, usize) {
        let Ok(cell) = usize::try_from(index) else {
            return (0, 0);
        };
        let lo = self.offsets.get(cell).copied().unwrap_or(0) as usize;
        let hi = self.offsets.get(cell + 1).copied().unwrap_or(0) as usize;
        (lo, hi.max(lo))
    }
}

impl RayQuery for UniformGrid {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn intersect(&self, mesh: &TriMesh, ray: &Ray) -> Hit {
        self.intersect_accepting(mesh, ray, None)
    }

    fn occluded(&self, mesh: &TriMesh, ray: &Ray) -> bool {
        self.occluded_accepting(mesh, ray, None)
    }
}

impl AcceptingQuery for UniformGrid {
    // Out of line, so plain queries share this one copy of the walks.
    #[inline(never)]
    fn intersect_accepting(&self, mesh: &TriMesh, ray: &Ray, accept: Option<&dyn Accept>) -> Hit {
        let work = &mut GridWork::default();
        let walk = Walk::<false, false> {
            grid: self,
            mesh,
            work,
        };
        run_query(mesh, ray, accept, walk)
    }

    #[inline(never)]
    fn occluded_accepting(&self, mesh: &TriMesh, ray: &Ray, accept: Option<&dyn Accept>) -> bool {
        let work = &mut GridWork::default();
        let walk = Walk::<false, true> {
            grid: self,
            mesh,
            work,
        };
        run_query(mesh, ray, accept, walk).is_hit()
    }
}

/// One query's walk through the grid: a 3D-DDA that visits the cells the ray passes through inside
/// `[tmin, tmax]`, front to back, and tests each cell's triangles with the test specialised for the
/// ray's axes. `COUNT` counts the work; `ANY` stops at the first hit (any-hit query).
struct Walk<'a, const COUNT: bool, const ANY: bool> {
    grid: &'a UniformGrid,
    mesh: &'a TriMesh,
    work: &'a mut GridWork,
}

/// Origins farther than this many of the smallest cells from the grid are walked by testing every
/// triangle: beyond it the f64 entry point of a far ray may be off its line by more than the margin.
const FAR_WALK_CELLS: f32 = 1.099_511_6e12;

/// 16·2^-149: sixteen times the largest error of a subnormal `t`, per unit of direction. Directions
/// longer than `margin / SUBNORMAL_T_ERROR` are walked scaled (see the walk).
const SUBNORMAL_T_ERROR: f64 = 2.242_077_542_919_707_3e-44;

/// `d` times the power of two that brings its largest component `largest` (finite, not zero) into
/// `[1, 2)`: the same line, with a direction whose t keeps f32's precision. In two steps, so each
/// factor is a normal f32.
fn unit_scaled(d: Vec3, largest: f32) -> Vec3 {
    let e = ((largest.to_bits() >> 23) & 0xff) as i32;
    // A subnormal largest component (biased exponent 0) needs the factor for 2^-126 and more.
    let k = 127 - e.max(1) + if e == 0 { 23 } else { 0 };
    let (k1, k2) = (k / 2, k - k / 2);
    let pow2 = |k: i32| f32::from_bits(((k + 127) as u32) << 23);
    d * pow2(k1) * pow2(k2)
}

impl<const COUNT: bool, const ANY: bool> TriangleLoop for Walk<'_, COUNT, ANY> {
    type Output = Hit;

    #[inline(always)]
    fn run<T: TriangleTest>(self, test: T) -> Hit {
        let Walk { grid, mesh, work } = self;
        let r = test.ray();
        let mut best = Hit::MISS;
        let mut mailbox = Mailbox::new();
        if grid.offsets.is_empty() {
            return best;
        }
        let (mut o, mut d) = (r.org, r.dir);
        let (mut t0, mut t1) = (r.tmin, r.tmax);
        let (lo, hi) = (grid.bounds.min, grid.bounds.max);
        let mut early_exit = true;
        // An origin farther than the margin covers: walk the same line from where it enters the
        // box (found in f64, rounded to f32: off the line by far less than the margin), over the
        // whole box and without the early exit, whose t would be in the wrong frame. Beyond 2^40
        // cells even the f64 entry point may be off by more than the margin: test every triangle.
        let reach = (lo - o).abs().max((hi - o).abs()).max_element();
        if !(reach <= grid.near_reach) {
            if !(reach <= FAR_WALK_CELLS * grid.min_cell) {
                return test_all::<T, ANY>(&test, mesh);
            }
            match entry_point(o, d, lo, hi) {
                Some(p) => o = p,
                None => return best,
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
        let largest = d.abs().max_element();
        let magnitude = lo.abs().max(hi.abs()).max_element() + o.abs().max_element();
        let uninvertible = (0..3).any(|a| d[a] != 0.0 && !(1.0 / d[a]).is_finite());
        let may_overflow = largest * (f32::MAX / 1024.0) < magnitude;
        let subnormal_t =
            f64::from(largest) * SUBNORMAL_T_ERROR > f64::from(grid.margin.min_element());
        if uninvertible || may_overflow || subnormal_t {
            early_exit = false;
            d = unit_scaled(d, largest);
            t0 = -f32::INFINITY;
            t1 = f32::INFINITY;
        }
        let mut inv = [0.0f32; 3];
        let mut moving = [false; 3];
        for a in 0..3 {
            let ia = 1.0 / d[a];
            if ia.is_finite() {
                inv[a] = ia;
                moving[a] = true;
                let ta = (lo[a] - o[a]) * ia;
                let tb = (hi[a] - o[a]) * ia;
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            } else if o[a] < lo[a] || o[a] > hi[a] {
                return best;
            }
        }
        if !(t0 <= t1) {
            return best;
        }
        // The cell of the entry point, and per axis: the step, the cell index where the walk leaves
        // the grid, the change of the flat index, and the t of the next cell boundary. Non-moving
        // axes have `t_next = ∞` and are never stepped. Arrays have a fourth, unused slot so that
        // an index `& 3` needs no bounds check.
        let t_start = t0.clamp(-f32::MAX, f32::MAX);
        let res = grid.res;
        let strides = [
            1i64,
            i64::from(res[0]),
            i64::from(res[0]) * i64::from(res[1]),
            0,
        ];
        let mut cell = [0i64; 4];
        let mut step = [0i64; 4];
        let mut up = [0i64; 4];
        let mut end = [0i64; 4];
        let mut t_next = [f32::INFINITY; 4];
        let mut plane_min = [0.0f32; 4];
        let mut plane_size = [0.0f32; 4];
        let mut org = [0.0f32; 4];
        let mut inv4 = [0.0f32; 4];
        let mut first_moving = 0;
        let mut moving_mask = 0u32;
        for a in (0..3).rev() {
            let p = o[a] + t_start * d[a];
            let c = math::floor((p - lo[a]) * grid.inv_cell_size[a]);
            let last = i64::from(res[a]) - 1;
            cell[a] = if c.is_nan() {
                0
            } else {
                (c.clamp(-1.0, last as f32 + 1.0) as i64).clamp(0, last)
            };
            plane_min[a] = lo[a];
            plane_size[a] = grid.cell_size[a];
            org[a] = o[a];
            inv4[a] = inv[a];
            if moving[a] {
                first_moving = a;
                moving_mask |= 1 << a;
                let is_up = d[a] > 0.0;
                step[a] = if is_up { 1 } else { -1 };
                up[a] = i64::from(is_up);
                end[a] = if is_up { last + 1 } else { -1 };
                t_next[a] = grid.boundary_t(a, cell[a] + up[a], o[a], inv[a]);
            }
        }
        let delta = [
            step[0] * strides[0],
            step[1] * strides[1],
            step[2] * strides[2],
            0,
        ];
        let mut index = cell[0] + cell[1] * strides[1] + cell[2] * strides[2];
        loop {
            // The axis whose boundary comes first (ties to the lower axis), without branches. A
            // non-moving axis has t = ∞ and is chosen only when every moving axis is at ∞ too (t
            // overflowed); step the first moving axis then, as the walk must still advance.
            let (tx, ty, tz) = (t_next[0], t_next[1], t_next[2]);
            let not_x = !(tx <= ty && tx <= tz);
            let mut axis = usize::from(not_x) * (1 + usize::from(!(ty <= tz)));
            if moving_mask & (1 << axis) == 0 {
                axis = first_moving;
            }
            let axis = axis & 3;
            let t_axis = t_next[axis];
            let t_exit = t_axis.min(t1);
            let (first, last) = grid.cell_span(index);
            if COUNT {
                work.cells += 1;
                // Real triangles only, not the padding of the last block.
                let listed = grid.refs.get(first..last).unwrap_or(&[]);
                work.tests += listed.iter().filter(|&&p| p != Hit::INVALID_ID).count() as u32;
            }
            let refs = grid.refs();
            if let Some(h) =
                test_refs::<T, ANY>(&test, mesh, refs, (first, last), &mut best, &mut mailbox)
            {
                return h;
            }
            // Any triangle not yet tested lies beyond this cell (by the insertion margin), so a hit
            // inside the cell cannot be beaten.
            if early_exit && best.t <= t_exit {
                return best;
            }
            if t_axis > t1 {
                return best;
            }
            // Step to the neighbour across the boundary; its far boundary is computed from the
            // plane's position (no accumulated error), as `boundary_t` does.
            cell[axis] += step[axis];
            if cell[axis] == end[axis] {
                return best;
            }
            index += delta[axis];
            let x = plane_min[axis] + (cell[axis] + up[axis]) as f32 * plane_size[axis];
            t_next[axis] = (x - org[axis]) * inv4[axis];
        }
    }
}

impl UniformGrid {
    /// Ray parameter at the plane between cells `k - 1` and `k` on `axis`, computed from the plane's
    /// position each time (no accumulated error).
    #[inline(always)]
    fn boundary_t(&self, axis: usize, k: i64, o: f32, inv: f32) -> f32 {
        let x = self.bounds.min[axis] + k as f32 * self.cell_size[axis];
        (x - o) * inv
    }
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

/// What the build needs of the grid's shape, copied out so the fill pass can borrow `refs` mutably.
struct Geometry {
    min: Vec3,
    res: [u32; 3],
    inv: Vec3,
    margin: Vec3,
    /// `min` in f64.
    min64: [f64; 3],
    /// The cell size in f64.
    size64: [f64; 3],
    /// Half a cell plus the margin (the enlarged cell's half extent), in f64.
    half64: [f64; 3],
}

/// The padded box and cells per axis for `live` triangles in `tight` at density `lambda`.
fn layout(tight: Aabb, live: usize, lambda: f32) -> Result<(Aabb, [u32; 3]), BuildError> {
    let ext = tight.extent();
    let max_ext = ext.max_element();
    let abs_scale = tight.min.abs().max(tight.max.abs()).max_element();
    // Pad so that triangles on the box faces lie strictly inside, by more than the walk's rounding
    // at the box's faces (16 roundings of the coordinates) and the far walk's entry point (1/2048
    // of a cell), and flat scenes get a thin slab.
    let pad = max_ext * (1.0 / 1024.0) + abs_scale * (16.0 * U32) + f32::MIN_POSITIVE;
    let bounds = Aabb {
        min: tight.min - Vec3::splat(pad),
        max: tight.max + Vec3::splat(pad),
    };
    let target = (f64::from(lambda) * live as f64).max(1.0);
    // Axes too thin to split get one cell; the others share the target in proportion to their extent.
    let e = [f64::from(ext.x), f64::from(ext.y), f64::from(ext.z)];
    let mut split = [true; 3];
    for (a, s) in split.iter_mut().enumerate() {
        *s = e[a] > f64::from(max_ext) * 1e-6;
    }
    let mut res = [1u32; 3];
    for _ in 0..3 {
        let dims = split.iter().filter(|&&s| s).count();
        if dims == 0 {
            break;
        }
        let volume: f64 = (0..3).filter(|&a| split[a]).map(|a| e[a]).product();
        let k = match dims {
            1 => target / volume,
            2 => math::sqrt64(target / volume),
            _ => math::cbrt(target / volume),
        };
        let mut changed = false;
        for a in 0..3 {
            if split[a] {
                let r = e[a] * k;
                if r < 1.0 {
                    split[a] = false;
                    changed = true;
                }
                res[a] = math::floor64(r + 0.5).clamp(1.0, target.min(f64::from(u32::MAX))) as u32;
            } else {
                res[a] = 1;
            }
        }
        if !changed {
            break;
        }
    }
    let cells = u64::from(res[0]) * u64::from(res[1]) * u64::from(res[2]);
    if cells >= u64::from(u32::MAX) || cells as u128 + 1 > usize::MAX as u128 {
        return Err(BuildError::CapacityExceeded { what: "grid cells" });
    }
    Ok((bounds, res))
}

/// The cells a triangle's bounds, enlarged by the margin, cover: `n[a]` cells from `lo[a]` on each
/// axis.
struct Footprint {
    lo: [u32; 3],
    n: [u32; 3],
}

/// In a build record: the footprint is too large for a mask, recompute it.
const RECOMPUTE: u32 = 1 << 31;

/// Cells `n` (at most 3 per axis, at most 24 in all) starting at flat index `base`, x fastest:
/// calls `visit(bit, cell)` with the cell's position in that order (its bit in a footprint mask).
#[inline(always)]
fn for_cells(base: usize, n: [u32; 3], rx: usize, rxy: usize, mut visit: impl FnMut(u32, usize)) {
    let mut bit = 0;
    let mut plane = base;
    for _ in 0..n[2] {
        let mut row = plane;
        for _ in 0..n[1] {
            for x in 0..n[0] as usize {
                visit(bit, row + x);
                bit += 1;
            }
            row += rx;
        }
        plane += rxy;
    }
}

/// The footprint shape stored in bits 24..30 of a build record.
#[inline(always)]
fn unpack_shape(packed: u32) -> [u32; 3] {
    [
        ((packed >> 24) & 3) + 1,
        ((packed >> 26) & 3) + 1,
        ((packed >> 28) & 3) + 1,
    ]
}

impl Footprint {
    #[inline(always)]
    fn of(g: &Geometry, tri: &[Vec3; 3]) -> Footprint {
        // The triangle's bounds (coordinates are finite: plain comparisons give `min`/`max`).
        let lt = |a: f32, b: f32| if a < b { a } else { b };
        let gt = |a: f32, b: f32| if a > b { a } else { b };
        let [p, q, r] = tri;
        let lo = Vec3::new(
            lt(lt(p.x, q.x), r.x),
            lt(lt(p.y, q.y), r.y),
            lt(lt(p.z, q.z), r.z),
        );
        let hi = Vec3::new(
            gt(gt(p.x, q.x), r.x),
            gt(gt(p.y, q.y), r.y),
            gt(gt(p.z, q.z), r.z),
        );
        let lo = cell_range(g, lo - g.margin);
        let hi = cell_range(g, hi + g.margin);
        Footprint {
            lo,
            n: [
                hi[0].saturating_sub(lo[0]) + 1,
                hi[1].saturating_sub(lo[1]) + 1,
                hi[2].saturating_sub(lo[2]) + 1,
            ],
        }
    }

    /// Bits 24..30 of a build record for this footprint, or `None` when it has more than 3 cells
    /// on an axis or more than 24 in all (then its mask would not fit).
    #[inline(always)]
    fn shape(&self) -> Option<u32> {
        let [x, y, z] = self.n;
        (x <= 3 && y <= 3 && z <= 3 && x * y * z <= 24)
            .then(|| ((x - 1) | ((y - 1) << 2) | ((z - 1) << 4)) << 24)
    }

    /// Calls `visit(cell, x, y, z)` for every cell of the footprint, x fastest.
    #[inline(always)]
    fn for_each(&self, g: &Geometry, mut visit: impl FnMut(usize, u32, u32, u32)) {
        let (rx, rxy) = (g.res[0] as usize, g.res[0] as usize * g.res[1] as usize);
        for z in self.lo[2]..self.lo[2] + self.n[2] {
            for y in self.lo[1]..self.lo[1] + self.n[1] {
                let row = y as usize * rx + z as usize * rxy;
                for x in self.lo[0]..self.lo[0] + self.n[0] {
                    visit(row + x as usize, x, y, z);
                }
            }
        }
    }
}

/// Which cells of its footprint a triangle overlaps (cells enlarged by the margin), by the
/// separating-axis theorem in f64, so that the only tolerance that matters is the margin:
/// - a footprint one cell thick in at most one axis needs no test (every cell of a one-cell-wide
///   row or a single cell overlaps);
/// - one cell thick in exactly one axis, the enlarged cells of the footprint contain the triangle's
///   whole extent along that axis, so the triangle meets a cell exactly when its projection onto the
///   other two axes meets the cell's rectangle: three edge normals suffice (the rectangle's own axes
///   are settled by the footprint);
/// - otherwise the nine edge × box-axis directions and the triangle's normal (the box axes are
///   settled by the footprint).
///
/// Each axis `n` is tested as "the triangle's projection `[lo, hi]` and the cell's projection
/// `n·c ± r` are disjoint", with `lo`, `hi`, `r` computed once per triangle and only `n·c` per
/// cell. Rounding in f64 is some 1e-16 of the coordinates, far below the margin (at least 1/64 of
/// a cell plus 128 f32 ulps of the coordinates), so no cell that the triangle overlaps is dropped.
// A short-lived value on the stack, one per triangle: the size difference does not matter.
#[allow(clippy::large_enum_variant)]
enum Filter {
    All,
    Flat(Axes<2, 3>),
    Solid(Axes<3, 10>),
}

/// `N` separating axes in `D` dimensions (the footprint axes `dims`): a cell with center `c`
/// overlaps on axis `n[i]` when `lo[i] ≤ n[i]·c ≤ hi[i]`, where `[lo, hi]` is the triangle's
/// projection widened by the enlarged cell's projected half extent.
struct Axes<const D: usize, const N: usize> {
    dims: [usize; D],
    n: [[f64; D]; N],
    lo: [f64; N],
    hi: [f64; N],
}

impl<const D: usize, const N: usize> Axes<D, N> {
    fn new(g: &Geometry, dims: [usize; D], tri: &[Vec3; 3], n: [[f64; D]; N]) -> Self {
        let v = tri.map(|p| dims.map(|a| f64::from(p[a])));
        let dot = |n: &[f64; D], p: &[f64; D]| (0..D).fold(0.0, |s, k| s + n[k] * p[k]);
        let mut axes = Axes {
            dims,
            n,
            lo: [0.0; N],
            hi: [0.0; N],
        };
        for (i, n) in n.iter().enumerate() {
            let p = [dot(n, &v[0]), dot(n, &v[1]), dot(n, &v[2])];
            let r = (0..D).fold(0.0, |s, k| s + n[k].abs() * g.half64[dims[k]]);
            axes.lo[i] = p[0].min(p[1]).min(p[2]) - r;
            axes.hi[i] = p[0].max(p[1]).max(p[2]) + r;
        }
        axes
    }

    /// True when the enlarged cell centered at `c` (in the axes' dimensions) overlaps.
    #[inline(always)]
    fn contains(&self, c: [f64; D]) -> bool {
        let mut inside = true;
        for i in 0..N {
            let nc = (0..D).fold(0.0, |s, k| s + self.n[i][k] * c[k]);
            inside &= (nc >= self.lo[i]) & (nc <= self.hi[i]);
        }
        inside
    }

    #[inline(always)]
    fn overlaps(&self, g: &Geometry, cell: [u32; 3]) -> bool {
        self.contains(
            self.dims
                .map(|a| g.min64[a] + (f64::from(cell[a]) + 0.5) * g.size64[a]),
        )
    }
}

impl Filter {
    #[inline(always)]
    fn new(g: &Geometry, tri: &[Vec3; 3], fp: &Footprint, exact: bool) -> Filter {
        let thick = fp.n.map(|n| n > 1);
        let spans = thick.iter().filter(|&&t| t).count();
        if !exact || spans < 2 {
            return Filter::All;
        }
        Filter::tests(g, tri, thick, spans)
    }

    #[inline(never)]
    fn tests(g: &Geometry, tri: &[Vec3; 3], thick: [bool; 3], spans: usize) -> Filter {
        let v = tri.map(|p| [f64::from(p.x), f64::from(p.y), f64::from(p.z)]);
        let edge = |i: usize| {
            let (p, q) = (v[i], v[(i + 1) % 3]);
            [q[0] - p[0], q[1] - p[1], q[2] - p[2]]
        };
        let e = [edge(0), edge(1), edge(2)];
        if spans == 2 {
            let (a, b) = match thick {
                [false, _, _] => (1, 2),
                [_, false, _] => (0, 2),
                _ => (0, 1),
            };
            let normal = |e: [f64; 3]| [-e[b], e[a]];
            return Filter::Flat(Axes::new(
                g,
                [a, b],
                tri,
                [normal(e[0]), normal(e[1]), normal(e[2])],
            ));
        }
        let cross = |u: [f64; 3], w: [f64; 3]| {
            [
                u[1] * w[2] - u[2] * w[1],
                u[2] * w[0] - u[0] * w[2],
                u[0] * w[1] - u[1] * w[0],
            ]
        };
        let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        Filter::Solid(Axes::new(
            g,
            [0, 1, 2],
            tri,
            [
                // The plane first: it separates the most cells of large triangles.
                cross(e[0], e[1]),
                cross(x, e[0]),
                cross(x, e[1]),
                cross(x, e[2]),
                cross(y, e[0]),
                cross(y, e[1]),
                cross(y, e[2]),
                cross(z, e[0]),
                cross(z, e[1]),
                cross(z, e[2]),
            ],
        ))
    }

    #[inline(always)]
    fn overlaps(&self, g: &Geometry, x: u32, y: u32, z: u32) -> bool {
        match self {
            Filter::All => true,
            Filter::Flat(axes) => axes.overlaps(g, [x, y, z]),
            Filter::Solid(axes) => axes.overlaps(g, [x, y, z]),
        }
    }
}

/// Footprints of more cells than this may be walked slab by slab ([`walk_footprint`]) instead of
/// cell by cell. Below it, testing every cell costs about as much as clipping and is simpler.
const WALK_MIN_CELLS: u32 = 64;

/// Whether walking the footprint slab by slab tests clearly fewer cells than enumerating it: the
/// footprint has more than [`WALK_MIN_CELLS`] cells and more than twice the cells the triangle is
/// expected to overlap. That estimate, in cell units, is the sum of the triangle's areas projected
/// onto the three axis planes (a plane crosses about that many cells) plus the footprint's side
/// lengths (cells cut by the edges). A sliver across the box overlaps a thin line of cells out of
/// nearly all of them and is walked; a big triangle of a flat floor fills half its footprint, and
/// testing each cell (three dot products) costs less than clipping per row. The factor 2 was the
/// best of 1, 2, 4, 8 in build instructions on stadium_teapot and slivers (docs/robustness.md).
fn worth_walking(g: &Geometry, tri: &[Vec3; 3], fp: &Footprint) -> bool {
    let cells = fp.n[0].saturating_mul(fp.n[1]).saturating_mul(fp.n[2]);
    if cells <= WALK_MIN_CELLS {
        return false;
    }
    let [p, q, r] = tri.map(|v| (v * g.inv).to_array().map(f64::from));
    let (e, f) = (
        [0, 1, 2].map(|k| q[k] - p[k]),
        [0, 1, 2].map(|k| r[k] - p[k]),
    );
    let cross = [
        e[1] * f[2] - e[2] * f[1],
        e[2] * f[0] - e[0] * f[2],
        e[0] * f[1] - e[1] * f[0],
    ];
    let area = 0.5 * (cross[0].abs() + cross[1].abs() + cross[2].abs());
    let sides = f64::from(fp.n[0]) + f64::from(fp.n[1]) + f64::from(fp.n[2]);
    // Non-finite (cell units overflow) compares false: enumerate, which is always correct.
    f64::from(cells) > 2.0 * (area + sides)
}

/// Whether the build finds the cells of a footprint that does not fit a mask by
/// [`walk_overlapped`] rather than by testing each of its cells: only when the filter tests cells
/// (an accepted-whole footprint, a column or `exact == false`, is all overlap) and the triangle
/// overlaps the footprint sparsely ([`worth_walking`]). Either way the cells found are the same.
#[inline(always)]
fn walks(g: &Geometry, tri: &[Vec3; 3], fp: &Footprint, filter: &Filter) -> bool {
    !matches!(filter, Filter::All) && worth_walking(g, tri, fp)
}

/// Calls `visit(cell)` for exactly the cells of footprint `fp` that `filter` accepts for the
/// triangle, testing only the cells [`walk_footprint`] finds near it, so the work is
/// proportional to the cells it overlaps, not to its bounds. Out of line and through `dyn`: the
/// triangles it serves are few and each costs clipping, while the plain enumeration stays inlined
/// in the build's loops (called through a function boundary, the count closure's state
/// round-trips through memory on every cell, which cost 15 % of the stadium's build time at equal
/// instruction counts).
#[inline(never)]
fn walk_overlapped(
    g: &Geometry,
    tri: &[Vec3; 3],
    fp: &Footprint,
    filter: &Filter,
    visit: &mut dyn FnMut(usize),
) {
    walk_footprint(g, tri, fp, &mut |cell, x, y, z| {
        if overlaps_out_of_line(filter, g, x, y, z) {
            visit(cell);
        }
    });
}

/// [`Filter::overlaps`] as one shared copy, for the walk: the enumeration inlines the test into its
/// loop, the walk (a few triangles, clipping per row) does not need to, and a second inlined copy
/// costs ~3 KB of code, which small embedded programs pay for (tests/c_api.rs keeps a size budget).
#[inline(never)]
fn overlaps_out_of_line(filter: &Filter, g: &Geometry, x: u32, y: u32, z: u32) -> bool {
    filter.overlaps(g, x, y, z)
}

/// A convex polygon in f64 with room for a triangle clipped by four planes (at most 7 vertices).
#[derive(Clone, Copy)]
struct Polygon {
    len: usize,
    v: [[f64; 3]; 8],
}

impl Polygon {
    fn triangle(tri: &[Vec3; 3]) -> Polygon {
        let mut v = [[0.0; 3]; 8];
        for (slot, p) in v.iter_mut().zip(tri) {
            *slot = [p.x, p.y, p.z].map(f64::from);
        }
        Polygon { len: 3, v }
    }

    fn vertices(&self) -> &[[f64; 3]] {
        self.v.get(..self.len).unwrap_or(&[])
    }

    /// The part of the polygon with `lo <= p[axis] <= hi` (Sutherland–Hodgman against both planes).
    /// Crossing points get `p[axis]` set to the plane exactly; their other coordinates are off by
    /// f64 rounding only (~1e-16 of the coordinates), far below the slack the caller adds.
    // One out-of-line copy: called from two places in the walk, never from a hot loop.
    #[inline(never)]
    fn clip(&self, axis: usize, lo: f64, hi: f64) -> Polygon {
        self.clip_side(axis, lo, false).clip_side(axis, hi, true)
    }

    /// Keeps `p[axis] >= plane` (or `<=` when `below`).
    fn clip_side(&self, axis: usize, plane: f64, below: bool) -> Polygon {
        let inside = |p: &[f64; 3]| {
            if below {
                p[axis] <= plane
            } else {
                p[axis] >= plane
            }
        };
        let mut out = Polygon {
            len: 0,
            v: [[0.0; 3]; 8],
        };
        let mut push = |p: [f64; 3]| {
            // A convex polygon gains at most one vertex per plane, so 8 slots hold a triangle
            // clipped by four planes; a full polygon would only lose vertices here, never panic.
            if let Some(slot) = out.v.get_mut(out.len) {
                *slot = p;
                out.len += 1;
            }
        };
        let vs = self.vertices();
        for (i, p) in vs.iter().enumerate() {
            let q = vs.get(i + 1).or(vs.first()).unwrap_or(p);
            if inside(p) {
                push(*p);
            }
            if inside(p) != inside(q) {
                let t = (plane - p[axis]) / (q[axis] - p[axis]);
                let mut x = [0.0; 3];
                for (k, x) in x.iter_mut().enumerate() {
                    *x = p[k] + t * (q[k] - p[k]);
                }
                x[axis] = plane;
                push(x);
            }
        }
        out
    }

    /// The polygon's extent along `axis` (`None` when it is empty).
    fn range(&self, axis: usize) -> Option<(f64, f64)> {
        let vs = self.vertices();
        let first = vs.first()?[axis];
        Some(vs.iter().fold((first, first), |(lo, hi), p| {
            (lo.min(p[axis]), hi.max(p[axis]))
        }))
    }
}

/// Calls `test(cell, x, y, z)` for every cell of footprint `fp` whose cell, enlarged by twice the
/// margin, the triangle meets: per slab along the footprint's thinnest axis the triangle clipped to
/// the slab, per row of that slab (along the middle axis) the piece clipped to the row, and the
/// cells along the thickest axis that the piece's extent there covers. The thickest axis is the one
/// left to a range, so it needs no clipping; an axis one cell thick in the footprint is never
/// clipped (the footprint already settles it).
///
/// Guarantee: a superset of the cells [`Filter`] accepts. The filter accepts a cell only when the
/// triangle meets it enlarged by the margin (up to f64 rounding); the walk keeps every cell the
/// triangle meets enlarged by twice the margin, and rounding in the clipping and in the cell
/// indices (~1e-16 of the coordinates) is far below the extra margin (≥ 1/64 of a cell plus 128 f32
/// ulps of the coordinates). Every cell it keeps is within twice the margin of the triangle, so the
/// cells tested stay proportional to the cells overlapped.
fn walk_footprint(
    g: &Geometry,
    tri: &[Vec3; 3],
    fp: &Footprint,
    test: &mut impl FnMut(usize, u32, u32, u32),
) {
    let stride = [1, g.res[0] as usize, g.res[0] as usize * g.res[1] as usize];
    let slack = [0, 1, 2].map(|a| 2.0 * f64::from(g.margin[a]));
    // Axes from the thinnest footprint side to the thickest (ties keep x, y, z order).
    let mut order = [0usize, 1, 2];
    order.sort_by_key(|&a| fp.n[a]);
    let [outer, middle, inner] = order;
    // Clips `poly` to cell `i`'s extent on `axis` enlarged by the slack, unless the footprint is one
    // cell thick there.
    let clip = |poly: &Polygon, axis: usize, i: u32| {
        if fp.n[axis] > 1 {
            let lo = g.min64[axis] + f64::from(i) * g.size64[axis];
            poly.clip(axis, lo - slack[axis], lo + g.size64[axis] + slack[axis])
        } else {
            *poly
        }
    };
    let whole = Polygon::triangle(tri);
    let mut at = [0u32; 3];
    for i in fp.lo[outer]..fp.lo[outer] + fp.n[outer] {
        at[outer] = i;
        let slab = clip(&whole, outer, i);
        let Some((j0, j1)) = cells_covering(g, fp, middle, slab.range(middle), slack[middle])
        else {
            continue;
        };
        for j in j0..=j1 {
            at[middle] = j;
            let row = clip(&slab, middle, j);
            let Some((k0, k1)) = cells_covering(g, fp, inner, row.range(inner), slack[inner])
            else {
                continue;
            };
            for k in k0..=k1 {
                at[inner] = k;
                let cell = (0..3).fold(0, |c, a| c + at[a] as usize * stride[a]);
                test(cell, at[0], at[1], at[2]);
            }
        }
    }
}

/// The footprint's cells on `axis` whose extent, enlarged by `slack`, meets `range`, rounded
/// outward; `None` when there are none or `range` is `None` (an empty polygon).
fn cells_covering(
    g: &Geometry,
    fp: &Footprint,
    axis: usize,
    range: Option<(f64, f64)>,
    slack: f64,
) -> Option<(u32, u32)> {
    let (lo, hi) = range?;
    let (first, last) = (fp.lo[axis], fp.lo[axis] + fp.n[axis] - 1);
    if fp.n[axis] <= 1 {
        return Some((first, last));
    }
    // The cell index of `v`: truncation equals `floor` for non-negative values, and a negative
    // one (or NaN) is below the footprint either way, where the clamp puts it. Multiplying by the
    // inverse instead of dividing, and truncating instead of calling `floor` (a libm call on
    // targets without a rounding instruction), keeps the walk as fast as the enumeration it
    // replaces; their rounding is far below the slack.
    let inv = 1.0 / g.size64[axis];
    let index = |v: f64| {
        let f = (v - g.min64[axis]) * inv;
        if f >= 0.0 {
            f as i64
        } else {
            0
        }
    };
    let a = index(lo - slack).max(i64::from(first));
    let b = index(hi + slack).min(i64::from(last));
    (a <= b).then_some((a as u32, b as u32))
}

/// Which cells of footprint `fp` (at most 3 per axis) the triangle overlaps, as a mask in the order
/// of [`for_cells`]: the tests of [`Filter`], written out for the small footprints almost every
/// triangle has.
#[inline(always)]
fn footprint_mask(g: &Geometry, tri: &[Vec3; 3], fp: &Footprint, exact: bool) -> u32 {
    let [nx, ny, nz] = fp.n;
    let spans = u32::from(nx > 1) + u32::from(ny > 1) + u32::from(nz > 1);
    if !exact || spans < 2 {
        return 1u32
            .checked_shl(nx * ny * nz)
            .map_or(u32::MAX, |b| b.wrapping_sub(1));
    }
    if spans == 2 {
        let (a, b) = if nx == 1 {
            (1, 2)
        } else if ny == 1 {
            (0, 2)
        } else {
            (0, 1)
        };
        flat_mask(g, tri, fp, a, b)
    } else {
        solid_mask(g, tri, fp)
    }
}

/// Centers of the footprint's first three cells along `axis`, in f64.
#[inline(always)]
fn centers(g: &Geometry, fp: &Footprint, axis: usize) -> [f64; 3] {
    let c = |i: u32| g.min64[axis] + (f64::from(fp.lo[axis] + i) + 0.5) * g.size64[axis];
    [c(0), c(1), c(2)]
}

/// [`footprint_mask`] for a footprint one cell thick along the axis other than `a` and `b`: the
/// triangle's projection onto the (a, b) plane against each cell's enlarged rectangle, separated
/// only along the three edge normals.
#[inline(never)]
fn flat_mask(g: &Geometry, tri: &[Vec3; 3], fp: &Footprint, a: usize, b: usize) -> u32 {
    let p = tri.map(|v| {
        let v = v.to_array();
        [f64::from(v[a]), f64::from(v[b])]
    });
    let (ha, hb) = (g.half64[a], g.half64[b]);
    // Per edge: normal (na, nb) and the projection interval widened by the rectangle's half extent.
    let mut axes = [[0.0f64; 4]; 3];
    for (i, axis) in axes.iter_mut().enumerate() {
        let (s, e) = (p[i], p[(i + 1) % 3]);
        let (na, nb) = (s[1] - e[1], e[0] - s[0]);
        let d = p.map(|q| na * q[0] + nb * q[1]);
        let r = na.abs() * ha + nb.abs() * hb;
        *axis = [
            na,
            nb,
            d[0].min(d[1]).min(d[2]) - r,
            d[0].max(d[1]).max(d[2]) + r,
        ];
    }
    let (ca, cb) = (centers(g, fp, a), centers(g, fp, b));
    let (na, nb) = (fp.n[a].min(3) as usize, fp.n[b].min(3) as usize);
    let mut mask = 0;
    let mut bit = 0;
    for &y in &cb[..nb] {
        for &x in &ca[..na] {
            let mut inside = true;
            for [n0, n1, lo, hi] in axes {
                let d = n0 * x + n1 * y;
                inside &= (d >= lo) & (d <= hi);
            }
            mask |= u32::from(inside) << bit;
            bit += 1;
        }
    }
    mask
}

/// [`footprint_mask`] for a footprint more than one cell thick on every axis: the triangle's plane
/// and the nine edge × box-axis directions.
#[inline(never)]
fn solid_mask(g: &Geometry, tri: &[Vec3; 3], fp: &Footprint) -> u32 {
    let Filter::Solid(axes) = Filter::new(g, tri, fp, true) else {
        return u32::MAX;
    };
    let (cx, cy, cz) = (centers(g, fp, 0), centers(g, fp, 1), centers(g, fp, 2));
    let [nx, ny, nz] = fp.n.map(|n| n.min(3) as usize);
    let mut mask = 0;
    let mut bit = 0;
    for &z in &cz[..nz] {
        for &y in &cy[..ny] {
            for &x in &cx[..nx] {
                mask |= u32::from(axes.contains([x, y, z])) << bit;
                bit += 1;
            }
        }
    }
    mask
}

/// The cell of `p` on each axis, clamped to the grid. `floor` then clamp to `[0, res − 1]`, written
/// as a truncation for non-negative values (equal to `floor` there; negative values and NaN clamp
/// to 0 either way), which avoids a libm call on targets without a rounding instruction.
#[inline(always)]
fn cell_range(g: &Geometry, p: Vec3) -> [u32; 3] {
    let mut c = [0u32; 3];
    for a in 0..3 {
        let f = (p[a] - g.min[a]) * g.inv[a];
        c[a] = if f >= 0.0 {
            (f as u32).min(g.res[a].saturating_sub(1))
        } else {
            0
        };
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::brute::BruteForce;
    use crate::mesh::MeshData;
    use crate::procedural;

    fn agree(mesh: &TriMesh, grid: &UniformGrid, ray: &Ray) {
        let want = BruteForce::new(mesh).intersect(mesh, ray);
        let got = grid.intersect(mesh, ray);
        assert!(
            got.same_bits(&want),
            "{ray:?}: grid {got:?}, brute force {want:?}"
        );
        assert_eq!(grid.occluded(mesh, ray), want.is_hit(), "{ray:?}");
    }

    /// The cells of each triangle's footprint that the overlap filter accepts, found by testing
    /// every cell (the reference) and by [`walk_footprint`]: the walk must find exactly the same
    /// cells (it may test a few more, which the filter rejects), and must test few cells beyond
    /// those it keeps. Slivers across the box, big triangles, sheets on cell planes, triangles far
    /// from the origin and tiny ones.
    #[test]
    fn slab_walk_finds_exactly_the_cells_the_exact_test_accepts() {
        let mut sheets = MeshData::default();
        for k in 0..=8 {
            let x = k as f32 / 8.0;
            sheets.push_quad([[x, 0.0, 0.0], [x, 1.0, 0.3], [0.2, x, 1.0], [1.0, 1.0, x]]);
        }
        let scenes = [
            procedural::random_slivers(3000, 5),
            procedural::random_slivers(500, 6).transformed(1e-6, [0.0; 3]),
            procedural::random_slivers(500, 7).transformed(1.0, [1e7, -1e7, 3e6]),
            procedural::random_soup(400, 8, 0.7),
            procedural::teapot_in_stadium(200, 400),
            sheets,
        ];
        for (s, data) in scenes.iter().enumerate() {
            let mut budget = MemoryBudget::new(0);
            let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
            let grid = UniformGrid::build(&mesh, &GridParams::FINE, &mut budget).unwrap();
            let g = grid.geometry();
            let (mut walked, mut kept, mut large) = (0usize, 0usize, 0usize);
            for tri in mesh.triangles() {
                let fp = Footprint::of(&g, tri);
                let filter = Filter::new(&g, tri, &fp, true);
                let mut want = Vec::new();
                fp.for_each(&g, |cell, x, y, z| {
                    if filter.overlaps(&g, x, y, z) {
                        want.push(cell);
                    }
                });
                let mut got = Vec::new();
                walk_footprint(&g, tri, &fp, &mut |cell, x, y, z| {
                    walked += 1;
                    if filter.overlaps(&g, x, y, z) {
                        got.push(cell);
                    }
                });
                got.sort_unstable();
                want.sort_unstable();
                assert_eq!(got, want, "scene {s}: {tri:?}");
                kept += want.len();
                large += usize::from(worth_walking(&g, tri, &fp));
            }
            // The walk tests cells near the triangle only: a few more than it keeps.
            assert!(
                walked <= 3 * kept + 8 * mesh.len(),
                "scene {s}: {walked} tested for {kept}"
            );
            if s < 3 {
                assert!(
                    large > 100,
                    "scene {s}: the slivers should have large footprints"
                );
            }
        }
    }

    /// Directions too small to invert in f32 (on every axis, or on the only moving axis of a scene far
    /// from the origin, where t overflows) used to spin forever; they must end and agree.
    #[test]
    fn tiny_directions_end_and_agree_with_brute_force() {
        for (scale, offset) in [(1.0, [0.0; 3]), (1e-30, [0.0; 3])] {
            let data = procedural::closed_sphere(6).transformed(scale, offset);
            let mut budget = MemoryBudget::new(0);
            let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
            let grid = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut budget).unwrap();
            let b = mesh.bounds();
            let center = 0.5 * (b.min + b.max);
            for d in [
                Vec3::new(1e-45, 0.0, 0.0),
                Vec3::new(-1e-45, 1e-45, 0.0),
                Vec3::new(0.0, 1e-30, 0.0),
                Vec3::new(0.0, -1e-30, 3e-39),
                Vec3::new(2e-39, 2e-39, 2e-39),
            ] {
                for org in [center, b.min, center + 0.4 * (b.max - b.min)] {
                    agree(&mesh, &grid, &Ray::new(org, d));
                    agree(&mesh, &grid, &Ray::segment(org, d, 0.0, f32::MAX));
                }
            }
        }
    }
}
