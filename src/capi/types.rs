//! C-visible types. Every enum has explicit numbers that never change; every struct is `repr(C)`.

use core::ffi::{c_char, c_void};

/// Status of every fallible call (`uint32_t`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum rq_status {
    /// Success.
    RQ_STATUS_OK = 0,
    /// A required pointer is NULL.
    RQ_STATUS_NULL_ARGUMENT = 1,
    /// An argument (an enum value, a size, an option) is out of range.
    RQ_STATUS_INVALID_ARGUMENT = 2,
    /// The mesh is refused: non-finite vertex, index out of range, stride below 12, counts overflow.
    RQ_STATUS_INVALID_MESH = 3,
    /// The caller's ABI version does not match the library's.
    RQ_STATUS_ABI_MISMATCH = 4,
    /// The call is not valid in the current state.
    RQ_STATUS_INVALID_OPERATION = 5,
    /// Not supported by this build.
    RQ_STATUS_UNSUPPORTED = 6,
    /// The allocator refused memory.
    RQ_STATUS_OUT_OF_MEMORY = 100,
    /// The build would exceed `memory_limit`.
    RQ_STATUS_MEMORY_LIMIT = 101,
    /// A callback cancelled the build.
    RQ_STATUS_CANCELLED = 102,
    /// Calibration blob: bad magic.
    RQ_STATUS_CALIB_BAD_MAGIC = 200,
    /// Calibration blob: unknown major format version.
    RQ_STATUS_CALIB_UNSUPPORTED_VERSION = 201,
    /// Calibration blob: shorter or longer than its header declares.
    RQ_STATUS_CALIB_TRUNCATED = 202,
    /// Calibration blob: CRC-32 mismatch.
    RQ_STATUS_CALIB_CHECKSUM = 203,
    /// Calibration blob: a constant is not finite or out of range.
    RQ_STATUS_CALIB_VALUE_OUT_OF_RANGE = 204,
    /// OBJ helper: the file cannot be opened or read (missing, a directory, no permission).
    RQ_STATUS_OBJ_UNREADABLE = 300,
    /// OBJ helper: a `v` or `f` line is malformed (too few values, not a number, not finite).
    RQ_STATUS_OBJ_MALFORMED = 301,
    /// OBJ helper: a face names vertex 0 or a vertex not defined on an earlier line.
    RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE = 302,
    /// A panic was caught at the boundary (a bug in rayq).
    RQ_STATUS_PANIC = 900,
    /// An internal invariant failed (a bug in rayq).
    RQ_STATUS_INTERNAL = 901,
}

/// Which acceleration structure (`uint32_t`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum rq_structure {
    /// Let the selector decide (default).
    RQ_STRUCTURE_AUTO = 0,
    /// Uniform grid.
    RQ_STRUCTURE_GRID = 1,
    /// SAH kd-tree.
    RQ_STRUCTURE_KDTREE = 2,
}

/// What `rq_build_options.expected_rays` means when it is not 0 (`uint32_t`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum rq_budget_kind {
    /// The rays the caller will trace (default): the selector decides at the build, on its sample
    /// rays; a scene left on the grid may still switch at `rq_scene_update` once the renderer's own
    /// tapped rays put W* at or below the rays remaining.
    RQ_BUDGET_EXPECTED = 0,
    /// An upper bound (a renderer that may stop early): below the estimated break-even the scene
    /// stays on the grid unless a later `rq_scene_update` is told a `rays_remaining` at or above
    /// the W* the renderer's own tapped rays give (with `rays_remaining` 0 it stays); above it the
    /// scene starts on the grid and `rq_scene_update` switches as with an unknown budget, but
    /// never once the rays that may still come are fewer than W*.
    RQ_BUDGET_AT_MOST = 1,
}

