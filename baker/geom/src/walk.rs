//! Walking a triangle mesh towards a point: from a triangle near it, step to the neighbour
//! across the edge that the point's closest point lies on, until a triangle is close enough.
//!
//! The measured errors query millions of points that lie a fraction of a triangle from the
//! previous query's answer (samples in spatial order). A hierarchy query that misses its hint
//! tests that triangle's leaf and then climbs or descends the tree, about seven triangles on the
//! baker's lower levels; a walk usually reaches a close-enough triangle in one or two steps.
//! It is only a shortcut: a walk that stops (a border, a fold, a local minimum, too many steps)
//! leaves the query to the hierarchy, starting from the closest triangle it saw.
//!
//! No library walks a general triangle soup in 3-D by closest-point regions (triangulation
//! crates walk planar Delaunay meshes), so this is written here.

use crate::bvh::{closest_feature2, point_triangle_distance2, Bvh, Feature, Real, Triangle};
use crate::edges::{edge_ends, edge_key};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// No triangle across this edge: an open border, or an edge with more than two triangles.
const NONE: u32 = u32::MAX;

/// Most steps of a walk before a query is left to the hierarchy, for queries in spatial order
/// (the baker's: each sample lies a few triangles from the previous one's answer at the lower
/// levels, where most queries are). Walks of 24 or 48 steps made no difference to the bake
/// (docs/BENCHMARKS.md).
pub const STEPS: usize = 8;

/// Per triangle, the triangle across each of its edges (edge k from corner k to corner k + 1).
pub struct Neighbours {
    across: Vec<[u32; 3]>,
}

impl Neighbours {
    /// The neighbours of the triangles whose corners are `corners` (three per triangle):
    /// position ids, so that copies of a vertex on an attribute seam join. An edge joins the
    /// two triangles that use it where exactly two edge slots in all have its key; any other
    /// count leaves its slots without a neighbour.
    pub fn new(corners: &[u32]) -> Neighbours {
        let positions = corners.iter().copied().max().map_or(0, |m| m as usize + 1);
        // Dense ids (a whole mesh's): each edge is found among the triangles at one of its
        // ends, without sorting every edge. Sparse ids (a group's, numbered over the whole
        // mesh), or a position with very many triangles: the sort, which needs no table over
        // every id and costs the same whatever the valences.
        let dense = corners.len() >= DENSE_MIN && positions <= corners.len();
        dense
            .then(|| Neighbours::by_position(corners, positions))
            .flatten()
            .unwrap_or_else(|| Neighbours::by_sort(corners))
    }

    /// [`Neighbours::new`] by sorting every edge slot by key and pairing runs of two.
    fn by_sort(corners: &[u32]) -> Neighbours {
        let triangles = corners.len() / 3;
        let mut edges: Vec<(u64, u32)> = (0..triangles * 3).map(|s| (slot_key(corners, s), s as u32)).collect();
        if edges.len() > 64 * 1024 {
            edges.par_sort_unstable();
        } else {
            edges.sort_unstable();
        }
        // Each run of two equal keys (an edge of exactly two triangles) joins its slots, side
        // by side: a slot is in one run only, so each is written once.
        let slots: Vec<AtomicU32> = (0..triangles * 3).map(|_| AtomicU32::new(NONE)).collect();
        let key = |i: usize| edges.get(i).map(|e| e.0);
        (0..edges.len()).into_par_iter().with_min_len(4096).for_each(|i| {
            let pair = (i == 0 || key(i - 1) != key(i)) && key(i + 1) == key(i) && key(i + 2) != key(i);
            if pair {
                let (a, b) = (edges[i].1, edges[i + 1].1);
                slots[a as usize].store(b / 3, Relaxed);
                slots[b as usize].store(a / 3, Relaxed);
            }
        });
        Neighbours::from_slots(slots)
    }

