//! The batch behind `bake-all`: find the assets, look each up in the content-addressed cache,
//! bake the misses in parallel, write the outputs atomically and report per asset. One bad
//! asset never stops the others.

use crate::config::PipelineConfig;
use cache::{CacheKey, KeyInputs, LocalDisk, Lookup, Storage};
use mres_build::bake::{bake, bake_file};
use mres_build::settings::BakeSettings;
use mres_format::MresFile;
use mres_import::scene::{
    flatten, mesh_file_name, scene_file_path, SceneFileInstance, SceneFileMesh, IDENTITY, SCENE_VERSION,
};
use mres_import::{import_scene, referenced_files, scene_outline, ImportLimits, SceneFile, SourceMesh};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Bumped whenever the baker's output for the same input and settings would change; part of
/// every cache key.
pub const BAKER_VERSION: u32 = 5;

/// What happened to one asset.
#[derive(Clone, Debug, Serialize)]
pub struct AssetReport {
    /// The input file.
    pub input: PathBuf,
    /// The main `.mres` written (absent on failure; the scene file for an instanced scene,
    /// which has no flattened mesh).
    pub output: Option<PathBuf>,
    /// The other `.mres` files: an instanced scene's meshes (`STEM.meshN.mres`).
    pub mesh_outputs: Vec<PathBuf>,
    /// The scene file written (docs/FORMAT.md "Scene file"), if the asset has one.
    pub scene: Option<PathBuf>,
    /// "baked", "cached" or "failed".
    pub status: &'static str,
    /// The error, on failure: names the file and the problem.
    pub error: Option<String>,
    /// Input triangles: the source's triangles after triangulation, before degenerate ones are
    /// dropped (the file header's `source_triangles`), the figure every command reports.
    pub input_triangles: u64,
    /// Triangles of level 0 (the welded source, without its degenerate triangles).
    pub level0_triangles: u64,
    /// Triangles dropped as degenerate (by the importer or on the position grid).
    pub degenerate_dropped: u64,
    /// DAG levels.
    pub levels: u32,
    /// Clusters.
    pub clusters: u64,
    /// Groups.
    pub groups: u64,
    /// Clusters in root groups.
    pub root_clusters: u64,
    /// Shards the mesh was built in when baked now (0: whole); `null` when it came from the cache.
    pub shards: Option<u64>,
    /// Bytes of the `.mres` files (all of a scene's).
    pub bytes: u64,
    /// Bytes of the scene file (0 without one).
    pub scene_bytes: u64,
    /// Bytes per source triangle.
    pub bytes_per_input_triangle: f64,
    /// Wall seconds spent on this asset (key, lookup, bake, write).
    pub seconds: f64,
    /// Whether every output came from the cache.
    pub cache_hit: bool,
    /// A corrupt cache entry was found (and replaced by a fresh bake).
    pub cache_repaired: bool,
}

/// Everything one batch needs.
pub struct Batch<'a> {
    /// The directory the assets were found in (a single file's directory).
    pub input_root: &'a Path,
    /// Where `input_root` lies under the asset root (the directory of the settings file, when
    /// the input is inside it): outputs and override globs use `prefix/` + the path below
    /// `input_root`, so that baking a subfolder writes what baking the whole tree writes.
    pub prefix: &'a Path,
    /// Output directory.
    pub out_dir: &'a Path,
    /// Settings and overrides.
    pub config: &'a PipelineConfig,
    /// The cache, if used.
    pub cache: Option<&'a LocalDisk>,
    /// Receives (asset, stage line) while an asset bakes.
    pub stage: &'a (dyn Fn(&Path, &str) + Sync),
}

/// The cache key of `input` under `settings`: input bytes, referenced files, settings, versions.
pub fn cache_key(input: &Path, settings: &BakeSettings) -> Result<CacheKey, String> {
    let read = |p: &Path| std::fs::read(p).map_err(|e| format!("{}: {e}", p.display()));
    let input_bytes = read(input)?;
    let dir = input.parent().unwrap_or(Path::new("."));
    let mut referenced = Vec::new();
    for r in referenced_files(input).map_err(|e| e.to_string())? {
        let name = r
            .strip_prefix(dir)
            .unwrap_or(&r)
            .components()
            .map(|c| c.as_os_str().to_string_lossy())
            .collect::<Vec<_>>()
            .join("/");
        referenced.push((name, read(&r)?));
    }
    let settings_text = serde_json::to_string(settings).map_err(|e| e.to_string())?;
    Ok(CacheKey::new(&KeyInputs {
        input_bytes: &input_bytes,
        referenced,
        settings: &settings_text,
        format_version: mres_format::VERSION,
        baker_version: BAKER_VERSION,
    }))
}

