//! The discrete-LOD alternative of the benchmarks (`preview --bench` on the GPU, `mres bench`'s
//! view cost on the CPU): the file's level-0 mesh welded by vertex (grid position, normal, UV),
//! then simplified with meshoptimizer (`simplify_with_attributes`, the baker's attribute
//! weights; permissive across seams where a halving stalls) to half the triangles per level,
//! each level with its object-space error: the two-sided distance between the level and the
//! original, measured as the validator measures a DAG cut (`crate::distance`: every triangle's
//! centroid and edge midpoints, both ways), made monotone. Both sides of the comparison are then
//! honest, and compared at the same measure. A renderer picks one level per instance by the
//! same screen-space error rule as the DAG (coarsest level whose projected error is ≤ τ at the
//! instance's nearest point).

use crate::distance::{two_sided_with, Surface};
use anyhow::{Context as _, Result};
use mres_format::{MresFile, FLAG_NORMALS, FLAG_UVS, NO_GROUP};
use mres_geom::edges::rotated_to_least;

/// One level of the chain: a range of the shared index buffer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChainLevel {
    /// First index in [`LodChain::indices`].
    pub first_index: u32,
    /// Indices of the level (3 per triangle).
    pub index_count: u32,
    /// Object-space error (0 for the original).
    pub error: f32,
}

/// A welded mesh and its simplified levels, finest first.
#[derive(Clone, Debug)]
pub struct LodChain {
    /// Positions (object space), shared by all levels.
    pub positions: Vec<[f32; 3]>,
    /// Indices of all levels, one after the other.
    pub indices: Vec<u32>,
    /// The levels, finest (the original) first.
    pub levels: Vec<ChainLevel>,
}

impl LodChain {
    /// Builds the chain from `file`'s level-0 clusters: halves the triangle count per level
    /// until fewer than `min_triangles` remain, simplification stalls, or 20 levels exist.
    /// Each level's error is measured with at most `max_samples` points per direction
    /// (`usize::MAX`: every sample, as the validator measures).
    pub fn build(file: &MresFile, min_triangles: usize, max_samples: usize) -> Result<LodChain> {
        let Level0 { positions, attributes, base } = Level0::of(file)?;
        let halve = Halving::new(&positions, &attributes)?;
        let mut indices = base.clone();
        let mut levels = vec![ChainLevel { first_index: 0, index_count: base.len() as u32, error: 0.0 }];
        let triangles = |indices: &[u32]| -> Vec<[[f64; 3]; 3]> {
            indices.chunks_exact(3).map(|t| [0, 1, 2].map(|k| positions[t[k] as usize].map(f64::from))).collect()
        };
        let original = Surface::new(triangles(&base));
        let mut current = base;
        let mut error = 0.0f32;
        while current.len() / 3 >= min_triangles.max(2) && levels.len() < 20 {
            let next = halve.run(&current);
            if stalls(&next, &current) {
                break;
            }
            // Measured against the original (rounded up to f32), monotone.
            let measured = two_sided_with(&triangles(&next), &original, max_samples).max;
            let rounded = measured as f32;
            let rounded = if (rounded as f64) < measured { rounded.next_up() } else { rounded };
            error = error.max(rounded);
            levels.push(ChainLevel { first_index: indices.len() as u32, index_count: next.len() as u32, error });
            indices.extend_from_slice(&next);
            current = next;
        }
        Ok(LodChain { positions, indices, levels })
    }
}

/// One level's simplification: half the triangles, attributes weighted where the file has them.
struct Halving<'a> {
    adapter: meshopt::VertexDataAdapter<'a>,
    attributes: &'a [f32],
    weights: Vec<f32>,
    /// No vertex is locked (an empty list would be read as one: the binding passes its pointer).
    unlocked: Vec<bool>,
}

impl<'a> Halving<'a> {
    fn new(positions: &'a [[f32; 3]], attributes: &'a [f32]) -> Result<Halving<'a>> {
        let adapter =
            meshopt::VertexDataAdapter::new(meshopt::typed_to_bytes(positions), 12, 0).context("vertex adapter")?;
        let weights = vec![ATTRIBUTE_WEIGHT; attributes.len() / positions.len().max(1)];
        Ok(Halving { adapter, attributes, weights, unlocked: vec![false; positions.len()] })
    }

    /// `current` simplified to about half its triangles; where the seams stop that, across
    /// them (as the baker's stuck groups are), so that the chain gets as coarse as the DAG's top.
    fn run(&self, current: &[u32]) -> Vec<u32> {
        let target = (current.len() / 2 / 3 * 3).max(3);
        if self.weights.is_empty() {
            return meshopt::simplify(current, &self.adapter, target, 1.0, meshopt::SimplifyOptions::None, None);
        }
        let simplify = |options| {
            let (attributes, weights, stride) = (self.attributes, &self.weights[..], self.weights.len() * 4);
            let (adapter, unlocked) = (&self.adapter, &self.unlocked[..]);
            meshopt::simplify_with_attributes_and_locks(
                current, adapter, attributes, weights, stride, unlocked, target, 1.0, options, None,
            )
        };
        let regular = simplify(meshopt::SimplifyOptions::None);
        if stalls(&regular, current) {
            simplify(meshopt::SimplifyOptions::Permissive)
        } else {
            regular
        }
    }
}

