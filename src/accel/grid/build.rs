//! The grid's build: each triangle's cells found once ([`Cells::for_each`]) and kept in triangle
//! order while they are counted, a prefix sum that turns the counts into block-aligned offsets,
//! and a fill that walks the kept cells backwards, so that each cell's list comes out sorted by id
//! with the triangles copied beside it. Linear in triangles plus cells plus references.

use alloc::vec::Vec;

use super::layout::Shape;
use super::voxel::{Cells, Overlap};
use super::{GridParams, Lists};
use crate::bigvec::BigVec;
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::Hit;
use crate::triangle::packs::{TriangleLayout, TrianglePacks};
use crate::triangle::Block4;

/// What [`lists`] builds.
pub(super) struct Built {
    /// The cells' offsets (`cells + 1` of them).
    pub offsets: Vec<u32>,
    pub lists: Lists,
    /// References over all cells (padding excluded).
    pub references: usize,
    /// The most references one cell holds.
    pub largest_cell: usize,
}

/// The triangles a grid lists.
#[derive(Clone, Copy)]
pub(super) enum Members<'a> {
    /// Every non-degenerate triangle of the mesh.
    Mesh,
    /// These (non-degenerate) triangles: a nested grid's cell list.
    Listed(&'a [u32]),
}

impl Members<'_> {
    /// How many triangles the build walks (degenerate ones of the mesh included).
    fn len(&self, mesh: &TriMesh) -> usize {
        match self {
            Members::Mesh => mesh.len(),
            Members::Listed(ids) => ids.len(),
        }
    }

    /// The id of the `i`-th triangle walked.
    #[inline(always)]
    fn prim(&self, i: usize) -> usize {
        match self {
            Members::Mesh => i,
            Members::Listed(ids) => ids.get(i).map_or(usize::MAX, |&p| p as usize),
        }
    }
}

/// The cell offsets and the lists of a grid of shape `shape` over `members` of `mesh`, with its
/// reference counts. Every allocation is charged to `budget`; on failure everything taken is
/// given back.
pub(super) fn lists(
    mesh: &TriMesh,
    members: Members<'_>,
    shape: &Shape,
    params: &GridParams,
    budget: &mut MemoryBudget,
) -> Result<Built, BuildError> {
    let cells = Cells::new(shape);
    let n_cells = shape.cells();
    let mut counts = budget.filled(n_cells + 1, 0u32, "grid cell offsets")?;
    let kept = match keep_cells(
        mesh,
        members,
        &cells,
        params.exact_overlap,
        &mut counts,
        budget,
    ) {
        Ok(k) => k,
        Err(e) => {
            budget.free(counts);
            return Err(e);
        }
    };
    let largest_cell = counts.iter().take(n_cells).max().map_or(0, |&n| n as usize);
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
            Ok(Built {
                offsets: counts,
                lists,
                references,
                largest_cell,
            })
        }
        Err(e) => {
            budget.free(counts);
            Err(e)
        }
    }
}

/// Each member's cells in member order, with the member's id beside each.
/// Both are written once, in order, right after they are taken: on huge pages when large
/// ([`BigVec`]).
struct Kept {
    cells: BigVec<u32>,
    /// The id of the triangle of each kept cell (as long as `cells`): the fill then walks
    /// references, not triangles with a varying number of cells each.
    prims: BigVec<u32>,
}

impl Kept {
    fn release(self, budget: &mut MemoryBudget) {
        budget.free_big(self.cells);
        budget.free_big(self.prims);
    }

    /// The references both vectors have room for.
    #[inline(always)]
    fn room(&self) -> usize {
        self.cells.capacity().min(self.prims.capacity())
    }

