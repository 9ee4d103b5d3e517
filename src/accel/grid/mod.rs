//! The uniform grid: a linear-time build (each triangle's cells found once by ranges, counted,
//! prefix-summed, filled) into flat arrays (build.rs, voxel.rs), and a 3D-DDA walk that visits
//! cells front to back (walk.rs); layout.rs chooses the box, the cells and the margin.

use alloc::vec::Vec;

use crate::accel::{
    run_clipped_query, test_blocks, test_refs, Aabb, AcceptingQuery, Mailbox, RayQuery, Refs,
};
use crate::bigvec::BigVec;
use crate::budget::{bytes_of, MemoryBudget};
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::{Hit, Ray};
use crate::triangle::packs::{TriangleLayout, TrianglePacks};
use crate::triangle::{Accept, Block4, TriangleTest};

mod blocks;
mod build;
mod content;
mod layout;
mod nested;
#[cfg(test)]
mod tests;
mod voxel;
mod walk;

use blocks::Blocks;
use build::Members;
use layout::Shape;
use nested::Nested;
use walk::{Plan, Walk};

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
    /// The default: λ = 0.35 with exact overlap. With the list test a cell's triangles cost less
    /// than the cells a ray steps through, so fewer, fuller cells win: over the 32 scenes of the
    /// evaluation and the failure-mode set, λ = 1/2 traced 12 % faster than λ = 2 (geometric mean;
    /// 1/4: 9 %, 1: 9 %) and built 1.7× faster (stop 19); once the AVX filter tested two blocks at
    /// a time (stop 33), λ = 0.35 built in 0.93× the time of 1/2 (mesh copy included) with the same
    /// time per ray within ±1 % (29 scenes, five alternated runs; docs/performance.md, "Stop 34").
    pub const DEFAULT: GridParams = GridParams {
        density: 0.35,
        exact_overlap: true,
        layout: TriangleLayout::Packed,
    };
    /// Fewer cells (λ = 1/8): less memory and a faster build, slower rays.
    pub const COARSE: GridParams = GridParams {
        density: 0.125,
        exact_overlap: true,
        layout: TriangleLayout::Packed,
    };
    /// More cells (λ = 2): faster rays through long slivers across the scene (docs/performance.md),
    /// more memory and a slower build.
    pub const FINE: GridParams = GridParams {
        density: 2.0,
        exact_overlap: true,
        layout: TriangleLayout::Packed,
    };
}

impl Default for GridParams {
    fn default() -> Self {
        GridParams::DEFAULT
    }
}

/// The cells' triangle lists.
#[derive(Debug)]
enum Lists {
    /// Block-aligned lists: block `b` holds the triangles `ids[b]` (gap lanes `Hit::INVALID_ID`
    /// and NaN); offsets count blocks.
    Packed {
        ids: BigVec<[u32; 4]>,
        tris: BigVec<Block4>,
    },
    /// Ids only, unaligned; offsets count ids; the test gathers from the mesh (`packs` is empty).
    Indexed { ids: Vec<u32>, packs: TrianglePacks },
}

