//! Fallible allocation with a memory limit and a memory monitor: every byte a build holds is counted
//! here, and asked for here before the allocator sees the request.

use alloc::vec::Vec;
use core::ffi::c_void;

use crate::bigvec::BigVec;
use crate::error::BuildError;

/// A caller's callback that is told, before each allocation of a build, how many bytes the build would
/// hold once the allocation is made, and that may refuse it (the build then fails with
/// [`BuildError::Cancelled`] and frees what it took). It is a C function pointer plus an opaque
/// pointer so that the C API can pass the caller's callback straight through.
///
/// Guarantees: [`MemoryMonitor::allows`] calls the callback exactly once per charge, with the
/// pointer given to [`MemoryMonitor::new`], on the thread that runs the build or
/// [`crate::Scene::update`].
#[derive(Clone, Copy, Debug)]
pub struct MemoryMonitor {
    callback: unsafe extern "C" fn(user: *mut c_void, bytes: usize) -> bool,
    user: *mut c_void,
}

// SAFETY: the pointer is only handed back to the caller's callback, and `MemoryMonitor::new`'s
// contract makes the caller answer for calling it from any thread, at once, while a copy exists.
unsafe impl Send for MemoryMonitor {}
// SAFETY: as for Send; a shared MemoryMonitor is only ever read.
unsafe impl Sync for MemoryMonitor {}

impl MemoryMonitor {
    /// A monitor that calls `callback(user, bytes)`; `true` lets the allocation go ahead.
    ///
    /// # Safety
    /// `callback` must be safe to call with `user` from any thread, possibly from several at once
    /// (scenes built on different threads may share a monitor), for as long as this monitor or
    /// any copy of it exists (`allows` is public and the monitor is `Copy`), and must not unwind.
    pub const unsafe fn new(
        callback: unsafe extern "C" fn(user: *mut c_void, bytes: usize) -> bool,
        user: *mut c_void,
    ) -> Self {
        MemoryMonitor { callback, user }
    }

    /// Asks the callback whether the build may hold `bytes` in total.
    pub fn allows(&self, bytes: usize) -> bool {
        // SAFETY: `new`'s contract.
        unsafe { (self.callback)(self.user, bytes) }
    }
}

/// Counts the bytes a build holds and refuses growth past a limit or when the allocator fails.
///
/// Guarantees: [`MemoryBudget::vec`] never aborts; it returns [`BuildError::MemoryLimit`] before
/// asking the allocator when the limit would be passed, and [`BuildError::OutOfMemory`] when the
/// allocator says no. With a [`MemoryMonitor`], every charge that passes the limit is put to the
/// monitor before the allocator is asked, and a refusal is [`BuildError::Cancelled`] (nothing taken).
/// `used` is the sum of the capacities (in bytes) handed out and not yet released.
#[derive(Clone, Copy, Debug, Default)]
pub struct MemoryBudget {
    limit: usize,
    used: usize,
    peak: usize,
    monitor: Option<MemoryMonitor>,
}

impl MemoryBudget {
    /// A budget with a limit in bytes; 0 means no limit.
    pub const fn new(limit: usize) -> Self {
        MemoryBudget {
            limit,
            used: 0,
            peak: 0,
            monitor: None,
        }
    }

    /// The same budget, with every later charge also put to `monitor` (None: no monitor).
    pub const fn with_monitor(mut self, monitor: Option<MemoryMonitor>) -> Self {
        self.monitor = monitor;
        self
    }

    /// Bytes currently held.
    pub fn used(&self) -> usize {
        self.used
    }

    /// The most bytes held at once.
    pub fn peak(&self) -> usize {
        self.peak
    }

    /// The limit in bytes (0 = none).
    pub fn limit(&self) -> usize {
        self.limit
    }

    /// Accounts for `bytes` more, or says why not: the limit first, then the monitor (told the total
    /// the build would hold), so a refused charge changes nothing.
    pub fn charge(&mut self, bytes: usize, what: &'static str) -> Result<(), BuildError> {
        let needed = self
            .used
            .checked_add(bytes)
            .ok_or(BuildError::OutOfMemory { what, bytes })?;
        if self.limit != 0 && needed > self.limit {
            return Err(BuildError::MemoryLimit {
                what,
                needed,
                limit: self.limit,
            });
        }
        if let Some(m) = &self.monitor {
            if !m.allows(needed) {
                return Err(BuildError::Cancelled { what, held: needed });
            }
        }
        self.used = needed;
        self.peak = self.peak.max(needed);
        Ok(())
    }

