//! Sharding: a mesh with more than `shard_triangles` triangles is split spatially into shards
//! that are built one by one (in parallel as threads allow), then merged in the upper levels
//! into one DAG with one root (DESIGN.md pipeline: "shard if large (spatial, borders locked)").
//!
//! 1. **Cells.** A k-d tree over (a sample of) the vertex positions, split at medians along
//!    the longest axis until a cell holds about `shard_triangles` triangles' worth of vertices.
//! 2. **Spill.** The triangles are streamed (from the OBJ file itself for a streamed import,
//!    see `mres_import::obj_stream`) and each is appended to its cell's spill file in a
//!    temporary directory, by centroid. Only the vertex attributes stay in memory.
//! 3. **Shards.** Each shard is read back, welded on the whole mesh's grid (so that shards
//!    meet exactly) and built level by level like a whole mesh. Its edges on the shard border
//!    are open in the shard, so they are locked at every shard level like any open edge. A
//!    shard stops when a level removes less than [`SHARD_STOP_REDUCTION`] of its triangles
//!    (what is left is mostly the locked border band) or it is down to a few groups. Its
//!    finished clusters are encoded right away (compact); its top clusters are kept.
//! 4. **Merge.** The top clusters of all shards are welded into one small mesh, where the shard
//!    borders are ordinary interior edges, and the level loop goes on to one root. So no edge
//!    stays locked for good: a shard border is simplified in the first merged levels.
//!
//! Peak memory is the vertex attributes (12–32 bytes per vertex), the encoded clusters (about
//! the size of the output), and the working set of the shards being built — not the whole
//! mesh's build. Output is deterministic: cells, spill order and shard results depend only on
//! the input and the settings, never on the thread count.

use crate::dag::{header, level0, to_dag_cluster, BuildStats, Builder, Cluster, StageClock};
use crate::error::BakeError;
use crate::progress::Progress;
use crate::settings::BakeSettings;
use crate::weld::{uv_quant, weld_on, WeldedMesh};
use mres_format::write::EncodedCluster;
use mres_format::{DagCluster, Grid, Group, Header, Sphere, UvQuant, NO_GROUP};
use mres_import::mesh::bounds;
use mres_import::mesh::{Corner, NONE};
use mres_import::ImportError;
use mres_import::SourceMesh;
use rayon::prelude::*;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;

/// A shard stops building levels once a level keeps more than this fraction of its triangles.
pub const SHARD_STOP_REDUCTION: f64 = 0.75;

/// Most vertices sampled to place the cell boundaries.
const CELL_SAMPLE: usize = 1 << 20;

/// The vertex attributes of a mesh to shard (owned: they are freed once the shards are read),
/// and a way to stream its triangles.
pub struct ShardSource<'a> {
    /// Positions (finite).
    pub positions: Vec<[f32; 3]>,
    /// Normals, or empty.
    pub normals: Vec<[f32; 3]>,
    /// UVs, or empty.
    pub uvs: Vec<[f32; 2]>,
    /// Triangles to stream (an estimate is fine: it only sizes the cells).
    pub triangles: u64,
    /// Calls its argument with every triangle's corners (attributes absent: [`NONE`]) and
    /// material, always in the same order. Owns what it reads (freed with the source).
    #[allow(clippy::type_complexity)]
    pub for_each_triangle: Box<dyn Fn(&mut dyn FnMut([Corner; 3], u32)) -> Result<(), ImportError> + Sync + 'a>,
}

/// The DAG of a sharded build, with its clusters already encoded.
pub struct ShardedDag {
    /// File header.
    pub header: Header,
    /// All groups.
    pub groups: Vec<Group>,
    /// All clusters.
    pub clusters: Vec<EncodedCluster>,
    /// Figures.
    pub stats: BuildStats,
    /// Welded vertices over all shards (shard-border vertices counted in each shard).
    pub welded_vertices: u64,
    /// Triangles dropped as degenerate.
    pub degenerate_dropped: u64,
}

/// One bytes-per-triangle record of a spill file: three corners (v, vt, vn) and the material.
const RECORD: usize = 40;

