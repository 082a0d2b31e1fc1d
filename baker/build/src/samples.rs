//! The level-0 samples each cluster stands for while errors are measured against the original
//! surface (docs/INVARIANTS.md §4): which points of the level-0 triangles a group's result is
//! measured from, how the members' samples are joined when their clusters are grouped, how a
//! group's samples are handed down to the clusters of its result, and how runs of them become
//! balls once they are small beside the error.
//!
//! Balls keep the upper levels cheap. Every level's groups together own every level-0
//! triangle, so without them each level would measure, sort and hand down the whole input
//! again (the top groups of the Stanford dragon: 866 K triangles each, one group per level, so
//! on one core). Where a cluster holds many more samples than triangles ([`GATHER_RATIO`]), a
//! run of them that fits in a sphere of radius at most [`BALL_FRACTION`] × the error becomes
//! one entry, measured at the sphere's centre with the radius added (distance to a surface
//! changes by at most the distance moved, so the bound holds for every point of its triangles,
//! not just the samples), at a cost of at most that fraction of the error.

use crate::weld::WeldedMesh;
use mres_geom::bvh::{Bvh, Triangle};
use rayon::prelude::*;
use std::sync::OnceLock;

/// A run of samples handed down becomes a ball when its enclosing sphere's radius is at most
/// this fraction of the error of the group it was handed down by (the next group's members'
/// error is at least that). It loosens a stored error by at most about this fraction.
/// Measured: see docs/BENCHMARKS.md (bake time).
pub const BALL_FRACTION: f64 = 0.2;

/// A cluster's samples are gathered into balls only where they are at least this many times
/// its triangles: at the upper levels, where every level would otherwise measure, sort and hand
/// down the whole input again. Below, where a ball would hold a few triangles, gathering would
/// cost more than it saves (the measure settles most of such samples by the previous query,
/// one distance each: `deviation::Last`). Measured: see docs/BENCHMARKS.md (bake time).
pub const GATHER_RATIO: usize = 32;

/// Joined lists longer than this are sorted on every thread by [`merge_owned`].
const PARALLEL_MERGE: usize = 64 * 1024;

/// The centroid's bit among a triangle's samples (see [`Samples::Triangle`]).
pub const CENTROID: u8 = 1 << 6;

/// Mark for a sample that was not measured (see [`assign_owned`]).
pub const NOT_FOUND: u32 = u32::MAX;

/// Mark for a sample of a part so small beside the group's error that it can raise no error
/// again (see `deviation::InputSide::measure`): its entry is handed to no cluster.
pub const VANISHED: u32 = u32::MAX - 1;

/// Level-0 samples a cluster stands for, with the Morton code of where they lie over the
/// mesh: the sort key, so that a group's samples come in spatial order (queries then start
/// near their answer, and runs of them form balls).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Owned {
    /// Morton code of the triangle's centroid (of the first triangle, for a ball).
    pub code: u32,
    /// Which points.
    pub samples: Samples,
}

/// The points an [`Owned`] stands for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Samples {
    /// Some samples of one level-0 triangle (welded vertex ids), as bits: corner k (bit k),
    /// the midpoint of edge k from corner k (bit 3 + k), the centroid (bit 6).
    Triangle([u32; 3], u8),
    /// Every point of some level-0 triangles, all within a sphere.
    Ball(Ball),
}

/// A sphere holding every point of some level-0 triangles (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ball {
    /// Centre, object coordinates.
    pub center: [f32; 3],
    /// Radius, rounded up (every point of the triangles is within it of `center`).
    pub radius: f32,
    /// A welded vertex of those triangles, of the largest connected part among them: its part
    /// size bounds the distance of the ball's points where their part vanished, and the
    /// outlier retries lock around it.
    pub at: u32,
}

impl Owned {
    /// A level-0 triangle's samples `bits`.
    pub fn triangle(code: u32, t: [u32; 3], bits: u8) -> Owned {
        Owned { code, samples: Samples::Triangle(t, bits) }
    }

