//! docs/INVARIANTS.md §3, a well-conditioned DAG (Cignoni et al., "Batched Multi-Triangulation";
//! Pettett §3.1.4): depth against log2 of the leaf count, triangle reduction and cluster growth
//! per level, no cluster with the same boundary as one of its children, group sizes, and
//! **edge age** — how many levels an original edge survives.

use crate::tables::{Edges, Thresholds};
use mres_format::{DecodedCluster, MresFile, NO_GROUP};
use serde::Serialize;
use std::collections::BTreeMap;

/// The DAG's shape figures.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Conditioning {
    /// log2 of the number of level-0 clusters: the depth a balanced DAG needs.
    pub log2_level0_clusters: f64,
    /// Levels down to the first level of a single cluster (the root chain above it is not
    /// counted; docs/INVARIANTS.md §3).
    pub depth: u32,
    /// `depth` divided by `log2_level0_clusters`.
    pub depth_ratio: f64,
    /// Triangles of level l+1 divided by triangles of level l.
    pub reduction_per_level: Vec<f64>,
    /// Mean cluster bounding radius (object space) per level: grows geometrically in a
    /// well-conditioned DAG.
    pub mean_cluster_radius_per_level: Vec<f64>,
    /// Number of non-root groups by member count.
    pub group_size_histogram: BTreeMap<u32, u64>,
    /// Clusters whose boundary equals one of their children's (a member left unchanged because
    /// all its vertices were locked, then emitted again).
    pub same_boundary_clusters: u64,
    /// A few of them.
    pub same_boundary_examples: Vec<String>,
    /// Mean over original interior edges of the highest level they still appear at.
    pub edge_age_mean: f64,
    /// Maximum of the same.
    pub edge_age_max: u32,
    /// Original interior edges by age: entry `a` counts the edges last seen at level `a`. A
    /// band of edges kept long (e.g. along shard borders) shows as a tail.
    pub edge_age_histogram: Vec<u64>,
    /// Original open and non-manifold edges: locked in every cut by design, not aged.
    pub locked_original_edges: u64,
}

