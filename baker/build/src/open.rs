//! Open-border marks (docs/INVARIANTS.md §1): each cluster marks the triangle edges that lie on
//! the surface's open border, so that the original's holes, rims, one-sided walls and cards can
//! be simplified like everything else and a cut still proves crack-free: its unmarked edges pair
//! up, its marked edges occur once.
//!
//! Marks are kept per triangle as three bits (bit k: the edge from corner k to corner
//! (k + 1) mod 3), the form the file stores. A set of triangles "needs" a mark on an edge when
//! that edge is open there: at level 0 an edge with an odd use count, after simplification an
//! edge the group's output uses an odd number of times away from the group border
//! (`simplify::EdgeCounts`).

use crate::weld::WeldedMesh;
use mres_geom::edges::edge_key;

/// The position-id edge keys of triangle `t` of `indices`, edge k from corner k.
pub fn triangle_edges(mesh: &WeldedMesh, indices: &[u32], t: usize) -> [u64; 3] {
    let p = |k: usize| mesh.position_ids[indices[3 * t + k] as usize];
    [edge_key(p(0), p(1)), edge_key(p(1), p(2)), edge_key(p(2), p(0))]
}

/// The keys that occur an odd number of times in sorted `keys`, sorted.
pub fn odd_of(keys: &[u64]) -> Vec<u64> {
    keys.chunk_by(|a, b| a == b).filter(|r| r.len() % 2 == 1).map(|r| r[0]).collect()
}

/// Marks each edge of `needed` (sorted, distinct) once, on its first use in `clusters` (in
/// order, triangles in order, edges in corner order): one mask per triangle per cluster.
pub fn mark(mesh: &WeldedMesh, clusters: &[Vec<u32>], needed: &[u64]) -> Vec<Vec<u8>> {
    let mut done = vec![false; needed.len()];
    clusters
        .iter()
        .map(|indices| {
            (0..indices.len() / 3)
                .map(|t| {
                    let mut mask = 0u8;
                    for (k, e) in triangle_edges(mesh, indices, t).into_iter().enumerate() {
                        if let Ok(i) = needed.binary_search(&e) {
                            if !done[i] {
                                done[i] = true;
                                mask |= 1 << k;
                            }
                        }
                    }
                    mask
                })
                .collect()
        })
        .collect()
}

/// The marked edges of `indices` under `masks` (one per triangle), sorted, with repeats.
pub fn marked_edges(mesh: &WeldedMesh, indices: &[u32], masks: &[u8]) -> Vec<u64> {
    let mut out: Vec<u64> = masks
        .iter()
        .enumerate()
        .flat_map(|(t, &m)| {
            let edges = triangle_edges(mesh, indices, t);
            (0..3).filter(move |k| m >> k & 1 != 0).map(move |k| edges[k])
        })
        .collect();
    out.sort_unstable();
    out
}

/// How often `e` occurs in the sorted `edges` (as [`marked_edges`] returns them).
pub fn count(edges: &[u64], e: u64) -> usize {
    edges.partition_point(|&m| m <= e) - edges.partition_point(|&m| m < e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::BakeSettings;
    use crate::weld::weld;
    use mres_geom::edges::sorted_edge_keys;
    use mres_import::SourceMesh;

    /// Two triangles sharing an edge (a quad): its four rim edges are open, the diagonal not.
    #[test]
    fn a_quad_marks_its_rim_once() {
        let mesh = SourceMesh::positions_only(
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            vec![0, 1, 2, 0, 2, 3],
        );
        let w = weld(&mesh, &BakeSettings::default()).unwrap();
        let needed = odd_of(&sorted_edge_keys(&w.indices, |v| w.position_ids[v as usize]));
        assert_eq!(needed.len(), 4);
        // Split into two one-triangle clusters: each marks its two rim edges, not the diagonal.
        let clusters = vec![w.indices[..3].to_vec(), w.indices[3..].to_vec()];
        let masks = mark(&w, &clusters, &needed);
        let ones: u32 = masks.iter().flatten().map(|m| m.count_ones()).sum();
        assert_eq!(ones, 4);
        let all: Vec<u8> = masks.concat();
        assert_eq!(marked_edges(&w, &w.indices, &all), needed);
        // Needing a mark twice marks it once.
        let twice = mark(&w, &[w.indices.clone(), w.indices.clone()], &needed);
        assert_eq!(twice[1].iter().map(|m| m.count_ones()).sum::<u32>(), 0);
    }
}
