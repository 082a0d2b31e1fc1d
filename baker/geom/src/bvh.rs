//! Nearest-point queries on a triangle set: a bounding-volume hierarchy and the exact
//! point-triangle distance. Used by the validator's honesty measure (`honesty`) and by the
//! baker's per-group deviation (`deviation`), so that both measure distance the same way.

use rayon::prelude::*;

/// The coordinate type of a [`Bvh`]: `f64` for the validator, `f32` for the baker's per-group
/// measure (half the memory, and its error is far below the position grid's step).
pub trait Real:
    Copy
    + Send
    + Sync
    + PartialOrd
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// +∞.
    const INFINITY: Self;
    /// −∞.
    const NEG_INFINITY: Self;
    /// The larger of the two.
    fn max(self, other: Self) -> Self;
    /// The smaller of the two.
    fn min(self, other: Self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
}

macro_rules! real {
    ($t:ty) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const INFINITY: Self = <$t>::INFINITY;
            const NEG_INFINITY: Self = <$t>::NEG_INFINITY;
            fn max(self, other: Self) -> Self {
                <$t>::max(self, other)
            }
            fn min(self, other: Self) -> Self {
                <$t>::min(self, other)
            }
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
        }
    };
}
real!(f32);
real!(f64);

/// A triangle: three corners.
pub type Triangle<T> = [[T; 3]; 3];

/// Bounding-volume hierarchy over triangles for nearest-point queries (median split on the
/// longest axis, leaves of up to 4 triangles).
pub struct Bvh<T = f64> {
    nodes: Vec<Node<T>>,
    order: Vec<u32>,
    /// Per triangle, the leaf that holds it (for queries that start from a hint).
    leaf_of: Vec<u32>,
    /// Per node, its parent (the root's is 0). Children come in pairs at an odd index and the
    /// next one, so a node's sibling is found from its index alone.
    parent: Vec<u32>,
}

#[derive(Clone, Copy)]
struct Node<T> {
    lo: [T; 3],
    hi: [T; 3],
    /// Leaf: first triangle in `order` and count; inner: children at `start` and `start + 1`.
    start: u32,
    count: u32,
}

impl<T: Real> Bvh<T> {
    /// Builds the hierarchy over `tris` (which later queries must pass again). Subtrees of
    /// more than `PARALLEL_BUILD` (16 K) triangles build side by side; each subtree's nodes have a
    /// fixed place (its size alone decides how many it has), so the result is the same for any
    /// thread count.
    pub fn new(tris: &[Triangle<T>]) -> Bvh<T> {
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        // Each triangle's box and centroid sum, once: every level of the build reads them.
        let boxes: Vec<([T; 3], [T; 3])> = tris.par_iter().with_min_len(4096).map(triangle_box).collect();
        let centroids: Vec<[T; 3]> =
            tris.par_iter().with_min_len(4096).map(|v| [0, 1, 2].map(|k| v[0][k] + v[1][k] + v[2][k])).collect();
        let counts = NodeCounts::new(tris.len());
        let empty = Node { lo: [T::ZERO; 3], hi: [T::ZERO; 3], start: 0, count: 0 };
        let total = counts.of(tris.len()) as usize;
        let (mut nodes, mut parent) = (vec![empty; total], vec![0u32; total]);
        let (root, rest) = nodes.split_at_mut(1);
        let build = Build { boxes: &boxes, centroids: &centroids, counts: &counts };
        build.subtree(0, (&mut order, 0), &mut root[0], (rest, &mut parent[1..], 1));
        let mut leaf_of = vec![0u32; tris.len()];
        for (index, n) in nodes.iter().enumerate().filter(|(_, n)| n.count > 0) {
            for &t in &order[n.start as usize..(n.start + n.count) as usize] {
                leaf_of[t as usize] = index as u32;
            }
        }
        Bvh { nodes, order, leaf_of, parent }
    }

    /// Distance from `p` to the nearest of `tris` (infinite when there are none).
    pub fn distance(&self, tris: &[Triangle<T>], p: [T; 3]) -> T {
        self.nearest(tris, p).0
    }

    /// Distance to the nearest triangle and its index.
    pub fn nearest(&self, tris: &[Triangle<T>], p: [T; 3]) -> (T, usize) {
        self.nearest_beyond(tris, p, T::ZERO)
    }

