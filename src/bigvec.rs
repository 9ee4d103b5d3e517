//! Large arrays that start on a huge-page boundary.
//!
//! A build writes its large arrays (the mesh copy, the grid's packed lists) once, right after taking
//! them, and on a fresh process every 4 KiB page of them costs a page fault at that first write
//! (about 2 µs each on the project's VM: a bunny grid build through the C API spent 5.9 ms instead
//! of 2.8; docs/performance.md, "Stop 46"). Transparent huge pages cut that cost about fivefold, but
//! the kernel backs only the 2 MiB pages that lie whole inside an advised range, and an allocator's
//! large blocks do not start on a 2 MiB boundary, so a few-megabyte `Vec` gets one huge page or
//! none. A [`BigVec`] of at least [`HUGE_PAGE`] bytes is allocated 2 MiB-aligned and advised whole
//! (`budget::advise_huge_pages`). A `Vec` cannot hold such a block: it frees with its element's
//! alignment, and the allocator must be given back the layout it was asked for. The budget charges
//! a block's own bytes, not the alignment's slack an allocator may map around it (untouched address
//! space with glibc).

use core::alloc::Layout;
use core::mem::{size_of, MaybeUninit};
use core::ops::{Deref, DerefMut};
use core::ptr::NonNull;

use crate::budget::advise_huge_pages;

/// A transparent huge page's size (x86-64 and most AArch64 kernels): blocks of at least this many
/// bytes are aligned to it where huge pages are advised.
pub const HUGE_PAGE: usize = 2 << 20;

/// Whether this build advises huge pages (`budget::advise_huge_pages`: Linux with `std`). Elsewhere
/// (the bare-metal archive, other systems) the alignment would buy nothing and could cost a small
/// allocator up to 2 MiB a block.
const ADVISED: bool = cfg!(all(feature = "std", target_os = "linux"));

/// A fixed-capacity array of plain values (`Copy`, so nothing to drop) whose block, when it holds
/// at least [`HUGE_PAGE`] bytes, starts on a [`HUGE_PAGE`] boundary and is advised for transparent
/// huge pages (Linux with `std`). It never grows: its capacity is set when it is made.
///
/// Guarantees: the first `len` elements are initialised; the block is freed with the layout it was
/// allocated with; dereferences to the initialised elements as a slice. Without the hint (see
/// `ADVISED`) it is a plain allocation with the element's alignment.
pub struct BigVec<T: Copy> {
    ptr: NonNull<T>,
    len: usize,
    cap: usize,
}

// SAFETY: a BigVec owns its elements as a Vec does.
unsafe impl<T: Copy + Send> Send for BigVec<T> {}
// SAFETY: shared access gives shared slices only.
unsafe impl<T: Copy + Sync> Sync for BigVec<T> {}

impl<T: Copy> BigVec<T> {
    /// The empty array (no block).
    pub const fn new() -> Self {
        BigVec {
            ptr: NonNull::dangling(),
            len: 0,
            cap: 0,
        }
    }

    /// The layout of a block of `cap` elements (`None` if its size overflows), or `None` for a
    /// block that takes no memory.
    fn layout(cap: usize) -> Option<Layout> {
        let bytes = cap.checked_mul(size_of::<T>())?;
        if bytes == 0 {
            return None;
        }
        let align = if bytes >= HUGE_PAGE && ADVISED {
            HUGE_PAGE.max(align_of::<T>())
        } else {
            align_of::<T>()
        };
        Layout::from_size_align(bytes, align).ok()
    }

    /// An empty array with room for exactly `cap` elements, or `None` when the size overflows or
    /// the allocator refuses (never aborts).
    pub fn with_capacity(cap: usize) -> Option<Self> {
        if cap == 0 || size_of::<T>() == 0 {
            // No block: `layout` is None for zero bytes, so Drop frees nothing.
            return Some(BigVec { cap, ..Self::new() });
        }
        let layout = Self::layout(cap)?;
        // SAFETY: the layout has a non-zero size (`layout` returns None otherwise).
        let ptr = NonNull::new(unsafe { alloc::alloc::alloc(layout) }.cast::<T>())?;
        if layout.align() == HUGE_PAGE {
            advise_huge_pages(ptr.as_ptr() as usize, layout.size());
        }
        Some(BigVec { ptr, len: 0, cap })
    }

    /// The elements it has room for.
    pub fn capacity(&self) -> usize {
        self.cap
    }

    /// Bytes of its block (0 without one).
    pub fn bytes(&self) -> usize {
        Self::layout(self.cap).map_or(0, |l| l.size())
    }

    /// The block's start, for writes past the length (see [`BigVec::set_len`]).
    pub fn as_mut_ptr(&mut self) -> *mut T {
        self.ptr.as_ptr()
    }

    /// The room past the length, uninitialised.
    pub fn spare_capacity_mut(&mut self) -> &mut [MaybeUninit<T>] {
        // SAFETY: the block holds `cap` elements; those past `len` are only handed out as
        // MaybeUninit, and the borrow of `self` keeps the block alive and unshared.
        unsafe {
            core::slice::from_raw_parts_mut(
                self.ptr.as_ptr().add(self.len).cast::<MaybeUninit<T>>(),
                self.cap - self.len,
            )
        }
    }