/// Whether a level `next` simplified from `current` keeps too much to be a level: over 90 %.
fn stalls(next: &[u32], current: &[u32]) -> bool {
    next.is_empty() || next.len() * 10 > current.len() * 9
}

/// Weight of each attribute component (normal xyz, UV scaled to the file's UV range) against
/// positions in the chain's simplification: the baker's default `normal_weight` and
/// `uv_weight`, so that the chain keeps the attributes' seams and shading as the DAG does.
const ATTRIBUTE_WEIGHT: f32 = 0.5;

/// A file's level-0 mesh, welded by vertex (grid position, normal and UV: a seam keeps its
/// copies, as a shipped LOD chain's mesh does; welded by position alone, the chain simplified
/// across the normal seams of hard-edged parts the DAG keeps, and drew about half the triangles
/// the attribute-aware chain draws of the flight helmet: docs/BENCHMARKS.md "View cost").
struct Level0 {
    positions: Vec<[f32; 3]>,
    /// Per vertex, its normal then its UV scaled to the file's UV range, where the file has them.
    attributes: Vec<f32>,
    base: Vec<u32>,
}

impl Level0 {
    /// The level-0 mesh in a canonical order: vertices by (grid position, attribute bits),
    /// each triangle rotated to start at its least vertex (winding kept), triangles sorted. The
    /// chain then depends on the level-0 surface alone, not on how the baker laid its clusters
    /// into pages: in file order, meshoptimizer's simplification (and the sample stride of the
    /// level measure) followed the page layout, and two bakes with the same level 0 gave chains
    /// 20–35 % apart in the view cost (docs/BENCHMARKS.md "View cost").
    fn of(file: &MresFile) -> Result<Level0> {
        let uv = file.header.uv;
        let scaled =
            |t: [f32; 2]| [0, 1].map(|k| if uv.extent[k] > 0.0 { (t[k] - uv.min[k]) / uv.extent[k] } else { 0.0 });
        // A vertex's key: grid position and attribute bits (normal, then scaled UV).
        let mut corners: Vec<Key> = Vec::new();
        for (p, info) in file.pages.iter().enumerate() {
            let raw = file.page(p as u32).with_context(|| format!("page {p}"))?;
            for c in info.first_cluster..info.first_cluster + info.cluster_count {
                if file.clusters[c as usize].own_group != NO_GROUP {
                    continue;
                }
                let d = file.decode_cluster(&raw, c).with_context(|| format!("page {p}"))?;
                let key = |v: usize| {
                    let normal = d.normals.get(v).into_iter().flatten().copied();
                    let uv = d.uvs.get(v).map(|&t| scaled(t)).into_iter().flatten();
                    let mut row = [0u32; 5];
                    for (slot, x) in row.iter_mut().zip(normal.chain(uv)) {
                        *slot = x.to_bits();
                    }
                    (d.positions[v], row)
                };
                corners.extend(d.indices.iter().map(|&i| key(i as usize)));
            }
        }
        // Canonical vertex numbers: the rank of the vertex's key.
        let mut keys = corners.clone();
        keys.sort_unstable();
        keys.dedup();
        let id = |k: &Key| keys.binary_search(k).unwrap_or(0) as u32;
        let mut triangles: Vec<[u32; 3]> =
            corners.chunks_exact(3).map(|t| rotated_to_least([id(&t[0]), id(&t[1]), id(&t[2])])).collect();
        triangles.sort_unstable();
        let has = |flag: u32| file.header.flags & flag != 0;
        let width = 3 * usize::from(has(FLAG_NORMALS)) + 2 * usize::from(has(FLAG_UVS));
        let positions = keys.iter().map(|k| file.header.grid.decode(k.0)).collect();
        let attributes = keys.iter().flat_map(|k| k.1[..width].iter().map(|&b| f32::from_bits(b))).collect();
        Ok(Level0 { positions, attributes, base: triangles.concat() })
    }
}

/// A level-0 vertex: its grid position and its attributes' bits (see [`Level0::of`]).
type Key = ([i32; 3], [u32; 5]);
