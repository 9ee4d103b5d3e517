//! Nested grids: a cell whose list is long (a teapot in a stadium: a detailed object inside one
//! cell of a grid sized for the whole scene) gets a grid of its own over the part of its enlarged
//! box its triangles occupy, and the walk walks that grid instead of testing the whole list
//! (Ize, Shirley and Parker's recursive grids, at most [`MAX_DEPTH`] deep; docs/design.md,
//! "Nested grids").

use glam::Vec3;

use super::build::{gather_blocks, Members};
use super::layout::Shape;
use super::{GridParams, Lists, UniformGrid};
use crate::bigvec::BigVec;
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::{Aabb, Hit};
use crate::select::calibration::Calibration;
use crate::triangle::Block4;

/// Grids nest at most this deep (the outer grid is depth 0). The code takes any depth; with two
/// levels (before the cells' large triangles were kept out of the nested grids' boxes) stadium-1M's
/// build took 1.2× as long as with one, for rays 10 % slower (docs/performance.md, "Stop 23").
pub(super) const MAX_DEPTH: usize = 1;

/// Lists shorter than this are tested whole. A nested grid costs a build over its triangles (about
/// as much per triangle as the outer grid's): at 256 (two levels) munich's and stadium-10k's builds
/// took 1.7× and 4.8× as long for rays at most 6 % faster (docs/performance.md, "Stop 23").
pub(super) const NESTED_MIN: usize = 1024;

/// A nested grid keeps its place when a ray crossing it is expected to cost at most this share of
/// testing the whole list.
const NESTED_GAIN: f64 = 0.5;

/// One cell's nested grid.
#[derive(Debug)]
pub(super) struct Nested {
    /// The cell's flat index in the outer grid.
    pub cell: usize,
    /// A grid over the cell's triangles that are not large (with nested grids of its own
    /// below [`MAX_DEPTH`]), in the box where their bounds meet the cell's box enlarged by two
    /// margins (and `Shape::new`'s padding around that).
    pub grid: UniformGrid,
    /// The cell's large triangles, wider on some axis than the cell or eight cells of a grid over
    /// it (`LARGE_CELLS`; a stadium's field around its teapot), tested whole on entering it, four
    /// to a block (ids, gap lanes `Hit::INVALID_ID`)...
    pub large_ids: BigVec<[u32; 4]>,
    /// ...and their triangles (gap lanes NaN).
    pub large: BigVec<Block4>,
    /// How many large triangles there are (padding excluded).
    pub large_count: u32,
}

impl Nested {
    /// Gives the nested grid's and the large triangles' bytes back to `budget` and drops them.
    pub fn release(self, budget: &mut MemoryBudget) {
        self.grid.release(budget);
        budget.free_big(self.large_ids);
        budget.free_big(self.large);
    }
}

/// A heavy cell's triangle wider than this many cells of a grid over the whole cell (on some axis)
/// is tested whole on entering the cell, not listed in its nested grid.
const LARGE_CELLS: f32 = 8.0;

/// Triangles sampled to find a dense object before a grid is sized: enough that a dense quarter
/// shows as a hundred or more of them (three quarters on stadium-1M), few enough to cost ~0.5 % of an
/// ordinary build's instructions (bunny: 4 096 cost 3.8 %, 1 024 0.9 %, mostly the sort).
const DENSE_SAMPLES: usize = 512;

