//! The triangles of a structure's reference list, four to a [`Block4`] in the list's order, so that
//! the hot loop reads them without going through the mesh.

use super::Block4;
use crate::bigvec::BigVec;
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::Hit;

/// How a structure holds the triangles its cells or leaves reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TriangleLayout {
    /// A copy of each referenced triangle beside the reference list, four per 144-byte block in
    /// the list's order (36 bytes per reference): the fastest.
    #[default]
    Packed,
    /// Only the list of triangle ids; each test gathers its four triangles from the mesh (no
    /// bytes beyond the ids), for builds where memory counts more than speed.
    Indexed,
}

/// Blocks of four triangles in the order of a reference list (empty for
/// [`TriangleLayout::Indexed`]).
///
/// Guarantees: with [`TriangleLayout::Packed`], block `i` lane `k` holds the triangle
/// `refs[4·i + k]` of the list it was built from (lanes past the end are zero), and there are
/// `ceil(refs.len() / 4)` blocks.
#[derive(Debug, Default)]
pub struct TrianglePacks {
    /// On a huge page when large (see [`BigVec`]): a build writes it once, right after taking it.
    blocks: BigVec<Block4>,
}

impl TrianglePacks {
    /// Packs the triangles `refs` names (ids of `mesh`), charging the blocks to `budget`.
    pub fn build(
        mesh: &TriMesh,
        refs: &[u32],
        layout: TriangleLayout,
        budget: &mut MemoryBudget,
    ) -> Result<TrianglePacks, BuildError> {
        if layout == TriangleLayout::Indexed || refs.is_empty() {
            return Ok(TrianglePacks::default());
        }
        let mut blocks = budget.big_vec::<Block4>(refs.len().div_ceil(4), "triangle packs")?;
        let written = blocks.extend_within(refs.chunks(4).map(|chunk| {
            let ids = core::array::from_fn(|lane| chunk.get(lane).map_or(Hit::INVALID_ID, |&p| p));
            Block4::gather(mesh.triangles(), ids)
        }));
        debug_assert_eq!(written, refs.len().div_ceil(4));
        Ok(TrianglePacks { blocks })
    }

    /// Blocks `first..end`, or `None` when there are no packs (indexed layout) or no such blocks.
    #[inline(always)]
    pub fn blocks(&self, first: usize, end: usize) -> Option<&[Block4]> {
        if self.blocks.is_empty() {
            return None;
        }
        self.blocks.get(first..end)
    }

    /// The layout these packs serve.
    pub fn layout(&self) -> TriangleLayout {
        if self.blocks.is_empty() {
            TriangleLayout::Indexed
        } else {
            TriangleLayout::Packed
        }
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.blocks.bytes()
    }

    /// Gives the bytes back to the budget they were charged to.
    pub fn release(self, budget: &mut MemoryBudget) {
        budget.free_big(self.blocks);
    }
}