    /// Like [`Bvh::nearest`] where the distance exceeds `enough`; otherwise some triangle
    /// within `enough` of `p` (the search stops at the first one found). For a maximum over
    /// many points of their distance, where only distances above the current maximum matter.
    pub fn nearest_beyond(&self, tris: &[Triangle<T>], p: [T; 3], enough: T) -> (T, usize) {
        let (d2, t) = self.nearest_squared(tris, p, enough * enough, usize::MAX);
        (d2.sqrt(), t)
    }

    /// Squared distance form of [`Bvh::nearest_beyond`] that first tries the leaf holding
    /// triangle `hint` (neighbouring query points are near the same triangles); `usize::MAX`
    /// for no hint. Past the hint's leaf it descends from the root, nearer child first, so
    /// that the triangle it stops at is near `p` among those within `enough2`: the baker hands
    /// a sample to the cluster of that triangle, and a nearer one keeps the next level's
    /// errors tight.
    pub fn nearest_squared(&self, tris: &[Triangle<T>], p: [T; 3], enough2: T, hint: usize) -> (T, usize) {
        let mut best = (T::INFINITY, 0usize);
        let Some(leaf) = self.try_hint(tris, p, enough2, hint, &mut best) else { return best };
        self.search(tris, 0, leaf, p, enough2, &mut stack(), &mut best);
        best
    }

    /// Like [`Bvh::nearest_squared`], but past the hint's leaf it climbs towards the root,
    /// searching each ancestor's other child: the triangles next to the hint come first, so a
    /// query that stops at any triangle within `enough2` visits a few nodes near its hint
    /// instead of descending from the root. For callers that need only the distance where it
    /// exceeds `enough2` (then the result is the nearest triangle, as for `nearest_squared`:
    /// the siblings along the path cover every other leaf once), not which triangle within it.
    pub fn within_squared(&self, tris: &[Triangle<T>], p: [T; 3], enough2: T, hint: usize) -> (T, usize) {
        let mut best = (T::INFINITY, 0usize);
        let Some(leaf) = self.try_hint(tris, p, enough2, hint, &mut best) else { return best };
        if leaf == NO_NODE {
            self.search(tris, 0, NO_NODE, p, enough2, &mut stack(), &mut best);
            return best;
        }
        let (mut node, mut stack) = (leaf, stack());
        while node != 0 {
            let sibling = if node % 2 == 1 { node + 1 } else { node - 1 };
            if self.search(tris, sibling, NO_NODE, p, enough2, &mut stack, &mut best) {
                break;
            }
            node = self.parent[node as usize];
        }
        best
    }

    /// Tests triangle `hint` and the rest of its leaf against `best`. `None` when the query is
    /// done (nothing to search, or a triangle within `enough2` found); else the hint's leaf,
    /// which the search skips, or [`NO_NODE`] without a hint.
    fn try_hint(&self, tris: &[Triangle<T>], p: [T; 3], enough2: T, hint: usize, best: &mut (T, usize)) -> Option<u32> {
        if self.order.is_empty() {
            return None;
        }
        let Some(&leaf) = self.leaf_of.get(hint) else { return Some(NO_NODE) };
        let d = point_triangle_distance2(p, &tris[hint]);
        *best = (d, hint);
        // The hint itself cannot improve on `best` again: pass it as done.
        if d <= enough2 || self.leaf(tris, leaf, p, enough2, hint, best) {
            return None;
        }
        Some(leaf)
    }

