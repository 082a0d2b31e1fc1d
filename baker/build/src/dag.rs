//! The builder's own DAG: groups and clusters as the level loop makes them, in welded vertex
//! ids, and the [`DagOutput`] that receives them (the `.mres` writer's adapter is `encode`).
//!
//! Errors and spheres are made monotone while building: a group's error is the max of its
//! simplification error and its members' own errors, and its sphere encloses its members'
//! own spheres (docs/INVARIANTS.md §2).

use crate::error::BakeError;
use crate::weld::{GridMesh, WeldedMesh};
use mres_format::{Grid, Sphere, UvQuant, NO_GROUP};
use rayon::prelude::*;

/// One group of the DAG.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuiltGroup {
    /// Encloses the spheres of its members (and so of everything below them).
    pub sphere: Sphere,
    /// Object-space error of the clusters it produced (+inf for a root group).
    pub error: f32,
    /// Simplification level: 0 for groups of level-0 clusters.
    pub level: u32,
}

/// One cluster while building, in the vertex ids of the welded mesh it was built on.
#[derive(Clone, Debug)]
pub struct BuiltCluster {
    /// Triangle list into the welded mesh's vertices.
    pub indices: Vec<u32>,
    /// The group that produced it, or `NO_GROUP`.
    pub own_group: u32,
    /// Own sphere: cluster bounds at level 0, the producing group's sphere above.
    pub own_sphere: Sphere,
    /// Own error: 0 at level 0, the producing group's error above.
    pub own_error: f32,
    /// The group it belongs to (assigned when its group is simplified or made root).
    pub group: u32,
    /// Open-border marks, one 3-bit mask per triangle (see [`crate::open`]).
    pub open: Vec<u8>,
    /// The level-0 sample points this cluster stands for, while the builder measures errors
    /// against the original surface (see [`crate::samples`]); emptied once grouped.
    pub owned: Vec<crate::samples::Owned>,
}

/// Receives the finished clusters of each welded mesh the DAG is built on, while that mesh
/// is still alive (the idea of meshoptimizer clusterlod's `clodOutput` callback): a sharded
/// build frees each shard's mesh once its clusters are handed over, so what the output keeps
/// sets the build's memory. Group ids in a batch are local to it until [`DagOutput::append`].
pub trait DagOutput: Sync {
    /// One finished cluster, converted.
    type Cluster: Send;
    /// Converts `cluster` (with its group set) of `mesh`, cluster `index` of its level loop
    /// (for errors); called from any thread, while the loop goes on (see `Converted`).
    fn convert(&self, mesh: &WeldedMesh, cluster: &BuiltCluster, index: usize) -> Result<Self::Cluster, BakeError>;
    /// Takes a converted batch in, mapping its group ids to the DAG's with `global`.
    fn append(&mut self, clusters: Vec<Self::Cluster>, global: &dyn Fn(u32) -> u32);
}

/// The clusters of one level loop converted by a [`DagOutput`] as they are finished. A
/// cluster is finished once its group is formed; the loop hands each level's newly grouped
/// clusters over beside the next level's partition, whose METIS calls run on one thread
/// (`levels::Builder::step`), so the conversion fills a core that would wait instead
/// of running after the last level. The rest are converted at the end ([`Converted::take`]).
pub(crate) struct Converted<C> {
    /// Per cluster index of the loop, its conversion where done.
    by_cluster: Vec<Option<C>>,
    /// The first conversion that failed, in the order they were handed over.
    error: Option<BakeError>,
}

impl<C: Send> Converted<C> {
    pub fn new() -> Self {
        Converted { by_cluster: Vec::new(), error: None }
    }

    /// Converts the clusters `batch` (indices into `clusters`, each grouped) of `mesh`, in
    /// parallel.
    pub fn convert<O: DagOutput<Cluster = C>>(
        &mut self,
        output: &O,
        mesh: &WeldedMesh,
        clusters: &[BuiltCluster],
        batch: &[usize],
    ) {
        let results: Vec<Result<C, BakeError>> =
            batch.par_iter().map(|&c| output.convert(mesh, &clusters[c], c)).collect();
        if let Some(&last) = batch.iter().max() {
            if self.by_cluster.len() <= last {
                self.by_cluster.resize_with(last + 1, || None);
            }
        }
        for (&c, result) in batch.iter().zip(results) {
            match result {
                Ok(converted) => self.by_cluster[c] = Some(converted),
                Err(e) => {
                    self.error.get_or_insert(e);
                }
            }
        }
    }

