//! glTF files that require extensions: what gltfpack writes (KHR_mesh_quantization,
//! EXT_meshopt_compression with its filters) imports as the float mesh it came from, a
//! required extension that changes nothing read here (materials, textures) imports, and one
//! that could change the geometry is refused. The `gltfpack_*.glb` files in `tests/data/`
//! are `mres generate seamed-sphere 6` (432 triangles, normals and UVs) written by gltfpack
//! 1.3: `-noq -kv` (`float`), `-kv` (`quantized`: u16 positions under a scaling node, i8
//! normals, u16 UVs), `-kv -vpn` (`quantized_normalized`), `-kv -cc` (`meshopt`: the quantized
//! views compressed, normals through the octahedral filter) and `-kv -cc -vpf -vtf -vnf`
//! (`meshopt_float`: float views through the exponential filter).

use std::path::{Path, PathBuf};

use mres_import::{import_file, ImportErrorKind, ImportLimits, SourceMesh};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

fn import(path: &Path) -> Result<SourceMesh, ImportErrorKind> {
    import_file(path, &ImportLimits::default()).map_err(|e| e.kind)
}

fn distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>().sqrt()
}

/// Asserts that `mesh` is `reference` up to the given error per attribute (UVs compared only
/// with `Some`): every vertex has a reference vertex that close in position, normal and UV,
/// and every triangle, its corners so matched, is a triangle of the reference (in any
/// rotation).
fn assert_matches(
    name: &str,
    mesh: &SourceMesh,
    reference: &SourceMesh,
    (position, normal, uv): (f32, f32, Option<f32>),
) {
    assert_eq!(mesh.triangle_count(), reference.triangle_count(), "{name}: triangles");
    let (normals, uvs) = (mesh.normals.as_ref().expect("normals"), mesh.uvs.as_ref().expect("UVs"));
    let (reference_normals, reference_uvs) = (reference.normals.as_ref().unwrap(), reference.uvs.as_ref().unwrap());
    let matched: Vec<u32> = (0..mesh.positions.len())
        .map(|v| {
            let near = |r: &usize| {
                distance(&mesh.positions[v], &reference.positions[*r]) <= position
                    && distance(&normals[v], &reference_normals[*r]) <= normal
                    && uv.is_none_or(|uv| distance(&uvs[v], &reference_uvs[*r]) <= uv)
            };
            let found = (0..reference.positions.len()).find(near);

            found.unwrap_or_else(|| {
                panic!("{name}: vertex {v} {:?} has no reference vertex within the error", mesh.positions[v])
            }) as u32
        })
        .collect();
    // Triangles by the reference's positions (its seams repeat a position with other UVs or
    // normals), each rotated to start at its smallest.
    let position = |r: u32| reference.positions.iter().position(|p| *p == reference.positions[r as usize]).unwrap();
    let key = |t: [u32; 3]| {
        let t = t.map(position);
        let k = (0..3).min_by_key(|&k| t[k]).unwrap();
        [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
    };
    let mut triangles: Vec<[usize; 3]> = reference.indices.chunks_exact(3).map(|t| key([t[0], t[1], t[2]])).collect();
    triangles.sort_unstable();
    for t in mesh.indices.chunks_exact(3) {
        let t = key([matched[t[0] as usize], matched[t[1] as usize], matched[t[2] as usize]]);
        assert!(triangles.binary_search(&t).is_ok(), "{name}: triangle {t:?} is not in the reference");
    }
}

#[test]
fn gltfpack_quantized_and_meshopt_compressed_files_import_as_their_float_source() {
    let reference = import(&data("gltfpack_float.glb")).unwrap();
    assert_eq!(reference.triangle_count(), 432);
    // 14-bit positions over a diagonal of 3.5 and 8-bit octahedral normals. (Its UVs are not
    // compared: gltfpack stores them as 12-bit values in normalised u16 and leaves the
    // scale back to each texture's KHR_texture_transform; this mesh has no texture.)
    let errors = (2.0 * 3.5 / 16383.0, 0.02, None);
    let quantized = import(&data("gltfpack_quantized.glb")).unwrap();
    assert_matches("gltfpack_quantized.glb", &quantized, &reference, errors);
    for name in ["gltfpack_quantized_normalized.glb", "gltfpack_meshopt.glb"] {
        let mesh = import(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_matches(name, &mesh, &reference, errors);
        assert_matches(name, &mesh, &quantized, (2.0 * 3.5 / 16383.0, 0.02, Some(1e-6)));
    }
    // Float views through the exponential filter (gltfpack keeps enough mantissa bits for
    // errors within 1e-4 on these positions and 1e-3 on the UVs).
    let float = import(&data("gltfpack_meshopt_float.glb")).unwrap();
    assert_matches("gltfpack_meshopt_float.glb", &float, &reference, (1e-4, 0.02, Some(1e-3)));
}

#[test]
fn compression_is_lossless_over_the_quantized_views() {
    // The same quantized mesh, stored plain and compressed (in another vertex order; the
    // normals' octahedral filter changes their encoding, not the positions and UVs).
    let plain = import(&data("gltfpack_quantized.glb")).unwrap();
    let compressed = import(&data("gltfpack_meshopt.glb")).unwrap();
    assert_matches("gltfpack_meshopt.glb", &compressed, &plain, (0.0, 0.02, Some(0.0)));
}

/// The GLB's JSON chunk and binary chunk.
fn chunks(glb: &[u8]) -> (serde_json::Value, Vec<u8>) {
    let json_length = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let json = serde_json::from_slice(&glb[20..20 + json_length]).unwrap();
    let bin = glb[20 + json_length + 8..].to_vec();
    (json, bin)
}

fn glb(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    let mut text = serde_json::to_vec(json).unwrap();
    text.resize(text.len().next_multiple_of(4), b' ');
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + text.len() + 8 + bin.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(bin);
    out
}

fn import_bytes(bytes: &[u8]) -> Result<SourceMesh, ImportErrorKind> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("edited.glb");
    std::fs::write(&path, bytes).unwrap();
    import(&path)
}

#[test]
fn a_damaged_compressed_view_is_an_error_naming_it() {
    let (json, mut bin) = chunks(&std::fs::read(data("gltfpack_meshopt.glb")).unwrap());
    // The index view's stream, overwritten with bytes no encoder writes.
    let views = json["bufferViews"].as_array().unwrap();
    let (v, indices) = views
        .iter()
        .enumerate()
        .find(|(_, v)| v["extensions"]["EXT_meshopt_compression"]["mode"] == "TRIANGLES")
        .unwrap();
    let c = &indices["extensions"]["EXT_meshopt_compression"];
    let (offset, length) = (c["byteOffset"].as_u64().unwrap() as usize, c["byteLength"].as_u64().unwrap() as usize);
    bin[offset..offset + length].fill(0xff);
    let error = import_bytes(&glb(&json, &bin)).unwrap_err().to_string();
    assert!(error.contains(&format!("bufferView {v} (EXT_meshopt_compression)")), "{error}");
    assert!(error.contains("does not decode"), "{error}");
    // A count the view cannot hold is refused before anything is decoded.
    let (mut json, bin) = chunks(&std::fs::read(data("gltfpack_meshopt.glb")).unwrap());
    json["bufferViews"][v]["extensions"]["EXT_meshopt_compression"]["count"] = serde_json::json!(1u64 << 40);
    let error = import_bytes(&glb(&json, &bin)).unwrap_err().to_string();
    assert!(error.contains("do not fit"), "{error}");
}

#[test]
fn required_extensions_are_refused_only_where_they_can_change_the_geometry() {
    let (mut json, bin) = chunks(&std::fs::read(data("gltfpack_quantized.glb")).unwrap());
    let require = |json: &mut serde_json::Value, extensions: &[&str]| {
        json["extensionsRequired"] = serde_json::json!(extensions);
        json["extensionsUsed"] = serde_json::json!(extensions);
    };
    let neutral = [
        "KHR_mesh_quantization",
        "KHR_materials_pbrSpecularGlossiness",
        "KHR_texture_transform",
        "EXT_mesh_gpu_instancing",
    ];
    require(&mut json, &neutral);
    assert_eq!(import_bytes(&glb(&json, &bin)).unwrap().triangle_count(), 432);
    for refused in ["KHR_draco_mesh_compression", "VENDOR_unknown"] {
        require(&mut json, &["KHR_mesh_quantization", refused]);
        match import_bytes(&glb(&json, &bin)) {
            Err(ImportErrorKind::UnsupportedGltfExtension(e)) => assert_eq!(e, refused),
            other => panic!("{refused}: {:?}", other.map(|m| m.triangle_count())),
        }
    }
}

/// Asserts that `a` and `b` hold the same triangles up to `error` per corner: every triangle
/// of `a` has one in `b` with its corners, in the same winding, that close.
fn assert_same_triangles(name: &str, a: &SourceMesh, b: &SourceMesh, error: f32) {
    assert_eq!(a.triangle_count(), b.triangle_count(), "{name}: triangles");
    let corners = |m: &SourceMesh, t: &[u32]| [0, 1, 2].map(|k| m.positions[t[k] as usize]);
    let others: Vec<[[f32; 3]; 3]> = b.indices.chunks_exact(3).map(|t| corners(b, t)).collect();
    for t in a.indices.chunks_exact(3).map(|t| corners(a, t)) {
        let same = |o: &[[f32; 3]; 3]| (0..3).any(|r| (0..3).all(|k| distance(&t[k], &o[(k + r) % 3]) <= error));
        assert!(others.iter().any(same), "{name}: triangle {t:?} is not in the other mesh");
    }
}

/// Every instance of `scene` as world triangles, in one mesh.
fn placed(scene: &mres_import::scene::ImportedScene) -> SourceMesh {
    let (mut positions, mut indices) = (Vec::new(), Vec::new());
    for instance in &scene.instances {
        let (mesh, m) = (&scene.meshes[instance.mesh].mesh, &instance.transform);
        let base = positions.len() as u32;
        positions.extend(
            mesh.positions
                .iter()
                .map(|p| [0, 1, 2].map(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])),
        );
        indices.extend(mesh.indices.iter().map(|i| base + i));
    }
    SourceMesh::positions_only(positions, indices)
}

