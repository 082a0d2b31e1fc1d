//! Weld: quantize positions to the global grid and merge vertices that are equal in every
//! attribute (position, normal, UV, material). Vertices equal in position only stay apart
//! (attribute seams) but share a *position id*, which is what locking and crack checks use.

use crate::settings::BakeSettings;
use mres_format::{Grid, UvQuant};
use mres_geom::edges::rotated_to_least;
use mres_geom::parts::UnionFind;
use mres_import::SourceMesh;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// A welded, quantized mesh: the input of the DAG build.
pub struct WeldedMesh {
    /// The global grid.
    pub grid: Grid,
    /// UV quantization (identity-like when the mesh has no UVs).
    pub uv: UvQuant,
    /// Grid coordinates per vertex.
    pub grid_positions: Vec<[i32; 3]>,
    /// Decoded (snapped) position per vertex: what simplification sees.
    pub positions: Vec<[f32; 3]>,
    /// Position id per vertex: vertices at the same grid point share it.
    pub position_ids: Vec<u32>,
    /// Number of distinct position ids.
    pub position_count: usize,
    /// Unit normals per vertex, if kept.
    pub normals: Option<Vec<[f32; 3]>>,
    /// UVs per vertex, if kept.
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Material per vertex (a vertex never spans two materials).
    pub materials: Vec<u32>,
    /// Whether more than one material occurs.
    pub multi_material: bool,
    /// Triangle list into the vertex arrays.
    pub indices: Vec<u32>,
    /// Triangles dropped because they became degenerate on the grid (plus the importer's), or
    /// repeated an earlier triangle exactly (see `drop_duplicates`).
    pub degenerate_dropped: u64,
    /// Triangles of the source.
    pub source_triangles: u64,
    /// With `preserve_area`: the grown copies of its small open parts' vertices, appended
    /// after the level-0 vertices (see [`crate::area`]).
    pub ladder: Option<Ladder>,
}

/// Marks a vertex of no part that grows (see [`Ladder`]).
pub(crate) const NO_PART: u32 = u32::MAX;

/// The grown copies of a mesh's small open parts' vertices (see [`crate::area`], which makes
/// and uses them; it is kept here, with the mesh it belongs to).
#[derive(Clone, Debug, Default)]
pub struct Ladder {
    /// Per level-0 vertex: its part (an id shared by the part's vertices), or NO_PART.
    pub(crate) part: Vec<u32>,
    /// Per welded vertex: the level-0 vertex it is a copy of (itself at rung 0).
    pub(crate) base: Vec<u32>,
    /// Per level-0 vertex of a part that grows: its copy at rung 1 (rung r at `+ r - 1`).
    pub(crate) first_copy: Vec<u32>,
    /// Position ids below this are the level-0 positions; the copies' follow.
    pub level0_positions: usize,
}

impl Ladder {
    /// The part of welded vertex `v` (a copy's is its level-0 vertex's), or NO_PART.
    pub(crate) fn part_of(&self, v: u32) -> u32 {
        self.part[self.base[v as usize] as usize]
    }

    /// The rung of welded vertex `v`: 0 for a level-0 vertex.
    pub(crate) fn rung_of(&self, v: u32) -> u8 {
        let b = self.base[v as usize];
        if b == v {
            0
        } else {
            (v - self.first_copy[b as usize] + 1) as u8
        }
    }

    /// The copy of `v`'s level-0 vertex at rung `r`.
    pub(crate) fn at(&self, v: u32, r: u8) -> u32 {
        let b = self.base[v as usize];
        if r == 0 {
            b
        } else {
            self.first_copy[b as usize] + u32::from(r) - 1
        }
    }
}

/// Welds `mesh` on a grid of `settings.position_bits` over its bounds. `None` if the mesh is
/// empty.
pub fn weld(mesh: &SourceMesh, settings: &BakeSettings) -> Option<WeldedMesh> {
    let (lo, hi) = mesh.bounds()?;
    let grid = Grid::covering(lo, hi, settings.position_bits);
    let uvs = mesh.uvs.as_ref().filter(|_| settings.keep_uvs);
    let uv = uv_quant(uvs.map(|v| v.as_slice()).unwrap_or(&[]));
    Some(weld_on(mesh, settings, grid, uv))
}

