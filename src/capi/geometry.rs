//! Scenes of several geometries in the C ABI: descriptions, conditioned rays and hits, batched
//! occlusion, moved vertices (DESIGN.md §4.1).

use alloc::boxed::Box;
use alloc::vec::Vec;
use core::ffi::c_void;
use core::mem::{offset_of, size_of};
use core::ptr;

use super::boundary;
use super::scene::{build_scene, scene_ref, to_ray, RawMesh, Refusal};
use super::types::*;
use super::RQ_INVALID_ID;
use crate::budget::try_box;
use crate::error::{BuildError, MeshError};
use crate::geometry::{Filter, Geometry, HitEx, RayEx};
use crate::mesh::MeshSource;
use crate::scene::Scene;

/// Fills the first `size` bytes of `desc` (`sizeof(rq_geometry_desc)` as the caller's header
/// declares it) with the defaults: no triangles, mask `0xFFFFFFFF`, no culling, no filter;
/// `struct_size` says how many bytes were written (at most the library's own struct). The header's
/// `rq_geometry_desc_init(desc)` calls this with `sizeof(rq_geometry_desc)`. Does nothing when
/// `desc` is NULL or `size` is below 4.
///
/// # Safety
/// `desc` is NULL or points to `size` writable bytes.
#[no_mangle]
pub unsafe extern "C" fn rq_geometry_desc_init_sized(desc: *mut rq_geometry_desc, size: usize) {
    boundary(|| {
        // SAFETY: the caller promises `size` writable bytes at `desc` (or NULL).
        unsafe {
            super::init_prefix(desc, size, |struct_size| rq_geometry_desc {
                struct_size,
                mesh: rq_mesh_desc {
                    vertices: ptr::null(),
                    vertex_count: 0,
                    vertex_stride: 12,
                    indices: ptr::null(),
                    triangle_count: 0,
                },
                mask: u32::MAX,
                flags: 0,
                filter: None,
                filter_user: ptr::null_mut(),
            })
        }
    })
}

/// The bytes of `rq_geometry_desc`'s first layout (up to `filter_user`).
const GEOMETRY_DESC_FIRST: usize = super::first_layout!(rq_geometry_desc, filter_user, *mut c_void);

/// The first version's entry, for programs compiled before the header made `rq_geometry_desc_init`
/// a macro over [`rq_geometry_desc_init_sized`]: only the first layout's bytes are written, whatever
/// fields are appended later.
///
/// # Safety
/// `desc` is NULL or points to writable memory of the first layout's size.
#[no_mangle]
pub unsafe extern "C" fn rq_geometry_desc_init(desc: *mut rq_geometry_desc) {
    // SAFETY: as the caller promises.
    unsafe { rq_geometry_desc_init_sized(desc, GEOMETRY_DESC_FIRST) }
}

/// The caller's filter and its user pointer.
#[derive(Clone, Copy)]
struct CallerFilter {
    call: unsafe extern "C" fn(*mut c_void, *const rq_ray_ex, *const rq_hit_ex) -> bool,
    user: *mut c_void,
}

// SAFETY: rq_scene_build_geometries' contract: the filter may be called with its user pointer from
// every thread that queries the scene, for as long as the scene lives.
unsafe impl Send for CallerFilter {}
// SAFETY: as for Send; the pair is only read.
unsafe impl Sync for CallerFilter {}

impl CallerFilter {
    fn ask(&self, ray: &RayEx, hit: &HitEx) -> bool {
        let r = to_ray_ex_c(ray);
        let h = to_hit_ex(hit);
        // SAFETY: the caller gave this callback and pointer for exactly this (contract).
        unsafe { (self.call)(self.user, &r, &h) }
    }
}

/// One description as read from C, with the defaults for what `struct_size` does not cover.
struct Description {
    mesh: rq_mesh_desc,
    mask: u32,
    flags: u32,
    filter: Option<CallerFilter>,
}

/// Reads element `i` of the caller's array of descriptions, all `size` bytes long.
///
/// # Safety
/// `base` points to `count` readable descriptions of `size` bytes each, `i < count`.
unsafe fn read_description(base: *const u8, size: usize, i: usize) -> Description {
    // SAFETY: element i lies inside the caller's array (contract); fields are read only when covered.
    let p = unsafe { base.add(i * size) } as *const rq_geometry_desc;
    let filter = read_field!(rq_geometry_desc, p, size, filter, rq_filter_fn, None);
    let user = read_field!(
        rq_geometry_desc,
        p,
        size,
        filter_user,
        *mut c_void,
        ptr::null_mut()
    );
    Description {
        mesh: read_field!(
            rq_geometry_desc,
            p,
            size,
            mesh,
            rq_mesh_desc,
            rq_mesh_desc {
                vertices: ptr::null(),
                vertex_count: 0,
                vertex_stride: 12,
                indices: ptr::null(),
                triangle_count: 0,
            }
        ),
        mask: read_field!(rq_geometry_desc, p, size, mask, u32, u32::MAX),
        flags: read_field!(rq_geometry_desc, p, size, flags, u32, 0),
        filter: filter.map(|call| CallerFilter { call, user }),
    }
}