/// A uniform grid over a [`TriMesh`].
///
/// # Guarantees
/// - every non-degenerate triangle is listed in every cell whose box, enlarged on every side by a
///   margin of 1/64 of a cell plus 16 f32 roundings of the grid's coordinates and of its extent,
///   it meets; that covers the walk's rounding for ray origins within
///   [`UniformGrid::near_reach`] of the grid, and farther rays are walked from a point at the
///   grid's entry (docs/design.md, "Uniform grid"), so the walk never skips a triangle the exact
///   test would hit;
/// - each cell's list is sorted by primitive id; with the packed layout it fills whole blocks of
///   four (gap lanes hold `Hit::INVALID_ID` and NaN);
/// - `offsets.len() == cells + 1`; without their top bit (`content::SLAB_FLAG`, set on a cell's
///   first offset when its content slab is worth a test) `offsets` is non-decreasing and ends at
///   the number of blocks (packed: at most 2^30, as the references are at most `u32::MAX`) or ids
///   (indexed: below 2^31, build.rs), below the flag either way.
#[derive(Debug)]
pub struct UniformGrid {
    shape: Shape,
    /// 1 / cell size in f64, for the walk's start cell.
    inv_cell64: [f64; 3],
    offsets: Vec<u32>,
    lists: Lists,
    /// Triangle references over all cells (padding excluded).
    references: usize,
    /// The most triangles a walk tests in one cell (see [`UniformGrid::largest_cell`]).
    largest_cell: usize,
    /// Which blocks of cells hold a triangle (empty-space skipping).
    blocks: Blocks,
    /// Grids over the heaviest cells' lists, sorted by cell (nested.rs).
    nested: Vec<Nested>,
    /// Lists at least this long (in the lists' units) may have a nested grid; `usize::MAX` when
    /// none has.
    nested_span: usize,
    /// Each cell's content slab (content.rs), for the plain walk; none for the indexed layout and
    /// for nested grids.
    content: content::Content,
}