    /// Doubles the room of both vectors, or more where the references so far, spread over the
    /// `done` of `total` members walked, project more, and at least to `written + need`, charged to
    /// `budget`, keeping their first `written` elements (written through raw pointers beyond the
    /// vectors' lengths, at most `room()`).
    #[cold]
    #[inline(never)]
    fn grow(
        &mut self,
        written: usize,
        need: usize,
        (done, total): (usize, usize),
        budget: &mut MemoryBudget,
    ) -> Result<(), BuildError> {
        debug_assert!(written <= self.room());
        // SAFETY: the callers wrote the first `written` elements of both vectors, within both
        // capacities. The lengths must cover them before a reallocation: a vector moves its
        // elements, and promises nothing of its spare capacity.
        unsafe {
            self.cells.set_len(written);
            self.prims.set_len(written);
        }
        let room = self.room();
        let doubled = room
            .checked_add(room.max(64))
            .ok_or(BuildError::OutOfMemory {
                what: "grid build scratch",
                bytes: usize::MAX,
            })?;
        // One reallocation where doubling would take two on scenes of long triangles (hair: 6.65
        // references a triangle against the first guess of 3), with an eighth to spare. At most
        // four times the room (a prefix of long triangles must not reserve many times what the
        // rest needs), and only within the memory limit, which doubling alone might still meet.
        let projected = (written as f64 * total as f64 / done.max(1) as f64 * 1.125) as usize;
        let projected = projected.min(room.saturating_mul(4));
        // The peak the two growths reach: each new block is taken while its old one is still held
        // (`reserve_big` copies), so both new blocks and the second old one at once.
        let u32_bytes = core::mem::size_of::<u32>();
        let extra = projected
            .saturating_mul(2 * u32_bytes)
            .saturating_sub(room.saturating_mul(u32_bytes));
        let fits = budget.limit() == 0 || budget.used().saturating_add(extra) <= budget.limit();
        let room = if fits {
            doubled.max(projected)
        } else {
            doubled
        }
        .max(written.saturating_add(need));
        // Should the second growth be refused, the first keeps its larger block until the build
        // releases both (`room` stays the smaller capacity, so nothing is written past it).
        budget.reserve_big(&mut self.cells, room, "grid build scratch")?;
        budget.reserve_big(&mut self.prims, room, "grid build scratch")
    }
}

