//! The checked-in C header equals what cbindgen generates from the crate's source now, so the
//! header an engine compiles against cannot drift from the library.
//!
//! `MRES_BLESS=1 cargo test -p mres-capi --test header` rewrites `include/mres.h`.

use std::path::Path;

#[test]
fn checked_in_header_is_the_generated_one() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).expect("cbindgen.toml parses");
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("src/lib.rs"))
        .generate()
        .expect("cbindgen generates the header");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let path = dir.join("include/mres.h");
    if std::env::var_os("MRES_BLESS").is_some() {
        std::fs::write(&path, &generated).expect("writes include/mres.h");
    }
    let checked_in = std::fs::read(&path).unwrap_or_default();
    assert!(
        checked_in == generated,
        "include/mres.h differs from the header cbindgen generates from src/; run \
         `MRES_BLESS=1 cargo test -p mres-capi --test header` and commit it"
    );
}
