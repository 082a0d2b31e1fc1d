//! Partition: group clusters with METIS on the cluster graph.
//!
//! Edge weights count the boundary edges two clusters share (Nanite, Pettett §3.1.3). Clusters
//! of different connected components that lie close together get weak locality links
//! (weight 1, as Nanite's partitioner adds), so disconnected parts group together and the DAG
//! still ends in a single root. Group sizes are held in range by recursive bisection with
//! target part weights (Pettett §3.1.4's "exact partitioning"): a set of `n` clusters is cut in
//! two parts sized for `⌊k/2⌋` and `⌈k/2⌉` groups, `k = round(n / target)`.

use crate::weld::WeldedMesh;
use rayon::prelude::*;

/// Locality links: each cluster is linked to this many successors in Morton order that
/// belong to another connected component.
const LOCALITY_WINDOW: usize = 8;
/// Weight of a locality link; a shared boundary edge weighs [`EDGE_WEIGHT`].
const LOCALITY_WEIGHT: i32 = 1;
/// Weight of one shared boundary edge.
const EDGE_WEIGHT: i32 = 16;

/// Serializes calls into METIS (see `metis_bisect`).
static METIS_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Weighted, undirected cluster graph in CSR form.
pub struct ClusterGraph {
    xadj: Vec<i32>,
    adjncy: Vec<i32>,
    weights: Vec<i32>,
    /// Morton code of each cluster's centre: the fallback order for splitting.
    morton: Vec<u32>,
}

/// Builds the cluster graph. `clusters[i]` is cluster i's triangle list (vertex ids),
/// `position_ids` maps vertex → position, `centers` is each cluster's centre.
pub fn cluster_graph(clusters: &[&[u32]], position_ids: &[u32], centers: &[[f32; 3]]) -> ClusterGraph {
    let n = clusters.len();
    // (edge key, cluster) for each cluster's boundary edges (those it does not use exactly
    // twice itself); runs of one key give the clusters sharing it. Interior edges are dropped
    // per cluster first, so the global sort sees about a quarter of all edges.
    let mut edges: Vec<(u64, u32)> = clusters
        .par_iter()
        .enumerate()
        .flat_map_iter(|(c, tris)| {
            let keys = mres_geom::edges::sorted_edge_keys(tris, |v| position_ids[v as usize]);
            let boundary: Vec<(u64, u32)> =
                keys.chunk_by(|a, b| a == b).filter(|r| r.len() != 2).map(|r| (r[0], c as u32)).collect();
            boundary
        })
        .collect();
    edges.par_sort_unstable();
    let mut pairs: Vec<(u32, u32)> = Vec::new();
    let mut run = Vec::new();
    for chunk in edges.chunk_by(|a, b| a.0 == b.0) {
        run.clear();
        run.extend(chunk.iter().map(|e| e.1));
        run.dedup();
        for i in 0..run.len() {
            for j in i + 1..run.len() {
                pairs.push((run[i], run[j]));
                pairs.push((run[j], run[i]));
            }
        }
    }
    drop(edges);

    let morton = morton_codes(centers);
    let components = components(n, &pairs);
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.sort_by_key(|&i| (morton[i as usize], i));
    let mut links: Vec<(u32, u32)> = Vec::new();
    for (i, &a) in order.iter().enumerate() {
        for &b in order.iter().skip(i + 1).take(LOCALITY_WINDOW) {
            if components[a as usize] != components[b as usize] {
                links.push((a, b));
                links.push((b, a));
            }
        }
    }

    let mut weighted: Vec<(u32, u32, i32)> = pairs.into_iter().map(|(a, b)| (a, b, EDGE_WEIGHT)).collect();
    weighted.extend(links.into_iter().map(|(a, b)| (a, b, LOCALITY_WEIGHT)));
    weighted.par_sort_unstable();
    let mut xadj = vec![0i32; n + 1];
    let mut adjncy = Vec::new();
    let mut weights = Vec::new();
    for chunk in weighted.chunk_by(|x, y| x.0 == y.0 && x.1 == y.1) {
        let (a, b, _) = chunk[0];
        adjncy.push(b as i32);
        weights.push(chunk.iter().map(|e| e.2).sum::<i32>());
        xadj[a as usize + 1] += 1;
    }
    for i in 0..n {
        xadj[i + 1] += xadj[i];
    }
    ClusterGraph { xadj, adjncy, weights, morton }
}