    /// The triangle's welded ids, or the ball's `at` three times (what the measure's input
    /// side indexes by).
    pub fn corners(&self) -> [u32; 3] {
        match self.samples {
            Samples::Triangle(t, _) => t,
            Samples::Ball(b) => [b.at; 3],
        }
    }

    /// The ball, if it is one.
    pub fn ball(&self) -> Option<Ball> {
        match self.samples {
            Samples::Ball(b) => Some(b),
            Samples::Triangle(..) => None,
        }
    }

    /// The sample bits to measure: a ball is measured at its centre only.
    pub fn bits(&self) -> u8 {
        match self.samples {
            Samples::Triangle(_, bits) => bits,
            Samples::Ball(_) => CENTROID,
        }
    }

    /// The sort order: by code, then by corners. A ball's corners are its `at` three times,
    /// which no triangle has (degenerate triangles are dropped on import), so a ball never
    /// compares equal to a triangle; two balls that compare equal keep their order (stable
    /// sorts only), and the entries of one triangle, equal here, are joined whatever their
    /// order. The corners are compared only on equal codes (rarely: most codes differ).
    fn order(&self, other: &Owned) -> std::cmp::Ordering {
        self.code.cmp(&other.code).then_with(|| self.corners().cmp(&other.corners()))
    }
}

/// Sorts a cluster's samples (see [`Owned`]).
pub fn sort_owned(owned: &mut [Owned]) {
    owned.sort_unstable_by(Owned::order);
}

/// The level-0 samples of a group's members (their lists), sorted (so in Morton order), one
/// entry per triangle (the bits of one triangle owned by several members are joined) and per
/// ball.
pub fn merge_owned<'a>(lists: impl Iterator<Item = &'a [Owned]>) -> Vec<Owned> {
    let lists: Vec<&[Owned]> = lists.filter(|l| !l.is_empty()).collect();
    // One member's list is sorted and has one entry per triangle already (see
    // `keep_together`): what sorting and joining would give.
    if let [one] = lists[..] {
        return one.to_vec();
    }
    let mut all: Vec<Owned> = Vec::with_capacity(lists.iter().map(|l| l.len()).sum());
    for list in lists {
        all.extend_from_slice(list);
    }
    // Each member's list is sorted (see `assign_owned`, and level 0's): the stable sort merges
    // such runs instead of sorting from scratch, and on a total order it gives the same result
    // (on every thread for the large groups of the top levels).
    if all.len() > PARALLEL_MERGE {
        all.par_sort_by(Owned::order);
    } else {
        all.sort_by(Owned::order);
    }
    // In place: a triangle's entries are adjacent, the first one kept gets the bits of all.
    all.dedup_by(|next, kept| match (next.samples, &mut kept.samples) {
        (Samples::Triangle(t, bits), Samples::Triangle(k, kept_bits)) if t == *k => {
            *kept_bits |= bits;
            true
        }
        _ => false,
    });
    all
}

/// The indices of the bits set among the low seven of `mask`, ascending: the samples a
/// triangle's bits name (see [`Samples::Triangle`]), found without testing all seven.
pub fn set_bits(mask: u8) -> impl Iterator<Item = usize> {
    let mut rest = mask & 0x7f;
    std::iter::from_fn(move || {
        let b = rest.trailing_zeros() as usize;
        rest &= rest.wrapping_sub(1); // clears the lowest set bit
        (b < 8).then_some(b)
    })
}

/// The sample point of bit `b` of triangle `t` (see [`Samples::Triangle`]).
pub fn sample_point(t: &Triangle<f32>, b: usize) -> [f32; 3] {
    match b {
        0..=2 => t[b],
        3..=5 => [0, 1, 2].map(|k| (t[b - 3][k] + t[(b - 2) % 3][k]) * 0.5),
        _ => [0, 1, 2].map(|k| (t[0][k] + t[1][k] + t[2][k]) * (1.0 / 3.0)),
    }
}

