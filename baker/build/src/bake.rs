//! One bake: import → weld → DAG → `.mres` bytes.

use crate::dag::{build_dag, BuildStats};
pub use crate::error::BakeError;
pub use crate::progress::Progress;
use crate::settings::BakeSettings;
use crate::shard::{build_sharded, ShardSource};
use crate::weld::weld;
use mres_import::mesh::{Corner, NONE};
use mres_import::obj_stream::ObjVertices;
use mres_import::SourceMesh;
use mres_import::{import_file, ImportLimits, InputKind};
use std::path::Path;
use std::time::Instant;

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

/// Imports and bakes the mesh file at `path`.
pub fn bake_file(path: &Path, settings: &BakeSettings) -> Result<Baked, BakeError> {
    bake_file_with_progress(path, settings, &|_| {})
}

/// [`bake_file`], reporting each stage to `progress`.
pub fn bake_file_with_progress(path: &Path, settings: &BakeSettings, progress: Progress) -> Result<Baked, BakeError> {
    let _span = tracing::info_span!("bake", path = %path.display()).entered();
    let start = Instant::now();
    progress("import");
    let limits = ImportLimits::default();
    // A large OBJ is read in two streaming passes, so that it never has to fit in memory as
    // text plus a mesh; if it is large enough to shard, the shards are fed from the file.
    let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    if InputKind::from_path(path) == Some(InputKind::Obj)
        && size / OBJ_MIN_BYTES_PER_TRIANGLE > settings.shard_triangles
    {
        settings.check().map_err(BakeError::Settings)?;
        let mut obj = ObjVertices::read(path, &limits)?;
        if obj.triangles > settings.shard_triangles {
            let import_seconds = start.elapsed().as_secs_f64();
            tracing::info!(triangles = obj.triangles, seconds = import_seconds, "streaming import, pass 1");
            let (positions, normals, uvs) =
                (std::mem::take(&mut obj.positions), std::mem::take(&mut obj.normals), std::mem::take(&mut obj.uvs));
            let triangles = obj.triangles;
            let for_each_triangle = Box::new(move |f: &mut dyn FnMut([Corner; 3], u32)| obj.for_each_triangle(path, f));
            let source = ShardSource { positions, normals, uvs, triangles, for_each_triangle };
            let mut baked = bake_sharded(source, settings, progress)?;
            baked.stats.import_seconds = import_seconds;
            return Ok(baked);
        }
    }
    let mesh = import_file(path, &limits)?;
    let import_seconds = start.elapsed().as_secs_f64();
    tracing::info!(triangles = mesh.triangle_count(), seconds = import_seconds, "imported");
    let mut baked = bake_mesh_with_progress(mesh, settings, progress)?;
    baked.stats.import_seconds = import_seconds;
    Ok(baked)
}

/// Bakes an imported mesh (consumed, so its memory is freed once welded).
pub fn bake_mesh(mesh: SourceMesh, settings: &BakeSettings) -> Result<Baked, BakeError> {
    bake_mesh_with_progress(mesh, settings, &|_| {})
}

/// [`bake_mesh`], reporting each stage to `progress`.
pub fn bake_mesh_with_progress(
    mesh: SourceMesh,
    settings: &BakeSettings,
    progress: Progress,
) -> Result<Baked, BakeError> {
    settings.check().map_err(BakeError::Settings)?;
    if mesh.triangle_count() as u64 > settings.shard_triangles {
        let SourceMesh { positions, normals, uvs, indices, materials, degenerate_dropped } = mesh;
        let index_or_none = |present: bool| if present { |v: u32| v } else { |_: u32| NONE };
        let (vn, vt) = (index_or_none(normals.is_some()), index_or_none(uvs.is_some()));
        let triangles = materials.len() as u64;
        let for_each_triangle = Box::new(move |f: &mut dyn FnMut([Corner; 3], u32)| {
            for (t, &material) in indices.chunks_exact(3).zip(&materials) {
                f([0, 1, 2].map(|k| Corner { v: t[k], vt: vt(t[k]), vn: vn(t[k]) }), material);
            }
            Ok(())
        });
        let source = ShardSource {
            positions,
            normals: normals.unwrap_or_default(),
            uvs: uvs.unwrap_or_default(),
            triangles,
            for_each_triangle,
        };
        let mut baked = bake_sharded(source, settings, progress)?;
        baked.stats.degenerate_dropped += degenerate_dropped;
        baked.stats.source_triangles += degenerate_dropped;
        return Ok(baked);
    }
    let start = Instant::now();
    progress(&format!("weld: {} triangles", mesh.triangle_count()));
    let welded = weld(&mesh, settings);
    let weld_seconds = start.elapsed().as_secs_f64();
    let source_triangles = mesh.triangle_count() as u64 + mesh.degenerate_dropped;
    drop(mesh);
    let welded = match welded {
        Some(w) if !w.indices.is_empty() => w,
        _ => return Err(BakeError::Empty(source_triangles)),
    };
    let (dag, mut build) = build_dag(&welded, settings, progress);
    build.stage_seconds.insert(0, ("weld".into(), weld_seconds));
    let mut stats = BakeStats {
        source_triangles,
        degenerate_dropped: welded.degenerate_dropped,
        welded_vertices: welded.positions.len() as u64,
        groups: dag.groups.len() as u64,
        clusters: dag.clusters.len() as u64,
        build,
        ..Default::default()
    };
    drop(welded);
    progress("write");
    let write_start = Instant::now();
    let bytes = mres_format::write_mres(&dag, settings.zstd_level)?;
    stats.build.stage_seconds.push(("write".into(), write_start.elapsed().as_secs_f64()));
    tracing::info!(bytes = bytes.len(), groups = stats.groups, clusters = stats.clusters, stages = ?stats.build.stage_seconds, "baked");
    Ok(Baked {
        stats: BakeStats { bytes: bytes.len() as u64, build_seconds: start.elapsed().as_secs_f64(), ..stats },
        bytes,
    })
}

/// The fewest bytes an OBJ triangle takes ("f 1 2 3\n" is 8, before any `v` line): files
/// smaller than this times `shard_triangles` cannot need sharding and are imported whole.
const OBJ_MIN_BYTES_PER_TRIANGLE: u64 = 8;

/// Bakes a mesh in shards (see `shard`); the source is freed once the shards are read.
fn bake_sharded(source: ShardSource, settings: &BakeSettings, progress: Progress) -> Result<Baked, BakeError> {
    let start = Instant::now();
    let dag = build_sharded(source, settings, progress)?;
    progress("write");
    let write_start = Instant::now();
    let (groups, clusters) = (dag.groups.len() as u64, dag.clusters.len() as u64);
    let mut build = dag.stats;
    let bytes = mres_format::write::write_encoded(&dag.header, &dag.groups, dag.clusters, settings.zstd_level)?;
    build.stage_seconds.push(("write".into(), write_start.elapsed().as_secs_f64()));
    tracing::info!(bytes = bytes.len(), groups, clusters, shards = build.shards, stages = ?build.stage_seconds, "baked");
    let stats = BakeStats {
        source_triangles: dag.header.source_triangles,
        degenerate_dropped: dag.degenerate_dropped,
        welded_vertices: dag.welded_vertices,
        groups,
        clusters,
        build,
        import_seconds: 0.0,
        build_seconds: start.elapsed().as_secs_f64(),
        bytes: bytes.len() as u64,
    };
    Ok(Baked { bytes, stats })
}
