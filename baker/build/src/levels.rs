//! The level loop on one welded mesh: level-0 clusters, then repeatedly group (METIS),
//! simplify each group in parallel with its border locked, and split the result into parent
//! clusters (docs/ARCHITECTURE.md "Data flow of one bake").
//!
//! The result is independent of the rayon thread count: groups are simplified in parallel but
//! collected in partition order.

use crate::chords::{self, Chords};
use crate::cluster::{bounding_sphere, enclosing_sphere, split};
use crate::dag::{BuildStats, BuiltCluster, BuiltGroup, Cell, Converted, DagOutput, TopCluster, LOCAL};
use crate::deviation::{measure_simplified, part_sizes, Original, Reference};
use crate::error::BakeError;
use crate::open;
use crate::partition::{cluster_graph, one_group, partition, triangle_order};
use crate::progress::Progress;
use crate::samples::{assign_owned, keep_together, merge_owned, sort_owned, without_vanished, Owned, CENTROID};
use crate::settings::{BakeSettings, ErrorBound};
use crate::simplify::{self, simplify_group, Locks, Method};
use crate::weld::WeldedMesh;
use mres_format::NO_GROUP;
use mres_geom::edges::{edge_ends, edge_keys, sorted_edge_keys};
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// Most clusters the final root group may hold. A mesh whose coarsest clusters cannot be
/// simplified further (an open boundary is locked in every cut) ends in one root group of up
/// to this many clusters; beyond it, several root groups are formed and reported.
pub const MAX_ROOT_CLUSTERS: usize = 256;
/// A stuck top of at most this many clusters is simplified as one group (the validator's
/// largest group size, docs/INVARIANTS.md §3).
const FORCED_GROUP_CLUSTERS: usize = 32;
/// `owner` of a position used by two or more groups of a level.
const SHARED: u32 = u32::MAX - 1;
/// The root chain ([`Builder::step`]) stops at a lone cluster of at most this many
/// triangles: below, a link saves a few triangles for a level's header and group.
const ROOT_CHAIN_TRIANGLES: usize = 16;
/// Safety stop on the number of levels.
const MAX_LEVELS: u32 = 64;

/// One simplified group: its parent clusters, its error, the method used.
struct Simplified {
    children: Vec<Child>,
    error: f32,
    method: Method,
}

/// A part's simplification that a level keeps, and whether the run that made it was lenient
/// (a stuck group's retry, see [`Builder::simplify_rounds`]); `None` where stuck.
type Kept = Option<(simplify::Simplified, bool)>;

/// What a level's groups must keep: the positions two groups use (the group borders), the
/// positions on a cell border ([`cell_borders`]), and which chords a group may add (see
/// [`crate::chords`]).
struct LevelLocks<'a> {
    mesh: &'a WeldedMesh,
    cell_border: &'a [bool],
    /// Per position id, the one group using it, or [`SHARED`].
    owner: Vec<AtomicU32>,
    chords: Chords,
}

impl<'a> LevelLocks<'a> {
    fn new(mesh: &'a WeldedMesh, cell_border: &'a [bool], parts: &[Vec<u32>], refs: &[&[u32]]) -> Self {
        let owner = owners(mesh, parts, refs);
        let chords = Chords::new(parts, refs, &mesh.position_ids, |p| owner[p as usize].load(Relaxed) == SHARED);
        LevelLocks { mesh, cell_border, owner, chords }
    }

    /// Whether welded vertex `v` is locked: on a group border or a cell border.
    fn vertex(&self, v: u32) -> bool {
        let p = self.mesh.position_ids[v as usize];
        self.owner[p as usize].load(Relaxed) == SHARED || self.cell_border[p as usize]
    }

    /// The first round's chord rule ([`Chords::free`]): no end on a cell border (another
    /// cell's groups, unseen here, may hold it).
    fn free(&self, e: u64) -> bool {
        self.chords.free(e, |p| self.cell_border[p as usize])
    }

    /// The later rounds' rule for group `g` ([`Chords::unshared`]).
    fn unshared(&self, g: u32, e: u64) -> bool {
        self.chords.unshared(g, e, |p| self.cell_border[p as usize])
    }
}

/// A part's triangles and open-border marks (see [`Builder::part_input`]).
struct PartInput {
    merged: Vec<u32>,
    masks: Vec<u8>,
}

/// One parent cluster of a simplified group: triangles, open-border marks, owned level-0
/// triangles (empty unless errors are measured against level 0).
struct Child {
    indices: Vec<u32>,
    open: Vec<u8>,
    owned: Vec<Owned>,
}

