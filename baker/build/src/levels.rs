//! The level loop on one welded mesh: level-0 clusters, then repeatedly group (METIS),
//! simplify each group in parallel with its border locked, and split the result into parent
//! clusters (docs/ARCHITECTURE.md "Data flow of one bake").
//!
//! The result is independent of the rayon thread count: groups are simplified in parallel but
//! collected in partition order.

use crate::cluster::{bounding_sphere, enclosing_sphere, split};
use crate::dag::{BuildStats, BuiltCluster, BuiltGroup, Cell, DagOutput, TopCluster, LOCAL};
use crate::deviation::{part_sizes, simplify_measured};
use crate::error::BakeError;
use crate::partition::{cluster_graph, partition};
use crate::progress::Progress;
use crate::settings::{BakeSettings, ErrorBound};
use crate::simplify::{simplify_group, Method};
use crate::weld::WeldedMesh;
use mres_format::NO_GROUP;
use mres_geom::edges::sorted_edge_keys;
use rayon::prelude::*;

/// Most clusters the final root group may hold. A mesh whose coarsest clusters cannot be
/// simplified further (an open boundary is locked in every cut) ends in one root group of up
/// to this many clusters; beyond it, several root groups are formed and reported.
pub const MAX_ROOT_CLUSTERS: usize = 256;
/// Safety stop on the number of levels.
const MAX_LEVELS: u32 = 64;

/// One simplified group: its triangles split into parent clusters, its error, the method used.
type Simplified = (Vec<Vec<u32>>, f32, Method);

/// Level-0 clusters of a welded mesh, with their own bounds.
pub(crate) fn level0(mesh: &WeldedMesh, settings: &BakeSettings) -> Vec<BuiltCluster> {
    level0_clusters(mesh, settings)
        .into_par_iter()
        .map(|indices| {
            let own_sphere = bounding_sphere(&indices, &mesh.positions);
            BuiltCluster { indices, own_group: NO_GROUP, own_sphere, own_error: 0.0, group: NO_GROUP }
        })
        .collect()
}

/// The level loop over one welded mesh: group the pending clusters, simplify each group with
/// its border locked, split the results into the next level's clusters.
pub(crate) struct Builder<'a> {
    mesh: &'a WeldedMesh,
    settings: &'a BakeSettings,
    /// Per position id: on an open or non-manifold edge of this mesh, so locked at every level.
    always_locked: Vec<bool>,
    /// Open and non-manifold edges with their use counts (see `open_and_nonmanifold`).
    special: Vec<(u64, u32)>,
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
}

impl<'a> Builder<'a> {
    /// A builder whose pending clusters are `clusters` (triangles into `mesh`); new groups
    /// start at `level`.
    pub fn new(mesh: &'a WeldedMesh, settings: &'a BakeSettings, clusters: Vec<BuiltCluster>, level: u32) -> Self {
        let (always_locked, special) = open_and_nonmanifold(mesh);
        let part_size = match settings.error_bound {
            ErrorBound::Measured => part_sizes(mesh),
            ErrorBound::Simplifier => Vec::new(),
        };
        let pending = (0..clusters.len()).collect();
        let stats = BuildStats::default();
        Builder {
            mesh,
            settings,
            always_locked,
            special,
            part_size,
            clusters,
            groups: Vec::new(),
            pending,
            level,
            stats,
        }
    }

    /// Triangles in the pending clusters.
    pub fn pending_triangles(&self) -> usize {
        self.pending.iter().map(|&c| self.clusters[c].indices.len() / 3).sum()
    }

