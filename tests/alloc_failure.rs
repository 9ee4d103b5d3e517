//! Allocation failure and memory limits: a counting global allocator that can be armed to refuse
//! the k-th allocation on the current thread. For every k through a full `Scene::build` of a small
//! scene (grid, kd-tree, Auto with a known and an unknown budget) the build returns `OutOfMemory`
//! (never aborts) and every byte allocated during it has been given back; a memory-limit sweep
//! from tiny to large either fits (`memory_bytes <= limit`) or returns `MemoryLimit`.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use rayq::select::clock::Clock;
use rayq::select::sample::RaySource;
use rayq::{procedural, BuildError, BuildOptions, Calibration, Scene, Structure};

/// Passes every request to the system allocator, except that on a thread where it is armed it
/// counts allocations and refuses the one numbered `fail_at`, and it keeps the thread's net live
/// bytes (allocated minus freed). Per thread, so the test harness's other threads are untouched.
struct Failing;

thread_local! {
    /// `Some(k)`: refuse the allocation when `COUNT` reaches k. `None`: not armed.
    static FAIL_AT: Cell<Option<u64>> = const { Cell::new(None) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
    static LIVE: Cell<i64> = const { Cell::new(0) };
    static REFUSED: Cell<bool> = const { Cell::new(false) };
}

impl Failing {
    /// True when this allocation is to be refused (and counts it).
    fn refuse() -> bool {
        let Some(k) = FAIL_AT.with(Cell::get) else {
            return false;
        };
        let n = COUNT.with(|c| {
            let n = c.get();
            c.set(n + 1);
            n
        });
        let refuse = n == k;
        if refuse {
            REFUSED.with(|r| r.set(true));
        }
        refuse
    }

    fn add(bytes: usize, sign: i64) {
        LIVE.with(|l| l.set(l.get() + sign * bytes as i64));
    }
}

// SAFETY: every call is forwarded to `System` unchanged or refused with a null pointer, which the
// GlobalAlloc contract allows.
unsafe impl GlobalAlloc for Failing {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if Failing::refuse() {
            return std::ptr::null_mut();
        }
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            Failing::add(layout.size(), 1);
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if Failing::refuse() {
            return std::ptr::null_mut();
        }
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            Failing::add(layout.size(), 1);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        Failing::add(layout.size(), -1);
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if Failing::refuse() {
            return std::ptr::null_mut();
        }
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            Failing::add(layout.size(), -1);
            Failing::add(new_size, 1);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Failing = Failing;

/// Runs `f` with the allocator armed to refuse allocation `k` on this thread. Returns `f`'s result
/// (already dropped into a summary), whether the refusal happened, how many allocations `f` made,
/// and its net live bytes afterwards.
fn armed<T>(
    k: Option<u64>,
    f: impl FnOnce() -> T,
    summary: impl FnOnce(&T) -> String,
) -> (String, bool, u64, i64) {
    COUNT.with(|c| c.set(0));
    LIVE.with(|l| l.set(0));
    REFUSED.with(|r| r.set(false));
    // Count from here, but never refuse when k is None: u64::MAX is never reached.
    FAIL_AT.with(|a| a.set(Some(k.unwrap_or(u64::MAX))));
    let out = f();
    FAIL_AT.with(|a| a.set(None));
    let text = summary(&out);
    drop(out);
    // `text` was allocated while armed and is still alive: take it out of the balance.
    let live = LIVE.with(Cell::get) - text.capacity() as i64;
    (text, REFUSED.with(Cell::get), COUNT.with(Cell::get), live)
}

/// The options of a build under test. The clock, when there is one, advances by the same step at
/// every reading, so that the timed check's verdict (a tie, which drops the kd-tree), and with it
/// the allocations, repeat exactly.
fn options(
    structure: Structure,
    expected_rays: u64,
    memory_limit: usize,
    timed: bool,
) -> BuildOptions {
    BuildOptions {
        structure,
        expected_rays,
        memory_limit,
        clock: timed.then_some(STEADY_CLOCK),
        ..BuildOptions::DEFAULT
    }
}

extern "C" fn steady(_user: *mut core::ffi::c_void) -> u64 {
    // Per thread, so that tests running at once do not step each other's clock.
    thread_local! {
        static NOW: Cell<u64> = const { Cell::new(0) };
    }
    NOW.with(|n| {
        n.set(n.get() + 1000);
        n.get()
    })
}

// SAFETY: `steady` ignores its pointer, is callable from any thread (each has its own count) and
// cannot unwind.
const STEADY_CLOCK: Clock = unsafe { Clock::new(steady, core::ptr::null_mut()) };

/// Estimates that always build the kd-tree (the grid 1 µs a ray, the kd-tree 0.1 µs, its build
/// 10 ns per N log2 N), for the timed check's build: the built-in calibration may not build one.
fn favouring_the_kd_tree() -> Calibration {
    Calibration::new(0, [10.0, 1000.0, 10.0, 1.0, 10.0, 0.0, 100.0, 0.0, 0.0]).unwrap()
}

/// The builds under test: every structure choice, and Auto both ways (a large known budget makes
/// it build the grid, sample, build the kd-tree and check it: by counted work on its own samples,
/// or, `true`, timed on the caller's samples by a steady clock, whose tie drops the kd-tree and
/// builds the grid again).
const BUILDS: [(&str, Structure, u64, bool); 5] = [
    ("grid", Structure::Grid, 0, false),
    ("kd-tree", Structure::KdTree, 0, false),
    ("auto, unknown budget", Structure::Auto, 0, false),
    ("auto, 1e9 rays", Structure::Auto, 1_000_000_000, false),
    (
        "auto, 1e9 rays, timed",
        Structure::Auto,
        1_000_000_000,
        true,
    ),
];

#[test]
fn every_refused_allocation_is_out_of_memory_and_leaks_nothing() {
    // Small but with every path: a closed sphere (kd splits, grid cells) plus slivers.
    let mut data = procedural::closed_sphere(4);
    data.append(&procedural::random_slivers(40, 3));
    let samples = common::test_rays(&common::mesh_of(&data), 8, 0, 4);
    let favouring = favouring_the_kd_tree();
    for (label, structure, rays, timed) in BUILDS {
        let opts = options(structure, rays, 0, timed);
        let given: Option<&dyn RaySource> = timed.then_some(&samples);
        let calibration = if timed {
            &favouring
        } else {
            Calibration::builtin()
        };
        let build = || Scene::build_with_samples(&data.as_source(), &opts, calibration, given);
        let (ok, _, total, live) = armed(None, build, |r| format!("{:?}", r.is_ok()));
        assert_eq!(ok, "true", "{label}: the unarmed build must succeed");
        if timed {
            // The path under test: a kd-tree built, timed, and dropped for the grid again.
            let r = build().unwrap().report();
            assert_eq!(r.outcome, rayq::scene::Outcome::GridFasterPerRay, "{label}");
            assert!(r.break_even_rays < rays as f64, "{label}: {r:?}");
        }
        assert_eq!(
            live, 0,
            "{label}: a built and dropped scene left {live} bytes alive"
        );
        assert!(
            total >= 3,
            "{label}: only {total} allocations; the sweep would prove nothing"
        );
        for k in 0..total {
            let (result, refused, _, live) = armed(Some(k), build, |r| match r {
                Err(BuildError::OutOfMemory { .. }) => "oom".to_string(),
                Err(e) => format!("other error {e:?}"),
                Ok(_) => "ok".to_string(),
            });
            assert!(refused, "{label}: allocation {k} of {total} never happened");
            assert_eq!(result, "oom", "{label}: refusing allocation {k} of {total}");
            assert_eq!(
                live, 0,
                "{label}: {live} bytes still alive after refusing allocation {k}"
            );
        }
    }
}

#[test]
fn memory_limit_sweep_fits_or_refuses() {
    let data = procedural::by_name("stadium", 2000).unwrap();
    let samples = common::test_rays(&common::mesh_of(&data), 8, 0, 4);
    let favouring = favouring_the_kd_tree();
    for (label, structure, rays, timed) in BUILDS {
        let given: Option<&dyn RaySource> = timed.then_some(&samples);
        let calibration = if timed {
            &favouring
        } else {
            Calibration::builtin()
        };
        let mut limit = 1usize;
        let mut fitted = false;
        while limit < 64 << 20 {
            match Scene::build_with_samples(
                &data.as_source(),
                &options(structure, rays, limit, timed),
                calibration,
                given,
            ) {
                Ok(scene) => {
                    let bytes = scene.report().memory_bytes;
                    assert!(
                        bytes <= limit,
                        "{label}: {bytes} bytes held under a {limit}-byte limit"
                    );
                    fitted = true;
                }
                Err(BuildError::MemoryLimit { .. }) => {
                    assert!(
                        !fitted,
                        "{label}: refused at {limit} bytes after fitting in less"
                    );
                }
                Err(e) => panic!("{label}: limit {limit}: {e:?}"),
            }
            limit = limit * 5 / 4 + 1;
        }
        assert!(fitted, "{label}: never fitted under 64 MiB");
    }
}