/// Finds each live member's cells once, keeps them with the member's id beside each, and counts
/// them in `counts` (one slot per cell).
#[inline(never)]
fn keep_cells(
    mesh: &TriMesh,
    members: Members<'_>,
    cells: &Cells,
    exact: bool,
    counts: &mut [u32],
    budget: &mut MemoryBudget,
) -> Result<Kept, BuildError> {
    let tris = mesh.triangles();
    let n = members.len(mesh);
    // About 2.5 references per triangle on well-shaped scenes; the vectors grow past that (`grow`).
    let guess = n.saturating_mul(3).max(64);
    let mut kept = Kept {
        cells: budget.big_vec::<u32>(guess, "grid build scratch")?,
        prims: BigVec::new(),
    };
    match budget.big_vec::<u32>(guess, "grid build scratch") {
        Ok(v) => kept.prims = v,
        Err(e) => {
            kept.release(budget);
            return Err(e);
        }
    }
    let mut failed = None;
    let degenerate = mesh.degenerate_bits();
    // For each mask of a small footprint's cells, the flat offsets of its cells from the
    // footprint's corner ([`small_cells`]), in the u32 of the kept cells (a cell's index is below
    // `u32::MAX`, so the kept cells' sums do not wrap): a triangle's cells are then two 4-lane adds
    // and stores, where a store per corner and a length advanced by its bit took ~33 instructions a
    // triangle (a quarter of bunny's count pass). Making the table costs a grid build ~8 600
    // instructions, so a grid of fewer than `SMALL_CELLS_TABLE_MIN` members makes each row when it
    // needs it instead (callgrind, a grid of four triangles: 4.0 k instructions without the table,
    // 12.6 k with it).
    let corners = if n >= SMALL_CELLS_TABLE_MIN {
        match small_cells_table(&cells.corner, budget) {
            Ok(t) => t,
            Err(e) => {
                kept.release(budget);
                return Err(e);
            }
        }
    } else {
        Vec::new()
    };
    let table = !corners.is_empty();
    // The references are written through raw pointers up to `len`, and the vectors' lengths set
    // from `len` only where the vectors are used themselves (`Kept::grow`, the end): the length
    // stays in a register instead of going through memory on every store.
    let mut len = 0;
    for i in 0..n {
        let prim = members.prim(i);
        // A listed member is live (it was listed); the mesh's degenerate triangles are skipped.
        let skip = matches!(members, Members::Mesh)
            && degenerate
                .get(prim / 32)
                .map_or(true, |w| w & (1 << (prim % 32)) != 0);
        let Some(tri) = tris.get(prim).filter(|_| !skip) else {
            continue;
        };
        match cells.classify(tri, exact) {
            Overlap::Small { base, mask } => {
                // At most eight cells: make room first, so that the stores stay in the capacity.
                if kept.room() - len < 8 {
                    if let Err(e) = kept.grow(len, 8, (i + 1, n), budget) {
                        failed = Some(e);
                        break;
                    }
                }
                debug_assert!(kept.room() - len >= 8);
                let (out, ids) = (kept.cells.as_mut_ptr(), kept.prims.as_mut_ptr());
                // SAFETY: both vectors have room for 8 elements from `len` (above).
                unsafe {
                    ids.add(len)
                        .cast::<[u32; 8]>()
                        .write_unaligned([prim as u32; 8])
                };
                let base = base as u32;
                // All eight slots are stored and the length advanced by the cells' count, without
                // a branch per cell (how many cells a triangle has is hard to predict): the slots
                // past the count are overwritten or left beyond the length.
                let m = mask as usize & 0xff;
                let row = if table {
                    debug_assert_eq!(corners.len(), 256);
                    // SAFETY: `m ≤ 255`, and a table holds a row for each of the 256 masks.
                    unsafe { *corners.get_unchecked(m) }
                } else {
                    small_cells(m, &cells.corner)
                };
                // SAFETY: both vectors have room for 8 elements from `len` (above).
                unsafe {
                    out.add(len)
                        .cast::<[u32; 8]>()
                        .write_unaligned(row.map(|c| base.wrapping_add(c)))
                };
                len += CELL_COUNT[m] as usize;
            }
            Overlap::Large(fp) => {
                if let Some((base, mut mask)) = cells.medium_cells(tri, &fp, exact) {
                    // At most 64 cells, counted: make room for them first (one growth makes room
                    // for at least 64), then store without a check per cell.
                    if kept.room() - len < mask.count_ones() as usize {
                        let need = mask.count_ones() as usize;
                        if let Err(e) = kept.grow(len, need, (i + 1, n), budget) {
                            failed = Some(e);
                            break;
                        }
                    }
                    debug_assert!(kept.room() - len >= mask.count_ones() as usize);
                    let (out, ids) = (kept.cells.as_mut_ptr(), kept.prims.as_mut_ptr());
                    while mask != 0 {
                        let bit = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        // SAFETY: one of the mask's cells, each below both capacities (above).
                        unsafe {
                            out.add(len).write(cells.medium_cell(base, bit) as u32);
                            ids.add(len).write(prim as u32);
                        }
                        len += 1;
                    }
                    continue;
                }
                // A footprint of at most `RESERVED_CELLS` cells: room for all of them first, then
                // stores without a check (~18 instructions a cell less on slivers).
                // Under a memory limit that room may not be there; the cells then go one by one
                // (below), which takes only what they need.
                let volume = (0..3).fold(1u64, |v, a| v * u64::from(fp.len(a)));
                let need = volume as usize;
                let reserved = volume <= RESERVED_CELLS
                    && (kept.room() - len >= need
                        || kept.grow(len, need, (i + 1, n), budget).is_ok());
                if reserved {
                    debug_assert!(kept.room() - len >= need);
                    let (out, ids) = (kept.cells.as_mut_ptr(), kept.prims.as_mut_ptr());
                    let start = len;
                    cells.for_each_large(tri, &fp, exact, &mut |cell| {
                        debug_assert!(len - start < need);
                        // SAFETY: a footprint's cell is emitted at most once, so at most `need`
                        // from `start`, within both capacities (above).
                        unsafe {
                            out.add(len).write(cell);
                            ids.add(len).write(prim as u32);
                        }
                        len += 1;
                    });
                    continue;
                }
                // As above, through raw pointers up to `len`, the room checked per cell (a long
                // triangle's cells are many, and two checked pushes each cost twice as much).
                cells.for_each_large(tri, &fp, exact, &mut |cell| {
                    if len == kept.room() {
                        if failed.is_some() {
                            return;
                        }
                        if let Err(e) = kept.grow(len, 1, (i + 1, n), budget) {
                            failed = Some(e);
                            return;
                        }
                    }
                    debug_assert!(len < kept.room());
                    let (out, ids) = (kept.cells.as_mut_ptr(), kept.prims.as_mut_ptr());
                    // SAFETY: `len` is below both capacities (above).
                    unsafe {
                        out.add(len).write(cell);
                        ids.add(len).write(prim as u32);
                    }
                    len += 1;
                });
                if failed.is_some() {
                    break;
                }
            }
        }
    }
    budget.free(corners);
    debug_assert!(len <= kept.room());
    // SAFETY: the first `len` elements of both were written.
    unsafe {
        kept.cells.set_len(len);
        kept.prims.set_len(len);
    }
    if let Some(e) = failed {
        kept.release(budget);
        return Err(e);
    }
    if kept.cells.len() > u32::MAX as usize {
        kept.release(budget);
        return Err(BuildError::CapacityExceeded {
            what: "grid references",
        });
    }
    count_cells(&kept.cells, counts);
    Ok(kept)
}