/// Reserves room for `n` elements without aborting when memory runs out.
fn room<T>(n: usize, what: &'static str) -> Result<Vec<T>, Refusal> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| {
        Refusal::Build(BuildError::OutOfMemory {
            what,
            bytes: n.saturating_mul(size_of::<T>()),
        })
    })?;
    Ok(v)
}

/// Builds a scene of `geometry_count` geometries (`geometries[i]` is geometry `i`; every element
/// has the caller's `sizeof(rq_geometry_desc)` in `struct_size`). Options, calibration, `*out` and
/// `on_error` as for `rq_scene_build`; a refused mesh is `RQ_STATUS_INVALID_MESH` (or
/// `RQ_STATUS_NULL_ARGUMENT`) with the geometry's index in the message; a flag outside
/// `rq_geometry_flags` is `RQ_STATUS_INVALID_ARGUMENT`. Hits of `rq_scene_intersect` name triangles
/// by their index across all geometries in order; `rq_scene_intersect_ex` gives geometry and local
/// index. `geometry_count == 0` builds an empty scene.
///
/// # Safety
/// `geometries` readable for `geometry_count` elements (may be NULL when 0), each mesh as for
/// `rq_scene_build`. A filter and its user pointer stay valid, and callable from every thread that
/// queries, for as long as the scene lives; a filter must not call rayq on this scene.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_build_geometries(
    geometries: *const rq_geometry_desc,
    geometry_count: usize,
    opts: *const rq_build_options,
    calib: *const rq_calibration,
    out: *mut *mut rq_scene,
) -> rq_status {
    boundary(|| {
        // SAFETY: per the function contract.
        unsafe {
            build_scene(opts, calib, out, |options, calibration, samples| {
                if geometry_count == 0 {
                    return Ok(Scene::build_geometries(
                        Vec::new(),
                        options,
                        calibration,
                        samples,
                    )?);
                }
                if geometries.is_null() {
                    return Err(Refusal::Null("geometries is NULL"));
                }
                let size = ptr::read_unaligned(geometries as *const u32) as usize;
                if size < offset_of!(rq_geometry_desc, mesh) + size_of::<rq_mesh_desc>()
                    || geometry_count.checked_mul(size).is_none()
                {
                    return Err(BuildError::InvalidArgument {
                        what:
                            "rq_geometry_desc.struct_size is too small: call rq_geometry_desc_init",
                    }
                    .into());
                }
                let base = geometries as *const u8;
                let mut descriptions: Vec<Description> = room(geometry_count, "geometry list")?;
                for i in 0..geometry_count {
                    let d = read_description(base, size, i);
                    if ptr::read_unaligned(base.add(i * size) as *const u32) as usize != size {
                        return Err(BuildError::InvalidArgument {
                            what: "rq_geometry_desc.struct_size differs between elements",
                        }
                        .into());
                    }
                    if d.flags & !3 != 0 {
                        return Err(BuildError::InvalidArgument {
                            what: "rq_geometry_desc.flags has bits outside rq_geometry_flags",
                        }
                        .into());
                    }
                    descriptions.push(d);
                }
                let mut meshes: Vec<RawMesh> = room(geometry_count, "geometry list")?;
                for (g, d) in descriptions.iter().enumerate() {
                    meshes.push(
                        RawMesh::new(&d.mesh)
                            .map_err(|error| BuildError::InvalidGeometry { geometry: g, error })?,
                    );
                }
                let mut list: Vec<Geometry<'_>> = room(geometry_count, "geometry list")?;
                for (d, mesh) in descriptions.iter().zip(&meshes) {
                    let filter: Option<Box<Filter>> = match d.filter {
                        None => None,
                        Some(f) => {
                            let ask = move |r: &RayEx, h: &HitEx| f.ask(r, h);
                            let Some(boxed) = try_box(ask) else {
                                return Err(BuildError::OutOfMemory {
                                    what: "geometry filter",
                                    bytes: size_of::<CallerFilter>(),
                                }
                                .into());
                            };
                            Some(boxed)
                        }
                    };
                    list.push(Geometry {
                        mesh: mesh as &dyn MeshSource,
                        mask: d.mask,
                        flags: d.flags,
                        filter,
                    });
                }
                Ok(Scene::build_geometries(
                    list,
                    options,
                    calibration,
                    samples,
                )?)
            })
        }
    })
}

