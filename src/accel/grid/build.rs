//! The grid's build: each triangle's cells found once ([`Cells::for_each`]) and kept in triangle
//! order while they are counted, a prefix sum that turns the counts into block-aligned offsets,
//! and a fill that walks the kept cells backwards, so that each cell's list comes out sorted by id
//! with the triangles copied beside it. Linear in triangles plus cells plus references.

use alloc::vec::Vec;

use super::layout::Shape;
use super::voxel::{Cells, Overlap};
use super::{GridParams, Lists};
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::Hit;
use crate::triangle::packs::{TriangleLayout, TrianglePacks};
use crate::triangle::Block4;

/// The cell offsets and the lists of a grid of shape `shape` over `mesh`, and the number of
/// references (padding excluded). Every allocation is charged to `budget`; on failure everything
/// taken is given back.
pub(super) fn lists(
    mesh: &TriMesh,
    shape: &Shape,
    params: &GridParams,
    budget: &mut MemoryBudget,
) -> Result<(Vec<u32>, Lists, usize), BuildError> {
    let cells = Cells::new(shape);
    let n_cells = shape.cells();
    let mut counts = budget.filled(n_cells + 1, 0u32, "grid cell offsets")?;
    let kept = match keep_cells(mesh, &cells, params.exact_overlap, &mut counts, budget) {
        Ok(k) => k,
        Err(e) => {
            budget.free(counts);
            return Err(e);
        }
    };
    let packed = params.layout == TriangleLayout::Packed;
    let filled = offsets(&mut counts, n_cells, if packed { 4 } else { 1 })
        .and_then(|total| fill_lists(mesh, &kept, &mut counts, total, packed, budget));
    let references = kept.cells.len();
    kept.release(budget);
    match filled {
        Ok(lists) => {
            if packed {
                // Offsets in blocks from here on: each list starts on one (see `offsets`).
                for c in counts.iter_mut() {
                    *c /= 4;
                }
            }
            Ok((counts, lists, references))
        }
        Err(e) => {
            budget.free(counts);
            Err(e)
        }
    }
}

/// Each live triangle's cells in triangle order, and how many each triangle has.
struct Kept {
    cells: Vec<u32>,
    per_triangle: Vec<u32>,
}

impl Kept {
    fn release(self, budget: &mut MemoryBudget) {
        budget.free(self.cells);
        budget.free(self.per_triangle);
    }
}

/// Finds each live triangle's cells once, counts them in `counts` (one slot per cell) and keeps
/// them for the fill.
#[inline(never)]
fn keep_cells(
    mesh: &TriMesh,
    cells: &Cells,
    exact: bool,
    counts: &mut [u32],
    budget: &mut MemoryBudget,
) -> Result<Kept, BuildError> {
    let tris = mesh.triangles();
    let mut per_triangle = budget.filled(tris.len(), 0u32, "grid build scratch")?;
    // About 2.5 references per triangle on well-shaped scenes; the vector doubles past that.
    let guess = tris.len().saturating_mul(3).max(64);
    let mut kept = match budget.vec::<u32>(guess, "grid build scratch") {
        Ok(v) => v,
        Err(e) => {
            budget.free(per_triangle);
            return Err(e);
        }
    };
    let mut failed = None;
    let degenerate = mesh.degenerate_bits();
    for (prim, (tri, count)) in tris.iter().zip(per_triangle.iter_mut()).enumerate() {
        if degenerate
            .get(prim / 32)
            .map_or(true, |w| w & (1 << (prim % 32)) != 0)
        {
            continue;
        }
        let before = kept.len();
        // Counts `cell` (a cell of the grid: each coordinate is clamped to `res − 1` by
        // `Cells`, and `counts` has one slot per cell and one more). A count cannot wrap: it
        // would need 2^32 references, which the total check below refuses.
        let mut count_cell = |cell: usize| {
            debug_assert!(cell < counts.len());
            // SAFETY: above.
            let n = unsafe { counts.get_unchecked_mut(cell) };
            *n = n.wrapping_add(1);
        };
        match cells.classify(tri, exact) {
            Overlap::Small { base, mut mask } => {
                // At most eight cells: make room first, so that the pushes never grow.
                if kept.capacity() - kept.len() < 8 {
                    if let Err(e) = grow(&mut kept, budget) {
                        failed = Some(e);
                        break;
                    }
                }
                while mask != 0 {
                    let bit = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let cell = base + cells.corner[bit & 7];
                    count_cell(cell);
                    kept.push(cell as u32);
                }
            }
            Overlap::Large(fp) => {
                cells.for_each_large(tri, &fp, exact, &mut |cell| {
                    count_cell(cell as usize);
                    if kept.len() == kept.capacity() && failed.is_none() {
                        if let Err(e) = grow(&mut kept, budget) {
                            failed = Some(e);
                        }
                    }
                    if kept.len() < kept.capacity() {
                        kept.push(cell);
                    }
                });
                if failed.is_some() {
                    break;
                }
            }
        }
        *count = (kept.len() - before) as u32;
    }
    if let Some(e) = failed {
        budget.free(kept);
        budget.free(per_triangle);
        return Err(e);
    }
    if kept.len() > u32::MAX as usize {
        budget.free(kept);
        budget.free(per_triangle);
        return Err(BuildError::CapacityExceeded {
            what: "grid references",
        });
    }
    Ok(Kept {
        cells: kept,
        per_triangle,
    })
}

/// Doubles the room of `kept`, charged to `budget`.
#[cold]
#[inline(never)]
fn grow(kept: &mut Vec<u32>, budget: &mut MemoryBudget) -> Result<(), BuildError> {
    let len = kept.len();
    // `budget.push` grows by doubling when the vector is full; fill it to the brim first.
    while kept.len() < kept.capacity() {
        kept.push(0);
    }
    let r = budget.push(kept, 0, "grid build scratch");
    kept.truncate(len);
    r
}