    /// Gives back `bytes` charged earlier.
    pub fn release(&mut self, bytes: usize) {
        self.used = self.used.saturating_sub(bytes);
    }

    /// An empty vector with room for exactly `len` elements, charged to the budget.
    pub fn vec<T>(&mut self, len: usize, what: &'static str) -> Result<Vec<T>, BuildError> {
        let mut v = Vec::new();
        self.reserve_to(&mut v, len, what)?;
        Ok(v)
    }

    /// Makes `v`'s capacity at least `cap` elements (exactly `cap` if it grows, as
    /// `Vec::try_reserve_exact`), keeping its contents: the growth is charged before the allocator
    /// is asked (fallibly; a refusal releases the charge), whatever the allocator rounds up is
    /// counted after, so that [`MemoryBudget::free`] balances, and new whole huge pages get the hint.
    pub fn reserve_to<T>(
        &mut self,
        v: &mut Vec<T>,
        cap: usize,
        what: &'static str,
    ) -> Result<(), BuildError> {
        let before = v.capacity();
        if cap <= before {
            return Ok(());
        }
        let size = core::mem::size_of::<T>();
        let bytes = (cap - before)
            .checked_mul(size)
            .ok_or(BuildError::OutOfMemory {
                what,
                bytes: usize::MAX,
            })?;
        self.charge(bytes, what)?;
        if v.try_reserve_exact(cap - v.len()).is_err() {
            self.release(bytes);
            return Err(BuildError::OutOfMemory { what, bytes });
        }
        hint_huge_pages(v);
        let extra = (v.capacity() - before).saturating_sub(cap - before) * size;
        self.used += extra;
        self.peak = self.peak.max(self.used);
        Ok(())
    }

    /// A vector of `len` copies of `value`, charged to the budget.
    pub fn filled<T: Copy>(
        &mut self,
        len: usize,
        value: T,
        what: &'static str,
    ) -> Result<Vec<T>, BuildError> {
        let mut v = self.vec(len, what)?;
        v.resize(len, value);
        Ok(v)
    }

    /// Appends `value` to a vector that grows as the build goes (doubling, at least 64 elements),
    /// charging each growth to the budget before asking the allocator. Inline, with the growth out
    /// of line: builders push one item at a time into vectors they usually reserved ahead, and the
    /// call per item cost the kd-tree build 5–7 % of its instructions.
    #[inline(always)]
    pub fn push<T>(
        &mut self,
        v: &mut Vec<T>,
        value: T,
        what: &'static str,
    ) -> Result<(), BuildError> {
        if v.len() == v.capacity() {
            self.grow_for_push(v, what)?;
        }
        // Never reallocates: the capacity is above the length here.
        v.push(value);
        Ok(())
    }

    /// Doubles `v`'s capacity (at least 64 elements) for [`MemoryBudget::push`], charged first.
    #[cold]
    #[inline(never)]
    fn grow_for_push<T>(&mut self, v: &mut Vec<T>, what: &'static str) -> Result<(), BuildError> {
        let cap =
            v.capacity()
                .checked_add(v.capacity().max(64))
                .ok_or(BuildError::OutOfMemory {
                    what,
                    bytes: usize::MAX,
                })?;
        self.reserve_to(v, cap, what)
    }

    /// An empty [`BigVec`] with room for exactly `len` elements, charged to the budget (its
    /// block starts on a huge page when it is large).
    pub fn big_vec<T: Copy>(
        &mut self,
        len: usize,
        what: &'static str,
    ) -> Result<BigVec<T>, BuildError> {
        let bytes = len
            .checked_mul(core::mem::size_of::<T>())
            .ok_or(BuildError::OutOfMemory {
                what,
                bytes: usize::MAX,
            })?;
        self.charge(bytes, what)?;
        BigVec::with_capacity(len).ok_or_else(|| {
            self.release(bytes);
            BuildError::OutOfMemory { what, bytes }
        })
    }

