//! Scenes: the meshes of an asset plus the instances that place them, in memory
//! ([`ImportedScene`], what [`crate::import_scene`] returns) and on disk ([`SceneFile`], the
//! scene file written beside the `.mres` files; layout in docs/FORMAT.md "Scene file").
//!
//! # What becomes its own mesh
//! A glTF scene where some mesh is placed by two or more nodes (after walking the node tree,
//! transforms composed) is split: every glTF mesh is read once, in its local space, baked
//! into its own `.mres`, and placed by one instance per node. A scene without instancing is
//! flattened into one mesh exactly as [`crate::import_file`] flattens it, and bakes
//! byte-identically.
//!
//! Why the meshes placed once are not flattened together in an instanced scene (which would
//! let many distinct parts merge at coarse levels): measured on a real many-part scene
//! (two_cylinder_engine.glb: 15 single-use and 14 shared meshes; release `bake-all`), the
//! flattened single-use part baked to 1,409,053 bytes and 1,227 clusters, where its 15
//! meshes baked apart take 1,231,487 bytes and 1,025 clusters: the merged DAG's coarse levels
//! barely simplify across disjoint parts, so merging costs bytes and bake time. Apart, the
//! output is exactly the unique meshes plus the instance table. The price is one root cluster
//! per mesh instead of one for the merged parts: a scene of thousands of distinct parts with
//! one instanced bolt bakes to thousands of files (the case for flattening small single-use
//! meshes, left open).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::SourceMesh;

/// Column-major 4×4 matrix, as glTF stores it (`m[column][row]`).
pub type Mat4 = [[f32; 4]; 4];

/// The identity transform.
pub const IDENTITY: Mat4 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// An imported asset as meshes to bake and instances that place them.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportedScene {
    /// The meshes, each baked once: the one flattened mesh of a scene without instancing, or
    /// every glTF mesh of an instanced scene in order of first placement.
    pub meshes: Vec<SceneMesh>,
    /// Every placement of a mesh: the flattened mesh once (identity), or each glTF mesh once
    /// per node that places it, in depth-first node order.
    pub instances: Vec<SceneInstance>,
    /// Material index -> name (the per-triangle indices of [`SourceMesh::materials`]; the same
    /// table for every mesh of the asset). `None` for an unnamed glTF material. An index past
    /// the end means "no material".
    pub material_names: Vec<Option<String>>,
}

impl ImportedScene {
    /// Whether the scene was split into glTF meshes (some mesh is placed more than once);
    /// else it is one flattened mesh.
    pub fn is_instanced(&self) -> bool {
        self.meshes.iter().any(|m| m.gltf_mesh.is_some())
    }
}

/// One mesh of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneMesh {
    /// The triangles: world space for the flattened mesh, local space for a glTF mesh.
    pub mesh: SourceMesh,
    /// The glTF mesh index; `None` for the flattened mesh.
    pub gltf_mesh: Option<usize>,
}

/// One placement of a scene mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneInstance {
    /// The node's name (`node N` if it has none); the file stem for the flattened mesh.
    pub name: String,
    /// The glTF node index; `None` for the flattened mesh.
    pub node: Option<usize>,
    /// Index into [`ImportedScene::meshes`].
    pub mesh: usize,
    /// Local-to-world transform.
    pub transform: Mat4,
}

/// The file name of a scene mesh's `.mres` for the asset whose main output is `STEM.mres`:
/// `STEM.mres` for the flattened mesh, `STEM.meshN.mres` for glTF mesh `N`.
pub fn mesh_file_name(stem: &str, gltf_mesh: Option<usize>) -> String {
    match gltf_mesh {
        None => format!("{stem}.mres"),
        Some(n) => format!("{stem}.mesh{n}.mres"),
    }
}

/// The scene file beside the main output `STEM.mres`: `STEM.scene.json`.
pub fn scene_file_path(main_mres: &Path) -> PathBuf {
    let stem = main_mres.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    main_mres.with_file_name(format!("{stem}{SCENE_SUFFIX}"))
}

/// How every scene file name ends.
pub const SCENE_SUFFIX: &str = ".scene.json";

/// The version of the scene file layout this crate writes and reads.
pub const SCENE_VERSION: u32 = 1;

/// A scene file (docs/FORMAT.md "Scene file"): the `.mres` files of one asset, their material
/// names and the instances that place them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Layout version, [`SCENE_VERSION`].
    pub version: u32,
    /// The meshes, each one `.mres` file.
    pub meshes: Vec<SceneFileMesh>,
    /// The placements.
    pub instances: Vec<SceneFileInstance>,
}

