//! Validation of a `.mres` file against docs/INVARIANTS.md: §1 (every cut crack-free), §2
//! (monotone errors, nested spheres), §3 (well-conditioned DAG, in `conditioning`), §4 (honest
//! errors, in `honesty`) and §5 (format integrity).
//!
//! Crack check (docs/INVARIANTS.md §1): edges are welded by grid position, and each triangle
//! edge is marked (it lies on the surface's open border) or not. For a set of clusters let U(e)
//! be the unmarked and M(e) the marked uses of edge e. (a) At level 0, M(e) = (U(e) + M(e))
//! mod 2: the original's odd edges carry one mark each. (b) Each simplified group keeps its
//! border: the edges its members use an odd number of times unmarked are exactly those its
//! outputs do, and its outputs mark an edge at most once. (c) In every cut, U(e) is even (twice,
//! or four times where simplification pinched a thin part into one edge: not a crack; counted
//! and reported) and M(e) ≤ 1. A hole or T-junction shows as an unmarked odd count along its
//! rim; a wrongly set or cleared mark breaks (a), (b) or (c). A cluster drawn together with one
//! of its parents (overlap) is caught directly: no selected cluster may be a member of the group
//! that produced another selected cluster. Each cluster's edges are precomputed as (edge id,
//! uses, marked uses) so that a cut costs one counter increment per distinct cluster edge.

use crate::conditioning::{conditioning, Conditioning};
use crate::honesty::Honesty;
pub use crate::tables::Thresholds;
use crate::tables::{edge_tables, Edges};
use mres_format::{select, DecodedCluster, MresError, MresFile, Sphere, NO_GROUP};
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use serde::Serialize;

/// What to check.
#[derive(Clone, Debug)]
pub struct ValidateOptions {
    /// Number of random view-dependent cuts (random cameras and pixel thresholds).
    pub random_cuts: usize,
    /// Most uniform cuts (0: one per distinct group error, all of them).
    pub uniform_cuts: usize,
    /// Seed of the camera generator.
    pub seed: u64,
    /// Most violations listed in the report (all are counted).
    pub max_listed: usize,
    /// The thresholds of docs/INVARIANTS.md §3 and §4.
    pub thresholds: Thresholds,
}

impl Default for ValidateOptions {
    fn default() -> Self {
        ValidateOptions {
            random_cuts: 1000,
            uniform_cuts: 0,
            seed: 1,
            max_listed: 20,
            thresholds: Thresholds::default(),
        }
    }
}

/// Per-level figures.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LevelStats {
    /// Level (0 = original geometry).
    pub level: u32,
    /// Clusters at this level.
    pub clusters: u64,
    /// Groups formed from clusters at this level.
    pub groups: u64,
    /// Triangles in this level's clusters.
    pub triangles: u64,
}

/// The validator's findings.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Report {
    /// File size in bytes.
    pub bytes: u64,
    /// Triangles of the source mesh.
    pub source_triangles: u64,
    /// File bytes per source triangle.
    pub bytes_per_input_triangle: f64,
    /// DAG levels.
    pub levels: u32,
    /// Figures per level.
    pub per_level: Vec<LevelStats>,
    /// Groups with infinite error.
    pub root_groups: u64,
    /// Clusters in root groups.
    pub root_clusters: u64,
    /// Mean triangles per level-0 cluster.
    pub level0_fill: f64,
    /// Pages.
    pub pages: u64,
    /// Uniform-threshold cuts checked.
    pub uniform_cuts: u64,
    /// Random view-dependent cuts checked.
    pub random_cuts: u64,
    /// Cuts with a crack or overlap.
    pub cracked_cuts: u64,
    /// Most edges used four or more times (pinches) in one cut.
    pub max_pinched_edges: u64,
    /// Child→parent relations checked for monotone error and nested spheres.
    pub relations_checked: u64,
    /// Total violations found.
    pub violation_count: u64,
    /// The first violations, each naming the group/cluster and the broken invariant.
    pub violations: Vec<String>,
    /// Conditioning figures (docs/INVARIANTS.md §3).
    pub conditioning: Conditioning,
    /// Honesty figures (docs/INVARIANTS.md §4).
    pub honesty: Honesty,
    /// The thresholds applied.
    pub thresholds: Thresholds,
}

