//! Nested grids: a cell whose list is long (a teapot in a stadium: a detailed object inside one
//! cell of a grid sized for the whole scene) gets a grid of its own over the part of its enlarged
//! box its triangles occupy, and the walk walks that grid instead of testing the whole list
//! (Ize, Shirley and Parker's recursive grids, at most [`MAX_DEPTH`] deep; docs/design.md,
//! "Nested grids").

use glam::Vec3;

#[cfg(test)]
use alloc::vec::Vec;

use super::build::Members;
use super::{GridParams, Lists, UniformGrid};
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::{Aabb, Hit};

/// Grids nest at most this deep (the outer grid is depth 0): a teapot in a stadium whose cell
/// also holds the field's large triangles gets a nested grid shaped by the field, and the sphere
/// gets its own grid one level further down.
pub(super) const MAX_DEPTH: usize = 2;

/// Lists shorter than this are tested whole: a nested walk's setup and cell steps cost about as
/// much as testing a few hundred triangles four at a time (docs/performance.md).
pub(super) const NESTED_MIN: usize = 256;

/// A cell step's price in triangle tests, for the check that a nested grid pays (the built-in
/// calibration's grid prices: 14.5 ns a cell, 1.04 ns a listed triangle).
const CELL_IN_TESTS: f64 = 14.0;

/// A nested grid keeps its place when a ray crossing it is expected to cost at most this share of
/// testing the whole list.
const NESTED_GAIN: f64 = 0.5;

/// One cell's nested grid.
#[derive(Debug)]
pub(super) struct Nested {
    /// The cell's flat index in the outer grid.
    pub cell: usize,
    /// A grid over the cell's list (nested grids of its own up to [`MAX_DEPTH`]).
    pub grid: UniformGrid,
}

/// Gives each cell of `grid` listing at least [`NESTED_MIN`] triangles a nested grid over them,
/// where one is expected to pay (see [`pays`]). Every allocation is charged to `budget`; on failure
/// the caller releases the grid (and what was nested so far with it).
pub(super) fn nest(
    grid: &mut UniformGrid,
    mesh: &TriMesh,
    params: &GridParams,
    budget: &mut MemoryBudget,
    depth: usize,
) -> Result<(), BuildError> {
    if depth >= MAX_DEPTH || grid.largest_cell < NESTED_MIN {
        return Ok(());
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
    let mut nested = budget.vec::<Nested>(heavy.clone().count(), "nested grids")?;
    let mut result = Ok(());
    for cell in heavy {
        match nest_cell(grid, cell, mesh, params, budget, depth + 1) {
            Ok(Some(sub)) => nested.push(Nested { cell, grid: sub }),
            Ok(None) => {}
            Err(e) => {
                result = Err(e);
                break;
            }
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
    // Kept on failure too, so that releasing the grid gives their bytes back.
    grid.nested = nested;
    if result.is_ok() {
        grid.largest_cell = largest_tested(grid);
    }
    result
}

/// The longest list a walk of `grid` tests whole: of a cell without a nested grid, or of a cell of
/// a nested grid.
fn largest_tested(grid: &UniformGrid) -> usize {
    let outer = (0..grid.cell_count())
        .filter(|&c| grid.nested_at(c).is_none())
        .map(|c| grid.listed(c) as usize)
        .max()
        .unwrap_or(0);
    grid.nested
        .iter()
        .map(|n| n.grid.largest_cell)
        .fold(outer, usize::max)
}

/// The nested grid (at `depth`, with its own nested grids) of `cell` when its list holds at least
/// [`NESTED_MIN`] triangles and the grid pays, else `None`.
fn nest_cell(
    grid: &UniformGrid,
    cell: usize,
    mesh: &TriMesh,
    params: &GridParams,
    budget: &mut MemoryBudget,
    depth: usize,
) -> Result<Option<UniformGrid>, BuildError> {
    let (first, end) = grid.span(cell);
    let mut ids = budget.vec::<u32>((end - first) * 4, "nested grid ids")?;
    match &grid.lists {
        Lists::Packed { ids: blocks, .. } => ids.extend(
            blocks
                .get(first..end)
                .unwrap_or(&[])
                .iter()
                .flatten()
                .filter(|&&p| p != Hit::INVALID_ID),
        ),
        Lists::Indexed { ids: listed, .. } => {
            ids.extend(listed.get(first..end).unwrap_or(&[]).iter());
        }
    }
    let tris = mesh.triangles();
    let listed_bounds = ids
        .iter()
        .filter_map(|&p| tris.get(p as usize))
        .fold(Aabb::EMPTY, |b, t| b.union(Aabb::of_triangle(t)));
    let cell_box = enlarged_cell(grid, cell);
    let tight = Aabb {
        min: listed_bounds.min.max(cell_box.min),
        max: listed_bounds.max.min(cell_box.max),
    };
    if ids.len() < NESTED_MIN || tight.is_empty() {
        budget.free(ids);
        return Ok(None);
    }
    let n = ids.len();
    let sub = UniformGrid::build_over(mesh, Members::Listed(&ids), tight, n, params, budget);
    budget.free(ids);
    let mut sub = sub?;
    if !pays(&sub, n) {
        sub.release(budget);
        return Ok(None);
    }
    if let Err(e) = nest(&mut sub, mesh, params, budget, depth) {
        sub.release(budget);
        return Err(e);
    }
    Ok(Some(sub))
}

/// The box of `cell` enlarged by twice the insertion margin: it holds every point at which a
/// triangle of the cell's list meets the cell's box enlarged by the margin, whatever the rounding
/// of the cell's planes (below `u·(A + E)`, against the margin's `16u·(A + E)`).
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
/// `n` triangles: a line crossing a convex box crosses a convex part of it with probability area
/// over area (isotropic lines), so it lists `references · a/A` triangles and steps through
/// `cells · a/A` cells on average (`a` a cell's area, `A` the box's).
fn pays(sub: &UniformGrid, n: usize) -> bool {
    let area = |e: Vec3| e.x * e.y + e.y * e.z + e.z * e.x;
    let shape = &sub.shape;
    let (a, whole) = (area(shape.cell_size), area(shape.bounds.extent()));
    if !(whole > 0.0) {
        return false;
    }
    let share = f64::from(a / whole);
    let expected = (sub.references as f64 + CELL_IN_TESTS * sub.cell_count() as f64) * share;
    expected <= NESTED_GAIN * n as f64
}

impl UniformGrid {
    /// The nested grid of cell `index`, if it has one.
    #[inline]
    pub(super) fn nested_at(&self, index: usize) -> Option<&UniformGrid> {
        self.nested
            .binary_search_by_key(&index, |n| n.cell)
            .ok()
            .and_then(|i| self.nested.get(i))
            .map(|n| &n.grid)
    }
}

#[cfg(test)]
impl UniformGrid {
    /// Drops the nested grids, so that every cell's whole list is tested (the reference the tests
    /// compare nesting with).
    pub(super) fn drop_nested(&mut self, budget: &mut MemoryBudget) {
        for n in self.nested.drain(..) {
            n.grid.release(budget);
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
    pub(super) fn nested_cells(&self) -> Vec<usize> {
        self.nested.iter().map(|n| n.cell).collect()
    }
}