/// Hands each level-0 sample of `owned` (the group's reference, in order) to a cluster of
/// `children` (the split of `output`, the group's result, whose stored error is `error`) within
/// `error` of it: the one holding the output triangle measuring found for it (`found`: per
/// sample, 7 per entry, see `deviation::Measured`), else one found by a search; a ball goes
/// whole, by its centre. The next level measures the sample against that cluster's group. A
/// sample must go to a cluster near itself, not just near its triangle: where a group border
/// later runs between two clusters, a level-0 triangle can straddle it, and its far corner would
/// be measured across the border. Every sample stays under exactly one pending cluster (those
/// measuring marked [`VANISHED`] are left out before: [`without_vanished`]). Each cluster's
/// samples are then gathered into balls (see `gather`).
pub fn assign_owned(
    mesh: &WeldedMesh,
    owned: &[Owned],
    (output, found): (&[u32], &[u32]),
    children: &[Vec<u32>],
    (error, part_size): (f32, &[f32]),
) -> Vec<Vec<Owned>> {
    let output_child = output_children(output, children);
    let point = |v: u32| mesh.positions[v as usize];
    let tris: Vec<Triangle<f32>> = output.chunks_exact(3).map(|t| [point(t[0]), point(t[1]), point(t[2])]).collect();
    // A corner the output kept was not measured: it goes with an output triangle using it.
    let id = |v: u32| mesh.position_ids[v as usize];
    let mut at_corner: rustc_hash::FxHashMap<u32, u32> = rustc_hash::FxHashMap::default();
    for (s, &v) in output.iter().enumerate() {
        at_corner.entry(id(v)).or_insert(s as u32 / 3);
    }
    let bvh: OnceLock<Bvh<f32>> = OnceLock::new();
    let close2 = error * error;
    // Not measured and not a kept corner: the output triangle nearest to it.
    let search =
        |p: [f32; 3], hint: usize| bvh.get_or_init(|| Bvh::new(&tris)).nearest_squared(&tris, p, close2 / 16.0, hint).1;
    let to = Destinations { output_child: &output_child, at_corner: &at_corner, search: &search };
    // Runs of a fixed size side by side (one group holds every level-0 sample at the top
    // levels), each handed down on its own and joined in order: the same for any thread count.
    let runs: Vec<Vec<Vec<Owned>>> = owned
        .par_chunks(HAND_DOWN_RUN)
        .enumerate()
        .map(|(r, run)| hand_down(mesh, run, &found[(7 * r * HAND_DOWN_RUN).min(found.len())..], &to, children.len()))
        .collect();
    let mut out = vec![Vec::new(); children.len()];
    for run in runs {
        for (list, more) in out.iter_mut().zip(run) {
            list.extend(more);
        }
    }
    let limit = BALL_FRACTION * error as f64;
    let gathered = |(list, c): (Vec<Owned>, &Vec<u32>)| {
        if dense(list.len(), c.len() / 3) {
            gather(mesh, list, limit, part_size)
        } else {
            list
        }
    };
    out.into_par_iter().zip(children).map(gathered).collect()
}

/// The samples of a group whose children will all be grouped together at the next level (the
/// level's only group, with few enough children for one group): they stay one list, given to
/// the first child (the others get none; the next group joins them all), gathered into balls
/// as [`assign_owned`] does, in fixed runs side by side. Handing every sample down to a child
/// only for the next group to sort them together again was, at the top levels, most of the
/// cost of a level beside the measure. `owned` is the group's (sorted), `output_triangles` its
/// result's triangle count, `error` its stored error.
pub fn keep_together(
    mesh: &WeldedMesh,
    owned: Vec<Owned>,
    output_triangles: usize,
    (error, part_size): (f32, &[f32]),
    children: usize,
) -> Vec<Vec<Owned>> {
    let limit = BALL_FRACTION * error as f64;
    let list = if dense(owned.len(), output_triangles) {
        let runs: Vec<Vec<Owned>> =
            owned.par_chunks(HAND_DOWN_RUN).map(|run| gather(mesh, run.to_vec(), limit, part_size)).collect();
        runs.concat()
    } else {
        owned
    };
    let mut out = vec![Vec::new(); children];
    if let Some(first) = out.first_mut() {
        *first = list;
    }
    out
}