/// Computes the figures and lists violations of `thresholds`.
pub(crate) fn conditioning(
    file: &MresFile,
    decoded: &[DecodedCluster],
    edges: &Edges,
    thresholds: &Thresholds,
) -> (Conditioning, Vec<String>) {
    let mut violations = Vec::new();
    let groups = &file.groups;
    let level_of = |c: usize| -> u32 {
        match file.clusters[c].own_group {
            NO_GROUP => 0,
            g => groups[g as usize].level + 1,
        }
    };
    let levels = (0..file.clusters.len()).map(level_of).max().map_or(0, |l| l + 1) as usize;
    let mut out = Conditioning::default();

    let mut triangles = vec![0u64; levels];
    let mut radius = vec![(0.0f64, 0u64); levels];
    let step = file.header.grid.step as f64;
    for (c, d) in decoded.iter().enumerate() {
        let l = level_of(c) as usize;
        triangles[l] += d.indices.len() as u64 / 3;
        let mut lo = [i32::MAX; 3];
        let mut hi = [i32::MIN; 3];
        for p in &d.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let diag = (0..3).map(|k| ((hi[k] as f64 - lo[k] as f64) * step).powi(2)).sum::<f64>().sqrt();
        radius[l].0 += diag / 2.0;
        radius[l].1 += 1;
    }
    let level0_clusters = radius.first().map_or(0, |r| r.1);
    out.log2_level0_clusters = (level0_clusters.max(1) as f64).log2();
    // The depth counts the levels down to the first one of a single cluster: the root chain
    // above it (a lone cluster simplified on by itself, a level at a time) is a list of ever
    // coarser choices, not a level of the hierarchy.
    let depth = radius.iter().position(|r| r.1 == 1).map_or(levels, |l| l + 1);
    out.depth = depth as u32;
    out.depth_ratio = depth as f64 / out.log2_level0_clusters.max(1.0);
    out.reduction_per_level = triangles.windows(2).map(|w| w[1] as f64 / w[0].max(1) as f64).collect();
    out.mean_cluster_radius_per_level = radius.iter().map(|(sum, n)| sum / (*n).max(1) as f64).collect();
    if depth as f64 > thresholds.max_depth_factor * out.log2_level0_clusters + thresholds.depth_slack {
        violations.push(format!(
            "DAG depth {depth} exceeds {} x log2(level-0 clusters) + {} = {:.1} (well-conditioned DAG)",
            thresholds.max_depth_factor,
            thresholds.depth_slack,
            thresholds.max_depth_factor * out.log2_level0_clusters + thresholds.depth_slack
        ));
    }

    for (g, group) in groups.iter().enumerate() {
        if group.error.is_finite() {
            *out.group_size_histogram.entry(group.cluster_count).or_insert(0) += 1;
            if group.cluster_count > thresholds.max_group_size {
                violations.push(format!(
                    "group {g}: {} clusters, above the maximum group size {} (well-conditioned DAG)",
                    group.cluster_count, thresholds.max_group_size
                ));
            }
        }
    }

    // Boundaries: a cluster's edges used an odd number of times unmarked within it (marked
    // edges are open border, not shared with a neighbour). A cluster whose remaining boundary
    // is empty (a whole closed part, or a part bounded only by open border) has nothing that
    // could have moved and is not compared.
    let boundary =
        |c: usize| -> Vec<u32> { edges.per_cluster[c].iter().filter(|e| (e.1 - e.2) % 2 == 1).map(|e| e.0).collect() };
    for c in 0..file.clusters.len() {
        let own = file.clusters[c].own_group;
        if own == NO_GROUP {
            continue;
        }
        let g = &groups[own as usize];
        let mine = boundary(c);
        if mine.is_empty() {
            continue;
        }
        if let Some(child) =
            (g.first_cluster..g.first_cluster + g.cluster_count).find(|&m| boundary(m as usize) == mine)
        {
            out.same_boundary_clusters += 1;
            if out.same_boundary_examples.len() < 5 {
                out.same_boundary_examples.push(format!("cluster {c} and its child {child} in group {own}"));
            }
        }
    }
    let derived = file.clusters.iter().filter(|c| c.own_group != NO_GROUP).count().max(1);
    if out.same_boundary_clusters as f64 > thresholds.max_same_boundary_fraction * derived as f64 {
        violations.push(format!(
            "{} of {derived} clusters have the same boundary as a child (more than {}; e.g. {}) (well-conditioned DAG)",
            out.same_boundary_clusters,
            thresholds.max_same_boundary_fraction,
            out.same_boundary_examples.join("; ")
        ));
    }

    // Edge age over the original's interior edges.
    let mut age: Vec<i64> = edges.original.iter().map(|&n| if n == 2 { 0 } else { -1 }).collect();
    out.locked_original_edges = edges.original.iter().filter(|&&n| n != 0 && n != 2).count() as u64;
    for (c, list) in edges.per_cluster.iter().enumerate() {
        let l = level_of(c) as i64;
        for &(e, _, _) in list {
            if age[e as usize] >= 0 && edges.original[e as usize] == 2 {
                age[e as usize] = age[e as usize].max(l);
            }
        }
    }
    let aged: Vec<i64> = age.into_iter().zip(&edges.original).filter(|(_, &n)| n == 2).map(|(a, _)| a).collect();
    out.edge_age_mean = aged.iter().sum::<i64>() as f64 / aged.len().max(1) as f64;
    out.edge_age_max = aged.iter().copied().max().unwrap_or(0) as u32;
    out.edge_age_histogram = vec![0; out.edge_age_max as usize + 1];
    for &a in &aged {
        out.edge_age_histogram[a as usize] += 1;
    }
    if out.edge_age_mean > thresholds.max_edge_age_mean {
        violations.push(format!(
            "mean edge age {:.2} above {} (edges stay locked too long)",
            out.edge_age_mean, thresholds.max_edge_age_mean
        ));
    }
    (out, violations)
}
