//! DESIGN.md invariant 4, honest errors: a cluster drawn in a cut stands in for the original
//! surface under it, and its own group's stored error must bound how far apart the two are.
//!
//! For a few uniform cuts (thresholds at quantiles of the stored errors), points are sampled
//! on the cut and on the level-0 surface and the two-sided distance is measured with a
//! bounding-volume hierarchy: a point on a drawn cluster is compared with that cluster's own
//! error; a point on the original surface with the own error of the drawn cluster nearest to
//! it. The worst and 99th-percentile ratios are reported.

use formats::mres::{select, DecodedCluster, MresFile, NO_GROUP};
use rayon::prelude::*;
use serde::Serialize;

/// Honesty figures.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Honesty {
    /// Cuts measured.
    pub cuts: u64,
    /// Points measured (both directions, all cuts).
    pub samples: u64,
    /// Largest distance / stored own error.
    pub worst_ratio: f64,
    /// 99th percentile of the same.
    pub p99_ratio: f64,
    /// Where the worst ratio was found.
    pub worst: String,
}

/// A triangle soup with, per triangle, the cluster it came from.
struct Soup {
    tris: Vec<[[f64; 3]; 3]>,
    cluster: Vec<u32>,
}

fn soup(file: &MresFile, decoded: &[DecodedCluster], clusters: impl Iterator<Item = u32>) -> Soup {
    let mut s = Soup { tris: Vec::new(), cluster: Vec::new() };
    for c in clusters {
        let d = &decoded[c as usize];
        let p: Vec<[f64; 3]> = d.positions.iter().map(|q| file.header.grid.decode(*q).map(|v| v as f64)).collect();
        for t in d.indices.chunks_exact(3) {
            s.tris.push([p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]]);
            s.cluster.push(c);
        }
    }
    s
}

/// Deterministic sample points: every triangle's centroid and edge midpoints, thinned to at
/// most `max` points (triangle order, even stride).
fn samples(s: &Soup, max: usize) -> Vec<([f64; 3], u32, usize)> {
    let stride = (s.tris.len() * 4).div_ceil(max.max(1)).max(1);
    let mut out = Vec::new();
    for (i, t) in s.tris.iter().enumerate() {
        let mid = |a: [f64; 3], b: [f64; 3]| [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0, (a[2] + b[2]) / 2.0];
        let c = [
            (t[0][0] + t[1][0] + t[2][0]) / 3.0,
            (t[0][1] + t[1][1] + t[2][1]) / 3.0,
            (t[0][2] + t[1][2] + t[2][2]) / 3.0,
        ];
        for (k, p) in [c, mid(t[0], t[1]), mid(t[1], t[2]), mid(t[2], t[0])].into_iter().enumerate() {
            if (i * 4 + k) % stride == 0 {
                out.push((p, s.cluster[i], i));
            }
        }
    }
    out
}

/// Measures honesty on `cuts` uniform cuts with about `samples_per_cut` points each way.
pub fn measure(file: &MresFile, decoded: &[DecodedCluster], cuts: usize, samples_per_cut: usize) -> Honesty {
    let groups = &file.groups;
    let own_error = |c: u32| match file.clusters[c as usize].own_group {
        NO_GROUP => 0.0,
        g => groups[g as usize].error as f64,
    };
    let level0 = soup(
        file,
        decoded,
        (0..file.clusters.len() as u32).filter(|&c| file.clusters[c as usize].own_group == NO_GROUP),
    );
    let level0_bvh = Bvh::new(&level0.tris);
    let part_size = component_diagonals(&level0.tris);
    let mut errors: Vec<f32> = groups.iter().map(|g| g.error).filter(|e| e.is_finite() && *e > 0.0).collect();
    errors.sort_by(f32::total_cmp);
    errors.dedup();
    let thresholds: Vec<f32> = (1..=cuts).filter_map(|i| errors.get(i * errors.len() / (cuts + 1)).copied()).collect();
    // Distances below this are grid rounding, not simplification.
    let floor = file.header.grid.step as f64;
    let mut ratios: Vec<(f64, String)> = Vec::new();
    let mut out = Honesty::default();
    for &t in &thresholds {
        let cut = select::uniform_cut(groups, &file.clusters, t);
        let cut_soup = soup(file, decoded, cut.iter().copied());
        let cut_bvh = Bvh::new(&cut_soup.tris);
        // Cut → original: compare with the drawn cluster's own error.
        let forward: Vec<(f64, String)> = samples(&cut_soup, samples_per_cut)
            .par_iter()
            .map(|(p, c, _)| {
                let d = level0_bvh.distance(&level0.tris, *p);
                (
                    ratio(d, own_error(*c), floor),
                    format!("cut at {t}: point {p:?} on cluster {c} is {d:.3e} from the original"),
                )
            })
            .collect();
        // Original → cut: compare with the largest own error among the drawn clusters that
        // replace the sampled level-0 cluster (its drawn ancestors).
        let bound = drawn_ancestor_error(file, &cut, &own_error);
        let backward: Vec<(f64, String)> = samples(&level0, samples_per_cut)
            .par_iter()
            .map(|(p, l, tri)| {
                // A part that vanished entirely is off by at most its own size on screen.
                let d = cut_bvh.distance(&cut_soup.tris, *p).min(part_size[*tri]);
                let e = bound[*l as usize];
                (ratio(d, e, floor), format!("cut at {t}: original point {p:?} of cluster {l} is {d:.3e} from the cut, whose clusters there claim {e:.3e}"))
            })
            .collect();
        out.cuts += 1;
        out.samples += (forward.len() + backward.len()) as u64;
        ratios.extend(forward);
        ratios.extend(backward);
    }
    ratios.sort_by(|a, b| a.0.total_cmp(&b.0));
    if let Some((worst, at)) = ratios.last() {
        out.worst_ratio = *worst;
        out.worst = at.clone();
        out.p99_ratio = ratios[(ratios.len() * 99 / 100).min(ratios.len() - 1)].0;
    }
    out
}

