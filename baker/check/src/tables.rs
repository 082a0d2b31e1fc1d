//! The tables the checks share: the validator's thresholds ([`Thresholds`]) and the file's
//! edges welded by grid position (`Edges`, built by `edge_tables`).

use mres_format::{MresFile, NO_GROUP};
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use serde::Serialize;

/// Every threshold the validator enforces, in one place. Defaults and why:
#[derive(Clone, Debug, Serialize)]
pub struct Thresholds {
    /// docs/INVARIANTS.md §3: levels ≤ `max_depth_factor` · log2(level-0 clusters) + `depth_slack`. Halving
    /// per level gives a factor of 1 (clusters halve); 2 allows stuck groups and small tops.
    pub max_depth_factor: f64,
    /// See `max_depth_factor`.
    pub depth_slack: f64,
    /// docs/INVARIANTS.md §3: most clusters in a non-root group (Nanite's upper bound).
    pub max_group_size: u32,
    /// docs/INVARIANTS.md §3: mean edge age, in levels (Pettett's exact partitioning reached 1.05; 1.5
    /// leaves room for stuck groups).
    pub max_edge_age_mean: f64,
    /// docs/INVARIANTS.md §3: most clusters (as a fraction of derived clusters) with the same boundary as
    /// a child. A few occur where a small member had all its vertices locked (next to holes,
    /// whose edges stay locked: 2% on a sphere with 200 holes); many would mean borders stay
    /// put across levels.
    pub max_same_boundary_fraction: f64,
    /// docs/INVARIANTS.md §4: largest measured distance / stored error over the sampled cuts. The baker
    /// stores, per group, its members' error plus the sampled two-sided distance between its
    /// output and its input (`deviation`), rounded up: by the triangle inequality that bounds
    /// the distance to the original, and it samples the points this check samples (centroids
    /// and edge midpoints), so no tolerance is needed. Measured worst 1.00 (p99 0.43–0.81) on
    /// the sample assets, the CI's nasty cases and the Stanford dragon; it was 1.6–2.6, 3.8 and
    /// 40 with meshoptimizer's estimates.
    pub max_error_ratio: f64,
    /// docs/INVARIANTS.md §4: uniform cuts measured and points sampled per cut and direction.
    pub honesty_cuts: usize,
    /// See `honesty_cuts`.
    pub honesty_samples: usize,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            max_depth_factor: 2.0,
            depth_slack: 2.0,
            max_group_size: 32,
            max_edge_age_mean: 1.5,
            max_same_boundary_fraction: 0.05,
            max_error_ratio: 1.0,
            honesty_cuts: 6,
            honesty_samples: 20_000,
        }
    }
}

/// Edge tables of a decoded file.
pub(crate) struct Edges {
    /// Per cluster: (edge id, uses within the cluster, marked uses among them).
    pub(crate) per_cluster: Vec<Vec<(u32, u8, u8)>>,
    /// Uses of each edge in the original (level-0) mesh.
    pub(crate) original: Vec<u32>,
    /// Edge id → the two grid positions (for messages).
    pub(crate) ends: Vec<([i32; 3], [i32; 3])>,
}

/// A cluster's triangle edges as (key by welded position id, marked), sorted.
fn cluster_edges(c: &mres_format::DecodedCluster, ids: &[u32]) -> Vec<(u64, bool)> {
    let mut keys: Vec<(u64, bool)> = c
        .indices
        .chunks_exact(3)
        .enumerate()
        .flat_map(|(t, tri)| {
            let mask = c.open_edges.get(t).copied().unwrap_or(0);
            (0..3).map(move |k| {
                let key = mres_geom::edges::edge_key(ids[tri[k] as usize], ids[tri[(k + 1) % 3] as usize]);
                (key, mask >> k & 1 != 0)
            })
        })
        .collect();
    keys.sort_unstable();
    keys
}

/// Welds every cluster's edges by grid position across the file and counts their uses.
pub(crate) fn edge_tables(file: &MresFile, decoded: &[mres_format::DecodedCluster]) -> Edges {
    // Weld by grid position across the whole file.
    let mut position_id: FxHashMap<[i32; 3], u32> = FxHashMap::default();
    let mut positions = Vec::new();
    let mut keys_per_cluster: Vec<Vec<(u64, bool)>> = Vec::with_capacity(decoded.len());
    for c in decoded {
        let ids: Vec<u32> = c
            .positions
            .iter()
            .map(|p| {
                *position_id.entry(*p).or_insert_with(|| {
                    positions.push(*p);
                    positions.len() as u32 - 1
                })
            })
            .collect();
        keys_per_cluster.push(cluster_edges(c, &ids));
    }
    let mut all: Vec<u64> = keys_per_cluster.iter().flatten().map(|k| k.0).collect();
    all.par_sort_unstable();
    all.dedup();
    let id_of = |k: u64| all.binary_search(&k).unwrap_or(0) as u32;
    let per_cluster: Vec<Vec<(u32, u8, u8)>> = keys_per_cluster
        .par_iter()
        .map(|keys| {
            keys.chunk_by(|a, b| a.0 == b.0)
                .map(|run| {
                    let marked = run.iter().filter(|k| k.1).count();
                    (id_of(run[0].0), run.len().min(255) as u8, marked.min(255) as u8)
                })
                .collect()
        })
        .collect();
    let mut original = vec![0u32; all.len()];
    for (c, info) in file.clusters.iter().enumerate() {
        if info.own_group == NO_GROUP {
            for &(e, n, _) in &per_cluster[c] {
                original[e as usize] += n as u32;
            }
        }
    }
    let ends = all.iter().map(|k| (positions[(k >> 32) as usize], positions[(k & 0xffff_ffff) as usize])).collect();
    Edges { per_cluster, original, ends }
}