/// The most cells of a large footprint for which [`keep_cells`] makes room before listing them
/// (4 096 cells, 32 KiB of room at most): a triangle lists each cell of its footprint once at most.
const RESERVED_CELLS: u64 = 4096;

/// The number of set bits of each byte.
const CELL_COUNT: [u8; 256] = {
    let mut t = [0u8; 256];
    let mut m = 0;
    while m < 256 {
        t[m] = (m as u32).count_ones() as u8;
        m += 1;
    }
    t
};

/// Grids of at least this many members make [`small_cells_table`]: it costs ~8 600 instructions
/// and saved ~32 a triangle on bunny (29.03 → 26.82 M for 69 451), so by instruction counts it
/// pays from about 270 triangles.
const SMALL_CELLS_TABLE_MIN: usize = 256;

/// [`small_cells`] of every mask, charged to `budget`: each row from the one without the mask's
/// highest bit, with that bit's corner appended (a few instructions a row).
fn small_cells_table(
    corner: &[usize; 8],
    budget: &mut MemoryBudget,
) -> Result<Vec<[u32; 8]>, BuildError> {
    let mut table = budget.vec::<[u32; 8]>(256, "grid build scratch")?;
    table.push([0; 8]);
    for mask in 1..256usize {
        let high = 31 - (mask as u32).leading_zeros() as usize;
        let rest = mask ^ (1 << high);
        let mut row = table.get(rest).copied().unwrap_or_default();
        if let Some(slot) = row.get_mut(usize::from(CELL_COUNT[rest])) {
            *slot = corner[high & 7] as u32;
        }
        table.push(row);
    }
    Ok(table)
}

/// The offsets `corner[bit]` of the cells of `mask` (bit `i + 2j + 4k` for the cell `i, j, k` of
/// a small footprint), in bit order, then zeros.
#[cold]
#[inline(never)]
fn small_cells(mask: usize, corner: &[usize; 8]) -> [u32; 8] {
    let mut row = [0u32; 8];
    let set = (0..8).filter(|b| mask >> b & 1 != 0);
    for (slot, b) in row.iter_mut().zip(set) {
        *slot = corner[b] as u32;
    }
    row
}

/// Counts each kept cell in its slot of `counts`, in a pass of its own: in the loop that finds the
/// cells, the increments of a varying number of cells per triangle cost a branch each. A count
/// cannot wrap: it would need 2^32 references, which [`keep_cells`] refuses.
#[inline(never)]
fn count_cells(kept: &[u32], counts: &mut [u32]) {
    for &cell in kept {
        debug_assert!((cell as usize) < counts.len());
        // SAFETY: every kept cell is a cell of the grid (each coordinate is clamped to `res − 1`
        // by `Cells`), and `counts` has one slot per cell and one more.
        let n = unsafe { counts.get_unchecked_mut(cell as usize) };
        *n = n.wrapping_add(1);
    }
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
    // The offsets must stay below the content slabs' flag bit (content.rs): packed offsets count
    // blocks, a quarter of the references, which then always do; indexed ones count ids, so an
    // indexed grid holds fewer than 2^31 references.
    let most = if align == 1 {
        u64::from(super::content::SLAB_FLAG) - 1
    } else {
        u64::from(u32::MAX)
    };
    if total > most {
        return Err(BuildError::CapacityExceeded {
            what: "grid references",
        });
    }
    if let Some(end) = counts.get_mut(cells) {
        *end = total as u32;
    }
    Ok(total as usize)
}

