//! A C-callable OBJ loader (feature `obj`), so C programs need no parser of their own.

use core::ffi::{c_char, CStr};
use core::ptr;

use super::boundary;
use super::types::*;
use crate::budget::try_box;
use crate::mesh::MeshData;

/// A loaded OBJ mesh (opaque). Free with `rq_obj_free`.
pub struct rq_obj {
    _private: [u8; 0],
}

/// Loads an OBJ file (all objects merged, polygons fanned into triangles).
/// `RQ_STATUS_INVALID_ARGUMENT` when the file cannot be read or parsed.
///
/// # Safety
/// `path` is a NUL-terminated string; `out` is writable.
#[no_mangle]
pub unsafe extern "C" fn rq_obj_load(path: *const c_char, out: *mut *mut rq_obj) -> rq_status {
    boundary(|| {
        if path.is_null() || out.is_null() {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        }
        // SAFETY: path is NUL-terminated (contract).
        let Ok(path) = unsafe { CStr::from_ptr(path) }.to_str() else {
            return rq_status::RQ_STATUS_INVALID_ARGUMENT;
        };
        let Ok(mesh) = crate::obj::load_obj(path) else {
            return rq_status::RQ_STATUS_INVALID_ARGUMENT;
        };
        let Some(b) = try_box(mesh) else {
            return rq_status::RQ_STATUS_OUT_OF_MEMORY;
        };
        // SAFETY: out is writable (contract).
        unsafe { out.write_unaligned(alloc::boxed::Box::into_raw(b) as *mut rq_obj) };
        rq_status::RQ_STATUS_OK
    })
}

/// Describes the loaded mesh for `rq_scene_build` (valid until `rq_obj_free`).
///
/// # Safety
/// `obj` is a live handle; `out` is writable.
#[no_mangle]
pub unsafe extern "C" fn rq_obj_mesh_desc(obj: *const rq_obj, out: *mut rq_mesh_desc) -> rq_status {
    boundary(|| {
        // SAFETY: a non-NULL handle is a live Box<MeshData> (contract).
        let Some(m) = (unsafe { (obj as *const MeshData).as_ref() }) else {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        };
        if out.is_null() {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        }
        let desc = rq_mesh_desc {
            vertices: m.vertices.as_ptr() as *const f32,
            vertex_count: m.vertices.len(),
            vertex_stride: 12,
            indices: m.indices.as_ptr() as *const u32,
            triangle_count: m.indices.len(),
        };
        // SAFETY: out is writable (contract).
        unsafe { out.write_unaligned(desc) };
        rq_status::RQ_STATUS_OK
    })
}

/// The box around the loaded vertices: `lo` and `hi` receive three floats each.
///
/// # Safety
/// `obj` is a live handle; `lo` and `hi` are writable for three floats.
#[no_mangle]
pub unsafe extern "C" fn rq_obj_bounds(
    obj: *const rq_obj,
    lo: *mut f32,
    hi: *mut f32,
) -> rq_status {
    boundary(|| {
        // SAFETY: a non-NULL handle is a live Box<MeshData> (contract).
        let Some(m) = (unsafe { (obj as *const MeshData).as_ref() }) else {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        };
        if lo.is_null() || hi.is_null() {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        }
        let b = m.bounds();
        if b.is_empty() {
            return rq_status::RQ_STATUS_INVALID_OPERATION;
        }
        // SAFETY: lo and hi hold three floats each (contract).
        unsafe {
            ptr::write_unaligned(lo as *mut [f32; 3], b.min.to_array());
            ptr::write_unaligned(hi as *mut [f32; 3], b.max.to_array());
        }
        rq_status::RQ_STATUS_OK
    })
}

/// Frees a loaded mesh; NULL is ignored.
///
/// # Safety
/// `obj` is NULL or a live handle not used afterwards.
#[no_mangle]
pub unsafe extern "C" fn rq_obj_free(obj: *mut rq_obj) {
    boundary(|| {
        if !obj.is_null() {
            // SAFETY: the handle is a Box<MeshData> from rq_obj_load (contract).
            drop(unsafe { alloc::boxed::Box::from_raw(obj as *mut MeshData) });
        }
    })
}
