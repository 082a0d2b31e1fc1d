//! Sharding: a mesh with more than `shard_triangles` triangles is split spatially into shards
//! that are built one by one (in parallel as threads allow), then merged in the upper levels
//! into one DAG with one root (docs/ARCHITECTURE.md "Large meshes: sharding and streaming
//! import").
//!
//! 1. **Cells.** A k-d tree over (a sample of) the vertex positions, split at medians along
//!    the longest axis until a cell holds about `shard_triangles` triangles' worth of vertices.
//! 2. **Spill.** The triangles are streamed (from the OBJ file itself for a streamed import,
//!    see `mres_import::obj_stream`) and each is appended to its cell's spill file in a
//!    temporary directory, by centroid. Only the vertex attributes stay in memory.
//! 3. **Shards (stage 1).** Each shard is read back, welded on the whole mesh's grid (so that
//!    shards meet exactly) and built [`LEVELS_PER_STAGE`] levels like a whole mesh. Its edges
//!    on the shard border are open in the shard but not marked (only the whole mesh's odd
//!    edges are), so they stay locked for those levels. Its
//!    finished clusters go to the [`DagOutput`] right away (the `.mres` encoder keeps them
//!    compact); its top clusters are kept on the integer grid ([`TopCluster`]).
//! 4. **Later stages.** The top clusters are cut into new cells whose borders avoid the
//!    previous stage's (the cut alternates between the 1/3 quantile and the median), each cell
//!    is welded by integer grid point and built another [`LEVELS_PER_STAGE`] levels, until the
//!    top fits one merge or a stage removes less than [`SHARD_STOP_REDUCTION`] of its
//!    triangles. A cell border thus lags the interior by at most [`LEVELS_PER_STAGE`] levels.
//! 5. **Merge.** What is left is welded into one mesh and the level loop goes on to one root.
//!    So no edge stays locked for good: every shard border is simplified in a later stage.
//!
//! Peak memory is the vertex attributes (12–32 bytes per vertex), the encoded clusters (about
//! the size of the output), and the working set of the shards being built — not the whole
//! mesh's build. Output is deterministic: cells, spill order and shard results depend only on
//! the input and the settings, never on the thread count.

use crate::area;
use crate::dag::{
    BuildStats, BuiltCluster, BuiltDag, Cell, Collected, Converted, DagOutput, Frame, StageClock, TopCluster,
};
use crate::error::BakeError;
use crate::levels::{level0, Builder, Level0Edges};
use crate::partition::numbered_in_triangle_order;
use crate::progress::Progress;
use crate::settings::BakeSettings;
use crate::source::TriangleSource;
use crate::weld::{uv_quant, weld_grid, weld_on, GridMesh, WeldedMesh};
use mres_format::{Grid, UvQuant, NO_GROUP};
use mres_geom::edges::edge_ends;
use mres_import::mesh::bounds;
use mres_import::mesh::{Corner, NONE};
use mres_import::SourceMesh;
use rayon::prelude::*;
use rustc_hash::FxHashSet;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

/// A shard stops building levels once a level keeps more than this fraction of its triangles.
pub const SHARD_STOP_REDUCTION: f64 = 0.75;

/// Levels each shard, and each cell of a later stage, builds before the top clusters are cut
/// into new cells. A cell border stays locked this many levels (the band along it lags the
/// interior by as much); then it lies inside a cell of the next stage and is simplified.
pub const LEVELS_PER_STAGE: u32 = 3;

/// Most vertices sampled to place the cell boundaries.
const CELL_SAMPLE: usize = 1 << 20;