    /// [`Neighbours::new`] for ids below `positions`: each position's triangles listed once
    /// (counted, then placed, side by side), and each edge slot's key counted among the edges
    /// of the triangles listed at its smaller end, position by position (a list and its
    /// triangles are read once for all of a position's edges, not once per edge slot: a
    /// position's ids lie scattered over a large mesh's triangles). The same result as
    /// [`Neighbours::by_sort`]; the order of a position's list, which the threads decide, does
    /// not change it. `None` where a position has more than [`MAX_LISTED`] triangles: each of
    /// its edges would look through all of them (a fan of a million triangles around one apex,
    /// a million times).
    fn by_position(corners: &[u32], positions: usize) -> Option<Neighbours> {
        // A triangle is listed once under each distinct position of its corners.
        let distinct = |t: &[u32], k: usize| (0..k).all(|j| t[j] != t[k]);
        let atomic_zeros = |n: usize| -> Vec<AtomicU32> { (0..n).map(|_| AtomicU32::new(0)).collect() };
        let counts = atomic_zeros(positions);
        corners.par_chunks_exact(3).with_min_len(4096).for_each(|t| {
            for k in (0..3).filter(|&k| distinct(t, k)) {
                counts[t[k] as usize].fetch_add(1, Relaxed);
            }
        });
        let mut start = Vec::with_capacity(positions + 1);
        let mut at = 0u32;
        for c in &counts {
            let c = c.load(Relaxed);
            if c > MAX_LISTED {
                return None;
            }
            start.push(at);
            at += c;
        }
        start.push(at);
        let fill: Vec<AtomicU32> = start[..positions].iter().map(|&s| AtomicU32::new(s)).collect();
        let listed = atomic_zeros(at as usize);
        corners.par_chunks_exact(3).enumerate().with_min_len(4096).for_each(|(i, t)| {
            for k in (0..3).filter(|&k| distinct(t, k)) {
                listed[fill[t[k] as usize].fetch_add(1, Relaxed) as usize].store(i as u32, Relaxed);
            }
        });
        let listed: Vec<u32> = listed.into_iter().map(AtomicU32::into_inner).collect();
        let lists = Lists { start: &start, listed: &listed };
        // Each edge slot is paired at its key's smaller end, so written once; a position's
        // list and its triangles are read once for all of its edges.
        let slots: Vec<AtomicU32> = (0..corners.len()).map(|_| AtomicU32::new(NONE)).collect();
        (0..positions as u32).into_par_iter().with_min_len(1024).for_each(|p| lists.pair(corners, p, &slots));
        Some(Neighbours::from_slots(slots))
    }

    /// The neighbours from their edge slots, three per triangle, each paired side by side.
    fn from_slots(slots: Vec<AtomicU32>) -> Neighbours {
        let across = slots.par_chunks(3).with_min_len(4096).map(|s| [0, 1, 2].map(|k| s[k].load(Relaxed))).collect();
        Neighbours { across }
    }

    /// From triangle `start` (of `tris`, the triangles this was made from), walks towards `p`
    /// for at most `steps` steps and returns the squared distance to the first triangle within
    /// `enough2` of `p`, or to the closest one it tested, and that triangle.
    pub fn walk<T: Real>(&self, tris: &[Triangle<T>], p: [T; 3], enough2: T, start: usize, steps: usize) -> (T, usize) {
        let mut at = start;
        let (d, mut feature) = closest_feature2(p, &tris[at]);
        let mut best = (d, at);
        let mut from = NONE;
        for _ in 0..steps {
            if best.0 <= enough2 {
                break;
            }
            // At a corner, the other edge of the corner where the first leads nowhere new.
            let [first, second] = match feature {
                Feature::Face => break,
                Feature::Edge(k) => [k; 2],
                Feature::Corner(edges) => edges,
            };
            let open = |e: usize| {
                let t = self.across[at][e];
                (t != NONE && t != from).then_some(t)
            };
            let Some(next) = open(first).or_else(|| open(second)) else { break };
            (from, at) = (at as u32, next as usize);
            let d;
            (d, feature) = closest_feature2(p, &tris[at]);
            if d < best.0 {
                best = (d, at);
            }
        }
        best
    }
}

