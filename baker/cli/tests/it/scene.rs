//! Scenes through `bake-all`: a glTF written by the test whose quad mesh is placed by three
//! nodes bakes each mesh once (into its own `.mres`, content-addressed in the cache), the
//! scene file lists every instance with its name and world transform and the material names,
//! `mres export` writes those names, stale scene outputs are found, and a broken scene file is
//! an error naming it.

use crate::{run, text, BAKE_ALL, MRES};
use std::path::{Path, PathBuf};

#[path = "../../../../formats/import/tests/common/instanced_scene.rs"]
mod instanced_scene;
use instanced_scene::scene_json;
use mres_format::MresFile;
use mres_import::SceneFile;

struct Tree {
    dir: tempfile::TempDir,
}

impl Tree {
    fn new() -> Tree {
        let t = Tree { dir: tempfile::tempdir().unwrap() };
        std::fs::create_dir_all(t.assets()).unwrap();
        t
    }
    fn assets(&self) -> PathBuf {
        self.dir.path().join("assets")
    }
    fn out(&self) -> PathBuf {
        self.dir.path().join("out")
    }
    fn write(&self, name: &str, text: &str) {
        std::fs::write(self.assets().join(name), text).unwrap();
    }
    /// Runs bake-all over the assets (with a cache) and returns the report.
    fn bake(&self, extra: &[&str]) -> serde_json::Value {
        let report = self.dir.path().join("report.json");
        let cache = self.dir.path().join("cache");
        let mut args = vec![
            self.assets().to_str().unwrap().to_owned(),
            "-o".into(),
            self.out().to_str().unwrap().to_owned(),
            "--cache-dir".into(),
            cache.to_str().unwrap().to_owned(),
            "--report".into(),
            report.to_str().unwrap().to_owned(),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(BAKE_ALL, &args);
        assert!(o.status.success(), "{}", text(&o));
        serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap()
    }
}

fn asset<'a>(report: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    let assets = report["assets"].as_array().unwrap();
    assets.iter().find(|a| a["input"].as_str().unwrap().ends_with(name)).unwrap()
}

fn source_triangles(path: &Path) -> u64 {
    MresFile::parse(std::fs::read(path).unwrap()).unwrap().header.source_triangles
}

#[test]
fn a_shared_mesh_is_baked_once_and_the_scene_file_places_it() {
    let t = Tree::new();
    t.write("engine.gltf", &scene_json(true));
    let report = t.bake(&[]);
    let out = t.out();
    // Each glTF mesh once in its own file: the quad (2 triangles) and the triangle, 3 stored
    // where flattening stores 3 x 2 + 1; no flattened main file.
    assert_eq!(source_triangles(&out.join("engine.mesh0.mres")), 2);
    assert_eq!(source_triangles(&out.join("engine.mesh1.mres")), 1);
    assert!(!out.join("engine.mres").exists());
    let r = asset(&report, "engine.gltf");
    assert_eq!(r["input_triangles"], 3);
    assert_eq!(r["mesh_outputs"], serde_json::json!([out.join("engine.mesh0.mres"), out.join("engine.mesh1.mres")]));
    assert_eq!(r["scene"], serde_json::json!(out.join("engine.scene.json")));
    assert_eq!(r["output"], r["scene"]);

    let scene = SceneFile::read(&out.join("engine.scene.json")).unwrap();
    let files: Vec<&str> = scene.meshes.iter().map(|m| m.file.as_str()).collect();
    assert_eq!(files, ["engine.mesh0.mres", "engine.mesh1.mres"]);
    for mesh in &scene.meshes {
        assert_eq!(mesh.materials, [Some("steel".to_owned()), Some("brass".to_owned())]);
    }
    let placed: Vec<(&str, usize)> = scene.instances.iter().map(|i| (i.name.as_str(), i.mesh)).collect();
    assert_eq!(placed, [("bolt_a", 0), ("bolt_b", 0), ("node 4", 1), ("bolt_c", 0)]);
    let expected: [[f32; 16]; 4] = [
        [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 10., 1., 0., 1.],
        [0., 2., 0., 0., -2., 0., 0., 0., 0., 0., 2., 0., 10., 2., 0., 1.],
        [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 10., 0., 0., 1.],
        [-1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.],
    ];
    for (instance, expected) in scene.instances.iter().zip(expected) {
        let close = instance.transform.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-5);
        assert!(close, "{}: {:?}", instance.name, instance.transform);
    }

    // A second run finds everything in the cache and leaves the outputs alone.
    let report = t.bake(&[]);
    assert_eq!(asset(&report, "engine.gltf")["status"], "cached");
    assert_eq!(report["stale"], serde_json::json!([]), "a scene's own outputs are not stale");
}

