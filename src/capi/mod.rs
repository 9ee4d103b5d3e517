//! The C ABI: the only place C names live. Conventions (README, "C API conventions"): const pointers
//! are read-only; out-parameters are written only on `RQ_STATUS_OK`; every `_free` accepts NULL; a
//! scene is immutable after build and may be queried from many threads; no panic crosses the boundary.
#![allow(non_camel_case_types)]

/// Reads field `$field` (of type `$ty`) of the `$struct` at `$p` when the caller's `$size` (its
/// `struct_size`) covers the whole field, else gives `$default`: how every growing options struct is
/// read, so a caller built against an older, shorter struct never has bytes past its end read.
/// Expands to an `unsafe` read; the caller vouches that `$p` points to `$size` readable bytes.
macro_rules! read_field {
    ($struct:ty, $p:expr, $size:expr, $field:ident, $ty:ty, $default:expr) => {{
        let offset = core::mem::offset_of!($struct, $field);
        if $size >= offset + core::mem::size_of::<$ty>() {
            // SAFETY: the caller's struct_size says these bytes are part of its struct.
            unsafe { core::ptr::read_unaligned(($p as *const u8).add(offset) as *const $ty) }
        } else {
            $default
        }
    }};
}

mod allocator;
/// The `bare-rt` global allocator (declares C's malloc/free, which must stay out of the header).
///
/// cbindgen:ignore
#[cfg(feature = "bare-rt")]
mod bare_alloc;
mod calibration;
mod geometry;
#[cfg(feature = "obj")]
mod obj;
mod panic;
mod scene;
mod types;

pub use allocator::*;
pub use calibration::*;
pub use geometry::*;
#[cfg(feature = "obj")]
pub use obj::*;
pub use panic::*;
pub use scene::*;
pub use types::*;

use core::ffi::c_char;

use crate::error::{BuildError, CalibError, MeshError};

/// The C ABI version; it changes only when a layout or a meaning changes incompatibly.
pub const RQ_ABI_VERSION: u32 = 1;
/// The primitive id of a miss.
pub const RQ_INVALID_ID: u32 = u32::MAX;

/// `rays_remaining` for `rq_scene_update` when no rays remain (the last batch was traced): the scene
/// never switches again. (`0` means "unknown".)
pub const RQ_RAYS_REMAINING_NONE: u64 = u64::MAX;

/// Writes the defaults of a growing struct (one that starts with a `u32` `struct_size`) to the
/// caller's `out`, whose struct is `size` bytes (the `sizeof` its header declares): only the first
/// `min(size, size_of::<T>())` bytes, and `defaults` is told that count for `struct_size`, so that a
/// caller built against an older, shorter struct never has bytes past its end written, and the
/// library then reads only fields it wrote. Nothing is written when `out` is NULL or the count is
/// less than the `struct_size` field itself. How every `*_init` fills its struct.
///
/// # Safety
/// `out` is NULL or points to `size` writable bytes.
unsafe fn init_prefix<T>(out: *mut T, size: usize, defaults: impl FnOnce(u32) -> T) {
    let n = size.min(core::mem::size_of::<T>());
    if out.is_null() || n < core::mem::size_of::<u32>() {
        return;
    }
    let value = defaults(n as u32);
    // SAFETY: `n` bytes of `value` are readable (n ≤ size_of::<T>()), and the caller promises
    // `size ≥ n` writable bytes at `out`; a byte copy needs no alignment and may copy padding.
    unsafe {
        core::ptr::copy_nonoverlapping((&value as *const T).cast::<u8>(), out.cast::<u8>(), n)
    }
}

/// The bytes of a growing struct's first layout: up to the end of its last field `$last` (of type
/// `$ty`). What the unsized `*_init` symbols write, for programs compiled before their header made
/// them macros over the sized ones: such a program's struct is at least this long, however many
/// fields later headers appended.
macro_rules! first_layout {
    ($struct:ty, $last:ident, $ty:ty) => {
        core::mem::offset_of!($struct, $last) + core::mem::size_of::<$ty>()
    };
}
pub(crate) use first_layout;
// Spelt out above so that cbindgen can write it; the Rust API's value is the same by construction.
const _: () = assert!(RQ_RAYS_REMAINING_NONE == crate::scene::RAYS_REMAINING_NONE);

/// What a function's return type gives when the body panics (std builds catch the panic).
trait PanicValue {
    // Without std nothing is caught, so nothing asks for the value.
    #[cfg_attr(not(feature = "std"), allow(dead_code))]
    fn on_panic() -> Self;
}

impl PanicValue for rq_status {
    fn on_panic() -> Self {
        rq_status::RQ_STATUS_PANIC
    }
}

impl PanicValue for bool {
    fn on_panic() -> Self {
        false
    }
}

impl PanicValue for () {
    fn on_panic() -> Self {}
}

impl<T> PanicValue for *const T {
    fn on_panic() -> Self {
        core::ptr::null()
    }
}

impl PanicValue for u32 {
    fn on_panic() -> Self {
        0
    }
}