/// Builds the DAG of `source` in shards of about `settings.shard_triangles` triangles.
pub fn build_sharded(
    source: ShardSource,
    settings: &BakeSettings,
    progress: Progress,
) -> Result<ShardedDag, BakeError> {
    let mut stats = BuildStats::default();
    let mut clock = StageClock::start();
    let (lo, hi) = bounds(&source.positions).ok_or(BakeError::Empty(0))?;
    let grid = Grid::covering(lo, hi, settings.position_bits);
    let keep_uvs = settings.keep_uvs && !source.uvs.is_empty();
    let keep_normals = settings.keep_normals && !source.normals.is_empty();
    let uv = if keep_uvs { uv_quant(&source.uvs) } else { uv_quant(&[]) };
    let cells = Cells::new(&source, settings.shard_triangles);
    progress(&format!("shard: {} triangles into {} cells", source.triangles, cells.count()));

    // Spill every triangle to its cell's file.
    let dir = tempfile::Builder::new().prefix("mres-shards-").tempdir().map_err(spill_error)?;
    let mut writers: Vec<BufWriter<File>> = (0..cells.count())
        .map(|s| File::create(dir.path().join(format!("{s}.bin"))).map(|f| BufWriter::with_capacity(1 << 16, f)))
        .collect::<Result<_, _>>()
        .map_err(spill_error)?;
    let mut io_error = None;
    let mut degenerate = 0u64;
    let mut kept = 0u64;
    let mut first_material = None;
    let mut multi_material = false;
    (source.for_each_triangle)(&mut |t, material| {
        let p = t.map(|c| source.positions[c.v as usize]);
        if p[0] == p[1] || p[1] == p[2] || p[0] == p[2] {
            degenerate += 1;
            return;
        }
        multi_material |= *first_material.get_or_insert(material) != material;
        let centroid = [0, 1, 2].map(|k| (p[0][k] + p[1][k] + p[2][k]) / 3.0);
        let mut record = [0u8; RECORD];
        let words = t.iter().flat_map(|c| [c.v, c.vt, c.vn]).chain([material]);
        for (chunk, w) in record.chunks_exact_mut(4).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        if let Err(e) = writers[cells.cell_of(centroid)].write_all(&record) {
            io_error.get_or_insert(e);
        }
        kept += 1;
    })?;
    for w in &mut writers {
        if let Err(e) = w.flush() {
            io_error.get_or_insert(e);
        }
    }
    drop(writers);
    if let Some(e) = io_error {
        return Err(spill_error(e));
    }
    if kept == 0 {
        return Err(BakeError::Empty(degenerate));
    }
    clock.lap(&mut stats, "spill");

    // Stage 1: build the shards from their spill files.
    let context = ShardContext { settings, grid, uv, keep_normals, keep_uvs, multi_material };
    let shards: Vec<CellResult> = (0..cells.count())
        .into_par_iter()
        .map(|s| {
            let result = context.build_shard(&source, &dir.path().join(format!("{s}.bin")));
            if let Ok(r) = &result {
                progress(&format!(
                    "shard {}/{}: {} triangles, {} levels, {} top clusters",
                    s + 1,
                    cells.count(),
                    r.triangles,
                    r.levels,
                    r.top.len()
                ));
            }
            result
        })
        .collect::<Result<_, _>>()?;
    drop((dir, source)); // the vertex attributes are not needed any more
    stats.shards = shards.len() as u64;
    let mut dag = Collected::default();
    let mut top = dag.collect(shards, &mut stats);
    clock.lap(&mut stats, "shards");

    // Later stages: while the top clusters are too many to merge, cut them into new cells
    // whose borders avoid the previous stage's, and build each a few levels.
    let mut stage = 1;
    loop {
        let triangles = triangles_of(&top);
        if triangles <= settings.shard_triangles {
            break;
        }
        stage += 1;
        let quantile = if stage % 2 == 0 { 1.0 / 3.0 } else { 0.5 };
        let cells = cut_cells(&top, settings.shard_triangles, quantile);
        progress(&format!("stage {stage}: {triangles} triangles in {} cells", cells.len()));
        let mut slots: Vec<Option<TopCluster>> = top.into_iter().map(Some).collect();
        let cell_tops: Vec<Vec<TopCluster>> =
            cells.iter().map(|ids| ids.iter().map(|&i| slots[i].take().expect("each once")).collect()).collect();
        let level = dag.level;
        let results: Vec<CellResult> =
            cell_tops.into_par_iter().map(|tops| context.build_cell(tops, level, false)).collect::<Result<_, _>>()?;
        top = dag.collect(results, &mut stats);
        if triangles_of(&top) as f64 > SHARD_STOP_REDUCTION * triangles as f64 {
            break; // the rest is locked geometry (open edges): merging it whole is all that helps
        }
    }
    clock.lap(&mut stats, "stages");

    // Merge what is left into one root.
    progress(&format!("merge: {} clusters", top.len()));
    let last = context.build_cell(top, dag.level, true)?;
    stats.root_groups = last.stats.root_groups;
    stats.root_clusters = last.stats.root_clusters;
    let header = last.header;
    let left = dag.collect(vec![last], &mut stats);
    debug_assert!(left.is_empty());
    let header = Header { source_triangles: kept + degenerate, ..header };
    let Collected { groups, encoded, welded_vertices, degenerate: dropped, .. } = dag;
    degenerate += dropped;
    clock.lap(&mut stats, "merge");
    Ok(ShardedDag { header, groups, clusters: encoded, stats, welded_vertices, degenerate_dropped: degenerate })
}