impl Report {
    /// True when no invariant is broken.
    pub fn ok(&self) -> bool {
        self.violation_count == 0
    }

    fn violation(&mut self, max: usize, msg: impl FnOnce() -> String) {
        self.violation_count += 1;
        if self.violations.len() < max {
            self.violations.push(msg());
        }
    }
}

/// Validates a parsed file.
pub fn validate(file: &MresFile, options: &ValidateOptions) -> Result<Report, MresError> {
    let decoded = file.decode_all()?;
    let max = options.max_listed;
    let mut report = Report {
        bytes: file.file_size() as u64,
        source_triangles: file.header.source_triangles,
        levels: file.header.level_count,
        pages: file.pages.len() as u64,
        ..Default::default()
    };
    report.bytes_per_input_triangle = report.bytes as f64 / report.source_triangles.max(1) as f64;
    levels_and_relations(file, &mut report, max);
    let edges = edge_tables(file, &decoded);
    // Conditioning (§3).
    let (shape, problems) = conditioning(file, &decoded, &edges, &options.thresholds);
    report.conditioning = shape;
    report.thresholds = options.thresholds.clone();
    for p in problems {
        report.violation(max, || p);
    }
    // Honesty (§4), open-border marks (§1 (a), (b)), crack-free cuts (§1 (c)).
    honesty(file, &decoded, (&options.thresholds, max), &mut report);
    for p in mark_problems(file, &edges) {
        report.violation(max, || p);
    }
    crack_free_cuts(file, &edges, options, &mut report);
    Ok(report)
}

/// The per-level figures, the roots and level-0 fill, and the relations of §2 (monotone errors,
/// nested spheres, DAG order; every group with a finite error produced clusters): into `report`,
/// violations listed up to `max`.
fn levels_and_relations(file: &MresFile, report: &mut Report, max: usize) {
    let (groups, clusters) = (&file.groups, &file.clusters);
    let cluster_level = |c: &mres_format::ClusterInfo| {
        if c.own_group == NO_GROUP {
            0
        } else {
            groups[c.own_group as usize].level + 1
        }
    };
    let levels =
        clusters.iter().map(|c| cluster_level(c) + 1).chain(groups.iter().map(|g| g.level + 1)).max().unwrap_or(0);
    report.per_level = (0..levels).map(|level| LevelStats { level, ..Default::default() }).collect();
    let mut outputs = vec![0u32; groups.len()];
    for (i, c) in clusters.iter().enumerate() {
        let l = &mut report.per_level[cluster_level(c) as usize];
        l.clusters += 1;
        l.triangles += c.triangle_count as u64;
        if c.own_group != NO_GROUP {
            outputs[c.own_group as usize] += 1;
            let (child, parent) = (&groups[c.own_group as usize], &groups[c.group as usize]);
            report.relations_checked += 1;
            // Written so that a NaN error is a violation too.
            #[allow(clippy::neg_cmp_op_on_partial_ord)]
            let below = !(parent.error >= child.error);
            if below {
                report.violation(max, || {
                    format!(
                        "cluster {i}: parent group {} error {} < own group {} error {} (monotone errors)",
                        c.group, parent.error, c.own_group, child.error
                    )
                });
            }
            if !contains(&parent.sphere, &child.sphere) {
                report.violation(max, || {
                    format!(
                        "cluster {i}: sphere of parent group {} does not contain own group {}'s (nested bounds)",
                        c.group, c.own_group
                    )
                });
            }
            if child.level >= parent.level {
                report.violation(max, || {
                    format!("cluster {i}: own group {} is not below its group {} (DAG order)", c.own_group, c.group)
                });
            }
        }
    }
    for (g, group) in groups.iter().enumerate() {
        if let Some(l) = report.per_level.get_mut(group.level as usize) {
            l.groups += 1;
        }
        if group.error.is_infinite() {
            report.root_groups += 1;
            report.root_clusters += group.cluster_count as u64;
        } else if outputs[g] == 0 {
            report.violation(max, || {
                format!("group {g}: finite error but no clusters produced by it (its members would vanish)")
            });
        }
    }
    if report.root_groups == 0 {
        report.violation(max, || "no root group (a group with infinite error)".into());
    }
    let level0 = &report.per_level.first().cloned().unwrap_or_default();
    report.level0_fill = level0.triangles as f64 / level0.clusters.max(1) as f64;
}