/// Each position's triangles (of [`Neighbours::by_position`]): those of position `p` are
/// `listed[start[p]..start[p + 1]]`.
struct Lists<'a> {
    start: &'a [u32],
    listed: &'a [u32],
}

impl Lists<'_> {
    /// Pairs the edge slots of `corners` whose key's smaller end is position `p`: each gets
    /// the triangle of the one other slot with its key, if there is exactly one (every
    /// triangle with such a slot is at `p`, so in its list), else [`NONE`].
    fn pair(&self, corners: &[u32], p: u32, slots: &[AtomicU32]) {
        let list = &self.listed[self.start[p as usize] as usize..self.start[p as usize + 1] as usize];
        for &t in list {
            let first = 3 * t as usize;
            for (s, slot) in (first..).zip(&slots[first..first + 3]) {
                if edge_ends(slot_key(corners, s))[0] == p {
                    slot.store(only_other(list, corners, s), Relaxed);
                }
            }
        }
    }
}

/// The triangle of the one other slot of `corners` with edge slot `s`'s key among the triangles
/// of `list` (which holds every triangle at one end of that edge), if there is exactly one;
/// else [`NONE`].
fn only_other(list: &[u32], corners: &[u32], s: usize) -> u32 {
    let key = slot_key(corners, s);
    let far = edge_ends(key)[1];
    let (mut count, mut other) = (0, NONE);
    for &u in list {
        let c = &corners[3 * u as usize..3 * u as usize + 3];
        // Only a triangle at the other end too has such a slot.
        if c[0] != far && c[1] != far && c[2] != far {
            continue;
        }
        for j in (3 * u as usize..3 * u as usize + 3).filter(|&j| j != s) {
            if slot_key(corners, j) == key {
                (count, other) = (count + 1, u);
            }
        }
    }
    if count == 1 {
        other
    } else {
        NONE
    }
}

/// Fewest corners for which [`Neighbours::new`] pairs edges by position rather than by sorting.
const DENSE_MIN: usize = 64 * 1024;

/// Most triangles at one position for [`Neighbours::by_position`] (scans, dense meshes, have
/// about six).
const MAX_LISTED: u32 = 256;

/// The edge key of slot `s` of `corners`: edge `s % 3` of triangle `s / 3`, from its corner
/// `s % 3` to the next.
fn slot_key(corners: &[u32], s: usize) -> u64 {
    edge_key(corners[s], corners[s - s % 3 + (s + 1) % 3])
}

/// Triangles with their hierarchy and neighbours: nearest-triangle queries that walk from a
/// hint first (see the module doc).
pub struct Surface<T> {
    /// The triangles.
    pub tris: Vec<Triangle<T>>,
    bvh: Bvh<T>,
    neighbours: Neighbours,
}

impl<T: Real> Surface<T> {
    /// The surface of `tris`, whose corners have the position ids `corners` (three per
    /// triangle; see [`Neighbours::new`]).
    pub fn new(tris: Vec<Triangle<T>>, corners: &[u32]) -> Surface<T> {
        Surface { bvh: Bvh::new(&tris), neighbours: Neighbours::new(corners), tris }
    }

    /// The hierarchy, for queries that do not walk.
    pub fn bvh(&self) -> &Bvh<T> {
        &self.bvh
    }

    /// [`Bvh::nearest_squared`] after a walk of at most `steps` from `hint` (a triangle index,
    /// or `usize::MAX` for none): a triangle within `enough2` the walk reaches, else the
    /// hierarchy's answer (the nearest triangle where it is farther than `enough2`).
    pub fn nearest_squared(&self, p: [T; 3], enough2: T, hint: usize, steps: usize) -> (T, usize) {
        match self.walk_within(p, enough2, hint, steps) {
            Ok(found) => found,
            Err(hint) => self.bvh.nearest_squared(&self.tris, p, enough2, hint),
        }
    }