fn spill_error(e: std::io::Error) -> BakeError {
    BakeError::Shard(format!("spill files (temporary directory; set TMPDIR to move it): {e}"))
}

/// The shard cells: a k-d tree whose leaves are cells.
struct Cells {
    /// Inner nodes: (axis, split value, child below, child at or above); a child index with
    /// the top bit set is cell `index & !LEAF`.
    nodes: Vec<(usize, f32, u32, u32)>,
    cells: usize,
}

const LEAF: u32 = 1 << 31;

impl Cells {
    fn new(source: &ShardSource, shard_triangles: u64) -> Cells {
        let n = source.positions.len();
        let stride = n.div_ceil(CELL_SAMPLE).max(1);
        let mut sample: Vec<[f32; 3]> = source.positions.iter().step_by(stride).copied().collect();
        // Vertices (sampled) per cell for about `shard_triangles` triangles.
        let vertices_per_triangle = n as f64 / source.triangles.max(1) as f64;
        let per_cell = ((shard_triangles as f64 * vertices_per_triangle / stride as f64) as usize).max(1);
        let mut cells = Cells { nodes: Vec::new(), cells: 0 };
        cells.split(&mut sample, per_cell);
        cells
    }

    /// Splits `points` until each part has at most `per_cell`; returns the subtree's index.
    fn split(&mut self, points: &mut [[f32; 3]], per_cell: usize) -> u32 {
        if points.len() <= per_cell || points.len() < 2 {
            self.cells += 1;
            return (self.cells as u32 - 1) | LEAF;
        }
        let (lo, hi) = bounds(points).expect("non-empty");
        let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
        let mid = points.len() / 2;
        points.select_nth_unstable_by(mid, |a, b| a[axis].total_cmp(&b[axis]));
        let at = points[mid][axis];
        let node = self.nodes.len();
        self.nodes.push((axis, at, 0, 0));
        let (below, above) = points.split_at_mut(mid);
        let below = self.split(below, per_cell);
        let above = self.split(above, per_cell);
        self.nodes[node].2 = below;
        self.nodes[node].3 = above;
        node as u32
    }

    fn count(&self) -> usize {
        self.cells
    }

    fn cell_of(&self, p: [f32; 3]) -> usize {
        let mut at = if self.nodes.is_empty() { LEAF } else { 0 };
        while at & LEAF == 0 {
            let (axis, split, below, above) = self.nodes[at as usize];
            at = if p[axis] < split { below } else { above };
        }
        (at & !LEAF) as usize
    }
}

