//! Foliage keeps its area (`preserve_area`, docs/INVARIANTS.md §4): where a group's
//! simplification removes small open parts (cards, leaves), the open parts it keeps are grown
//! about their own centre so that the group's open-part area stays about what it was.
//!
//! Every vertex of an upper level is a vertex of the welded mesh, so the grown parts' vertices
//! are made before the build: each vertex of a small open part gets [`RUNGS`] copies, rung `r`
//! scaled by 2^(r/2) about its part's area centroid (so one rung doubles a part's area, what a
//! level that halves its triangles by removing half the cards loses). A group moves the parts
//! it may grow (no vertex shared with another group) up the whole rungs that stay below its
//! input's open-part area, and some of them one rung more, to come nearest to it. The grown
//! triangles are measured against the original surface like any other, so the stored errors
//! stay honest: they grow with the dilation, which is the price of the coverage.
//! (Nanite's "preserve area" grows open borders instead; meshoptimizer has no such option.)

use crate::settings::{BakeSettings, PreserveArea};
use crate::weld::{Ladder, WeldedMesh, NO_PART as NONE};
use mres_geom::edges::{edge_ends, edge_key};
use mres_geom::parts::triangle_area;

/// Copies per vertex of a small open part: up to 2^(RUNGS/2) = 16 × its size, 256 × its area.
pub const RUNGS: u8 = 8;

/// Most triangles of a part that grows: foliage cards and leaves, not walls or terrain.
pub const SMALL_PART: usize = 64;

/// With `preserve_area = "auto"`, the share of a mesh's surface area in small open parts from
/// which they grow: a card field or a tree's leaves (90-100 %), not a scene with a few
/// decals or open sheets (of the 23 inputs of docs/BENCHMARKS.md the card fields have 100 %,
/// the terrarium 10 %, the rooms 3.9 %, the pirate 1.5 %, the rest none).
pub const AUTO_SHARE: f64 = 0.5;

/// `mesh` ready for the levels: with a [`Ladder`] where `settings.preserve_area` asks for one
/// (for `Auto`, where its small open parts hold at least [`AUTO_SHARE`] of its area).
/// `edges`: the mesh's edge keys, sorted, where the caller has them (else they are made here).
pub fn prepare(mesh: WeldedMesh, settings: &BakeSettings, edges: Option<&[u64]>) -> WeldedMesh {
    if settings.preserve_area == PreserveArea::Off {
        return mesh;
    }
    let made;
    let edges = match edges {
        Some(e) => e,
        None => {
            made = mres_geom::edges::sorted_edge_keys(&mesh.indices, |v| mesh.position_ids[v as usize]);
            &made[..]
        }
    };
    let growing = growing_parts(&mesh, edges);
    let share = growing.area / growing.total_area.max(f64::MIN_POSITIVE);
    let grow = settings.preserve_area == PreserveArea::On || share >= AUTO_SHARE;
    tracing::info!(share, grow, setting = ?settings.preserve_area, "small open parts (preserve_area)");
    if grow {
        with_ladder(mesh, &growing)
    } else {
        mesh
    }
}

/// `mesh` with a [`Ladder`] for its `growing` parts: copies of their vertices appended, each
/// with a position id of its own, on the mesh's grid. A grown part may reach beyond the
/// mesh's bounds: grid coordinates are any i32 (docs/FORMAT.md, cluster positions).
fn with_ladder(mut mesh: WeldedMesh, growing: &Growing) -> WeldedMesh {
    let vertices = mesh.positions.len();
    let part: Vec<u32> = (0..vertices).map(|v| growing.part[mesh.position_ids[v] as usize]).collect();
    let copies = part.iter().filter(|&&p| p != NONE).count() * RUNGS as usize;
    reserve(&mut mesh, copies);
    let mut base = Vec::with_capacity(vertices + copies);
    base.extend(0..vertices as u32);
    let mut ladder = Ladder { base, part, first_copy: vec![NONE; vertices], level0_positions: mesh.position_count };
    // A copy's position id: one per (position, rung), so that seam copies stay joined.
    let mut position_copy = vec![NONE; mesh.position_count];
    for v in 0..vertices {
        let part = ladder.part[v];
        if part == NONE {
            continue;
        }
        let p = mesh.position_ids[v] as usize;
        if position_copy[p] == NONE {
            position_copy[p] = mesh.position_count as u32;
            mesh.position_count += RUNGS as usize;
        }
        ladder.first_copy[v] = mesh.positions.len() as u32;
        let centre = growing.centre[part as usize];
        for r in 1..=RUNGS {
            let scale = 2f64.powf(f64::from(r) / 2.0);
            let grown = [0, 1, 2].map(|k| (centre[k] + (f64::from(mesh.positions[v][k]) - centre[k]) * scale) as f32);
            let q = mesh.grid.quantize(grown);
            copy_vertex(&mut mesh, v, q, position_copy[p] + u32::from(r) - 1);
            ladder.base.push(v as u32);
        }
    }
    mesh.ladder = Some(ladder);
    mesh
}

