//! docs/INVARIANTS.md §4, honest errors: a cluster drawn in a cut stands in for the original
//! surface under it, and its own group's stored error must bound how far apart the two are.
//!
//! For a few uniform cuts (thresholds at quantiles of the stored errors), points are sampled
//! on the cut and on the level-0 surface and the two-sided distance is measured with a
//! bounding-volume hierarchy: a point on a drawn cluster is compared with that cluster's own
//! error; a point on the original surface with the largest own error among the drawn clusters
//! that replace its level-0 cluster (its drawn ancestors), whichever drawn cluster is nearest
//! to it. The worst and 99th-percentile ratios are reported.

use mres_format::{select, DecodedCluster, MresFile, NO_GROUP};
use mres_geom::bvh::Bvh;
use mres_geom::parts::{diagonals, UnionFind};
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
    /// Groups with samples: per group the largest ratio among the samples on its output
    /// clusters (cut → original) and the samples whose nearest cut point is on them (original
    /// → cut). How tight the stored errors are: 1 is exact.
    pub groups_measured: u64,
    /// Median over those groups of their largest ratio.
    pub group_median_ratio: f64,
    /// 10th percentile of the same.
    pub group_p10_ratio: f64,
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

/// The validator's sample points on a soup (`distance::samples`: centroids and edge midpoints,
/// thinned), each with its cluster and triangle.
fn samples(s: &Soup, max: usize) -> Vec<([f64; 3], u32, usize)> {
    crate::distance::samples(&s.tris, max).into_iter().map(|(p, i)| (p, s.cluster[i], i)).collect()
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
    // Per group, the largest ratio of a sample attributed to it.
    let mut per_group = vec![f64::NAN; groups.len()];
    let mut attribute = |c: u32, r: f64| {
        let g = file.clusters[c as usize].own_group;
        if g != NO_GROUP && r.is_finite() {
            let slot = &mut per_group[g as usize];
            *slot = if slot.is_nan() { r } else { slot.max(r) };
        }
    };
    let mut out = Honesty::default();
    for &t in &thresholds {
        let cut = select::uniform_cut(groups, &file.clusters, t);
        let cut_soup = soup(file, decoded, cut.iter().copied());
        let cut_bvh = Bvh::new(&cut_soup.tris);
        // Cut → original: compare with the drawn cluster's own error.
        let forward: Vec<(f64, String, u32)> = samples(&cut_soup, samples_per_cut)
            .par_iter()
            .map(|(p, c, _)| {
                let d = level0_bvh.distance(&level0.tris, *p);
                (
                    ratio(d, own_error(*c), floor),
                    format!("cut at {t}: point {p:?} on cluster {c} is {d:.3e} from the original"),
                    *c,
                )
            })
            .collect();
        // Original → cut: compare with the largest own error among the drawn clusters that
        // replace the sampled level-0 cluster (its drawn ancestors).
        let bound = drawn_ancestor_error(file, &cut, &own_error);
        let backward: Vec<(f64, String, u32)> = samples(&level0, samples_per_cut)
            .par_iter()
            .map(|(p, l, tri)| {
                // A part that vanished entirely is off by at most its own size on screen.
                let (d, nearest) = cut_bvh.nearest(&cut_soup.tris, *p);
                let d = d.min(part_size[*tri]);
                let e = bound[*l as usize];
                let c = cut_soup.cluster.get(nearest).copied().unwrap_or(*l);
                (ratio(d, e, floor), format!("cut at {t}: original point {p:?} of cluster {l} is {d:.3e} from the cut, whose clusters there claim {e:.3e}"), c)
            })
            .collect();
        out.cuts += 1;
        out.samples += (forward.len() + backward.len()) as u64;
        for (r, at, c) in forward.into_iter().chain(backward) {
            attribute(c, r);
            ratios.push((r, at));
        }
    }
    let mut tight: Vec<f64> = per_group.into_iter().filter(|r| !r.is_nan()).collect();
    tight.sort_by(f64::total_cmp);
    out.groups_measured = tight.len() as u64;
    if !tight.is_empty() {
        out.group_median_ratio = tight[tight.len() / 2];
        out.group_p10_ratio = tight[tight.len() / 10];
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
    let mut sets = UnionFind::new(0);
    let ids: Vec<[u32; 3]> =
        tris.iter().map(|t| t.map(|p| *vertex.entry(p.map(f64::to_bits)).or_insert_with(|| sets.push()))).collect();
    for t in &ids {
        sets.union(t[0], t[1]);
        sets.union(t[0], t[2]);
    }
    let diagonal = diagonals(&mut sets, ids.iter().zip(tris).flat_map(|(i, t)| (0..3).map(move |k| (i[k], t[k]))));
    ids.iter().map(|t| diagonal[sets.find(t[0]) as usize]).collect()
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
