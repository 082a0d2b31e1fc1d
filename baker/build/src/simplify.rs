//! Simplify: reduce one group to about half its triangles with its border locked vertex by
//! vertex and open borders simplified along themselves (meshopt
//! `simplify_with_attributes_and_locks`, absolute error, normals and UVs weighted),
//! with a permissive and then a sloppy fallback when the group is stuck (as clusterlod does),
//! and the permissive run beside a regular one that folds (see [`simplify_group`]).

use crate::area;
use crate::open;
use crate::settings::BakeSettings;
use crate::weld::WeldedMesh;
use meshopt::{SimplifyOptions, VertexDataAdapter};
use mres_geom::edges::edge_ends;
use mres_geom::parts::{diagonals, UnionFind};

/// Which simplifier produced a group's result.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Method {
    /// Attribute-aware edge collapse that respects seams.
    Regular,
    /// Edge collapse allowed across attribute seams.
    Permissive,
    /// Whole small components removed (`meshopt_simplifyPrune`), for groups of many
    /// disconnected parts that cannot be simplified one by one (closed boxes, cards).
    Prune,
    /// Vertex clustering (topology not preserved), locks respected.
    Sloppy,
}

/// A group's simplified triangles, in the mesh's vertex ids.
pub struct Simplified {
    /// Triangle list into the welded mesh's vertices.
    pub indices: Vec<u32>,
    /// Object-space error meshopt reports for the collapse sequence.
    pub error: f32,
    /// The simplifier that reached the target.
    pub method: Method,
    /// The output's edges that need an open-border mark, sorted (see [`crate::open`]).
    pub needed: Vec<u64>,
    /// The output's new edges between two locked positions (chords, see [`crate::chords`]).
    pub chords: Vec<u64>,
    /// Whether open parts grew to keep the group's area (see [`crate::area`]).
    pub grown: bool,
}

/// What a group's simplification must keep: the welded vertices it must not move, and which
/// new edges between two locked positions (edge keys of position ids) it may add (see
/// [`crate::chords`]).
pub struct Locks<'a> {
    /// Whether a welded vertex is locked.
    pub vertex: &'a (dyn Fn(u32) -> bool + Sync),
    /// Whether a new edge between two locked positions is allowed.
    pub chord: &'a (dyn Fn(u64) -> bool + Sync),
}