/// The honesty of the stored errors (§4), measured over `t.honesty_cuts` cuts: into `report`, a
/// violation above `t.max_error_ratio` (violations listed up to `max`).
fn honesty(file: &MresFile, decoded: &[DecodedCluster], (t, max): (&Thresholds, usize), report: &mut Report) {
    report.honesty = crate::honesty::measure(file, decoded, t.honesty_cuts, t.honesty_samples);
    if report.honesty.worst_ratio > t.max_error_ratio {
        let h = report.honesty.clone();
        report.violation(max, || {
            format!(
                "measured deviation {:.2}x the stored error (limit {}): {} (honest errors)",
                h.worst_ratio, t.max_error_ratio, h.worst
            )
        });
    }
}

/// The crack-free cuts of §1 (c): the uniform cuts at (up to `options.uniform_cuts` of) the
/// groups' errors and `options.random_cuts` view cuts, checked on every thread: into `report`.
fn crack_free_cuts(file: &MresFile, edges: &Edges, options: &ValidateOptions, report: &mut Report) {
    let (groups, clusters) = (&file.groups, &file.clusters);
    let max = options.max_listed;
    let mut thresholds: Vec<f32> = groups.iter().map(|g| g.error).filter(|e| e.is_finite()).collect();
    thresholds.push(0.0);
    thresholds.sort_by(f32::total_cmp);
    thresholds.dedup();
    if options.uniform_cuts >= 2 && thresholds.len() > options.uniform_cuts {
        let last = thresholds.len() - 1;
        let n = options.uniform_cuts - 1;
        thresholds = (0..=n).map(|i| thresholds[i * last / n]).collect();
        thresholds.dedup();
    }
    let uniform: Vec<(String, Vec<u32>)> = thresholds
        .iter()
        .map(|&t| (format!("uniform cut at error {t}"), select::uniform_cut(groups, clusters, t)))
        .collect();
    let cameras = random_views(file, options.random_cuts, options.seed);
    report.uniform_cuts = uniform.len() as u64;
    report.random_cuts = cameras.len() as u64;
    let checks: Vec<(String, CutCheck)> = uniform
        .into_par_iter()
        .map(|(name, cut)| (name, check_cut(edges, &cut, groups, clusters)))
        .chain(cameras.into_par_iter().map(|(view, tau)| {
            let cut = select::view_cut(groups, clusters, &view, tau);
            (format!("view cut eye {:?} tau {tau} px", view.eye), check_cut(edges, &cut, groups, clusters))
        }))
        .collect();
    for (name, check) in checks {
        report.max_pinched_edges = report.max_pinched_edges.max(check.pinched);
        if !check.problems.is_empty() {
            report.cracked_cuts += 1;
            let problems = check.problems;
            report.violation(max, || {
                format!("{name}: {} problems (crack-free cuts); first: {}", problems.len(), problems[0])
            });
        }
    }
}

/// True if `outer` contains `inner` (checked in f64).
fn contains(outer: &Sphere, inner: &Sphere) -> bool {
    let d: f64 = (0..3).map(|k| (outer.center[k] as f64 - inner.center[k] as f64).powi(2)).sum::<f64>().sqrt();
    d + inner.radius as f64 <= outer.radius as f64
}

