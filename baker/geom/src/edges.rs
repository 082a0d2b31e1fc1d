//! Edges by position: the key that adjacency, locking and every crack check share.

use rayon::prelude::*;

/// Key of the edge between two positions, independent of direction.
pub fn edge_key(a: u32, b: u32) -> u64 {
    (a.min(b) as u64) << 32 | a.max(b) as u64
}

/// The two positions of edge key `e` ([`edge_key`]), the smaller first.
pub fn edge_ends(e: u64) -> [u32; 2] {
    [(e >> 32) as u32, e as u32]
}

/// Triangle `t` rotated to start at its least vertex, winding kept: equal for the rotations of
/// one triangle, different for the opposite winding (a key for exact copies of a triangle).
pub fn rotated_to_least(t: [u32; 3]) -> [u32; 3] {
    let least = if t[0] <= t[1] && t[0] <= t[2] {
        0
    } else if t[1] <= t[2] {
        1
    } else {
        2
    };
    [t[least], t[(least + 1) % 3], t[(least + 2) % 3]]
}

/// The edge keys of a triangle list (three per triangle, edge k from corner k), in triangle
/// order; `position` maps an index to its position id.
pub fn edge_keys<T: Copy>(triangles: &[T], position: impl Fn(T) -> u32) -> Vec<u64> {
    let mut keys = Vec::with_capacity(triangles.len());
    for t in triangles.chunks_exact(3) {
        let p = [position(t[0]), position(t[1]), position(t[2])];
        keys.extend_from_slice(&[edge_key(p[0], p[1]), edge_key(p[1], p[2]), edge_key(p[2], p[0])]);
    }
    keys
}

/// The edge keys of a triangle list (three per triangle), sorted so that equal edges are
/// adjacent; `position` maps an index to its position id.
pub fn sorted_edge_keys<T: Copy>(triangles: &[T], position: impl Fn(T) -> u32) -> Vec<u64> {
    let mut keys = edge_keys(triangles, position);
    // A whole mesh's edges sort on every thread; a group's, on one (groups run side by side).
    if keys.len() > PARALLEL_SORT {
        keys.par_sort_unstable();
    } else {
        keys.sort_unstable();
    }
    keys
}

/// Edge lists longer than this are sorted in parallel by [`sorted_edge_keys`].
const PARALLEL_SORT: usize = 64 * 1024;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_ignore_direction_and_sort() {
        assert_eq!(edge_key(3, 7), edge_key(7, 3));
        let keys = sorted_edge_keys(&[0u32, 1, 2, 2, 1, 3], |v| v);
        assert_eq!(keys.len(), 6);
        assert_eq!(keys.iter().filter(|&&k| k == edge_key(1, 2)).count(), 2);
        assert!(keys.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(edge_keys(&[0u32, 1, 2], |v| v + 1), vec![edge_key(1, 2), edge_key(2, 3), edge_key(3, 1)]);
    }
}
