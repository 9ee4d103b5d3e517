//! Each cell's content slab: the bounds, on the cell's thinnest axis, of its triangles' points in
//! and near the cell, so that the walk can pass over a cell whose triangles the ray cannot reach in
//! its window without reading their blocks — a ray leaving a floor, or passing over it
//! (docs/design.md, "Uniform grid", "Content slabs").
//!
//! Why passing over such a cell loses no hit: the walk finds a hit at point `P` of triangle `T` in
//! the cell that owns `P` (up to the walk's rounding, which the margin covers), where `T` is listed
//! because it meets that cell enlarged by the margin. That cell's slab holds every point of its
//! listed triangles within twice the margin of the cell (each triangle's bounds, which hold its
//! points exactly, cut to that enlarged cell), so it holds `P`; the test widens the line's
//! crossings of the slab's planes by more than their rounding (8 ulps), so a line through `P` at a `t`
//! inside the window never misses it. Only lines walked from the ray's own origin use it (a far
//! origin's line is off the ray by up to the margin).

use alloc::vec::Vec;
use core::mem::MaybeUninit;

use glam::{Vec3, Vec4};

use super::layout::{Shape, U32};
use super::walk::Line;
use crate::budget::MemoryBudget;
use crate::error::BuildError;
use crate::triangle::Block4;

/// The bounds of one cell's content on its thinnest axis (relative to the cell's side): the slab
/// `lo ≤ x[axis] ≤ hi` holds every listed triangle's points near the cell. `axis` 3: no slab
/// worth a test (see [`USEFUL_SHARE`]).
#[derive(Clone, Copy, Debug)]
struct Slab {
    lo: f32,
    hi: f32,
    axis: u32,
}

/// Relative slack of a computed crossing `(b − o)·inv`: 16u (8 ulps; three roundings — the
/// difference, the product and the inverse — are at most about 3u, 6u with a subnormal inverse).
const T_SLACK: f32 = 16.0 * U32;
/// Absolute slack of a crossing: four of the smallest subnormal steps, for one that underflows.
const T_FLOOR: f32 = 5.6e-45;

/// The bit of a cell's first offset that says its content slab is worth a test (see
/// [`UniformGrid::cell`](super::UniformGrid)): the walk reads it with the offsets it loads anyway,
/// where a separate bit per cell, and the slab read for every cell, cost 2–9 % of the time of
/// scenes whose slabs are seldom passed (hair-50k, soup-10k, dragon_res2).
pub(super) const SLAB_FLAG: u32 = 1 << 31;

#[cfg(all(test, feature = "std"))]
std::thread_local! {
    /// Cells the plain walk passed over on this thread (tests check that the walk uses the slabs).
    pub(super) static PASSED: core::cell::Cell<usize> = const { core::cell::Cell::new(0) };
}

/// The content slabs of a grid's cells (none for the indexed layout and nested grids): one slot
/// per cell, written only for the flagged cells, so that a scene with few thin cells touches few of
/// the slots' pages (written whole, the slots cost sibenik's, engine_2cyl's and dragon_res2's grid
/// builds 6–9 % of their time, most of it first touches of fresh pages; an array of 2 MiB or more
/// gets the build's huge-page hint, whose pages are touched whole).
#[derive(Debug, Default)]
pub(super) struct Content {
    slabs: Vec<MaybeUninit<Slab>>,
}