    /// Sets the length.
    ///
    /// # Safety
    /// `len` is at most the capacity, and the first `len` elements have been written.
    pub unsafe fn set_len(&mut self, len: usize) {
        debug_assert!(len <= self.cap);
        self.len = len;
    }

    /// Appends the items of `items` while there is room, and returns how many it appended.
    pub fn extend_within<I: IntoIterator<Item = T>>(&mut self, items: I) -> usize {
        let start = self.len;
        let spare = self.spare_capacity_mut();
        let mut written = 0;
        for (slot, item) in spare.iter_mut().zip(items) {
            slot.write(item);
            written += 1;
        }
        // SAFETY: the `written` slots past the old length were just written, within the capacity.
        unsafe { self.set_len(start + written) };
        written
    }

    /// Fills the room with copies of `value`, up to the capacity.
    pub fn fill_to_capacity(&mut self, value: T) {
        for slot in self.spare_capacity_mut() {
            slot.write(value);
        }
        // SAFETY: every slot up to the capacity was written (above or before).
        unsafe { self.set_len(self.cap) };
    }
}

impl<T: Copy> Drop for BigVec<T> {
    fn drop(&mut self) {
        if let Some(layout) = Self::layout(self.cap) {
            // SAFETY: a block with a layout was allocated in `with_capacity` with this same layout
            // (the capacity never changes), and is freed once, here.
            unsafe { alloc::alloc::dealloc(self.ptr.as_ptr().cast::<u8>(), layout) };
        }
    }
}

impl<T: Copy> Default for BigVec<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Copy> Deref for BigVec<T> {
    type Target = [T];

    fn deref(&self) -> &[T] {
        // SAFETY: the first `len` elements are initialised (the type's guarantee); the pointer is
        // dangling and aligned only when `len` is 0.
        unsafe { core::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> DerefMut for BigVec<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        // SAFETY: as for `deref`, with the unique borrow of `self`.
        unsafe { core::slice::from_raw_parts_mut(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy + PartialEq> PartialEq for BigVec<T> {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

impl<T: Copy + core::fmt::Debug> core::fmt::Debug for BigVec<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Small blocks keep their element's alignment, large ones start on a huge page, and both
    /// hold what was written, up to their capacity and no further.
    #[test]
    fn a_big_block_starts_on_a_huge_page_and_holds_what_was_written() {
        let small = BigVec::<[u32; 4]>::with_capacity(10).unwrap();
        assert_eq!(small.capacity(), 10);
        assert_eq!(small.bytes(), 160);
        let n = HUGE_PAGE / 16 + 5;
        let mut big = BigVec::<[u32; 4]>::with_capacity(n).unwrap();
        if ADVISED {
            assert_eq!(big.as_mut_ptr() as usize % HUGE_PAGE, 0);
        }
        assert_eq!(big.extend_within((0..3u32).map(|i| [i; 4])), 3);
        big.fill_to_capacity([7; 4]);
        assert_eq!(big.len(), n);
        assert_eq!(big[2], [2; 4]);
        assert_eq!(big[n - 1], [7; 4]);
        assert_eq!(big.extend_within([[9; 4]]), 0, "no room past the capacity");
        assert!(big.spare_capacity_mut().is_empty());
        let empty = BigVec::<u64>::with_capacity(0).unwrap();
        assert!(empty.is_empty() && empty.bytes() == 0);
        let mut units = BigVec::<()>::with_capacity(3).unwrap();
        units.fill_to_capacity(());
        assert_eq!((units.len(), units.capacity(), units.bytes()), (3, 3, 0));
        assert!(BigVec::<u64>::with_capacity(usize::MAX).is_none());
    }

    /// The budget charges a BigVec's bytes before allocating, refuses past its limit without
    /// allocating, and takes the bytes back when it is freed.
    #[test]
    fn the_budget_charges_and_releases_a_big_vec() {
        let mut budget = crate::budget::MemoryBudget::new(HUGE_PAGE * 2);
        let v = budget.big_filled(HUGE_PAGE / 8, 1u64, "test").unwrap();
        assert_eq!(budget.used(), HUGE_PAGE);
        assert_eq!(v.bytes(), HUGE_PAGE);
        assert!(v.iter().all(|&x| x == 1));
        let refused = budget.big_vec::<u64>(HUGE_PAGE / 4, "test");
        assert!(matches!(
            refused,
            Err(crate::error::BuildError::MemoryLimit { .. })
        ));
        assert_eq!(budget.used(), HUGE_PAGE, "a refusal takes nothing");
        budget.free_big(v);
        assert_eq!(budget.used(), 0);
    }

    /// Growing keeps the elements and the budget's count: the new block's bytes replace the old.
    #[test]
    fn a_big_vec_grows_keeping_its_elements() {
        let mut budget = crate::budget::MemoryBudget::new(0);
        let mut v = budget.big_vec::<u32>(3, "test").unwrap();
        v.extend_within([7, 8, 9]);
        let n = HUGE_PAGE / 4 + 1;
        budget.reserve_big(&mut v, n, "test").unwrap();
        assert_eq!((v.len(), v.capacity()), (3, n));
        assert_eq!(&v[..], &[7, 8, 9]);
        assert_eq!(budget.used(), v.bytes());
        budget.reserve_big(&mut v, 2, "test").unwrap();
        assert_eq!(v.capacity(), n, "never shrinks");
        budget.free_big(v);
        assert_eq!(budget.used(), 0);
    }
}