/// The kd-tree's build quality (`uint32_t`): the build time traded against the time per ray. The
/// selector's estimates assume DEFAULT; the other two change only the trees it or the caller builds.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum rq_kd_quality {
    /// The library's tree (`KdTreeParams::DEFAULT`): binned SAH, costs chosen by time.
    RQ_KD_QUALITY_DEFAULT = 0,
    /// A faster build for few rays (`KdTreeParams::FAST`: tests priced at half the default's, so
    /// shallower trees with bigger leaves: about 0.78× the build for about 2–3 % slower rays;
    /// docs/performance.md, "Stop 34").
    RQ_KD_QUALITY_FAST = 1,
    /// The exact SAH sweep up to 1 024 triangles a node (`KdTreeParams::HIGH`): about 2.7× the
    /// build for 2–4 % faster rays, so only for very long runs (docs/performance.md, "Stop 34").
    RQ_KD_QUALITY_HIGH = 2,
}

/// Why the scene uses its structure (`uint32_t`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum rq_outcome {
    /// The caller chose the structure (or only one was available).
    RQ_OUTCOME_FORCED = 0,
    /// `t_grid <= t_kd`: the kd-tree never pays (estimated, or measured on the tapped queries by
    /// `rq_scene_update` after a kd-tree built on the library's samples).
    RQ_OUTCOME_GRID_FASTER_PER_RAY = 1,
    /// Expected rays < W*: kept the grid.
    RQ_OUTCOME_BELOW_BREAK_EVEN = 2,
    /// Expected rays >= W*: built the kd-tree.
    RQ_OUTCOME_ABOVE_BREAK_EVEN = 3,
    /// Budget unknown, still on the grid.
    RQ_OUTCOME_ONLINE_ON_GRID = 4,
    /// Switched to the kd-tree in `rq_scene_update` (budget unknown or AT_MOST, or the tapped
    /// queries showed that the kd-tree pays for the rays remaining).
    RQ_OUTCOME_ONLINE_SWITCHED = 5,
}

/// A ray `org + t*dir`, `tmin <= t <= tmax` (32 bytes). `dir` need not be normalized.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rq_ray {
    /// Origin.
    pub org: [f32; 3],
    /// Smallest accepted t.
    pub tmin: f32,
    /// Direction.
    pub dir: [f32; 3],
    /// Largest accepted t (may be INFINITY).
    pub tmax: f32,
}

/// A hit (16 bytes). Miss: `t = +INFINITY, u = v = 0, prim = RQ_INVALID_ID`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rq_hit {
    /// Ray parameter.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
    /// Triangle index, or `RQ_INVALID_ID`.
    pub prim: u32,
}

/// An indexed triangle mesh in the caller's memory. The build copies what it needs.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rq_mesh_desc {
    /// Vertex data: xyz (three floats) at the start of each `vertex_stride`-byte record. Need not be
    /// aligned.
    pub vertices: *const f32,
    /// Number of vertices.
    pub vertex_count: usize,
    /// Bytes from one vertex to the next (at least 12).
    pub vertex_stride: usize,
    /// Three vertex indices per triangle. Need not be aligned.
    pub indices: *const u32,
    /// Number of triangles.
    pub triangle_count: usize,
}

/// Error callback: told the status and a NUL-terminated message that lives only during the call.
pub type rq_error_fn =
    Option<unsafe extern "C" fn(user: *mut c_void, status: rq_status, message: *const c_char)>;

