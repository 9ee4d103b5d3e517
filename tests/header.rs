//! `include/rayq.h` must be exactly what cbindgen generates from `src/capi` today.

use std::path::Path;

#[test]
fn committed_header_is_fresh() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(root.join("cbindgen.toml")).expect("cbindgen.toml");
    let bindings = cbindgen::Builder::new()
        .with_src(root.join("src/capi/mod.rs"))
        .with_config(config)
        .generate()
        .expect("cbindgen failed to generate the header");
    let mut fresh = Vec::new();
    bindings.write(&mut fresh);
    let fresh = String::from_utf8(fresh).expect("header is UTF-8");
    let path = root.join("include/rayq.h");
    if std::env::var_os("RAYQ_BLESS").is_some() {
        std::fs::write(&path, &fresh).expect("write include/rayq.h");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == fresh,
        "include/rayq.h is stale: regenerate it with `RAYQ_BLESS=1 cargo test --test header` and commit it"
    );
}
