//! Scene import: a glTF written by the test, whose quad mesh is placed by three nodes (one of
//! them under a rotated, scaled parent, one mirrored) and whose triangle mesh is placed once
//! by an unnamed node; material names of glTF and OBJ.

use std::path::{Path, PathBuf};

use base64::Engine as _;
use mres_import::scene::{flatten, IDENTITY};

use mres_import::{import_file, import_scene, material_names, scene_outline, ImportLimits, SourceMesh};

/// The quad's positions (local space).
const QUAD: [[f32; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
/// The triangle's positions.
const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [0.0, 2.0, 1.0]];

/// Buffer: quad positions (48 bytes), quad normals (48), triangle positions (36), quad
/// indices (12), triangle indices (6, padded to 8).
fn buffer() -> Vec<u8> {
    let mut bytes: Vec<u8> = Vec::new();
    let floats = |bytes: &mut Vec<u8>, points: &[[f32; 3]]| {
        bytes.extend(points.iter().flatten().flat_map(|c| c.to_le_bytes()));
    };
    floats(&mut bytes, &QUAD);
    floats(&mut bytes, &[[0.0, 0.0, 1.0]; 4]);
    floats(&mut bytes, &TRI);
    bytes.extend([0u16, 1, 2, 0, 2, 3, 0, 1, 2, 0].iter().flat_map(|i| i.to_le_bytes()));
    bytes
}

/// The instanced scene (see the module docs); `instanced: false` places the quad only once.
pub fn scene_json(instanced: bool) -> String {
    let data = base64::engine::general_purpose::STANDARD.encode(buffer());
    let (bolt_b, bolt_c) = if instanced { (r#", "mesh": 0"#, r#", "mesh": 0"#) } else { ("", "") };
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0, 5]}}],
        "nodes": [
          {{"name": "root", "translation": [10, 0, 0], "children": [1, 2, 4]}},
          {{"name": "bolt_a", "mesh": 0, "translation": [0, 1, 0]}},
          {{"name": "arm", "rotation": [0, 0, 0.70710678, 0.70710678], "scale": [2, 2, 2], "children": [3]}},
          {{"name": "bolt_b", "translation": [1, 0, 0]{bolt_b}}},
          {{"mesh": 1}},
          {{"name": "bolt_c", "scale": [-1, 1, 1]{bolt_c}}}],
        "materials": [{{"name": "steel"}}, {{"name": "brass"}}],
        "meshes": [
          {{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 3, "material": 0}}]}},
          {{"primitives": [{{"attributes": {{"POSITION": 2}}, "indices": 4, "material": 1}}]}}],
        "buffers": [{{"byteLength": 152, "uri": "data:application/octet-stream;base64,{data}"}}],
        "bufferViews": [{{"buffer": 0, "byteLength": 48}}, {{"buffer": 0, "byteOffset": 48, "byteLength": 48}},
          {{"buffer": 0, "byteOffset": 96, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 132, "byteLength": 12}},
          {{"buffer": 0, "byteOffset": 144, "byteLength": 6}}],
        "accessors": [
          {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}},
          {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"}},
          {{"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,1], "max": [2,2,1]}},
          {{"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}},
          {{"bufferView": 4, "componentType": 5123, "count": 3, "type": "SCALAR"}}]}}"#
    )
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn apply(m: &[f32; 16], p: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|r| m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r])
}

/// Every triangle as world positions, sorted (order-independent comparison).
fn world_triangles(mesh: &SourceMesh, transform: &[f32; 16]) -> Vec<[[i64; 3]; 3]> {
    let key = |p: [f32; 3]| p.map(|c| (c * 1e4).round() as i64);
    let mut out: Vec<_> = mesh
        .indices
        .chunks_exact(3)
        .map(|t| {
            let mut corners = [0, 1, 2].map(|k| key(apply(transform, mesh.positions[t[k] as usize])));
            corners.sort();
            corners
        })
        .collect();
    out.sort();
    out
}

fn close(a: &[f32; 16], b: &[f32; 16]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
}

