//! Importer tests: the bad-input corpus in `tests/bad-inputs/` (every file must fail with
//! its expected error, naming the file, without panicking), good inputs in
//! `formats/import/tests/data/` and generated ones (external buffers), and the real meshes in
//! `../shared/meshes/` (skipped when absent). The truncation / byte-flip fuzz tests are unit
//! tests in `src/lib.rs`: they import from memory, which is fast.

use std::path::{Path, PathBuf};

use mres_import::obj_stream::ObjVertices;
use mres_import::SourceMesh;
use mres_import::{import_file, referenced_files, ImportError, ImportErrorKind, ImportLimits};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

fn bad_input(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/bad-inputs").join(name)
}

fn import(path: &Path) -> Result<SourceMesh, ImportError> {
    import_file(path, &ImportLimits::default())
}

fn import_ok(path: &Path) -> SourceMesh {
    let mesh = import(path).unwrap_or_else(|e| panic!("{e}"));
    check_invariants(&mesh);
    mesh
}

/// The invariants documented on `SourceMesh`.
fn check_invariants(mesh: &SourceMesh) {
    assert_eq!(mesh.indices.len(), 3 * mesh.materials.len());
    let n = mesh.positions.len();
    assert!(mesh.indices.iter().all(|&i| (i as usize) < n));
    assert!(mesh.positions.iter().flatten().all(|c| c.is_finite()));
    if let Some(normals) = &mesh.normals {
        assert_eq!(normals.len(), n);
        for v in normals {
            let length = dot(*v, *v).sqrt();
            assert!(length == 0.0 || (length - 1.0).abs() < 1e-5, "{v:?}");
        }
    }
    if let Some(uvs) = &mesh.uvs {
        assert_eq!(uvs.len(), n);
        assert!(uvs.iter().flatten().all(|c| c.is_finite()));
    }
    for t in mesh.indices.chunks_exact(3) {
        assert!(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
    }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Corner positions of every triangle.
fn triangles(mesh: &SourceMesh) -> Vec<[[f32; 3]; 3]> {
    let p = |i: u32| mesh.positions[i as usize];
    let corners = mesh.indices.chunks_exact(3);
    corners.map(|t| [p(t[0]), p(t[1]), p(t[2])]).collect()
}

/// Area-weighted normal (cross product of two edges) of a triangle.
fn geometric_normal(t: &[[f32; 3]; 3]) -> [f32; 3] {
    cross(sub(t[1], t[0]), sub(t[2], t[0]))
}

// ---------------------------------------------------------------------------------------
// Bad inputs

type KindCheck = fn(&ImportErrorKind) -> bool;

/// Every file of `tests/bad-inputs/` that is imported, with the error it must give.
/// (`.bin` files are buffers of the `.gltf` files; see the README there.)
const BAD_INPUTS: &[(&str, KindCheck)] = &[
    ("empty.obj", |k| matches!(k, ImportErrorKind::EmptyFile)),
    ("truncated.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("nan_position.obj", |k| matches!(k, ImportErrorKind::NonFinitePosition(_))),
    ("inf_position.obj", |k| matches!(k, ImportErrorKind::NonFinitePosition(_))),
    ("index_out_of_range.obj", |k| matches!(k, ImportErrorKind::IndexOutOfRange { .. })),
    ("negative_index_out_of_range.obj", |k| matches!(k, ImportErrorKind::IndexOutOfRange { .. })),
    ("texcoord_index_zero.obj", |k| matches!(k, ImportErrorKind::IndexOutOfRange { .. })),
    ("no_faces.obj", |k| matches!(k, ImportErrorKind::NoTriangles { .. })),
    ("degenerate_only.obj", |k| matches!(k, ImportErrorKind::NoTriangles { degenerate_dropped: 2 })),
    ("lines_only.obj", |k| matches!(k, ImportErrorKind::NoTriangles { .. })),
    ("not_utf8.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("bad_face_token.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("bad_vertex_value.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("bad_texcoord.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("bad_normal.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("w_zero.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("w_overflow.obj", |k| matches!(k, ImportErrorKind::NonFinitePosition(_))),
    ("face_without_vertices.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("bad_face_vertex_slots.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("face_vertex_without_position.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("usemtl_without_name.obj", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("forward_reference_across_objects.obj", |k| {
        matches!(k, ImportErrorKind::IndexOutOfRange { index: 3, count: 2, .. })
    }),
    ("empty.ply", |k| matches!(k, ImportErrorKind::EmptyFile)),
    ("not_ply.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("no_end_header.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("unknown_format.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("truncated_binary.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("vertex_count_beyond_file.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("face_index_out_of_range.ply", |k| matches!(k, ImportErrorKind::IndexOutOfRange { index: 3, count: 3, .. })),
    ("negative_face_index.ply", |k| matches!(k, ImportErrorKind::IndexOutOfRange { index: -1, count: 3, .. })),
    ("nan_position.ply", |k| matches!(k, ImportErrorKind::NonFinitePosition(_))),
    ("double_overflows_float.ply", |k| matches!(k, ImportErrorKind::NonFinitePosition(_))),
    ("missing_z.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("float_face_indices.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("float_list_count.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("duplicate_property.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("duplicate_element.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("negative_list_count.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("huge_face_list.ply", |k| matches!(k, ImportErrorKind::TooLarge(_))),
    ("trailing_data.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("ascii_extra_value.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("ascii_bad_number.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("no_vertex_element.ply", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("point_cloud.ply", |k| matches!(k, ImportErrorKind::NoTriangles { degenerate_dropped: 0 })),
    ("degenerate_only.ply", |k| matches!(k, ImportErrorKind::NoTriangles { degenerate_dropped: 2 })),
    ("empty.glb", |k| matches!(k, ImportErrorKind::EmptyFile)),
    ("truncated.glb", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("glb_header_length_too_small.glb", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("glb_chunk_past_end.glb", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("glb_missing_bin_chunk.glb", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("glb_version_1.glb", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("not_glb.glb", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("bad_json.gltf", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("no_meshes.gltf", |k| matches!(k, ImportErrorKind::NoMeshes)),
    ("points_only.gltf", |k| matches!(k, ImportErrorKind::UnsupportedPrimitiveMode(_))),
    ("lines_only.gltf", |k| matches!(k, ImportErrorKind::UnsupportedPrimitiveMode(_))),
    ("buffer_length_beyond_file.gltf", |k| {
        matches!(k, ImportErrorKind::BufferTooShort { declared: 1_000_000, actual: 44, .. })
    }),
    ("huge_accessor.gltf", |k| matches!(k, ImportErrorKind::InvalidAccessor { .. })),
    ("view_beyond_buffer.gltf", |k| matches!(k, ImportErrorKind::InvalidAccessor { .. })),
    ("uri_escape.gltf", |k| matches!(k, ImportErrorKind::UriOutsideAssetDir(_))),
    ("uri_absolute.gltf", |k| matches!(k, ImportErrorKind::UriOutsideAssetDir(_))),
    ("uri_file_scheme.gltf", |k| matches!(k, ImportErrorKind::UriOutsideAssetDir(_))),
    ("uri_percent_escape.gltf", |k| matches!(k, ImportErrorKind::UriOutsideAssetDir(_))),
    ("uri_http.gltf", |k| matches!(k, ImportErrorKind::UnsupportedUri(_))),
    ("missing_buffer_file.gltf", |k| matches!(k, ImportErrorKind::BufferIo { .. })),
    ("bad_base64.gltf", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("index_out_of_range.gltf", |k| matches!(k, ImportErrorKind::IndexOutOfRange { .. })),
    ("nan_position.gltf", |k| matches!(k, ImportErrorKind::NonFinitePosition(_))),
    ("position_accessor_out_of_range.gltf", |k| matches!(k, ImportErrorKind::IndexOutOfRange { index: 99, .. })),
    ("node_cycle.gltf", |k| matches!(k, ImportErrorKind::Parse(_))),
    ("node_dag_explosion.gltf", |k| matches!(k, ImportErrorKind::TooLarge(_))),
    ("required_extension.gltf", |k| matches!(k, ImportErrorKind::UnsupportedGltfExtension(_))),
    ("zero_count_accessor.gltf", |k| matches!(k, ImportErrorKind::InvalidAccessor { .. })),
    ("stride_smaller_than_element.gltf", |k| matches!(k, ImportErrorKind::InvalidAccessor { .. })),
    ("position_wrong_type.gltf", |k| matches!(k, ImportErrorKind::InvalidAccessor { .. })),
    ("float_indices.gltf", |k| matches!(k, ImportErrorKind::InvalidAccessor { .. })),
];

/// Where the error of each OBJ and PLY bad input must say the problem is (line or byte
/// offset, with what follows it); every OBJ / PLY syntax, index or position error is listed.
const LOCATIONS: &[(&str, &str)] = &[
    ("truncated.obj", "line 5: v line with fewer than 3 numbers"),
    ("nan_position.obj", "line 2: v [NaN, 0.0, 0.0]"),
    ("inf_position.obj", "line 3: v [0.0, inf, 0.0]"),
    ("index_out_of_range.obj", "line 4: vertex position index 4 is out of range (3 available)"),
    ("negative_index_out_of_range.obj", "line 4: vertex position index -4"),
    ("texcoord_index_zero.obj", "line 5: texture coordinate index 0"),
    ("not_utf8.obj", "line 4: not UTF-8 text"),
    ("bad_face_token.obj", "line 4: bad face vertex \"x\""),
    ("bad_vertex_value.obj", "line 4: bad number \"x\" in a v line"),
    ("bad_texcoord.obj", "line 4: vt line with fewer than 2 numbers"),
    ("bad_normal.obj", "line 4: bad number \"one\" in a vn line"),
    ("w_zero.obj", "line 4: v line with w = 0"),
    ("w_overflow.obj", "line 2: v [inf, 0.0, 0.0]"),
    ("face_without_vertices.obj", "line 4: face without vertices"),
    ("bad_face_vertex_slots.obj", "line 6: bad face vertex \"3/1/1/1\""),
    ("face_vertex_without_position.obj", "line 5: face vertex without a position index"),
    ("usemtl_without_name.obj", "line 4: usemtl without a material name"),
    ("forward_reference_across_objects.obj", "line 3: vertex position index 3 is out of range (2 available)"),
    ("not_ply.ply", "line 1: not a PLY file"),
    ("no_end_header.ply", "line 8: the file ends before end_header"),
    ("unknown_format.ply", "line 2: unknown encoding \"binary_middle_endian\""),
    ("truncated_binary.ply", "byte 210: face 0: the file ends here (4 bytes needed, 2 left; truncated?)"),
    ("vertex_count_beyond_file.ply", "line 3: element vertex declares 1000000000 entries"),
    ("face_index_out_of_range.ply", "byte 214: face 0: vertex index 3 is out of range (3 available)"),
    ("negative_face_index.ply", "line 13: face 0: vertex index -1 is out of range"),
    ("nan_position.ply", "byte 181: vertex 1: [NaN, 0.0, 0.0]"),
    ("double_overflows_float.ply", "line 11: vertex 1: [inf, 0.0, 0.0]"),
    ("missing_z.ply", "line 3: element vertex has no scalar property \"z\""),
    ("float_face_indices.ply", "line 7: face property \"vertex_indices\" is not a list of integers"),
    ("float_list_count.ply", "line 8: list \"vertex_indices\" has a floating-point count type"),
    ("duplicate_property.ply", "line 7: element \"vertex\" has a second property \"y\""),
    ("duplicate_element.ply", "line 9: second element named \"vertex\""),
    ("negative_list_count.ply", "byte 204: face 0: negative list length -3"),
    ("trailing_data.ply", "byte 218: 4 bytes after the last element"),
    ("ascii_extra_value.ply", "line 11: vertex 1: more values than the header declares"),
    ("ascii_bad_number.ply", "line 11: vertex 1: \"0,5\" is not a valid float value"),
    ("no_vertex_element.ply", "line 5: the header declares no \"vertex\" element"),
];

#[test]
fn every_bad_input_fails_with_its_error_and_names_the_file() {
    for (name, expected) in BAD_INPUTS {
        let path = bad_input(name);
        assert!(path.is_file(), "{name} is missing from tests/bad-inputs");
        let err = match import(&path) {
            Ok(mesh) => panic!("{name}: imported {} triangles", mesh.triangle_count()),
            Err(err) => err,
        };
        let message = err.to_string();
        assert!(message.starts_with(&path.display().to_string()), "{name}: message does not name the file: {message}");
        assert_eq!(err.path, path);
        assert!(expected(&err.kind), "{name}: unexpected error: {message}");
        println!("{name}: {}", err.kind);
        let located = matches!(
            err.kind,
            ImportErrorKind::Parse(_) | ImportErrorKind::IndexOutOfRange { .. } | ImportErrorKind::NonFinitePosition(_)
        );
        let text_format = name.ends_with(".obj") || name.ends_with(".ply");
        match LOCATIONS.iter().find(|(n, _)| n == name) {
            Some((_, location)) => assert!(message.contains(location), "{name}: expected {location:?} in: {message}"),
            None => assert!(!(located && text_format), "{name}: LOCATIONS has no entry for: {message}"),
        }
    }
}

/// The streaming OBJ reader (used for large files) rejects every bad OBJ with the same message.
#[test]
fn streaming_obj_reader_gives_the_same_errors() {
    // Degenerate triangles are dropped by the whole-file importer only (pass 1 leaves them to
    // its caller).
    for (name, _) in BAD_INPUTS.iter().filter(|(n, _)| n.ends_with(".obj") && !n.starts_with("degenerate")) {
        let path = bad_input(name);
        let whole = import(&path).unwrap_err().to_string();
        let streamed = match ObjVertices::read(&path, &ImportLimits::default()) {
            Ok(v) => panic!("{name}: the streaming reader accepted it ({} triangles)", v.triangles),
            Err(err) => err.to_string(),
        };
        assert_eq!(streamed, whole, "{name}");
    }
}

#[test]
fn bad_input_corpus_and_readme_list_the_same_files() {
    let dir = bad_input("");
    let readme = std::fs::read_to_string(dir.join("README.md")).unwrap();
    let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|entry| entry.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name != "README.md" && !name.ends_with(".bin"))
        .collect();
    on_disk.sort();
    let mut tested: Vec<String> = BAD_INPUTS.iter().map(|(n, _)| n.to_string()).collect();
    tested.sort();
    assert_eq!(on_disk, tested, "files in tests/bad-inputs vs. BAD_INPUTS");
    for name in &tested {
        assert!(readme.contains(&format!("`{name}`")), "README.md does not list {name}");
    }
}

#[test]
fn missing_file_and_unknown_extension() {
    let missing = data("does_not_exist.obj");
    let err = import(&missing).unwrap_err();
    assert!(matches!(err.kind, ImportErrorKind::Io(_)), "{err}");
    assert!(err.to_string().contains("does_not_exist.obj"));
    let err = import(&data("two_objects.mtl")).unwrap_err();
    assert!(matches!(err.kind, ImportErrorKind::UnsupportedExtension), "{err}");
    assert!(referenced_files(&missing).is_err());
}

#[test]
fn limits_are_enforced() {
    let tiny_file = ImportLimits { max_file_bytes: 100, ..ImportLimits::default() };
    let one_triangle = ImportLimits { max_triangles: 1, ..ImportLimits::default() };
    for name in ["cube_uv_seams.obj", "strip_fan.gltf"] {
        for limits in [tiny_file, one_triangle] {
            let err = import_file(&data(name), &limits).unwrap_err();
            assert!(matches!(err.kind, ImportErrorKind::TooLarge(_)), "{err}");
        }
    }
    // The limit applies to external buffers too.
    let dir = tempfile::tempdir().unwrap();
    let gltf = write_external_buffer_gltf(dir.path());
    let limits = ImportLimits { max_file_bytes: 40, ..ImportLimits::default() };
    let err = import_file(&gltf, &limits).unwrap_err();
    assert!(matches!(err.kind, ImportErrorKind::TooLarge(_)), "{err}");
}

// ---------------------------------------------------------------------------------------
// Good OBJ inputs

#[test]
fn obj_cube_with_uv_seams_splits_vertices() {
    let mesh = import_ok(&data("cube_uv_seams.obj"));
    assert_eq!(mesh.triangle_count(), 12);
    assert_eq!(mesh.positions.len(), 24, "8 positions, each in 3 UV tiles");
    assert_eq!(mesh.degenerate_dropped, 0);
    assert!(mesh.normals.is_none());
    assert!(mesh.uvs.is_some());
    // Each quad face (two consecutive triangles) has 4 vertices of its own: no vertex is
    // shared across a UV seam.
    let faces: Vec<Vec<u32>> = mesh
        .indices
        .chunks(6)
        .map(|face| {
            let mut vertices = face.to_vec();
            vertices.sort();
            vertices.dedup();
            vertices
        })
        .collect();
    assert!(faces.iter().all(|f| f.len() == 4));
    let mut all: Vec<u32> = faces.concat();
    all.sort();
    all.dedup();
    assert_eq!(all.len(), 24);
    // Closed and consistently wound: every triangle faces away from the centre.
    for t in triangles(&mesh) {
        let centroid = [0, 1, 2].map(|k| (t[0][k] + t[1][k] + t[2][k]) / 3.0);
        let outward = sub(centroid, [0.5; 3]);
        assert!(dot(geometric_normal(&t), outward) > 0.0);
    }
    assert_eq!(mesh.materials, vec![0; 12]);
}

#[test]
fn obj_two_objects_materials_by_first_use() {
    for name in ["two_objects.obj", "missing_mtl.obj"] {
        let mesh = import_ok(&data(name));
        assert_eq!(mesh.triangle_count(), 4, "{name}");
        // red (first used) = 0, green = 1.
        assert_eq!(mesh.materials, vec![0, 0, 1, 0], "{name}");
        let first_object_x = triangles(&mesh)[..2].iter().flatten().all(|p| p[0] <= 1.0);
        assert!(first_object_x, "{name}: the first object's triangles come first");
    }
    assert_eq!(referenced_files(&data("two_objects.obj")).unwrap(), vec![data("two_objects.mtl")]);
    assert_eq!(referenced_files(&data("missing_mtl.obj")).unwrap(), Vec::<PathBuf>::new());
}

#[test]
fn obj_quads_and_ngons_are_triangulated() {
    let mesh = import_ok(&data("quads_ngon.obj"));
    assert_eq!(mesh.triangle_count(), 2 + 3 + 4);
    let area: f32 = triangles(&mesh)
        .iter()
        .map(|t| {
            let n = geometric_normal(t);
            assert!(n[2] > 0.0, "winding kept");
            n[2] / 2.0
        })
        .sum();
    assert!((area - 3.75).abs() < 1e-5, "area {area}");
    assert!(mesh.normals.unwrap().iter().all(|n| *n == [0.0, 0.0, 1.0]));
}

#[test]
fn obj_faces_of_one_or_two_vertices_are_counted_as_dropped() {
    // Such a face has no triangle; both readers count it, so that the bake reports it.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("short_faces.obj");
    std::fs::write(&path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\nf 3\n").unwrap();
    let mesh = import_ok(&path);
    assert_eq!((mesh.triangle_count(), mesh.degenerate_dropped), (1, 2));
    let streamed = ObjVertices::read(&path, &ImportLimits::default()).unwrap();
    assert_eq!((streamed.triangles, streamed.short_faces), (1, 2));
    // With no triangle at all, the error counts them.
    std::fs::write(&path, "v 0 0 0\nv 1 0 0\nf 1 2\n").unwrap();
    let err = import(&path).unwrap_err();
    assert!(matches!(err.kind, ImportErrorKind::NoTriangles { degenerate_dropped: 1 }), "{err}");
    let err = ObjVertices::read(&path, &ImportLimits::default()).unwrap_err();
    assert!(matches!(err.kind, ImportErrorKind::NoTriangles { degenerate_dropped: 1 }), "{err}");
}

#[test]
fn obj_attribute_missing_on_some_faces_is_dropped() {
    let mesh = import_ok(&data("partial_uvs.obj"));
    assert_eq!(mesh.triangle_count(), 2);
    assert!(mesh.uvs.is_none());
    let normals = mesh.normals.unwrap();
    assert!(normals.iter().all(|n| *n == [0.0, 0.0, 1.0]), "renormalised");
}

#[test]
fn obj_vertex_colours_on_some_vertices_are_ignored() {
    // tobj fails on colours that only some vertices have; the importer blanks them.
    let mesh = import_ok(&data("partial_vertex_colours.obj"));
    assert_eq!(mesh.triangle_count(), 2);
    assert_eq!(mesh.positions[0], [0.0, 0.0, 0.0]);
}

#[test]
fn obj_with_malformed_mtl_imports() {
    let mesh = import_ok(&data("broken_mtl.obj"));
    assert_eq!(mesh.materials, vec![0]);
    assert_eq!(referenced_files(&data("broken_mtl.obj")).unwrap(), vec![data("broken_mtl.mtl")]);
}

// ---------------------------------------------------------------------------------------
// Good glTF inputs

#[test]
fn gltf_two_primitives_under_a_node_transform() {
    let path = data("two_primitives_transform.gltf");
    let mesh = import_ok(&path);
    assert_eq!(mesh.triangle_count(), 2);
    // Node: scale 2, then translate x by 10.
    let expected =
        [[10.0, 0.0, 0.0], [12.0, 0.0, 0.0], [10.0, 2.0, 0.0], [10.0, 0.0, 2.0], [12.0, 0.0, 2.0], [10.0, 2.0, 2.0]];
    assert_eq!(mesh.positions, expected);
    // Primitive 0 has material 0; primitive 1 none: one past the last material.
    assert_eq!(mesh.materials, vec![0, 1]);
    // Only primitive 0 has TEXCOORD_0: dropped; both have NORMAL.
    assert!(mesh.uvs.is_none());
    assert!(mesh.normals.unwrap().iter().all(|n| *n == [0.0, 0.0, 1.0]));
    assert!(referenced_files(&path).unwrap().is_empty(), "data: URIs only");
}

#[test]
fn gltf_strip_and_fan() {
    let mesh = import_ok(&data("strip_fan.gltf"));
    assert_eq!(mesh.triangle_count(), 3 + 3);
    let tris = triangles(&mesh);
    for t in &tris {
        assert!(geometric_normal(t)[2] > 0.0, "counter-clockwise: {t:?}");
    }
    // Every fan triangle has the centre (3.5, 0.5), stored last, as a corner.
    assert!(tris[3..].iter().all(|t| t.contains(&[3.5, 0.5, 0.0])));
    let area: f32 = tris.iter().map(|t| geometric_normal(t)[2] / 2.0).sum();
    assert!((area - 2.25).abs() < 1e-5, "strip 1.5 + fan 0.75, got {area}");
}

#[test]
fn gltf_non_indexed_triangles() {
    let mesh = import_ok(&data("non_indexed.gltf"));
    assert_eq!(mesh.triangle_count(), 2);
    assert_eq!(mesh.indices, vec![0, 1, 2, 3, 4, 5]);
}

#[test]
fn gltf_instances_flattened_and_mirror_keeps_winding() {
    let mesh = import_ok(&data("mirrored_instances.gltf"));
    assert_eq!(mesh.triangle_count(), 2, "one mesh under two nodes");
    let normals = mesh.normals.clone().unwrap();
    for (t, corners) in triangles(&mesh).iter().zip(mesh.indices.chunks_exact(3)) {
        assert!(t.iter().all(|p| p[2] == 5.0), "parent translation applied");
        let n = normals[corners[0] as usize];
        assert!(dot(geometric_normal(t), n) > 0.0, "winding agrees with normal");
    }
    assert!(mesh.positions.iter().any(|p| p[0] < 0.0), "mirrored instance");
}

#[test]
fn gltf_interleaved_attributes_and_sparse_positions() {
    let mesh = import_ok(&data("interleaved_sparse.gltf"));
    assert_eq!(mesh.triangle_count(), 2);
    // byteStride 24: positions and normals interleaved; vertex 2 replaced by the sparse
    // accessor's value.
    let expected = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 2.0, 0.0], [0.0, 1.0, 0.0]];
    assert_eq!(mesh.positions, expected);
    assert_eq!(mesh.normals.unwrap(), vec![[0.0, 0.0, 1.0]; 4]);
}

#[test]
fn gltf_without_scenes_imports_every_mesh() {
    let mesh = import_ok(&data("no_scenes.gltf"));
    assert_eq!(mesh.triangle_count(), 2);
    assert!(mesh.positions.iter().any(|p| p[2] == 3.0));
}

/// One triangle: 36 bytes of positions, then 3 u16 indices padded to 8 bytes.
fn triangle_buffer() -> Vec<u8> {
    let positions = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let mut bytes: Vec<u8> = positions.iter().flat_map(|c| c.to_le_bytes()).collect();
    bytes.extend([0u16, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
    bytes.extend([0, 0]);
    bytes
}

/// glTF JSON for [`triangle_buffer`]; `uri` is the buffer URI, or none for GLB's BIN chunk.
fn triangle_json(uri: Option<&str>) -> String {
    let uri = uri.map(|u| format!(r#", "uri": "{u}""#)).unwrap_or_default();
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
        "nodes": [{{"mesh": 0, "translation": [0, 0, 1]}}],
        "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
        "buffers": [{{"byteLength": 44{uri}}}],
        "bufferViews": [{{"buffer": 0, "byteLength": 36}},
                        {{"buffer": 0, "byteOffset": 36, "byteLength": 6}}],
        "accessors": [
          {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
            "min": [0, 0, 0], "max": [1, 1, 0]}},
          {{"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}}]}}"#
    )
}

/// Writes `scene.gltf` and `sub dir/tri data.bin` (referenced percent-encoded) into `dir`.
fn write_external_buffer_gltf(dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir.join("sub dir")).unwrap();
    std::fs::write(dir.join("sub dir/tri data.bin"), triangle_buffer()).unwrap();
    let gltf = dir.join("scene.gltf");
    std::fs::write(&gltf, triangle_json(Some("sub%20dir/tri%20data.bin"))).unwrap();
    gltf
}

#[test]
fn gltf_external_buffer_with_percent_encoded_uri() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = write_external_buffer_gltf(dir.path());
    let mesh = import_ok(&gltf);
    assert_eq!(mesh.positions, [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]]);
    assert_eq!(referenced_files(&gltf).unwrap(), vec![dir.path().join("sub dir").join("tri data.bin")]);
    // The buffer file gone: an error naming the glTF file and the URI.
    std::fs::remove_file(dir.path().join("sub dir/tri data.bin")).unwrap();
    let err = import(&gltf).unwrap_err();
    assert!(matches!(err.kind, ImportErrorKind::BufferIo { .. }), "{err}");
    assert!(err.to_string().contains("scene.gltf") && err.to_string().contains("tri%20data"));
}

#[test]
fn glb_with_binary_chunk() {
    // triangle.glb: the glTF of `triangle_json` with the buffer in the BIN chunk.
    let path = data("triangle.glb");
    let mesh = import_ok(&path);
    assert_eq!(mesh.positions, [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]]);
    assert_eq!(mesh.materials, vec![0], "no materials: index 0 = one past the last");
    assert!(mesh.normals.is_none() && mesh.uvs.is_none());
    assert!(referenced_files(&path).unwrap().is_empty());
}

// ---------------------------------------------------------------------------------------
// Good PLY inputs

/// Position, normal and UV of a triangle corner.
type CornerAttributes = ([f32; 3], [f32; 3], [f32; 2]);

/// Each triangle's corners as (position, normal, UV), for comparing meshes whose vertices are
/// numbered differently (tobj numbers them in order of first use).
fn corners(mesh: &SourceMesh) -> Vec<[CornerAttributes; 3]> {
    let corner = |i: u32| {
        let i = i as usize;
        let normal = mesh.normals.as_ref().map_or([9.0; 3], |n| n[i]);
        let uv = mesh.uvs.as_ref().map_or([9.0; 2], |u| u[i]);
        (mesh.positions[i], normal, uv)
    };
    mesh.indices.chunks_exact(3).map(|t| [corner(t[0]), corner(t[1]), corner(t[2])]).collect()
}

#[test]
fn ply_cube_in_every_encoding_equals_the_obj() {
    let obj = import_ok(&data("cube.obj"));
    assert_eq!(obj.triangle_count(), 12);
    let expected = corners(&obj);
    for name in ["cube_ascii.ply", "cube_binary_le.ply", "cube_binary_be.ply"] {
        let ply = import_ok(&data(name));
        assert_eq!(ply.positions.len(), 8, "{name}: one vertex per PLY vertex");
        assert_eq!(ply.materials, vec![0; 12], "{name}");
        assert_eq!(ply.degenerate_dropped, 0, "{name}");
        let got = corners(&ply);
        assert_eq!(got.len(), expected.len(), "{name}");
        for (g, e) in got.iter().zip(&expected) {
            for k in 0..3 {
                assert_eq!((g[k].0, g[k].2), (e[k].0, e[k].2), "{name}: position and UV");
                // The OBJ's normals went through 9 decimal digits: equal to within rounding.
                assert!((0..3).all(|c| (g[k].1[c] - e[k].1[c]).abs() < 1e-6), "{name}: normal {g:?} {e:?}");
            }
        }
        assert!(referenced_files(&data(name)).unwrap().is_empty());
    }
}

#[test]
fn ply_faces_before_vertices_pentagon_and_texture_uv() {
    let mesh = import_ok(&data("faces_first_pentagon.ply"));
    assert_eq!(mesh.triangle_count(), 3, "pentagon fan; the two-index face is skipped");
    assert_eq!(mesh.indices, vec![0, 1, 2, 0, 2, 3, 0, 3, 4]);
    let area: f32 = triangles(&mesh).iter().map(|t| geometric_normal(t)[2] / 2.0).sum();
    assert!((area - 5.0).abs() < 1e-6, "area {area}");
    assert_eq!(mesh.uvs.unwrap()[4], [0.0, 0.5], "texture_u / texture_v");
    assert!(mesh.normals.is_none());
}

#[test]
fn ply_limits_are_enforced() {
    let one_triangle = ImportLimits { max_triangles: 1, ..ImportLimits::default() };
    let tiny_file = ImportLimits { max_file_bytes: 100, ..ImportLimits::default() };
    for limits in [one_triangle, tiny_file] {
        let err = import_file(&data("cube_binary_le.ply"), &limits).unwrap_err();
        assert!(matches!(err.kind, ImportErrorKind::TooLarge(_)), "{err}");
    }
    // Vertices: three times the triangle limit.
    let two_vertices = ImportLimits { max_triangles: 2, ..ImportLimits::default() };
    let err = import_file(&data("cube_ascii.ply"), &two_vertices).unwrap_err();
    assert!(err.to_string().contains("8 vertices, the limit is 6"), "{err}");
}

// ---------------------------------------------------------------------------------------
// Real meshes (skipped where ../shared is not checked out)

fn shared_mesh(name: &str) -> Option<PathBuf> {
    let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/meshes")).join(name);
    if path.is_file() {
        Some(path)
    } else {
        println!("skipped: {} is not present", path.display());
        None
    }
}

fn check_real_mesh(name: &str, triangles: usize) {
    let Some(path) = shared_mesh(name) else {
        return;
    };
    let mesh = import_ok(&path);
    let imported = mesh.triangle_count();
    assert!(
        imported <= triangles && imported + 8 >= triangles,
        "{name}: {imported} triangles ({} degenerate dropped), expected about {triangles}",
        mesh.degenerate_dropped
    );
    assert_eq!(imported as u64 + mesh.degenerate_dropped, triangles as u64);
    let (lo, hi) = mesh.bounds().unwrap();
    assert!((0..3).all(|k| lo[k] < hi[k]), "{name}: flat bounds {lo:?} {hi:?}");
}

#[test]
fn real_stanford_bunny_obj() {
    check_real_mesh("stanford_bunny_zipper.obj", 69_451);
}

#[test]
fn real_flight_helmet_glb() {
    check_real_mesh("flight_helmet.glb", 94_722);
}

#[test]
fn real_nefertiti_glb() {
    check_real_mesh("nefertiti.glb", 99_938);
}
