//! Scene functions of the C ABI.

use core::ffi::c_void;
use core::mem::{offset_of, size_of};
use core::ptr;

use glam::Vec3;

use super::types::*;
use super::{boundary, Message};
use crate::accel::kdtree::KdTreeParams;
use crate::budget::{try_box, MemoryMonitor};
use crate::error::{BuildError, MeshError};
use crate::mesh::MeshSource;
use crate::ray::{Hit, Ray};
use crate::scene::{BudgetKind, BuildOptions, Outcome, Scene, Structure};
use crate::select::calibration::Calibration;
use crate::select::clock::Clock;
use crate::select::sample::RaySource;

/// Fills the first `size` bytes of `opts` (`sizeof(rq_build_options)` as the caller's header
/// declares it) with the defaults: AUTO, unknown budget, library-made sample rays, no memory limit,
/// no error callback, no memory monitor, the library's clock (none in a build without `std`);
/// `struct_size` says how many bytes were written (at most the library's own struct), so a program
/// built against an older, shorter struct has nothing past its end written. The header's
/// `rq_build_options_init(opts)` calls this with `sizeof(rq_build_options)`. Does nothing when
/// `opts` is NULL or `size` is below 4.
///
/// # Safety
/// `opts` is NULL or points to `size` writable bytes.
#[no_mangle]
pub unsafe extern "C" fn rq_build_options_init_sized(opts: *mut rq_build_options, size: usize) {
    boundary(|| {
        // SAFETY: the caller promises `size` writable bytes at `opts` (or NULL).
        unsafe {
            super::init_prefix(opts, size, |struct_size| rq_build_options {
                struct_size,
                structure: rq_structure::RQ_STRUCTURE_AUTO,
                expected_rays: 0,
                sample_rays: ptr::null(),
                sample_ray_count: 0,
                memory_limit: 0,
                on_error: None,
                user: ptr::null_mut(),
                memory_monitor: None,
                memory_monitor_user: ptr::null_mut(),
                budget_kind: rq_budget_kind::RQ_BUDGET_EXPECTED,
                kd_quality: rq_kd_quality::RQ_KD_QUALITY_DEFAULT,
                clock: crate::select::clock::DEFAULT_CALLBACK,
                clock_user: ptr::null_mut(),
            })
        }
    })
}

/// The bytes of `rq_build_options`' first layout (up to `user`).
const BUILD_OPTIONS_FIRST: usize = super::first_layout!(rq_build_options, user, *mut c_void);

/// The first version's entry, for programs compiled before the header made `rq_build_options_init`
/// a macro over [`rq_build_options_init_sized`]: their struct may be that first layout, so only its
/// bytes are written (the defaults, `struct_size` their count), whatever fields were appended since.
/// A program compiled with this header reaches the sized entry instead.
///
/// # Safety
/// `opts` is NULL or points to writable memory of the first layout's size.
#[no_mangle]
pub unsafe extern "C" fn rq_build_options_init(opts: *mut rq_build_options) {
    // SAFETY: as the caller promises.
    unsafe { rq_build_options_init_sized(opts, BUILD_OPTIONS_FIRST) }
}

/// Options as read from C, with the defaults for fields the caller's `struct_size` does not cover.
struct Options {
    structure: Structure,
    expected_rays: u64,
    budget_kind: BudgetKind,
    kd_quality: rq_kd_quality,
    memory_limit: usize,
    sample_rays: *const rq_ray,
    sample_ray_count: usize,
    on_error: rq_error_fn,
    user: *mut core::ffi::c_void,
    memory_monitor: Option<MemoryMonitor>,
    clock: Option<Clock>,
}

/// Reads field `$field` of an `rq_build_options` at `$p` when `$size` covers it, else `$default`.
macro_rules! read_covered {
    ($p:expr, $size:expr, $field:ident, $ty:ty, $default:expr) => {
        read_field!(rq_build_options, $p, $size, $field, $ty, $default)
    };
}

