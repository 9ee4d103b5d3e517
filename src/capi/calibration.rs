//! Calibration functions of the C ABI.

use core::ptr;

use super::boundary;
use super::types::*;
use crate::budget::try_box;
use crate::select::calibration::{Calibration, BLOB_LEN, BUILTIN};

static BUILTIN_STATIC: Calibration = BUILTIN;

fn builtin_ptr() -> *const rq_calibration {
    &BUILTIN_STATIC as *const Calibration as *const rq_calibration
}

/// Reads a calibration blob (format in the README). Every check (magic, version, length, CRC-32,
/// each value finite and in range) passes before `*out` is written; each failure has its own status.
///
/// # Safety
/// `data` is readable for `len` bytes; `out` is writable.
#[no_mangle]
pub unsafe extern "C" fn rq_calibration_from_bytes(
    data: *const u8,
    len: usize,
    out: *mut *mut rq_calibration,
) -> rq_status {
    boundary(|| {
        if data.is_null() || out.is_null() {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        }
        // SAFETY: data is readable for len bytes (contract).
        let bytes = unsafe { core::slice::from_raw_parts(data, len) };
        match Calibration::from_bytes(bytes) {
            Ok(c) => match try_box(c) {
                Some(b) => {
                    // SAFETY: out is writable (contract).
                    unsafe {
                        out.write_unaligned(alloc::boxed::Box::into_raw(b) as *mut rq_calibration)
                    };
                    rq_status::RQ_STATUS_OK
                }
                None => rq_status::RQ_STATUS_OUT_OF_MEMORY,
            },
            Err(e) => e.into(),
        }
    })
}

/// Writes the blob of `calib` into `buf` (capacity `cap`); `*written` receives its length. A buffer
/// that is too small gives `RQ_STATUS_INVALID_ARGUMENT` and writes nothing. Size query: with
/// `buf == NULL` and `cap == 0`, only `*written` receives the size the blob needs.
///
/// # Safety
/// `calib` is a live handle; `buf` NULL or writable for `cap` bytes; `written` writable.
#[no_mangle]
pub unsafe extern "C" fn rq_calibration_to_bytes(
    calib: *const rq_calibration,
    buf: *mut u8,
    cap: usize,
    written: *mut usize,
) -> rq_status {
    boundary(|| {
        if calib.is_null() || written.is_null() {
            return rq_status::RQ_STATUS_NULL_ARGUMENT;
        }
        if buf.is_null() {
            if cap != 0 {
                return rq_status::RQ_STATUS_NULL_ARGUMENT;
            }
            // SAFETY: written is writable (contract).
            unsafe { written.write_unaligned(BLOB_LEN) };
            return rq_status::RQ_STATUS_OK;
        }
        // SAFETY: calib is a live handle pointing to a Calibration; buf is writable for cap bytes.
        let (c, out) = unsafe {
            (
                &*(calib as *const Calibration),
                core::slice::from_raw_parts_mut(buf, cap),
            )
        };
        match c.to_bytes(out) {
            Ok(n) => {
                // SAFETY: written is writable (contract).
                unsafe { written.write_unaligned(n) };
                rq_status::RQ_STATUS_OK
            }
            Err(e) => e.into(),
        }
    })
}

/// The calibration compiled into the library (static; never freed).
#[no_mangle]
pub extern "C" fn rq_calibration_builtin() -> *const rq_calibration {
    boundary(builtin_ptr)
}

/// Frees a calibration from `rq_calibration_from_bytes`; NULL and the built-in one are ignored.
///
/// # Safety
/// `calib` is NULL, the built-in handle, or a live handle not used afterwards.
#[no_mangle]
pub unsafe extern "C" fn rq_calibration_free(calib: *mut rq_calibration) {
    boundary(|| {
        if !calib.is_null() && !ptr::eq(calib as *const rq_calibration, builtin_ptr()) {
            // SAFETY: the handle is a Box<Calibration> from rq_calibration_from_bytes (contract).
            drop(unsafe { alloc::boxed::Box::from_raw(calib as *mut Calibration) });
        }
    })
}