/// The position ids of the `vertices` for which `locked` is true, sorted.
fn locked_positions(mesh: &WeldedMesh, vertices: &[u32], locked: impl Fn(u32) -> bool) -> Vec<u32> {
    let mut out: Vec<u32> = vertices.iter().filter(|&&v| locked(v)).map(|&v| mesh.position_ids[v as usize]).collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// Sloppy simplification estimates its error loosely; scale it (clusterlod does the same).
const SLOPPY_ERROR_FACTOR: f32 = 2.0;

/// A regular result whose error exceeds this fraction of the group's extent is a fold (see
/// [`simplify_group`]): the permissive run is tried too.
const FOLD: f32 = 0.1;

/// Attempts per method: after a result breaks the border or makes a non-manifold edge, the
/// offending positions are locked and the method runs again.
const REPAIR_ATTEMPTS: usize = 4;

/// Simplifies the triangle list `indices` (welded vertex ids, open-border `masks` per
/// triangle) with every vertex for which `locked` is true kept in place; open borders are
/// simplified along themselves. `None` when no simplifier gets below the stuck ratio with the
/// group's border intact and no new hole.
///
/// With `lenient` (every group of the level was stuck), an output edge used an odd number of
/// times may join any positions away from the group border: it becomes a marked open edge,
/// and the measured error accounts for any hole.
pub fn simplify_group(
    mesh: &WeldedMesh,
    indices: &[u32],
    masks: &[u8],
    locks: &Locks,
    settings: &BakeSettings,
    lenient: bool,
) -> Option<Simplified> {
    if indices.is_empty() {
        return None; // meshoptimizer asserts on a target above the input
    }
    let locked = locks.vertex;
    // Compact the group's vertices so that each group works on a small, local vertex array.
    let mut vertices: Vec<u32> = indices.to_vec();
    vertices.sort_unstable();
    vertices.dedup();
    let local: Vec<u32> = indices.iter().map(|v| vertices.binary_search(v).unwrap_or(0) as u32).collect();
    let positions: Vec<[f32; 3]> = vertices.iter().map(|&v| mesh.positions[v as usize]).collect();
    let (attributes, weights) = attributes(mesh, &vertices, settings);
    let bytes = meshopt::typed_to_bytes(&positions);
    let adapter = VertexDataAdapter::new(bytes, 12, 0).ok()?;
    let triangles = indices.len() / 3;
    let group = Group {
        mesh,
        vertices: &vertices,
        local: &local,
        positions: &positions,
        adapter: &adapter,
        attributes: &attributes,
        weights: &weights,
        limit: (triangles as f32 * settings.stuck_ratio) as usize,
        border: EdgeCounts {
            lenient,
            ..EdgeCounts::new(mesh, indices, masks, &locked_positions(mesh, &vertices, locked), locks.chord)
        },
    };
    // One method, its result repaired where it breaks the border (at most REPAIR_ATTEMPTS).
    let attempt = |method: Method| -> Option<Simplified> {
        let pinned = |v: u32| group.border.pinned.binary_search(&mesh.position_ids[v as usize]).is_ok();
        let mut locks: Vec<bool> = vertices.iter().map(|&v| locked(v) || pinned(v)).collect();
        let mut ratio = settings.simplify_ratio;
        for _ in 0..REPAIR_ATTEMPTS {
            let target = ((triangles as f32 * ratio) as usize).max(1) * 3;
            let (out, error) = group.run(method, &locks, target)?;
            if out.is_empty() || out.len() / 3 > group.limit || !error.is_finite() {
                return None;
            }
            match group.border.check(mesh, &out) {
                Ok((mut needed, chords)) => {
                    let mut out = out;
                    let grown = area::grow(mesh, indices, &mut out, &mut needed, locked);
                    return Some(Simplified { indices: out, error, method, needed, chords, grown });
                }
                Err(bad) => {
                    // Lock the offending edges' ends and their neighbours, and aim a little
                    // less low: such pinches come from the last collapses.
                    let mut lock_positions: Vec<u32> = bad.iter().flat_map(|&e| edge_ends(e)).collect();
                    lock_positions.sort_unstable();
                    let ring: Vec<u32> = indices
                        .chunks_exact(3)
                        .filter(|t| {
                            t.iter().any(|&v| lock_positions.binary_search(&mesh.position_ids[v as usize]).is_ok())
                        })
                        .flatten()
                        .map(|&v| mesh.position_ids[v as usize])
                        .collect();
                    lock_positions.extend(ring);
                    lock_positions.sort_unstable();
                    for (v, lock) in vertices.iter().zip(&mut locks) {
                        *lock |= lock_positions.binary_search(&mesh.position_ids[*v as usize]).is_ok();
                    }
                    ratio = (ratio + 0.1).min(settings.stuck_ratio - 0.05);
                }
            }
        }
        None
    };
    if let Some(regular) = attempt(Method::Regular) {
        // A fold: the regular run cannot collapse along an edge whose two triangles disagree
        // in winding (a wall meeting a floor, one of them flipped), nor move a position whose
        // vertices are not a clean seam (a wall with its own normals standing inside a floor),
        // and it reaches its target by folding one panel onto the other. The permissive run
        // collapses there; the smaller error is kept. (A floor and a wall of 19,200
        // triangles: 160 triangles at 5.7 against 150 at 9e-5 at the level where it folded.)
        // A lenient run with attributes tries it too: it runs because the group was stuck,
        // and non-manifold positions whose sheets have their own normals or UVs stay put in a
        // regular run (walls with normals crossing inside a floor: 0.59, 3.9 % of the
        // diagonal, against a permissive result below 1e-3).
        let folded = regular.error > FOLD * meshopt::simplify_scale(&adapter);
        if folded || (lenient && !weights.is_empty()) {
            if let Some(permissive) = attempt(Method::Permissive).filter(|p| p.error < regular.error) {
                return Some(permissive);
            }
        }
        return Some(regular);
    }
    for method in [Method::Permissive, Method::Prune, Method::Sloppy] {
        if method == Method::Permissive && weights.is_empty() {
            continue; // without attributes there are no seams to relax
        }
        if let Some(result) = attempt(method) {
            return Some(result);
        }
    }
    None
}

/// One group's simplification inputs.
struct Group<'a> {
    mesh: &'a WeldedMesh,
    /// Local vertex → mesh vertex.
    vertices: &'a [u32],
    /// Triangle list in local vertices.
    local: &'a [u32],
    positions: &'a [[f32; 3]],
    adapter: &'a VertexDataAdapter<'a>,
    attributes: &'a [f32],
    weights: &'a [f32],
    /// Most triangles a result may keep and still count as progress.
    limit: usize,
    border: EdgeCounts<'a>,
}