/// Runs an exported body so that no panic unwinds into C: with std the panic is caught and the
/// return type's panic value returned; without std the `bare-rt` panic handler (src/capi/panic.rs)
/// is the last defence.
fn boundary<T: PanicValue>(body: impl FnOnce() -> T) -> T {
    #[cfg(feature = "std")]
    {
        std::panic::catch_unwind(core::panic::AssertUnwindSafe(body))
            .unwrap_or_else(|_| T::on_panic())
    }
    #[cfg(not(feature = "std"))]
    {
        body()
    }
}

impl From<MeshError> for rq_status {
    fn from(e: MeshError) -> Self {
        match e {
            MeshError::MissingData { .. } => rq_status::RQ_STATUS_NULL_ARGUMENT,
            _ => rq_status::RQ_STATUS_INVALID_MESH,
        }
    }
}

impl From<BuildError> for rq_status {
    fn from(e: BuildError) -> Self {
        match e {
            BuildError::InvalidMesh(m) => m.into(),
            BuildError::InvalidGeometry { error, .. } => error.into(),
            BuildError::OutOfMemory { .. } | BuildError::CapacityExceeded { .. } => {
                rq_status::RQ_STATUS_OUT_OF_MEMORY
            }
            BuildError::MemoryLimit { .. } => rq_status::RQ_STATUS_MEMORY_LIMIT,
            BuildError::Unsupported { .. } => rq_status::RQ_STATUS_UNSUPPORTED,
            BuildError::InvalidArgument { .. } => rq_status::RQ_STATUS_INVALID_ARGUMENT,
            BuildError::Cancelled { .. } => rq_status::RQ_STATUS_CANCELLED,
        }
    }
}

impl From<CalibError> for rq_status {
    fn from(e: CalibError) -> Self {
        match e {
            CalibError::BadMagic => rq_status::RQ_STATUS_CALIB_BAD_MAGIC,
            CalibError::UnsupportedVersion { .. } => rq_status::RQ_STATUS_CALIB_UNSUPPORTED_VERSION,
            CalibError::Truncated { .. } => rq_status::RQ_STATUS_CALIB_TRUNCATED,
            CalibError::Checksum => rq_status::RQ_STATUS_CALIB_CHECKSUM,
            CalibError::ValueOutOfRange { .. } => rq_status::RQ_STATUS_CALIB_VALUE_OUT_OF_RANGE,
            CalibError::BufferTooSmall { .. } => rq_status::RQ_STATUS_INVALID_ARGUMENT,
        }
    }
}

/// A description of any status code, as a static NUL-terminated string (never NULL; unknown codes get
/// "unknown status").
#[no_mangle]
pub extern "C" fn rq_status_str(status: u32) -> *const c_char {
    boundary(|| status_text(status).as_ptr().cast())
}

fn status_text(status: u32) -> &'static [u8] {
    match status {
        0 => b"ok\0",
        1 => b"a required pointer argument is NULL\0",
        2 => b"an argument is out of range\0",
        3 => b"the mesh is invalid (non-finite vertex, index out of range, bad stride or count)\0",
        4 => b"ABI version mismatch\0",
        5 => b"the operation is not valid in this state\0",
        6 => b"not supported by this build\0",
        100 => b"out of memory\0",
        101 => b"memory limit reached\0",
        102 => b"cancelled\0",
        200 => b"calibration blob: bad magic\0",
        201 => b"calibration blob: unsupported format version\0",
        202 => b"calibration blob: truncated or wrong length\0",
        203 => b"calibration blob: checksum mismatch\0",
        204 => b"calibration blob: value out of range\0",
        300 => b"OBJ file: cannot be opened or read\0",
        301 => b"OBJ file: malformed line\0",
        302 => b"OBJ file: face index out of range\0",
        900 => b"a panic was caught at the C boundary (a bug in rayq)\0",
        901 => b"internal error (a bug in rayq)\0",
        _ => b"unknown status\0",
    }
}

/// The ABI version the library was built with; compare with `RQ_ABI_VERSION` from the header.
#[no_mangle]
pub extern "C" fn rq_abi_version() -> u32 {
    boundary(|| RQ_ABI_VERSION)
}

/// The library version as a static NUL-terminated string, e.g. "rayq 0.1.0".
#[no_mangle]
pub extern "C" fn rq_version_string() -> *const c_char {
    boundary(|| {
        concat!("rayq ", env!("CARGO_PKG_VERSION"), "\0")
            .as_ptr()
            .cast()
    })
}

/// A fixed-size, NUL-terminated message buffer, so that error callbacks get text without allocating.
struct Message {
    buf: [u8; 256],
    len: usize,
}

impl Message {
    fn new(args: core::fmt::Arguments<'_>) -> Message {
        let mut m = Message {
            buf: [0; 256],
            len: 0,
        };
        let _ = core::fmt::write(&mut m, args);
        m
    }

    fn as_ptr(&self) -> *const c_char {
        self.buf.as_ptr().cast()
    }
}

impl core::fmt::Write for Message {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        // Keep the last byte for the terminating NUL; cut at a char boundary.
        for ch in s.chars() {
            let mut tmp = [0u8; 4];
            let bytes = ch.encode_utf8(&mut tmp).as_bytes();
            if self.len + bytes.len() >= self.buf.len() {
                return Ok(());
            }
            self.buf[self.len..self.len + bytes.len()].copy_from_slice(bytes);
            self.len += bytes.len();
        }
        Ok(())
    }
}