fn components(n: usize, pairs: &[(u32, u32)]) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for &(a, b) in pairs {
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        if ra != rb {
            parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
    (0..n as u32).map(|i| find(&mut parent, i)).collect()
}

/// The triangles of `mesh` (indices into its triangle list) in Morton order of their
/// centroids, equal codes in index order: the order of the level-0 clusters and of the whole
/// surface the errors are measured against.
pub fn triangle_order(mesh: &WeldedMesh) -> Vec<u32> {
    let centroids: Vec<[f32; 3]> = mesh
        .indices
        .par_chunks_exact(3)
        .map(|t| {
            let p = t.iter().map(|&v| mesh.positions[v as usize]);
            p.fold([0.0; 3], |a, b| [a[0] + b[0] / 3.0, a[1] + b[1] / 3.0, a[2] + b[2] / 3.0])
        })
        .collect();
    let codes = morton_codes(&centroids);
    drop(centroids);
    let mut order: Vec<(u32, u32)> = codes.into_iter().enumerate().map(|(t, code)| (code, t as u32)).collect();
    order.par_sort_unstable();
    order.into_iter().map(|(_, t)| t).collect()
}

/// `mesh` with its vertices and position ids numbered by first use in its [`triangle_order`]
/// (see [`WeldedMesh::numbered_by`]), and that order: how a whole mesh or a shard enters
/// level 0.
pub fn numbered_in_triangle_order(mesh: WeldedMesh) -> (WeldedMesh, Vec<u32>) {
    let order = triangle_order(&mesh);
    (mesh.numbered_by(&order), order)
}

/// 30-bit Morton codes of points, quantized over their bounding box.
pub fn morton_codes(points: &[[f32; 3]]) -> Vec<u32> {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let extent = (0..3).map(|k| hi[k] - lo[k]).fold(f32::MIN_POSITIVE, f32::max);
    let spread = |v: u32| {
        let mut x = v & 0x3ff;
        x = (x | x << 16) & 0x030000ff;
        x = (x | x << 8) & 0x0300f00f;
        x = (x | x << 4) & 0x030c30c3;
        (x | x << 2) & 0x09249249
    };
    points
        .iter()
        .map(|p| {
            let q = |k: usize| (((p[k] - lo[k]) / extent) * 1023.0).clamp(0.0, 1023.0) as u32;
            spread(q(0)) | spread(q(1)) << 1 | spread(q(2)) << 2
        })
        .collect()
}

/// Partitions all clusters of `graph` into groups of about `target` clusters (each within
/// `[target/2, 3*target/2]` where METIS can manage it). Deterministic.
pub fn partition(graph: &ClusterGraph, target: usize) -> Vec<Vec<u32>> {
    let n = graph.xadj.len() - 1;
    let mut groups = Vec::new();
    let mut local = vec![u32::MAX; n];
    bisect(graph, (0..n as u32).collect(), target.max(1), &mut local, &mut groups);
    groups
}

/// Whether [`partition`] makes one group of `n` clusters for a `target` group size.
pub fn one_group(n: usize, target: usize) -> bool {
    let target = target.max(1);
    n <= target + target / 2
}

fn bisect(graph: &ClusterGraph, nodes: Vec<u32>, target: usize, local: &mut [u32], out: &mut Vec<Vec<u32>>) {
    let n = nodes.len();
    if one_group(n, target) {
        out.push(nodes);
        return;
    }
    let k = ((n + target / 2) / target).max(2);
    let left_share = (k / 2) as f32 / k as f32;
    let (left, right) =
        metis_bisect(graph, &nodes, left_share, local).unwrap_or_else(|| ordered_split(graph, &nodes, left_share));
    bisect(graph, left, target, local, out);
    bisect(graph, right, target, local, out);
}

/// Splits `nodes` in Morton order at `share` — the fallback when METIS cannot.
fn ordered_split(graph: &ClusterGraph, nodes: &[u32], share: f32) -> (Vec<u32>, Vec<u32>) {
    let mut sorted = nodes.to_vec();
    sorted.sort_by_key(|&i| (graph.morton[i as usize], i));
    let at = ((nodes.len() as f32 * share).round() as usize).clamp(1, nodes.len() - 1);
    let right = sorted.split_off(at);
    (sorted, right)
}

fn metis_bisect(graph: &ClusterGraph, nodes: &[u32], share: f32, local: &mut [u32]) -> Option<(Vec<u32>, Vec<u32>)> {
    for (i, &g) in nodes.iter().enumerate() {
        local[g as usize] = i as u32;
    }
    let mut xadj = Vec::with_capacity(nodes.len() + 1);
    let mut adjncy = Vec::new();
    let mut weights = Vec::new();
    xadj.push(0);
    for &g in nodes {
        let (s, e) = (graph.xadj[g as usize] as usize, graph.xadj[g as usize + 1] as usize);
        for j in s..e {
            let l = local[graph.adjncy[j] as usize];
            if l != u32::MAX {
                adjncy.push(l as i32);
                weights.push(graph.weights[j]);
            }
        }
        xadj.push(adjncy.len() as i32);
    }
    for &g in nodes {
        local[g as usize] = u32::MAX;
    }
    if adjncy.is_empty() {
        return None;
    }
    let tpwgts = [share, 1.0 - share];
    let mut part = vec![0i32; nodes.len()];
    // METIS keeps its random state in a process-wide global that each call re-seeds: calls
    // from two threads (two assets baking at once) would interleave and make the partition
    // depend on timing. Serialize them; partitioning is a small part of a bake.
    let _guard = METIS_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let result = metis::Graph::new(1, 2, &xadj, &adjncy)
        .ok()?
        .set_adjwgt(&weights)
        .set_tpwgts(&tpwgts)
        .set_option(metis::option::Seed(42))
        .part_recursive(&mut part);
    result.ok()?;
    let (mut left, mut right) = (Vec::new(), Vec::new());
    for (i, &g) in nodes.iter().enumerate() {
        if part[i] == 0 {
            left.push(g)
        } else {
            right.push(g)
        }
    }
    if left.is_empty() || right.is_empty() {
        return None;
    }
    Some((left, right))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strip of `n` clusters, each sharing 4 edges with the next.
    fn strip(n: usize) -> (Vec<Vec<u32>>, Vec<u32>, Vec<[f32; 3]>) {
        let mut clusters = Vec::new();
        for c in 0..n as u32 {
            // Two quads per cluster between columns c and c+1 of a 2-row vertex grid.
            let v = |x: u32, y: u32| x * 3 + y;
            let mut t = Vec::new();
            for y in 0..2 {
                t.extend_from_slice(&[v(c, y), v(c + 1, y), v(c + 1, y + 1), v(c, y), v(c + 1, y + 1), v(c, y + 1)]);
            }
            clusters.push(t);
        }
        let ids = (0..(n as u32 + 1) * 3).collect();
        let centers = (0..n).map(|c| [c as f32, 0.0, 0.0]).collect();
        (clusters, ids, centers)
    }

    #[test]
    fn groups_are_contiguous_and_in_range() {
        let (clusters, ids, centers) = strip(200);
        let refs: Vec<&[u32]> = clusters.iter().map(|c| c.as_slice()).collect();
        let graph = cluster_graph(&refs, &ids, &centers);
        let groups = partition(&graph, 16);
        let mut seen: Vec<u32> = groups.iter().flatten().copied().collect();
        seen.sort();
        assert_eq!(seen, (0..200).collect::<Vec<_>>());
        for g in &groups {
            assert!((8..=24).contains(&g.len()), "group of {}", g.len());
            let (lo, hi) = (g.iter().min().unwrap(), g.iter().max().unwrap());
            assert_eq!((hi - lo + 1) as usize, g.len(), "group not contiguous on a strip: {g:?}");
        }
    }

    #[test]
    fn disconnected_clusters_get_locality_links() {
        // 50 separate single-triangle clusters on a line.
        let clusters: Vec<Vec<u32>> = (0..50u32).map(|c| vec![c * 3, c * 3 + 1, c * 3 + 2]).collect();
        let refs: Vec<&[u32]> = clusters.iter().map(|c| c.as_slice()).collect();
        let ids: Vec<u32> = (0..150).collect();
        let centers: Vec<[f32; 3]> = (0..50).map(|c| [c as f32, 0.0, 0.0]).collect();
        let graph = cluster_graph(&refs, &ids, &centers);
        assert!(graph.adjncy.len() >= 50, "locality links missing");
        let groups = partition(&graph, 8);
        assert!(groups.iter().all(|g| (4..=12).contains(&g.len())));
    }
}
