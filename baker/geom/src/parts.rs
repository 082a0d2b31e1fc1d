//! Connected parts of a triangle set: disjoint sets (union-find) and each part's size. A part
//! that simplification removes is off by its own size, not by its distance to the next surface:
//! the prune simplifier, the baker's deviation bound and the validator all measure it so.

/// Disjoint sets over `0..n`, each named by its smallest element (path halving).
pub struct UnionFind {
    parent: Vec<u32>,
}

impl UnionFind {
    /// `n` singletons.
    pub fn new(n: usize) -> UnionFind {
        UnionFind { parent: (0..n as u32).collect() }
    }

    /// Adds a singleton and returns it.
    pub fn push(&mut self) -> u32 {
        self.parent.push(self.parent.len() as u32);
        self.parent.len() as u32 - 1
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.parent.len()
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.parent.is_empty()
    }

    /// The name (smallest element) of `x`'s set.
    pub fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            self.parent[x as usize] = self.parent[self.parent[x as usize] as usize];
            x = self.parent[x as usize];
        }
        x
    }

    /// Merges the sets of `a` and `b`.
    pub fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
}

/// Bounding-box diagonal of each set, indexed by element (only set names' entries are
/// meaningful; others are 0); `points` gives (element, point) pairs.
pub fn diagonals(sets: &mut UnionFind, points: impl Iterator<Item = (u32, [f64; 3])>) -> Vec<f64> {
    let mut lo = vec![[f64::INFINITY; 3]; sets.len()];
    let mut hi = vec![[f64::NEG_INFINITY; 3]; sets.len()];
    for (x, p) in points {
        let r = sets.find(x) as usize;
        for k in 0..3 {
            lo[r][k] = lo[r][k].min(p[k]);
            hi[r][k] = hi[r][k].max(p[k]);
        }
    }
    lo.iter().zip(&hi).map(|(l, h)| (0..3).map(|k| (h[k] - l[k]).max(0.0).powi(2)).sum::<f64>().sqrt()).collect()
}

/// Area of the triangle with corners `p`.
pub fn triangle_area(p: [[f64; 3]; 3]) -> f64 {
    let (u, w) = ([0, 1, 2].map(|k| p[1][k] - p[0][k]), [0, 1, 2].map(|k| p[2][k] - p[0][k]));
    let c = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]];
    0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_and_their_diagonals() {
        let mut sets = UnionFind::new(4);
        sets.union(3, 1);
        let points = [(0, [0.0, 0.0, 0.0]), (1, [0.0, 0.0, 0.0]), (3, [3.0, 4.0, 0.0]), (2, [9.0, 9.0, 9.0])];
        let d = diagonals(&mut sets, points.into_iter());
        assert_eq!((sets.find(3), sets.find(0), sets.find(2)), (1, 0, 2));
        assert_eq!((d[1], d[0], d[2]), (5.0, 0.0, 0.0));
    }
}