/// What one cut's check found.
struct CutCheck {
    /// Descriptions of the first bad edges or overlaps (all counted).
    problems: Vec<String>,
    /// Edges used four or more times.
    pinched: u64,
}

/// Checks the open-border marks of level 0 and of every simplified group (see the module doc,
/// (a) and (b)); one message per broken cluster set.
fn mark_problems(file: &MresFile, edges: &Edges) -> Vec<String> {
    let n = file.clusters.len();
    let level0: Vec<u32> = (0..n as u32).filter(|&c| file.clusters[c as usize].own_group == NO_GROUP).collect();
    let mut problems = Vec::new();
    let (uses, marks) = tally(edges, &level0);
    let mut wrong: Vec<u32> =
        uses.iter().filter(|(e, u)| marks.get(*e).copied().unwrap_or(0) != *u % 2).map(|e| *e.0).collect();
    wrong.sort_unstable();
    if let Some(&e) = wrong.first() {
        let (a, b) = edges.ends[e as usize];
        problems.push(format!(
            "level 0: {} edges marked wrongly, first {a:?}-{b:?} used {}x with {} marks (open-border marks)",
            wrong.len(),
            uses[&e],
            marks.get(&e).copied().unwrap_or(0)
        ));
    }
    let mut outputs: Vec<Vec<u32>> = vec![Vec::new(); file.groups.len()];
    for (c, info) in file.clusters.iter().enumerate() {
        if info.own_group != NO_GROUP {
            outputs[info.own_group as usize].push(c as u32);
        }
    }
    let group_problems: Vec<String> = (0..file.groups.len())
        .into_par_iter()
        .filter(|&g| file.groups[g].error.is_finite())
        .filter_map(|g| {
            let group = &file.groups[g];
            let members: Vec<u32> = (group.first_cluster..group.first_cluster + group.cluster_count).collect();
            group_border_problem(edges, g, &members, &outputs[g])
        })
        .collect();
    problems.extend(group_problems);
    problems
}

/// Per edge, the uses and the marked uses by `clusters`.
fn tally(edges: &Edges, clusters: &[u32]) -> (FxHashMap<u32, u32>, FxHashMap<u32, u32>) {
    let (mut uses, mut marks) = (FxHashMap::default(), FxHashMap::default());
    for &c in clusters {
        for &(e, n, m) in &edges.per_cluster[c as usize] {
            *uses.entry(e).or_insert(0) += n as u32;
            if m > 0 {
                *marks.entry(e).or_insert(0) += m as u32;
            }
        }
    }
    (uses, marks)
}

/// The edges `clusters` use an odd number of times unmarked, sorted.
fn unmarked_odd(uses: &FxHashMap<u32, u32>, marks: &FxHashMap<u32, u32>) -> Vec<u32> {
    let mut odd: Vec<u32> =
        uses.iter().filter(|(e, u)| (**u - marks.get(*e).copied().unwrap_or(0)) % 2 == 1).map(|(e, _)| *e).collect();
    odd.sort_unstable();
    odd
}

/// (b) for group `g`: its outputs keep its members' unmarked odd edges and mark no edge twice.
fn group_border_problem(edges: &Edges, g: usize, members: &[u32], outputs: &[u32]) -> Option<String> {
    let (in_uses, in_marks) = tally(edges, members);
    let (out_uses, out_marks) = tally(edges, outputs);
    let (before, after) = (unmarked_odd(&in_uses, &in_marks), unmarked_odd(&out_uses, &out_marks));
    if before != after {
        let e = before
            .iter()
            .chain(&after)
            .find(|e| before.binary_search(e).is_err() || after.binary_search(e).is_err())?;
        let (a, b) = edges.ends[*e as usize];
        return Some(format!(
            "group {g}: its outputs change its border at edge {a:?}-{b:?} (unmarked odd in members: {}, in outputs: {}) (open-border marks)",
            before.binary_search(e).is_ok(),
            after.binary_search(e).is_ok()
        ));
    }
    let (e, m) = out_marks.iter().filter(|(_, m)| **m > 1).min()?;
    let (a, b) = edges.ends[*e as usize];
    Some(format!("group {g}: its outputs mark edge {a:?}-{b:?} {m} times (open-border marks)"))
}