/// Level-0 clusters of a welded mesh, with their own bounds; the edges of `open` (sorted
/// position-id keys: the original's odd edges) are marked once each. `edges` are the mesh's
/// edges; `order` is the mesh's [`triangle_order`].
pub(crate) fn level0(
    mesh: &WeldedMesh,
    settings: &BakeSettings,
    (edges, open): (&Level0Edges, &[u64]),
    order: &[u32],
) -> Vec<BuiltCluster> {
    let clusters = level0_clusters(mesh, settings, order);
    // Passes over every triangle, independent of each other: side by side.
    let non_manifold = edges.non_manifold();
    let (marks, (samples, codes)) = rayon::join(
        || open::mark(mesh, &clusters, open),
        || rayon::join(|| first_samples(mesh, &clusters, &non_manifold), || triangle_codes(mesh, &clusters)),
    );
    clusters
        .into_par_iter()
        .zip(marks)
        .zip(samples.into_par_iter().zip(codes))
        .map(|((indices, open), (samples, codes))| {
            let own_sphere = bounding_sphere(&indices, &mesh.positions);
            let owned = indices.chunks_exact(3).zip(samples).zip(codes);
            let mut owned: Vec<Owned> =
                owned.map(|((t, bits), code)| Owned::triangle(code, [t[0], t[1], t[2]], bits)).collect();
            // Sorted, as every later cluster's is, so that `merge_owned` merges sorted runs.
            sort_owned(&mut owned);
            BuiltCluster { indices, own_group: NO_GROUP, own_sphere, own_error: 0.0, group: NO_GROUP, open, owned }
        })
        .collect()
}

/// Per triangle of `clusters`, the Morton code of its centroid over the whole mesh.
fn triangle_codes(mesh: &WeldedMesh, clusters: &[Vec<u32>]) -> Vec<Vec<u32>> {
    let p = |v: u32| mesh.positions[v as usize];
    let centroid = |t: &[u32]| [0, 1, 2].map(|k| (p(t[0])[k] + p(t[1])[k] + p(t[2])[k]) * (1.0 / 3.0));
    let centroids: Vec<[f32; 3]> = clusters.iter().flat_map(|c| c.chunks_exact(3).map(centroid)).collect();
    let mut codes = crate::partition::morton_codes(&centroids).into_iter();
    clusters.iter().map(|c| codes.by_ref().take(c.len() / 3).collect()).collect()
}

/// Per triangle of `clusters`, the level-0 samples it owns (see `samples::Samples`): its
/// centroid, and each corner and edge midpoint on the first triangle (in cluster order) that
/// uses that position or edge, so that a shared point is measured once per level.
/// `non_manifold`: the mesh's edges used three times or more, sorted.
///
/// Side by side: a position's first use is the least of its corners' places (an atomic
/// minimum, the same for any order); an edge used twice within one cluster and nowhere else
/// (most edges) is decided in its cluster, and only the rest (cluster borders, open and
/// non-manifold edges) in one pass in cluster order, where a set of every edge was the level's
/// longest serial pass.
fn first_samples(mesh: &WeldedMesh, clusters: &[Vec<u32>], non_manifold: &[u64]) -> Vec<Vec<u8>> {
    let id = |v: u32| mesh.position_ids[v as usize];
    let starts: Vec<usize> = clusters.iter().scan(0, |at, c| Some(std::mem::replace(at, *at + c.len()))).collect();
    let first_corner: Vec<AtomicU32> = (0..mesh.position_count).map(|_| AtomicU32::new(u32::MAX)).collect();
    clusters.par_iter().zip(&starts).for_each(|(indices, &start)| {
        for (s, &v) in indices.iter().enumerate() {
            first_corner[id(v) as usize].fetch_min((start + s) as u32, Relaxed);
        }
    });
    let mut local: Vec<(Vec<u8>, Vec<_>)> = clusters
        .par_iter()
        .zip(&starts)
        .map(|(indices, &start)| {
            let mut bits = vec![CENTROID; indices.len() / 3];
            for (s, &v) in indices.iter().enumerate() {
                if first_corner[id(v) as usize].load(Relaxed) == (start + s) as u32 {
                    bits[s / 3] |= 1 << (s % 3);
                }
            }
            let mut edges: Vec<(u64, u32)> = edge_keys(indices, id).into_iter().zip(0..).collect();
            edges.sort_unstable();
            let mut rest = Vec::new();
            for run in edges.chunk_by(|a, b| a.0 == b.0) {
                if run.len() == 2 && non_manifold.binary_search(&run[0].0).is_err() {
                    bits[run[0].1 as usize / 3] |= 8 << (run[0].1 % 3);
                } else {
                    rest.extend_from_slice(run);
                }
            }
            // In the cluster's order, for the pass below.
            rest.sort_unstable_by_key(|e| e.1);
            (bits, rest)
        })
        .collect();
    let mut edge_seen = rustc_hash::FxHashSet::default();
    edge_seen.reserve(local.iter().map(|l| l.1.len()).sum());
    for (bits, rest) in &mut local {
        for &(e, s) in rest.iter() {
            if edge_seen.insert(e) {
                bits[s as usize / 3] |= 8 << (s % 3);
            }
        }
    }
    local.into_iter().map(|l| l.0).collect()
}

/// The level loop over one welded mesh: group the pending clusters, simplify each group with
/// its border locked, split the results into the next level's clusters.
pub(crate) struct Builder<'a> {
    mesh: &'a WeldedMesh,
    settings: &'a BakeSettings,
    /// Per position id: on a shard or cell border, locked at every level of this builder
    /// (see [`cell_borders`]).
    cell_border: Vec<bool>,
    /// The whole level-0 surface, when the pending clusters started at level 0 and errors are
    /// measured (see `deviation::Original`).
    original: Option<Original>,
    /// Per position id, the size of its connected part (see `deviation::part_sizes`).
    part_size: Vec<f32>,
    /// Every cluster built so far, in creation order.
    pub clusters: Vec<BuiltCluster>,
    /// Every group formed so far; ids are local (`LOCAL` | index) until collected.
    pub groups: Vec<BuiltGroup>,
    /// Clusters without a group yet, ascending.
    pub pending: Vec<usize>,
    /// The level the next groups get.
    pub level: u32,
    pub stats: BuildStats,
    /// The first level's groups where the caller made them ([`Prepared::parts`]).
    parts: Option<Vec<Vec<u32>>>,
    /// Clusters grouped since they were last handed over to be converted (see [`Converted`]).
    grouped: Vec<usize>,
}

