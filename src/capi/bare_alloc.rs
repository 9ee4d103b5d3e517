//! The global allocator of a `bare-rt` build: the program's hooks once `rq_set_allocator` installed
//! them, C `malloc`/`posix_memalign`/`free` otherwise.
//!
//! A small state machine decides which, once and for all: the first allocation without hooks fixes
//! "C heap" and the hooks can no longer be installed, so no block ever crosses from one heap to the
//! other's `free`.

use core::alloc::{GlobalAlloc, Layout};
use core::cell::UnsafeCell;
use core::ffi::{c_int, c_void};
use core::sync::atomic::{AtomicU8, Ordering};

// The C library's heap (the module is `cbindgen:ignore`d in mod.rs, so these stay out of rayq.h).
extern "C" {
    fn malloc(size: usize) -> *mut c_void;
    fn free(ptr: *mut c_void);
    fn posix_memalign(out: *mut *mut c_void, align: usize, size: usize) -> c_int;
}

/// The program's allocation callbacks, as `rq_set_allocator` validated them.
pub(super) struct Hooks {
    pub(super) alloc: unsafe extern "C" fn(*mut c_void, usize, usize) -> *mut c_void,
    pub(super) free: unsafe extern "C" fn(*mut c_void, *mut c_void, usize, usize),
    pub(super) user: *mut c_void,
}

/// Nothing allocated yet, no hooks.
const UNTOUCHED: u8 = 0;
/// The C heap serves every allocation, for good.
const C_HEAP: u8 = 1;
/// `install` is writing the hooks.
const INSTALLING: u8 = 2;
/// The hooks serve every allocation, for good.
const HOOKED: u8 = 3;

static STATE: AtomicU8 = AtomicU8::new(UNTOUCHED);

struct HookCell(UnsafeCell<Option<Hooks>>);

// SAFETY: written once, by the one thread that moved STATE to INSTALLING, and read only after
// STATE is HOOKED (release/acquire), never written again.
unsafe impl Sync for HookCell {}

static HOOKS: HookCell = HookCell(UnsafeCell::new(None));

/// Installs `hooks` if nothing has been allocated and no hooks were installed; `Err` otherwise.
pub(super) fn install(hooks: Hooks) -> Result<(), ()> {
    STATE
        .compare_exchange(UNTOUCHED, INSTALLING, Ordering::AcqRel, Ordering::Acquire)
        .map_err(|_| ())?;
    // SAFETY: the compare-exchange made this thread the only writer, and no reader looks before
    // STATE becomes HOOKED.
    unsafe { *HOOKS.0.get() = Some(hooks) };
    STATE.store(HOOKED, Ordering::Release);
    Ok(())
}

/// The hooks if installed; otherwise fixes the C heap for good and gives None.
fn hooks() -> Option<&'static Hooks> {
    loop {
        match STATE.load(Ordering::Acquire) {
            // SAFETY: HOOKED is stored after the one write, with release ordering.
            HOOKED => return unsafe { (*HOOKS.0.get()).as_ref() },
            C_HEAP => return None,
            UNTOUCHED => {
                if STATE
                    .compare_exchange(UNTOUCHED, C_HEAP, Ordering::AcqRel, Ordering::Acquire)
                    .is_ok()
                {
                    return None;
                }
            }
            // Another thread is inside rq_set_allocator (against its contract); wait for it.
            _ => core::hint::spin_loop(),
        }
    }
}

/// `malloc` guarantees at least pointer alignment on every C library; larger alignments go to
/// `posix_memalign`.
const MALLOC_ALIGN: usize = core::mem::size_of::<usize>();

struct BareAllocator;

// SAFETY: every block comes from the heap (hooks or C) that also frees it, with the layout it was
// asked for; misaligned blocks from a hook are given back and reported as failures.
unsafe impl GlobalAlloc for BareAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let (size, align) = (layout.size(), layout.align());
        if let Some(h) = hooks() {
            // SAFETY: rq_set_allocator's contract.
            let p = unsafe { (h.alloc)(h.user, size, align) };
            if !p.is_null() && (p as usize) % align != 0 {
                // A hook that breaks its alignment promise would make references UB: refuse it.
                // SAFETY: the block came from this hook with this size and alignment.
                unsafe { (h.free)(h.user, p, size, align) };
                return core::ptr::null_mut();
            }
            return p.cast();
        }
        if align <= MALLOC_ALIGN {
            // SAFETY: malloc accepts any size.
            return unsafe { malloc(size) }.cast();
        }
        let mut p = core::ptr::null_mut();
        // SAFETY: align is a power of two and a multiple of the pointer size (align > MALLOC_ALIGN).
        if unsafe { posix_memalign(&mut p, align, size) } != 0 {
            return core::ptr::null_mut();
        }
        p.cast()
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        match hooks() {
            // SAFETY: the block came from these hooks (the state never changes once it is HOOKED).
            Some(h) => unsafe { (h.free)(h.user, ptr.cast(), layout.size(), layout.align()) },
            // SAFETY: the block came from malloc or posix_memalign.
            None => unsafe { free(ptr.cast()) },
        }
    }
}

#[global_allocator]
static GLOBAL: BareAllocator = BareAllocator;