/// Triangles in `top`.
fn triangles_of(top: &[TopCluster]) -> u64 {
    top.iter().map(|t| t.cluster.indices.len() as u64 / 3).sum()
}

/// A shard's coarsest cluster, carried into the merge.
struct TopCluster {
    /// Its geometry (group not yet known).
    cluster: DagCluster,
    own_sphere: Sphere,
    own_error: f32,
}

/// Levels each shard, and each cell of a later stage, builds before the top clusters are cut
/// into new cells. A cell border stays locked this many levels (the band along it lags the
/// interior by as much); then it lies inside a cell of the next stage and is simplified.
pub const LEVELS_PER_STAGE: u32 = 3;

/// Group ids a shard or cell assigns are local until its result is collected: this bit marks
/// them (ids without it are global already).
const LOCAL: u32 = 1 << 31;

/// What one shard or cell leaves.
struct CellResult {
    /// New groups; the group `LOCAL | i` is `groups[i]`.
    groups: Vec<Group>,
    /// Finished clusters.
    encoded: Vec<EncodedCluster>,
    /// Clusters without a group yet.
    top: Vec<TopCluster>,
    /// The level the next groups get.
    levels: u32,
    stats: BuildStats,
    /// The header its clusters were encoded for.
    header: Header,
    triangles: u64,
    welded_vertices: u64,
    degenerate: u64,
}

/// The groups and encoded clusters collected so far, under global ids.
#[derive(Default)]
struct Collected {
    groups: Vec<Group>,
    encoded: Vec<EncodedCluster>,
    /// The highest level reached by any cell so far.
    level: u32,
    welded_vertices: u64,
    degenerate: u64,
}

impl Collected {
    /// Takes the results in order, giving their local groups global ids; returns their top
    /// clusters.
    fn collect(&mut self, results: Vec<CellResult>, stats: &mut BuildStats) -> Vec<TopCluster> {
        let mut top = Vec::new();
        for r in results {
            let offset = self.groups.len() as u32;
            let shift = |g: u32| if g != NO_GROUP && g & LOCAL != 0 { (g & !LOCAL) + offset } else { g };
            self.groups.extend(r.groups);
            self.encoded.extend(r.encoded.into_iter().map(|mut c| {
                c.group = shift(c.group);
                c.own_group = shift(c.own_group);
                c
            }));
            top.extend(r.top.into_iter().map(|mut t| {
                t.cluster.own_group = shift(t.cluster.own_group);
                t
            }));
            stats.add(&r.stats);
            self.welded_vertices += r.welded_vertices;
            self.degenerate += r.degenerate;
            self.level = self.level.max(r.levels);
        }
        top
    }
}

/// Splits the top clusters into cells of at most `max_triangles` (by their centres, a k-d
/// tree cut at the `quantile` of the triangles along the longest axis). Alternating the
/// quantile between stages keeps a new stage's cell borders off the previous stage's.
fn cut_cells(top: &[TopCluster], max_triangles: u64, quantile: f64) -> Vec<Vec<usize>> {
    fn split(top: &[TopCluster], mut ids: Vec<usize>, max: u64, q: f64, out: &mut Vec<Vec<usize>>) {
        let tri = |i: usize| top[i].cluster.indices.len() as u64 / 3;
        let total: u64 = ids.iter().map(|&i| tri(i)).sum();
        if total <= max || ids.len() < 2 {
            out.push(ids);
            return;
        }
        let centers: Vec<[f32; 3]> = ids.iter().map(|&i| top[i].own_sphere.center).collect();
        let (lo, hi) = bounds(&centers).expect("non-empty");
        let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
        ids.sort_by(|&a, &b| top[a].own_sphere.center[axis].total_cmp(&top[b].own_sphere.center[axis]).then(a.cmp(&b)));
        let mut at = ids.len() / 2;
        let mut acc = 0;
        for (k, &i) in ids.iter().enumerate() {
            acc += tri(i);
            if acc as f64 >= q * total as f64 {
                at = k + 1;
                break;
            }
        }
        let above = ids.split_off(at.clamp(1, ids.len() - 1));
        split(top, ids, max, q, out);
        split(top, above, max, q, out);
    }
    let mut out = Vec::new();
    split(top, (0..top.len()).collect(), max_triangles, quantile, &mut out);
    out
}