/// [`weld`] on a given grid and UV quantization (a shard of a larger mesh uses the whole
/// mesh's, so that shards meet exactly).
pub fn weld_on(mesh: &SourceMesh, settings: &BakeSettings, grid: Grid, uv: UvQuant) -> WeldedMesh {
    let rows = Rows {
        grid_point: &|s| grid.quantize(mesh.positions[s]),
        normals: mesh.normals.as_deref().filter(|_| settings.keep_normals),
        uvs: mesh.uvs.as_deref().filter(|_| settings.keep_uvs),
    };
    // Welding units: source vertices, or (source vertex, material) pairs when a vertex can be
    // used by triangles of several materials (a vertex never spans two materials).
    let first_material = mesh.materials.first().copied().unwrap_or(0);
    let multi_material = mesh.materials.par_iter().any(|&m| m != first_material);
    let units: Vec<(u32, u32)> = if multi_material {
        let mut corners: Vec<(u32, u32)> =
            mesh.indices.par_iter().enumerate().map(|(i, &v)| (v, mesh.materials[i / 3])).collect();
        corners.par_sort_unstable();
        corners.dedup();
        corners
    } else {
        (0..mesh.positions.len() as u32).map(|v| (v, first_material)).collect()
    };
    let (mut out, unit_vertex) = weld_units(&units, &rows, settings, (grid, uv));
    out.multi_material = multi_material;
    let vertex_of = |corner: usize| -> u32 {
        let src = mesh.indices[corner];
        if multi_material {
            let unit = units.binary_search(&(src, mesh.materials[corner / 3])).unwrap_or(0);
            unit_vertex[unit]
        } else {
            unit_vertex[src as usize]
        }
    };
    let collapsed = add_triangles(&mut out, mesh.triangle_count(), vertex_of);
    warn_collapsed(&out, &collapsed, vertex_of, grid.step, settings.position_bits);
    out.degenerate_dropped += drop_duplicates(&mut out.indices) + mesh.degenerate_dropped;
    out.source_triangles = mesh.triangle_count() as u64 + mesh.degenerate_dropped;
    out
}

/// Vertices already on a grid, with their attributes and materials: clusters carried from one
/// welded mesh into the next (the top clusters of sharded builds). Welding them compares grid
/// points as integers, so vertices that were one grid point stay one.
#[derive(Clone, Debug, Default)]
pub struct GridMesh {
    /// Grid coordinates per vertex.
    pub positions: Vec<[i32; 3]>,
    /// Normals per vertex, if kept.
    pub normals: Option<Vec<[f32; 3]>>,
    /// UVs per vertex, if kept.
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Material per vertex.
    pub materials: Vec<u32>,
    /// Triangle list into the vertex arrays.
    pub indices: Vec<u32>,
}

impl GridMesh {
    /// The vertices `vertices` of `mesh` (in that order) and `indices` into them.
    pub fn extract(mesh: &WeldedMesh, vertices: &[u32], indices: Vec<u32>) -> GridMesh {
        let pick = || vertices.iter().map(|&v| v as usize);
        GridMesh {
            positions: pick().map(|v| mesh.grid_positions[v]).collect(),
            normals: mesh.normals.as_ref().map(|n| pick().map(|v| n[v]).collect()),
            uvs: mesh.uvs.as_ref().map(|u| pick().map(|v| u[v]).collect()),
            materials: pick().map(|v| mesh.materials[v]).collect(),
            indices,
        }
    }

    /// Appends `other`'s vertices and triangles (attributes this mesh lacks are dropped).
    pub fn append(&mut self, other: &GridMesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        if let (Some(dst), Some(src)) = (&mut self.normals, &other.normals) {
            dst.extend_from_slice(src);
        }
        if let (Some(dst), Some(src)) = (&mut self.uvs, &other.uvs) {
            dst.extend_from_slice(src);
        }
        self.materials.extend_from_slice(&other.materials);
        self.indices.extend(other.indices.iter().map(|&i| base + i));
    }
}