    /// Builds one level. Returns false (and changes nothing) when there is nothing left to
    /// group, and false after a level where no group could be simplified.
    pub fn step(&mut self, progress: Progress) -> bool {
        if self.pending.len() <= 1 || self.level >= MAX_LEVELS {
            return false;
        }
        let clusters = &self.clusters;
        let refs: Vec<&[u32]> = self.pending.iter().map(|&c| clusters[c].indices.as_slice()).collect();
        let centers: Vec<[f32; 3]> = self.pending.iter().map(|&c| clusters[c].own_sphere.center).collect();
        let graph = cluster_graph(&refs, &self.mesh.position_ids, &centers);
        let parts = partition(&graph, self.settings.group_size as usize);
        let results = self.simplify_parts(&parts, &refs);
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
    /// parallel, with the positions it shares with other parts locked; `None` where stuck.
    fn simplify_parts(&self, parts: &[Vec<u32>], refs: &[&[u32]]) -> Vec<Option<Simplified>> {
        let (mesh, settings) = (self.mesh, self.settings);
        // Which group uses each position; positions used by two groups are locked.
        let mut owner = vec![u32::MAX; mesh.position_count];
        for (g, part) in parts.iter().enumerate() {
            for &c in part {
                for &v in refs[c as usize] {
                    let o = &mut owner[mesh.position_ids[v as usize] as usize];
                    *o = if *o == u32::MAX || *o == g as u32 { g as u32 } else { u32::MAX - 1 };
                }
            }
        }
        let always_locked = &self.always_locked;
        let locked = |v: u32| {
            let p = mesh.position_ids[v as usize] as usize;
            owner[p] == u32::MAX - 1 || always_locked[p]
        };
        let (special, part_size) = (&self.special, &self.part_size);
        let own_errors: Vec<f32> = self.pending.iter().map(|&c| self.clusters[c].own_error).collect();
        parts
            .par_iter()
            .map(|part| {
                let merged: Vec<u32> = part.iter().flat_map(|&c| refs[c as usize].iter().copied()).collect();
                let (s, error) = match settings.error_bound {
                    ErrorBound::Measured => {
                        // Per input triangle, the own error of the member it came from.
                        let errors: Vec<f32> = part
                            .iter()
                            .flat_map(|&c| std::iter::repeat_n(own_errors[c as usize], refs[c as usize].len() / 3))
                            .collect();
                        simplify_measured(mesh, &merged, &errors, locked, special, settings, part_size)?
                    }
                    ErrorBound::Simplifier => {
                        let s = simplify_group(mesh, &merged, locked, special, settings)?;
                        let error = s.error;
                        (s, error)
                    }
                };
                let children = split(&s.indices, &mesh.positions, settings.max_triangles as usize / 4, settings);
                Some((children, error, s.method))
            })
            .collect()
    }

    /// Makes each simplified part a group whose children are pending next; a stuck part's
    /// clusters stay pending. Returns whether any part was simplified.
    fn adopt(&mut self, parts: &[Vec<u32>], results: Vec<Option<Simplified>>) -> bool {
        let clusters = &mut self.clusters;
        let mut next = Vec::new();
        let mut progressed = false;
        for (part, result) in parts.iter().zip(results) {
            let members: Vec<usize> = part.iter().map(|&c| self.pending[c as usize]).collect();
            let Some((children, error, method)) = result else {
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
            }
            for indices in children {
                next.push(clusters.len());
                let (own_sphere, own_error) = (sphere, error);
                clusters.push(BuiltCluster { indices, own_group: id, own_sphere, own_error, group: NO_GROUP });
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
    pub fn build_to_root(&mut self, progress: Progress) {
        while self.step(progress) {}
        self.make_roots();
    }

    /// Hands the clusters that got a group to `output` (in creation order) and keeps the
    /// pending ones as top clusters, on the grid.
    pub fn finish<O: DagOutput>(self, output: &O) -> Result<Cell<O::Clusters>, BakeError> {
        let mut is_top = vec![false; self.clusters.len()];
        for &c in &self.pending {
            is_top[c] = true;
        }
        let top = self.pending.iter().map(|&c| TopCluster::new(self.mesh, &self.clusters[c])).collect();
        let finished: Vec<BuiltCluster> =
            self.clusters.into_iter().zip(is_top).filter(|(_, top)| !top).map(|(c, _)| c).collect();
        Ok(Cell {
            groups: self.groups,
            finished: output.convert(self.mesh, &finished)?,
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

/// Level-0 clusters: triangles sorted by the Morton code of their centroid and cut into chunks
/// of [`LEVEL0_CHUNK`] triangles, each split by the meshlet builder on its own thread (one call
/// on the whole mesh would run on one core). Only each chunk's last cluster can be partial.
fn level0_clusters(mesh: &WeldedMesh, settings: &BakeSettings) -> Vec<Vec<u32>> {
    let centroids: Vec<[f32; 3]> = mesh
        .indices
        .par_chunks_exact(3)
        .map(|t| {
            let p = t.iter().map(|&v| mesh.positions[v as usize]);
            p.fold([0.0; 3], |a, b| [a[0] + b[0] / 3.0, a[1] + b[1] / 3.0, a[2] + b[2] / 3.0])
        })
        .collect();
    let codes = crate::partition::morton_codes(&centroids);
    drop(centroids);
    let mut order: Vec<(u32, u32)> = codes.into_iter().enumerate().map(|(t, code)| (code, t as u32)).collect();
    order.par_sort_unstable();
    order
        .par_chunks(LEVEL0_CHUNK)
        .flat_map_iter(|chunk| {
            let indices: Vec<u32> = chunk
                .iter()
                .flat_map(|&(_, t)| mesh.indices[t as usize * 3..t as usize * 3 + 3].iter().copied())
                .collect();
            split(&indices, &mesh.positions, settings.max_triangles as usize, settings)
        })
        .collect()
}

/// The original's open (used once) and non-manifold (used 3+ times) edges, with their use
/// counts, sorted; and per position whether it lies on one. Those positions stay locked at
/// every level so that every cut has exactly the original's boundary.
fn open_and_nonmanifold(mesh: &WeldedMesh) -> (Vec<bool>, Vec<(u64, u32)>) {
    let mut edges: Vec<u64> = mesh
        .indices
        .par_chunks(3 * 4096)
        .flat_map_iter(|c| sorted_edge_keys(c, |v| mesh.position_ids[v as usize]))
        .collect();
    edges.par_sort_unstable();
    let mut locked = vec![false; mesh.position_count];
    let mut special = Vec::new();
    for run in edges.chunk_by(|a, b| a == b) {
        if run.len() != 2 {
            locked[(run[0] >> 32) as usize] = true;
            locked[(run[0] & 0xffff_ffff) as usize] = true;
            special.push((run[0], run.len() as u32));
        }
    }
    (locked, special)
}
