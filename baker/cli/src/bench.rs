//! Bench: our builder and meshoptimizer's clusterlod (`meshopt::clusterlod::clod_build`) on the
//! same input, each run by `mres bench` in its own child process so that peak RSS is per
//! builder. This module holds what one child does.

use meshopt::clusterlod::{clod_build, clod_default_config, ClodMesh};
use mres_build::bake::bake;
use mres_build::settings::BakeSettings;
use mres_format::{select, MresFile};
use mres_import::SourceMesh;
use serde::Serialize;
use std::time::Instant;

/// Relative thresholds (× bounding-box diagonal) at which triangles per uniform cut are counted.
pub const CUT_THRESHOLDS: [f32; 4] = [0.0, 1e-4, 1e-3, 1e-2];

/// What one builder run measured.
#[derive(Clone, Debug, Default, Serialize, serde::Deserialize)]
pub struct BuilderRun {
    /// "mres" or "clusterlod".
    pub builder: String,
    /// Seconds to build (ours: weld + DAG + compressed file; clusterlod: clod_build).
    pub seconds: f64,
    /// Seconds to build the DAG in memory, the part comparable to clod_build (ours: weld + DAG,
    /// without encoding and compressing the file; clusterlod: the same as `seconds`).
    #[serde(default)]
    pub dag_seconds: f64,
    /// Peak resident set of the whole child process (import included), bytes.
    pub peak_rss_bytes: u64,
    /// Input triangles: the source's triangles after triangulation, before degenerate ones
    /// are dropped (what a bake's `.mres` header calls `source_triangles`).
    pub input_triangles: u64,
    /// Triangles of the builder's level 0 (for ours the welded source, without degenerates).
    #[serde(default)]
    pub level0_triangles: u64,
    /// Input triangles dropped as degenerate: `input_triangles - level0_triangles`.
    #[serde(default)]
    pub degenerate_dropped: u64,
    /// DAG levels.
    pub levels: u32,
    /// Clusters in the top (infinite-error) groups.
    pub root_clusters: u64,
    /// Mean triangles per level-0 cluster.
    pub level0_fill: f64,
    /// Triangles in the uniform cut at each of [`CUT_THRESHOLDS`] × diagonal.
    pub cut_triangles: Vec<u64>,
    /// Size of the `.mres` file (ours only).
    pub bytes: u64,
}

/// Peak RSS of this process (`VmHWM`), bytes.
pub fn peak_rss() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map_or(0, |kb| kb * 1024)
}

fn diagonal(mesh: &SourceMesh) -> f32 {
    mesh.bounds()
        .map_or(0.0, |(lo, hi)| ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt())
}

/// Runs our builder.
pub fn run_mres(mesh: SourceMesh, settings: &BakeSettings) -> anyhow::Result<BuilderRun> {
    let input_triangles = mesh.triangle_count() as u64 + mesh.degenerate_dropped;
    let diag = diagonal(&mesh);
    let start = Instant::now();
    let baked = bake(mesh, settings, &|_| {})?;
    let seconds = start.elapsed().as_secs_f64();
    let dag_seconds =
        baked.stats.build.stage_seconds.iter().filter(|(s, _)| s != "write" && s != "encode").map(|(_, t)| t).sum();
    let file = MresFile::parse(baked.bytes)?;
    let tri = |cut: Vec<u32>| cut.iter().map(|&c| file.clusters[c as usize].triangle_count as u64).sum();
    let level0: Vec<_> = file.clusters.iter().filter(|c| c.own_group == mres_format::NO_GROUP).collect();
    let level0_triangles = crate::batch::level0_triangles(&file);
    Ok(BuilderRun {
        builder: "mres".into(),
        seconds,
        dag_seconds,
        peak_rss_bytes: peak_rss(),
        input_triangles,
        level0_triangles,
        degenerate_dropped: input_triangles.saturating_sub(level0_triangles),
        levels: file.header.level_count,
        root_clusters: baked.stats.build.root_clusters,
        level0_fill: level0.iter().map(|c| c.triangle_count as f64).sum::<f64>() / level0.len().max(1) as f64,
        cut_triangles: CUT_THRESHOLDS
            .iter()
            .map(|t| tri(select::uniform_cut(&file.groups, &file.clusters, t * diag)))
            .collect(),
        bytes: file.file_size() as u64,
    })
}