/// Writes `bytes` to `path` through a temporary file and a rename, creating directories.
fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let tmp = path.with_extension(format!("mres.tmp{}", std::process::id()));
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path)
}

impl Batch<'_> {
    /// The path of `input` under the asset root.
    pub fn relative(&self, input: &Path) -> PathBuf {
        let below = input.strip_prefix(self.input_root).unwrap_or(input);
        self.prefix.join(below)
    }

    /// The main `.mres` file `input` is baked to (its flattened mesh); an instanced scene's
    /// meshes go beside it instead ([`mesh_file_name`]), with the scene file ([`scene_file_path`]).
    pub fn output_for(&self, input: &Path) -> PathBuf {
        self.out_dir.join(self.relative(input)).with_extension("mres")
    }

    /// Processes every asset in parallel; `progress` is called after each one.
    pub fn run(&self, assets: &[PathBuf], progress: impl Fn(&AssetReport) + Sync) -> Vec<AssetReport> {
        assets
            .par_iter()
            .map(|input| {
                let report = self.process(input);
                progress(&report);
                report
            })
            .collect()
    }

    /// Every file of the output directory the batch that gave `reports` stands behind: the
    /// outputs it wrote, and for a failed asset whatever its previous bake left (its main
    /// `.mres`, scene file and `STEM.meshN.mres` files), which a failure must not make stale.
    pub fn expected_outputs(&self, reports: &[AssetReport]) -> HashSet<PathBuf> {
        let mut expected = HashSet::new();
        for r in reports {
            expected.extend(r.output.iter().cloned());
            expected.extend(r.mesh_outputs.iter().cloned());
            expected.extend(r.scene.iter().cloned());
            if r.error.is_some() {
                let main = self.output_for(&r.input);
                expected.extend(previous_outputs(&main));
                expected.insert(scene_file_path(&main));
                expected.insert(main);
            }
        }
        expected
    }

    fn process(&self, input: &Path) -> AssetReport {
        let start = Instant::now();
        let mut report = AssetReport::failed(input);
        if let Err(e) = self.process_into(input, &mut report) {
            report.error = Some(e);
            report.status = "failed";
        }
        report.seconds = start.elapsed().as_secs_f64();
        report
    }

    /// Bakes (or finds in the cache) every `.mres` of `input`, writes them and the scene file,
    /// and fills `report`.
    fn process_into(&self, input: &Path, report: &mut AssetReport) -> Result<(), String> {
        let main = self.output_for(input);
        let settings = self.config.settings_for(&self.relative(input));
        let outline = scene_outline(input).map_err(|e| e.to_string())?;
        let (units, scene) = if outline.instanced {
            self.scene_units(input, &main, &settings)?
        } else {
            let key = match self.cache {
                Some(_) => Some(cache_key(input, &settings)?),
                None => None,
            };
            let unit = Unit { output: main.clone(), key, mesh: None };
            let scene = (!outline.material_names.is_empty()).then(|| {
                let name = main.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
                single_scene(input, name, outline.material_names)
            });
            (vec![unit], scene)
        };
        let baked: Vec<Result<UnitResult, String>> =
            units.into_par_iter().map(|unit| self.bake_unit(input, unit, &settings)).collect();
        let baked = baked.into_iter().collect::<Result<Vec<_>, String>>()?;
        for unit in &baked {
            write_if_changed(&unit.output, &unit.bytes)
                .map_err(|e| format!("{}: writing: {e}", unit.output.display()))?;
        }
        if let Some(scene) = &scene {
            let path = scene_file_path(&main);
            let text = scene.to_json();
            write_if_changed(&path, text.as_bytes()).map_err(|e| format!("{}: writing: {e}", path.display()))?;
            report.scene = Some(path);
            report.scene_bytes = text.len() as u64;
        }
        report.fill(&main, baked);
        Ok(())
    }

    /// The units of an instanced scene: each mesh keyed by its content.
    fn scene_units(
        &self,
        input: &Path,
        main: &Path,
        settings: &BakeSettings,
    ) -> Result<(Vec<Unit>, Option<SceneFile>), String> {
        (self.stage)(input, "import scene");
        let scene = import_scene(input, &ImportLimits::default()).map_err(|e| e.to_string())?;
        let stem = main.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        let names: Vec<String> = scene.meshes.iter().map(|m| mesh_file_name(&stem, m.gltf_mesh)).collect();
        let file = SceneFile::from_scene(&scene, &names);
        let settings_text = serde_json::to_string(settings).map_err(|e| e.to_string())?;
        let units = scene
            .meshes
            .into_iter()
            .zip(&names)
            .map(|(m, name)| {
                let key = self.cache.map(|_| {
                    let hash = mesh_content_hash(&m.mesh);
                    CacheKey::for_mesh(&hash, &settings_text, mres_format::VERSION, BAKER_VERSION)
                });
                Unit { output: main.with_file_name(name), key, mesh: Some(m.mesh) }
            })
            .collect();
        Ok((units, Some(file)))
    }

    /// The bytes of one unit: from the cache, else baked (and put in the cache).
    fn bake_unit(&self, input: &Path, unit: Unit, settings: &BakeSettings) -> Result<UnitResult, String> {
        let mut result =
            UnitResult { output: unit.output, bytes: Vec::new(), cache_hit: false, repaired: false, baked: None };
        if let (Some(cache), Some(key)) = (self.cache, &unit.key) {
            match cache.get(key).map_err(|e| e.to_string())? {
                Lookup::Hit(bytes) => {
                    result.cache_hit = true;
                    result.bytes = bytes;
                    return Ok(result);
                }
                Lookup::Corrupt { .. } => result.repaired = true,
                Lookup::Miss => {}
            }
        }
        let stage = |line: &str| (self.stage)(input, line);
        let baked = match unit.mesh {
            None => bake_file(input, settings, &stage).map_err(|e| e.to_string())?,
            Some(mesh) => bake(mesh, settings, &stage).map_err(|e| format!("{}: {e}", result.output.display()))?,
        };
        result.baked = Some((baked.stats.build.shards, baked.stats.degenerate_dropped));
        if let (Some(cache), Some(key)) = (self.cache, &unit.key) {
            cache.put(key, &baked.bytes).map_err(|e| format!("cache: {e}"))?;
        }
        result.bytes = baked.bytes;
        Ok(result)
    }
}