/// Checks one cut: edge counts (see the module doc, (c)) and direct parent/child overlap.
fn check_cut(
    edges: &Edges,
    cut: &[u32],
    groups: &[mres_format::Group],
    clusters: &[mres_format::ClusterInfo],
) -> CutCheck {
    let (uses, marks) = tally(edges, cut);
    let marked = |e: u32| marks.get(&e).copied().unwrap_or(0);
    let mut bad: Vec<(u32, u32, u32)> = uses
        .iter()
        .map(|(e, n)| (*e, *n - marked(*e), marked(*e)))
        .filter(|(_, unmarked, m)| unmarked % 2 != 0 || *m > 1)
        .collect();
    bad.sort_unstable();
    let mut problems = Vec::new();
    for &(e, unmarked, m) in &bad {
        if problems.len() >= 3 {
            problems.push(String::new());
            continue;
        }
        let owners: Vec<String> = cut
            .iter()
            .filter(|&&c| edges.per_cluster[c as usize].iter().any(|x| x.0 == e))
            .map(|&c| format!("cluster {c} (group {})", clusters[c as usize].group))
            .collect();
        let (a, b) = edges.ends[e as usize];
        problems.push(format!(
            "edge {a:?}-{b:?} used {unmarked}x unmarked and {m}x marked (expected an even count and at most one mark), in [{}]",
            owners.join(", ")
        ));
    }
    let pinched = uses.iter().filter(|(e, n)| **n - marked(**e) >= 4).count() as u64;
    // Overlap: a selected cluster together with a member of the group that produced it.
    let mut selected = vec![false; clusters.len()];
    for &c in cut {
        selected[c as usize] = true;
    }
    for &c in cut {
        let own = clusters[c as usize].own_group;
        if own == NO_GROUP {
            continue;
        }
        let g = &groups[own as usize];
        if let Some(m) = (g.first_cluster..g.first_cluster + g.cluster_count).find(|&m| selected[m as usize]) {
            problems.push(format!(
                "cluster {c} drawn together with its child cluster {m} (member of group {own}): overlap"
            ));
        }
    }
    CutCheck { problems, pinched }
}

/// Random cameras around and inside the model's bounds, with random pixel thresholds.
fn random_views(file: &MresFile, n: usize, seed: u64) -> Vec<(select::ViewParams, f32)> {
    let Some(root) = file.groups.iter().max_by(|a, b| a.sphere.radius.total_cmp(&b.sphere.radius)) else {
        return Vec::new();
    };
    let (center, radius) = (root.sphere.center, root.sphere.radius.max(1e-6));
    let mut state = seed;
    let mut next = move || {
        // splitmix64
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let z = next() * 2.0 - 1.0;
            let phi = next() * std::f64::consts::TAU;
            let s = (1.0 - z * z).sqrt();
            // Distances from deep inside the bounds to far away, log-uniform.
            let distance = radius as f64 * 10f64.powf(next() * 2.5 - 1.3);
            let eye = [
                center[0] + (s * phi.cos() * distance) as f32,
                center[1] + (s * phi.sin() * distance) as f32,
                center[2] + (z * distance) as f32,
            ];
            // Thresholds log-uniform in [0.25, 16] px: continuous values probe every gap between
            // stored errors, not just a few fixed ones.
            let tau = (0.25 * 64f64.powf(next())) as f32;
            let view = select::ViewParams {
                eye,
                proj_y: 1.0 / (30f32.to_radians().tan()),
                viewport_height: 1080.0,
                z_near: radius * 1e-3,
            };
            (view, tau)
        })
        .collect()
}