/// What a caller of [`Builder::with_prepared`] made beforehand, side by side with the level-0
/// clusters: each is made by the builder where missing.
#[derive(Default)]
pub(crate) struct Prepared {
    /// The whole level-0 surface (`Original::new`), where errors are measured.
    pub original: Option<Original>,
    /// The clusters are the level-0 clusters of a whole mesh, which mark each of its odd
    /// edges once: no position is on a cell border (see [`cell_borders`]).
    pub whole_mesh: bool,
    /// The part sizes ([`part_sizes`]), where errors are measured.
    pub part_size: Option<Vec<f32>>,
    /// The first level's groups of all the clusters ([`groups`]).
    pub parts: Option<Vec<Vec<u32>>>,
}

impl<'a> Builder<'a> {
    /// A builder whose pending clusters are `clusters` (triangles into `mesh`); new groups
    /// start at `level`.
    pub fn new(mesh: &'a WeldedMesh, settings: &'a BakeSettings, clusters: Vec<BuiltCluster>, level: u32) -> Self {
        Self::with_prepared(mesh, settings, clusters, level, Prepared::default())
    }

    /// [`Builder::new`] with what the caller made while the level-0 clusters were (see
    /// [`Prepared`]); what it lacks is made here.
    pub fn with_prepared(
        mesh: &'a WeldedMesh,
        settings: &'a BakeSettings,
        clusters: Vec<BuiltCluster>,
        level: u32,
        prepared: Prepared,
    ) -> Self {
        let Prepared { original, whole_mesh, part_size, parts } = prepared;
        let from_level0 = clusters.iter().all(|c| c.own_group == NO_GROUP && !c.owned.is_empty());
        let measured = settings.error_bound == ErrorBound::Measured;
        // Independent passes over the whole mesh, two of them serial: side by side.
        let (original, (cell_border, part_size)) = rayon::join(
            || {
                (measured && from_level0)
                    .then(|| original.unwrap_or_else(|| Original::new(mesh, &triangle_order(mesh))))
            },
            || {
                let locked =
                    || if whole_mesh { vec![false; mesh.position_count] } else { cell_borders(mesh, &clusters) };
                let sizes = || part_size.unwrap_or_else(|| if measured { part_sizes(mesh) } else { Vec::new() });
                rayon::join(locked, sizes)
            },
        );
        let pending = (0..clusters.len()).collect();
        let stats = BuildStats::default();
        Builder {
            mesh,
            settings,
            cell_border,
            original,
            part_size,
            clusters,
            groups: Vec::new(),
            pending,
            level,
            stats,
            parts,
            grouped: Vec::new(),
        }
    }

    /// Triangles in the pending clusters.
    pub fn pending_triangles(&self) -> usize {
        self.pending.iter().map(|&c| self.clusters[c].indices.len() / 3).sum()
    }

    /// Builds one level, handing the clusters grouped since the last call to `output` to be
    /// converted into `converted` beside the level's partition (see [`Converted`]). Returns
    /// false (and changes nothing) when there is nothing left to group, and false after a
    /// level where no group could be simplified.
    ///
    /// A lone pending cluster of more than [`ROOT_CHAIN_TRIANGLES`] is a group of its own: the
    /// root chain (docs/INVARIANTS.md §3) simplifies it on, a level at a time, while it halves.
    /// The first single cluster is often near 128 triangles (where the last halving happened
    /// to land), with an error far below what coarse cuts allow (a floor with walls: 128
    /// triangles within 1e-4 of the diagonal, while clusterlod's root, where its own halving
    /// landed, has 99); each link is a coarser choice for distant objects.
    pub fn step<O: DagOutput>(
        &mut self,
        progress: Progress,
        output: &O,
        converted: &mut Converted<O::Cluster>,
    ) -> bool {
        let lone_and_small = self.pending.len() == 1 && self.pending_triangles() <= ROOT_CHAIN_TRIANGLES;
        if self.pending.is_empty() || lone_and_small || self.level >= MAX_LEVELS {
            return false;
        }
        let (mesh, clusters) = (self.mesh, &self.clusters);
        let pending = || self.pending.iter().map(|&c| &clusters[c]);
        let refs: Vec<&[u32]> = pending().map(|c| c.indices.as_slice()).collect();
        let grouped = std::mem::take(&mut self.grouped);
        let mut convert = || converted.convert(output, mesh, clusters, &grouped);
        let mut parts = match self.parts.take() {
            Some(parts) => {
                convert();
                parts
            }
            None => rayon::join(|| groups(mesh, pending(), self.settings), convert).0,
        };
        let mut results = self.simplify_parts(&parts, &refs, false);
        if results.iter().all(Option::is_none) {
            // Stuck everywhere: lenient runs, and a small top taken whole (no group border is
            // left to keep), so that every input reaches one root cluster.
            if self.pending.len() <= FORCED_GROUP_CLUSTERS {
                parts = vec![(0..self.pending.len() as u32).collect()];
            }
            results = self.simplify_parts(&parts, &refs, true);
        }
        drop(refs);
        let progressed = self.adopt(&parts, results);
        self.level += 1;
        let triangles = self.pending_triangles();
        progress(&format!("level {}: {} clusters, {triangles} triangles", self.level, self.pending.len()));
        tracing::info!(
            level = self.level,
            clusters = self.pending.len(),
            triangles,
            groups = parts.len(),
            "level built"
        );
        progressed
    }

