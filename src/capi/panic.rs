//! `rq_set_panic_hook` and, with feature `bare-rt`, the panic handler that calls it and aborts.
//! rayq is written not to panic on any input; in a `bare-rt` build, where no panic can be caught,
//! this is the last line of defence: the program hears why (to log it) and the process stops.

use core::ffi::{c_char, c_void};

use super::boundary;
use super::types::rq_status;

/// Panic hook: told a NUL-terminated message (valid during the call only). It may log; it must not
/// call rayq. When it returns, the library calls `abort()`.
pub type rq_panic_hook_fn = Option<unsafe extern "C" fn(user: *mut c_void, message: *const c_char)>;

/// Sets (or, with NULL, clears) the hook a `bare-rt` build calls if rayq ever panics, just before it
/// aborts. Call it at start-up. Builds without `bare-rt` return `RQ_STATUS_UNSUPPORTED` and keep
/// nothing: there a panic is caught at the boundary and the call returns its failure value
/// (`RQ_STATUS_PANIC`, `false`, NULL).
///
/// # Safety
/// `hook`, when not NULL, is callable with `user` from any thread for the rest of the program.
#[no_mangle]
pub unsafe extern "C" fn rq_set_panic_hook(hook: rq_panic_hook_fn, user: *mut c_void) -> rq_status {
    boundary(|| {
        #[cfg(feature = "bare-rt")]
        {
            handler::set(hook, user);
            rq_status::RQ_STATUS_OK
        }
        #[cfg(not(feature = "bare-rt"))]
        {
            let _ = (hook, user);
            rq_status::RQ_STATUS_UNSUPPORTED
        }
    })
}

/// The panic handler and the hook it calls.
///
/// cbindgen:ignore
#[cfg(feature = "bare-rt")]
mod handler {
    use core::cell::UnsafeCell;
    use core::ffi::c_void;
    use core::sync::atomic::{AtomicBool, Ordering};

    use super::super::Message;
    use super::rq_panic_hook_fn;

    // From the C library; this module is `cbindgen:ignore`d, so it stays out of rayq.h.
    extern "C" {
        fn abort() -> !;
    }

    /// The hook and its pointer, changed together under a spin lock.
    struct Slot {
        locked: AtomicBool,
        hook: UnsafeCell<(rq_panic_hook_fn, *mut c_void)>,
    }

    // SAFETY: `hook` is only touched by the thread holding `locked`.
    unsafe impl Sync for Slot {}

    static SLOT: Slot = Slot {
        locked: AtomicBool::new(false),
        hook: UnsafeCell::new((None, core::ptr::null_mut())),
    };

    fn with_slot<R>(f: impl FnOnce(&mut (rq_panic_hook_fn, *mut c_void)) -> R) -> R {
        while SLOT
            .locked
            .compare_exchange_weak(false, true, Ordering::Acquire, Ordering::Relaxed)
            .is_err()
        {
            core::hint::spin_loop();
        }
        // SAFETY: this thread holds the lock.
        let r = f(unsafe { &mut *SLOT.hook.get() });
        SLOT.locked.store(false, Ordering::Release);
        r
    }

    pub(super) fn set(hook: rq_panic_hook_fn, user: *mut c_void) {
        with_slot(|slot| *slot = (hook, user));
    }

    /// Set by the first panic: a second one (another thread, or a panic while reporting) aborts at
    /// once instead of calling the hook again.
    static PANICKING: AtomicBool = AtomicBool::new(false);

    #[panic_handler]
    fn on_panic(info: &core::panic::PanicInfo<'_>) -> ! {
        if !PANICKING.swap(true, Ordering::AcqRel) {
            let (hook, user) = with_slot(|slot| *slot);
            if let Some(hook) = hook {
                let message = Message::new(format_args!("rayq: {info}"));
                // SAFETY: rq_set_panic_hook's contract.
                unsafe { hook(user, message.as_ptr()) };
            }
        }
        // SAFETY: abort takes no arguments and never returns.
        unsafe { abort() }
    }
}