impl Content {
    /// The content of a grid with packed lists `blocks` (cell `c`'s blocks are
    /// `offsets[c]..offsets[c + 1]`, none flagged yet), charged to `budget`, flagging the cells
    /// whose slab is worth a test; none (nothing kept, nothing flagged) when no cell's is, or when
    /// the blocks would reach the flag bit (they do not: a packed grid holds at most 2^30 blocks).
    /// The slots are charged like the grid's other arrays: a build without room for them fails
    /// whole (the allocation sweeps of tests/alloc_failure.rs hold every refusal to that).
    pub(super) fn new(
        shape: &Shape,
        offsets: &mut [u32],
        blocks: &[Block4],
        budget: &mut MemoryBudget,
    ) -> Result<Content, BuildError> {
        let cells = offsets.len().saturating_sub(1);
        if offsets.last().is_some_and(|&n| n >= SLAB_FLAG) {
            return Ok(Content::default());
        }
        let mut slabs = budget.vec::<MaybeUninit<Slab>>(cells, "grid content slabs")?;
        // SAFETY: the vector has room for `cells` (`vec` reserved them), and a `MaybeUninit`
        // needs no initialisation.
        unsafe { slabs.set_len(cells) };
        let mut flagged = false;
        let (m, size) = (shape.margin, shape.cell_size);
        let [rx, ry, rz] = shape.res.map(|r| r as usize);
        let mut c = 0;
        for z in 0..rz {
            for y in 0..ry {
                for x in 0..rx {
                    let (first, end) = (offsets[c] as usize, offsets[c + 1] as usize);
                    let list = blocks.get(first..end).unwrap_or(&[]);
                    if !list.is_empty() && list.len() <= MAX_BLOCKS {
                        let corner =
                            shape.bounds.min + Vec3::new(x as f32, y as f32, z as f32) * size;
                        let slab = Slab::of(list, corner, size, m);
                        if slab.axis < 3 {
                            // Cell `c`'s first offset, read above before the flag (`c + 1`'s is
                            // read next, unflagged).
                            offsets[c] |= SLAB_FLAG;
                            if let Some(slot) = slabs.get_mut(c) {
                                slot.write(slab);
                            }
                            flagged = true;
                        }
                    }
                    c += 1;
                }
            }
        }
        if !flagged {
            budget.free(slabs);
            return Ok(Content::default());
        }
        Ok(Content { slabs })
    }

    /// Whether there are slabs (some cell is flagged).
    #[cfg(test)]
    pub(super) fn is_some(&self) -> bool {
        !self.slabs.is_empty()
    }

    /// Whether `line` misses cell `index`'s slab for every `t` in `[line.t0, t1]` (so the walk may
    /// pass over the cell).
    ///
    /// # Safety
    /// Cell `index` must be flagged ([`SLAB_FLAG`] on its first offset): only flagged cells' slabs
    /// are written.
    #[inline(always)]
    pub(super) unsafe fn misses(&self, index: usize, line: &Line, t1: f32) -> bool {
        self.slabs.get(index).is_some_and(|b| {
            // SAFETY: `new` wrote the slab of every cell it flagged (the caller's promise).
            let b = unsafe { b.assume_init_ref() };
            b.misses(line.org, line.inv, line.t0, t1)
        })
    }

    /// Bytes held.
    pub(super) fn memory_bytes(&self) -> usize {
        crate::budget::bytes_of(&self.slabs)
    }

    /// Gives the bytes back to `budget`.
    pub(super) fn release(self, budget: &mut MemoryBudget) {
        budget.free(self.slabs);
    }
}

