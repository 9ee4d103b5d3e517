//! Tells the C API test (`tests/c_api.rs`) which target triple to hand to the `cc` crate.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!(
        "cargo:rustc-env=RAYQ_BUILD_TARGET={}",
        std::env::var("TARGET").unwrap()
    );
}