    /// A [`BigVec`] of `len` copies of `value`, charged to the budget.
    pub fn big_filled<T: Copy>(
        &mut self,
        len: usize,
        value: T,
        what: &'static str,
    ) -> Result<BigVec<T>, BuildError> {
        let mut v = self.big_vec(len, what)?;
        v.fill_to_capacity(value);
        Ok(v)
    }

    /// Makes `v`'s capacity at least `cap` elements (exactly `cap` if it grows), keeping its
    /// contents: a new block charged first, the elements copied, the old block released. Both
    /// blocks are held while the elements move, as a reallocation may hold them.
    pub fn reserve_big<T: Copy>(
        &mut self,
        v: &mut BigVec<T>,
        cap: usize,
        what: &'static str,
    ) -> Result<(), BuildError> {
        if cap <= v.capacity() {
            return Ok(());
        }
        let mut bigger = self.big_vec::<T>(cap, what)?;
        let copied = bigger.extend_within(v.iter().copied());
        debug_assert_eq!(copied, v.len());
        let old = core::mem::replace(v, bigger);
        self.free_big(old);
        Ok(())
    }

    /// Releases a [`BigVec`] charged with [`MemoryBudget::big_vec`] and drops it.
    pub fn free_big<T: Copy>(&mut self, v: BigVec<T>) {
        self.release(v.bytes());
    }

    /// Releases a temporary vector charged with [`MemoryBudget::vec`] and drops it.
    pub fn free<T>(&mut self, v: Vec<T>) {
        self.release(v.capacity() * core::mem::size_of::<T>());
    }
}

/// Asks the kernel to back the whole 2 MiB pages inside `v`'s new, untouched allocation with
/// transparent huge pages, if it holds any (see [`advise_huge_pages`]).
#[inline]
fn hint_huge_pages<T>(v: &mut Vec<T>) {
    let bytes = v.capacity().saturating_mul(core::mem::size_of::<T>());
    advise_huge_pages(v.as_mut_ptr() as usize, bytes);
}

/// Asks the kernel to back the whole 2 MiB pages inside the block of `bytes` at `start` (an
/// allocation the caller owns and has not touched yet) with transparent huge pages (Linux with
/// `std`; elsewhere nothing). A build writes each byte of its large arrays once, right after taking
/// them, so their first touch is much of a build's time: on the project's VMs a fresh 4 KiB page
/// costs about 2 µs (0.55–0.59 ns a byte, against 0.10–0.12 ns a byte with the hint;
/// docs/performance.md, stops 19 and 46). Embree gives its large blocks the same hint. Only
/// advice: a kernel that refuses it changes nothing.
#[inline]
pub(crate) fn advise_huge_pages(start: usize, bytes: usize) {
    #[cfg(all(feature = "std", target_os = "linux"))]
    {
        use crate::bigvec::HUGE_PAGE;
        if bytes >= HUGE_PAGE {
            let lo = start.saturating_add(HUGE_PAGE - 1) & !(HUGE_PAGE - 1);
            let hi = start.saturating_add(bytes) & !(HUGE_PAGE - 1);
            if hi > lo {
                // SAFETY: [lo, hi) lies inside the caller's allocation; MADV_HUGEPAGE changes only
                // how the kernel backs those pages, never their contents or their validity.
                unsafe {
                    libc::madvise(lo as *mut c_void, hi - lo, libc::MADV_HUGEPAGE);
                }
            }
        }
    }
    #[cfg(not(all(feature = "std", target_os = "linux")))]
    let _ = (start, bytes);
}

/// Bytes a vector holds (its capacity), for memory reports.
pub fn bytes_of<T>(v: &Vec<T>) -> usize {
    v.capacity() * core::mem::size_of::<T>()
}

/// Moves `value` into a new box, or gives `None` when the allocator refuses (instead of aborting).
pub fn try_box<T>(value: T) -> Option<alloc::boxed::Box<T>> {
    let layout = core::alloc::Layout::new::<T>();
    if layout.size() == 0 {
        return Some(alloc::boxed::Box::new(value));
    }
    // SAFETY: the layout has a non-zero size; on success the memory is initialised with `value` before
    // `Box::from_raw` takes ownership, and it was allocated by the global allocator with T's layout.
    unsafe {
        let p = alloc::alloc::alloc(layout) as *mut T;
        if p.is_null() {
            return None;
        }
        p.write(value);
        Some(alloc::boxed::Box::from_raw(p))
    }
}