/// The bounds of the triangles in a cell's list `blocks` (not empty) cut to `[cut_lo, cut_hi]`,
/// four lanes at a time, or `None` once those of its first 1, 2, 4, 8, ... blocks are at least
/// `wide` on every axis (no slab would be worth a test: most cells of hair, soups and scanned
/// surfaces end there, for a fraction of the pass). Only the last block
/// of a list has unused lanes (NaN; a list fills whole blocks, mod.rs), so the others take plain
/// `min`/`max` and the last one comparisons, which pass over a NaN.
fn bounds_of(blocks: &[Block4], cut_lo: Vec3, cut_hi: Vec3, wide: Vec3) -> Option<(Vec3, Vec3)> {
    let (mut lo, mut hi) = ([Vec4::INFINITY; 3], [Vec4::NEG_INFINITY; 3]);
    let reduce = |lo: &[Vec4; 3], hi: &[Vec4; 3]| {
        (
            Vec3::new(
                lo[0].min_element(),
                lo[1].min_element(),
                lo[2].min_element(),
            )
            .max(cut_lo),
            Vec3::new(
                hi[0].max_element(),
                hi[1].max_element(),
                hi[2].max_element(),
            )
            .min(cut_hi),
        )
    };
    let (last, whole) = blocks.split_last()?;
    for (b, block) in whole.iter().enumerate() {
        for i in 0..3 {
            for k in 0..3 {
                let x = Vec4::from_array(block.v[3 * i + k]);
                lo[k] = lo[k].min(x);
                hi[k] = hi[k].max(x);
            }
        }
        // After blocks 1, 2, 4, 8, ...: a long list that is wide stops soon, for a few checks.
        if b & (b + 1) == 0 {
            let (l, h) = reduce(&lo, &hi);
            if (h - l).cmpge(wide).all() {
                return None;
            }
        }
    }
    for i in 0..3 {
        for k in 0..3 {
            let x = Vec4::from_array(last.v[3 * i + k]);
            lo[k] = Vec4::select(x.cmplt(lo[k]), x, lo[k]);
            hi[k] = Vec4::select(x.cmpgt(hi[k]), x, hi[k]);
        }
    }
    Some(reduce(&lo, &hi))
}

/// Lists of more blocks get no slab: their bounds cost the build a pass over many blocks (bunny's
/// lists of ~9 blocks: 6 % of its grid build) for slabs seldom thin (a cell's part of a floor is
/// typically one or two blocks).
const MAX_BLOCKS: usize = 4;

/// A slab narrower than this share of the cell's side is worth testing a line against.
const USEFUL_SHARE: f32 = 0.125;

impl Slab {
    /// The slab of a cell with corner `corner`, side `size` and margin `m` holding the triangles
    /// of `list` (not empty), or [`Slab::FULL`] when it is not worth a test.
    fn of(list: &[Block4], corner: Vec3, size: Vec3, m: Vec3) -> Slab {
        // The cell enlarged by twice the margin: its corner's rounding (a few ulps of the box's
        // coordinates) is far inside one margin (at least 16 roundings of them, layout.rs).
        let (cut_lo, cut_hi) = (corner - 2.0 * m, corner + size + 2.0 * m);
        let Some((lo, hi)) = bounds_of(list, cut_lo, cut_hi, size * USEFUL_SHARE) else {
            return Slab::FULL;
        };
        let share = (hi - lo) / size;
        let axis = if share.x <= share.y && share.x <= share.z {
            0
        } else if share.y <= share.z {
            1
        } else {
            2
        };
        // A slab wider than a share of the cell's side seldom lets a ray pass: the walk then
        // tests the list without reading it.
        if share[axis] < USEFUL_SHARE {
            Slab {
                lo: lo[axis],
                hi: hi[axis],
                axis: axis as u32,
            }
        } else {
            Slab::FULL
        }
    }

    /// No slab: the cell's list is tested.
    const FULL: Slab = Slab {
        lo: f32::NEG_INFINITY,
        hi: f32::INFINITY,
        axis: 3,
    };

    /// Whether the line `org + t·dir` (`inv` its direction's inverse, per axis) certainly misses the slab for every `t` in `[t0, t1]`. A zero component's infinite
    /// inverse gives infinite or NaN crossings, which never make a false miss.
    #[inline(always)]
    fn misses(&self, org: Vec3, inv: Vec3, t0: f32, t1: f32) -> bool {
        let (o, i) = match self.axis {
            0 => (org.x, inv.x),
            1 => (org.y, inv.y),
            2 => (org.z, inv.z),
            _ => return false,
        };
        let (x, y) = ((self.lo - o) * i, (self.hi - o) * i);
        let (x, y) = if x < y { (x, y) } else { (y, x) };
        let (x, y) = (
            x - (x.abs() * T_SLACK + T_FLOOR),
            y + (y.abs() * T_SLACK + T_FLOOR),
        );
        // A NaN compares false: no miss.
        x > t1 || y < t0
    }
}