/// Whether `samples` entries over `triangles` triangles are gathered into balls (see
/// [`GATHER_RATIO`]).
fn dense(samples: usize, triangles: usize) -> bool {
    samples >= GATHER_RATIO * triangles
}

/// Entries handed down together by one call of [`hand_down`]: a group of the lower levels
/// (about 2,000 entries) is one run, as before runs existed.
const HAND_DOWN_RUN: usize = 4096;

/// Where [`hand_down`] sends a sample: the child of each output triangle, the output triangle
/// of each kept corner's position, and the search for the rest.
struct Destinations<'a> {
    output_child: &'a [u32],
    at_corner: &'a rustc_hash::FxHashMap<u32, u32>,
    search: &'a (dyn Fn([f32; 3], usize) -> usize + Sync),
}

/// [`assign_owned`] for a run of entries `owned`, whose `found` slots start the given slice:
/// per child, its entries of the run, in order.
fn hand_down(mesh: &WeldedMesh, owned: &[Owned], found: &[u32], to: &Destinations, children: usize) -> Vec<Vec<Owned>> {
    let point = |v: u32| mesh.positions[v as usize];
    let id = |v: u32| mesh.position_ids[v as usize];
    let mut out = vec![Vec::new(); children];
    let mut bits = vec![0u8; children];
    let mut hint = usize::MAX;
    for (i, o) in owned.iter().enumerate() {
        let f = |b: usize| found.get(7 * i + b).copied().unwrap_or(NOT_FOUND);
        let (t, mask) = match o.samples {
            Samples::Ball(ball) => {
                hint = match f(6) {
                    NOT_FOUND => (to.search)(ball.center, hint),
                    f => f as usize,
                };
                out[to.output_child[hint] as usize].push(*o);
                continue;
            }
            Samples::Triangle(t, mask) => (t, mask),
        };
        let (mut touched, mut count) = ([0usize; 7], 0);
        for b in set_bits(mask) {
            // Looked up only for an unmeasured corner (most samples were measured).
            let kept = || if b < 3 { to.at_corner.get(&id(t[b])) } else { None };
            let nearest = match f(b) {
                NOT_FOUND if let Some(&k) = kept() => k as usize,
                NOT_FOUND => (to.search)(sample_point(&t.map(point), b), hint),
                f => f as usize,
            };
            hint = nearest;
            let c = to.output_child[nearest] as usize;
            if bits[c] == 0 {
                touched[count] = c;
                count += 1;
            }
            bits[c] |= 1 << b;
        }
        for &c in &touched[..count] {
            out[c].push(Owned::triangle(o.code, t, std::mem::take(&mut bits[c])));
        }
    }
    out
}

/// `owned` and its `found` slots (7 per entry) without the entries measuring marked
/// [`VANISHED`] (it fills all of an entry's slots): what is handed down.
pub fn without_vanished(owned: Vec<Owned>, found: Vec<u32>) -> (Vec<Owned>, Vec<u32>) {
    if !found.contains(&VANISHED) {
        return (owned, found);
    }
    let kept = owned.into_iter().zip(found.chunks_exact(7)).filter(|(_, slots)| slots[0] != VANISHED);
    let (owned, slots): (Vec<Owned>, Vec<&[u32]>) = kept.unzip();
    (owned, slots.concat())
}