/// Runs clusterlod with its default configuration for 128-triangle clusters, with the same
/// attribute weights we use (normals and UVs when present).
pub fn run_clusterlod(mesh: SourceMesh, settings: &BakeSettings) -> anyhow::Result<BuilderRun> {
    let input_triangles = mesh.triangle_count() as u64 + mesh.degenerate_dropped;
    let diag = diagonal(&mesh);
    let start = Instant::now();
    let bytes = meshopt::typed_to_bytes(&mesh.positions);
    let adapter = meshopt::VertexDataAdapter::new(bytes, 12, 0)?;
    let mut attributes = Vec::new();
    let mut weights = Vec::new();
    if let Some(n) = &mesh.normals {
        weights.extend_from_slice(&[settings.normal_weight; 3]);
        attributes.push(n.iter().map(|v| v.to_vec()).collect::<Vec<_>>());
    }
    if let Some(uv) = &mesh.uvs {
        weights.extend_from_slice(&[settings.uv_weight; 2]);
        attributes.push(uv.iter().map(|v| v.to_vec()).collect::<Vec<_>>());
    }
    let rows: Vec<f32> =
        (0..mesh.positions.len()).flat_map(|v| attributes.iter().flat_map(move |a| a[v].clone())).collect();
    drop(attributes);
    let mut clod_mesh = ClodMesh::new(&mesh.indices, &adapter);
    if !weights.is_empty() {
        clod_mesh.vertex_attributes = &rows;
        clod_mesh.vertex_attributes_stride = weights.len() * 4;
        clod_mesh.attribute_weights = &weights;
    }
    let config = clod_default_config(settings.max_triangles as usize);
    // Per cluster: (group, refined, triangles); per group: (depth, error).
    let mut groups: Vec<(i32, f32)> = Vec::new();
    let mut clusters: Vec<(usize, i32, u32)> = Vec::new();
    clod_build(config, &clod_mesh, |group, out| {
        let id = groups.len();
        groups.push((group.depth, group.simplified.error));
        clusters.extend(out.iter().map(|c| (id, c.refined, (c.indices.len() / 3) as u32)));
        id as i32
    });
    let seconds = start.elapsed().as_secs_f64();
    let cut = |t: f32| -> u64 {
        clusters
            .iter()
            .filter(|(g, refined, _)| {
                let own = if *refined < 0 { 0.0 } else { groups[*refined as usize].1 };
                own <= t && t < groups[*g].1
            })
            .map(|c| c.2 as u64)
            .sum()
    };
    let level0: Vec<_> = clusters.iter().filter(|c| c.1 < 0).collect();
    let level0_triangles = level0.iter().map(|c| c.2 as u64).sum::<u64>();
    Ok(BuilderRun {
        builder: "clusterlod".into(),
        seconds,
        dag_seconds: seconds,
        peak_rss_bytes: peak_rss(),
        input_triangles,
        level0_triangles,
        degenerate_dropped: input_triangles.saturating_sub(level0_triangles),
        levels: groups.iter().map(|g| g.0 + 1).max().unwrap_or(0) as u32,
        root_clusters: clusters.iter().filter(|c| groups[c.0].1 == f32::MAX).count() as u64,
        level0_fill: level0.iter().map(|c| c.2 as f64).sum::<f64>() / level0.len().max(1) as f64,
        cut_triangles: CUT_THRESHOLDS.iter().map(|t| cut(t * diag)).collect(),
        bytes: 0,
    })
}