/// Per triangle, the bounding-box diagonal of its connected component (triangles sharing a
/// vertex position): when simplification drops a whole small part (a far-away box), the
/// deviation a viewer sees is the part's size, not its distance to the next surface.
fn component_diagonals(tris: &[[[f64; 3]; 3]]) -> Vec<f64> {
    let mut vertex: rustc_hash::FxHashMap<[u64; 3], u32> = rustc_hash::FxHashMap::default();
    let mut parent: Vec<u32> = Vec::new();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    let ids: Vec<[u32; 3]> = tris
        .iter()
        .map(|t| {
            t.map(|p| {
                *vertex.entry(p.map(f64::to_bits)).or_insert_with(|| {
                    parent.push(parent.len() as u32);
                    parent.len() as u32 - 1
                })
            })
        })
        .collect();
    for t in &ids {
        for k in 1..3 {
            let (a, b) = (find(&mut parent, t[0]), find(&mut parent, t[k]));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut lo = vec![[f64::INFINITY; 3]; parent.len()];
    let mut hi = vec![[f64::NEG_INFINITY; 3]; parent.len()];
    let roots: Vec<u32> = ids.iter().map(|t| find(&mut parent, t[0])).collect();
    for (t, &r) in tris.iter().zip(&roots) {
        for p in t {
            for k in 0..3 {
                lo[r as usize][k] = lo[r as usize][k].min(p[k]);
                hi[r as usize][k] = hi[r as usize][k].max(p[k]);
            }
        }
    }
    let diag = |r: usize| (0..3).map(|k| (hi[r][k] - lo[r][k]).powi(2)).sum::<f64>().sqrt();
    roots.iter().map(|&r| diag(r as usize)).collect()
}

/// Per cluster, the largest own error among the drawn clusters at or above it in the DAG
/// (following group → outputs upward); the drawn clusters of a valid cut cover every cluster.
fn drawn_ancestor_error(file: &MresFile, cut: &[u32], own_error: &impl Fn(u32) -> f64) -> Vec<f64> {
    let n = file.clusters.len();
    let mut drawn = vec![false; n];
    for &c in cut {
        drawn[c as usize] = true;
    }
    // Outputs of each group, and clusters in an order where outputs come before members:
    // clusters are stored coarse to fine, so a reverse-free pass over increasing index works.
    let mut outputs: Vec<Vec<u32>> = vec![Vec::new(); file.groups.len()];
    for (c, info) in file.clusters.iter().enumerate() {
        if info.own_group != NO_GROUP {
            outputs[info.own_group as usize].push(c as u32);
        }
    }
    let mut bound = vec![0.0f64; n];
    for c in 0..n {
        bound[c] = if drawn[c] {
            own_error(c as u32)
        } else {
            outputs[file.clusters[c].group as usize].iter().map(|&o| bound[o as usize]).fold(0.0, f64::max)
        };
    }
    bound
}

fn ratio(distance: f64, error: f64, floor: f64) -> f64 {
    if distance <= floor {
        0.0
    } else if error <= 0.0 {
        f64::INFINITY
    } else {
        distance / error
    }
}

/// Bounding-volume hierarchy over triangles for nearest-point queries (median split on the
/// longest axis, leaves of up to 4 triangles).
pub(crate) struct Bvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
}

struct Node {
    lo: [f64; 3],
    hi: [f64; 3],
    /// Leaf: first triangle in `order` and count; inner: children at `start` and `start + 1`.
    start: u32,
    count: u32,
}

impl Bvh {
    pub(crate) fn new(tris: &[[[f64; 3]; 3]]) -> Bvh {
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let mut nodes = vec![Node { lo: [0.0; 3], hi: [0.0; 3], start: 0, count: 0 }];
        let mut stack = vec![(0usize, 0usize, tris.len())];
        while let Some((node, start, end)) = stack.pop() {
            let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for &t in &order[start..end] {
                for v in &tris[t as usize] {
                    for k in 0..3 {
                        lo[k] = lo[k].min(v[k]);
                        hi[k] = hi[k].max(v[k]);
                    }
                }
            }
            nodes[node].lo = lo;
            nodes[node].hi = hi;
            if end - start <= 4 {
                nodes[node].start = start as u32;
                nodes[node].count = (end - start) as u32;
                continue;
            }
            let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
            let centroid = |t: u32| tris[t as usize].iter().map(|v| v[axis]).sum::<f64>();
            let mid = (start + end) / 2;
            order[start..end].select_nth_unstable_by(mid - start, |&a, &b| centroid(a).total_cmp(&centroid(b)));
            let child = nodes.len();
            nodes.push(Node { lo, hi, start: 0, count: 0 });
            nodes.push(Node { lo, hi, start: 0, count: 0 });
            nodes[node].start = child as u32;
            stack.push((child, start, mid));
            stack.push((child + 1, mid, end));
        }
        Bvh { nodes, order }
    }

    pub(crate) fn distance(&self, tris: &[[[f64; 3]; 3]], p: [f64; 3]) -> f64 {
        self.nearest(tris, p).0
    }

    /// Distance to the nearest triangle and its index.
    fn nearest(&self, tris: &[[[f64; 3]; 3]], p: [f64; 3]) -> (f64, usize) {
        let mut best = (f64::INFINITY, 0usize);
        if self.order.is_empty() {
            return best;
        }
        // Depth is at most ~2·log2(n) + 1; 96 entries cover any mesh that fits in memory.
        let mut stack = [0u32; 96];
        let mut top = 1usize;
        let box_dist = |n: &Node| (0..3).map(|k| (n.lo[k] - p[k]).max(p[k] - n.hi[k]).max(0.0).powi(2)).sum::<f64>();
        while top > 0 {
            top -= 1;
            let n = &self.nodes[stack[top] as usize];
            if box_dist(n) >= best.0 * best.0 {
                continue;
            }
            if n.count > 0 {
                for &t in &self.order[n.start as usize..(n.start + n.count) as usize] {
                    let d = point_triangle_distance(p, &tris[t as usize]);
                    if d < best.0 {
                        best = (d, t as usize);
                    }
                }
            } else if top + 2 <= stack.len() {
                let (a, b) = (n.start, n.start + 1);
                let (near, far) = if box_dist(&self.nodes[a as usize]) <= box_dist(&self.nodes[b as usize]) {
                    (a, b)
                } else {
                    (b, a)
                };
                stack[top] = far;
                stack[top + 1] = near;
                top += 2;
            }
        }
        best
    }
}

/// Distance from `p` to triangle `t` (closest point by region, Ericson's "Real-Time Collision
/// Detection" §5.1.5).
fn point_triangle_distance(p: [f64; 3], t: &[[f64; 3]; 3]) -> f64 {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    let at = |u: f64, v: f64| -> f64 {
        let q = [a[0] + ab[0] * u + ac[0] * v, a[1] + ab[1] * u + ac[1] * v, a[2] + ab[2] * u + ac[2] * v];
        dot(sub(p, q), sub(p, q)).sqrt()
    };
    if d1 <= 0.0 && d2 <= 0.0 {
        return at(0.0, 0.0);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return at(1.0, 0.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return at(d1 / (d1 - d3), 0.0);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return at(0.0, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return at(0.0, d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at(1.0 - w, w);
    }
    let denom = 1.0 / (va + vb + vc);
    at(vb * denom, vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_triangle_distances() {
        let t = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
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
    }
}
