//! OBJ importer: the input is written to a `.obj` file (see `tempfile.rs`) and imported with
//! `import_file` (limits: 1 MiB, 2^20 triangles); `referenced_files` runs on it too.
//! Differential: whenever the whole-file (tobj) import succeeds, the streaming reader
//! (`obj_stream`, used for large files) must succeed too and yield the same triangles that are
//! not degenerate (three distinct positions). Every syntax, index or position error names its
//! line.
#![no_main]

#[path = "tempfile.rs"]
mod tempfile;

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use mres_import::obj_stream::ObjVertices;
use mres_import::{import_file, referenced_files, ImportErrorKind, ImportLimits};

const LIMITS: ImportLimits = ImportLimits { max_file_bytes: 1 << 20, max_triangles: 1 << 20 };

static PATH: OnceLock<PathBuf> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    // A material library next to the input, so `mtllib x.mtl` lines can resolve.
    let path = PATH.get_or_init(|| {
        tempfile::input_path(
            "obj",
            "obj",
            &[("x.mtl", include_bytes!("../../formats/import/tests/data/two_objects.mtl"))],
        )
    });
    tempfile::write(path, data);
    let whole = import_file(path, &LIMITS);
    let _ = referenced_files(path);
    let streamed = ObjVertices::read(path, &LIMITS);
    for err in [whole.as_ref().err(), streamed.as_ref().err()].into_iter().flatten() {
        let located = matches!(
            err.kind,
            ImportErrorKind::Parse(_) | ImportErrorKind::IndexOutOfRange { .. } | ImportErrorKind::NonFinitePosition(_)
        );
        assert!(!located || err.to_string().contains("line "), "no line number: {err}");
    }
    if let Ok(mesh) = whole {
        let v = streamed.expect("the streaming reader accepts what the whole-file importer accepts");
        let mut triangles = Vec::new();
        v.for_each_triangle(path, |t, _| {
            let p = t.map(|c| v.positions[c.v as usize]);
            if p[0] != p[1] && p[1] != p[2] && p[0] != p[2] {
                triangles.push(p);
            }
        })
        .expect("pass 2 succeeds after pass 1");
        let expected: Vec<[[f32; 3]; 3]> =
            mesh.indices.chunks_exact(3).map(|t| [0, 1, 2].map(|k| mesh.positions[t[k] as usize])).collect();
        assert_eq!(triangles, expected, "streamed and whole imports differ");
    }
});