#[test]
fn identical_meshes_in_different_assets_share_cache_entries() {
    let t = Tree::new();
    t.write("a.gltf", &scene_json(true));
    t.bake(&[]);
    // Other file bytes, same meshes: the per-mesh keys hit.
    t.write("b.gltf", &format!("\n\n{}", scene_json(true)));
    let report = t.bake(&[]);
    assert_eq!(asset(&report, "b.gltf")["status"], "cached");
    let mesh = |name: &str| std::fs::read(t.out().join(name)).unwrap();
    assert_eq!(mesh("a.mesh1.mres"), mesh("b.mesh1.mres"));
    assert_eq!(mesh("a.mesh0.mres"), mesh("b.mesh0.mres"));
}

#[test]
fn a_scene_without_instancing_bakes_as_before() {
    let t = Tree::new();
    t.write("single.gltf", &scene_json(false));
    t.bake(&["--no-cache"]);
    let settings = mres_build::settings::BakeSettings::default();
    let alone = mres_build::bake::bake_file(&t.assets().join("single.gltf"), &settings, &|_| {}).unwrap();
    assert_eq!(std::fs::read(t.out().join("single.mres")).unwrap(), alone.bytes, "byte-identical to a plain bake");
    let names: Vec<String> =
        std::fs::read_dir(t.out()).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    let mut names = names;
    names.sort();
    // Its material names still get a scene file; no mesh files.
    assert_eq!(names, ["single.mres", "single.scene.json"]);
}

#[test]
fn obj_material_names_reach_the_scene_file_and_export() {
    let t = Tree::new();
    t.write("m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nusemtl rust red\nf 1 2 3\nusemtl chrome\nf 2 4 3\n");
    t.bake(&["--no-cache"]);
    let scene = SceneFile::read(&t.out().join("m.scene.json")).unwrap();
    assert_eq!(scene.meshes[0].file, "m.mres");
    assert_eq!(scene.meshes[0].materials, [Some("rust red".to_owned()), Some("chrome".to_owned())]);
    let obj = t.dir.path().join("cut.obj");
    let mres = t.out().join("m.mres");
    let o = run(MRES, &["export", mres.to_str().unwrap(), "--error", "0", "-o", obj.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let exported = std::fs::read_to_string(&obj).unwrap();
    assert!(exported.contains("usemtl rust red\n") && exported.contains("usemtl chrome\n"), "{exported}");

    // A truncated scene file is an error that names it.
    let scene_path = t.out().join("m.scene.json");
    let bytes = std::fs::read(&scene_path).unwrap();
    std::fs::write(&scene_path, &bytes[..bytes.len() / 2]).unwrap();
    let o = run(MRES, &["export", mres.to_str().unwrap(), "--error", "0", "-o", obj.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains(scene_path.to_str().unwrap()) && text(&o).contains("invalid scene file"), "{}", text(&o));
}

#[test]
fn outputs_of_a_scene_no_longer_instanced_are_stale() {
    let t = Tree::new();
    t.write("engine.gltf", &scene_json(true));
    t.bake(&["--no-cache"]);
    t.write("engine.gltf", &scene_json(false));
    let report = t.bake(&["--no-cache"]);
    let old = [t.out().join("engine.mesh0.mres"), t.out().join("engine.mesh1.mres")];
    assert_eq!(report["stale"], serde_json::json!(old));
    let report = t.bake(&["--no-cache", "--prune"]);
    assert_eq!(report["pruned"], serde_json::json!(old));
    assert!(t.out().join("engine.mres").is_file());
    assert!(t.out().join("engine.scene.json").is_file(), "still written: the materials have names");
}