impl Group<'_> {
    /// Runs `method` with `locks`; returns the result in mesh vertex ids without triangles
    /// degenerate by position, and its object-space error.
    fn run(&self, method: Method, locks: &[bool], target: usize) -> Option<(Vec<u32>, f32)> {
        let (local, adapter) = (self.local, self.adapter);
        let stride = self.weights.len() * 4;
        // No `LockBorder`: the group border is locked vertex by vertex (`locks`), and open
        // borders collapse along themselves, as meshoptimizer does for unlocked borders.
        let base = SimplifyOptions::ErrorAbsolute;
        let mut error = 0.0f32;
        let result = match method {
            Method::Regular | Method::Permissive => {
                let options = if method == Method::Permissive { base | SimplifyOptions::Permissive } else { base };
                meshopt::simplify_with_attributes_and_locks(
                    local,
                    adapter,
                    self.attributes,
                    self.weights,
                    stride,
                    locks,
                    target,
                    f32::MAX,
                    options,
                    Some(&mut error),
                )
            }
            Method::Prune => {
                let (r, e) = prune_components(local, self.positions, locks, self.vertices, self.mesh, target);
                error = e;
                r
            }
            Method::Sloppy => {
                let r = meshopt::simplify_sloppy_with_locks(local, adapter, locks, target, f32::MAX, Some(&mut error));
                // Sloppy error is relative to the group's extent.
                error *= meshopt::simplify_scale(adapter) * SLOPPY_ERROR_FACTOR;
                r
            }
        };
        let mut out = Vec::with_capacity(result.len());
        for t in result.chunks_exact(3) {
            let g = [self.vertices[t[0] as usize], self.vertices[t[1] as usize], self.vertices[t[2] as usize]];
            let p = g.map(|v| self.mesh.position_ids[v as usize]);
            if p[0] != p[1] && p[1] != p[2] && p[0] != p[2] {
                out.extend_from_slice(&g);
            }
        }
        Some((out, error))
    }
}

/// Edge use counts by position, to check that a simplified group keeps its border exactly
/// and opens no hole inside: the local form of the crack-freedom invariant
/// (docs/INVARIANTS.md §1), which also says which output edges need an open-border mark.
struct EdgeCounts<'a> {
    /// Sorted (edge, uses, marked uses) of the group border: the input edges used an odd
    /// number of times unmarked (shared with another group, or a cell border) and every input
    /// edge between two locked positions (another group may use it too). Kept exactly.
    border: Vec<(u64, u32, u32)>,
    /// Locked positions of the group, sorted: an output must not add an edge between two
    /// unless `chord` allows it.
    locked: Vec<u32>,
    /// Whether the output may add this edge between two locked positions ([`Locks::chord`]).
    chord: &'a (dyn Fn(u64) -> bool + Sync),
    /// Positions on a marked input edge, sorted: the only ones an open output edge may join
    /// (the simplifier moves open-border vertices along the border, never opens a hole).
    open: Vec<u32>,
    /// Any position may be joined by an open output edge (see [`simplify_group`]).
    lenient: bool,
    /// Positions locked before the first run, sorted: the corners of each triangle whose
    /// three edges the group uses once each, one of them a border edge. Such a triangle
    /// stands alone in the group (half of a card split between groups), so collapsing a
    /// corner along its open edges would remove it and its border edge with it; the check
    /// would refuse that, and the repair that follows runs again aiming higher.
    pinned: Vec<u32>,
}