/// Build options. Fill with `rq_build_options_init`, then change what you need. The library reads
/// only the fields that `struct_size` covers, so a program built against an older header keeps working.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rq_build_options {
    /// `sizeof(rq_build_options)` as the caller knows it.
    pub struct_size: u32,
    /// AUTO (default), GRID or KDTREE.
    pub structure: rq_structure,
    /// Rays the caller expects to trace; 0 = unknown (start on the grid, see `rq_scene_update`).
    pub expected_rays: u64,
    /// Representative rays for the selector; NULL = the library makes some.
    pub sample_rays: *const rq_ray,
    /// Number of sample rays.
    pub sample_ray_count: usize,
    /// Memory limit in bytes for everything the scene holds; 0 = none.
    pub memory_limit: usize,
    /// Called once with the status and a message when the build fails; may be NULL.
    pub on_error: rq_error_fn,
    /// Passed to `on_error`.
    pub user: *mut c_void,
    /// Asked before each allocation of a build (`rq_scene_build` in every mode, and the switch in
    /// `rq_scene_update`), told the bytes the build would then hold in total; returning false refuses
    /// the allocation and the call fails with `RQ_STATUS_CANCELLED`, freeing everything it took. Runs
    /// on the calling thread; must not call rayq. NULL = no monitor. Kept by the scene for
    /// `rq_scene_update`, so it and its user pointer must stay valid as long as the scene.
    pub memory_monitor: rq_memory_monitor_fn,
    /// Passed to `memory_monitor`.
    pub memory_monitor_user: *mut c_void,
    /// Whether `expected_rays` is the count (EXPECTED, default) or an upper bound (AT_MOST).
    pub budget_kind: rq_budget_kind,
    /// The quality of any kd-tree the scene builds (DEFAULT, FAST, HIGH), forced or chosen by AUTO.
    pub kd_quality: rq_kd_quality,
    /// The clock by which AUTO's check after a kd-tree build times your rays on both structures
    /// (nanoseconds that never go back; only differences on one thread are used): `sample_rays`,
    /// and the queries `rq_scene_update` tapped. The library's own sample rays are priced from their
    /// counted work instead, by prices fitted to them; but a kd-tree chosen on them is timed once
    /// more against a grid on your tapped queries by `rq_scene_update` (see there).
    /// `rq_build_options_init` sets the library's own clock (this thread's CPU time on Linux,
    /// monotonic wall time elsewhere) where it has one; NULL prices every check, which is
    /// deterministic but blind to what your rays cost beyond their counts (on diffuse bounces the
    /// prices keep a slower kd-tree on most scenes), and so does a `struct_size` that stops before
    /// this field; a clock that does not move over a pass of them is as good as none. Called on the
    /// thread that builds or updates the scene (scenes on different threads may call one clock at
    /// once); must not call rayq. Kept by the scene for `rq_scene_update`, so it and `clock_user`
    /// must stay valid as long as the scene.
    pub clock: rq_clock_fn,
    /// Passed to `clock`.
    pub clock_user: *mut c_void,
}

/// A clock: nanoseconds that never go back (its epoch is free: only differences are used).
pub type rq_clock_fn = Option<unsafe extern "C" fn(user: *mut c_void) -> u64>;

/// Memory monitor: told the bytes a build would hold after the allocation it is about to make;
/// returns true to allow it, false to cancel the build.
pub type rq_memory_monitor_fn =
    Option<unsafe extern "C" fn(user: *mut c_void, bytes_about_to_be_held: usize) -> bool>;

/// What a scene reports. Set `struct_size`; the library writes only the fields it covers.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rq_scene_report {
    /// `sizeof(rq_scene_report)` as the caller knows it.
    pub struct_size: u32,
    /// The structure in use now: GRID or KDTREE.
    pub structure: rq_structure,
    /// Why.
    pub outcome: rq_outcome,
    /// Triangles in the mesh (degenerate ones included).
    pub triangle_count: usize,
    /// Bytes the scene holds.
    pub memory_bytes: usize,
    /// Grid cells per axis (0 when no grid is held).
    pub grid_resolution: [u32; 3],
    /// Estimated seconds per ray on the grid (NaN when not estimated).
    pub grid_ray_seconds: f64,
    /// Estimated seconds per ray on the kd-tree (NaN when not estimated).
    pub kd_ray_seconds: f64,
    /// Estimated kd-tree build time (NaN when not estimated).
    pub kd_build_seconds: f64,
    /// Estimated W*; +INFINITY when the kd-tree is not faster per ray; NaN when not estimated.
    pub break_even_rays: f64,
    /// The ray budget the scene was built for (0 = unknown).
    pub expected_rays: u64,
    /// Triangle references per non-degenerate triangle in the structure in use.
    pub references_per_triangle: f64,
    /// kd-tree nodes, interior and leaves (0 when no kd-tree is held).
    pub kd_node_count: usize,
    /// Depth of the kd-tree's deepest leaf (0 when no kd-tree is held).
    pub kd_depth: u32,
    /// Geometries in the scene (1 for a scene built by `rq_scene_build`).
    pub geometry_count: usize,
}

