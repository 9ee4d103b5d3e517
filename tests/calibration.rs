//! The committed default blob and the built-in `const` calibration are the same bytes.

use rayq::select::calibration::{Calibration, BLOB_LEN, BUILTIN};

#[test]
fn committed_default_blob_matches_the_builtin_const() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/calib/default.rqcal");
    let mut bytes = [0u8; BLOB_LEN];
    BUILTIN.to_bytes(&mut bytes).unwrap();
    if std::env::var_os("RAYQ_BLESS").is_some() {
        std::fs::write(path, bytes).unwrap();
    }
    let committed = std::fs::read(path).expect("calib/default.rqcal is committed");
    assert_eq!(committed, bytes, "calib/default.rqcal differs from BUILTIN: regenerate with RAYQ_BLESS=1 cargo test --test calibration");
    assert_eq!(Calibration::from_bytes(&committed), Ok(BUILTIN));
}
