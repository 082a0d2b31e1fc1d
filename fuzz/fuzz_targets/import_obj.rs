//! OBJ importer: the input is written to a `.obj` file (see `tempfile.rs`) and imported with
//! `import_file` (limits: 1 MiB, 2^20 triangles); `referenced_files` runs on it too.
#![no_main]

#[path = "tempfile.rs"]
mod tempfile;

use std::path::PathBuf;
use std::sync::OnceLock;

use formats::import::{import_file, referenced_files, ImportLimits};
use libfuzzer_sys::fuzz_target;

const LIMITS: ImportLimits = ImportLimits { max_file_bytes: 1 << 20, max_triangles: 1 << 20 };

static PATH: OnceLock<PathBuf> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    // A material library next to the input, so `mtllib x.mtl` lines can resolve.
    let path = PATH.get_or_init(|| {
        tempfile::input_path("obj", "obj", &[("x.mtl", include_bytes!("../../formats/tests/data/two_objects.mtl"))])
    });
    tempfile::write(path, data);
    let _ = import_file(path, &LIMITS);
    let _ = referenced_files(path);
});