/// Reads the options, never materialising an out-of-range enum.
///
/// # Safety
/// `p` is NULL or points to readable memory of at least `struct_size` bytes (capped at our size).
unsafe fn read_options(
    p: *const rq_build_options,
) -> Result<Options, (rq_status, &'static str, Options)> {
    let mut o = Options {
        structure: Structure::Auto,
        expected_rays: 0,
        budget_kind: BudgetKind::Expected,
        kd_quality: rq_kd_quality::RQ_KD_QUALITY_DEFAULT,
        memory_limit: 0,
        sample_rays: ptr::null(),
        sample_ray_count: 0,
        on_error: None,
        user: ptr::null_mut(),
        memory_monitor: None,
        clock: Clock::DEFAULT,
    };
    if p.is_null() {
        return Ok(o);
    }
    // SAFETY: struct_size is the first field and always present.
    let size = unsafe { ptr::read_unaligned(p as *const u32) } as usize;
    o.on_error = read_covered!(p, size, on_error, rq_error_fn, None);
    o.user = read_covered!(p, size, user, *mut core::ffi::c_void, ptr::null_mut());
    if size < offset_of!(rq_build_options, structure) + size_of::<u32>() {
        return Err((
            rq_status::RQ_STATUS_INVALID_ARGUMENT,
            "rq_build_options.struct_size is too small: call rq_build_options_init",
            o,
        ));
    }
    let structure: u32 = read_covered!(p, size, structure, u32, 0);
    o.structure = match structure {
        0 => Structure::Auto,
        1 => Structure::Grid,
        2 => Structure::KdTree,
        _ => {
            return Err((
                rq_status::RQ_STATUS_INVALID_ARGUMENT,
                "rq_build_options.structure is not an rq_structure value",
                o,
            ))
        }
    };
    o.expected_rays = read_covered!(p, size, expected_rays, u64, 0);
    let budget_kind: u32 = read_covered!(p, size, budget_kind, u32, 0);
    o.budget_kind = match budget_kind {
        0 => BudgetKind::Expected,
        1 => BudgetKind::AtMost,
        _ => {
            return Err((
                rq_status::RQ_STATUS_INVALID_ARGUMENT,
                "rq_build_options.budget_kind is not an rq_budget_kind value",
                o,
            ))
        }
    };
    let kd_quality: u32 = read_covered!(p, size, kd_quality, u32, 0);
    o.kd_quality = match kd_quality {
        0 => rq_kd_quality::RQ_KD_QUALITY_DEFAULT,
        1 => rq_kd_quality::RQ_KD_QUALITY_FAST,
        2 => rq_kd_quality::RQ_KD_QUALITY_HIGH,
        _ => {
            return Err((
                rq_status::RQ_STATUS_INVALID_ARGUMENT,
                "rq_build_options.kd_quality is not an rq_kd_quality value",
                o,
            ))
        }
    };
    o.memory_limit = read_covered!(p, size, memory_limit, usize, 0);
    o.sample_rays = read_covered!(p, size, sample_rays, *const rq_ray, ptr::null());
    o.sample_ray_count = read_covered!(p, size, sample_ray_count, usize, 0);
    let monitor = read_covered!(p, size, memory_monitor, rq_memory_monitor_fn, None);
    let monitor_user = read_covered!(
        p,
        size,
        memory_monitor_user,
        *mut core::ffi::c_void,
        ptr::null_mut()
    );
    // SAFETY: rq_scene_build's contract: the callback is callable with its user pointer for as long
    // as the scene lives, on the threads that build or update it.
    o.memory_monitor = monitor.map(|f| unsafe { MemoryMonitor::new(f, monitor_user) });
    // A caller built against a header without `clock` gets none: the library behaves for it as it
    // did (the check priced, deterministic; no re-check of a kd-tree in `rq_scene_update`).
    let clock = read_covered!(p, size, clock, rq_clock_fn, None);
    let clock_user = read_covered!(p, size, clock_user, *mut core::ffi::c_void, ptr::null_mut());
    // SAFETY: rq_scene_build's contract: the clock is callable with its user pointer for as long as
    // the scene lives, on the threads that build or update it.
    o.clock = clock.map(|f| unsafe { Clock::new(f, clock_user) });
    if o.sample_rays.is_null() && o.sample_ray_count != 0 {
        return Err((
            rq_status::RQ_STATUS_NULL_ARGUMENT,
            "rq_build_options.sample_rays is NULL but sample_ray_count is not 0",
            o,
        ));
    }
    Ok(o)
}

