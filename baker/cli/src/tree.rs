//! The asset tree of a batch: which files are meshes to bake, which are companions of a mesh
//! (its material libraries, buffers and textures, the settings file) and which are skipped and
//! why; and which `.mres` files in the output directory no current asset produces.

use crate::config::CONFIG_FILE_NAME;
use mres_import::{referenced_files, InputKind};
use serde::Serialize;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// A file under the input that is neither baked nor used by a baked asset.
#[derive(Clone, Debug, Serialize, PartialEq, Eq)]
pub struct Skipped {
    /// The file.
    pub path: PathBuf,
    /// Why it is not baked.
    pub reason: String,
}

/// What [`find_assets`] found under an input directory.
#[derive(Clone, Debug, Default)]
pub struct Found {
    /// The mesh files, sorted.
    pub assets: Vec<PathBuf>,
    /// Files that are not baked and not used by any asset, sorted, with the reason.
    pub skipped: Vec<Skipped>,
    /// Files used without being baked: material libraries, buffers and textures an asset
    /// references, and the settings file in use.
    pub companions: usize,
}

/// Walks `root` (sorted, following links), leaving out the directories in `exclude` (the
/// output and cache directories when they lie inside the tree). `config` is the settings file
/// in use, if any: it is a companion, while any other `pipeline.toml` found is skipped.
pub fn find_assets(root: &Path, exclude: &[PathBuf], config: Option<&Path>) -> std::io::Result<Found> {
    let exclude: Vec<PathBuf> = exclude.iter().filter_map(|d| d.canonicalize().ok()).collect();
    let (mut assets, mut others) = (Vec::new(), Vec::new());
    walk(root, &exclude, &mut assets, &mut others)?;
    let used = used_companions(&assets, &others);
    let config = config.and_then(|c| c.canonicalize().ok());
    let mut found = Found { assets, ..Found::default() };
    for path in others {
        let canonical = path.canonicalize().unwrap_or_else(|_| path.clone());
        if used.contains(&canonical) || config.as_ref() == Some(&canonical) {
            found.companions += 1;
        } else {
            let reason = skip_reason(&path, config.as_deref());
            found.skipped.push(Skipped { path, reason });
        }
    }
    Ok(found)
}

fn walk(dir: &Path, exclude: &[PathBuf], assets: &mut Vec<PathBuf>, others: &mut Vec<PathBuf>) -> std::io::Result<()> {
    let with_dir = |e: std::io::Error| std::io::Error::new(e.kind(), format!("{}: {e}", dir.display()));
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(with_dir)?
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()
        .map_err(with_dir)?;
    entries.sort();
    for path in entries {
        if path.is_dir() {
            if !path.canonicalize().is_ok_and(|c| exclude.contains(&c)) {
                walk(&path, exclude, assets, others)?;
            }
        } else if InputKind::from_path(&path).is_some() {
            assets.push(path);
        } else {
            others.push(path);
        }
    }
    Ok(())
}

fn skip_reason(path: &Path, config: Option<&Path>) -> String {
    if path.file_name().is_some_and(|n| n == CONFIG_FILE_NAME) {
        return match config {
            Some(c) => format!("settings of a subtree, not used: this bake's settings come from {}", c.display()),
            None => "settings of a subtree, not used: this bake uses the embedded defaults".into(),
        };
    }
    match path.extension() {
        Some(ext) => format!("no importer for .{} files", ext.to_string_lossy()),
        None => "no importer for files without an extension".into(),
    }
}

/// The files (canonical paths) that the assets use: what [`referenced_files`] lists, plus the
/// textures of OBJ material libraries and of glTF images, which the baker never reads but an
/// asset tree holds on purpose. Only assets whose directory holds one of `others` are read.
fn used_companions(assets: &[PathBuf], others: &[PathBuf]) -> HashSet<PathBuf> {
    let mut used = HashSet::new();
    for asset in assets {
        let dir = asset.parent().unwrap_or(Path::new(""));
        if !others.iter().any(|o| o.starts_with(dir)) {
            continue;
        }
        // An unreadable asset fails its own bake with a clear error; here it uses nothing.
        let referenced = referenced_files(asset).unwrap_or_default();
        let mut files = texture_references(asset);
        for r in &referenced {
            if r.extension().is_some_and(|e| e.eq_ignore_ascii_case("mtl")) {
                files.extend(mtl_textures(r));
            }
        }
        files.extend(referenced);
        used.extend(files.into_iter().filter_map(|f| f.canonicalize().ok()));
    }
    used
}

/// Texture paths of an OBJ material library: the last word of each `map_*`, `bump`, `disp`,
/// `decal`, `norm` or `refl` statement (options come before it), relative to the library.
fn mtl_textures(mtl: &Path) -> Vec<PathBuf> {
    let dir = mtl.parent().unwrap_or(Path::new(""));
    let text = std::fs::read_to_string(mtl).unwrap_or_default();
    text.lines()
        .filter_map(|line| {
            let mut words = line.split_whitespace();
            let keyword = words.next()?;
            let is_texture =
                keyword.starts_with("map_") || ["bump", "disp", "decal", "norm", "refl"].contains(&keyword);
            is_texture.then(|| words.last()).flatten().map(|name| dir.join(name.replace('\\', "/")))
        })
        .collect()
}