/// Welds a mesh whose vertices are on `grid` already; `multi_material` is the whole mesh's
/// flag. Every vertex has one material, so the welding units are the vertices.
pub fn weld_grid(
    mesh: &GridMesh,
    settings: &BakeSettings,
    (grid, uv): (Grid, UvQuant),
    multi_material: bool,
) -> WeldedMesh {
    let rows = Rows { grid_point: &|s| mesh.positions[s], normals: mesh.normals.as_deref(), uvs: mesh.uvs.as_deref() };
    let units: Vec<(u32, u32)> = mesh.materials.iter().enumerate().map(|(v, &m)| (v as u32, m)).collect();
    let (mut out, unit_vertex) = weld_units(&units, &rows, settings, (grid, uv));
    out.multi_material = multi_material;
    let triangles = mesh.indices.len() / 3;
    add_triangles(&mut out, triangles, |corner| unit_vertex[mesh.indices[corner] as usize]);
    out.source_triangles = triangles as u64;
    out
}

/// The per-vertex data welding reads: grid point and attributes of source vertex `s`.
struct Rows<'a> {
    grid_point: &'a (dyn Fn(usize) -> [i32; 3] + Sync),
    normals: Option<&'a [[f32; 3]]>,
    uvs: Option<&'a [[f32; 2]]>,
}

/// Welds the units (source vertex, material): the welded vertices (no triangles yet) and the
/// welded vertex of each unit.
fn weld_units(
    units: &[(u32, u32)],
    rows: &Rows,
    settings: &BakeSettings,
    (grid, uv): (Grid, UvQuant),
) -> (WeldedMesh, Vec<u32>) {
    // Key: grid point, quantized attributes, material. Attributes are compared after
    // quantization so that vertices that encode identically also weld. Sorting by key (ties
    // by unit) makes the numbering deterministic and puts equal grid points next to each other.
    type Key = ([i32; 3], [u32; 2], [u16; 2], u32);
    let mut keyed: Vec<(Key, u32)> = units
        .par_iter()
        .enumerate()
        .map(|(i, &(src, material))| {
            let s = src as usize;
            let n = rows.normals.map(|n| mres_format::bits::oct_encode(n[s], settings.normal_bits)).unwrap_or([0; 2]);
            let t = rows.uvs.map(|u| uv.quantize(u[s])).unwrap_or([0; 2]);
            (((rows.grid_point)(s), n, t, material), i as u32)
        })
        .collect();
    keyed.par_sort_unstable();

    // Runs of equal keys are welded vertices, runs of equal grid points positions: numbered
    // by prefix counts, so that every vertex is made side by side.
    let starts: Vec<u32> = (0..keyed.len() as u32)
        .into_par_iter()
        .filter(|&i| i == 0 || keyed[i as usize - 1].0 != keyed[i as usize].0)
        .collect();
    let new_point = |r: usize| r == 0 || keyed[starts[r - 1] as usize].0 .0 != keyed[starts[r] as usize].0 .0;
    let position_ids: Vec<u32> = (0..starts.len())
        .map(new_point)
        .scan(0u32, |count, new| {
            *count += u32::from(new);
            Some(*count - 1)
        })
        .collect();
    let source = |r: usize| units[keyed[starts[r] as usize].1 as usize].0 as usize;
    let vertices = 0..starts.len();
    let grid_positions: Vec<[i32; 3]> =
        vertices.clone().into_par_iter().map(|r| keyed[starts[r] as usize].0 .0).collect();
    let unit_vertex: Vec<AtomicU32> = (0..units.len()).map(|_| AtomicU32::new(0)).collect();
    vertices.clone().into_par_iter().for_each(|r| {
        let end = starts.get(r + 1).map_or(keyed.len(), |&e| e as usize);
        for &(_, unit) in &keyed[starts[r] as usize..end] {
            unit_vertex[unit as usize].store(r as u32, Relaxed);
        }
    });
    let out = WeldedMesh {
        grid,
        uv,
        positions: grid_positions.par_iter().map(|&q| grid.decode(q)).collect(),
        grid_positions,
        position_count: position_ids.last().map_or(0, |&p| p as usize + 1),
        position_ids,
        normals: rows.normals.map(|n| vertices.clone().into_par_iter().map(|r| n[source(r)]).collect()),
        uvs: rows.uvs.map(|u| vertices.clone().into_par_iter().map(|r| u[source(r)]).collect()),
        materials: vertices.into_par_iter().map(|r| keyed[starts[r] as usize].0 .3).collect(),
        multi_material: false,
        indices: Vec::new(),
        degenerate_dropped: 0,
        source_triangles: 0,
        ladder: None,
    };
    (out, unit_vertex.into_iter().map(AtomicU32::into_inner).collect())
}