/// The caller's sample rays (`rq_build_options.sample_rays`), read one at a time, unaligned.
struct CallerRays {
    rays: *const rq_ray,
    count: usize,
}

impl RaySource for CallerRays {
    fn ray_count(&self) -> usize {
        self.count
    }
    fn ray(&self, i: usize) -> Ray {
        // SAFETY: i < count and the caller promised `count` readable rays (rq_scene_build's contract).
        to_ray(&unsafe { ptr::read_unaligned(self.rays.add(i)) })
    }
}

/// The caller's strided arrays, checked for NULL and address overflow before the first read.
pub(super) struct RawMesh {
    vertices: *const u8,
    vertex_count: usize,
    stride: usize,
    indices: *const u8,
    triangle_count: usize,
}

impl RawMesh {
    /// # Safety
    /// The descriptor's pointers, when not NULL, must cover the sizes its counts imply.
    pub(super) unsafe fn new(d: &rq_mesh_desc) -> Result<RawMesh, MeshError> {
        if d.vertex_stride < 12 {
            return Err(MeshError::StrideTooSmall {
                stride: d.vertex_stride,
            });
        }
        let vertex_bytes = match d.vertex_count {
            0 => Some(0),
            n => (n - 1)
                .checked_mul(d.vertex_stride)
                .and_then(|b| b.checked_add(12)),
        };
        let index_bytes = d.triangle_count.checked_mul(12);
        let fits = |p: usize, bytes: Option<usize>| {
            bytes.is_some_and(|b| b <= isize::MAX as usize && p.checked_add(b).is_some())
        };
        if !fits(d.vertices as usize, vertex_bytes) {
            return Err(MeshError::CountOverflow {
                what: "vertex_count * vertex_stride",
            });
        }
        if !fits(d.indices as usize, index_bytes) {
            return Err(MeshError::CountOverflow {
                what: "triangle_count * 12",
            });
        }
        if d.vertex_count != 0 && d.vertices.is_null() {
            return Err(MeshError::MissingData {
                what: "rq_mesh_desc.vertices",
            });
        }
        if d.triangle_count != 0 && d.indices.is_null() {
            return Err(MeshError::MissingData {
                what: "rq_mesh_desc.indices",
            });
        }
        Ok(RawMesh {
            vertices: d.vertices as *const u8,
            vertex_count: d.vertex_count,
            stride: d.vertex_stride,
            indices: d.indices as *const u8,
            triangle_count: d.triangle_count,
        })
    }
}

impl MeshSource for RawMesh {
    fn vertex_count(&self) -> usize {
        self.vertex_count
    }
    fn triangle_count(&self) -> usize {
        self.triangle_count
    }
    fn vertex(&self, i: usize) -> [f32; 3] {
        // SAFETY: i < vertex_count and RawMesh::new checked that the range does not overflow; the
        // caller promised the memory. Unaligned reads accept any pointer alignment.
        unsafe { ptr::read_unaligned(self.vertices.add(i * self.stride) as *const [f32; 3]) }
    }
    fn triangle(&self, i: usize) -> [u32; 3] {
        // SAFETY: as above, for the index array.
        unsafe { ptr::read_unaligned(self.indices.add(i * 12) as *const [u32; 3]) }
    }
}