/// The image URIs of a glTF or GLB file (not `data:` URIs), relative to the file.
fn texture_references(asset: &Path) -> Vec<PathBuf> {
    let json = match InputKind::from_path(asset) {
        Some(InputKind::Gltf) => std::fs::read(asset).ok(),
        Some(InputKind::Glb) => glb_json(asset),
        _ => None,
    };
    let Some(value) = json.and_then(|j| serde_json::from_slice::<serde_json::Value>(&j).ok()) else {
        return Vec::new();
    };
    let dir = asset.parent().unwrap_or(Path::new(""));
    let images = value.get("images").and_then(|i| i.as_array()).cloned().unwrap_or_default();
    images
        .iter()
        .filter_map(|image| image.get("uri")?.as_str().map(str::to_owned))
        .filter(|uri| !uri.starts_with("data:"))
        .map(|uri| dir.join(percent_decode(&uri)))
        .collect()
}

/// The JSON chunk of a GLB file: 12-byte header, then chunk length and type, then the chunk.
fn glb_json(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read;
    let mut file = std::fs::File::open(path).ok()?;
    let mut head = [0u8; 20];
    file.read_exact(&mut head).ok()?;
    let length = u32::from_le_bytes(head[12..16].try_into().ok()?) as u64;
    let mut json = Vec::new();
    file.take(length.min(64 << 20)).read_to_end(&mut json).ok()?;
    Some(json)
}

/// Decodes `%XX` escapes of a URI (glTF URIs are percent-encoded); a bad escape is kept as is.
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes.get(i + 1..i + 3).and_then(|h| std::str::from_utf8(h).ok());
        match (bytes[i], hex.and_then(|h| u8::from_str_radix(h, 16).ok())) {
            (b'%', Some(b)) => {
                out.push(b);
                i += 3;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Whether `path` is something a batch writes: a `.mres` or a scene file.
fn is_output(path: &Path) -> bool {
    let scene =
        path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.ends_with(mres_import::scene::SCENE_SUFFIX));
    scene || path.extension().is_some_and(|e| e == "mres")
}

/// The outputs (`.mres` and scene files) under `dir` that are not in `expected`: outputs of
/// assets renamed or deleted (or no longer instanced) since they were baked. Sorted; empty if
/// `dir` does not exist.
pub fn stale_outputs(dir: &Path, expected: &HashSet<PathBuf>) -> std::io::Result<Vec<PathBuf>> {
    fn walk(dir: &Path, expected: &HashSet<PathBuf>, stale: &mut Vec<PathBuf>) -> std::io::Result<()> {
        for entry in
            std::fs::read_dir(dir).map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", dir.display())))?
        {
            let path = entry?.path();
            if path.is_dir() {
                walk(&path, expected, stale)?;
            } else if is_output(&path) && !expected.contains(&path) {
                stale.push(path);
            }
        }
        Ok(())
    }
    let mut stale = Vec::new();
    if dir.is_dir() {
        walk(dir, expected, &mut stale)?;
    }
    stale.sort();
    Ok(stale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn companions_are_not_skipped_and_skipped_files_say_why() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        std::fs::create_dir(root.join("sub")).unwrap();
        std::fs::write(root.join("a.obj"), "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        std::fs::write(root.join("a.mtl"), "newmtl m\nmap_Kd -s 1 1 1 tex/a.png\nbump sub/n.png\n").unwrap();
        std::fs::create_dir(root.join("tex")).unwrap();
        std::fs::write(root.join("tex/a.png"), "").unwrap();
        std::fs::write(root.join("sub/n.png"), "").unwrap();
        std::fs::write(
            root.join("m.gltf"),
            r#"{"asset":{"version":"2.0"},"images":[{"uri":"i%20j.jpg"},{"uri":"data:x"}]}"#,
        )
        .unwrap();
        std::fs::write(root.join("i j.jpg"), "").unwrap();
        std::fs::write(root.join("pipeline.toml"), "").unwrap();
        std::fs::write(root.join("sub/pipeline.toml"), "").unwrap();
        std::fs::write(root.join("sub/x.fbx"), "").unwrap();
        std::fs::write(root.join("unused.png"), "").unwrap();
        let found = find_assets(root, &[], Some(&root.join("pipeline.toml"))).unwrap();
        assert_eq!(found.assets, [root.join("a.obj"), root.join("m.gltf")]);
        assert_eq!(found.companions, 5, "a.mtl, two textures of it, one glTF image, the settings");
        let skipped: Vec<_> =
            found.skipped.iter().map(|s| (s.path.strip_prefix(root).unwrap(), s.reason.as_str())).collect();
        assert_eq!(skipped.len(), 3, "{skipped:?}");
        assert_eq!(skipped[0].0, Path::new("sub/pipeline.toml"));
        assert!(skipped[0].1.contains("not used"), "{}", skipped[0].1);
        assert_eq!(skipped[1], (Path::new("sub/x.fbx"), "no importer for .fbx files"));
        assert_eq!(skipped[2], (Path::new("unused.png"), "no importer for .png files"));
        // An excluded directory is not walked.
        let found = find_assets(root, &[root.join("sub")], None).unwrap();
        assert!(found.skipped.iter().all(|s| !s.path.starts_with(root.join("sub"))));
    }

    #[test]
    fn stale_outputs_are_the_unexpected_mres_files() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        std::fs::create_dir(out.join("d")).unwrap();
        for f in ["a.mres", "d/b.mres", "d/c.mres", "d/notes.txt", "d/c.mres.tmp12"] {
            std::fs::write(out.join(f), "").unwrap();
        }
        let expected: HashSet<PathBuf> = [out.join("a.mres"), out.join("d/c.mres")].into();
        assert_eq!(stale_outputs(out, &expected).unwrap(), [out.join("d/b.mres")]);
        assert!(stale_outputs(&out.join("missing"), &expected).unwrap().is_empty());
    }
}