/// Room for `copies` more vertices in every per-vertex array of `mesh` (exactly: the copies
/// outnumber the level-0 vertices eightfold, so growing by doubling would overshoot).
fn reserve(mesh: &mut WeldedMesh, copies: usize) {
    mesh.grid_positions.reserve_exact(copies);
    mesh.positions.reserve_exact(copies);
    mesh.position_ids.reserve_exact(copies);
    if let Some(n) = &mut mesh.normals {
        n.reserve_exact(copies);
    }
    if let Some(u) = &mut mesh.uvs {
        u.reserve_exact(copies);
    }
    mesh.materials.reserve_exact(copies);
}

/// Appends a copy of vertex `v` at grid point `q` with position id `id`.
fn copy_vertex(mesh: &mut WeldedMesh, v: usize, q: [i32; 3], id: u32) {
    mesh.grid_positions.push(q);
    mesh.positions.push(mesh.grid.decode(q));
    mesh.position_ids.push(id);
    if let Some(n) = &mut mesh.normals {
        n.push(n[v]);
    }
    if let Some(u) = &mut mesh.uvs {
        u.push(u[v]);
    }
    if mesh.materials.len() > v {
        mesh.materials.push(mesh.materials[v]);
    }
}

/// The parts that grow: per position id, its part's id or NONE, and per part id its area
/// centroid; their area and the mesh's.
struct Growing {
    part: Vec<u32>,
    centre: Vec<[f64; 3]>,
    area: f64,
    total_area: f64,
}

/// The connected parts (by position) of at most [`SMALL_PART`] triangles with an open edge
/// (one used by a single triangle); `edges` are the mesh's edge keys, sorted.
fn growing_parts(mesh: &WeldedMesh, edges: &[u64]) -> Growing {
    let id = |v: u32| mesh.position_ids[v as usize];
    let n = mesh.position_count;
    let once = |r: &&[u64]| r.len() == 1;
    if !edges.chunk_by(|a, b| a == b).any(|r| once(&r)) {
        // Closed: no part grows (most meshes; the passes below would cost a scan's bake 1-4 %).
        return Growing { part: vec![NONE; n], centre: Vec::new(), area: 0.0, total_area: 1.0 };
    }
    let mut sets = mesh.part_sets(n);
    let (mut triangles, mut open) = (vec![0usize; n], vec![false; n]);
    let (mut area, mut moment) = (vec![0.0f64; n], vec![[0.0f64; 3]; n]);
    for t in mesh.indices.chunks_exact(3) {
        let root = sets.find(id(t[0])) as usize;
        let p = [0, 1, 2].map(|k| mesh.positions[t[k] as usize].map(f64::from));
        let a = triangle_area(p);
        triangles[root] += 1;
        area[root] += a;
        for k in 0..3 {
            moment[root][k] += a * (p[0][k] + p[1][k] + p[2][k]) / 3.0;
        }
    }
    for run in edges.chunk_by(|a, b| a == b).filter(once) {
        open[sets.find(edge_ends(run[0])[0]) as usize] = true;
    }
    let mut ids = vec![NONE; n];
    let (mut centre, mut growing_area) = (Vec::new(), 0.0);
    for root in 0..n {
        if open[root] && triangles[root] <= SMALL_PART && area[root] > 0.0 {
            ids[root] = centre.len() as u32;
            centre.push(moment[root].map(|m| m / area[root]));
            growing_area += area[root];
        }
    }
    let part = (0..n as u32).map(|p| ids[sets.find(p) as usize]).collect();
    Growing { part, centre, area: growing_area, total_area: area.iter().sum() }
}

