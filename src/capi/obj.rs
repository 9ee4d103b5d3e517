//! A C-callable OBJ loader (feature `obj`), so C programs need no parser of their own. The parser is
//! `crate::obj`; this file turns its errors into statuses and `on_error` messages.

extern crate std;

use core::ffi::{c_char, c_void, CStr};
use core::ptr;
use std::ffi::CString;
use std::path::Path;
use std::string::ToString;

use super::boundary;
use super::types::*;
use crate::budget::try_box;
use crate::mesh::MeshData;
use crate::obj::ObjErrorKind;

/// A loaded OBJ mesh (opaque). Free with `rq_obj_free`.
pub struct rq_obj {
    _private: [u8; 0],
}

/// Options of `rq_obj_load_ex`. Fill with `rq_obj_load_options_init`, then set what you need; the
/// library reads only the fields the caller's `struct_size` covers (the others keep their defaults).
#[repr(C)]
pub struct rq_obj_load_options {
    /// `sizeof(rq_obj_load_options)` as the caller knows it.
    pub struct_size: u32,
    /// Called once when the load fails, on the calling thread, with the status and a message that
    /// names the file and, for what is wrong inside it, the line: `path:line: what` (valid only
    /// during the call). NULL = not called.
    pub on_error: rq_error_fn,
    /// Passed to `on_error`.
    pub user: *mut c_void,
}

/// Fills the first `size` bytes of `opts` (`sizeof(rq_obj_load_options)` as the caller's header
/// declares it) with the defaults (no error callback); `struct_size` says how many bytes were
/// written (at most the library's own struct). The header's `rq_obj_load_options_init(opts)` calls
/// this with `sizeof(rq_obj_load_options)`. Does nothing when `opts` is NULL or `size` is below 4.
///
/// # Safety
/// `opts` is NULL or points to `size` writable bytes.
#[no_mangle]
pub unsafe extern "C" fn rq_obj_load_options_init_sized(
    opts: *mut rq_obj_load_options,
    size: usize,
) {
    boundary(|| {
        // SAFETY: the caller promises `size` writable bytes at `opts` (or NULL).
        unsafe {
            super::init_prefix(opts, size, |struct_size| rq_obj_load_options {
                struct_size,
                on_error: None,
                user: ptr::null_mut(),
            })
        }
    })
}

/// The bytes of `rq_obj_load_options`' first layout (up to `user`).
const OBJ_LOAD_OPTIONS_FIRST: usize = super::first_layout!(rq_obj_load_options, user, *mut c_void);

/// The first version's entry, for programs compiled before the header made
/// `rq_obj_load_options_init` a macro over [`rq_obj_load_options_init_sized`]: only the first
/// layout's bytes are written, whatever fields are appended later.
///
/// # Safety
/// `opts` is NULL or points to writable memory of the first layout's size.
#[no_mangle]
pub unsafe extern "C" fn rq_obj_load_options_init(opts: *mut rq_obj_load_options) {
    // SAFETY: as the caller promises.
    unsafe { rq_obj_load_options_init_sized(opts, OBJ_LOAD_OPTIONS_FIRST) }
}

impl From<ObjErrorKind> for rq_status {
    fn from(kind: ObjErrorKind) -> Self {
        match kind {
            ObjErrorKind::Unreadable => rq_status::RQ_STATUS_OBJ_UNREADABLE,
            ObjErrorKind::Malformed => rq_status::RQ_STATUS_OBJ_MALFORMED,
            ObjErrorKind::IndexOutOfRange => rq_status::RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE,
            // Indices are u32 in rq_mesh_desc: the same refusal as a mesh whose counts overflow.
            ObjErrorKind::TooLarge => rq_status::RQ_STATUS_INVALID_MESH,
            ObjErrorKind::OutOfMemory => rq_status::RQ_STATUS_OUT_OF_MEMORY,
        }
    }
}

