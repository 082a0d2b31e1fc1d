//! Scene import: a glTF written by the test, whose quad mesh is placed by three nodes (one of
//! them under a rotated, scaled parent, one mirrored) and whose triangle mesh is placed once
//! by an unnamed node; material names of glTF and OBJ.

use std::path::{Path, PathBuf};

#[path = "common/instanced_scene.rs"]
mod instanced_scene;
use instanced_scene::{scene_json, QUAD, TRI};
use mres_import::scene::{flatten, IDENTITY};

use mres_import::{import_file, import_scene, material_names, scene_outline, ImportLimits, SourceMesh};

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