/// Grows the small open parts of a group's simplification `out` (welded ids; `needed`, its
/// edges that need an open-border mark, follows) so that the open-part area is about that of
/// its `input` again. Only parts with no `locked` vertex move (a locked vertex may be another
/// group's too); all of a part's vertices move the same number of rungs. Returns whether
/// anything moved.
pub fn grow(
    mesh: &WeldedMesh,
    input: &[u32],
    out: &mut [u32],
    needed: &mut [u64],
    locked: impl Fn(u32) -> bool,
) -> bool {
    let Some(ladder) = &mesh.ladder else { return false };
    // A part with a locked vertex in the output stays as it is.
    let mut fixed: Vec<u32> =
        out.iter().filter(|&&v| ladder.part_of(v) != NONE && locked(v)).map(|&v| ladder.part_of(v)).collect();
    fixed.sort_unstable();
    fixed.dedup();
    let moves = |p: u32| p != NONE && fixed.binary_search(&p).is_err();
    let climbs = climbs(mesh, ladder, input, out, moves);
    if climbs.is_empty() {
        return false;
    }
    let climb = |v: u32| {
        let by = climbs.binary_search_by_key(&ladder.part_of(v), |c| c.0).ok()?;
        let to = (i32::from(ladder.rung_of(v)) + climbs[by].1).clamp(0, i32::from(RUNGS)) as u8;
        Some(ladder.at(v, to))
    };
    move_up(mesh, out, needed, climb);
    true
}

/// The rungs each part of `out` that `moves` (by part id) climbs, sorted by part, for the
/// open-part area of `out` to be about that of `input` (one rung doubles a part's area): all
/// of them the whole rungs that stay below the target, then one more for as many parts (in
/// part order) as bring the sum nearest to it. Empty for none.
fn climbs(
    mesh: &WeldedMesh,
    ladder: &Ladder,
    input: &[u32],
    out: &[u32],
    moves: impl Fn(u32) -> bool,
) -> Vec<(u32, i32)> {
    let part = |t: &[u32]| ladder.part_of(t[0]);
    let area_of = |t: &[u32]| area_of(mesh, t);
    let before: f64 = input.chunks_exact(3).filter(|t| part(t) != NONE).map(area_of).sum();
    let mut areas: Vec<(u32, f64)> =
        out.chunks_exact(3).filter(|t| part(t) != NONE).map(|t| (part(t), area_of(t))).collect();
    areas.sort_by_key(|a| a.0);
    let mut parts: Vec<(u32, f64)> = Vec::new();
    for run in areas.chunk_by(|a, b| a.0 == b.0) {
        parts.push((run[0].0, run.iter().map(|a| a.1).sum()));
    }
    let kept: f64 = parts.iter().filter(|p| !moves(p.0)).map(|p| p.1).sum();
    parts.retain(|p| moves(p.0));
    let now: f64 = parts.iter().map(|p| p.1).sum();
    let target = before - kept;
    if now <= 0.0 || target <= 0.0 || (target / now - 1.0).abs() < 0.25 {
        return Vec::new();
    }
    let base = (target / now).log2().floor() as i32;
    let mut left = target - now * 2f64.powi(base);
    parts
        .iter()
        .map(|&(p, a)| {
            let more = a * 2f64.powi(base);
            let up = left >= 0.5 * more;
            if up {
                left -= more;
            }
            (p, base + i32::from(up))
        })
        .filter(|c| c.1 != 0)
        .collect()
}

/// Area of triangle `t` (welded ids) of `mesh`.
fn area_of(mesh: &WeldedMesh, t: &[u32]) -> f64 {
    triangle_area([0, 1, 2].map(|k| mesh.positions[t[k] as usize].map(f64::from)))
}