/// Builds the DAG of `source` in shards of about `settings.shard_triangles` triangles into
/// `output`; the source is dropped once the shards are read.
pub fn build_sharded<S: TriangleSource, O: DagOutput>(
    source: S,
    settings: &BakeSettings,
    progress: Progress,
    output: O,
) -> Result<BuiltDag<O>, BakeError> {
    let mut stats = BuildStats::default();
    let mut clock = StageClock::start();
    let (lo, hi) = bounds(source.positions()).ok_or(BakeError::Empty(0))?;
    let keep_uvs = settings.keep_uvs && !source.uvs().is_empty();
    let keep_normals = settings.keep_normals && !source.normals().is_empty();
    let uvs: &[[f32; 2]] = if keep_uvs { source.uvs() } else { &[] };
    let grid = (Grid::covering(lo, hi, settings.position_bits), uv_quant(uvs));
    let cells = Cells::new(&source, settings.shard_triangles);
    progress(&format!("shard: {} triangles into {} cells", source.triangles(), cells.count()));
    let spill = Spill::new(&source, &cells, grid.0)?;
    clock.lap(&mut stats, "spill");

    // Stage 1: build the shards from their spill files.
    let context = ShardContext { settings, grid, keep_normals, keep_uvs, multi_material: spill.multi_material };
    let mut dag = Collected::new(output);
    let shards = context.build_shards(&source, &spill, cells.count(), &dag.output, progress)?;
    let (kept, degenerate, multi_material) = (spill.kept, spill.degenerate, spill.multi_material);
    drop(spill); // removes the spill files
    let importer_dropped = source.dropped();
    drop(source); // the vertex attributes are not needed any more
    stats.shards = shards.len() as u64;
    let top = dag.collect(shards, &mut stats);
    clock.lap(&mut stats, "shards");
    let top = context.stages(&mut dag, top, &mut stats, progress)?;
    clock.lap(&mut stats, "stages");

    // Merge what is left into one root.
    progress(&format!("merge: {} clusters", top.len()));
    let last = context.build_cell(top, dag.level, true, &dag.output)?;
    let left = dag.collect(vec![last], &mut stats);
    debug_assert!(left.is_empty());
    clock.lap(&mut stats, "merge");
    // Input triangles include the ones an in-memory source's importer dropped, as in a whole
    // build (files baked before BAKER_VERSION 4 recorded kept + spill-dropped only).
    let source_triangles = kept + degenerate + importer_dropped;
    dag.degenerate += degenerate + importer_dropped;
    let frame = Frame { grid: grid.0, uv: grid.1, normals: keep_normals, uvs: keep_uvs, multi_material };
    Ok(dag.finish(frame, source_triangles, stats))
}

fn spill_error(e: std::io::Error) -> BakeError {
    BakeError::Shard(format!("spill files (temporary directory; set TMPDIR to move it): {e}"))
}

/// Every triangle of a source, in its cell's spill file (a temporary directory, removed on
/// drop): only the vertex attributes stay in memory.
struct Spill {
    dir: tempfile::TempDir,
    /// The whole mesh's edges used an odd number of times (its open and odd non-manifold
    /// edges), by [`grid_edge`] key: a shard marks these and locks its other open edges,
    /// which are shard borders.
    open: FxHashSet<u128>,
    /// Triangles spilled.
    kept: u64,
    /// Triangles dropped as degenerate (two corners at one position).
    degenerate: u64,
    multi_material: bool,
}

/// One triangle of a spill file: three corners (v, vt, vn) and the material, as ten native
/// `u32`s. Hand-written: the files are fixed-size records that never leave this process.
type Record = [u32; 10];
const RECORD_BYTES: usize = std::mem::size_of::<Record>();

impl Spill {
    fn new(source: &impl TriangleSource, cells: &Cells, grid: Grid) -> Result<Spill, BakeError> {
        let dir = tempfile::Builder::new().prefix("mres-shards-").tempdir().map_err(spill_error)?;
        let mut spill = Spill { dir, open: FxHashSet::default(), kept: 0, degenerate: 0, multi_material: false };
        let mut writers: Vec<BufWriter<File>> = (0..cells.count())
            .map(|s| File::create(spill.path(s)).map(|f| BufWriter::with_capacity(1 << 16, f)))
            .collect::<Result<_, _>>()
            .map_err(spill_error)?;
        let mut io_error = None;
        let mut first_material = None;
        let positions = source.positions();
        source.for_each_triangle(&mut |t, material| {
            let p = t.map(|c| positions[c.v as usize]);
            if p[0] == p[1] || p[1] == p[2] || p[0] == p[2] {
                spill.degenerate += 1;
                return;
            }
            spill.multi_material |= *first_material.get_or_insert(material) != material;
            // Toggling each edge leaves the odd ones (a triangle that the grid makes
            // degenerate toggles its one real edge twice, as welding drops it).
            let q = p.map(|x| grid.quantize(x));
            for k in 0..3 {
                let e = grid_edge(q[k], q[(k + 1) % 3]);
                if !spill.open.remove(&e) {
                    spill.open.insert(e);
                }
            }
            let centroid = [0, 1, 2].map(|k| (p[0][k] + p[1][k] + p[2][k]) / 3.0);
            if let Err(e) = writers[cells.cell_of(centroid)].write_all(&record_bytes(t, material)) {
                io_error.get_or_insert(e);
            }
            spill.kept += 1;
        })?;
        for w in &mut writers {
            if let Err(e) = w.flush() {
                io_error.get_or_insert(e);
            }
        }
        drop(writers);
        match (io_error, spill.kept) {
            (Some(e), _) => Err(spill_error(e)),
            (None, 0) => Err(BakeError::Empty(spill.degenerate)),
            (None, _) => Ok(spill),
        }
    }