    /// Like [`Surface::within_squared`], with a second walk from triangle `second()` where the
    /// first, from `first`, does not get within `enough2`; the hierarchy then starts from the
    /// closer of the two walks' ends.
    pub fn within_squared2(
        &self,
        p: [T; 3],
        enough2: T,
        first: usize,
        second: impl FnOnce() -> usize,
        steps: usize,
    ) -> (T, usize) {
        let a = match self.walk_within(p, enough2, first, steps) {
            Ok(found) => return found,
            Err(a) => a,
        };
        let b = match self.walk_within(p, enough2, second(), steps) {
            Ok(found) => return found,
            Err(b) => b,
        };
        let distance = |t: usize| self.tris.get(t).map_or(T::INFINITY, |tri| point_triangle_distance2(p, tri));
        let start = if distance(a) <= distance(b) { a } else { b };
        self.bvh.within_squared(&self.tris, p, enough2, start)
    }

    /// Like [`Surface::nearest_squared`], with [`Bvh::within_squared`] after the walk.
    pub fn within_squared(&self, p: [T; 3], enough2: T, hint: usize, steps: usize) -> (T, usize) {
        match self.walk_within(p, enough2, hint, steps) {
            Ok(found) => found,
            Err(hint) => self.bvh.within_squared(&self.tris, p, enough2, hint),
        }
    }

    /// A walk of at most `steps` from `hint` (a triangle index; any other value walks
    /// nowhere): the first triangle it reaches within `enough2` of `p` and the squared
    /// distance, else (`Err`) the closest triangle it saw, or `hint` if it did not walk: the
    /// hint for the hierarchy.
    pub fn walk_within(&self, p: [T; 3], enough2: T, hint: usize, steps: usize) -> Result<(T, usize), usize> {
        if hint >= self.tris.len() {
            return Err(hint);
        }
        let (d2, t) = self.neighbours.walk(&self.tris, p, enough2, hint, steps);
        if d2 <= enough2 {
            Ok((d2, t))
        } else {
            Err(t)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat `n` × `n` grid of unit squares, two triangles each, and its corners' ids.
    fn grid(n: u32) -> (Vec<Triangle<f64>>, Vec<u32>) {
        let id = |x: u32, y: u32| y * (n + 1) + x;
        let at = |v: u32| [(v % (n + 1)) as f64, (v / (n + 1)) as f64, 0.0];
        let mut corners = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let (a, b, c, d) = (id(x, y), id(x + 1, y), id(x + 1, y + 1), id(x, y + 1));
                corners.extend_from_slice(&[a, b, c, a, c, d]);
            }
        }
        let tris = corners.chunks_exact(3).map(|t| [at(t[0]), at(t[1]), at(t[2])]).collect();
        (tris, corners)
    }

    #[test]
    fn neighbours_pair_up_inner_edges_only() {
        let (_, corners) = grid(3);
        let n = Neighbours::new(&corners);
        // Each square's diagonal joins its two triangles; the grid's outline has no neighbour.
        assert_eq!(n.across[0][2], 1);
        assert_eq!(n.across[1][0], 0);
        let open = n.across.iter().flatten().filter(|&&t| t == NONE).count();
        assert_eq!(open, 12);
        // A third triangle on an edge leaves it without neighbours.
        let mut more = corners.clone();
        more.extend_from_slice(&[0, 5, 17]);
        assert_eq!(Neighbours::new(&more).across[0][2], NONE);
    }