    /// Simplifies each part (a group of pending clusters, whose triangles are `refs`) in
    /// parallel, with the positions it shares with other parts locked, and measures and splits
    /// each result kept ([`Builder::simplify_rounds`], [`Builder::finish_part`]); `None` where
    /// stuck. `lenient`: every run is lenient (the whole level was stuck; see
    /// [`simplify_group`]).
    fn simplify_parts(&self, parts: &[Vec<u32>], refs: &[&[u32]], lenient: bool) -> Vec<Option<Simplified>> {
        let level = LevelLocks::new(self.mesh, &self.cell_border, parts, refs);
        let inputs: Vec<PartInput> = parts.par_iter().map(|part| self.part_input(part, refs)).collect();
        let kept = self.simplify_rounds(&level, &inputs, lenient);
        // A retry of an outlier may add its result's own chords and unshared ones: none that
        // another group's kept result has or a retry of another group can add.
        let finish = |(g, kept): (usize, Kept)| {
            let (mut s, lenient) = kept?;
            // Nothing after the measure reads a result's chords.
            let own = std::mem::take(&mut s.chords);
            let chord = |e: u64| level.unshared(g as u32, e) || own.binary_search(&e).is_ok();
            let vertex = |v: u32| level.vertex(v);
            let locks = Locks { vertex: &vertex, chord: &chord };
            Some(self.finish_part(&parts[g], &inputs[g], s, &locks, lenient))
        };
        kept.into_par_iter().enumerate().map(finish).collect()
    }

    /// The simplification of each part that a level keeps (see [`Kept`]), in rounds that only
    /// simplify: two for the chords between locked positions (see [`crate::chords`]), and
    /// where some parts simplify and others are stuck, a third for the stuck ones, lenient.
    /// A result that a later round replaces is never measured (on the two-cylinder engine, a
    /// quarter of the groups of the lower levels add a chord a lower-numbered group added too).
    fn simplify_rounds(&self, level: &LevelLocks, inputs: &[PartInput], lenient: bool) -> Vec<Kept> {
        let simplify = |g: usize, chord: &(dyn Fn(u64) -> bool + Sync), lenient: bool| {
            let vertex = |v: u32| level.vertex(v);
            let locks = Locks { vertex: &vertex, chord };
            let input = &inputs[g];
            simplify_group(self.mesh, &input.merged, &input.masks, &locks, self.settings, lenient).map(|s| (s, lenient))
        };
        let free = |e: u64| level.free(e);
        let mut kept: Vec<Kept> = (0..inputs.len()).into_par_iter().map(|g| simplify(g, &free, lenient)).collect();
        // Each group of a later round may add only chords no other group can have.
        let again = |groups: Vec<usize>, lenient: bool| -> Vec<(usize, Kept)> {
            let run = |g: usize| (g, simplify(g, &|e: u64| level.unshared(g as u32, e), lenient));
            groups.into_par_iter().map(run).collect()
        };
        let added: Vec<Option<&[u64]>> = kept.iter().map(|k| k.as_ref().map(|s| s.0.chords.as_slice())).collect();
        for (g, result) in again(chords::conflicted(&added), lenient) {
            kept[g] = result;
        }
        if !lenient && kept.iter().any(Option::is_some) {
            // Some groups simplified and some are stuck: the stuck ones try again, lenient,
            // rather than waiting for a level where all are stuck. Their unshared chords
            // cannot meet another group's, of any round.
            let stuck = (0..inputs.len()).filter(|&g| kept[g].is_none()).collect();
            for (g, result) in again(stuck, true) {
                kept[g] = result;
            }
        }
        kept
    }

    /// A part's triangles (its clusters' triangles one after another) and their open-border
    /// marks: what its simplification runs on.
    fn part_input(&self, part: &[u32], refs: &[&[u32]]) -> PartInput {
        PartInput {
            merged: part.iter().flat_map(|&c| refs[c as usize].iter().copied()).collect(),
            masks: part.iter().flat_map(|&c| self.clusters[self.pending[c as usize]].open.iter().copied()).collect(),
        }
    }

