//! One bake: open the source, build its DAG whole or in shards, write `.mres` bytes.

use crate::dag::BuiltDag;
use crate::encode::{write, Encoder};
pub use crate::error::BakeError;
pub use crate::progress::Progress;
use crate::settings::BakeSettings;
use crate::shard::build_sharded;
pub use crate::source::Source;
use crate::whole::build_whole;
use std::path::Path;
use std::time::Instant;

pub use crate::dag::BuildStats;

/// The result of baking one mesh.
pub struct Baked {
    /// The `.mres` file.
    pub bytes: Vec<u8>,
    /// Figures about the build.
    pub stats: BakeStats,
}

/// Figures about one bake, for reports and benchmarks.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct BakeStats {
    /// Triangles in the source file.
    pub source_triangles: u64,
    /// Triangles dropped as degenerate (importer plus grid welding).
    pub degenerate_dropped: u64,
    /// Vertices after welding.
    pub welded_vertices: u64,
    /// Groups in the DAG.
    pub groups: u64,
    /// Clusters in the DAG.
    pub clusters: u64,
    /// DAG build figures.
    pub build: BuildStats,
    /// Seconds spent importing.
    pub import_seconds: f64,
    /// Seconds spent welding, building and writing.
    pub build_seconds: f64,
    /// Size of the `.mres` file.
    pub bytes: u64,
}

/// Imports the mesh file at `path` (a large OBJ is streamed) and bakes it, reporting each
/// stage to `progress` (`&|_| {}` for none).
pub fn bake_file(path: &Path, settings: &BakeSettings, progress: Progress) -> Result<Baked, BakeError> {
    // At error level, so that every event of the bake names its file (warnings included).
    let _span = tracing::error_span!("bake", path = %path.display()).entered();
    let start = Instant::now();
    progress("import");
    let source = Source::open(path, settings.shard_triangles)?;
    let import_seconds = start.elapsed().as_secs_f64();
    tracing::info!(seconds = import_seconds, streamed = matches!(source, Source::Obj(_)), "imported");
    let baked = bake(source, settings, progress)?;
    Ok(Baked { stats: BakeStats { import_seconds, ..baked.stats }, ..baked })
}

/// Bakes `source` (consumed, so that its memory is freed as soon as it has been read): whole
/// if it has at most `settings.shard_triangles` triangles, else in shards.
pub fn bake<'p>(
    source: impl Into<Source<'p>>,
    settings: &BakeSettings,
    progress: Progress,
) -> Result<Baked, BakeError> {
    settings.check().map_err(BakeError::Settings)?;
    let start = Instant::now();
    let output = Encoder::new(settings);
    let dag = match source.into() {
        Source::Mesh(mesh) if mesh.triangle_count() as u64 <= settings.shard_triangles => {
            build_whole(mesh, settings, progress, output)?
        }
        source => build_sharded(source, settings, progress, output)?,
    };
    let stats = stats(&dag);
    progress("write");
    let write_start = Instant::now();
    let bytes = write(dag, settings.zstd_level)?;
    let mut stats = BakeStats { bytes: bytes.len() as u64, build_seconds: start.elapsed().as_secs_f64(), ..stats };
    stats.build.stage_seconds.push(("write".into(), write_start.elapsed().as_secs_f64()));
    let (groups, clusters, stages) = (stats.groups, stats.clusters, &stats.build.stage_seconds);
    tracing::info!(bytes = bytes.len(), groups, clusters, shards = stats.build.shards, stages = ?stages, "baked");
    Ok(Baked { bytes, stats })
}

/// The figures of a built DAG (the file's size and the times are added when written).
fn stats(dag: &BuiltDag<Encoder>) -> BakeStats {
    BakeStats {
        source_triangles: dag.source_triangles,
        degenerate_dropped: dag.degenerate_dropped,
        welded_vertices: dag.welded_vertices,
        groups: dag.groups.len() as u64,
        clusters: dag.clusters.count() as u64,
        build: dag.stats.clone(),
        ..Default::default()
    }
}