/// Replaces each vertex of `out` for which `moved` names another by it, and the edges of
/// `needed` (edge keys of position ids, sorted again) with it.
fn move_up(mesh: &WeldedMesh, out: &mut [u32], needed: &mut [u64], moved: impl Fn(u32) -> Option<u32>) {
    let id = |v: u32| mesh.position_ids[v as usize];
    let mut position_map: Vec<(u32, u32)> = Vec::new();
    for v in out.iter_mut() {
        if let Some(w) = moved(*v) {
            position_map.push((id(*v), id(w)));
            *v = w;
        }
    }
    position_map.sort_unstable();
    position_map.dedup();
    let map = |p: u32| position_map.binary_search_by_key(&p, |m| m.0).map_or(p, |i| position_map[i].1);
    for e in needed.iter_mut() {
        let [a, b] = edge_ends(*e);
        *e = edge_key(map(a), map(b));
    }
    needed.sort_unstable();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::{BakeSettings, PreserveArea};
    use crate::weld::weld;
    use mres_import::SourceMesh;

    /// Two unit cards (two triangles each) side by side, with their ladder.
    fn two_cards() -> WeldedMesh {
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for x in [0.0f32, 3.0] {
            let base = positions.len() as u32;
            positions.extend([[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x + 1.0, 1.0, 0.0], [x, 1.0, 0.0]]);
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
        let settings = BakeSettings { preserve_area: PreserveArea::On, ..BakeSettings::default() };
        prepare(weld(&SourceMesh::positions_only(positions, indices), &settings).unwrap(), &settings, None)
    }

    /// A closed box of side `side` at the origin (12 triangles) and one unit card beside it.
    fn box_and_card(side: f32) -> SourceMesh {
        let corner = |i: u32| [0, 1, 2].map(|k| if i >> k & 1 == 1 { side } else { 0.0 });
        let mut positions: Vec<[f32; 3]> = (0..8).map(corner).collect();
        let mut indices = vec![
            0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5,
        ];
        positions.extend([[-3.0, 0.0, 0.0], [-2.0, 0.0, 0.0], [-2.0, 1.0, 0.0], [-3.0, 1.0, 0.0]]);
        indices.extend([8, 9, 10, 8, 10, 11]);
        SourceMesh::positions_only(positions, indices)
    }

    #[test]
    fn auto_grows_only_where_small_open_parts_hold_most_of_the_area() {
        let grows = |side: f32, preserve_area: PreserveArea| {
            let settings = BakeSettings { preserve_area, ..BakeSettings::default() };
            prepare(weld(&box_and_card(side), &settings).unwrap(), &settings, None).ladder.is_some()
        };
        // The card (area 1) beside a box of area 6 side²: most of the area at side 0.2 (0.24),
        // a small share at side 1 (6).
        assert!(grows(0.2, PreserveArea::Auto));
        assert!(!grows(1.0, PreserveArea::Auto));
        assert!(grows(1.0, PreserveArea::On));
        assert!(!grows(0.2, PreserveArea::Off));
    }

    fn area(mesh: &WeldedMesh, indices: &[u32]) -> f64 {
        indices.chunks_exact(3).map(|t| area_of(mesh, t)).sum()
    }

    #[test]
    fn a_kept_card_grows_by_the_area_its_group_lost_unless_locked() {
        let mesh = two_cards();
        let ladder = mesh.ladder.as_ref().unwrap();
        assert_eq!(mesh.positions.len(), 8 * (1 + RUNGS as usize));
        assert_eq!(ladder.level0_positions, 8);
        let input = mesh.indices.clone();
        // The group keeps one card of two: it doubles (one rung), about its own centre.
        let kept: Vec<u32> = input[..6].to_vec();
        let mut out = kept.clone();
        let mut needed = vec![edge_key(mesh.position_ids[out[0] as usize], mesh.position_ids[out[1] as usize])];
        assert!(grow(&mesh, &input, &mut out, &mut needed, |_| false));
        let ratio = area(&mesh, &out) / area(&mesh, &kept);
        assert!((ratio - 2.0).abs() < 1e-3, "area ratio {ratio}");
        let centre = |t: &[u32]| {
            let n = t.len() as f32;
            [0, 1, 2].map(|k| t.iter().map(|&v| mesh.positions[v as usize][k]).sum::<f32>() / n)
        };
        let (a, b) = (centre(&out), centre(&kept));
        assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-3), "{a:?} {b:?}");
        // Its open-border mark moved to the grown copies.
        let ids = |v: u32| mesh.position_ids[v as usize];
        assert_eq!(needed, vec![edge_key(ids(out[0]), ids(out[1]))]);
        // A card with a locked vertex (another group's too) stays as it is.
        let mut out = kept.clone();
        assert!(!grow(&mesh, &input, &mut out, &mut Vec::new(), |v| v == kept[0]));
        assert_eq!(out, kept);
        // Nothing lost, nothing grows.
        let mut out = input.clone();
        assert!(!grow(&mesh, &input, &mut out, &mut Vec::new(), |_| false));
    }
}