    /// Measures one part's simplification `s` (made with `locks` from `input`, see
    /// [`Builder::simplify_parts`]) and splits it into its children with their samples.
    fn finish_part(
        &self,
        part: &[u32],
        input: &PartInput,
        s: simplify::Simplified,
        locks: &Locks,
        lenient: bool,
    ) -> Simplified {
        let (mesh, settings) = (self.mesh, self.settings);
        let part_size = &self.part_size;
        let (clusters, pending) = (&self.clusters, &self.pending);
        let members = || part.iter().map(|&c| &clusters[pending[c as usize]]);
        let members_error = members().map(|m| m.own_error).fold(0.0, f32::max);
        let owned = match settings.error_bound {
            ErrorBound::Measured => merge_owned(members().map(|m| m.owned.as_slice())),
            ErrorBound::Simplifier => Vec::new(),
        };
        let (s, error, found) = match settings.error_bound {
            ErrorBound::Measured => {
                let merged = &input.merged;
                let reference = self.reference(part, merged, &owned, members_error, lenient);
                let inputs = (&merged[..], &input.masks[..]);
                let m = measure_simplified(mesh, inputs, s, &reference, locks, settings, part_size);
                (m.simplified, m.error, m.found)
            }
            ErrorBound::Simplifier => {
                let error = s.error;
                (s, error, Vec::new())
            }
        };
        let indices = split(&s.indices, &mesh.positions, settings.max_triangles as usize / 4, settings);
        let open = open::mark(mesh, &indices, &s.needed);
        let (owned, found) = without_vanished(owned, found);
        let owned = if owned.is_empty() {
            vec![Vec::new(); indices.len()]
        } else if part.len() == self.pending.len() && one_group(indices.len(), settings.group_size as usize) {
            // The level's only group, whose children will all form the next level's only
            // group: handing its samples down to them only to join them again is spared.
            keep_together(mesh, owned, s.indices.len() / 3, (error, part_size), indices.len())
        } else {
            assign_owned(mesh, &owned, (&s.indices, &found), &indices, (error, part_size))
        };
        let children = indices
            .into_iter()
            .zip(open)
            .zip(owned)
            .map(|((indices, open), owned)| Child { indices, open, owned })
            .collect();
        Simplified { children, error, method: s.method }
    }

    /// What a part's result is measured against: the level-0 triangles under it (`owned`,
    /// errors 0: nothing adds up), or where those are not at hand (a later shard stage) its
    /// members' triangles (`merged`), each with its member's error. Where the level-0 samples
    /// are at hand, a part may own none (every one vanished: its parts are smaller than the
    /// error, which they can raise no more): its result is then measured against the original
    /// surface only. (Measured against its members instead, each with its error, the top
    /// groups of 250 boxes added up their errors level by level: 1.5 to 7.4 where the
    /// boxes' size, 1.5, bounds every vanished point.)
    fn reference<'r>(
        &'r self,
        part: &[u32],
        merged: &'r [u32],
        owned: &'r [Owned],
        members_error: f32,
        lenient: bool,
    ) -> Reference<'r> {
        if self.original.is_none() {
            let members = part.iter().map(|&c| &self.clusters[self.pending[c as usize]]);
            let errors = members.flat_map(|m| std::iter::repeat_n(m.own_error, m.indices.len() / 3)).collect();
            let triangles = Cow::Borrowed(merged);
            Reference { triangles, errors, owned: None, members_error, original: None, lenient }
        } else {
            let errors = vec![0.0; owned.len()];
            let triangles = Cow::Owned(owned.par_iter().with_min_len(4096).flat_map_iter(|o| o.corners()).collect());
            let original = self.original.as_ref();
            Reference { triangles, errors, owned: Some(owned), members_error, original, lenient }
        }
    }

    /// Makes each simplified part a group whose children are pending next; a stuck part's
    /// clusters stay pending. Returns whether any part was simplified.
    fn adopt(&mut self, parts: &[Vec<u32>], results: Vec<Option<Simplified>>) -> bool {
        let clusters = &mut self.clusters;
        let mut next = Vec::new();
        let mut progressed = false;
        for (part, result) in parts.iter().zip(results) {
            let members: Vec<usize> = part.iter().map(|&c| self.pending[c as usize]).collect();
            let Some(Simplified { children, error, method, .. }) = result else {
                self.stats.stuck_groups += 1;
                next.extend_from_slice(&members);
                continue;
            };
            progressed = true;
            self.stats.methods[method as usize] += 1;
            let id = LOCAL | self.groups.len() as u32;
            let sphere = enclosing_sphere(members.iter().map(|&c| clusters[c].own_sphere));
            let error = members.iter().map(|&c| clusters[c].own_error).fold(error, f32::max);
            self.groups.push(BuiltGroup { sphere, error, level: self.level });
            for &c in &members {
                clusters[c].group = id;
                clusters[c].owned = Vec::new();
            }
            self.grouped.extend_from_slice(&members);
            for Child { indices, open, owned } in children {
                next.push(clusters.len());
                let (own_sphere, own_error, group) = (sphere, error, NO_GROUP);
                clusters.push(BuiltCluster { indices, own_group: id, own_sphere, own_error, group, open, owned });
            }
        }
        next.sort_unstable();
        self.pending = next;
        progressed
    }

    /// Makes the pending clusters the root group(s): whatever could not be simplified further.
    /// Error +inf: always drawn when nothing coarser exists.
    pub fn make_roots(&mut self) {
        let pending = std::mem::take(&mut self.pending);
        let roots: Vec<Vec<usize>> = if pending.len() <= MAX_ROOT_CLUSTERS {
            vec![pending.clone()]
        } else {
            let refs: Vec<&[u32]> = pending.iter().map(|&c| self.clusters[c].indices.as_slice()).collect();
            let centers: Vec<[f32; 3]> = pending.iter().map(|&c| self.clusters[c].own_sphere.center).collect();
            let graph = cluster_graph(&refs, &self.mesh.position_ids, &centers);
            partition(&graph, self.settings.group_size as usize)
                .into_iter()
                .map(|p| p.into_iter().map(|c| pending[c as usize]).collect())
                .collect()
        };
        self.stats.root_groups = roots.len() as u64;
        self.stats.root_clusters = pending.len() as u64;
        for members in roots {
            let id = LOCAL | self.groups.len() as u32;
            let sphere = enclosing_sphere(members.iter().map(|&c| self.clusters[c].own_sphere));
            let level = self.level;
            self.groups.push(BuiltGroup { sphere, error: f32::INFINITY, level });
            for &c in &members {
                self.clusters[c].group = id;
            }
        }
    }

    /// Builds levels until nothing is left to group, then makes the root group(s).
    pub fn build_to_root<O: DagOutput>(
        &mut self,
        progress: Progress,
        output: &O,
        converted: &mut Converted<O::Cluster>,
    ) {
        while self.step(progress, output, converted) {}
        self.make_roots();
    }

    /// Hands the clusters that got a group to `output` (in creation order) and keeps the
    /// pending ones as top clusters, on the grid.
    pub fn finish<O: DagOutput>(
        self,
        output: &O,
        converted: Converted<O::Cluster>,
    ) -> Result<Cell<O::Cluster>, BakeError> {
        let mut is_top = vec![false; self.clusters.len()];
        for &c in &self.pending {
            is_top[c] = true;
        }
        let top = self.pending.iter().map(|&c| TopCluster::new(self.mesh, &self.clusters[c])).collect();
        let finished: Vec<usize> = (0..self.clusters.len()).filter(|&c| !is_top[c]).collect();
        Ok(Cell {
            groups: self.groups,
            finished: converted.take(output, self.mesh, &self.clusters, &finished)?,
            top,
            levels: self.level,
            stats: self.stats,
            triangles: 0,
            welded_vertices: 0,
            degenerate: 0,
        })
    }
}