/// Turns the per-cell counts into the ends of the cell lists, each list starting on a multiple of
/// `align` (1 or 4; so an empty cell's list is empty, not the gap before the next), and
/// `counts[cells]` into the aligned total, which it returns.
#[inline(never)]
fn offsets(counts: &mut [u32], cells: usize, align: u64) -> Result<usize, BuildError> {
    debug_assert!(align.is_power_of_two());
    let round = |t: u64| (t + align - 1) & !(align - 1);
    let mut total: u64 = 0;
    for n in counts.iter_mut().take(cells) {
        total = round(total) + u64::from(*n);
        *n = total as u32;
    }
    let total = round(total);
    if total > u64::from(u32::MAX) {
        return Err(BuildError::CapacityExceeded {
            what: "grid references",
        });
    }
    if let Some(end) = counts.get_mut(cells) {
        *end = total as u32;
    }
    Ok(total as usize)
}

/// Walks the kept cells backwards (last triangle first), handing each reference's slot — the
/// cell's end counted down, so lists come out sorted by id and `counts[c]` ends at the start of
/// cell `c`'s list — to `place(slot, prim, triangle)`. Each cell is counted down exactly as many
/// times as it was counted up, so every slot lies in `[start, end)` of its cell's list (no
/// underflow, and below the total).
#[inline(always)]
fn fill(
    mesh: &TriMesh,
    kept: &Kept,
    counts: &mut [u32],
    mut place: impl FnMut(usize, u32, &[glam::Vec3; 3]),
) {
    let mut end = kept.cells.len();
    let tris = mesh.triangles();
    for (prim, (tri, &n)) in tris.iter().zip(&kept.per_triangle).enumerate().rev() {
        let start = end - n as usize;
        for &cell in kept.cells.get(start..end).unwrap_or(&[]).iter().rev() {
            debug_assert!((cell as usize) < counts.len());
            // SAFETY: every kept cell is a cell of the grid (keep_cells), and `counts` has a slot
            // for each.
            let c = unsafe { counts.get_unchecked_mut(cell as usize) };
            *c -= 1;
            place(*c as usize, prim as u32, tri);
        }
        end = start;
    }
}

/// The lists: packed (ids four to a block beside a copy of their triangles; the gap lanes at the
/// end of each list hold `Hit::INVALID_ID` and NaN) or indexed (ids only, unaligned).
#[inline(never)]
fn fill_lists(
    mesh: &TriMesh,
    kept: &Kept,
    counts: &mut [u32],
    total: usize,
    packed: bool,
    budget: &mut MemoryBudget,
) -> Result<Lists, BuildError> {
    if !packed {
        let mut ids = budget.filled(total, Hit::INVALID_ID, "grid references")?;
        fill(mesh, kept, counts, |slot, prim, _| {
            if let Some(id) = ids.get_mut(slot) {
                *id = prim;
            }
        });
        return Ok(Lists::Indexed {
            ids,
            packs: TrianglePacks::default(),
        });
    }
    let blocks = total / 4;
    let mut ids = budget.vec::<[u32; 4]>(blocks, "grid references")?;
    let mut tris = match budget.vec::<Block4>(blocks, "triangle packs") {
        Ok(t) => t,
        Err(e) => {
            budget.free(ids);
            return Err(e);
        }
    };
    // Debug builds mark every id lane, so that a lane the writes below missed shows.
    const UNWRITTEN: u32 = Hit::INVALID_ID - 1;
    if cfg!(debug_assertions) {
        ids.resize(blocks, [UNWRITTEN; 4]);
        ids.clear();
    }
    let (id_ptr, tri_ptr) = (ids.as_mut_ptr(), tris.as_mut_ptr());
    // Writes `prim` and `tri` into lane `slot % 4` of block `slot / 4`.
    //
    // SAFETY (for every call below): `slot < total = 4 · blocks`, and both vectors have room for
    // `blocks` blocks; the writes go through raw pointers into the reserved, not yet initialised
    // memory, one lane at a time.
    let put = |slot: usize, prim: u32, tri: &[glam::Vec3; 3]| unsafe {
        debug_assert!(slot < total);
        let (b, lane) = (slot / 4, slot % 4);
        core::ptr::addr_of_mut!((*id_ptr.add(b))[lane]).write(prim);
        let v = core::ptr::addr_of_mut!((*tri_ptr.add(b)).v);
        for (i, p) in tri.iter().enumerate() {
            for (k, x) in p.to_array().into_iter().enumerate() {
                core::ptr::addr_of_mut!((*v)[3 * i + k][lane]).write(x);
            }
        }
    };
    // The gap lanes at the end of each list: `counts[c]` is still the end of cell `c`'s list
    // (`offsets`), and the next list starts at that end rounded up to a block.
    const GAP: [glam::Vec3; 3] = [glam::Vec3::NAN; 3];
    for &end in counts.iter().take(counts.len().saturating_sub(1)) {
        let end = end as usize;
        for slot in end..(end + 3) & !3 {
            put(slot, Hit::INVALID_ID, &GAP);
        }
    }
    fill(mesh, kept, counts, put);
    // SAFETY: every lane of the `blocks` blocks is written: the slots `0..total` are the cells'
    // lists one after the other, each list its references (`fill` writes each slot of
    // `[start, end)` once: it counts each cell down exactly as often as it was counted up) and its
    // gap lanes up to the next block (written above); an empty cell's list is empty.
    unsafe {
        ids.set_len(blocks);
        tris.set_len(blocks);
    }
    debug_assert!(ids.iter().flatten().all(|&id| id != UNWRITTEN));
    Ok(Lists::Packed { ids, tris })
}