/// What one query did, for the selector's deterministic cost model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GridWork {
    /// Cells visited.
    pub cells: u32,
    /// Triangles listed in the cells visited (padding excluded): the tests the walk runs before
    /// the filter and the mailbox.
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
            let lists = match params.layout {
                TriangleLayout::Packed => Lists::Packed {
                    ids: BigVec::new(),
                    tris: BigVec::new(),
                },
                TriangleLayout::Indexed => Lists::Indexed {
                    ids: Vec::new(),
                    packs: TrianglePacks::default(),
                },
            };
            return Ok(UniformGrid {
                shape: Shape::EMPTY,
                inv_cell64: [0.0; 3],
                offsets: Vec::new(),
                lists,
                references: 0,
                largest_cell: 0,
                blocks: Blocks::default(),
                nested: Vec::new(),
                nested_span: usize::MAX,
                content: content::Content::default(),
            });
        }
        let outer = nested::sized_for(mesh, tight, live, params, budget);
        let mut grid = UniformGrid::build_over(mesh, Members::Mesh, tight, outer, params, budget)?;
        nested::nest(&mut grid, mesh, params, budget, 0);
        if outer < live && nested::left_heavy(&grid) {
            // Sized for nested grids that did not all come (the memory limit, a margin that swamps
            // their cells, a grid that would not pay): the coarser cells' lists, tested whole, were
            // 2.5–4× as long as the grid sized for every triangle gives (a review's finding).
            grid.release(budget);
            grid = UniformGrid::build_over(mesh, Members::Mesh, tight, live, params, budget)?;
            nested::nest(&mut grid, mesh, params, budget, 0);
        }
        if let Lists::Packed { tris, .. } = &grid.lists {
            match content::Content::new(&grid.shape, &mut grid.offsets, tris, budget) {
                Ok(content) => grid.content = content,
                Err(e) => {
                    grid.release(budget);
                    return Err(e);
                }
            }
        }
        Ok(grid)
    }

    /// A grid over `members` of `mesh` sized for `live` triangles (not zero), in a box around
    /// `tight` (not empty), without nested grids (nested.rs adds them).
    fn build_over(
        mesh: &TriMesh,
        members: Members<'_>,
        tight: Aabb,
        live: usize,
        params: &GridParams,
        budget: &mut MemoryBudget,
    ) -> Result<UniformGrid, BuildError> {
        let shape = Shape::new(tight, live, params.density)?;
        let built = build::lists(mesh, members, &shape, params, budget)?;
        let size = shape.cell_size;
        let mut grid = UniformGrid {
            shape,
            inv_cell64: [size.x, size.y, size.z].map(|s| 1.0 / f64::from(s)),
            offsets: built.offsets,
            lists: built.lists,
            references: built.references,
            largest_cell: built.largest_cell,
            blocks: Blocks::default(),
            nested: Vec::new(),
            nested_span: usize::MAX,
            content: content::Content::default(),
        };
        let offsets = &grid.offsets;
        let occupied = |c: usize| offsets.get(c) != offsets.get(c + 1);
        match Blocks::new(shape.res, occupied, budget) {
            Ok(blocks) => grid.blocks = blocks,
            Err(e) => {
                grid.release(budget);
                return Err(e);
            }
        }
        Ok(grid)
    }

    /// Cells per axis (zero for an empty scene).
    pub fn resolution(&self) -> [u32; 3] {
        self.shape.res
    }

    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Number of triangle references over all cells, those of nested grids included.
    pub fn reference_count(&self) -> usize {
        let nested = |n: &Nested| n.grid.reference_count() + n.large_count as usize;
        self.references + self.nested.iter().map(nested).sum::<usize>()
    }

    /// Number of cells with a nested grid of their own (docs/design.md, "Nested grids").
    pub fn nested_count(&self) -> usize {
        self.nested.len()
    }

    /// The most triangles a walk tests in one cell (padding excluded): the longest list of a cell
    /// without a nested grid, of a nested cell's triangles larger than the cell, or of a nested
    /// grid's cell (docs/design.md, "Nested grids"). A ray whose origin is too far for a nested
    /// grid's walk (beyond 2^40 of its cells) tests the nested cell's whole list instead.
    pub fn largest_cell(&self) -> usize {
        self.largest_cell
    }

    /// Bytes the grid holds (offsets, block bits, references and their triangle packs, content
    /// slabs, nested grids).
    pub fn memory_bytes(&self) -> usize {
        bytes_of(&self.offsets)
            + self.content.memory_bytes()
            + self.blocks.memory_bytes()
            + bytes_of(&self.nested)
            + self
                .nested
                .iter()
                .map(|n| n.grid.memory_bytes() + n.large_ids.bytes() + n.large.bytes())
                .sum::<usize>()
            + match &self.lists {
                Lists::Packed { ids, tris } => ids.bytes() + tris.bytes(),
                Lists::Indexed { ids, packs } => bytes_of(ids) + packs.memory_bytes(),
            }
    }

    /// Bytes of the triangle packs alone (zero for the indexed layout).
    pub fn pack_bytes(&self) -> usize {
        let own = match &self.lists {
            Lists::Packed { tris, .. } => tris.bytes(),
            Lists::Indexed { packs, .. } => packs.memory_bytes(),
        };
        let nested = |n: &Nested| n.grid.pack_bytes() + n.large.bytes();
        own + self.nested.iter().map(nested).sum::<usize>()
    }

    /// The largest distance of a ray origin from the grid (per axis, to the box's far side) that
    /// the cells' margin covers; farther rays are walked from their entry point (docs/design.md).
    pub fn near_reach(&self) -> f32 {
        self.shape.near_reach
    }

    /// Gives the grid's bytes back to the budget it was charged to and drops it.
    pub fn release(mut self, budget: &mut MemoryBudget) {
        for n in self.nested.drain(..) {
            n.release(budget);
        }
        budget.free(self.nested);
        budget.free(self.offsets);
        self.content.release(budget);
        self.blocks.release(budget);
        match self.lists {
            Lists::Packed { ids, tris } => {
                budget.free_big(ids);
                budget.free_big(tris);
            }
            Lists::Indexed { ids, packs } => {
                budget.free(ids);
                packs.release(budget);
            }
        }
    }

    /// The closest hit, also counting the work done.
    pub fn intersect_counted(&self, mesh: &TriMesh, ray: &Ray, work: &mut GridWork) -> Hit {
        self.query::<true, false>(mesh, ray, None, work)
    }

    /// Every query's walk: the ray's plan through the grid (its box first), then the walk
    /// (`COUNT` counts the work in `work`; `ANY` stops at the first hit).
    #[inline(always)]
    fn query<const COUNT: bool, const ANY: bool>(
        &self,
        mesh: &TriMesh,
        ray: &Ray,
        accept: Option<&dyn Accept>,
        work: &mut GridWork,
    ) -> Hit {
        run_clipped_query(mesh, self.shape.bounds, ray, accept, |ray| {
            Some(Walk::<COUNT, ANY> {
                grid: self,
                mesh,
                work,
                plan: Plan::entering(self, ray)?,
            })
        })
    }

    /// Where cell `index`'s list starts and ends in the lists (blocks or ids).
    ///
    /// `index` must be below [`UniformGrid::cell_count`]: the walk keeps every coordinate of its
    /// cell inside the grid (walk.rs), so the flat index is below the product of the resolution.
    #[inline(always)]
    fn span(&self, index: usize) -> (usize, usize) {
        let (first, end, _) = self.cell(index);
        (first, end)
    }

    /// [`UniformGrid::span`], and whether the cell has a content slab worth a test (content.rs):
    /// the flag bit of its offset, so that the walk learns it from the values it loads anyway.
    #[inline(always)]
    fn cell(&self, index: usize) -> (usize, usize, bool) {
        debug_assert!(index + 1 < self.offsets.len());
        // SAFETY: `index < cells` (above) and `offsets.len() == cells + 1` (the type's guarantees).
        let (lo, hi) = unsafe {
            (
                *self.offsets.get_unchecked(index),
                *self.offsets.get_unchecked(index + 1),
            )
        };
        (
            (lo & !content::SLAB_FLAG) as usize,
            (hi & !content::SLAB_FLAG) as usize,
            lo & content::SLAB_FLAG != 0,
        )
    }

    /// Tests the triangles of a cell's list `(first, end)` (from [`UniformGrid::span`], not empty),
    /// keeping the best hit in `best`; with `ANY`, returns the first hit.
    #[inline(always)]
    fn test_span<T: TriangleTest, const ANY: bool>(
        &self,
        test: &T,
        mesh: &TriMesh,
        (first, end): (usize, usize),
        best: &mut Hit,
        mailbox: &mut Mailbox,
    ) -> Option<Hit> {
        match &self.lists {
            Lists::Packed { ids, tris } => {
                debug_assert!(first <= end && end <= tris.len() && tris.len() == ids.len());
                // SAFETY: offsets (without their flag bit) are non-decreasing and end at the number
                // of blocks, which both arrays hold (the type's guarantees), so
                // `first <= end <= len`.
                let (ids, tris) = unsafe {
                    (
                        ids.get_unchecked(first..end),
                        tris.get_unchecked(first..end),
                    )
                };
                let id = |block: usize, lane: usize| {
                    ids.get(block)
                        .map_or(Hit::INVALID_ID, |four| four[lane & 3])
                };
                test_blocks::<T, ANY>(test, tris, id, best, mailbox)
            }
            Lists::Indexed { ids, packs } => {
                test_refs::<T, ANY>(test, mesh, Refs { ids, packs }, (first, end), best, mailbox)
            }
        }
    }

    /// Real triangles listed in cell `index` (for the counted walk; see [`UniformGrid::span`]).
    fn listed(&self, index: usize) -> u32 {
        let (first, end) = self.span(index);
        let real = |p: &u32| *p != Hit::INVALID_ID;
        let n = match &self.lists {
            Lists::Packed { ids, .. } => ids
                .get(first..end)
                .map_or(0, |b| b.iter().flatten().filter(|p| real(p)).count()),
            Lists::Indexed { ids, .. } => ids
                .get(first..end)
                .map_or(0, |b| b.iter().filter(|p| real(p)).count()),
        };
        n as u32
    }
}

impl RayQuery for UniformGrid {
    fn bounds(&self) -> Aabb {
        self.shape.bounds
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
        self.query::<false, false>(mesh, ray, accept, &mut GridWork::default())
    }

    #[inline(never)]
    fn occluded_accepting(&self, mesh: &TriMesh, ray: &Ray, accept: Option<&dyn Accept>) -> bool {
        self.query::<false, true>(mesh, ray, accept, &mut GridWork::default())
            .is_hit()
    }
}