fn report_error(o: &Options, status: rq_status, message: &Message) -> rq_status {
    if let Some(cb) = o.on_error {
        // SAFETY: the caller gave this callback and user pointer for exactly this purpose.
        unsafe { cb(o.user, status, message.as_ptr()) };
    }
    status
}

/// Validates the mesh and builds a scene; `opts` NULL means defaults, `calib` NULL the built-in
/// calibration. On success `*out` receives the scene; on failure `*out` is untouched and `on_error`
/// (if set) is told why.
///
/// # Safety
/// Pointers are NULL or valid for the sizes their counts imply; the mesh arrays are only read. A
/// `memory_monitor` and a `clock`, with their user pointers, stay valid for as long as the scene
/// lives.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_build(
    mesh: *const rq_mesh_desc,
    opts: *const rq_build_options,
    calib: *const rq_calibration,
    out: *mut *mut rq_scene,
) -> rq_status {
    boundary(|| {
        // SAFETY: opts and calib are NULL or valid (function contract).
        unsafe {
            build_scene(opts, calib, out, |options, calibration, samples| {
                if mesh.is_null() {
                    return Err(Refusal::Null("mesh is NULL"));
                }
                // SAFETY: mesh is not NULL and points to a descriptor (contract).
                let desc = ptr::read_unaligned(mesh);
                // SAFETY: the descriptor's arrays cover its counts (contract).
                let raw = RawMesh::new(&desc).map_err(BuildError::InvalidMesh)?;
                Ok(Scene::build_with_samples(
                    &raw,
                    options,
                    calibration,
                    samples,
                )?)
            })
        }
    })
}

/// Why a build was refused before or during the build.
pub(super) enum Refusal {
    /// A required pointer is NULL.
    Null(&'static str),
    /// The build failed.
    Build(BuildError),
}

impl From<BuildError> for Refusal {
    fn from(e: BuildError) -> Self {
        Refusal::Build(e)
    }
}

/// The part every scene build shares: reads the options and the calibration, runs `build` with the
/// options as Rust sees them, the calibration and the caller's sample rays, and hands the scene to
/// `*out` (or tells `on_error` why not).
///
/// # Safety
/// As for [`rq_scene_build`]: `opts` and `calib` NULL or valid, `out` NULL or writable.
pub(super) unsafe fn build_scene(
    opts: *const rq_build_options,
    calib: *const rq_calibration,
    out: *mut *mut rq_scene,
    build: impl FnOnce(&BuildOptions, &Calibration, Option<&dyn RaySource>) -> Result<Scene, Refusal>,
) -> rq_status {
    // SAFETY: opts is NULL or a readable options struct (function contract).
    let o = match unsafe { read_options(opts) } {
        Ok(o) => o,
        Err((status, text, o)) => {
            return report_error(&o, status, &Message::new(format_args!("{text}")))
        }
    };
    if out.is_null() {
        return report_error(
            &o,
            rq_status::RQ_STATUS_NULL_ARGUMENT,
            &Message::new(format_args!("out is NULL")),
        );
    }
    let calibration: &Calibration = if calib.is_null() {
        Calibration::builtin()
    } else {
        // SAFETY: non-NULL calibration handles come from rq_calibration_* and point to a Calibration.
        unsafe { &*(calib as *const Calibration) }
    };
    let options = BuildOptions {
        structure: o.structure,
        expected_rays: o.expected_rays,
        budget_kind: o.budget_kind,
        kdtree: match o.kd_quality {
            rq_kd_quality::RQ_KD_QUALITY_DEFAULT => KdTreeParams::DEFAULT,
            rq_kd_quality::RQ_KD_QUALITY_FAST => KdTreeParams::FAST,
            rq_kd_quality::RQ_KD_QUALITY_HIGH => KdTreeParams::HIGH,
        },
        memory_limit: o.memory_limit,
        memory_monitor: o.memory_monitor,
        clock: o.clock,
        ..BuildOptions::DEFAULT
    };
    let samples = CallerRays {
        rays: o.sample_rays,
        count: o.sample_ray_count,
    };
    let samples: Option<&dyn RaySource> = if o.sample_rays.is_null() {
        None
    } else {
        Some(&samples)
    };
    let scene = match build(&options, calibration, samples) {
        Ok(s) => s,
        Err(Refusal::Null(text)) => {
            return report_error(
                &o,
                rq_status::RQ_STATUS_NULL_ARGUMENT,
                &Message::new(format_args!("{text}")),
            )
        }
        Err(Refusal::Build(e)) => {
            return report_error(&o, e.into(), &Message::new(format_args!("{e}")))
        }
    };
    let Some(boxed) = try_box(scene) else {
        let e = BuildError::OutOfMemory {
            what: "scene handle",
            bytes: size_of::<Scene>(),
        };
        return report_error(&o, e.into(), &Message::new(format_args!("{e}")));
    };
    // SAFETY: out is not NULL (checked) and writable (contract).
    unsafe { out.write_unaligned(alloc::boxed::Box::into_raw(boxed) as *mut rq_scene) };
    rq_status::RQ_STATUS_OK
}

/// Frees a scene; NULL is ignored.
///
/// # Safety
/// `scene` is NULL or came from `rq_scene_build` and is not used afterwards.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_free(scene: *mut rq_scene) {
    boundary(|| {
        if !scene.is_null() {
            // SAFETY: the handle is a Box<Scene> made by rq_scene_build (contract).
            drop(unsafe { alloc::boxed::Box::from_raw(scene as *mut Scene) });
        }
    })
}