    /// The clusters `finished` (ascending indices into `clusters`) converted, in that order:
    /// those converted already, and the rest now; the first error of any conversion.
    pub fn take<O: DagOutput<Cluster = C>>(
        mut self,
        output: &O,
        mesh: &WeldedMesh,
        clusters: &[BuiltCluster],
        finished: &[usize],
    ) -> Result<Vec<C>, BakeError> {
        let missing: Vec<usize> =
            finished.iter().copied().filter(|&c| self.by_cluster.get(c).is_none_or(Option::is_none)).collect();
        self.convert(output, mesh, clusters, &missing);
        if let Some(e) = self.error {
            return Err(e);
        }
        let mut by_cluster = self.by_cluster;
        Ok(finished.iter().map(|&c| by_cluster[c].take().expect("converted above")).collect())
    }
}

/// Quantization and attributes shared by every cluster of a DAG.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    /// The position grid.
    pub grid: Grid,
    /// The UV quantization.
    pub uv: UvQuant,
    /// Whether vertices have normals.
    pub normals: bool,
    /// Whether vertices have UVs.
    pub uvs: bool,
    /// Whether more than one material occurs.
    pub multi_material: bool,
}

impl Frame {
    /// The frame of a welded mesh.
    pub fn of(mesh: &WeldedMesh) -> Frame {
        Frame {
            grid: mesh.grid,
            uv: mesh.uv,
            normals: mesh.normals.is_some(),
            uvs: mesh.uvs.is_some(),
            multi_material: mesh.multi_material,
        }
    }
}

/// A built DAG: its groups in id order, its clusters as `O` keeps them, and figures.
pub struct BuiltDag<O> {
    /// Quantization and attributes.
    pub frame: Frame,
    /// Every group; a cluster's group ids index this.
    pub groups: Vec<BuiltGroup>,
    /// Every cluster, as the output converted them.
    pub clusters: O,
    /// Input triangles: the source's triangles after triangulation, the ones dropped as
    /// degenerate (by the importer or later) included; the file header records this.
    pub source_triangles: u64,
    /// Triangles dropped as degenerate (importer, spilling and grid welding).
    pub degenerate_dropped: u64,
    /// Welded vertices (a sharded build counts shard-border vertices in each shard).
    pub welded_vertices: u64,
    /// Figures about the build.
    pub stats: BuildStats,
}

/// Figures about one build, for reports.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct BuildStats {
    /// Groups simplified with each method: regular, permissive, prune, sloppy.
    pub methods: [u64; 4],
    /// Groups whose simplification got stuck (their clusters waited for the next level).
    pub stuck_groups: u64,
    /// Number of root groups (1 unless the coarsest level is larger than `MAX_ROOT_CLUSTERS`).
    pub root_groups: u64,
    /// Clusters in the root group(s).
    pub root_clusters: u64,
    /// Shards the mesh was split into (0: built whole).
    pub shards: u64,
    /// Wall seconds per stage: level-0 clusters, all simplification levels, encoding.
    pub stage_seconds: Vec<(String, f64)>,
}

impl BuildStats {
    /// Adds another build's counters (not its stage times).
    pub(crate) fn add(&mut self, other: &BuildStats) {
        for (a, b) in self.methods.iter_mut().zip(other.methods) {
            *a += b;
        }
        self.stuck_groups += other.stuck_groups;
        self.root_groups += other.root_groups;
        self.root_clusters += other.root_clusters;
    }
}

/// Times the stages of a build into [`BuildStats::stage_seconds`].
pub(crate) struct StageClock(std::time::Instant);

impl StageClock {
    pub fn start() -> StageClock {
        StageClock(std::time::Instant::now())
    }

