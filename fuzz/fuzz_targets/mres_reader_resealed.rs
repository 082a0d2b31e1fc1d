//! `.mres` reader past the checksums: the input is an "unsealed" `.mres` (pages stored
//! uncompressed, checksums ignored; see `reseal.rs`). The harness compresses the pages and
//! recomputes every checksum, then runs `MresFile::parse`, `decode_all` and the LOD selection
//! (`uniform_cut`, `view_cut`) on the result. Seeds are made from real files with
//! `cargo run --example unseal` (see README.md).
#![no_main]

#[path = "reseal.rs"]
mod reseal;

use libfuzzer_sys::fuzz_target;
use mres_format::{uniform_cut, view_cut, MresFile, ViewParams};

fuzz_target!(|data: &[u8]| {
    let Ok(file) = MresFile::parse(reseal::seal(data)) else { return };
    let _ = file.decode_all();
    for threshold in [0.0, 1e-4, 1.0, f32::INFINITY] {
        let _ = uniform_cut(&file.groups, &file.clusters, threshold);
    }
    let view = ViewParams { eye: [0.0, 0.0, 3.0], proj_y: 1.0, viewport_height: 1080.0, z_near: 0.01 };
    let _ = view_cut(&file.groups, &file.clusters, &view, 1.0);
});