/// # Safety
/// `scene` is NULL or a live handle.
pub(super) unsafe fn scene_ref<'a>(scene: *const rq_scene) -> Option<&'a Scene> {
    // SAFETY: a non-NULL handle is a live Box<Scene> (contract).
    unsafe { (scene as *const Scene).as_ref() }
}

pub(super) fn to_ray(r: &rq_ray) -> Ray {
    Ray {
        org: Vec3::from(r.org),
        tmin: r.tmin,
        dir: Vec3::from(r.dir),
        tmax: r.tmax,
    }
}

fn to_hit(h: Hit) -> rq_hit {
    rq_hit {
        t: h.t,
        u: h.u,
        v: h.v,
        prim: h.prim,
    }
}

/// The closest hit of `ray`: true on a hit. `*out` is always written when not NULL (a miss as
/// `t = INFINITY, u = v = 0, prim = RQ_INVALID_ID`); a NULL scene or ray is a miss.
///
/// # Safety
/// `scene` is NULL or a live handle; `ray` NULL or readable; `out` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_intersect(
    scene: *const rq_scene,
    ray: *const rq_ray,
    out: *mut rq_hit,
) -> bool {
    boundary(|| {
        // SAFETY: per the function contract.
        let hit = match (unsafe { scene_ref(scene) }, ray.is_null()) {
            (Some(s), false) => s.intersect(&to_ray(&unsafe { ptr::read_unaligned(ray) })),
            _ => Hit::MISS,
        };
        if !out.is_null() {
            // SAFETY: out is writable (contract).
            unsafe { out.write_unaligned(to_hit(hit)) };
        }
        hit.is_hit()
    })
}

/// True when anything blocks `ray` in `[tmin, tmax]`; a NULL scene or ray is not occluded.
///
/// # Safety
/// `scene` is NULL or a live handle; `ray` NULL or readable.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_occluded(scene: *const rq_scene, ray: *const rq_ray) -> bool {
    boundary(|| match (unsafe { scene_ref(scene) }, ray.is_null()) {
        // SAFETY: ray is not NULL and readable (contract).
        (Some(s), false) => s.occluded(&to_ray(&unsafe { ptr::read_unaligned(ray) })),
        _ => false,
    })
}