/// Returns `status`, first telling `on_error` (when set) why.
fn refuse(on_error: rq_error_fn, user: *mut c_void, status: rq_status, text: &str) -> rq_status {
    if let Some(cb) = on_error {
        // Messages quote file contents escaped (crate::obj), so a NUL can only come from elsewhere;
        // replacing it keeps the text whole instead of dropping it.
        let message = CString::new(text.replace('\0', "\\0")).unwrap_or_default();
        // SAFETY: the caller gave this callback and user pointer for exactly this purpose.
        unsafe { cb(user, status, message.as_ptr()) };
    }
    status
}

/// The path as the OS takes it: any bytes on Unix, UTF-8 elsewhere.
fn os_path(path: &CStr) -> Option<&Path> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        Some(Path::new(std::ffi::OsStr::from_bytes(path.to_bytes())))
    }
    #[cfg(not(unix))]
    {
        path.to_str().ok().map(Path::new)
    }
}

/// Loads an OBJ file (all objects merged, polygons fanned into triangles; docs/shipping.md says what
/// is read and what is refused). The same as `rq_obj_load_ex(path, NULL, out)`: the status says why
/// a load failed, `rq_obj_load_ex` also gives the file and line.
///
/// # Safety
/// `path` is a NUL-terminated string; `out` is writable.
#[no_mangle]
pub unsafe extern "C" fn rq_obj_load(path: *const c_char, out: *mut *mut rq_obj) -> rq_status {
    // SAFETY: the same contract.
    unsafe { rq_obj_load_ex(path, ptr::null(), out) }
}

/// Loads an OBJ file as `rq_obj_load` does; `opts` NULL means defaults. On success `*out` receives
/// the mesh; on failure `*out` is untouched and `on_error` (if set) is told why. Statuses:
/// `RQ_STATUS_OBJ_UNREADABLE` (missing, a directory, no permission, a read error),
/// `RQ_STATUS_OBJ_MALFORMED` (a `v` or `f` line with too few values, a token that is not a number or
/// index, a non-finite coordinate), `RQ_STATUS_OBJ_INDEX_OUT_OF_RANGE` (a face names vertex 0 or one
/// not defined on an earlier line), `RQ_STATUS_INVALID_MESH` (more vertices than `uint32_t` indices
/// reach), `RQ_STATUS_OUT_OF_MEMORY`, `RQ_STATUS_NULL_ARGUMENT`, and `RQ_STATUS_INVALID_ARGUMENT`
/// for a path that is not UTF-8 where the OS wants UTF-8.
///
/// # Safety
/// `path` is a NUL-terminated string; `opts` is NULL or readable for its `struct_size` bytes;
/// `out` is writable.
#[no_mangle]
pub unsafe extern "C" fn rq_obj_load_ex(
    path: *const c_char,
    opts: *const rq_obj_load_options,
    out: *mut *mut rq_obj,
) -> rq_status {
    boundary(|| {
        let (on_error, user) = if opts.is_null() {
            (None, ptr::null_mut())
        } else {
            // SAFETY: struct_size is the first field and always present (contract).
            let size = unsafe { ptr::read_unaligned(opts as *const u32) } as usize;
            (
                read_field!(rq_obj_load_options, opts, size, on_error, rq_error_fn, None),
                read_field!(
                    rq_obj_load_options,
                    opts,
                    size,
                    user,
                    *mut c_void,
                    ptr::null_mut()
                ),
            )
        };
        let fail = |status, text: &str| refuse(on_error, user, status, text);
        if path.is_null() || out.is_null() {
            let text = if path.is_null() {
                "path is NULL"
            } else {
                "out is NULL"
            };
            return fail(rq_status::RQ_STATUS_NULL_ARGUMENT, text);
        }
        // SAFETY: path is NUL-terminated (contract).
        let path = unsafe { CStr::from_ptr(path) };
        let Some(os) = os_path(path) else {
            let text = std::format!("{}: the path is not UTF-8", path.to_string_lossy());
            return fail(rq_status::RQ_STATUS_INVALID_ARGUMENT, &text);
        };
        let mesh = match crate::obj::load_obj(os) {
            Ok(mesh) => mesh,
            Err(e) => return fail(e.kind.into(), &e.to_string()),
        };
        let Some(b) = try_box(mesh) else {
            let text = std::format!("{}: out of memory for the mesh handle", os.display());
            return fail(rq_status::RQ_STATUS_OUT_OF_MEMORY, &text);
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