#[test]
fn shared_mesh_is_read_once_in_local_space_and_placed_by_every_node() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "engine.gltf", &scene_json(true));
    let scene = import_scene(&path, &ImportLimits::default()).unwrap();
    assert!(scene.is_instanced());
    assert!(scene_outline(&path).unwrap().instanced);
    // Each glTF mesh once, in order of first placement, in its local space.
    assert_eq!(scene.meshes.len(), 2);
    assert_eq!(scene.meshes[0].gltf_mesh, Some(0));
    assert_eq!(scene.meshes[0].mesh.positions, QUAD.to_vec(), "the shared mesh stays in local space");
    assert_eq!(scene.meshes[0].mesh.triangle_count(), 2);
    assert!(scene.meshes[0].mesh.normals.is_some(), "its normals are kept though the triangle has none");
    assert_eq!(scene.meshes[1].gltf_mesh, Some(1));
    assert_eq!(scene.meshes[1].mesh.positions, TRI.to_vec());

    let placed: Vec<(&str, Option<usize>, usize)> =
        scene.instances.iter().map(|i| (i.name.as_str(), i.node, i.mesh)).collect();
    assert_eq!(
        placed,
        [("bolt_a", Some(1), 0), ("bolt_b", Some(3), 0), ("node 4", Some(4), 1), ("bolt_c", Some(5), 0)]
    );
    let t = |i: usize| flatten(&scene.instances[i].transform);
    assert_eq!(t(0), [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 10., 1., 0., 1.]);
    // root (translate 10) * arm (rotate 90° about z, scale 2) * bolt_b (translate 1 along x).
    assert!(close(&t(1), &[0., 2., 0., 0., -2., 0., 0., 0., 0., 0., 2., 0., 10., 2., 0., 1.]), "{:?}", t(1));
    assert_eq!(t(2), [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 10., 0., 0., 1.]);
    assert_eq!(t(3), [-1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.]);
}

#[test]
fn instances_reproduce_the_flattened_import() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "engine.gltf", &scene_json(true));
    let scene = import_scene(&path, &ImportLimits::default()).unwrap();
    let mut placed: Vec<_> = scene
        .instances
        .iter()
        .flat_map(|i| world_triangles(&scene.meshes[i.mesh].mesh, &flatten(&i.transform)))
        .collect();
    placed.sort();
    let flat = import_file(&path, &ImportLimits::default()).unwrap();
    assert_eq!(placed, world_triangles(&flat, &flatten(&IDENTITY)));
}

#[test]
fn scene_without_instancing_is_the_flattened_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "single.gltf", &scene_json(false));
    let scene = import_scene(&path, &ImportLimits::default()).unwrap();
    assert!(!scene.is_instanced());
    assert!(!scene_outline(&path).unwrap().instanced);
    assert_eq!(scene.meshes.len(), 1);
    assert_eq!(scene.meshes[0].mesh, import_file(&path, &ImportLimits::default()).unwrap());
    assert_eq!(scene.instances.len(), 1);
    assert_eq!(scene.instances[0].transform, IDENTITY);
}

#[test]
fn material_names_follow_the_material_indices() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = write(dir.path(), "engine.gltf", &scene_json(true));
    let names = material_names(&gltf).unwrap();
    assert_eq!(names, [Some("steel".to_owned()), Some("brass".to_owned())]);
    let scene = import_scene(&gltf, &ImportLimits::default()).unwrap();
    assert_eq!(scene.material_names, names);
    assert!(scene.meshes[0].mesh.materials.iter().all(|&m| m == 0), "the quad is steel");
    assert_eq!(scene.meshes[1].mesh.materials, [1], "the triangle is brass");

    // OBJ: order of first `usemtl`; faces before any `usemtl` get one past the names.
    let obj = write(
        dir.path(),
        "m.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nusemtl rust red\nf 2 4 3\nusemtl chrome\nf 1 2 4\n\
         usemtl rust red\nf 1 4 3\n",
    );
    let names = material_names(&obj).unwrap();
    assert_eq!(names, [Some("rust red".to_owned()), Some("chrome".to_owned())]);
    assert_eq!(import_file(&obj, &ImportLimits::default()).unwrap().materials, [2, 0, 1, 0]);
    assert_eq!(import_scene(&obj, &ImportLimits::default()).unwrap().material_names, names);
}