/// How many of the `live` triangles of `mesh` (bounds `tight`) the outer grid, whose dense cells
/// get nested grids, is sized for: all of them, unless a sample says that at least a quarter
/// lie in cells that will get nested grids — a detailed object in a big sparse scene (a teapot in
/// a stadium). Such triangles are walked in their own grids, so counting them in the outer one only
/// made its cells finer around the rest: stadium-1M's field was listed in 6.6 cells a triangle,
/// in 350 000 cells for the 250 000 triangles outside the sphere (docs/performance.md, "Stop 45").
///
/// The sample is every `k`-th triangle's centroid in the cells of the grid sized for all of them
/// (`k` making at most [`DENSE_SAMPLES`]); a cell holding `c ≥ 2` of them stands for `c·k`
/// triangles and counts as dense from [`NESTED_MIN`]. One sample alone is not a cluster (from
/// about half a million triangles `k` alone reaches it), and an ordinary scene's samples seldom
/// share a cell: about `S²/(2·occupied cells)` pairs, far from a quarter of them. Below a quarter
/// each axis's resolution would move by less than a tenth (an eighth on a flat scene's two), so
/// ordinary scenes keep their grid exactly. Deterministic; when the sample's memory is refused,
/// every triangle counts. The caller sizes for every triangle after all when a dense cell gets no
/// nested grid ([`left_heavy`]).
pub(super) fn sized_for(
    mesh: &TriMesh,
    tight: Aabb,
    live: usize,
    params: &GridParams,
    budget: &mut MemoryBudget,
) -> usize {
    // Below this a dense quarter is one nested grid's worth, which a sample would cost a larger
    // share of a small build to find.
    if live < 4 * NESTED_MIN {
        return live;
    }
    let Ok(shape) = Shape::new(tight, live, params.density) else {
        return live;
    };
    let stride = mesh.len().div_ceil(DENSE_SAMPLES).max(1);
    let Ok(mut cells) = budget.vec::<u32>(mesh.len().div_ceil(stride), "grid density sample")
    else {
        return live;
    };
    let res = shape.res.map(|r| r as usize);
    let inv = Vec3::ONE / shape.cell_size;
    for (i, tri) in mesh.triangles().iter().enumerate().step_by(stride) {
        if mesh.is_degenerate(i as u32) {
            continue;
        }
        let centroid = (tri[0] + tri[1] + tri[2]) * (1.0 / 3.0);
        let k = ((centroid - shape.bounds.min) * inv).to_array();
        // `as` saturates (NaN to 0); the clamp keeps a centroid rounded onto a far face inside.
        let at = |a: usize| (k[a] as usize).min(res[a] - 1);
        cells.push((at(0) + res[0] * (at(1) + res[1] * at(2))) as u32);
    }
    cells.sort_unstable();
    let dense: usize = cells
        .chunk_by(|a, b| a == b)
        .filter(|run| run.len() >= 2)
        .map(|run| run.len() * stride)
        .filter(|&n| n >= NESTED_MIN)
        .sum();
    budget.free(cells);
    if dense * 4 >= live {
        live.saturating_sub(dense).max(1)
    } else {
        live
    }
}

/// Gives each cell of `grid` listing at least [`NESTED_MIN`] triangles a nested grid over them,
/// where one is expected to pay (see [`pays`]). Nested grids are optional: a cell whose nested grid
/// cannot be built (the memory budget, or a grid whose margin would swamp its cells) keeps its
/// list, so the outer grid never fails for them. Every allocation is charged to `budget`.
pub(super) fn nest(
    grid: &mut UniformGrid,
    mesh: &TriMesh,
    params: &GridParams,
    budget: &mut MemoryBudget,
    depth: usize,
) {
    if depth >= MAX_DEPTH || grid.largest_cell < NESTED_MIN {
        return;
    }
    let unit = match grid.lists {
        Lists::Packed { .. } => 4,
        Lists::Indexed { .. } => 1,
    };
    // A list of at least NESTED_MIN ids spans at least this many units; a shorter span cannot be one.
    let min_span = NESTED_MIN.div_ceil(unit);
    let cells = grid.cell_count();
    let heavy = (0..cells).filter(|&c| {
        let (first, end) = grid.span(c);
        end - first >= min_span
    });
    let Ok(mut nested) = budget.vec::<Nested>(heavy.clone().count(), "nested grids") else {
        return;
    };
    for cell in heavy {
        // A cell whose nested grid fails keeps its list (nest_cell gave back what it took).
        if let Ok(Some(n)) = nest_cell(grid, cell, mesh, params, budget, depth + 1) {
            nested.push(n);
        }
    }
    // The shortest nested cell's list: shorter lists (and long ones not worth a nested grid,
    // which are rare) are tested in the outer walk's loop without a look-up.
    grid.nested_span = nested
        .iter()
        .map(|n| {
            let (first, end) = grid.span(n.cell);
            end - first
        })
        .min()
        .unwrap_or(usize::MAX);
    grid.nested = nested;
    grid.largest_cell = largest_tested(grid);
}

/// Whether a cell of `grid` lists at least [`NESTED_MIN`] triangles without a nested grid.
pub(super) fn left_heavy(grid: &UniformGrid) -> bool {
    longest_unnested(grid) >= NESTED_MIN
}

/// The longest list a walk of `grid` tests whole: of a cell without a nested grid, of a nested
/// cell's large triangles, or of a cell of a nested grid.
fn largest_tested(grid: &UniformGrid) -> usize {
    grid.nested
        .iter()
        .map(|n| n.grid.largest_cell.max(n.large_count as usize))
        .fold(longest_unnested(grid), usize::max)
}

