//! The clock the selector may read: with one, the check after a kd-tree build times the sample rays
//! on both structures instead of pricing their counted work (docs/design.md, "The check after the
//! kd-tree is built"). The library needs no clock; `std` builds bring their own.

use core::ffi::c_void;

/// A clock in nanoseconds that never goes back, read through a C-callable function and the pointer
/// it is given. Only differences of two readings on one thread are used, so its epoch is free.
///
/// Guarantees: [`Clock::now_ns`] calls the function exactly once per reading, with the pointer
/// given to [`Clock::new`], on the calling thread (a scene reads it on the thread that builds or
/// updates it).
#[derive(Clone, Copy, Debug)]
pub struct Clock {
    callback: unsafe extern "C" fn(user: *mut c_void) -> u64,
    user: *mut c_void,
}

// SAFETY: the pointer is only handed back to the caller's function, and `Clock::new`'s contract
// makes the caller answer for calling it from any thread, at once, while a copy exists.
unsafe impl Send for Clock {}
// SAFETY: as for Send; a shared Clock is only ever read.
unsafe impl Sync for Clock {}

impl Clock {
    /// A clock that reads `callback(user)`.
    ///
    /// # Safety
    /// `callback` must be safe to call with `user` from any thread, possibly from several at once
    /// (scenes built on different threads may share a clock), for as long as this clock or any
    /// copy of it exists, and must not unwind.
    pub const unsafe fn new(
        callback: unsafe extern "C" fn(user: *mut c_void) -> u64,
        user: *mut c_void,
    ) -> Self {
        Clock { callback, user }
    }

    /// The time now, in nanoseconds.
    #[inline]
    pub fn now_ns(&self) -> u64 {
        // SAFETY: `new`'s contract.
        unsafe { (self.callback)(self.user) }
    }

    /// Nanoseconds that `f` took by this clock (0 if the clock went back), and its result.
    #[inline]
    pub fn time<T>(&self, f: impl FnOnce() -> T) -> (u64, T) {
        let start = self.now_ns();
        let r = f();
        (self.now_ns().saturating_sub(start), r)
    }

    /// The clock of `std` builds: this thread's CPU time on Linux (so that time a shared machine
    /// gives to other threads or guests does not count), monotonic wall time elsewhere.
    #[cfg(feature = "std")]
    pub const THREAD: Clock = Clock {
        callback: thread_clock,
        user: core::ptr::null_mut(),
    };

    /// The clock a scene uses unless told otherwise: [`Clock::THREAD`] in `std` builds, none
    /// without `std` (the check then prices counted work). Made from [`DEFAULT_CALLBACK`].
    pub const DEFAULT: Option<Clock> = match DEFAULT_CALLBACK {
        Some(callback) => Some(Clock {
            callback,
            user: core::ptr::null_mut(),
        }),
        None => None,
    };
}

/// The function of [`Clock::DEFAULT`] (its pointer is null): [`Clock::THREAD`]'s in `std` builds,
/// none without; what the C API's `rq_build_options_init` sets.
#[cfg(feature = "std")]
pub const DEFAULT_CALLBACK: Option<unsafe extern "C" fn(user: *mut c_void) -> u64> =
    Some(thread_clock);
/// The function of [`Clock::DEFAULT`] (its pointer is null): [`Clock::THREAD`]'s in `std` builds,
/// none without; what the C API's `rq_build_options_init` sets.
#[cfg(not(feature = "std"))]
pub const DEFAULT_CALLBACK: Option<unsafe extern "C" fn(user: *mut c_void) -> u64> = None;

/// [`Clock::THREAD`]'s function (C-callable, so that the C API can hand it out as the default).
#[cfg(feature = "std")]
pub extern "C" fn thread_clock(_user: *mut c_void) -> u64 {
    thread_nanos()
}

/// This thread's CPU time in nanoseconds (`CLOCK_THREAD_CPUTIME_ID`), or monotonic time since the
/// first reading where that clock is missing.
#[cfg(feature = "std")]
pub fn thread_nanos() -> u64 {
    thread_cpu_nanos().unwrap_or_else(|| {
        static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
        let elapsed = START.get_or_init(std::time::Instant::now).elapsed();
        u64::try_from(elapsed.as_nanos()).unwrap_or(u64::MAX)
    })
}

#[cfg(all(feature = "std", target_os = "linux"))]
fn thread_cpu_nanos() -> Option<u64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec to the pointer it is given, which is valid.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0;
    let secs = u64::try_from(ts.tv_sec).ok()?;
    let nanos = u64::try_from(ts.tv_nsec).ok()?;
    ok.then(|| secs.saturating_mul(1_000_000_000).saturating_add(nanos))
}

#[cfg(all(feature = "std", not(target_os = "linux")))]
fn thread_cpu_nanos() -> Option<u64> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    unsafe extern "C" fn counter(user: *mut c_void) -> u64 {
        // SAFETY: the tests pass a pointer to a live u64 that only this thread touches.
        let n = unsafe { &mut *user.cast::<u64>() };
        *n += 10;
        *n
    }

    /// The callback is read once per reading with the caller's pointer; `time` is the difference
    /// of the two readings around its closure.
    #[test]
    fn a_clock_reads_its_callback() {
        let mut state = 5u64;
        // SAFETY: `counter` reads and writes `state`, which outlives the clock, on this thread.
        let clock = unsafe { Clock::new(counter, (&mut state as *mut u64).cast()) };
        assert_eq!(clock.now_ns(), 15);
        let (ns, v) = clock.time(|| 7);
        assert_eq!((ns, v), (10, 7));
        assert_eq!(state, 35);
    }

    #[cfg(feature = "std")]
    #[test]
    fn the_thread_clock_does_not_go_back() {
        let a = Clock::THREAD.now_ns();
        let mut x = 0u64;
        for i in 0..100_000u64 {
            x = x.wrapping_mul(31).wrapping_add(core::hint::black_box(i));
        }
        core::hint::black_box(x);
        assert!(Clock::THREAD.now_ns() >= a);
    }
}
