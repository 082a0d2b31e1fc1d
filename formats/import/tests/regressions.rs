//! Regression tests for problems found by fuzzing (fuzz/README.md).

use mres_import::{import_file, ImportErrorKind, ImportLimits};
use std::path::Path;

/// Found by reading the code while fuzzing (fuzz/README.md, "Results"): a 1.2 KB glTF whose 24 nodes each list the next one twice expands to
/// 2^24 − 1 instances. The importer used to build all of them (1.2 GB) before checking the
/// triangle limit; it now counts instances without expanding and fails at once.
#[test]
fn node_graph_explosion_is_rejected_before_expansion() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/node_dag_2pow24.gltf");
    let limits = ImportLimits { max_file_bytes: 1 << 20, max_triangles: 1 << 20 };
    let err = import_file(&path, &limits).expect_err("must be rejected");
    assert!(matches!(err.kind, ImportErrorKind::TooLarge(_)), "{err}");
    assert!(err.to_string().contains("node_dag_2pow24.gltf"), "{err}");
}

/// Found by fuzzing (fuzz/artifacts-found/import_obj-double-bom-*.obj): an OBJ starting with two
/// byte-order marks. The whole-file importer strips one, so its first line starts with the
/// second and is a line it does not know; the streaming reader stripped both and read a `v`
/// line, so the two readers disagreed on the vertices (and on whether the file is valid). Both
/// now blank exactly one, so that a bare `usemtl` after it also reads alike.
#[test]
fn double_byte_order_mark_reads_alike_in_both_obj_readers() {
    use mres_import::obj_stream::ObjVertices;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("double_bom.obj");
    let text = "\u{feff}\u{feff}v w0 0 0\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    std::fs::write(&path, text).unwrap();
    let limits = ImportLimits::default();
    let whole = import_file(&path, &limits).expect("the whole-file importer ignores the unknown first line");
    let streamed = ObjVertices::read(&path, &limits).expect("so does the streaming reader");
    assert_eq!(streamed.positions, whole.positions);
    let mut corners = Vec::new();
    streamed.for_each_triangle(&path, |t, _| corners.extend(t.map(|c| c.v))).unwrap();
    assert_eq!(corners, whole.indices);
    // The blanked mark leaves a line starting with spaces; tobj's (and so both readers') name
    // of a "   usemtl" line is "usemtl".
    std::fs::write(&path, "\u{feff}usemtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let whole = import_file(&path, &limits).expect("whole-file import");
    let streamed = ObjVertices::read(&path, &limits).expect("streaming reader");
    assert_eq!(streamed.positions, whole.positions);
}