/// One `.mres` of an asset to produce.
struct Unit {
    output: PathBuf,
    /// The cache key (`None` without a cache).
    key: Option<CacheKey>,
    /// The mesh to bake, or `None` to bake the input file itself (as before scenes: streamed
    /// OBJ, byte-identical output).
    mesh: Option<SourceMesh>,
}

/// One `.mres` produced.
struct UnitResult {
    output: PathBuf,
    bytes: Vec<u8>,
    cache_hit: bool,
    repaired: bool,
    /// (shards, degenerate triangles dropped) when baked now.
    baked: Option<(u64, u64)>,
}

/// The scene file of an asset that is one mesh (file name `mres`) with material names.
fn single_scene(input: &Path, mres: String, names: Vec<Option<String>>) -> SceneFile {
    let stem = input.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    SceneFile {
        version: SCENE_VERSION,
        meshes: vec![SceneFileMesh { file: mres, materials: names }],
        instances: vec![SceneFileInstance { name: stem, node: None, mesh: 0, transform: flatten(&IDENTITY) }],
    }
}

/// blake3 of a mesh's content: every array with a tag and its length, absent and present
/// attributes told apart, and the dropped-triangle count (it is part of the file header).
pub fn mesh_content_hash(mesh: &SourceMesh) -> [u8; 32] {
    let mut h = blake3::Hasher::new_derive_key("mres-cli 2025 source mesh content");
    let mut field = |tag: &[u8; 4], count: usize, words: &mut dyn Iterator<Item = [u8; 4]>| {
        h.update(tag);
        h.update(&(count as u64).to_le_bytes());
        words.for_each(|w| {
            h.update(&w);
        });
    };
    let floats = |v: &[f32]| v.iter().map(|x| x.to_le_bytes()).collect::<Vec<_>>();
    field(b"POSI", mesh.positions.len(), &mut floats(mesh.positions.as_flattened()).into_iter());
    if let Some(normals) = &mesh.normals {
        field(b"NORM", normals.len(), &mut floats(normals.as_flattened()).into_iter());
    }
    if let Some(uvs) = &mesh.uvs {
        field(b"TEXC", uvs.len(), &mut floats(uvs.as_flattened()).into_iter());
    }
    field(b"INDX", mesh.indices.len(), &mut mesh.indices.iter().map(|i| i.to_le_bytes()));
    field(b"MATL", mesh.materials.len(), &mut mesh.materials.iter().map(|i| i.to_le_bytes()));
    let dropped = mesh.degenerate_dropped;
    field(b"DROP", 2, &mut [dropped as u32, (dropped >> 32) as u32].into_iter().map(u32::to_le_bytes));
    *h.finalize().as_bytes()
}