fn to_ray_ex(r: &rq_ray_ex) -> RayEx {
    RayEx {
        ray: to_ray(&rq_ray {
            org: r.org,
            tmin: r.tmin,
            dir: r.dir,
            tmax: r.tmax,
        }),
        mask: r.mask,
        flags: r.flags,
    }
}

fn to_ray_ex_c(r: &RayEx) -> rq_ray_ex {
    rq_ray_ex {
        org: r.ray.org.to_array(),
        tmin: r.ray.tmin,
        dir: r.ray.dir.to_array(),
        tmax: r.ray.tmax,
        mask: r.mask,
        flags: r.flags,
    }
}

fn to_hit_ex(h: &HitEx) -> rq_hit_ex {
    rq_hit_ex {
        t: h.t,
        u: h.u,
        v: h.v,
        prim: h.prim,
        geom: h.geom,
        ng: h.ng.to_array(),
    }
}

/// The closest hit that passes the ray's and the geometries' conditions: true on a hit. `*out` is
/// always written when not NULL (a miss as `t = INFINITY, u = v = 0, prim = geom = RQ_INVALID_ID,
/// ng = 0`); a NULL scene or ray is a miss. Works on every scene (one built by `rq_scene_build` is
/// geometry 0 with mask `0xFFFFFFFF`).
///
/// # Safety
/// `scene` is NULL or a live handle; `ray` NULL or readable; `out` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_intersect_ex(
    scene: *const rq_scene,
    ray: *const rq_ray_ex,
    out: *mut rq_hit_ex,
) -> bool {
    boundary(|| {
        // SAFETY: per the function contract.
        let hit = match (unsafe { scene_ref(scene) }, ray.is_null()) {
            (Some(s), false) => s.intersect_ex(&to_ray_ex(&unsafe { ptr::read_unaligned(ray) })),
            _ => HitEx::MISS,
        };
        if !out.is_null() {
            // SAFETY: out is writable (contract).
            unsafe { out.write_unaligned(to_hit_ex(&hit)) };
        }
        hit.prim != RQ_INVALID_ID
    })
}

/// True when `rq_scene_intersect_ex` would hit; stops at the first accepted candidate. A NULL scene
/// or ray is not occluded.
///
/// # Safety
/// `scene` is NULL or a live handle; `ray` NULL or readable.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_occluded_ex(
    scene: *const rq_scene,
    ray: *const rq_ray_ex,
) -> bool {
    boundary(|| match (unsafe { scene_ref(scene) }, ray.is_null()) {
        // SAFETY: ray is not NULL and readable (contract).
        (Some(s), false) => s.occluded_ex(&to_ray_ex(&unsafe { ptr::read_unaligned(ray) })),
        _ => false,
    })
}

/// Runs `each(i)` for `i < n` after the checks every batched call shares: a NULL scene is
/// `RQ_STATUS_NULL_ARGUMENT`; `n == 0` is a no-op that accepts NULL arrays; otherwise both arrays
/// must be non-NULL.
fn batch(
    scene: Option<&Scene>,
    inputs: *const u8,
    outputs: *mut u8,
    n: usize,
    mut each: impl FnMut(&Scene, usize),
) -> rq_status {
    let Some(s) = scene else {
        return rq_status::RQ_STATUS_NULL_ARGUMENT;
    };
    if n == 0 {
        return rq_status::RQ_STATUS_OK;
    }
    if inputs.is_null() || outputs.is_null() {
        return rq_status::RQ_STATUS_NULL_ARGUMENT;
    }
    for i in 0..n {
        each(s, i);
    }
    rq_status::RQ_STATUS_OK
}

