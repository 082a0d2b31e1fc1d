//! The batch behind `bake-all`: find the assets, look each up in the content-addressed cache,
//! bake the misses in parallel, write the outputs atomically and report per asset. One bad
//! asset never stops the others.

use crate::config::PipelineConfig;
use cache::{CacheKey, KeyInputs, LocalDisk, Lookup, Storage};
use mres_build::bake::bake_file;
use mres_build::settings::BakeSettings;
use mres_format::MresFile;
use mres_import::referenced_files;
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Bumped whenever the baker's output for the same input and settings would change; part of
/// every cache key.
pub const BAKER_VERSION: u32 = 4;

/// What happened to one asset.
#[derive(Clone, Debug, Serialize)]
pub struct AssetReport {
    /// The input file.
    pub input: PathBuf,
    /// The `.mres` written (absent on failure).
    pub output: Option<PathBuf>,
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
    /// Bytes of the `.mres` file.
    pub bytes: u64,
    /// Bytes per source triangle.
    pub bytes_per_input_triangle: f64,
    /// Wall seconds spent on this asset (key, lookup, bake, write).
    pub seconds: f64,
    /// Whether the output came from the cache.
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

    /// The `.mres` file `input` is baked to.
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

    fn process(&self, input: &Path) -> AssetReport {
        let start = Instant::now();
        let output = self.output_for(input);
        let settings = self.config.settings_for(&self.relative(input));
        let mut report = AssetReport {
            input: input.to_path_buf(),
            output: None,
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
            bytes_per_input_triangle: 0.0,
            seconds: 0.0,
            cache_hit: false,
            cache_repaired: false,
        };
        // Dropped degenerates are known from the bake; for a cache hit they are derived below.
        let mut dropped = None;
        let result = (|| -> Result<Vec<u8>, String> {
            let key = match self.cache {
                Some(_) => Some(cache_key(input, &settings)?),
                None => None,
            };
            if let (Some(cache), Some(key)) = (self.cache, &key) {
                match cache.get(key).map_err(|e| e.to_string())? {
                    Lookup::Hit(bytes) => {
                        report.cache_hit = true;
                        return Ok(bytes);
                    }
                    Lookup::Corrupt { .. } => report.cache_repaired = true,
                    Lookup::Miss => {}
                }
            }
            let baked = bake_file(input, &settings, &|line| (self.stage)(input, line)).map_err(|e| e.to_string())?;
            report.shards = Some(baked.stats.build.shards);
            dropped = Some(baked.stats.degenerate_dropped);
            if let (Some(cache), Some(key)) = (self.cache, &key) {
                cache.put(key, &baked.bytes).map_err(|e| format!("cache: {e}"))?;
            }
            Ok(baked.bytes)
        })();
        match result {
            Ok(bytes) => {
                let unchanged = std::fs::metadata(&output).is_ok_and(|m| m.len() == bytes.len() as u64)
                    && std::fs::read(&output).is_ok_and(|old| old == bytes);
                match (unchanged, write_atomic(&output, &bytes)) {
                    (true, _) | (false, Ok(())) => {
                        report.status = if report.cache_hit { "cached" } else { "baked" };
                        report.output = Some(output.clone());
                        if let Ok(file) = MresFile::parse(bytes) {
                            report.input_triangles = file.header.source_triangles;
                            report.level0_triangles = level0_triangles(&file);
                            report.degenerate_dropped =
                                dropped.unwrap_or(report.input_triangles.saturating_sub(report.level0_triangles));
                            report.levels = file.header.level_count;
                            report.clusters = file.clusters.len() as u64;
                            report.groups = file.groups.len() as u64;
                            report.root_clusters = file
                                .groups
                                .iter()
                                .filter(|g| g.error.is_infinite())
                                .map(|g| g.cluster_count as u64)
                                .sum();
                            report.bytes = file.file_size() as u64;
                            report.bytes_per_input_triangle =
                                report.bytes as f64 / report.input_triangles.max(1) as f64;
                        }
                    }
                    (false, Err(e)) => report.error = Some(format!("{}: writing: {e}", output.display())),
                }
            }
            Err(e) => report.error = Some(e),
        }
        report.seconds = start.elapsed().as_secs_f64();
        report
    }
}

/// Triangles of the level-0 clusters (those no group's simplification produced).
pub fn level0_triangles(file: &MresFile) -> u64 {
    file.clusters.iter().filter(|c| c.own_group == mres_format::NO_GROUP).map(|c| c.triangle_count as u64).sum()
}
