//! glTF / GLB importer. The first input byte picks the extension (even: `.glb`, odd:
//! `.gltf`); the rest is written to that file and imported with `import_file` (limits:
//! 1 MiB, 2^20 triangles); `referenced_files` and the instancing import `import_scene` run on
//! it too, and the bytes are also read as a scene file (`SceneFile::parse`). Each extension has its own
//! directory, which also holds the external buffers that seeds refer to (`strip_fan.bin`,
//! `buffer_length_beyond_file.bin`); a URI naming `input.gltf` reads the input itself.
#![no_main]

#[path = "tempfile.rs"]
mod tempfile;

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use mres_import::{import_file, import_scene, referenced_files, ImportLimits, SceneFile};

const LIMITS: ImportLimits = ImportLimits { max_file_bytes: 1 << 20, max_triangles: 1 << 20 };

const BUFFERS: &[(&str, &[u8])] = &[
    ("strip_fan.bin", include_bytes!("../data/strip_fan.bin")),
    ("buffer_length_beyond_file.bin", include_bytes!("../../tests/bad-inputs/buffer_length_beyond_file.bin")),
];

static GLB: OnceLock<PathBuf> = OnceLock::new();
static GLTF: OnceLock<PathBuf> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let Some((&selector, contents)) = data.split_first() else { return };
    let path = if selector % 2 == 0 {
        GLB.get_or_init(|| tempfile::input_path("glb", "glb", BUFFERS))
    } else {
        GLTF.get_or_init(|| tempfile::input_path("gltf", "gltf", BUFFERS))
    };
    tempfile::write(path, contents);
    let _ = import_file(path, &LIMITS);
    let _ = import_scene(path, &LIMITS);
    let _ = referenced_files(path);
    let _ = SceneFile::parse(contents);
});