/// Per triangle of `output`, the index of the child cluster (of `children`, its split) that
/// holds it.
fn output_children(output: &[u32], children: &[Vec<u32>]) -> Vec<u32> {
    let key = |t: &[u32]| {
        let mut k = [t[0], t[1], t[2]];
        k.sort_unstable();
        k
    };
    let mut child_of: rustc_hash::FxHashMap<[u32; 3], u32> = rustc_hash::FxHashMap::default();
    for (i, c) in children.iter().enumerate() {
        for t in c.chunks_exact(3) {
            child_of.insert(key(t), i as u32);
        }
    }
    output.chunks_exact(3).map(|t| child_of.get(&key(t)).copied().unwrap_or(0)).collect()
}

/// A sphere in f64: centre and radius.
type Sphere = ([f64; 3], f64);

/// Joins runs of `list` (one cluster's samples, in Morton order) whose enclosing sphere has a
/// radius of at most `limit` into balls, keeping the order: a run's ball takes its first entry's
/// code. A triangle alone that fits becomes a ball too (one query instead of up to seven); one
/// that does not fit stays as it is.
pub(crate) fn gather(mesh: &WeldedMesh, list: Vec<Owned>, limit: f64, part_size: &[f32]) -> Vec<Owned> {
    if limit <= 0.0 {
        return list;
    }
    let size = |v: u32| part_size[mesh.position_ids[v as usize] as usize];
    let mut out = Vec::with_capacity(list.len());
    // The run: its first entry, how many, enclosing sphere, vertex of the largest part.
    let mut run: Option<(Owned, usize, Sphere, u32)> = None;
    for o in list {
        if too_large(mesh, &o, limit) {
            // It ends the run and stays as it is (what joining it would come to, for less).
            out.extend(run.take().map(|(first, count, s, a)| finish(first, count, s, a, limit)));
            out.push(o);
            continue;
        }
        let (sphere, at) = enclosing(mesh, &o);
        if let Some((first, count, s, a)) = &mut run {
            let joined = join(*s, sphere);
            if joined.1 <= limit {
                (*count, *s) = (*count + 1, joined);
                if size(at) > size(*a) {
                    *a = at;
                }
                continue;
            }
            out.push(finish(*first, *count, *s, *a, limit));
        }
        run = Some((o, 1, sphere, at));
    }
    if let Some((first, count, s, a)) = run {
        out.push(finish(first, count, s, a, limit));
    }
    out
}

/// The entry for a finished run of [`gather`]: a ball, or its one entry where that is
/// already a ball or does not fit.
fn finish(first: Owned, count: usize, (center, radius): Sphere, at: u32, limit: f64) -> Owned {
    if count == 1 && (matches!(first.samples, Samples::Ball(_)) || radius > limit) {
        return first;
    }
    let rounded = center.map(|x| x as f32);
    // Rounding the centre to f32 moves it: the radius grows by that, and is rounded up.
    let moved = (0..3).map(|k| (rounded[k] as f64 - center[k]).powi(2)).sum::<f64>().sqrt();
    let r = radius + moved;
    let mut radius = r as f32;
    if (radius as f64) < r {
        radius = radius.next_up();
    }
    Owned { code: first.code, samples: Samples::Ball(Ball { center: rounded, radius, at }) }
}

/// Whether a triangle entry fits in no sphere of radius `limit`: half its longest edge (a
/// bound from below on any enclosing sphere's radius, and on [`enclosing`]'s) exceeds it, with
/// a margin for rounding. Where the errors are still small beside the level-0 triangles (the
/// top levels of a fine scan), most entries are so, and this spares their spheres.
fn too_large(mesh: &WeldedMesh, o: &Owned, limit: f64) -> bool {
    let Samples::Triangle(t, _) = o.samples else { return false };
    let p = t.map(|v| mesh.positions[v as usize].map(f64::from));
    let edge2 = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>();
    let longest2 = edge2(p[0], p[1]).max(edge2(p[1], p[2])).max(edge2(p[2], p[0]));
    longest2 > 4.0 * limit * limit * (1.0 + 1e-9)
}

