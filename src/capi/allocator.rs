//! `rq_set_allocator`: route every allocation of a `bare-rt` build through the program's callbacks.
//! Builds without `bare-rt` use the Rust global allocator the program links (std's, or a `no_std`
//! program's own), which rayq does not own, so they refuse the hooks.

use core::ffi::c_void;

use super::boundary;
use super::types::rq_status;

/// Allocation callback: `size` bytes (never 0) aligned to `align` (a power of two), or NULL when
/// there is no memory. A NULL return is never fatal: the call that needed the memory fails with
/// `RQ_STATUS_OUT_OF_MEMORY` and frees what it took.
pub type rq_alloc_fn =
    Option<unsafe extern "C" fn(user: *mut c_void, size: usize, align: usize) -> *mut c_void>;

/// Free callback: gives back a block from `alloc` with the same `size` and `align` it was asked for.
pub type rq_free_fn =
    Option<unsafe extern "C" fn(user: *mut c_void, ptr: *mut c_void, size: usize, align: usize)>;

/// The program's allocator for a `bare-rt` build. The callbacks may be called from any thread that
/// calls rayq, and must be thread-safe if rayq is used from several threads.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rq_allocator {
    /// `sizeof(rq_allocator)` as the caller knows it; must cover `free`.
    pub struct_size: u32,
    /// Passed to both callbacks.
    pub user: *mut c_void,
    /// Allocates; must not be NULL.
    pub alloc: rq_alloc_fn,
    /// Frees; must not be NULL.
    pub free: rq_free_fn,
}

/// Installs the program's allocator. Only in `bare-rt` builds, only once, and only before any other
/// rayq call has allocated (memory from the default `malloc` must never reach the program's `free`):
/// a second call, or a call after an allocation, is `RQ_STATUS_INVALID_OPERATION`. NULL `allocator`,
/// `alloc` or `free` is `RQ_STATUS_NULL_ARGUMENT`; a `struct_size` that does not cover `free` is
/// `RQ_STATUS_INVALID_ARGUMENT` (neither counts as the one call). Every other build returns
/// `RQ_STATUS_UNSUPPORTED` and changes nothing: there the program owns the global allocator.
///
/// # Safety
/// `allocator` is NULL or readable for its `struct_size`; the callbacks stay callable with `user`
/// for the rest of the program, and never unwind.
#[no_mangle]
pub unsafe extern "C" fn rq_set_allocator(allocator: *const rq_allocator) -> rq_status {
    boundary(|| {
        #[cfg(feature = "bare-rt")]
        {
            // SAFETY: the function contract.
            unsafe { install(allocator) }
        }
        #[cfg(not(feature = "bare-rt"))]
        {
            let _ = allocator;
            rq_status::RQ_STATUS_UNSUPPORTED
        }
    })
}

/// # Safety
/// As [`rq_set_allocator`].
#[cfg(feature = "bare-rt")]
unsafe fn install(allocator: *const rq_allocator) -> rq_status {
    use core::mem::{offset_of, size_of};
    if allocator.is_null() {
        return rq_status::RQ_STATUS_NULL_ARGUMENT;
    }
    // SAFETY: struct_size is the first field; the caller promises it is readable.
    let size = unsafe { core::ptr::read_unaligned(allocator as *const u32) } as usize;
    if size < offset_of!(rq_allocator, free) + size_of::<rq_free_fn>() {
        return rq_status::RQ_STATUS_INVALID_ARGUMENT;
    }
    // SAFETY: struct_size covers the whole struct as this library knows it.
    let a = unsafe { core::ptr::read_unaligned(allocator) };
    let (Some(alloc), Some(free)) = (a.alloc, a.free) else {
        return rq_status::RQ_STATUS_NULL_ARGUMENT;
    };
    let hooks = super::bare_alloc::Hooks {
        alloc,
        free,
        user: a.user,
    };
    match super::bare_alloc::install(hooks) {
        Ok(()) => rq_status::RQ_STATUS_OK,
        Err(()) => rq_status::RQ_STATUS_INVALID_OPERATION,
    }
}
