//! Empty-space skipping: which blocks of `BLOCK × BLOCK × BLOCK` cells hold a triangle, so that the
//! walk crosses an empty block in one step (walk.rs).
//!
//! A block's faces are the cell planes `k·BLOCK` (and the grid's faces), the very planes the walk
//! computes for single cells, so stepping over blocks decides nothing the cell-by-cell walk would
//! decide otherwise: it visits the same cells of the occupied blocks in the same order.

use alloc::vec::Vec;

use crate::budget::MemoryBudget;
use crate::error::BuildError;

/// Cells per block side (a power of two). Over the evaluation's scenes a ray's cells are 90 % empty
/// on most scenes (bunny: 11.4 of 12.9), so a block step saves several cell steps; docs/performance.md
/// has the measurement that chose the size.
pub(super) const BLOCK: u32 = 4;

/// One bit per block of cells, set when some cell of the block has a non-empty list.
///
/// Guarantees: `res[a] = ceil(cells[a] / BLOCK)` for the grid's cells per axis, and `bits` holds a bit
/// for every block (x fastest, then y, then z); a clear bit means every cell of the block is empty.
#[derive(Debug, Default)]
pub(super) struct Blocks {
    /// Blocks per axis.
    pub res: [u32; 3],
    /// `BLOCK − 1` when some block is empty, else all ones: a cell plane `k` (never 0 when
    /// crossed) is a block face worth looking past exactly when `k & faces == 0`, so a grid with no
    /// empty block (hair, soups) pays nothing for the skipping.
    pub faces: u32,
    bits: Vec<u64>,
}

impl Blocks {
    /// The blocks of a grid of `cells` cells per axis whose cell `i` (x fastest) has a non-empty list
    /// when `occupied(i)`, charged to `budget`.
    pub fn new(
        cells: [u32; 3],
        occupied: impl Fn(usize) -> bool,
        budget: &mut MemoryBudget,
    ) -> Result<Blocks, BuildError> {
        let res = cells.map(|c| c.div_ceil(BLOCK));
        let count = res.iter().map(|&r| r as usize).product::<usize>();
        let mut bits = budget.filled(count.div_ceil(64), 0u64, "grid blocks")?;
        let mut cell = 0usize;
        for z in 0..cells[2] {
            for y in 0..cells[1] {
                let row = (z / BLOCK * res[1] + y / BLOCK) as usize * res[0] as usize;
                for x in 0..cells[0] {
                    if occupied(cell) {
                        let b = row + (x / BLOCK) as usize;
                        if let Some(w) = bits.get_mut(b / 64) {
                            *w |= 1 << (b % 64);
                        }
                    }
                    cell += 1;
                }
            }
        }
        let full = |(i, &w): (usize, &u64)| {
            let used = (count - 64 * i).min(64);
            w == u64::MAX >> (64 - used)
        };
        let faces = if bits.iter().enumerate().all(full) {
            u32::MAX
        } else {
            BLOCK - 1
        };
        Ok(Blocks { res, faces, bits })
    }

    /// Whether block `b` holds a triangle. `b` must be a block of the grid (below the product of
    /// `res`): the walk keeps every block coordinate inside the grid, as it does the cells'.
    #[inline(always)]
    pub fn occupied(&self, b: usize) -> bool {
        debug_assert!(b / 64 < self.bits.len());
        // SAFETY: above; `bits` has a bit for every block (the type's guarantees).
        let w = unsafe { *self.bits.get_unchecked(b / 64) };
        w & (1 << (b % 64)) != 0
    }

    /// Marks every block occupied, so that a walk steps through every cell (the reference the
    /// tests compare skipping with).
    #[cfg(test)]
    pub fn occupy_all(&mut self) {
        for w in &mut self.bits {
            *w = u64::MAX;
        }
        self.faces = u32::MAX;
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        crate::budget::bytes_of(&self.bits)
    }

    /// Gives the bytes back to the budget they were charged to.
    pub fn release(self, budget: &mut MemoryBudget) {
        budget.free(self.bits);
    }
}
