//! PLY importer: the input is written to a `.ply` file (see `tempfile.rs`) and imported with
//! `import_file` (limits: 1 MiB, 2^20 triangles); `referenced_files` runs on it too. Beyond
//! "no panic": an accepted mesh satisfies `SourceMesh`'s invariants, and every syntax, index
//! or position error says where (a line or byte offset).
#![no_main]

#[path = "tempfile.rs"]
mod tempfile;

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use mres_import::{import_file, referenced_files, ImportErrorKind, ImportLimits};

const LIMITS: ImportLimits = ImportLimits { max_file_bytes: 1 << 20, max_triangles: 1 << 20 };

static PATH: OnceLock<PathBuf> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let path = PATH.get_or_init(|| tempfile::input_path("ply", "ply", &[]));
    tempfile::write(path, data);
    let _ = referenced_files(path);
    match import_file(path, &LIMITS) {
        Ok(mesh) => {
            let n = mesh.positions.len();
            assert_eq!(mesh.indices.len(), 3 * mesh.materials.len());
            assert!(mesh.indices.iter().all(|&i| (i as usize) < n));
            assert!(mesh.positions.iter().flatten().all(|c| c.is_finite()));
            assert!(mesh.materials.iter().all(|&m| m == 0));
            assert!(mesh.normals.as_ref().is_none_or(|v| v.len() == n));
            assert!(mesh.uvs.as_ref().is_none_or(|v| v.len() == n));
        }
        Err(err) => {
            let located = matches!(
                err.kind,
                ImportErrorKind::Parse(_)
                    | ImportErrorKind::IndexOutOfRange { .. }
                    | ImportErrorKind::NonFinitePosition(_)
            );
            let message = err.to_string();
            assert!(!located || message.contains("line ") || message.contains("byte "), "{message}");
        }
    }
});