    /// Searches the subtree at `root` but node `skip` for triangles nearer than `best`, nearer
    /// child first; true once one is within `enough2`. A node at least as far as `best` cannot
    /// hold a nearer triangle (`best` only shrinks), so it is not pushed.
    #[allow(clippy::too_many_arguments)]
    fn search(
        &self,
        tris: &[Triangle<T>],
        root: u32,
        skip: u32,
        p: [T; 3],
        enough2: T,
        stack: &mut [(u32, T); 64],
        best: &mut (T, usize),
    ) -> bool {
        stack[0] = (root, box_distance2(&self.nodes[root as usize], p));
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let (index, distance) = stack[top];
            if index == skip || distance >= best.0 {
                continue;
            }
            let n = &self.nodes[index as usize];
            if n.count > 0 {
                if self.leaf(tris, index, p, enough2, usize::MAX, best) {
                    return true;
                }
            } else if top + 2 <= stack.len() {
                let (a, b) = (n.start, n.start + 1);
                let pair = &self.nodes[a as usize..a as usize + 2]; // one bounds check for both
                let (da, db) = (box_distance2(&pair[0], p), box_distance2(&pair[1], p));
                let (near, far) = if da <= db { ((a, da), (b, db)) } else { ((b, db), (a, da)) };
                // Far first, so that near is visited first.
                for (child, d) in [far, near] {
                    if d < best.0 {
                        stack[top] = (child, d);
                        top += 1;
                    }
                }
            }
        }
        false
    }

    /// Tests the triangles of leaf `index` but `done` against `best` (squared distance,
    /// triangle); true once one is within `enough2`.
    #[inline]
    fn leaf(
        &self,
        tris: &[Triangle<T>],
        index: u32,
        p: [T; 3],
        enough2: T,
        done: usize,
        best: &mut (T, usize),
    ) -> bool {
        let n = &self.nodes[index as usize];
        for &t in &self.order[n.start as usize..(n.start + n.count) as usize] {
            if t as usize == done {
                continue;
            }
            let d = point_triangle_distance2(p, &tris[t as usize]);
            if d < best.0 {
                *best = (d, t as usize);
                if d <= enough2 {
                    return true;
                }
            }
        }
        false
    }
}

/// Subtrees of more triangles than this build their two halves side by side ([`Bvh::new`]).
const PARALLEL_BUILD: usize = 16 * 1024;

/// Most triangles of a leaf.
const LEAF: usize = 4;

/// How many nodes the subtree over `n` triangles has, for each size a subtree of the
/// hierarchy over `n` can have (the median split gives at most two sizes per depth).
struct NodeCounts(Vec<(usize, u32)>);

impl NodeCounts {
    fn new(n: usize) -> NodeCounts {
        fn count(s: usize, memo: &mut Vec<(usize, u32)>) -> u32 {
            if let Some(&(_, c)) = memo.iter().find(|m| m.0 == s) {
                return c;
            }
            let c = if s <= LEAF { 1 } else { 1 + count(s / 2, memo) + count(s - s / 2, memo) };
            memo.push((s, c));
            c
        }
        let mut memo = Vec::new();
        count(n, &mut memo);
        NodeCounts(memo)
    }

    /// The node count of a subtree over `s` triangles.
    fn of(&self, s: usize) -> u32 {
        self.0.iter().find(|m| m.0 == s).map_or(1, |m| m.1)
    }
}

/// What every subtree of one [`Bvh::new`] reads.
struct Build<'a, T> {
    boxes: &'a [([T; 3], [T; 3])],
    centroids: &'a [[T; 3]],
    counts: &'a NodeCounts,
}

impl<T: Real> Build<'_, T> {
    /// Builds the subtree at node `index` over `order` (its triangles, from `first` in the
    /// whole order) into `node` and, below it, its descendants into `below` (their nodes and
    /// parents, numbered from `next`): its two children first (a pair at an odd index), then
    /// the left child's descendants, then the right child's.
    fn subtree(
        &self,
        index: u32,
        (order, first): (&mut [u32], usize),
        node: &mut Node<T>,
        (below, parents, next): (&mut [Node<T>], &mut [u32], u32),
    ) {
        let (mut lo, mut hi) = ([T::INFINITY; 3], [T::NEG_INFINITY; 3]);
        for &t in order.iter() {
            let (tlo, thi) = &self.boxes[t as usize];
            // Comparisons rather than `min`/`max` (NaN rules cost instructions); on finite
            // values the bounds are the same, up to the sign of a zero, which no distance
            // or extent computed from them sees.
            for k in 0..3 {
                if tlo[k] < lo[k] {
                    lo[k] = tlo[k];
                }
                if thi[k] > hi[k] {
                    hi[k] = thi[k];
                }
            }
        }
        (node.lo, node.hi) = (lo, hi);
        if order.len() <= LEAF {
            (node.start, node.count) = (first as u32, order.len() as u32);
            return;
        }
        let extent = |a: usize| hi[a] - lo[a];
        let axis = if extent(0) >= extent(1) && extent(0) >= extent(2) {
            0
        } else if extent(1) >= extent(2) {
            1
        } else {
            2
        };
        let centroid = |t: u32| self.centroids[t as usize][axis];
        let (mid, parallel) = (order.len() / 2, order.len() > PARALLEL_BUILD);
        order.select_nth_unstable_by(mid, |&a, &b| {
            centroid(a).partial_cmp(&centroid(b)).unwrap_or(std::cmp::Ordering::Equal)
        });
        (node.start, node.count) = (next, 0);
        let (pair, rest) = below.split_at_mut(2);
        let (pair_parents, rest_parents) = parents.split_at_mut(2);
        pair_parents.fill(index);
        let left_below = self.counts.of(mid) as usize - 1;
        let (left_rest, right_rest) = rest.split_at_mut(left_below);
        let (left_parents, right_parents) = rest_parents.split_at_mut(left_below);
        let (left_order, right_order) = order.split_at_mut(mid);
        let (left, right) = pair.split_at_mut(1);
        let after = next + 2;
        let mut build_left = || self.subtree(next, (left_order, first), &mut left[0], (left_rest, left_parents, after));
        let right_next = after + left_below as u32;
        let mut build_right = || {
            self.subtree(next + 1, (right_order, first + mid), &mut right[0], (right_rest, right_parents, right_next))
        };
        if parallel {
            rayon::join(build_left, build_right);
        } else {
            build_left();
            build_right();
        }
    }
}