/// What every shard shares.
struct ShardContext<'a> {
    settings: &'a BakeSettings,
    grid: Grid,
    uv: UvQuant,
    keep_normals: bool,
    keep_uvs: bool,
    multi_material: bool,
}

impl ShardContext<'_> {
    /// Welds `mesh` on the whole mesh's grid, with the whole mesh's attribute flags.
    fn weld(&self, mesh: &SourceMesh) -> WeldedMesh {
        let mut welded = weld_on(mesh, self.settings, self.grid, self.uv);
        welded.multi_material = self.multi_material;
        welded
    }

    /// Reads a spill file and builds the shard's first levels.
    fn build_shard(&self, source: &ShardSource, spill: &Path) -> Result<CellResult, BakeError> {
        let mut bytes = Vec::new();
        BufReader::new(File::open(spill).map_err(spill_error)?).read_to_end(&mut bytes).map_err(spill_error)?;
        let words: Vec<u32> = bytes.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        drop(bytes);
        // Local vertices: distinct corners, in sorted order (deterministic).
        let corner = |w: &[u32]| Corner { v: w[0], vt: w[1], vn: w[2] };
        let corners_of = |words: &[u32]| -> Vec<Corner> {
            words.chunks_exact(RECORD / 4).flat_map(|r| (0..3).map(move |k| corner(&r[3 * k..3 * k + 3]))).collect()
        };
        let mut corners = corners_of(&words);
        corners.par_sort_unstable();
        corners.dedup();
        let s = source;
        let mesh = SourceMesh {
            positions: corners.iter().map(|c| s.positions[c.v as usize]).collect(),
            normals: self.keep_normals.then(|| corners.iter().map(|c| attribute(&s.normals, c.vn)).collect()),
            uvs: self.keep_uvs.then(|| corners.iter().map(|c| attribute(&s.uvs, c.vt)).collect()),
            indices: corners_of(&words)
                .into_iter()
                .map(|c| corners.binary_search(&c).expect("corner is present") as u32)
                .collect(),
            materials: words.chunks_exact(RECORD / 4).map(|r| r[9]).collect(),
            degenerate_dropped: 0,
        };
        drop((words, corners));
        let triangles = mesh.triangle_count() as u64;
        let welded = self.weld(&mesh);
        drop(mesh);
        let mut result = self.run(&welded, level0(&welded, self.settings), Vec::new(), 0, false)?;
        result.triangles = triangles;
        result.welded_vertices = welded.positions.len() as u64;
        result.degenerate = welded.degenerate_dropped;
        Ok(result)
    }

    /// Welds top clusters into one mesh and builds on: [`LEVELS_PER_STAGE`] levels, or with
    /// `to_root` to the root group.
    fn build_cell(&self, tops: Vec<TopCluster>, level: u32, to_root: bool) -> Result<CellResult, BakeError> {
        let merged = self.merged_mesh(&tops);
        let clusters = self.top_clusters(&merged, &tops)?;
        self.run(&merged, clusters, tops, level, to_root)
    }

    /// The level loop on `clusters` (the first `inputs.len()` of them are `inputs`, whose
    /// geometry is kept as it is), then encodes what got a group.
    fn run(
        &self,
        welded: &WeldedMesh,
        clusters: Vec<Cluster>,
        inputs: Vec<TopCluster>,
        level: u32,
        to_root: bool,
    ) -> Result<CellResult, BakeError> {
        let quiet: Progress = &|_| {};
        let mut builder = Builder::new(welded, self.settings, clusters, level, LOCAL);
        if to_root {
            while builder.step(quiet) {}
            builder.make_roots();
        } else {
            loop {
                let before = builder.pending_triangles() as f64;
                if builder.level >= level + LEVELS_PER_STAGE
                    || builder.pending.len() <= 4 * self.settings.group_size as usize
                    || !builder.step(quiet)
                {
                    break;
                }
                if builder.pending_triangles() as f64 > SHARD_STOP_REDUCTION * before {
                    break;
                }
            }
        }
        let pending = std::mem::take(&mut builder.pending);
        let header = header(welded, self.settings);
        let mut is_top = vec![false; builder.clusters.len()];
        for &c in &pending {
            is_top[c] = true;
        }
        let geometry = |i: usize, c: &Cluster| match inputs.get(i) {
            Some(t) => DagCluster { group: c.group, ..t.cluster.clone() },
            None => to_dag_cluster(welded, c),
        };
        let encoded: Vec<EncodedCluster> = builder
            .clusters
            .par_iter()
            .enumerate()
            .filter(|(i, _)| !is_top[*i])
            .map(|(i, c)| EncodedCluster::new(&geometry(i, c), &header, i).map_err(BakeError::Write))
            .collect::<Result<_, _>>()?;
        let top = pending
            .iter()
            .map(|&i| {
                let c = &builder.clusters[i];
                TopCluster { cluster: geometry(i, c), own_sphere: c.own_sphere, own_error: c.own_error }
            })
            .collect();
        Ok(CellResult {
            groups: std::mem::take(&mut builder.groups),
            encoded,
            top,
            levels: builder.level,
            stats: std::mem::take(&mut builder.stats),
            header,
            triangles: 0,
            welded_vertices: 0,
            degenerate: 0,
        })
    }

    /// The shards' top clusters as one mesh, welded on the shared grid: shard borders meet.
    fn merged_mesh(&self, top: &[TopCluster]) -> WeldedMesh {
        let mut mesh = SourceMesh {
            normals: self.keep_normals.then(Vec::new),
            uvs: self.keep_uvs.then(Vec::new),
            ..Default::default()
        };
        for t in top {
            let c = &t.cluster;
            let base = mesh.positions.len() as u32;
            mesh.positions.extend(c.positions.iter().map(|&q| self.grid.decode(q)));
            if let Some(n) = &mut mesh.normals {
                n.extend_from_slice(&c.normals);
            }
            if let Some(u) = &mut mesh.uvs {
                u.extend_from_slice(&c.uvs);
            }
            mesh.indices.extend(c.indices.iter().map(|&i| base + i as u32));
            if c.materials.is_empty() {
                // Single-material mesh: every vertex has the same material.
                mesh.materials.extend(std::iter::repeat_n(0, c.indices.len() / 3));
            } else {
                mesh.materials.extend(c.materials.iter().map(|&m| m as u32));
            }
        }
        self.weld(&mesh)
    }

    /// The top clusters as pending clusters of the merged mesh (same triangle order).
    /// Fails if welding moved a vertex off its grid point (the grid's f32 arithmetic cannot
    /// round-trip: a mesh very far from its origin relative to its size).
    fn top_clusters(&self, merged: &WeldedMesh, top: &[TopCluster]) -> Result<Vec<Cluster>, BakeError> {
        let mut at = 0;
        let mut clusters = Vec::with_capacity(top.len());
        for t in top {
            let n = t.cluster.indices.len();
            let indices = merged.indices.get(at..at + n).unwrap_or_default();
            let exact = indices.len() == n
                && indices
                    .iter()
                    .zip(&t.cluster.indices)
                    .all(|(&v, &local)| merged.grid_positions[v as usize] == t.cluster.positions[local as usize]);
            if !exact {
                return Err(BakeError::Shard(
                    "merging shards: the position grid does not round-trip in f32 (mesh too far from the origin for its \
                     size?); raise shard_triangles to bake it whole"
                        .into(),
                ));
            }
            let indices = indices.to_vec();
            at += n;
            clusters.push(Cluster {
                indices,
                own_group: t.cluster.own_group,
                own_sphere: t.own_sphere,
                own_error: t.own_error,
                group: NO_GROUP,
            });
        }
        Ok(clusters)
    }
}

fn attribute<T: Copy + Default>(values: &[T], index: u32) -> T {
    if index == NONE {
        T::default()
    } else {
        values.get(index as usize).copied().unwrap_or_default()
    }
}