    /// Records the time since the previous lap (or the start) as `stage`.
    pub fn lap(&mut self, stats: &mut BuildStats, stage: &str) {
        stats.stage_seconds.push((stage.to_string(), self.0.elapsed().as_secs_f64()));
        self.0 = std::time::Instant::now();
    }
}

/// A cluster left without a group when its mesh is done (a shard's coarsest), carried into
/// the next mesh on the grid: its vertices are welded there by their integer grid points.
pub struct TopCluster {
    /// Its vertices (first-use order) and triangles.
    pub mesh: GridMesh,
    /// The group that produced it, or `NO_GROUP`.
    pub own_group: u32,
    /// Own sphere.
    pub own_sphere: Sphere,
    /// Own error.
    pub own_error: f32,
    /// Open-border marks per triangle.
    pub open: Vec<u8>,
}

impl TopCluster {
    /// `cluster` of `mesh`, with its vertices in first-use order.
    pub fn new(mesh: &WeldedMesh, cluster: &BuiltCluster) -> TopCluster {
        let (vertices, local) = meshopt::extract_meshlet_indices(&cluster.indices);
        let local = local.into_iter().map(u32::from).collect();
        TopCluster {
            mesh: GridMesh::extract(mesh, &vertices, local),
            own_group: cluster.own_group,
            own_sphere: cluster.own_sphere,
            own_error: cluster.own_error,
            open: cluster.open.clone(),
        }
    }

    /// Its triangle count.
    pub fn triangles(&self) -> u64 {
        self.mesh.indices.len() as u64 / 3
    }
}

/// Group ids a mesh's level loop assigns are local until its [`Cell`] is collected: this bit
/// marks them (ids without it are global already).
pub(crate) const LOCAL: u32 = 1 << 31;

/// What the level loop leaves on one welded mesh (a whole mesh, a shard or a later cell).
pub(crate) struct Cell<C> {
    /// New groups; the group `LOCAL | i` is `groups[i]`.
    pub groups: Vec<BuiltGroup>,
    /// Finished clusters, converted by the output.
    pub finished: Vec<C>,
    /// Clusters without a group yet.
    pub top: Vec<TopCluster>,
    /// The level the next groups get.
    pub levels: u32,
    pub stats: BuildStats,
    /// Triangles it was built from (shards only).
    pub triangles: u64,
    pub welded_vertices: u64,
    pub degenerate: u64,
}

/// The groups and clusters collected so far, under global ids.
pub(crate) struct Collected<O> {
    pub groups: Vec<BuiltGroup>,
    pub output: O,
    /// The highest level reached by any cell so far.
    pub level: u32,
    pub welded_vertices: u64,
    pub degenerate: u64,
}

impl<O: DagOutput> Collected<O> {
    pub fn new(output: O) -> Self {
        Collected { groups: Vec::new(), output, level: 0, welded_vertices: 0, degenerate: 0 }
    }

    /// Takes the cells in order, giving their local groups global ids; returns their top
    /// clusters.
    pub fn collect(&mut self, cells: Vec<Cell<O::Cluster>>, stats: &mut BuildStats) -> Vec<TopCluster> {
        let mut top = Vec::new();
        for cell in cells {
            let offset = self.groups.len() as u32;
            let global = |g: u32| if g != NO_GROUP && g & LOCAL != 0 { (g & !LOCAL) + offset } else { g };
            self.groups.extend(cell.groups);
            self.output.append(cell.finished, &global);
            top.extend(cell.top.into_iter().map(|t| TopCluster { own_group: global(t.own_group), ..t }));
            stats.add(&cell.stats);
            self.welded_vertices += cell.welded_vertices;
            self.degenerate += cell.degenerate;
            self.level = self.level.max(cell.levels);
        }
        top
    }

    /// The DAG collected, with the figures its builder adds.
    pub fn finish(self, frame: Frame, source_triangles: u64, stats: BuildStats) -> BuiltDag<O> {
        BuiltDag {
            frame,
            groups: self.groups,
            clusters: self.output,
            source_triangles,
            degenerate_dropped: self.degenerate,
            welded_vertices: self.welded_vertices,
            stats,
        }
    }
}