/// `rq_scene_intersect_ex` for `n` rays into `hits[0..n]` (the arrays must not overlap). With a valid
/// scene, `n == 0` is a no-op that accepts NULL arrays; a NULL scene is `RQ_STATUS_NULL_ARGUMENT`.
///
/// # Safety
/// `rays` readable and `hits` writable for `n` elements when `n > 0`.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_intersect_ex_n(
    scene: *const rq_scene,
    rays: *const rq_ray_ex,
    hits: *mut rq_hit_ex,
    n: usize,
) -> rq_status {
    boundary(|| {
        // SAFETY: per the function contract; i < n inside.
        batch(
            unsafe { scene_ref(scene) },
            rays as _,
            hits as _,
            n,
            |s, i| unsafe {
                let r = ptr::read_unaligned(rays.add(i));
                hits.add(i)
                    .write_unaligned(to_hit_ex(&s.intersect_ex(&to_ray_ex(&r))));
            },
        )
    })
}

/// `rq_scene_occluded` for `n` rays: `occluded[i]` = 1 when ray `i` is blocked, else 0. Checks as
/// for `rq_scene_intersect_n`.
///
/// # Safety
/// `rays` readable and `occluded` writable for `n` elements when `n > 0`.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_occluded_n(
    scene: *const rq_scene,
    rays: *const rq_ray,
    occluded: *mut u8,
    n: usize,
) -> rq_status {
    boundary(|| {
        // SAFETY: per the function contract; i < n inside.
        batch(
            unsafe { scene_ref(scene) },
            rays as _,
            occluded,
            n,
            |s, i| unsafe {
                let r = ptr::read_unaligned(rays.add(i));
                occluded.add(i).write(u8::from(s.occluded(&to_ray(&r))));
            },
        )
    })
}

/// `rq_scene_occluded_ex` for `n` rays: `occluded[i]` = 1 when ray `i` is blocked, else 0. Checks
/// as for `rq_scene_intersect_n`.
///
/// # Safety
/// `rays` readable and `occluded` writable for `n` elements when `n > 0`.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_occluded_ex_n(
    scene: *const rq_scene,
    rays: *const rq_ray_ex,
    occluded: *mut u8,
    n: usize,
) -> rq_status {
    boundary(|| {
        // SAFETY: per the function contract; i < n inside.
        batch(
            unsafe { scene_ref(scene) },
            rays as _,
            occluded,
            n,
            |s, i| unsafe {
                let r = ptr::read_unaligned(rays.add(i));
                occluded
                    .add(i)
                    .write(u8::from(s.occluded_ex(&to_ray_ex(&r))));
            },
        )
    })
}

/// New positions for the vertices of geometry `geom` (a scene from `rq_scene_build` is geometry 0):
/// as many as it was built with, xyz at the start of each `vertex_stride`-byte record, same topology.
/// The scene then rebuilds its structure as a new build with its options would: the grid (linear
/// time) or the kd-tree as forced, and with AUTO the selection again on the moved mesh (library
/// sample rays, the scene's `expected_rays`), so the kd-tree is built only when the selector says it
/// pays; `rq_scene_report_get` tells what it holds afterwards. The new structure is built while the
/// old one is held (the memory limit must hold both). On failure (RQ_STATUS_INVALID_ARGUMENT for no
/// such geometry, RQ_STATUS_INVALID_MESH for a non-finite coordinate or a stride below 12,
/// RQ_STATUS_MEMORY_LIMIT, RQ_STATUS_OUT_OF_MEMORY, RQ_STATUS_CANCELLED) the scene is unchanged and
/// usable. Not concurrently with queries or other calls on this scene.
///
/// # Safety
/// `scene` is NULL or a live handle nobody else is using; `vertices` NULL or readable for the
/// geometry's vertex count records of `vertex_stride` bytes.
#[no_mangle]
pub unsafe extern "C" fn rq_scene_set_vertices(
    scene: *mut rq_scene,
    geom: u32,
    vertices: *const f32,
    vertex_stride: usize,
) -> rq_status {
    boundary(|| {
        // SAFETY: a non-NULL handle is a live Box<Scene> with no concurrent users (contract).
        let Some(s) = (unsafe { (scene as *mut Scene).as_mut() }) else {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        };
        let Some(count) = s.mesh().geometry_vertex_count(geom as usize) else {
            return rq_status::RQ_STATUS_INVALID_ARGUMENT;
        };
        let desc = rq_mesh_desc {
            vertices,
            vertex_count: count,
            vertex_stride,
            indices: ptr::null(),
            triangle_count: 0,
        };
        // SAFETY: the caller promised `count` records of `vertex_stride` bytes (contract).
        let raw = match unsafe { RawMesh::new(&desc) } {
            Ok(r) => r,
            Err(e) => return MeshError::into(e),
        };
        match s.set_vertices(geom as usize, &|i| raw.vertex(i)) {
            Ok(()) => rq_status::RQ_STATUS_OK,
            Err(e) => e.into(),
        }
    })
}
