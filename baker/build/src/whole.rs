//! A mesh of at most `shard_triangles` triangles is built whole: welded on a grid over its
//! bounds, cut into level-0 clusters, and built level by level to the root.

use crate::area;
use crate::dag::{BuildStats, BuiltDag, Collected, Converted, DagOutput, Frame, StageClock};
use crate::deviation::{part_sizes, Original};
use crate::error::BakeError;
use crate::levels::{groups, level0, Builder, Level0Edges, Prepared};
use crate::partition::numbered_in_triangle_order;
use crate::progress::Progress;
use crate::settings::{BakeSettings, ErrorBound};
use crate::weld::weld;
use mres_import::SourceMesh;

/// Builds the DAG of `mesh` (consumed, so that its memory is freed once welded) into `output`.
pub fn build_whole<O: DagOutput>(
    mesh: SourceMesh,
    settings: &BakeSettings,
    progress: Progress,
    output: O,
) -> Result<BuiltDag<O>, BakeError> {
    let mut stats = BuildStats::default();
    let mut clock = StageClock::start();
    progress(&format!("weld: {} triangles", mesh.triangle_count()));
    let welded = weld(&mesh, settings);
    let source_triangles = mesh.triangle_count() as u64 + mesh.degenerate_dropped;
    drop(mesh);
    let welded = match welded {
        Some(w) if !w.indices.is_empty() => w,
        _ => return Err(BakeError::Empty(source_triangles)),
    };
    clock.lap(&mut stats, "weld");
    // The whole level-0 surface that errors are measured against, made beside the clusters.
    let measured = settings.error_bound == ErrorBound::Measured;
    let (welded, order) = numbered_in_triangle_order(welded);
    // The mesh's edges, sorted once: its open and non-manifold edges for the clusters, its
    // open parts (a ladder's copies add no triangle, so they leave the edges as they are).
    let edges = Level0Edges::new(&welded);
    let welded = area::prepare(welded, settings, Some(edges.sorted()));
    // The part sizes and the first level's groups (METIS) are serial passes: beside the
    // surface's parallel build.
    let ((original, part_size), (clusters, parts)) = rayon::join(
        || rayon::join(|| measured.then(|| Original::new(&welded, &order)), || measured.then(|| part_sizes(&welded))),
        || {
            let clusters = level0(&welded, settings, (&edges, &edges.odd()), &order);
            let parts = groups(&welded, clusters.iter(), settings);
            (clusters, parts)
        },
    );
    drop(order);
    drop(edges);
    let prepared = Prepared { original, whole_mesh: true, part_size, parts: Some(parts) };
    let mut builder = Builder::with_prepared(&welded, settings, clusters, 0, prepared);
    clock.lap(&mut stats, "level 0");
    progress(&format!("level 0: {} clusters", builder.clusters.len()));
    let mut converted = Converted::new();
    builder.build_to_root(progress, &output, &mut converted);
    clock.lap(&mut stats, "levels");
    let cell = builder.finish(&output, converted)?;
    let mut dag = Collected::new(output);
    dag.collect(vec![cell], &mut stats);
    dag.welded_vertices = welded.positions.len() as u64;
    dag.degenerate = welded.degenerate_dropped;
    clock.lap(&mut stats, "encode");
    Ok(dag.finish(Frame::of(&welded), source_triangles, stats))
}