/// Triangles per chunk of the level-0 split: chunks are clustered in parallel.
const LEVEL0_CHUNK: usize = 128 * 512;

/// Level-0 clusters: triangles in `order` (Morton order of their centroids, [`triangle_order`]) cut into chunks
/// of [`LEVEL0_CHUNK`] triangles, each split by the meshlet builder on its own thread (one call
/// on the whole mesh would run on one core). Only each chunk's last cluster can be partial.
fn level0_clusters(mesh: &WeldedMesh, settings: &BakeSettings, order: &[u32]) -> Vec<Vec<u32>> {
    order
        .par_chunks(LEVEL0_CHUNK)
        .flat_map_iter(|chunk| {
            let indices: Vec<u32> =
                chunk.iter().flat_map(|&t| mesh.indices[t as usize * 3..t as usize * 3 + 3].iter().copied()).collect();
            split(&indices, &mesh.positions, settings.max_triangles as usize, settings)
        })
        .collect()
}

/// Per position id, whether it stays locked at every level of this builder: the ends of the
/// edges the pending `clusters` use an odd number of times unmarked (a shard or cell border:
/// the neighbouring cell holds the other side). Non-manifold edges (used three or more times)
/// are not locked: they simplify like any other edge, as meshoptimizer classifies their
/// vertices (locked until a group was stuck, they held the coarse levels of meshes with fins
/// or duplicate faces at 2-3 times the error of a discrete LOD chain: docs/BENCHMARKS.md).
fn cell_borders(mesh: &WeldedMesh, clusters: &[BuiltCluster]) -> Vec<bool> {
    let id = |v: u32| mesh.position_ids[v as usize];
    let (mut edges, mut marked): (Vec<u64>, Vec<u64>) = clusters
        .par_iter()
        // Unsorted per cluster: the joined list is sorted once.
        .map(|c| (edge_keys(&c.indices, id), open::marked_edges(mesh, &c.indices, &c.open)))
        .reduce(
            || (Vec::new(), Vec::new()),
            |mut a, b| {
                a.0.extend(b.0);
                a.1.extend(b.1);
                a
            },
        );
    edges.par_sort_unstable();
    marked.par_sort_unstable();
    let mut border = vec![false; mesh.position_count];
    for run in edges.chunk_by(|a, b| a == b) {
        if (run.len() - open::count(&marked, run[0])) % 2 == 1 {
            for p in edge_ends(run[0]) {
                border[p as usize] = true;
            }
        }
    }
    border
}

/// The sorted edge keys of a whole welded mesh (position ids), sorted once for what level 0
/// needs of them: its odd (open) edges and its non-manifold ones.
pub(crate) struct Level0Edges {
    keys: Vec<u64>,
}

impl Level0Edges {
    /// The edges of `mesh`'s triangles.
    pub fn new(mesh: &WeldedMesh) -> Level0Edges {
        Level0Edges { keys: sorted_edge_keys(&mesh.indices, |v| mesh.position_ids[v as usize]) }
    }