/// A sphere holding every point an entry stands for (a triangle: centroid and the farthest
/// corner; all of it, not just its samples), and its vertex for [`Ball::at`].
fn enclosing(mesh: &WeldedMesh, o: &Owned) -> (Sphere, u32) {
    match o.samples {
        Samples::Ball(b) => ((b.center.map(f64::from), b.radius as f64), b.at),
        Samples::Triangle(t, _) => {
            let p = t.map(|v| mesh.positions[v as usize].map(f64::from));
            let c = [0, 1, 2].map(|k| (p[0][k] + p[1][k] + p[2][k]) / 3.0);
            let r = p.iter().map(|q| distance(*q, c)).fold(0.0, f64::max);
            ((c, r), t[0])
        }
    }
}

/// The smallest sphere holding spheres `a` and `b`.
fn join(a: Sphere, b: Sphere) -> Sphere {
    let d = distance(a.0, b.0);
    if d + b.1 <= a.1 {
        return a;
    }
    if d + a.1 <= b.1 {
        return b;
    }
    let r = (d + a.1 + b.1) * 0.5;
    // d > 0 here: with d = 0 one sphere holds the other.
    let s = (r - a.1) / d;
    ([0, 1, 2].map(|k| a.0[k] + (b.0[k] - a.0[k]) * s), r)
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::BakeSettings;
    use crate::weld::weld;
    use mres_import::SourceMesh;

    /// A bumpy grid of `n` × `n` quads (two triangles each) and its triangles' samples, all
    /// bits, in Morton order as level 0 gives them.
    fn grid(n: u32) -> (WeldedMesh, Vec<Owned>) {
        let at = |x: u32, y: u32| y * (n + 1) + x;
        let positions =
            (0..=n).flat_map(|y| (0..=n).map(move |x| [x as f32, y as f32, ((x * 7 + y * 3) % 5) as f32 * 0.1]));
        let mut indices = Vec::new();
        for y in 0..n {
            for x in 0..n {
                indices.extend([at(x, y), at(x + 1, y), at(x + 1, y + 1), at(x, y), at(x + 1, y + 1), at(x, y + 1)]);
            }
        }
        let source = SourceMesh::positions_only(positions.collect(), indices);
        let mesh = weld(&source, &BakeSettings::default()).unwrap();
        let p = |v: u32| mesh.positions[v as usize];
        let centroids: Vec<[f32; 3]> = mesh
            .indices
            .chunks_exact(3)
            .map(|t| [0, 1, 2].map(|k| (p(t[0])[k] + p(t[1])[k] + p(t[2])[k]) / 3.0))
            .collect();
        let codes = crate::partition::morton_codes(&centroids);
        let mut owned: Vec<Owned> = mesh
            .indices
            .chunks_exact(3)
            .zip(codes)
            .map(|(t, c)| Owned::triangle(c, [t[0], t[1], t[2]], 0x7f))
            .collect();
        sort_owned(&mut owned);
        (mesh, owned)
    }

    /// Every corner of the triangles an entry stands for, with the entry it ends up in.
    fn covered(mesh: &WeldedMesh, before: &[Owned], after: &[Owned]) {
        let mut balls = after.iter().filter_map(|o| if let Samples::Ball(b) = o.samples { Some(b) } else { None });
        let kept: Vec<[u32; 3]> =
            after.iter().filter(|o| matches!(o.samples, Samples::Triangle(..))).map(|o| o.corners()).collect();
        let balls: Vec<Ball> = balls.by_ref().collect();
        for o in before {
            let t = o.corners();
            if kept.contains(&t) {
                continue;
            }
            let inside = |b: &Ball| {
                t.iter().all(|&v| {
                    let q = mesh.positions[v as usize];
                    (0..3).map(|k| (q[k] as f64 - b.center[k] as f64).powi(2)).sum::<f64>().sqrt() <= b.radius as f64
                })
            };
            assert!(balls.iter().any(inside), "triangle {t:?} is in no ball and not kept");
        }
    }

    #[test]
    fn gathered_balls_hold_their_triangles_and_keep_the_order() {
        let (mesh, owned) = grid(12);
        let sizes = vec![1e9f32; mesh.position_count];
        // Too small a limit for any triangle: nothing changes.
        assert_eq!(gather(&mesh, owned.clone(), 0.3, &sizes), owned);
        let balls = gather(&mesh, owned.clone(), 1.5, &sizes);
        assert!(balls.len() * 2 < owned.len(), "{} entries from {}", balls.len(), owned.len());
        assert!(balls.windows(2).all(|w| w[0].order(&w[1]).is_le()));
        covered(&mesh, &owned, &balls);
        for o in &balls {
            if let Samples::Ball(b) = o.samples {
                assert!(b.radius <= 1.5 * (1.0 + 1e-6), "{b:?}");
            }
        }
        // Balls of balls still hold every triangle.
        let coarser = gather(&mesh, balls.clone(), 4.0, &sizes);
        assert!(coarser.len() < balls.len());
        covered(&mesh, &owned, &coarser);
    }

    #[test]
    fn samples_kept_together_join_again_unchanged() {
        let (mesh, owned) = grid(12);
        let sizes = vec![1e9f32; mesh.position_count];
        // Too few samples per output triangle to gather: the list itself, on the first child.
        let kept = keep_together(&mesh, owned.clone(), owned.len(), (0.1, &sizes), 3);
        assert_eq!(kept.len(), 3);
        assert!(kept[0] == owned && kept[1].is_empty() && kept[2].is_empty());
        assert_eq!(merge_owned(kept.iter().map(Vec::as_slice)), owned);
        // Many: gathered into balls that still hold every triangle, in order.
        let kept = keep_together(&mesh, owned.clone(), 2, (7.5, &sizes), 2);
        assert!(kept[0].len() * 2 < owned.len() && kept[1].is_empty());
        assert!(kept[0].windows(2).all(|w| w[0].order(&w[1]).is_le()));
        covered(&mesh, &owned, &kept[0]);
        // Lists split among members join into the sorted list, bits of a shared triangle
        // joined.
        let (mut a, mut b): (Vec<Owned>, Vec<Owned>) = (Vec::new(), Vec::new());
        for (i, o) in owned.iter().enumerate() {
            let Samples::Triangle(t, bits) = o.samples else { unreachable!() };
            match i % 3 {
                0 => a.push(*o),
                1 => b.push(*o),
                _ => {
                    a.push(Owned::triangle(o.code, t, bits & 0x0f));
                    b.push(Owned::triangle(o.code, t, bits & 0x70));
                }
            }
        }
        assert_eq!(merge_owned([a.as_slice(), &[], b.as_slice()].into_iter()), owned);
    }

    #[test]
    fn set_bits_lists_the_low_seven_bits_ascending() {
        for mask in 0..=255u8 {
            let expected: Vec<usize> = (0..7).filter(|b| mask >> b & 1 != 0).collect();
            assert_eq!(set_bits(mask).collect::<Vec<_>>(), expected, "{mask:#b}");
        }
    }

    #[test]
    fn joined_spheres_hold_both() {
        let cases = [
            (([0.0, 0.0, 0.0], 1.0), ([3.0, 0.0, 0.0], 0.5)),
            (([0.0, 0.0, 0.0], 2.0), ([0.5, 0.0, 0.0], 0.5)),
            (([1.0, 2.0, 3.0], 0.1), ([1.0, 2.0, 3.0], 0.7)),
            (([1.0, -2.0, 0.5], 0.25), ([-1.0, 1.0, 2.5], 0.0)),
        ];
        for (a, b) in cases {
            let (c, r) = join(a, b);
            for s in [a, b] {
                assert!(distance(c, s.0) + s.1 <= r * (1.0 + 1e-12), "{a:?} {b:?} -> {c:?} {r}");
            }
            // Never larger than the two side by side.
            assert!(r <= (distance(a.0, b.0) + a.1 + b.1) * 0.5 + 1e-12 || r == a.1.max(b.1));
        }
    }
}