/// Faces a geometry never reports (`rq_geometry_desc.flags`, a bitwise or). The front face is the
/// side from which the vertices (v0, v1, v2) appear counter-clockwise.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum rq_geometry_flags {
    /// No ray reports this geometry's back faces.
    RQ_GEOMETRY_CULL_BACK_FACES = 1,
    /// No ray reports this geometry's front faces.
    RQ_GEOMETRY_CULL_FRONT_FACES = 2,
}

/// Faces a ray ignores (`rq_ray_ex.flags`, a bitwise or), in every geometry.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum rq_ray_flags {
    /// The ray reports no back face.
    RQ_RAY_CULL_BACK_FACES = 1,
    /// The ray reports no front face.
    RQ_RAY_CULL_FRONT_FACES = 2,
}

/// A ray with conditions (40 bytes): it sees geometry `g` when `(mask & g.mask) != 0`, and ignores
/// the faces `flags` names (`rq_ray_flags`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rq_ray_ex {
    /// Origin.
    pub org: [f32; 3],
    /// Smallest accepted t.
    pub tmin: f32,
    /// Direction.
    pub dir: [f32; 3],
    /// Largest accepted t (may be INFINITY).
    pub tmax: f32,
    /// Which geometries the ray sees.
    pub mask: u32,
    /// `rq_ray_flags`.
    pub flags: u32,
}

/// A hit in a scene of several geometries (32 bytes). `prim` is the triangle's index in geometry
/// `geom`; `ng = (v1 - v0) x (v2 - v0)`, not normalized. A miss: `t = +INFINITY, u = v = 0,
/// prim = geom = RQ_INVALID_ID, ng = 0`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rq_hit_ex {
    /// Ray parameter.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
    /// The triangle's index in its geometry, or `RQ_INVALID_ID`.
    pub prim: u32,
    /// The geometry's index, or `RQ_INVALID_ID`.
    pub geom: u32,
    /// Geometric normal `(v1 - v0) x (v2 - v0)`.
    pub ng: [f32; 3],
}

/// Any-hit filter: called for a candidate hit of its geometry (one the ray meets, in its mask and not
/// culled); returns false to ignore the candidate. Candidates come in any order, a triangle's possibly
/// more than once; called on the querying thread, from every thread that queries.
pub type rq_filter_fn = Option<
    unsafe extern "C" fn(
        user: *mut c_void,
        ray: *const rq_ray_ex,
        candidate: *const rq_hit_ex,
    ) -> bool,
>;

/// One geometry of a scene. Fill with `rq_geometry_desc_init`, then set the mesh and what you need.
/// The library reads only the fields `struct_size` covers.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct rq_geometry_desc {
    /// `sizeof(rq_geometry_desc)` as the caller knows it (the same for every element of an array).
    pub struct_size: u32,
    /// The triangles (copied at build).
    pub mesh: rq_mesh_desc,
    /// Seen by rays with `(ray.mask & mask) != 0`; default `0xFFFFFFFF`.
    pub mask: u32,
    /// `rq_geometry_flags`; default 0.
    pub flags: u32,
    /// NULL (default): every candidate counts.
    pub filter: rq_filter_fn,
    /// Passed to `filter`.
    pub filter_user: *mut c_void,
}

/// An immutable scene (opaque). Free with `rq_scene_free`.
pub struct rq_scene {
    _private: [u8; 0],
}

/// Machine cost constants (opaque, immutable, shareable between threads).
pub struct rq_calibration {
    _private: [u8; 0],
}
