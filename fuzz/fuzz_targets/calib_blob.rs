//! The calibration blob parser on arbitrary bytes: it never panics, and whatever it accepts writes
//! back to exactly the bytes a re-read accepts again (a round trip of the accepted layout).
//!
//!     cargo +nightly fuzz run calib_blob fuzz/corpus/calib_blob
#![no_main]

use libfuzzer_sys::fuzz_target;
use rayq::select::calibration::{Calibration, BLOB_LEN};

fuzz_target!(|data: &[u8]| {
    if let Ok(c) = Calibration::from_bytes(data) {
        let mut out = [0u8; BLOB_LEN];
        let n = c
            .to_bytes(&mut out)
            .expect("an accepted calibration writes");
        assert_eq!(Calibration::from_bytes(&out[..n]), Ok(c));
    }
});