/// No node: a query without a hint skips none.
const NO_NODE: u32 = u32::MAX;

/// A query's stack of nodes to visit, each with its box distance, computed once when pushed.
/// The median split halves every node, so the depth is below 32 for any u32 triangle count,
/// and a subtree's search holds at most one entry per level plus one: 64 cover every tree.
/// (Set up only by queries that get past their hint.)
fn stack<T: Real>() -> [(u32, T); 64] {
    [(0u32, T::ZERO); 64]
}

/// The bounding box of triangle `t`.
fn triangle_box<T: Real>(t: &Triangle<T>) -> ([T; 3], [T; 3]) {
    let lo = [0, 1, 2].map(|k| t[0][k].min(t[1][k]).min(t[2][k]));
    let hi = [0, 1, 2].map(|k| t[0][k].max(t[1][k]).max(t[2][k]));
    (lo, hi)
}

/// Squared distance from `p` to the box of `n`.
fn box_distance2<T: Real>(n: &Node<T>, p: [T; 3]) -> T {
    // A plain comparison, not `max`: this runs on every visited node, and `max`'s NaN rules
    // cost instructions. On the finite values here it gives the same result (up to the
    // sign of a zero, which squaring removes).
    let larger = |a: T, b: T| if a > b { a } else { b };
    let axis = |k: usize| larger(larger(n.lo[k] - p[k], p[k] - n.hi[k]), T::ZERO);
    let (x, y, z) = (axis(0), axis(1), axis(2));
    x * x + y * y + z * z
}

/// Distance from `p` to triangle `t` (closest point by region, Ericson's "Real-Time Collision
/// Detection" §5.1.5).
pub fn point_triangle_distance<T: Real>(p: [T; 3], t: &Triangle<T>) -> T {
    point_triangle_distance2(p, t).sqrt()
}

/// Squared [`point_triangle_distance`].
#[inline]
pub fn point_triangle_distance2<T: Real>(p: [T; 3], t: &Triangle<T>) -> T {
    closest_feature2(p, t).0
}

/// Where on a triangle the closest point to a point lies: inside the face, on edge k (from
/// corner k to corner k + 1), or at corner k.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feature {
    /// Inside the face.
    Face,
    /// On the edge from corner k to corner k + 1 (mod 3).
    Edge(usize),
    /// At a corner: its two edges, the one the point leans towards more first.
    Corner([usize; 2]),
}