/// Warns where triangles of the source that the importer kept (`collapsed`, by index, with
/// `vertex_of` their corners' welded vertices) were dropped as thinner than the grid's `step`
/// and left nothing in their place: thin geometry (a railing, a cable, a strip) the file would
/// lack without a word. A dropped sliver inside a surface (thousands on a scan) has its
/// corners used by the triangles around it and is not worth a warning.
fn warn_collapsed(out: &WeldedMesh, collapsed: &[u32], vertex_of: impl Fn(usize) -> u32, step: f32, bits: u32) {
    if collapsed.is_empty() {
        return;
    }
    let mut used = vec![false; out.position_count];
    for &v in &out.indices {
        used[out.position_ids[v as usize] as usize] = true;
    }
    let alone = |t: u32| (0..3).any(|k| !used[out.position_ids[vertex_of(3 * t as usize + k) as usize] as usize]);
    let vanished = collapsed.iter().filter(|&&t| alone(t)).count();
    if vanished > 0 {
        tracing::warn!(
            "{vanished} triangles are thinner than the position grid's step ({step:e}) and were dropped with \
             nothing left in their place: raise position_bits (now {bits}) to keep them"
        );
    }
}

/// Adds the `triangles` triangles whose corner `c` is welded vertex `vertex_of(c)`, dropping
/// those that are degenerate on the grid; returns the dropped ones.
fn add_triangles(out: &mut WeldedMesh, triangles: usize, vertex_of: impl Fn(usize) -> u32 + Sync) -> Vec<u32> {
    let welded: Vec<Option<[u32; 3]>> = (0..triangles)
        .into_par_iter()
        .map(|t| {
            let welded = [vertex_of(3 * t), vertex_of(3 * t + 1), vertex_of(3 * t + 2)];
            let p = welded.map(|v| out.position_ids[v as usize]);
            (p[0] != p[1] && p[1] != p[2] && p[0] != p[2]).then_some(welded)
        })
        .collect();
    out.indices = welded.par_iter().with_min_len(4096).flat_map_iter(|t| t.iter().flatten().copied()).collect();
    let dropped: Vec<u32> = (0..triangles as u32).filter(|&t| welded[t as usize].is_none()).collect();
    out.degenerate_dropped += dropped.len() as u64;
    dropped
}

/// Drops each triangle that repeats an earlier one exactly: the same welded vertices in the
/// same winding (any rotation), so the same positions, attributes and material. Such a copy
/// adds nothing to the surface but makes its three edges non-manifold (used three times or
/// more), and the simplifier's collapses around them pinch edges that the group's crack check
/// then refuses: on the generated defects (1,335 copies in 120,217 triangles) the first level
/// kept 66 % instead of half, and the bake took 1.4 times as long. Two-sided sheets (the
/// opposite winding) and copies with other attributes are kept. Returns how many were dropped;
/// the first of equal triangles stays. Source triangles only: the clusters a sharded build
/// carries on are welded as they are (their edge counts are what the cut invariant checks).
fn drop_duplicates(indices: &mut Vec<u32>) -> u64 {
    let mut keys: Vec<([u32; 3], u32)> = indices
        .par_chunks_exact(3)
        .enumerate()
        .map(|(i, t)| (rotated_to_least([t[0], t[1], t[2]]), i as u32))
        .collect();
    keys.par_sort_unstable();
    // Sorted by (key, index): each run's first is the earliest of its copies.
    let mut repeat = vec![false; indices.len() / 3];
    let mut dropped = 0;
    for run in keys.chunk_by(|a, b| a.0 == b.0) {
        for &(_, t) in &run[1..] {
            (repeat[t as usize], dropped) = (true, dropped + 1);
        }
    }
    if dropped > 0 {
        let kept = indices.chunks_exact(3).zip(&repeat).filter(|(_, &r)| !r).flat_map(|(t, _)| t.iter().copied());
        *indices = kept.collect();
    }
    dropped
}