/// Closest hits of `n` rays into `hits[0..n]` (the two arrays must not overlap). With a valid scene,
/// `n == 0` is a no-op that accepts NULL arrays; a NULL scene is always `RQ_STATUS_NULL_ARGUMENT`.
///
/// # Safety
/// `rays` readable and `hits` writable for `n` elements when `n > 0`.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_intersect_n(
    scene: *const rq_scene,
    rays: *const rq_ray,
    hits: *mut rq_hit,
    n: usize,
) -> rq_status {
    boundary(|| {
        // SAFETY: per the function contract.
        let Some(s) = (unsafe { scene_ref(scene) }) else {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        };
        if n == 0 {
            return rq_status::RQ_STATUS_OK;
        }
        if rays.is_null() || hits.is_null() {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        }
        for i in 0..n {
            // SAFETY: i < n and the arrays hold n elements (contract).
            unsafe {
                let r = ptr::read_unaligned(rays.add(i));
                hits.add(i)
                    .write_unaligned(to_hit(s.intersect(&to_ray(&r))));
            }
        }
        rq_status::RQ_STATUS_OK
    })
}

fn c_structure(s: Structure) -> rq_structure {
    match s {
        Structure::Auto => rq_structure::RQ_STRUCTURE_AUTO,
        Structure::Grid => rq_structure::RQ_STRUCTURE_GRID,
        Structure::KdTree => rq_structure::RQ_STRUCTURE_KDTREE,
    }
}

fn c_outcome(o: Outcome) -> rq_outcome {
    match o {
        Outcome::Forced => rq_outcome::RQ_OUTCOME_FORCED,
        Outcome::GridFasterPerRay => rq_outcome::RQ_OUTCOME_GRID_FASTER_PER_RAY,
        Outcome::BelowBreakEven => rq_outcome::RQ_OUTCOME_BELOW_BREAK_EVEN,
        Outcome::AboveBreakEven => rq_outcome::RQ_OUTCOME_ABOVE_BREAK_EVEN,
        Outcome::OnlineOnGrid => rq_outcome::RQ_OUTCOME_ONLINE_ON_GRID,
        Outcome::OnlineSwitched => rq_outcome::RQ_OUTCOME_ONLINE_SWITCHED,
    }
}

/// Writes `$value` into field `$field` of `*$p` when `$size` covers the whole field.
macro_rules! write_covered {
    ($p:expr, $size:expr, $field:ident, $value:expr) => {{
        let value = $value;
        let at = offset_of!(rq_scene_report, $field);
        if $size >= at + core::mem::size_of_val(&value) {
            // SAFETY: the caller's struct_size says these bytes belong to its report struct.
            unsafe { ptr::write_unaligned(($p as *mut u8).add(at) as *mut _, value) };
        }
    }};
}

/// Fills the fields of `*out` that `out->struct_size` covers (struct_size itself is left alone).
///
/// # Safety
/// `scene` is NULL or a live handle; `out` NULL or writable for `out->struct_size` bytes.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_report_get(
    scene: *const rq_scene,
    out: *mut rq_scene_report,
) -> rq_status {
    boundary(|| {
        // SAFETY: per the function contract.
        let Some(s) = (unsafe { scene_ref(scene) }) else {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        };
        if out.is_null() {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        }
        // SAFETY: out is readable (contract); struct_size is its first field.
        let size = unsafe { ptr::read_unaligned(out as *const u32) } as usize;
        if size < size_of::<u32>() * 2 {
            return rq_status::RQ_STATUS_INVALID_ARGUMENT;
        }
        let r = s.report();
        write_covered!(out, size, structure, c_structure(r.structure));
        write_covered!(out, size, outcome, c_outcome(r.outcome));
        write_covered!(out, size, triangle_count, r.triangle_count);
        write_covered!(out, size, memory_bytes, r.memory_bytes);
        write_covered!(out, size, grid_resolution, r.grid_resolution);
        write_covered!(out, size, grid_ray_seconds, r.grid_ray_seconds);
        write_covered!(out, size, kd_ray_seconds, r.kd_ray_seconds);
        write_covered!(out, size, kd_build_seconds, r.kd_build_seconds);
        write_covered!(out, size, break_even_rays, r.break_even_rays);
        write_covered!(out, size, expected_rays, r.expected_rays);
        write_covered!(
            out,
            size,
            references_per_triangle,
            r.references_per_triangle
        );
        write_covered!(out, size, kd_node_count, r.kd_node_count);
        write_covered!(out, size, kd_depth, r.kd_depth);
        write_covered!(out, size, geometry_count, r.geometry_count);
        rq_status::RQ_STATUS_OK
    })
}