    #[test]
    fn pairing_by_position_matches_the_sort() {
        // A grid with extras: a third triangle on an edge (non-manifold), a triangle twice,
        // and triangles with a repeated corner (an edge from a position to itself).
        let (_, mut corners) = grid(6);
        corners.extend_from_slice(&[0, 8, 30, 9, 10, 17, 9, 10, 17, 3, 3, 4, 4, 3, 3, 20, 21, 20]);
        let mut state = 11u64;
        for _ in 0..40 {
            // Random triangles over the same positions, some sharing edges with the grid.
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let a = (state >> 33) as u32 % 49;
            corners.extend_from_slice(&[a, (a + 1) % 49, (a + 7) % 49]);
        }
        // And a grid large enough to be listed on several threads.
        let (_, large) = grid(150);
        for corners in [corners, large] {
            let positions = *corners.iter().max().unwrap() as usize + 1;
            let (sorted, listed) =
                (Neighbours::by_sort(&corners), Neighbours::by_position(&corners, positions).unwrap());
            assert_eq!(sorted.across, listed.across);
            let across = || listed.across.iter().flatten();
            assert!(across().any(|&t| t != NONE) && across().any(|&t| t == NONE));
        }
    }

    #[test]
    fn a_wide_fan_is_paired_by_sorting() {
        // A closed fan of 300 triangles around position 0: too many to list by position.
        let fan: Vec<u32> = (0..300u32).flat_map(|i| [0, 1 + i, 1 + (i + 1) % 300]).collect();
        assert!(Neighbours::by_position(&fan, 301).is_none());
        let n = Neighbours::new(&fan);
        // Each triangle's neighbours are the triangles before and after it around the apex.
        assert_eq!(n.across[0], [299, NONE, 1]);
        assert!(Neighbours::by_position(&fan[..3 * 200], 301).is_some());
    }

    #[test]
    fn walks_reach_the_triangle_under_the_point() {
        let (tris, corners) = grid(8);
        let n = Neighbours::new(&corners);
        let p = [6.7, 5.2, 0.25];
        let (d2, t) = n.walk(&tris, p, 0.0625 + 1e-9, 0, 64);
        assert!(d2 <= 0.0625 + 1e-9, "{d2}");
        assert_eq!(point_triangle_distance2(p, &tris[t]), d2);
        assert!((0..3).all(|k| (tris[t][k][0] - 6.5).abs() <= 0.5 + 1e-9 && (tris[t][k][1] - 5.5).abs() <= 0.5 + 1e-9));
        // Too few steps: the closest triangle seen, farther than enough.
        let (d2, t) = n.walk(&tris, p, 0.0625, 0, 2);
        assert!(d2 > 0.0625 && point_triangle_distance2(p, &tris[t]) == d2);
        // Outside the grid: the walk stops at the border, at a triangle touching it.
        let (d2, _) = n.walk(&tris, [-3.0, 4.5, 0.0], 0.0, 0, 64);
        assert!((d2 - 9.0).abs() < 1e-9, "{d2}");
    }

    #[test]
    fn surface_queries_answer_as_the_hierarchy_does() {
        // A bumpy grid: points above and beside it, hints near and far.
        let (mut tris, corners) = grid(12);
        for t in &mut tris {
            for v in t.iter_mut() {
                v[2] = (v[0] * 0.7).sin() * (v[1] * 0.4).cos();
            }
        }
        let surface = Surface::new(tris.clone(), &corners);
        let mut state = 7u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f64 / (1u64 << 24) as f64
        };
        for _ in 0..300 {
            let p = [next() * 16.0 - 2.0, next() * 16.0 - 2.0, next() * 4.0 - 2.0];
            let exact = tris.iter().map(|t| point_triangle_distance2(p, t)).fold(f64::INFINITY, f64::min);
            let hint = (next() * tris.len() as f64) as usize;
            for query in [Surface::nearest_squared, Surface::within_squared] {
                let (d2, t) = query(&surface, p, 0.0, hint, 8);
                assert!(d2 == exact && point_triangle_distance2(p, &tris[t]) == d2, "{d2} {exact}");
                let (d2, t) = query(&surface, p, exact * 2.0 + 0.01, hint, 8);
                assert!(d2 <= exact * 2.0 + 0.01 && point_triangle_distance2(p, &tris[t]) == d2);
            }
        }
    }
}