impl WeldedMesh {
    /// The connected parts of its triangles, by position id, over the first `positions` ids
    /// (a triangle's corners joined).
    pub fn part_sets(&self, positions: usize) -> UnionFind {
        let id = |v: u32| self.position_ids[v as usize];
        let mut sets = UnionFind::new(positions);
        for t in self.indices.chunks_exact(3) {
            sets.union(id(t[0]), id(t[1]));
            sets.union(id(t[0]), id(t[2]));
        }
        sets
    }

    /// The same mesh with its vertices and position ids numbered by first use in the
    /// triangle order `order` (a permutation of its triangles; the triangles themselves keep
    /// their places). With `order` the Morton order of [`crate::partition::triangle_order`],
    /// vertices near each other in space get near numbers: the level-0 samples of every level
    /// read their corners' positions and ids by vertex number, in Morton order, and with the
    /// importer's numbering (a scan's, say) each such read missed the caches. The Stanford
    /// dragon bakes about 6 % faster (docs/BENCHMARKS.md, thirteenth session).
    pub fn numbered_by(self, order: &[u32]) -> WeldedMesh {
        let (vertices, positions) = (self.positions.len(), self.position_count);
        let (mut vertex_new, mut position_new) = (vec![u32::MAX; vertices], vec![u32::MAX; positions]);
        let (mut vertex_old, mut numbered) = (Vec::with_capacity(vertices), 0u32);
        let corners = order.iter().flat_map(|&t| &self.indices[3 * t as usize..3 * t as usize + 3]);
        // Vertices no triangle uses (welding can leave some) follow, in their old order. Every
        // position id is some vertex's, so all of them are numbered here.
        for v in corners.copied().chain(0..vertices as u32) {
            if vertex_new[v as usize] == u32::MAX {
                vertex_new[v as usize] = vertex_old.len() as u32;
                vertex_old.push(v);
                let p = self.position_ids[v as usize] as usize;
                if position_new[p] == u32::MAX {
                    position_new[p] = numbered;
                    numbered += 1;
                }
            }
        }
        WeldedMesh {
            grid_positions: gather_copy(&self.grid_positions, &vertex_old),
            positions: gather_copy(&self.positions, &vertex_old),
            position_ids: vertex_old
                .par_iter()
                .map(|&v| position_new[self.position_ids[v as usize] as usize])
                .collect(),
            normals: self.normals.as_deref().map(|n| gather_copy(n, &vertex_old)),
            uvs: self.uvs.as_deref().map(|u| gather_copy(u, &vertex_old)),
            materials: if self.materials.len() == vertices {
                gather_copy(&self.materials, &vertex_old)
            } else {
                self.materials
            },
            indices: self.indices.par_iter().map(|&v| vertex_new[v as usize]).collect(),
            ..self
        }
    }
}

/// `values` at `places`, in that order.
fn gather_copy<T: Copy + Send + Sync>(values: &[T], places: &[u32]) -> Vec<T> {
    places.par_iter().map(|&p| values[p as usize]).collect()
}