    /// The edge keys, sorted (an edge used n times n times).
    pub fn sorted(&self) -> &[u64] {
        &self.keys
    }

    /// The edges used an odd number of times (the open ones), sorted: what the level-0
    /// clusters mark (see [`crate::open::mark`]).
    pub fn odd(&self) -> Vec<u64> {
        open::odd_of(&self.keys)
    }

    /// The edges used three times or more, sorted.
    pub fn non_manifold(&self) -> Vec<u64> {
        self.keys.chunk_by(|a, b| a == b).filter(|r| r.len() >= 3).map(|r| r[0]).collect()
    }
}

/// The groups of `clusters` for one level: METIS on their graph (see [`crate::partition`]),
/// as lists of indices into `clusters`.
pub(crate) fn groups<'c>(
    mesh: &WeldedMesh,
    clusters: impl Iterator<Item = &'c BuiltCluster> + Clone,
    settings: &BakeSettings,
) -> Vec<Vec<u32>> {
    let refs: Vec<&[u32]> = clusters.clone().map(|c| c.indices.as_slice()).collect();
    let centers: Vec<[f32; 3]> = clusters.map(|c| c.own_sphere.center).collect();
    let graph = cluster_graph(&refs, &mesh.position_ids, &centers);
    partition(&graph, settings.group_size as usize)
}