/// Walks the kept references backwards (last member first), writing each one's id into its slot
/// of `ids` — the cell's end counted down, so lists come out sorted by id and `counts[c]` ends at
/// the start of cell `c`'s list. Each cell is counted down exactly as many times as it was counted
/// up, so every slot lies in `[start, end)` of its cell's list (no underflow, and below the total,
/// the length of `ids`).
#[inline(never)]
fn scatter_ids(kept: &Kept, counts: &mut [u32], ids: &mut [u32]) {
    for (&cell, &prim) in kept.cells.iter().zip(kept.prims.iter()).rev() {
        debug_assert!((cell as usize) < counts.len());
        // SAFETY: every kept cell is a cell of the grid (keep_cells), and `counts` has a slot for
        // each.
        let c = unsafe { counts.get_unchecked_mut(cell as usize) };
        *c -= 1;
        debug_assert!((*c as usize) < ids.len());
        // SAFETY: above, `*c` is a slot of the cell's list, below the total.
        unsafe { *ids.get_unchecked_mut(*c as usize) = prim };
    }
}

/// The lists: packed (ids four to a block beside a copy of their triangles; the gap lanes at the
/// end of each list hold `Hit::INVALID_ID` and NaN) or indexed (ids only, unaligned).
///
/// The ids are scattered into their lists first (4 bytes per reference), and the packed blocks
/// then gathered in list order, whole blocks at a time: scattering the 36 bytes of each triangle
/// lane by lane instead took twice the time.
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
        scatter_ids(kept, counts, &mut ids);
        return Ok(Lists::Indexed {
            ids,
            packs: TrianglePacks::default(),
        });
    }
    let blocks = total / 4;
    // Every lane starts unused, so the gap lanes at the end of each list need no pass of their own.
    let mut ids = budget.big_filled(blocks, [Hit::INVALID_ID; 4], "grid references")?;
    scatter_ids(kept, counts, ids.as_flattened_mut());
    match gather_blocks(mesh, &ids, budget) {
        Ok(tris) => Ok(Lists::Packed { ids, tris }),
        Err(e) => {
            budget.free_big(ids);
            Err(e)
        }
    }
}

/// The triangles of `ids` copied beside them, a block per four ids (gap lanes `Hit::INVALID_ID`
/// give NaN lanes), charged to `budget`.
pub(super) fn gather_blocks(
    mesh: &TriMesh,
    ids: &[[u32; 4]],
    budget: &mut MemoryBudget,
) -> Result<BigVec<Block4>, BuildError> {
    let mut tris = budget.big_vec::<Block4>(ids.len(), "triangle packs")?;
    let all = mesh.triangles();
    let written = tris.extend_within(ids.iter().map(|&four| Block4::gather(all, four)));
    debug_assert_eq!(written, ids.len());
    Ok(tris)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each mask's row lists the offsets of its set bits' corners in bit order, then zeros, and
    /// the count table counts the bits.
    #[test]
    fn small_cells_pack_the_masks_cells_in_bit_order() {
        let corner = [0, 1, 10, 11, 100, 101, 110, 111];
        let mut budget = MemoryBudget::new(0);
        let table = small_cells_table(&corner, &mut budget).unwrap();
        assert_eq!(table.len(), 256);
        for mask in 0..256 {
            let row = small_cells(mask, &corner);
            assert_eq!(table[mask], row, "mask {mask:#b}");
            let want: Vec<u32> = (0..8)
                .filter(|b| mask >> b & 1 != 0)
                .map(|b| corner[b] as u32)
                .collect();
            assert_eq!(CELL_COUNT[mask] as usize, want.len(), "mask {mask:#b}");
            assert_eq!(&row[..want.len()], &want[..], "mask {mask:#b}");
            assert!(row[want.len()..].iter().all(|&c| c == 0), "mask {mask:#b}");
        }
        budget.free(table);
    }
}