/// [`point_triangle_distance2`] and the feature of `t` that holds the closest point, by
/// Ericson's regions ("Real-Time Collision Detection" §5.1.5): one pass for walks, which need
/// both (see [`crate::walk`]); where only the distance is used the feature's comparisons are
/// dead code and vanish.
#[inline(always)]
pub fn closest_feature2<T: Real>(p: [T; 3], t: &Triangle<T>) -> (T, Feature) {
    let sub = |a: [T; 3], b: [T; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [T; 3], b: [T; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let zero = T::ZERO;
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    let at = |u: T, v: T| -> T {
        let q = [a[0] + ab[0] * u + ac[0] * v, a[1] + ab[1] * u + ac[1] * v, a[2] + ab[2] * u + ac[2] * v];
        dot(sub(p, q), sub(p, q))
    };
    // Corner A: towards B (edge 0) or towards C (edge 2), whichever p leans to.
    if d1 <= zero && d2 <= zero {
        return (dot(ap, ap), Feature::Corner(if d1 >= d2 { [0, 2] } else { [2, 0] }));
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    // Corner B: towards A (edge 0, along −ab) or towards C (edge 1, along ac − ab).
    if d3 >= zero && d4 <= d3 {
        return (dot(bp, bp), Feature::Corner(if zero - d3 >= d4 - d3 { [0, 1] } else { [1, 0] }));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= zero && d1 >= zero && d3 <= zero {
        return (at(d1 / (d1 - d3), zero), Feature::Edge(0));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    // Corner C: towards A (edge 2, along −ac) or towards B (edge 1, along ab − ac).
    if d6 >= zero && d5 <= d6 {
        return (dot(cp, cp), Feature::Corner(if zero - d6 >= d5 - d6 { [2, 1] } else { [1, 2] }));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= zero && d2 >= zero && d6 <= zero {
        return (at(zero, d2 / (d2 - d6)), Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= zero && (d4 - d3) >= zero && (d5 - d6) >= zero {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (at(T::ONE - w, w), Feature::Edge(1));
    }
    let denom = T::ONE / (va + vb + vc);
    (at(vb * denom, vc * denom), Feature::Face)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_triangle_distances() {
        let t: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!((point_triangle_distance([0.2, 0.2, 0.5], &t) - 0.5).abs() < 1e-12);
        assert!((point_triangle_distance([-1.0, 0.0, 0.0], &t) - 1.0).abs() < 1e-12);
        assert!((point_triangle_distance([1.0, 1.0, 0.0], &t) - 0.5f64.sqrt()).abs() < 1e-12);
        let tris: Vec<[[f64; 3]; 3]> = (0..100)
            .map(|i| {
                let x = i as f64;
                [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]
            })
            .collect();
        let bvh = Bvh::new(&tris);
        let (d, t) = bvh.nearest(&tris, [50.2, 0.2, 3.0]);
        assert!((d - 3.0).abs() < 1e-12 && t == 50, "{d} {t}");
        // A hint far from the point still finds the nearest triangle.
        let (d2, t) = bvh.nearest_squared(&tris, [50.2, 0.2, 3.0], 0.0, 3);
        assert!((d2 - 9.0f64).abs() < 1e-9 && t == 50, "{d2} {t}");
        let small: Vec<[[f32; 3]; 3]> = tris.iter().map(|t| t.map(|v| v.map(|x| x as f32))).collect();
        let bvh = Bvh::new(&small);
        let (d2, t) = bvh.nearest_squared(&small, [20.2, 0.2, -2.0], 0.0, 90);
        assert!((d2 - 4.0f32).abs() < 1e-5 && t == 20, "{d2} {t}");
    }

    #[test]
    fn the_closest_feature_holds_the_closest_point() {
        // Distance to segment a-b, and to the plane of t where the foot is inside.
        let segment2 = |p: [f64; 3], a: [f64; 3], b: [f64; 3]| {
            let ab = [0, 1, 2].map(|k| b[k] - a[k]);
            let ap = [0, 1, 2].map(|k| p[k] - a[k]);
            let u = ((0..3).map(|k| ab[k] * ap[k]).sum::<f64>() / (0..3).map(|k| ab[k] * ab[k]).sum::<f64>())
                .clamp(0.0, 1.0);
            (0..3).map(|k| (ap[k] - u * ab[k]).powi(2)).sum::<f64>()
        };
        let t: Triangle<f64> = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.5, 1.5, 0.0]];
        let (mut faces, mut edges, mut corners) = (0, 0, 0);
        for i in 0..41 {
            for j in 0..41 {
                let p = [i as f64 * 0.1 - 1.0, j as f64 * 0.1 - 1.0, 0.3];
                let (d2, feature) = closest_feature2(p, &t);
                assert!((d2 - point_triangle_distance2(p, &t)).abs() == 0.0);
                let edge2 = |k: usize| segment2(p, t[k], t[(k + 1) % 3]);
                let nearest_edge = (0..3).map(edge2).fold(f64::INFINITY, f64::min);
                match feature {
                    // Above the face: the plane's distance, nearer than any edge.
                    Feature::Face => {
                        faces += 1;
                        assert!((d2 - 0.09).abs() < 1e-12 && d2 <= nearest_edge + 1e-12, "{p:?}");
                    }
                    Feature::Edge(k) => {
                        edges += 1;
                        assert!((d2 - edge2(k)).abs() < 1e-12 && d2 >= 0.09 - 1e-12, "{p:?} {k}");
                    }
                    // A corner's two edges meet at it; it is the closest point.
                    Feature::Corner([e, f]) => {
                        corners += 1;
                        let corner = if (e + 1) % 3 == f { f } else { e };
                        assert!(e != f && (e + 1) % 3 == f || (f + 1) % 3 == e);
                        let c2 = (0..3).map(|k| (p[k] - t[corner][k]).powi(2)).sum::<f64>();
                        assert!((d2 - c2).abs() < 1e-12, "{p:?} {feature:?}");
                    }
                }
            }
        }
        assert!(faces > 0 && edges > 0 && corners > 0, "{faces} {edges} {corners}");
    }

    /// Pseudo-random triangles in a unit cube (a fixed linear congruential sequence).
    fn scattered(n: usize) -> Vec<Triangle<f32>> {
        let mut state = 12345u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        (0..n)
            .map(|_| {
                let a = [next(), next(), next()];
                [a, a.map(|x| x + 0.05 * next()), a.map(|x| x - 0.05 * next())]
            })
            .collect()
    }

    #[test]
    fn queries_find_the_exact_nearest_or_one_within_enough() {
        let tris = scattered(500);
        let bvh = Bvh::new(&tris);
        for (i, t) in scattered(200).iter().enumerate() {
            let p = t[1].map(|x| x * 1.2 - 0.1);
            let exact = tris.iter().map(|t| point_triangle_distance2(p, t)).fold(f32::INFINITY, f32::min);
            for hint in [usize::MAX, i, 499] {
                for query in [Bvh::nearest_squared, Bvh::within_squared] {
                    let (d2, t) = query(&bvh, &tris, p, 0.0, hint);
                    assert!(d2 == exact && point_triangle_distance2(p, &tris[t]) == d2, "{d2} {exact}");
                    let enough2 = exact * 4.0;
                    let (d2, t) = query(&bvh, &tris, p, enough2, hint);
                    assert!(d2 <= enough2 && point_triangle_distance2(p, &tris[t]) == d2, "{d2} {enough2}");
                }
            }
        }
    }

    #[test]
    fn a_tree_built_on_several_threads_is_whole_and_answers_exactly() {
        // Enough triangles that the top subtrees build side by side.
        let tris = scattered(3 * PARALLEL_BUILD + 7);
        let bvh = Bvh::new(&tris);
        assert_eq!(bvh.nodes.len(), 2 * bvh.nodes.iter().filter(|n| n.count > 0).count() - 1);
        // Every inner node's pair of children sits at an odd index and names it as parent;
        // every triangle is in exactly one leaf, the one `leaf_of` names.
        let mut seen = vec![0u32; tris.len()];
        for (i, n) in bvh.nodes.iter().enumerate() {
            if n.count == 0 {
                assert!(n.start % 2 == 1, "node {i}: children at {}", n.start);
                for c in [n.start, n.start + 1] {
                    assert_eq!(bvh.parent[c as usize], i as u32);
                }
            }
            for &t in &bvh.order[n.start as usize..(n.start + n.count) as usize] {
                seen[t as usize] += 1;
                assert_eq!(bvh.leaf_of[t as usize], i as u32);
            }
        }
        assert!(seen.iter().all(|&k| k == 1));
        for (i, t) in scattered(50).iter().enumerate() {
            let p = t[2].map(|x| x * 1.1 - 0.05);
            let exact = tris.iter().map(|t| point_triangle_distance2(p, t)).fold(f32::INFINITY, f32::min);
            for query in [Bvh::nearest_squared, Bvh::within_squared] {
                assert_eq!(query(&bvh, &tris, p, 0.0, i * 997).0, exact);
            }
        }
    }
}