/// `gpu_instancing_source.gltf`: a unit cube placed by seven nodes (rotations, non-uniform
/// scales) under a rotated, scaled, moved parent; `gltfpack_gpu_instancing*.glb` are
/// gltfpack 1.3's `-mi` output of it (one node, seven EXT_mesh_gpu_instancing copies whose
/// transforms hold the parent's), quantized (i16 rotations) and `-noq`.
#[test]
fn gpu_instances_are_placements_of_one_mesh() {
    let source = import(&data("gpu_instancing_source.gltf")).unwrap();
    assert_eq!(source.triangle_count(), 7 * 12);
    for (name, error) in [("gltfpack_gpu_instancing_float.glb", 1e-4), ("gltfpack_gpu_instancing.glb", 5e-3)] {
        let flat = import(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_same_triangles(name, &flat, &source, error);
        let scene = mres_import::import_scene(&data(name), &ImportLimits::default()).unwrap();
        assert!(scene.is_instanced(), "{name}: one mesh, placed seven times");
        assert_eq!((scene.meshes.len(), scene.instances.len()), (1, 7), "{name}");
        assert_eq!(scene.meshes[0].mesh.triangle_count(), 12, "{name}: the cube once");
        assert_same_triangles(name, &placed(&scene), &source, error);
    }
    // The copies' transforms come before the node's own: the same transform on the
    // instancing node and above the source's root gives the same triangles.
    let (trs, s) = (serde_json::json!([5.0, -2.0, 1.0]), 0.5f64.sin() / 2f64.sqrt());
    let rotation = serde_json::json!([s, 0.0, s, 0.5f64.cos()]);
    let (mut json, bin) = chunks(&std::fs::read(data("gltfpack_gpu_instancing_float.glb")).unwrap());
    let node = json["nodes"].as_array_mut().unwrap().iter_mut().find(|n| n.get("extensions").is_some()).unwrap();
    (node["translation"], node["rotation"], node["scale"]) =
        (trs.clone(), rotation.clone(), serde_json::json!([1.5, 1.5, 1.5]));
    let moved = import_bytes(&glb(&json, &bin)).unwrap();
    let mut source: serde_json::Value =
        serde_json::from_slice(&std::fs::read(data("gpu_instancing_source.gltf")).unwrap()).unwrap();
    let above =
        serde_json::json!({"children": [0], "translation": trs, "rotation": rotation, "scale": [1.5, 1.5, 1.5]});
    source["nodes"].as_array_mut().unwrap().push(above);
    source["scenes"][0]["nodes"] = serde_json::json!([8]);
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("source.gltf"), serde_json::to_vec(&source).unwrap()).unwrap();
    assert_same_triangles("moved", &moved, &import(&dir.path().join("source.gltf")).unwrap(), 1e-3);
}
