//! Edges by position: the key that adjacency, locking and every crack check share.

/// Key of the edge between two positions, independent of direction.
pub fn edge_key(a: u32, b: u32) -> u64 {
    (a.min(b) as u64) << 32 | a.max(b) as u64
}

/// The edge keys of a triangle list (three per triangle), sorted so that equal edges are
/// adjacent; `position` maps an index to its position id.
pub fn sorted_edge_keys<T: Copy>(triangles: &[T], position: impl Fn(T) -> u32) -> Vec<u64> {
    let mut keys: Vec<u64> = triangles
        .chunks_exact(3)
        .flat_map(|t| (0..3).map(|k| edge_key(position(t[k]), position(t[(k + 1) % 3]))).collect::<Vec<_>>())
        .collect();
    keys.sort_unstable();
    keys
}

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
    }
}