fn edge_keys(mesh: &WeldedMesh, indices: &[u32]) -> Vec<u64> {
    mres_geom::edges::sorted_edge_keys(indices, |v| mesh.position_ids[v as usize])
}

impl<'a> EdgeCounts<'a> {
    /// The border of the group `indices` whose triangles carry `masks`; `locked` tells the
    /// locked positions, `chord` which new edges between two of them are allowed.
    fn new(
        mesh: &WeldedMesh,
        indices: &[u32],
        masks: &[u8],
        locked: &[u32],
        chord: &'a (dyn Fn(u64) -> bool + Sync),
    ) -> EdgeCounts<'a> {
        let keys = edge_keys(mesh, indices);
        let marked = open::marked_edges(mesh, indices, masks);
        let marks = |e: u64| open::count(&marked, e);
        let is_locked = |p: u32| locked.binary_search(&p).is_ok();
        let border: Vec<(u64, u32, u32)> = keys
            .chunk_by(|a, b| a == b)
            .filter_map(|r| {
                let m = marks(r[0]);
                let unmarked_odd = (r.len() - m) % 2 == 1;
                (unmarked_odd || edge_ends(r[0]).iter().all(|&p| is_locked(p))).then_some((
                    r[0],
                    r.len() as u32,
                    m as u32,
                ))
            })
            .collect();
        let mut open: Vec<u32> = marked.iter().flat_map(|&e| edge_ends(e)).collect();
        open.sort_unstable();
        open.dedup();
        let pinned = pinned(mesh, indices, &keys, &border);
        EdgeCounts { border, locked: locked.to_vec(), chord, open, lenient: false, pinned }
    }

    /// True when the group shares no edge or position with anything else (or is lenient).
    fn isolated(&self) -> bool {
        self.lenient || (self.border.is_empty() && self.locked.is_empty())
    }

    /// The output's edges that need a mark and its chords (both sorted) if `out` uses every
    /// border edge as often as the input, adds no edge between two locked positions that
    /// `chord` refuses, and its other odd edges join open-border positions only; otherwise
    /// the offending edges (including border edges it lost).
    fn check(&self, mesh: &WeldedMesh, out: &[u32]) -> Result<(Vec<u64>, Vec<u64>), Vec<u64>> {
        let keys = edge_keys(mesh, out);
        let (mut bad, mut needed, mut chords) = (Vec::new(), Vec::new(), Vec::new());
        let mut seen = vec![false; self.border.len()];
        let all = |set: &[u32], e: u64| edge_ends(e).iter().all(|p| set.binary_search(p).is_ok());
        // Both lists are sorted: walk the border along the keys instead of searching it.
        let mut next = 0;
        for run in keys.chunk_by(|a, b| a == b) {
            let e = run[0];
            while next < self.border.len() && self.border[next].0 < e {
                next += 1;
            }
            let border = self.border.get(next).filter(|b| b.0 == e);
            if border.is_none() && all(&self.locked, e) {
                // A new edge between two locked positions (a chord).
                if !(self.chord)(e) {
                    bad.push(e);
                    continue;
                }
                chords.push(e);
            }
            match border {
                Some(&(_, uses, marks)) => {
                    seen[next] = true;
                    if uses != run.len() as u32 || marks > 1 {
                        bad.push(e);
                    } else if marks == 1 {
                        needed.push(e);
                    }
                }
                // A group that shares nothing (an isolated part, or the whole top) may open
                // any edge: no neighbour can crack, and the measured error sees a hole.
                None if run.len() % 2 == 1 && (all(&self.open, e) || self.isolated()) => needed.push(e),
                None if run.len() % 2 == 1 => bad.push(e),
                None => {}
            }
        }
        bad.extend(self.border.iter().zip(&seen).filter(|(_, s)| !**s).map(|(e, _)| e.0));
        if bad.is_empty() {
            Ok((needed, chords))
        } else {
            Err(bad)
        }
    }
}