/// The longest list of a cell of `grid` without a nested grid.
fn longest_unnested(grid: &UniformGrid) -> usize {
    let unit = match grid.lists {
        Lists::Packed { .. } => 4,
        Lists::Indexed { .. } => 1,
    };
    // A list holds at most `unit` ids per unit of its span, so only a list whose span could beat
    // the longest so far has its ids counted (a pass over every id was ~10 % of sibenik's build).
    let mut longest = 0;
    for c in 0..grid.cell_count() {
        let (first, end) = grid.span(c);
        if (end - first) * unit > longest && grid.nested_at(c).is_none() {
            longest = longest.max(grid.listed(c) as usize);
        }
    }
    longest
}

/// The nested grid (at `depth`, with its own nested grids) of `cell` when its list holds at least
/// [`NESTED_MIN`] triangles, at most half of them large (`LARGE_CELLS`), and the grid pays, else
/// `None`.
fn nest_cell(
    grid: &UniformGrid,
    cell: usize,
    mesh: &TriMesh,
    params: &GridParams,
    budget: &mut MemoryBudget,
    depth: usize,
) -> Result<Option<Nested>, BuildError> {
    let (first, end) = grid.span(cell);
    // The list's real ids (gap lanes skipped), at most `room` of them.
    let (list, room): (&[u32], usize) = match &grid.lists {
        Lists::Packed { ids, .. } => {
            let blocks = ids.get(first..end).unwrap_or(&[]);
            (blocks.as_flattened(), blocks.len() * 4)
        }
        Lists::Indexed { ids, .. } => (ids.get(first..end).unwrap_or(&[]), end - first),
    };
    // One pass: triangles wider than the cell on some axis would stretch the nested grid over the
    // whole cell (the field around a teapot), so they are tested whole; the rest gets the grid,
    // in the box of their bounds.
    let mut small = budget.vec::<u32>(room, "nested grid ids")?;
    let mut large = match budget.vec::<u32>(room, "nested grid ids") {
        Ok(v) => v,
        Err(e) => {
            budget.free(small);
            return Err(e);
        }
    };
    let tris = mesh.triangles();
    // A triangle wider than eight cells of a grid over the whole cell would be listed in dozens of
    // them: it too is tested whole. (Where the outer grid was sized without a dense object,
    // `sized_for`, its cell around the object holds parts of the sparse rest: a teapot's cell of a
    // stadium's field, whose triangles are smaller than the cell but far larger than the teapot's.)
    let whole = grid.shape.cell_size;
    let size = Shape::new(enlarged_cell(grid, cell), room.max(1), params.density)
        .map_or(whole, |sub| whole.min(sub.cell_size * LARGE_CELLS));
    let mut small_bounds = Aabb::EMPTY;
    for &p in list.iter().filter(|&&p| p != Hit::INVALID_ID) {
        let Some(tri) = tris.get(p as usize) else {
            continue;
        };
        // A triangle's box is never empty: its extent needs no emptiness test.
        let bounds = Aabb::of_triangle(tri);
        if (bounds.max - bounds.min).cmpgt(size).any() {
            large.push(p);
        } else {
            small.push(p);
            small_bounds = small_bounds.union(bounds);
        }
    }
    let n = small.len() + large.len();
    let result = if n < NESTED_MIN || 2 * large.len() > n {
        Ok(None)
    } else {
        let split = Split {
            small: &small,
            small_bounds,
            large: &large,
        };
        nest_small(grid, cell, split, mesh, params, budget, depth)
    };
    budget.free(small);
    budget.free(large);
    result
}

/// A heavy cell's triangles: those that are not large, their bounds, and the large ones.
struct Split<'a> {
    small: &'a [u32],
    small_bounds: Aabb,
    large: &'a [u32],
}