/// Writes `bytes` to `path` atomically, unless the file already holds exactly them.
fn write_if_changed(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let unchanged = std::fs::metadata(path).is_ok_and(|m| m.len() == bytes.len() as u64)
        && std::fs::read(path).is_ok_and(|old| old == bytes);
    if unchanged {
        return Ok(());
    }
    write_atomic(path, bytes)
}

/// The `STEM.meshN.mres` files beside the main output `STEM.mres` (what a previous scene bake
/// left).
fn previous_outputs(main: &Path) -> Vec<PathBuf> {
    let (Some(dir), Some(stem)) = (main.parent(), main.file_stem().and_then(|s| s.to_str())) else {
        return Vec::new();
    };
    let prefix = format!("{stem}.mesh");
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            let number = name.strip_prefix(&prefix).and_then(|rest| rest.strip_suffix(".mres"));
            number.is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
        })
        .collect()
}

impl AssetReport {
    fn failed(input: &Path) -> AssetReport {
        AssetReport {
            input: input.to_path_buf(),
            output: None,
            mesh_outputs: Vec::new(),
            scene: None,
            status: "failed",
            error: None,
            input_triangles: 0,
            level0_triangles: 0,
            degenerate_dropped: 0,
            levels: 0,
            clusters: 0,
            groups: 0,
            root_clusters: 0,
            shards: None,
            bytes: 0,
            scene_bytes: 0,
            bytes_per_input_triangle: 0.0,
            seconds: 0.0,
            cache_hit: false,
            cache_repaired: false,
        }
    }

    /// Fills the figures from the `.mres` files written (summed over them; levels: the most).
    fn fill(&mut self, main: &Path, units: Vec<UnitResult>) {
        self.cache_hit = units.iter().all(|u| u.cache_hit);
        self.cache_repaired = units.iter().any(|u| u.repaired);
        self.status = if self.cache_hit { "cached" } else { "baked" };
        let baked: Vec<(u64, u64)> = units.iter().filter_map(|u| u.baked).collect();
        self.shards = (!baked.is_empty()).then(|| baked.iter().map(|b| b.0).sum());
        let mut known_dropped = 0;
        for unit in &units {
            if unit.output == main {
                self.output = Some(unit.output.clone());
            } else {
                self.mesh_outputs.push(unit.output.clone());
            }
            let Ok(file) = MresFile::parse(unit.bytes.clone()) else { continue };
            let level0 = level0_triangles(&file);
            self.input_triangles += file.header.source_triangles;
            self.level0_triangles += level0;
            known_dropped += unit.baked.map_or(file.header.source_triangles.saturating_sub(level0), |b| b.1);
            self.levels = self.levels.max(file.header.level_count);
            self.clusters += file.clusters.len() as u64;
            self.groups += file.groups.len() as u64;
            self.root_clusters +=
                file.groups.iter().filter(|g| g.error.is_infinite()).map(|g| g.cluster_count as u64).sum::<u64>();
            self.bytes += file.file_size() as u64;
        }
        if self.output.is_none() {
            // An instanced scene has no flattened mesh: the scene file stands for the asset.
            self.output = self.scene.clone();
        }
        self.degenerate_dropped = known_dropped;
        self.bytes_per_input_triangle = self.bytes as f64 / self.input_triangles.max(1) as f64;
    }
}

/// Triangles of the level-0 clusters (those no group's simplification produced).
pub fn level0_triangles(file: &MresFile) -> u64 {
    file.clusters.iter().filter(|c| c.own_group == mres_format::NO_GROUP).map(|c| c.triangle_count as u64).sum()
}