/// Tells the scene how many rays were traced since the last call and how many remain (0 = unknown,
/// `RQ_RAYS_REMAINING_NONE` = none: the scene never switches again). Call between batches, never
/// concurrently with queries. A scene built with AUTO and an unknown budget (or an AT_MOST bound
/// above W*) that is still on the grid switches to the kd-tree when `rays_remaining` is at least
/// the estimated W*, or, with the budget unknown, once the time lost on the grid reaches the
/// kd-tree's estimated build time and, under an AT_MOST bound, the rays that may still come are at
/// least W* (outcome ONLINE_SWITCHED). While AUTO holds the grid the scene keeps about one query in
/// 64 (by a hash of the ray, up to 1 024); once it holds 256, this call estimates the costs from
/// those rays instead of the library's samples (the report's estimates and W* change), and a scene
/// built with a known budget switches too when `rays_remaining` is at least the new W*. From the
/// first batch measured so, every switch waits for a batch's tapped rays to agree: each measured
/// batch starts the tap over, and the switch comes at the first call whose batch (256 tapped rays
/// or more, about 16 000 queries) asks for it after one that asked too; a batch that does not ask
/// cancels it. Meanwhile the report may show a W* below `rays_remaining` with the grid held. The
/// kd-tree is kept only if the last batch's tapped rays took it less time than the grid (with a
/// `clock`; without one, only if their counted work on it, priced, is the smaller). The kd-tree is
/// built while the grid is still held; if it does not fit `memory_limit` (RQ_STATUS_MEMORY_LIMIT),
/// memory runs out, or the build's `memory_monitor` refuses an allocation (RQ_STATUS_CANCELLED), the
/// scene stays on the grid, unchanged and usable.
///
/// With a `clock`, a kd-tree AUTO built at `rq_scene_build` on the library's own samples is checked
/// once more: the scene taps its queries on the kd-tree too, and the first call that finds 256 of
/// them (with `rays_remaining` 0, or enough rays left that a grid's build costs at most a sixteenth
/// of their estimated time on it) times them on the kd-tree, builds a grid, times them on it, and
/// keeps the faster (RQ_OUTCOME_GRID_FASTER_PER_RAY for the grid). Both are held meanwhile: if the
/// grid does not fit `memory_limit`, memory runs out or the monitor refuses, the call returns that
/// status, the scene keeps its kd-tree, unchanged and usable, and the re-check is not tried again.
///
/// # Safety
/// `scene` is NULL or a live handle not being queried by another thread.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_update(
    scene: *mut rq_scene,
    rays_traced: u64,
    rays_remaining: u64,
) -> rq_status {
    boundary(|| {
        // SAFETY: a non-NULL handle is a live Box<Scene> with no concurrent users (contract).
        let Some(s) = (unsafe { (scene as *mut Scene).as_mut() }) else {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        };
        match s.update(rays_traced, rays_remaining) {
            Ok(()) => rq_status::RQ_STATUS_OK,
            Err(e) => e.into(),
        }
    })
}