/// One mesh of a scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFileMesh {
    /// The `.mres` file, relative to the scene file's directory, `/`-separated.
    pub file: String,
    /// Material index -> name (`null`: unnamed); indices past the end have no material.
    pub materials: Vec<Option<String>>,
}

/// One placement in a scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFileInstance {
    /// The node's name.
    pub name: String,
    /// The glTF node index, when the instance comes from a node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node: Option<usize>,
    /// Index into [`SceneFile::meshes`].
    pub mesh: usize,
    /// Local-to-world transform, column-major (glTF's order); affine (last row 0 0 0 1).
    pub transform: [f32; 16],
}

/// A scene file that could not be read; names the file and the problem.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {kind}", path = path.display())]
pub struct SceneError {
    /// The scene file.
    pub path: PathBuf,
    /// What is wrong.
    pub kind: SceneErrorKind,
}

/// The problems a scene file can have.
#[derive(Debug, thiserror::Error)]
pub enum SceneErrorKind {
    /// The file could not be read.
    #[error("cannot read scene file: {0}")]
    Io(std::io::Error),
    /// Not valid scene JSON (syntax, truncation, missing or unknown fields); the message
    /// gives the line and column.
    #[error("invalid scene file: {0}")]
    Parse(String),
    /// A layout version this reader does not know.
    #[error("scene file version {0}, this reader knows version {SCENE_VERSION}")]
    Version(u32),
    /// Something the JSON grammar allows but the layout does not.
    #[error("invalid scene file: {0}")]
    Invalid(String),
}

impl SceneFile {
    /// The scene file of `scene`, whose mesh `i` is stored in `files[i]` (relative paths).
    pub fn from_scene(scene: &ImportedScene, files: &[String]) -> SceneFile {
        let meshes = files
            .iter()
            .map(|file| SceneFileMesh { file: file.clone(), materials: scene.material_names.clone() })
            .collect();
        let instances = scene
            .instances
            .iter()
            .map(|i| SceneFileInstance {
                name: i.name.clone(),
                node: i.node,
                mesh: i.mesh,
                transform: flatten(&i.transform),
            })
            .collect();
        SceneFile { version: SCENE_VERSION, meshes, instances }
    }

    /// Reads and checks the scene file at `path`.
    pub fn read(path: &Path) -> Result<SceneFile, SceneError> {
        let fail = |kind| SceneError { path: path.to_path_buf(), kind };
        let bytes = std::fs::read(path).map_err(|e| fail(SceneErrorKind::Io(e)))?;
        SceneFile::parse(&bytes).map_err(fail)
    }

    /// Parses and checks scene file bytes: the version, mesh indices, relative file paths
    /// that stay inside the scene's directory, finite affine transforms.
    pub fn parse(bytes: &[u8]) -> Result<SceneFile, SceneErrorKind> {
        #[derive(Deserialize)]
        struct Version {
            version: u32,
        }
        // The version first, so that a newer layout is reported as such, not as bad fields.
        let version: Version = serde_json::from_slice(bytes).map_err(|e| SceneErrorKind::Parse(e.to_string()))?;
        if version.version != SCENE_VERSION {
            return Err(SceneErrorKind::Version(version.version));
        }
        let file: SceneFile = serde_json::from_slice(bytes).map_err(|e| SceneErrorKind::Parse(e.to_string()))?;
        file.check()?;
        Ok(file)
    }

    fn check(&self) -> Result<(), SceneErrorKind> {
        let invalid = |message: String| Err(SceneErrorKind::Invalid(message));
        if self.meshes.is_empty() {
            return invalid("no meshes".into());
        }
        for (m, mesh) in self.meshes.iter().enumerate() {
            if crate::resolve_inside(Path::new("."), &mesh.file).is_none() || mesh.file.contains('\\') {
                return invalid(format!(
                    "mesh {m}: file {:?} is not a relative path inside the scene's directory",
                    mesh.file
                ));
            }
        }
        for (i, instance) in self.instances.iter().enumerate() {
            if instance.mesh >= self.meshes.len() {
                return invalid(format!("instance {i}: mesh {} of {}", instance.mesh, self.meshes.len()));
            }
            let t = &instance.transform;
            if !t.iter().all(|x| x.is_finite()) || [t[3], t[7], t[11]] != [0.0; 3] || t[15] != 1.0 {
                return invalid(format!("instance {i}: transform is not a finite affine matrix"));
            }
        }
        Ok(())
    }

