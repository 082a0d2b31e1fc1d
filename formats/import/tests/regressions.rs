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