    /// The spill file of cell `s`.
    fn path(&self, s: usize) -> PathBuf {
        self.dir.path().join(format!("{s}.bin"))
    }

    /// The records of a spill file.
    fn read(path: &Path) -> Result<Vec<Record>, BakeError> {
        let mut bytes = Vec::new();
        BufReader::new(File::open(path).map_err(spill_error)?).read_to_end(&mut bytes).map_err(spill_error)?;
        let word = |b: &[u8]| u32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
        Ok(bytes.chunks_exact(RECORD_BYTES).map(|r| std::array::from_fn(|k| word(&r[4 * k..]))).collect())
    }
}

/// A direction-free key of the edge between grid points `a` and `b`: two independent 64-bit
/// mixes of the six coordinates (collisions are far below one in 10^18 edges).
fn grid_edge(a: [i32; 3], b: [i32; 3]) -> u128 {
    let (a, b) = if a <= b { (a, b) } else { (b, a) };
    let mix = |seed: u64| {
        a.iter().chain(&b).fold(seed, |h, &v| {
            let z = (h ^ v as u32 as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
            z ^ (z >> 29)
        })
    };
    (mix(0x243f_6a88_85a3_08d3) as u128) << 64 | mix(0x1319_8a2e_0370_7344) as u128
}

/// The spill record of a triangle.
fn record_bytes(t: [Corner; 3], material: u32) -> [u8; RECORD_BYTES] {
    let words = t.iter().flat_map(|c| [c.v, c.vt, c.vn]).chain([material]);
    let mut bytes = [0u8; RECORD_BYTES];
    for (chunk, w) in bytes.chunks_exact_mut(4).zip(words) {
        chunk.copy_from_slice(&w.to_ne_bytes());
    }
    bytes
}

/// The corners of a spill record.
fn corners(r: &Record) -> [Corner; 3] {
    [0, 1, 2].map(|k| Corner { v: r[3 * k], vt: r[3 * k + 1], vn: r[3 * k + 2] })
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
    fn new(source: &impl TriangleSource, shard_triangles: u64) -> Cells {
        let n = source.positions().len();
        let stride = n.div_ceil(CELL_SAMPLE).max(1);
        let mut sample: Vec<[f32; 3]> = source.positions().iter().step_by(stride).copied().collect();
        // Vertices (sampled) per cell for about `shard_triangles` triangles.
        let vertices_per_triangle = n as f64 / source.triangles().max(1) as f64;
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

/// Splits the top clusters into cells of at most `max_triangles` (by their centres, a k-d
/// tree cut at the `quantile` of the triangles along the longest axis). Alternating the
/// quantile between stages keeps a new stage's cell borders off the previous stage's.
fn cut_cells(top: &[TopCluster], max_triangles: u64, quantile: f64) -> Vec<Vec<usize>> {
    fn split(top: &[TopCluster], mut ids: Vec<usize>, max: u64, q: f64, out: &mut Vec<Vec<usize>>) {
        let tri = |i: usize| top[i].triangles();
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
    /// The whole mesh's grid and UV quantization, so that shards meet exactly.
    grid: (Grid, UvQuant),
    keep_normals: bool,
    keep_uvs: bool,
    multi_material: bool,
}

impl ShardContext<'_> {
    /// Builds the first levels of every shard, in parallel, in cell order.
    fn build_shards<O: DagOutput>(
        &self,
        source: &impl TriangleSource,
        spill: &Spill,
        count: usize,
        output: &O,
        progress: Progress,
    ) -> Result<Vec<Cell<O::Cluster>>, BakeError> {
        (0..count)
            .into_par_iter()
            .map(|s| {
                let cell = self.build_shard(source, &spill.path(s), &spill.open, output)?;
                let (levels, top) = (cell.levels, cell.top.len());
                let triangles = cell.triangles;
                progress(&format!(
                    "shard {}/{count}: {triangles} triangles, {levels} levels, {top} top clusters",
                    s + 1
                ));
                Ok(cell)
            })
            .collect()
    }

    /// Reads a spill file and builds the shard's first levels.
    fn build_shard<O: DagOutput>(
        &self,
        source: &impl TriangleSource,
        spill: &Path,
        global_open: &FxHashSet<u128>,
        output: &O,
    ) -> Result<Cell<O::Cluster>, BakeError> {
        let records = Spill::read(spill)?;
        let mesh = self.shard_mesh(source, &records);
        drop(records);
        let triangles = mesh.triangle_count() as u64;
        let mut welded = weld_on(&mesh, self.settings, self.grid.0, self.grid.1);
        welded.multi_material = self.multi_material;
        drop(mesh);
        let (welded, order) = numbered_in_triangle_order(welded);
        let edges = Level0Edges::new(&welded);
        let welded = area::prepare(welded, self.settings, Some(edges.sorted()));
        // The shard's odd edges that are odd in the whole mesh too are open; the rest are
        // shard borders (`Builder` locks them).
        let mut point = vec![[0i32; 3]; welded.position_count];
        for (v, &p) in welded.position_ids.iter().enumerate() {
            point[p as usize] = welded.grid_positions[v];
        }
        let q = |p: u32| point[p as usize];
        let open: Vec<u64> = edges
            .odd()
            .into_iter()
            .filter(|&e| {
                let [a, b] = edge_ends(e);
                global_open.contains(&grid_edge(q(a), q(b)))
            })
            .collect();
        let cell = self.levels(&welded, level0(&welded, self.settings, (&edges, &open), &order), 0, false, output)?;
        Ok(Cell {
            triangles,
            welded_vertices: welded.positions.len() as u64,
            degenerate: welded.degenerate_dropped,
            ..cell
        })
    }

    /// A shard's triangles as a mesh of its own: its vertices are the distinct corners, in
    /// sorted order (deterministic).
    fn shard_mesh(&self, source: &impl TriangleSource, records: &[Record]) -> SourceMesh {
        let mut distinct: Vec<Corner> = records.iter().flat_map(corners).collect();
        distinct.par_sort_unstable();
        distinct.dedup();
        let (normals, uvs) = (source.normals(), source.uvs());
        let vertex = |c: Corner| distinct.binary_search(&c).expect("corner is present") as u32;
        SourceMesh {
            positions: distinct.iter().map(|c| source.positions()[c.v as usize]).collect(),
            normals: self.keep_normals.then(|| distinct.iter().map(|c| attribute(normals, c.vn)).collect()),
            uvs: self.keep_uvs.then(|| distinct.iter().map(|c| attribute(uvs, c.vt)).collect()),
            indices: records.iter().flat_map(|r| corners(r).map(vertex)).collect(),
            materials: records.iter().map(|r| r[9]).collect(),
            degenerate_dropped: 0,
        }
    }

    /// Later stages: while the top clusters are too many to merge, cuts them into new cells
    /// whose borders avoid the previous stage's, and builds each a few levels.
    fn stages<O: DagOutput>(
        &self,
        dag: &mut Collected<O>,
        mut top: Vec<TopCluster>,
        stats: &mut BuildStats,
        progress: Progress,
    ) -> Result<Vec<TopCluster>, BakeError> {
        let mut stage = 1;
        loop {
            let triangles = triangles_of(&top);
            if triangles <= self.settings.shard_triangles {
                return Ok(top);
            }
            stage += 1;
            let quantile = if stage % 2 == 0 { 1.0 / 3.0 } else { 0.5 };
            let cells = cut_cells(&top, self.settings.shard_triangles, quantile);
            progress(&format!("stage {stage}: {triangles} triangles in {} cells", cells.len()));
            let mut slots: Vec<Option<TopCluster>> = top.into_iter().map(Some).collect();
            let cell_tops: Vec<Vec<TopCluster>> =
                cells.iter().map(|ids| ids.iter().filter_map(|&i| slots[i].take()).collect()).collect();
            let (level, output) = (dag.level, &dag.output);
            let results: Vec<Cell<O::Cluster>> = cell_tops
                .into_par_iter()
                .map(|tops| self.build_cell(tops, level, false, output))
                .collect::<Result<_, _>>()?;
            top = dag.collect(results, stats);
            if triangles_of(&top) as f64 > SHARD_STOP_REDUCTION * triangles as f64 {
                return Ok(top); // the rest is locked geometry (cell borders): merging it whole is all that helps
            }
        }
    }

    /// Welds top clusters into one mesh and builds on: [`LEVELS_PER_STAGE`] levels, or with
    /// `to_root` to the root group.
    fn build_cell<O: DagOutput>(
        &self,
        tops: Vec<TopCluster>,
        level: u32,
        to_root: bool,
        output: &O,
    ) -> Result<Cell<O::Cluster>, BakeError> {
        let (merged, clusters) = self.merge(tops);
        // The merged top clusters' small open parts grow on from where the shards left them.
        let merged = area::prepare(merged, self.settings, None);
        self.levels(&merged, clusters, level, to_root, output)
    }

    /// The level loop on `clusters` of `welded`: to the root, or one stage's levels.
    fn levels<O: DagOutput>(
        &self,
        welded: &WeldedMesh,
        clusters: Vec<BuiltCluster>,
        level: u32,
        to_root: bool,
        output: &O,
    ) -> Result<Cell<O::Cluster>, BakeError> {
        let quiet: Progress = &|_| {};
        let mut builder = Builder::new(welded, self.settings, clusters, level);
        let mut converted = Converted::new();
        if to_root {
            builder.build_to_root(quiet, output, &mut converted);
        } else {
            loop {
                let before = builder.pending_triangles() as f64;
                if builder.level >= level + LEVELS_PER_STAGE
                    || builder.pending.len() <= 4 * self.settings.group_size as usize
                    || !builder.step(quiet, output, &mut converted)
                {
                    break;
                }
                if builder.pending_triangles() as f64 > SHARD_STOP_REDUCTION * before {
                    break;
                }
            }
        }
        builder.finish(output, converted)
    }

    /// The top clusters as one mesh, welded by their grid points (so shard borders meet), and
    /// as pending clusters of that mesh.
    fn merge(&self, top: Vec<TopCluster>) -> (WeldedMesh, Vec<BuiltCluster>) {
        let mut mesh = GridMesh {
            normals: self.keep_normals.then(Vec::new),
            uvs: self.keep_uvs.then(Vec::new),
            ..Default::default()
        };
        for t in &top {
            mesh.append(&t.mesh);
        }
        let merged = weld_grid(&mesh, self.settings, self.grid, self.multi_material);
        // A top cluster's triangles have three distinct grid points, so none is dropped and
        // the merged triangles are the clusters' in order.
        debug_assert_eq!(merged.indices.len(), mesh.indices.len());
        let mut rest = merged.indices.as_slice();
        let clusters = top
            .iter()
            .map(|t| {
                let (indices, tail) = rest.split_at(t.mesh.indices.len().min(rest.len()));
                rest = tail;
                BuiltCluster {
                    indices: indices.to_vec(),
                    own_group: t.own_group,
                    own_sphere: t.own_sphere,
                    own_error: t.own_error,
                    group: NO_GROUP,
                    open: t.open.clone(),
                    owned: Vec::new(),
                }
            })
            .collect();
        (merged, clusters)
    }
}

/// Triangles in `top`.
fn triangles_of(top: &[TopCluster]) -> u64 {
    top.iter().map(TopCluster::triangles).sum()
}

fn attribute<T: Copy + Default>(values: &[T], index: u32) -> T {
    if index == NONE {
        T::default()
    } else {
        values.get(index as usize).copied().unwrap_or_default()
    }
}