/// [`nest_cell`] once the cell's triangles are split.
fn nest_small(
    grid: &UniformGrid,
    cell: usize,
    split: Split<'_>,
    mesh: &TriMesh,
    params: &GridParams,
    budget: &mut MemoryBudget,
    depth: usize,
) -> Result<Option<Nested>, BuildError> {
    let Split {
        small,
        small_bounds,
        large: large_list,
    } = split;
    let cell_box = enlarged_cell(grid, cell);
    let tight = Aabb {
        min: small_bounds.min.max(cell_box.min),
        max: small_bounds.max.min(cell_box.max),
    };
    // The nested grid's margin covers rounding on the scene's coordinates (16u·A): for an object
    // far from the origin against its size it would swamp small cells, and every triangle would be
    // listed in most of them (λ·n² references). Such a cell keeps its list.
    let swamped = Shape::new(tight, small.len().max(1), params.density).map_or(true, |shape| {
        shape.margin.cmpgt(shape.cell_size * 0.25).any()
    });
    if small.is_empty() || tight.is_empty() || swamped {
        return Ok(None);
    }
    let sub = UniformGrid::build_over(
        mesh,
        Members::Listed(small),
        tight,
        small.len(),
        params,
        budget,
    )?;
    if !pays(&sub, large_list.len(), small.len() + large_list.len()) {
        sub.release(budget);
        return Ok(None);
    }
    let blocks = large_list.len().div_ceil(4);
    let mut large_ids = match budget.big_filled(blocks, [Hit::INVALID_ID; 4], "nested grid ids") {
        Ok(v) => v,
        Err(e) => {
            sub.release(budget);
            return Err(e);
        }
    };
    for (lane, &p) in large_ids.as_flattened_mut().iter_mut().zip(large_list) {
        *lane = p;
    }
    let large = match gather_blocks(mesh, &large_ids, budget) {
        Ok(v) => v,
        Err(e) => {
            sub.release(budget);
            budget.free_big(large_ids);
            return Err(e);
        }
    };
    let mut nested = Nested {
        cell,
        grid: sub,
        large_ids,
        large,
        large_count: large_list.len() as u32,
    };
    nest(&mut nested.grid, mesh, params, budget, depth);
    Ok(Some(nested))
}

/// The box of `cell` enlarged by twice the insertion margin: it holds every point at which a
/// triangle of the cell's list meets the cell's box enlarged by the margin, whatever the rounding
/// of the cell's planes (a few `u·(A + E)`, against the margin's `16u·(A + E)`).
pub(super) fn enlarged_cell(grid: &UniformGrid, cell: usize) -> Aabb {
    let shape = &grid.shape;
    let [rx, ry, _] = shape.res.map(|r| r as usize);
    let k = [cell % rx, cell / rx % ry, cell / (rx * ry)].map(|k| k as f32);
    let lo = Vec3::from(k);
    let pad = shape.margin * 2.0;
    Aabb {
        min: shape.bounds.min + lo * shape.cell_size - pad,
        max: shape.bounds.min + (lo + Vec3::ONE) * shape.cell_size + pad,
    }
}

/// Whether a ray crossing `sub`'s box is expected to cost at most [`NESTED_GAIN`] of testing all
/// `n` triangles when `large` of them are tested whole besides: a line crossing a convex box
/// crosses a convex part of it with probability area over area (isotropic lines), so it lists
/// `references · a/A` triangles and steps through `cells · a/A` cells on average (`a` a cell's
/// area, `A` the box's), a cell step priced as the selector's cost model prices it.
fn pays(sub: &UniformGrid, large: usize, n: usize) -> bool {
    let area = |e: Vec3| e.x * e.y + e.y * e.z + e.z * e.x;
    let shape = &sub.shape;
    let (a, whole) = (area(shape.cell_size), area(shape.bounds.extent()));
    if !(whole > 0.0) {
        return false;
    }
    let share = f64::from(a / whole);
    // A cell step's price in listed triangles, from the built-in calibration's grid prices (the
    // selector's cost model; 14.0 at stop 23, 14.6 since stop 24's refit, which changed no nesting
    // decision on the bundled and procedural scenes). A build decides this before any calibration
    // is known.
    let calibration = Calibration::builtin();
    let cell_in_tests = calibration.value(2) / calibration.value(3);
    let crossing = (sub.references as f64 + cell_in_tests * sub.cell_count() as f64) * share;
    large as f64 + crossing <= NESTED_GAIN * n as f64
}

impl UniformGrid {
    /// The nested grid of cell `index`, if it has one.
    #[inline]
    pub(super) fn nested_at(&self, index: usize) -> Option<&Nested> {
        self.nested
            .binary_search_by_key(&index, |n| n.cell)
            .ok()
            .and_then(|i| self.nested.get(i))
    }
}

#[cfg(test)]
impl UniformGrid {
    /// Drops the nested grids, so that every cell's whole list is tested (the reference the tests
    /// compare nesting with).
    pub(super) fn drop_nested(&mut self, budget: &mut MemoryBudget) {
        for n in self.nested.drain(..) {
            n.release(budget);
        }
        self.nested_span = usize::MAX;
    }

    /// How deep the grids nest (0 without nested grids).
    pub(super) fn nesting_depth(&self) -> usize {
        self.nested
            .iter()
            .map(|n| 1 + n.grid.nesting_depth())
            .max()
            .unwrap_or(0)
    }

    /// The cells with a nested grid.
    pub(super) fn nested_cells(&self) -> alloc::vec::Vec<usize> {
        self.nested.iter().map(|n| n.cell).collect()
    }
}