/// The UV quantization covering `uvs`.
pub fn uv_quant(uvs: &[[f32; 2]]) -> UvQuant {
    let mut min = [f32::INFINITY; 2];
    let mut max = [f32::NEG_INFINITY; 2];
    for uv in uvs {
        for k in 0..2 {
            min[k] = min[k].min(uv[k]);
            max[k] = max[k].max(uv[k]);
        }
    }
    if uvs.is_empty() {
        return UvQuant { min: [0.0; 2], extent: [0.0; 2] };
    }
    UvQuant { min, extent: [max[0] - min[0], max[1] - min[1]] }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles sharing an edge, with different UVs on the shared vertices; with `third`,
    /// a third triangle of another material on that edge's second copy.
    fn seamed_pair(third: bool) -> SourceMesh {
        let mut mesh = SourceMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0, 1.0, 0.0],
            ],
            uvs: Some(vec![[0.0, 0.0], [0.5, 0.0], [0.0, 0.5], [0.6, 0.0], [0.0, 0.6], [1.0, 1.0]]),
            normals: None,
            indices: vec![0, 1, 2, 3, 5, 4],
            materials: vec![0, 0],
            degenerate_dropped: 0,
        };
        if third {
            mesh.positions.push([2.0, 0.0, 1.0]);
            mesh.uvs.as_mut().unwrap().push([0.2, 0.2]);
            mesh.indices.extend([3, 6, 5]);
            mesh.materials.push(1);
        }
        mesh
    }

    #[test]
    fn seams_stay_apart_but_share_position_ids() {
        let w = weld(&seamed_pair(false), &BakeSettings::default()).unwrap();
        assert_eq!(w.grid_positions.len(), 6);
        assert_eq!(w.position_count, 4);
        // Vertices share a position id exactly when they share a grid point.
        for a in 0..6 {
            for b in 0..6 {
                assert_eq!(w.position_ids[a] == w.position_ids[b], w.grid_positions[a] == w.grid_positions[b]);
            }
        }
        // The shared edge (1,0,0)-(0,1,0) is used by both triangles through different vertices.
        let pos = |t: usize, k: usize| w.position_ids[w.indices[3 * t + k] as usize];
        let edge = |t: usize| [pos(t, 0), pos(t, 1), pos(t, 2)];
        let shared = edge(0).iter().filter(|p| edge(1).contains(p)).count();
        assert_eq!(shared, 2);
    }

    #[test]
    fn numbering_by_an_order_keeps_every_triangle_and_seam() {
        // The seamed pair, plus a third triangle, numbered in another order.
        let mesh = seamed_pair(true);
        let w = weld(&mesh, &BakeSettings::default()).unwrap();
        let order = [2, 0, 1];
        let n = weld(&mesh, &BakeSettings::default()).unwrap().numbered_by(&order);
        // Every triangle keeps its place, its corners' attributes and its seams.
        let corner = |m: &WeldedMesh, s: usize| {
            let v = m.indices[s] as usize;
            (m.grid_positions[v], m.positions[v], m.uvs.as_ref().unwrap()[v], m.materials[v])
        };
        assert_eq!(w.indices.len(), n.indices.len());
        for s in 0..w.indices.len() {
            assert_eq!(corner(&w, s), corner(&n, s));
            for r in 0..w.indices.len() {
                let same =
                    |m: &WeldedMesh| m.position_ids[m.indices[s] as usize] == m.position_ids[m.indices[r] as usize];
                assert_eq!(same(&w), same(&n), "corners {s} and {r}");
            }
        }
        assert_eq!(n.position_count, w.position_count);
        // Vertices and positions are numbered by first use in `order`: 0, 1, 2, ... in turn.
        let firsts = |ids: Vec<u32>| {
            let mut seen = Vec::new();
            for i in ids {
                if !seen.contains(&i) {
                    seen.push(i);
                }
            }
            seen
        };
        let corners: Vec<usize> = order.iter().flat_map(|&t| 3 * t as usize..3 * t as usize + 3).collect();
        let vertices = firsts(corners.iter().map(|&s| n.indices[s]).collect());
        assert_eq!(vertices, (0..vertices.len() as u32).collect::<Vec<_>>());
        let positions = firsts(corners.iter().map(|&s| n.position_ids[n.indices[s] as usize]).collect());
        assert_eq!(positions, (0..n.position_count as u32).collect::<Vec<_>>());
    }

    #[test]
    fn materials_split_vertices() {
        let mesh = SourceMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
            indices: vec![0, 1, 2, 1, 3, 2],
            materials: vec![0, 1],
            ..Default::default()
        };
        let w = weld(&mesh, &BakeSettings::default()).unwrap();
        assert!(w.multi_material);
        assert_eq!(w.grid_positions.len(), 6, "the two shared vertices are split by material");
        assert_eq!(w.position_count, 4);
        for t in 0..2 {
            let m: Vec<u32> = w.indices[3 * t..3 * t + 3].iter().map(|&v| w.materials[v as usize]).collect();
            assert!(m.iter().all(|&x| x == t as u32));
        }
    }

    #[test]
    fn duplicates_weld_and_grid_degenerates_drop() {
        let mesh = SourceMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [1e-9, 0.0, 0.0]],
            indices: vec![0, 1, 2, 3, 2, 0, 0, 4, 2],
            materials: vec![0, 0, 0],
            ..Default::default()
        };
        let w = weld(&mesh, &BakeSettings::default()).unwrap();
        assert_eq!(w.grid_positions.len(), 3);
        // The second triangle welds into a rotation of the first: a copy, dropped.
        assert_eq!(w.indices.len(), 3);
        assert_eq!(w.degenerate_dropped, 2);
    }

    #[test]
    fn exact_copies_drop_and_two_sided_or_differently_shaded_ones_stay() {
        let quad = |normals: Vec<[f32; 3]>, indices: Vec<u32>| {
            let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]];
            let materials = vec![0; indices.len() / 3];
            let mesh = SourceMesh { positions, normals: Some(normals), indices, materials, ..Default::default() };
            weld(&mesh, &BakeSettings::default()).unwrap()
        };
        let up = vec![[0.0, 0.0, 1.0]; 4];
        // Two triangles, each again rotated, then the first once more: three copies dropped.
        let w = quad(up.clone(), vec![0, 1, 2, 1, 3, 2, 1, 2, 0, 3, 2, 1, 0, 1, 2]);
        assert_eq!((w.indices.len(), w.degenerate_dropped), (6, 3));
        // The opposite winding (a two-sided sheet) stays.
        let w = quad(up, vec![0, 1, 2, 0, 2, 1]);
        assert_eq!((w.indices.len(), w.degenerate_dropped), (6, 0));
        // The same positions with other normals (other welded vertices) stay.
        let mut normals = vec![[0.0, 0.0, 1.0]; 4];
        normals[3] = [0.0, 0.0, -1.0];
        let mesh = SourceMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
            normals: Some(normals),
            indices: vec![0, 1, 2, 0, 3, 2],
            materials: vec![0, 0],
            ..Default::default()
        };
        let w = weld(&mesh, &BakeSettings::default()).unwrap();
        assert_eq!((w.indices.len(), w.degenerate_dropped), (6, 0));
    }

    #[test]
    fn grid_welding_merges_copies_by_grid_point() {
        let mesh = SourceMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
            normals: Some(vec![[0.0, 0.0, 1.0]; 4]),
            indices: vec![0, 1, 2, 1, 3, 2],
            materials: vec![0, 1],
            ..Default::default()
        };
        let settings = BakeSettings::default();
        let w = weld(&mesh, &settings).unwrap();
        let all: Vec<u32> = (0..w.grid_positions.len() as u32).collect();
        let half = w.indices.len() / 2;
        // Each triangle carried on its own, as two top clusters are.
        let mut merged = GridMesh { normals: Some(Vec::new()), ..Default::default() };
        merged.append(&GridMesh::extract(&w, &all, w.indices[..half].to_vec()));
        merged.append(&GridMesh::extract(&w, &all, w.indices[half..].to_vec()));
        let again = weld_grid(&merged, &settings, (w.grid, w.uv), w.multi_material);
        assert_eq!(again.grid_positions, w.grid_positions, "the copies weld back into one vertex each");
        assert_eq!(again.indices, w.indices);
        assert_eq!(again.position_count, w.position_count);
        assert_eq!(again.materials, w.materials);
    }
}