/// The corners of the triangles of `indices` whose three edges are each used once among the
/// sorted edge `keys`, one of them in `border` (see [`EdgeCounts::pinned`]); sorted.
fn pinned(mesh: &WeldedMesh, indices: &[u32], keys: &[u64], border: &[(u64, u32, u32)]) -> Vec<u32> {
    let once = |e: u64| {
        let start = keys.partition_point(|&k| k < e);
        keys.get(start + 1) != Some(&e)
    };
    let on_border = |e: u64| border.binary_search_by_key(&e, |b| b.0).is_ok();
    let mut out = Vec::new();
    for t in indices.chunks_exact(3) {
        let p = [0, 1, 2].map(|k| mesh.position_ids[t[k] as usize]);
        let e = [0, 1, 2].map(|k| mres_geom::edges::edge_key(p[k], p[(k + 1) % 3]));
        if e.iter().all(|&e| once(e)) && e.iter().any(|&e| on_border(e)) {
            out.extend_from_slice(&p);
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Per-vertex attribute rows (normal xyz, uv normalized to the mesh's UV range) and weights.
fn attributes(mesh: &WeldedMesh, vertices: &[u32], settings: &BakeSettings) -> (Vec<f32>, Vec<f32>) {
    let mut weights = Vec::new();
    if mesh.normals.is_some() && settings.normal_weight > 0.0 {
        weights.extend_from_slice(&[settings.normal_weight; 3]);
    }
    if mesh.uvs.is_some() && settings.uv_weight > 0.0 {
        weights.extend_from_slice(&[settings.uv_weight; 2]);
    }
    let mut rows = Vec::with_capacity(vertices.len() * weights.len());
    if weights.is_empty() {
        return (rows, weights);
    }
    for &v in vertices {
        if let (Some(n), true) = (&mesh.normals, settings.normal_weight > 0.0) {
            rows.extend_from_slice(&n[v as usize]);
        }
        if let (Some(uv), true) = (&mesh.uvs, settings.uv_weight > 0.0) {
            let t = uv[v as usize];
            let scale = |k: usize| {
                if mesh.uv.extent[k] > 0.0 {
                    (t[k] - mesh.uv.min[k]) / mesh.uv.extent[k]
                } else {
                    0.0
                }
            };
            rows.extend_from_slice(&[scale(0), scale(1)]);
        }
    }
    (rows, weights)
}

/// Removes whole connected components without locked vertices, smallest first, until at most
/// `target` indices remain. The error is the largest removed component's bounding diagonal:
/// a part vanishes only once it projects below the threshold.
fn prune_components(
    local: &[u32],
    positions: &[[f32; 3]],
    locks: &[bool],
    vertices: &[u32],
    mesh: &WeldedMesh,
    target: usize,
) -> (Vec<u32>, f32) {
    // Components by position: union vertices of each triangle, and vertices sharing a position.
    let n = positions.len();
    let mut sets = UnionFind::new(n);
    for t in local.chunks_exact(3) {
        sets.union(t[0], t[1]);
        sets.union(t[1], t[2]);
    }
    let mut by_position: Vec<(u32, u32)> =
        (0..n as u32).map(|v| (mesh.position_ids[vertices[v as usize] as usize], v)).collect();
    by_position.sort_unstable();
    for run in by_position.chunk_by(|a, b| a.0 == b.0) {
        for w in run.windows(2) {
            sets.union(w[0].1, w[1].1);
        }
    }
    let root: Vec<u32> = (0..n as u32).map(|v| sets.find(v)).collect();
    // Per component: bounds, triangle count, locked.
    let diagonal = diagonals(&mut sets, positions.iter().enumerate().map(|(v, p)| (v as u32, p.map(f64::from))));
    let diagonal = |r: usize| diagonal[r] as f32;
    let mut locked = vec![false; n];
    let mut triangles = vec![0usize; n];
    for v in 0..n {
        locked[root[v] as usize] |= locks[v];
    }
    for t in local.chunks_exact(3) {
        triangles[root[t[0] as usize] as usize] += 1;
    }
    let mut candidates: Vec<usize> = (0..n).filter(|&r| triangles[r] > 0 && !locked[r]).collect();
    candidates.sort_by(|&a, &b| diagonal(a).total_cmp(&diagonal(b)).then(a.cmp(&b)));
    let mut removed = vec![false; n];
    let mut remaining = local.len();
    let mut error = 0.0f32;
    for r in candidates {
        // Keep at least one component: a group never vanishes entirely.
        if remaining <= target || remaining == triangles[r] * 3 {
            break;
        }
        removed[r] = true;
        remaining -= triangles[r] * 3;
        error = error.max(diagonal(r));
    }
    let kept = local.chunks_exact(3).filter(|t| !removed[root[t[0] as usize] as usize]).flatten().copied().collect();
    (kept, error)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::weld::weld;
    use mres_geom::edges::edge_key;
    use mres_import::SourceMesh;

    /// A row of 40 cards (quads of two triangles, apart from each other, slightly bent so
    /// that collapses have a cost); the last is a tenth of the others' size.
    fn cards() -> WeldedMesh {
        let (mut positions, mut indices) = (Vec::new(), Vec::new());
        for c in 0..40u32 {
            let (x, s) = (c as f32 * 2.0, if c == 39 { 0.1 } else { 1.0 });
            positions.extend([[x, 0.0, 0.0], [x + s, 0.0, 0.1 * s], [x + s, s, 0.0], [x, s, 0.1 * s]]);
            indices.extend([4 * c, 4 * c + 1, 4 * c + 2, 4 * c, 4 * c + 2, 4 * c + 3]);
        }
        weld(&SourceMesh::positions_only(positions, indices), &BakeSettings::default()).unwrap()
    }

    #[test]
    fn half_a_card_on_the_group_border_is_kept_without_a_repair() {
        let mesh = cards();
        let odd = crate::open::odd_of(&edge_keys(&mesh, &mesh.indices));
        // The group holds every card but the last one's second triangle, which another group
        // holds: the last card's diagonal is a group border, its ends locked.
        let group = mesh.indices[..mesh.indices.len() - 3].to_vec();
        let masks = crate::open::mark(&mesh, std::slice::from_ref(&group), &odd).remove(0);
        let last = &mesh.indices[mesh.indices.len() - 3..];
        let id = |v: u32| mesh.position_ids[v as usize];
        let diagonal = [id(last[0]), id(last[1])];
        let locked = |v: u32| diagonal.contains(&id(v));
        let chord = |_: u64| true;
        let locks = Locks { vertex: &locked, chord: &chord };
        let settings = BakeSettings::default();
        let s = simplify_group(&mesh, &group, &masks, &locks, &settings, false).expect("the group simplifies");
        // The lone half card keeps its border edge; the first run, aiming at half the
        // triangles, passes (a repair would aim at 60 %).
        let keys = edge_keys(&mesh, &s.indices);
        assert!(keys.contains(&edge_key(diagonal[0], diagonal[1])));
        let triangles = group.len() / 3;
        assert!(
            s.indices.len() / 3 <= (triangles as f32 * settings.simplify_ratio) as usize,
            "{} of {triangles}",
            s.indices.len() / 3
        );
    }
}