/// Per position id, the group of `parts` (lists of indices into `refs`, the clusters'
/// triangles) that uses it, [`SHARED`] where two or more do, `u32::MAX` where none does. Groups
/// mark their positions side by side: a position's final mark does not depend on the order
/// (a second group's mark makes it shared, and shared stays).
fn owners(mesh: &WeldedMesh, parts: &[Vec<u32>], refs: &[&[u32]]) -> Vec<AtomicU32> {
    let owner: Vec<AtomicU32> = (0..mesh.position_count).map(|_| AtomicU32::new(u32::MAX)).collect();
    parts.par_iter().enumerate().for_each(|(g, part)| {
        let g = g as u32;
        for &v in part.iter().flat_map(|&c| refs[c as usize]) {
            let o = &owner[mesh.position_ids[v as usize] as usize];
            let mark = |now: u32| (now != g && now != SHARED).then_some(if now == u32::MAX { g } else { SHARED });
            // A failed exchange re-reads the mark; it ends at `g` or SHARED.
            let _ = o.fetch_update(Relaxed, Relaxed, mark);
        }
    });
    owner
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::weld::weld;
    use mres_geom::edges::edge_key;
    use mres_import::SourceMesh;

    /// A strip of quads (open rim) with a fin: a third triangle on one inner edge.
    fn finned_strip() -> WeldedMesh {
        let mut positions = Vec::new();
        for x in 0..6 {
            positions.extend([[x as f32, 0.0, 0.0], [x as f32, 1.0, 0.0]]);
        }
        positions.push([2.0, 0.5, 1.0]);
        let mut indices = Vec::new();
        for x in 0..5u32 {
            let (a, b, c, d) = (2 * x, 2 * x + 2, 2 * x + 3, 2 * x + 1);
            indices.extend([a, b, c, a, c, d]);
        }
        indices.extend([4, 5, 12]);
        weld(&SourceMesh::positions_only(positions, indices), &BakeSettings::default()).unwrap()
    }

    /// Two separate grids of quads far apart, of 128 triangles each: 8 × 4 quads where every
    /// triangle is there twice (every edge is non-manifold), and 8 × 8 quads.
    fn grid_and_doubled_grid() -> WeldedMesh {
        let (mut positions, mut indices) = (Vec::new(), Vec::new());
        for (g, (x0, rows)) in [(0.0f32, 4u32), (100.0, 8)].into_iter().enumerate() {
            let base = positions.len() as u32;
            for y in 0..=rows {
                for x in 0..9 {
                    // A gentle bump, so that collapses have a cost.
                    let z = ((x as f32 - 4.0).powi(2) + (y as f32 - 4.0).powi(2)) * 0.01;
                    positions.push([x0 + x as f32, y as f32, z]);
                }
            }
            for y in 0..rows {
                for x in 0..8u32 {
                    let v = |dx: u32, dy: u32| base + (y + dy) * 9 + x + dx;
                    for t in [[v(0, 0), v(1, 0), v(1, 1)], [v(0, 0), v(1, 1), v(0, 1)]] {
                        indices.extend(t);
                        if g == 0 {
                            indices.extend(t);
                        }
                    }
                }
            }
        }
        weld(&SourceMesh::positions_only(positions, indices), &BakeSettings::default()).unwrap()
    }

    #[test]
    fn groups_with_non_manifold_edges_simplify_in_their_first_run() {
        // The doubled grid's every edge is non-manifold: locked, it was stuck (None) in the
        // first run and simplified only in the stuck groups' lenient retry.
        let mesh = grid_and_doubled_grid();
        let settings = BakeSettings::default();
        let edges = Level0Edges::new(&mesh);
        let clusters = level0(&mesh, &settings, (&edges, &edges.odd()), &triangle_order(&mesh));
        let doubled = |c: &BuiltCluster| mesh.positions[c.indices[0] as usize][0] < 10.0;
        let parts: Vec<Vec<u32>> = [true, false]
            .map(|d| (0..clusters.len() as u32).filter(|&c| doubled(&clusters[c as usize]) == d).collect())
            .into();
        assert_eq!(parts, vec![vec![0], vec![1]], "one level-0 cluster per grid");
        let builder = Builder::new(&mesh, &settings, clusters, 0);
        let refs: Vec<&[u32]> = builder.clusters.iter().map(|c| c.indices.as_slice()).collect();
        let level = LevelLocks::new(&mesh, &builder.cell_border, &parts, &refs);
        let inputs: Vec<PartInput> = parts.iter().map(|part| builder.part_input(part, &refs)).collect();
        for (g, kept) in builder.simplify_rounds(&level, &inputs, false).iter().enumerate() {
            let (simplified, lenient) = kept.as_ref().unwrap_or_else(|| panic!("group {g} is stuck"));
            assert!(!lenient, "group {g} simplified only in the stuck groups' retry");
            let kept = simplified.indices.len() / 3;
            assert!(kept * 4 <= 128 * 3, "group {g}: {kept} of 128 triangles kept");
        }
    }

    #[test]
    fn a_whole_mesh_level_0_has_no_cell_border_and_an_unmarked_open_edge_makes_one() {
        let mesh = finned_strip();
        let edges = Level0Edges::new(&mesh);
        let clusters = level0(&mesh, &BakeSettings::default(), (&edges, &edges.odd()), &triangle_order(&mesh));
        // The fin's non-manifold edge locks nothing; every odd edge is marked once.
        assert!(cell_borders(&mesh, &clusters).iter().all(|&b| !b));
        let mut unmarked = clusters.clone();
        unmarked[0].open.iter_mut().for_each(|m| *m = 0);
        assert!(cell_borders(&mesh, &unmarked).iter().any(|&b| b));
    }

    #[test]
    fn positions_of_two_groups_are_shared_on_any_thread_count() {
        let mesh = finned_strip();
        let id = |x: usize, y: usize| {
            mesh.position_ids[mesh.positions.iter().position(|p| *p == [x as f32, y as f32, 0.0]).unwrap()]
        };
        // Clusters: the strip's quads one by one (two triangles each) and the fin.
        let quads: Vec<&[u32]> = mesh.indices.chunks(6).collect();
        let parts = vec![vec![0, 1], vec![2], vec![3, 4, 5]];
        let expected = |owner: &[AtomicU32]| {
            let mark = |p: u32| owner[p as usize].load(Relaxed);
            // Column 1 is inside group 0, columns 2 and 3 are group borders.
            assert_eq!((mark(id(1, 0)), mark(id(1, 1))), (0, 0));
            assert_eq!((mark(id(2, 0)), mark(id(3, 1))), (SHARED, SHARED));
            assert_eq!((mark(id(5, 0)), mark(id(0, 1))), (2, 0));
            owner.iter().map(|o| o.load(Relaxed)).collect::<Vec<_>>()
        };
        let marks: Vec<Vec<u32>> = [1, 3]
            .map(|threads| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                expected(&pool.install(|| owners(&mesh, &parts, &quads)))
            })
            .into();
        assert_eq!(marks[0], marks[1]);
        assert!(marks[0].iter().all(|&m| m != u32::MAX), "every position is used");
    }

    #[test]
    fn shared_samples_go_to_their_first_triangle() {
        let mesh = finned_strip();
        let id = |v: u32| mesh.position_ids[v as usize];
        // The serial rule: the first triangle in cluster order that uses a position or edge.
        let reference = |clusters: &[Vec<u32>]| -> Vec<Vec<u8>> {
            let (mut corners, mut edges) = (std::collections::HashSet::new(), std::collections::HashSet::new());
            let mut bits = |t: &[u32]| {
                (0..3).fold(CENTROID, |b, k| {
                    let corner = u8::from(corners.insert(id(t[k]))) << k;
                    let edge = u8::from(edges.insert(edge_key(id(t[k]), id(t[(k + 1) % 3])))) << (3 + k);
                    b | corner | edge
                })
            };
            clusters.iter().map(|c| c.chunks_exact(3).map(&mut bits).collect()).collect()
        };
        let quads: Vec<&[u32]> = mesh.indices.chunks(6).collect();
        let edges = Level0Edges::new(&mesh);
        // The fin's edge is used by quads 1 and 2 as well: a cluster holding both uses only
        // must leave it to the fin's earlier cluster; the other clusters share borders.
        let fin = quads[5].to_vec();
        let splits = [
            vec![fin.clone(), [&quads[1][..3], &quads[2][3..]].concat(), [quads[0], quads[3], quads[4]].concat()],
            vec![quads[0..5].concat(), fin.clone()],
            vec![quads[4].to_vec(), quads[2].to_vec(), fin, quads[0].to_vec(), quads[1].to_vec(), quads[3].to_vec()],
        ];
        for clusters in &splits {
            let got = first_samples(&mesh, clusters, &edges.non_manifold());
            assert_eq!(got, reference(clusters));
            let owned = |bit: u8| got.iter().flatten().filter(|&&b| b & bit != 0).count();
            assert_eq!(owned(1) + owned(2) + owned(4), mesh.position_count);
        }
    }
}