    /// The path of mesh `i`'s file, resolved against the directory of the scene file at
    /// `scene_path` (checked by [`SceneFile::parse`] to stay inside it).
    pub fn mesh_path(&self, scene_path: &Path, i: usize) -> PathBuf {
        crate::resolve_inside(&crate::asset_dir(scene_path), &self.meshes[i].file)
            .unwrap_or_else(|| crate::asset_dir(scene_path).join(&self.meshes[i].file))
    }

    /// The file as JSON text: one mesh and one instance per line (a scene of thousands of
    /// instances stays readable and small), ending in a newline.
    pub fn to_json(&self) -> String {
        let mut out = format!("{{\n  \"version\": {},\n  \"meshes\": [\n", self.version);
        push_lines(&mut out, self.meshes.iter().map(one_line));
        out.push_str("  ],\n  \"instances\": [\n");
        push_lines(&mut out, self.instances.iter().map(one_line));
        out.push_str("  ]\n}\n");
        out
    }
}

/// Appends `lines` indented, comma-separated.
fn push_lines(out: &mut String, lines: impl Iterator<Item = String>) {
    let lines: Vec<String> = lines.collect();
    for (k, text) in lines.iter().enumerate() {
        out.push_str("    ");
        out.push_str(text);
        out.push_str(if k + 1 < lines.len() { ",\n" } else { "\n" });
    }
}

/// `value` as one line of JSON.
fn one_line<T: Serialize>(value: &T) -> String {
    // Serialising these plain structs cannot fail (no maps, no non-string keys).
    serde_json::to_string(value).unwrap_or_default()
}

/// `m` as 16 floats, column-major.
pub fn flatten(m: &Mat4) -> [f32; 16] {
    let mut out = [0.0; 16];
    for (c, column) in m.iter().enumerate() {
        out[c * 4..c * 4 + 4].copy_from_slice(column);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> SceneFile {
        SceneFile {
            version: SCENE_VERSION,
            meshes: vec![
                SceneFileMesh { file: "a.mres".into(), materials: vec![Some("steel".into()), None] },
                SceneFileMesh { file: "sub/a.mesh3.mres".into(), materials: vec![] },
            ],
            instances: vec![SceneFileInstance {
                name: "bolt \"1\"".into(),
                node: Some(4),
                mesh: 1,
                transform: flatten(&[
                    [0.5, 0.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 0.0],
                    [1.0, 2.0, 3.1, 1.0],
                ]),
            }],
        }
    }

    #[test]
    fn json_round_trips_exactly() {
        let file = sample();
        let text = file.to_json();
        assert_eq!(SceneFile::parse(text.as_bytes()).unwrap(), file);
        assert_eq!(text.lines().count(), 10, "{text}");
    }

    #[test]
    fn truncated_and_invalid_files_are_errors() {
        let text = sample().to_json();
        for cut in 0..text.len() - 2 {
            assert!(SceneFile::parse(&text.as_bytes()[..cut]).is_err(), "cut at {cut}");
        }
        let bad = [
            (text.replace("\"version\": 1", "\"version\": 9"), "version 9"),
            (text.replace("\"mesh\":1", "\"mesh\":2"), "mesh 2 of 2"),
            (text.replace("sub/a.mesh3", "../a"), "not a relative path"),
            (text.replace("\"a.mres\"", "\"/a.mres\""), "not a relative path"),
            (text.replace("3.1,1.0", "3.1,2.0"), "affine"),
            (text.replace("\"name\"", "\"nom\""), "unknown field"),
        ];
        for (bytes, expected) in bad {
            let message = SceneFile::parse(bytes.as_bytes()).unwrap_err().to_string();
            assert!(message.contains(expected), "{message} lacks {expected}");
        }
    }

    #[test]
    fn read_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.scene.json");
        std::fs::write(&path, &sample().to_json()[..40]).unwrap();
        let message = SceneFile::read(&path).unwrap_err().to_string();
        assert!(message.starts_with(&path.display().to_string()) && message.contains("line"), "{message}");
    }

    #[test]
    fn names_beside_the_main_output() {
        assert_eq!(scene_file_path(Path::new("out/d/engine.mres")), Path::new("out/d/engine.scene.json"));
        assert_eq!(mesh_file_name("engine", Some(7)), "engine.mesh7.mres");
        assert_eq!(mesh_file_name("engine", None), "engine.mres");
    }
}
