//! The honest group error (docs/INVARIANTS.md §4): a group's stored error must bound the
//! distance between its simplified triangles and the level-0 surface they replace, both ways.
//!
//! meshoptimizer reports an estimate for one simplification step, measured against the step's
//! input rather than the original, and a group's error was that estimate made monotone; the
//! validator measured up to 2.6× more than it on the sample assets and 40× at one spot of the
//! Stanford dragon. Here each group measures, locally, the sampled two-sided distance `d`
//! between its output triangles S and its input triangles C (its members' triangles), and
//! stores the largest, over samples, of `d` at the sample plus the error of the member it is
//! measured from: by the triangle inequality, if every point of a member is within that
//! member's error of the original surface (and back), every point of S is within that bound.
//! Measuring against C, not the original, keeps the cost local (a few thousand triangles per
//! group), so the bake pays a small fraction of what measuring against the original did.
//! Groups that deviate far more than meshoptimizer estimates (outliers) are simplified again
//! with their worst spots locked ([`measure_simplified`]).

use crate::samples::{sample_point, set_bits, Owned, Samples, NOT_FOUND, VANISHED};
use crate::settings::BakeSettings;
use crate::simplify::{simplify_group, Locks, Simplified};
use crate::weld::WeldedMesh;
use mres_geom::bvh::{Bvh, Triangle};
use mres_geom::edges::edge_key;
use mres_geom::parts::diagonals;
use mres_geom::walk::{Surface, STEPS};
use mres_import::mesh::bounds;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// The sampled distance is scaled by this before it is added: the samples (vertices, edge
/// midpoints, centroids) miss the largest distance between them, and the next level's samples
/// fall elsewhere. Measured: see docs/BENCHMARKS.md (honesty).
pub const SAMPLING_MARGIN: f64 = 1.0;

/// A group whose measured distance is more than this many times meshoptimizer's estimate is an
/// outlier: it is simplified again with the vertices around its farthest samples locked, and
/// the result with the smaller error is kept. Such groups (a few dozen of the dragon's 887)
/// would otherwise pass their error on to every ancestor. Measured: see docs/BENCHMARKS.md.
pub const OUTLIER_RATIO: f64 = 4.0;

/// Re-simplifications of one outlier group at most; each locks more.
const OUTLIER_RETRIES: usize = 3;

/// Per position id, the bounding-box diagonal of the original (level-0) connected part it
/// belongs to: how far off a point of that part can be when the part vanishes.
/// The grown copies of [`crate::area`] (no level-0 triangle uses them) get 0.
pub fn part_sizes(mesh: &WeldedMesh) -> Vec<f32> {
    let id = |v: u32| mesh.position_ids[v as usize];
    let level0 = mesh.ladder.as_ref().map_or(mesh.position_count, |l| l.level0_positions);
    let mut sets = mesh.part_sets(level0);
    let points = mesh.positions.iter().enumerate().map(|(v, p)| (id(v as u32), p.map(f64::from)));
    let diagonal = diagonals(&mut sets, points.filter(|&(p, _)| (p as usize) < level0));
    let mut sizes: Vec<f32> = (0..level0 as u32).map(|p| diagonal[sets.find(p) as usize] as f32).collect();
    sizes.resize(mesh.position_count, 0.0);
    sizes
}

/// The surface a group's output is measured against: the original (level-0) triangles under
/// the group (errors 0), or, where those are not at hand (a later shard stage), the members'
/// triangles, each with its member's error.
pub struct Reference<'a> {
    /// Triangle list in welded vertex ids.
    pub triangles: std::borrow::Cow<'a, [u32]>,
    /// Per triangle, the error of the surface it stands for.
    pub errors: Vec<f32>,
    /// With `triangles` from these (their [`Owned::corners`]): which samples belong to this
    /// group, and the balls among them; all samples of every triangle when `None`.
    pub owned: Option<&'a [Owned]>,
    /// The largest own error among the group's members: the stored error is at least this
    /// (monotone errors), and the outlier test counts only what the step adds beyond it.
    pub members_error: f32,
    /// With `triangles` the level-0 triangles under the group: the whole original surface,
    /// which output samples are measured against.
    pub original: Option<&'a Original>,
    /// Passed to `simplify_group`.
    pub lenient: bool,
}

/// Measures the stored error of `first`, a group's simplification (`simplify_group` on `input`
/// with open-border `masks` and `locks`), against `reference` (see [`group_error`]). An outlier
/// (whose error exceeds the members' by more than [`OUTLIER_RATIO`] × meshoptimizer's estimate)
/// is simplified again with the vertices around its farthest samples locked as well, keeping
/// the result with the smallest stored error. Returns the result and its stored error.
///
/// The caller simplifies first and measures only the results it keeps (a level's chord
/// conflicts and stuck groups are settled before any measure); `locks.chord` must then allow
/// only chords no other group of the level can add besides those `first` has, so that a retry
/// cannot meet another group's chord.
pub fn measure_simplified(
    mesh: &WeldedMesh,
    (input, masks): (&[u32], &[u8]),
    first: Simplified,
    reference: &Reference,
    locks: &Locks,
    settings: &BakeSettings,
    part_size: &[f32],
) -> Measured {
    let (members, triangles, errors) = (reference.members_error, &reference.triangles[..], &reference.errors);
    let sides = Sides { input: triangles, triangle_errors: errors, owned: reference.owned, members: input };
    // Samples farther than the outlier ratio × the estimate are kept with their distances:
    // the spots that set an outlier's error are among them (see `Far`). The measure starts
    // from the members' error, which the stored error is at least: a query stops at any
    // triangle within it (the same stored error as from the estimate, for fewer steps).
    let error_of = |s: &Simplified| {
        let record = Some(OUTLIER_RATIO * s.error as f64);
        let floor = s.error.max(members) as f64;
        let (total, far, found) = measure(mesh, &sides, &s.indices, part_size, floor, record, reference.original);
        (stored(total, s.error).max(members), far, found)
    };
    let mut best = first;
    let (mut error, mut far, mut found) = error_of(&best);
    let mut extra: Vec<u32> = Vec::new();
    for _ in 0..OUTLIER_RETRIES {
        let (estimate, added) = (best.error as f64, error as f64 - members as f64);
        // Grown open parts (`preserve_area`) are off the surface on purpose: not an outlier.
        if added <= OUTLIER_RATIO * estimate || best.grown {
            break;
        }
        // Lock around the samples farther than half the excess (and than the outlier ratio).
        let hot_above = (added * 0.5 / SAMPLING_MARGIN).max(OUTLIER_RATIO * estimate);
        let before = extra.len();
        extra.extend(far.hot(mesh, input, hot_above));
        extra.sort_unstable();
        extra.dedup();
        if extra.len() == before {
            break;
        }
        let id = |v: u32| mesh.position_ids[v as usize];
        let lock = |v: u32| (locks.vertex)(v) || extra.binary_search(&id(v)).is_ok();
        let retry_locks = Locks { vertex: &lock, chord: locks.chord };
        let Some(retry) = simplify_group(mesh, input, masks, &retry_locks, settings, reference.lenient) else { break };
        let (e, fa, f) = error_of(&retry);
        if e >= error {
            break;
        }
        (best, error, far, found) = (retry, e, fa, f);
    }
    Measured { simplified: best, error, found }
}

/// What [`measure_simplified`] returns.
pub struct Measured {
    /// The simplified group.
    pub simplified: Simplified,
    /// Its stored error.
    pub error: f32,
    /// Per reference sample, the output triangle within `error` of it that measuring found
    /// (`NOT_FOUND` where not measured, `VANISHED` where its part can raise no error again),
    /// for [`crate::samples::assign_owned`].
    pub found: Vec<u32>,
}

/// A group's stored error (object space) when all its members have error `members_error`: see
/// [`measure_simplified`] and `measure`. At least `simplifier_error`, meshoptimizer's estimate.
/// Both triangle lists are in welded vertex ids; `part_size` is [`part_sizes`].
pub fn group_error(
    mesh: &WeldedMesh,
    input: &[u32],
    output: &[u32],
    part_size: &[f32],
    members_error: f32,
    simplifier_error: f32,
) -> f32 {
    let errors = vec![members_error; input.len() / 3];
    let sides = Sides { input, triangle_errors: &errors, owned: None, members: input };
    let (total, _, _) = measure(mesh, &sides, output, part_size, simplifier_error as f64, None, None);
    stored(total, simplifier_error).max(members_error)
}

/// The reference side of a measurement: triangles (welded ids), each one's member error, and
/// optionally the level-0 samples they come from (see [`Reference::owned`]).
struct Sides<'a> {
    input: &'a [u32],
    triangle_errors: &'a [f32],
    owned: Option<&'a [Owned]>,
    /// The members' triangles (welded ids; `input` itself without `owned`). An output
    /// triangle among them was measured when its member was made, within that member's error,
    /// which the stored error is at least: it is not measured again, nor its edges.
    members: &'a [u32],
}

/// The whole level-0 surface of a welded mesh, in object coordinates, for measuring output
/// samples against (see `measure`). Its triangles are in Morton order of their centroids, so
/// that a walk's neighbours and a query's leaves lie near each other in memory: the surface of
/// a large mesh is far beyond the caches, and a query's cost was mostly its memory reads.
pub struct Original {
    /// Its triangles, walked from the previous sample's triangle to the next sample.
    surface: Surface<f32>,
    /// Per triangle of `surface`, its index in the mesh's `indices`.
    source: Vec<u32>,
    /// Per position id, the first triangle of `surface` using it: where a second walk to an
    /// output sample starts when the walk from the previous sample's triangle does not get
    /// within the bound. An output corner is a level-0 vertex, so the sample lies within the
    /// output triangle's size of there; the previous sample's triangle is often dozens of
    /// triangles away at the upper levels (the output triangles the members already had are
    /// not measured, so the measured ones lie apart), and a query left to the hierarchy costs
    /// about 20 walks.
    at_position: Vec<u32>,
    /// The centre of the mesh's bounds, subtracted from every point: distances are found in
    /// coordinates around it, so that their rounding depends on the mesh's size and not on
    /// where it lies (a terrain in map coordinates, 4e6 from the origin, got 32 m on every
    /// error from rounding at the absolute coordinates).
    centre: [f32; 3],
    /// Bound on the f32 rounding of a distance at these coordinates.
    slack: f64,
}

impl Original {
    /// The level-0 triangles of `mesh` (its `indices`), in `order` (the mesh's
    /// [`crate::partition::triangle_order`], which the level-0 clusters share).
    pub fn new(mesh: &WeldedMesh, order: &[u32]) -> Original {
        let (centre, largest) = bounds(&mesh.positions).map_or(([0.0; 3], 0.0), around);
        let p = |v: u32| sub(mesh.positions[v as usize], centre);
        let source = order.to_vec();
        let corners = |t: u32| &mesh.indices[t as usize * 3..t as usize * 3 + 3];
        let tris: Vec<Triangle<f32>> = source
            .par_iter()
            .map(|&t| {
                let c = corners(t);
                [p(c[0]), p(c[1]), p(c[2])]
            })
            .collect();
        let ids: Vec<u32> =
            source.iter().flat_map(|&t| corners(t).iter().map(|&v| mesh.position_ids[v as usize])).collect();
        // Rounding of the subtractions, products and sums: a few dozen ulps of the largest
        // coordinate around the centre (far below the position grid's step). The points
        // themselves are the file's (FORMAT.md §3): the subtraction of the centre is exact
        // where a coordinate is within a factor of 2 of the centre's (a mesh far from the
        // origin), and rounds by at most half an ulp of the result elsewhere.
        let slack = 64.0 * f32::EPSILON as f64 * largest as f64;
        // The first triangle of each position, in surface order: the same for any thread count.
        let at_position: Vec<AtomicU32> = (0..mesh.position_count).map(|_| AtomicU32::new(u32::MAX)).collect();
        ids.par_iter().enumerate().with_min_len(4096).for_each(|(s, &p)| {
            at_position[p as usize].fetch_min(s as u32 / 3, Relaxed);
        });
        let at_position = at_position.into_iter().map(AtomicU32::into_inner).collect();
        Original { surface: Surface::new(tris, &ids), source, at_position, centre, slack }
    }

    /// Output → original for `output` (welded ids) with sample bits `duty`, from the bound
    /// `worst`: the largest bound and the samples found farther than `record2` (squared).
    /// Which original triangle within the bound a query stops at does not matter here, only a
    /// distance beyond.
    fn measure(
        &self,
        mesh: &WeldedMesh,
        (output, duty): (&[u32], &[u8]),
        mut worst: f64,
        record2: Option<f32>,
    ) -> (f64, Far) {
        let local = |v: u32| sub(mesh.positions[v as usize], self.centre);
        let id = |v: u32| mesh.position_ids[v as usize];
        let mut far = Far::default();
        let mut hint = usize::MAX;
        for (t, &duty) in output.chunks_exact(3).zip(duty) {
            let tri = [local(t[0]), local(t[1]), local(t[2])];
            for b in set_bits(duty) {
                let p = sample_point(&tri, b);
                let d = ((worst / SAMPLING_MARGIN - self.slack).max(0.0)) as f32;
                let enough = d * d;
                // From the previous sample's triangle (mostly near, and in the caches), else
                // from a level-0 triangle at the sample's nearest corner (edge k's midpoint, bit
                // 3 + k, at corner k; the centroid at corner 0), then the hierarchy from the
                // closer end (a corner can be far: the apex of a fan of slivers).
                let corner = || self.at_position[id(t[b.saturating_sub(3) % 3]) as usize] as usize;
                let (d2, nearest) = self.surface.within_squared2(p, enough, hint, corner, STEPS);
                hint = nearest;
                if d2 > enough {
                    worst = worst.max(SAMPLING_MARGIN * ((d2 as f64).sqrt() + self.slack));
                    if record2.is_some_and(|h| d2 > h) {
                        far.add(d2, self.corners(mesh, nearest).iter().chain(t).map(|&v| id(v)));
                    }
                }
            }
        }
        (worst, far)
    }

    /// The welded vertex ids of triangle `t` (of `surface`).
    fn corners<'m>(&self, mesh: &'m WeldedMesh, t: usize) -> &'m [u32] {
        let t = self.source[t] as usize;
        &mesh.indices[t * 3..t * 3 + 3]
    }
}

/// The centre of box `(lo, hi)` and its reach: the largest coordinate of a point in it,
/// taken from the centre in f32 (the subtraction rounds monotonically, so no point's is
/// larger than a corner's). An empty box gives the origin and 0.
fn around((lo, hi): Box3) -> ([f32; 3], f32) {
    if (0..3).any(|k| lo[k] > hi[k]) {
        return ([0.0; 3], 0.0);
    }
    let centre = [0, 1, 2].map(|k| lo[k] * 0.5 + hi[k] * 0.5);
    let reach = (0..3).map(|k| (hi[k] - centre[k]).max(centre[k] - lo[k])).fold(0.0f32, f32::max);
    (centre, reach)
}

/// An axis-aligned box: lower and upper corner.
type Box3 = ([f32; 3], [f32; 3]);

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `total` rounded up to f32, and at least `simplifier_error`.
fn stored(total: f64, simplifier_error: f32) -> f32 {
    let rounded = total as f32;
    let rounded = if (rounded as f64) < total { f32::from_bits(rounded.to_bits() + 1) } else { rounded };
    rounded.max(simplifier_error)
}

/// The largest, over samples, of a sample's distance to the other side (× [`SAMPLING_MARGIN`])
/// plus the error of the member it is measured from, or `floor` if that is larger (values up to
/// `floor` are not found exactly). By the triangle inequality this bounds the distance between
/// the output and the level-0 surface, both ways, if each member's error bounds the distance
/// between its triangles and the level-0 surface under it: a point of the output is within
/// `d + e` of level 0 through its nearest input point (on a member of error `e`); a level-0
/// point under a member of error `e` is within `e` of that member's triangles, and those are
/// within `d` of the output. Taking each sample's own member's error, not the largest member's,
/// keeps one member's large error from adding to every other member's distance.
/// `triangle_errors` gives each input triangle's member error. A point of the input farther
/// from the output than its part's size counts as its part's size (the part vanished). With
/// `record_above`, also returns the samples found farther than it (see [`Far`]).
///
/// Samples: output → input, the centroid of each output triangle and the midpoint of each
/// output edge (its corners are input vertices); input → output, the input vertices the output
/// dropped, and the centroid and edge midpoints of the input triangles. A sample on a triangle
/// or edge that both sides share is at distance 0 and left out (the members' errors themselves
/// are kept by the caller); a corner or edge that several input triangles share is sampled
/// once, with the largest of their errors. Distances are found in f32 around the group's centre
/// and rounded up by a bound on that arithmetic's error (far below the position grid's step).
///
/// With `original` (the whole level-0 surface of this mesh), output samples are measured
/// against all of it rather than `input`: near the group border the level-0 triangles under the
/// group (handed down by nearest cluster) need not cover the output exactly, and the distance to
/// the original surface is what a viewer sees (and what the validator measures). There the
/// output triangles the members had (`Sides::members`), and their edges, are not measured:
/// they were, when they were made, within an error the stored one is at least.
#[allow(clippy::too_many_arguments)]
fn measure(
    mesh: &WeldedMesh,
    sides: &Sides,
    output: &[u32],
    part_size: &[f32],
    floor: f64,
    record_above: Option<f64>,
    original: Option<&Original>,
) -> (f64, Far, Vec<u32>) {
    let (input, triangle_errors) = (sides.input, sides.triangle_errors);
    // Per input sample (7 per triangle), the output triangle its query stopped at: within the
    // returned error of it (see `assign_owned`); NOT_FOUND where the sample was not measured.
    let mut found = vec![NOT_FOUND; input.len() / 3 * 7];
    let id = |v: u32| mesh.position_ids[v as usize];
    // The input's entries in object coordinates first (one pass over the mesh's positions, in
    // parallel: at the top levels the input is every level-0 triangle, in one group), then its
    // bounds, then the entries around the bounds' centre.
    let absolute = |v: u32| mesh.positions[v as usize];
    // A ball's entry is its centre three times (measured at its centroid, the centre).
    let entry = |o: &Owned| match o.samples {
        Samples::Ball(b) => [b.center; 3],
        Samples::Triangle(t, _) => t.map(absolute),
    };
    let mut input_tris: Vec<Triangle<f32>> = match sides.owned {
        Some(owned) => owned.par_iter().map(entry).collect(),
        None => input.par_chunks_exact(3).map(|t| [absolute(t[0]), absolute(t[1]), absolute(t[2])]).collect(),
    };
    let (center, reach) = around(input_bounds(&input_tris, sides.owned, absolute));
    // Rounding of the f32 subtraction, products and sums (a few dozen ulps of the group's reach).
    let slack = 64.0 * f32::EPSILON as f64 * reach as f64;
    let to_local = |p: [f32; 3]| sub(p, center);
    input_tris.par_iter_mut().with_min_len(4096).for_each(|t| *t = t.map(to_local));
    let local = |v: u32| to_local(mesh.positions[v as usize]);
    let triangles = |indices: &[u32]| -> Vec<Triangle<f32>> {
        indices.par_chunks_exact(3).map(|t| [local(t[0]), local(t[1]), local(t[2])]).collect()
    };
    let output_tris = triangles(output);
    let (mut input_duty, output_duty) =
        duties(mesh, (input, sides.members), output, triangle_errors, sides.owned.is_some());
    // Per input entry, a distance added to its samples': a ball's radius (measured at its
    // centre, see `crate::samples`).
    let mut reach_of = vec![0.0f32; input_tris.len()];
    if let Some(owned) = sides.owned {
        let entries = input_duty.par_iter_mut().zip(&mut reach_of);
        entries.zip(owned).for_each(|((d, r), o)| {
            *d &= o.bits();
            if let Some(b) = o.ball() {
                *r = b.radius;
            }
        });
    }

    let limits = Limits { slack, record2: record_above.map(|h| (h * h) as f32) };
    let record2 = limits.record2;
    let largest = triangle_errors.iter().copied().fold(0.0f32, f32::max) as f64;
    let mut worst = floor;
    let mut far = Far::default();
    // Samples of a triangle by its duty bits: corners, edge midpoints, centroid.
    let samples = |tri: Triangle<f32>, duty: u8| set_bits(duty).map(move |b| sample_point(&tri, b));

    // Output → input: the nearest input triangle's member error (any member's, until found
    // exactly).
    if let Some(o) = original {
        // In runs side by side, each from the bound so far (the top levels' few groups have
        // thousands of output triangles, far apart on the original surface).
        let runs: Vec<(f64, Far)> = output
            .par_chunks(3 * OUTPUT_RUN)
            .zip(output_duty.par_chunks(OUTPUT_RUN))
            .map(|(output, duty)| o.measure(mesh, (output, duty), worst, record2))
            .collect();
        far.join(&mut worst, runs);
    } else {
        let input_bvh = Bvh::new(&input_tris);
        let mut hint = usize::MAX;
        for ((t, tri), &duty) in output.chunks_exact(3).zip(&output_tris).zip(&output_duty) {
            for p in samples(*tri, duty) {
                let enough = limits.enough2(worst, largest);
                let (d2, nearest) = input_bvh.nearest_squared(&input_tris, p, enough, hint);
                hint = nearest;
                if d2 > enough {
                    worst = worst.max(limits.total(d2, triangle_errors[nearest] as f64));
                    if record2.is_some_and(|h| d2 > h) {
                        far.add(d2, input[nearest * 3..nearest * 3 + 3].iter().chain(t).map(|&v| id(v)));
                    }
                }
            }
        }
    }

    // Input → output, in runs measured in parallel (large groups are few, at the top levels).
    let ids: Vec<u32> = output.iter().map(|&v| id(v)).collect();
    let output_surface = Surface::new(output_tris, &ids);
    let side = InputSide {
        mesh,
        center,
        input,
        output,
        tris: &input_tris,
        duty: &input_duty,
        errors: triangle_errors,
        reach: &reach_of,
    };
    let runs: Vec<(f64, Far)> = found
        .par_chunks_mut(7 * RUN_TRIANGLES)
        .enumerate()
        .map(|(k, found)| {
            let first = k * RUN_TRIANGLES;
            side.measure(first, found, &output_surface, part_size, worst, limits)
        })
        .collect();
    far.join(&mut worst, runs);
    (worst, far, found)
}

/// Samples a measurement found farther from the other side than its `record_above`, with
/// their exact distances (queries beyond the running bound find the nearest triangle), each
/// with the position ids around it: the corners of the input triangle it lies on or is
/// nearest to, and of the output triangle it lies on or is nearest to; for an input sample
/// also its point, whose nearest position of the group's input [`Far::hot`] names (a level-0
/// sample's corners are level-0 positions, which the input above level 1 has mostly lost:
/// locking only those, a retry changed nothing and the outlier stayed). These are the samples that
/// raised the running maximum of their run, so the spots that set an outlier's error, not
/// every sample beyond its hot threshold: the retry locks around them without a second pass
/// over every sample (a full measure per retry, the whole input at the top levels), and the
/// next retry locks around the spots that remain.
#[derive(Default)]
pub(crate) struct Far {
    /// (squared distance, position id), a sample's ids one after another.
    samples: Vec<(f32, u32)>,
    /// (squared distance, point in object coordinates) of the input samples among them:
    /// above level 1 their triangles' corners are level-0 positions the group's input has
    /// mostly lost, so [`Far::hot`] also names the input positions nearest to the points.
    points: Vec<(f32, [f32; 3])>,
}

impl Far {
    fn add(&mut self, d2: f32, ids: impl Iterator<Item = u32>) {
        self.samples.extend(ids.map(|p| (d2, p)));
    }

    /// Joins the results of runs measured side by side, in order: `worst` becomes the largest
    /// of their bounds, and their samples follow these.
    fn join(&mut self, worst: &mut f64, runs: Vec<(f64, Far)>) {
        for (run_worst, run_far) in runs {
            *worst = worst.max(run_worst);
            self.samples.extend(run_far.samples);
            self.points.extend(run_far.points);
        }
    }

    /// The position ids around the samples farther than `above` (distance alone), the
    /// position of `input` (the group's triangles, welded ids) nearest to each such input
    /// sample, and the corners of the `input` triangles that use any of them: what a collapse
    /// moved there came from them. Sorted, without repeats.
    fn hot(&self, mesh: &WeldedMesh, input: &[u32], above: f64) -> Vec<u32> {
        let above2 = (above * above) as f32;
        let mut hot: Vec<u32> = self.samples.iter().filter(|s| s.0 > above2).map(|s| s.1).collect();
        if hot.is_empty() {
            return hot;
        }
        let id = |v: u32| mesh.position_ids[v as usize];
        let far_points = self.points.iter().filter(|p| p.0 > above2);
        hot.extend(far_points.filter_map(|&(_, p)| nearest_vertex(mesh, input.iter().copied(), p)).map(id));
        hot.sort_unstable();
        hot.dedup();
        let ring: Vec<u32> = input
            .chunks_exact(3)
            .filter(|t| t.iter().any(|&v| hot.binary_search(&id(v)).is_ok()))
            .flatten()
            .map(|&v| id(v))
            .collect();
        hot.extend(ring);
        hot.sort_unstable();
        hot.dedup();
        hot
    }
}

/// The vertex among `candidates` (welded ids) nearest to `p`, the first of equals; `None`
/// without candidates.
fn nearest_vertex(mesh: &WeldedMesh, candidates: impl IntoIterator<Item = u32>, p: [f32; 3]) -> Option<u32> {
    let d2 = |v: u32| {
        let q = mesh.positions[v as usize];
        (0..3).map(|k| (q[k] - p[k]) * (q[k] - p[k])).sum::<f32>()
    };
    candidates.into_iter().min_by(|&a, &b| d2(a).total_cmp(&d2(b)))
}

/// The bounds of a measurement's input: its entries `tris` (object coordinates), and with
/// `owned` its balls' spheres and each ball's vertex [`Ball::at`](crate::samples::Ball).
fn input_bounds(tris: &[Triangle<f32>], owned: Option<&[Owned]>, absolute: impl Fn(u32) -> [f32; 3] + Sync) -> Box3 {
    let empty = || ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    let union = |(alo, ahi): Box3, (blo, bhi): Box3| {
        ([0, 1, 2].map(|k| alo[k].min(blo[k])), [0, 1, 2].map(|k| ahi[k].max(bhi[k])))
    };
    let of_points = |points: &[[f32; 3]], r: f32| {
        points.iter().fold(empty(), |b, p| union(b, (p.map(|x| x - r), p.map(|x| x + r))))
    };
    let corners = tris.par_iter().with_min_len(4096).map(|t| of_points(t, 0.0)).reduce(empty, union);
    let balls = owned.into_iter().flatten().filter_map(Owned::ball).collect::<Vec<_>>();
    let spheres = balls.par_iter().map(|b| union(of_points(&[b.center], b.radius), of_points(&[absolute(b.at)], 0.0)));
    union(corners, spheres.reduce(empty, union))
}

/// Output triangles measured together against the original surface in one parallel run of
/// `Original::measure`: a group of the lower levels is one run. Fixed, so that the result does
/// not depend on the thread count.
const OUTPUT_RUN: usize = 1024;

/// Input triangles measured together in one parallel run of `InputSide::measure`. Fixed, so
/// that the result does not depend on the thread count.
const RUN_TRIANGLES: usize = 4096;

/// When a sample's distance matters: the f32 rounding `slack` of a group's distances, and the
/// squared distance above which a sample found beyond the bound is recorded (see [`Far`]).
#[derive(Clone, Copy)]
struct Limits {
    slack: f64,
    record2: Option<f32>,
}

impl Limits {
    /// The squared distance below which a sample with member error `e` cannot raise `worst`:
    /// the query may stop at any triangle within it.
    fn enough2(&self, worst: f64, e: f64) -> f32 {
        let d = ((worst - e) / SAMPLING_MARGIN - self.slack).max(0.0) as f32;
        d * d
    }

    /// A sample's bound: its distance (squared `d2`), rounded up, plus its member error `e`.
    fn total(&self, d2: f32, e: f64) -> f64 {
        e + SAMPLING_MARGIN * ((d2 as f64).sqrt() + self.slack)
    }

    /// Whether a sample of member error `e` whose part has squared size `size2` (the most its
    /// distance counts for) can neither raise `worst` nor be recorded as far: it need not be
    /// measured, here or at any ancestor.
    fn vanished(&self, size2: f32, e: f64, worst: f64) -> bool {
        self.total(size2, e) <= worst && self.record2.is_none_or(|h| size2 <= h)
    }
}

/// The input side of a measurement, in the group's local coordinates.
struct InputSide<'a> {
    mesh: &'a WeldedMesh,
    /// The group's centre, which `tris` are around.
    center: [f32; 3],
    input: &'a [u32],
    output: &'a [u32],
    tris: &'a [Triangle<f32>],
    duty: &'a [u8],
    errors: &'a [f32],
    /// Per entry, the radius added where it is a ball, measured at its centre.
    reach: &'a [f32],
}

impl InputSide<'_> {
    /// Input → output for the triangles from `first` on whose `found` slots are given
    /// (7 per triangle), starting from the bound `worst`: the dropped vertices first (the
    /// farthest points, usually), so that the edge and centroid samples that follow mostly stop
    /// at the first triangle within the worst. Returns the run's largest bound and its far
    /// positions, and fills `found` with the output triangle each query stopped at.
    fn measure(
        &self,
        first: usize,
        found: &mut [u32],
        output: &Surface<f32>,
        part_size: &[f32],
        mut worst: f64,
        limits: Limits,
    ) -> (f64, Far) {
        let id = |v: u32| self.mesh.position_ids[v as usize];
        let mut far = Far::default();
        let mut hint = usize::MAX;
        let mut last = Last { point: [0.0; 3], distance: f32::INFINITY };
        for pass in [0b000_0111u8, 0b111_1000] {
            for (j, slots) in found.chunks_exact_mut(7).enumerate() {
                let i = first + j;
                let (t, tri) = (&self.input[3 * i..3 * i + 3], &self.tris[i]);
                let e = self.errors[i] + self.reach[i];
                let size = || part_size[id(t[0]) as usize];
                if self.duty[i] & pass != 0 && limits.vanished(size() * size(), e as f64, worst) {
                    // Its part's size, the most it can count for, is within the bound already:
                    // it cannot raise this group's error nor, errors being monotone, any
                    // ancestor's (measured from level-0 samples, errors 0: nothing adds up).
                    slots.fill(VANISHED);
                    continue;
                }
                // The output triangle sample `b` is found at; a ball, measured at its centre,
                // is found there whole.
                let ball = self.reach[i] > 0.0;
                let place = |slots: &mut [u32], b: usize, t: usize| {
                    if ball {
                        slots.fill(t as u32);
                    } else {
                        slots[b] = t as u32;
                    }
                };
                for b in set_bits(self.duty[i] & pass) {
                    let enough = limits.enough2(worst, e as f64);
                    let p = sample_point(tri, b);
                    if last.settles(p, enough) {
                        // Within the bound of the last query's triangle (see `Last`).
                        place(slots, b, hint);
                        continue;
                    }
                    let (d2, nearest) = output.nearest_squared(p, enough, hint, STEPS);
                    (hint, last) = (nearest, Last { point: p, distance: d2.sqrt() });
                    place(slots, b, nearest);
                    // A point farther than its part's size counts as that: the part vanished
                    // (looked up only beyond `enough`, where the capped value can matter).
                    let d2 = if d2 > enough { d2.min(size() * size()) } else { d2 };
                    if d2 > enough {
                        worst = worst.max(limits.total(d2, e as f64));
                        if limits.record2.is_some_and(|h| d2 > h) {
                            let near = &self.output[3 * nearest..3 * nearest + 3];
                            far.add(d2, t.iter().chain(near).map(|&v| id(v)));
                            let p = sample_point(tri, b);
                            far.points.push((d2, [0, 1, 2].map(|k| p[k] + self.center[k])));
                        }
                    }
                }
            }
        }
        (worst, far)
    }
}

/// The last query of a run of input samples: its point and its distance to the triangle it
/// stopped at. Distance to a triangle is 1-Lipschitz, so a sample `p` within `enough` minus
/// that distance of the point lies within `enough` of that triangle, and no query needs to
/// say so: the samples follow one another in space (entries in Morton order, a triangle's
/// samples side by side), and from the middle levels up the bound spans several level-0
/// triangles. Such a sample cannot raise the error, and the triangle is a valid `found` for
/// it (within the group's error).
#[derive(Clone, Copy)]
struct Last {
    point: [f32; 3],
    distance: f32,
}

impl Last {
    /// Whether `p` lies within `enough2` (squared) of the last query's triangle: its distance
    /// plus the way from its point, padded for the f32 rounding of both.
    fn settles(&self, p: [f32; 3], enough2: f32) -> bool {
        let way2: f32 = (0..3).map(|k| (p[k] - self.point[k]) * (p[k] - self.point[k])).sum();
        let reach = (self.distance + way2.sqrt()) * (1.0 + 1e-5);
        reach * reach <= enough2
    }
}

/// Which samples each triangle of `input` and of `output` measures, as bits: corner k (bit k;
/// input only: the corners the output dropped), the midpoint of edge k from corner k (bit 3 + k)
/// and the centroid (bit 6). A sample that lies on both sides (a kept corner, an edge or a
/// triangle both have) is at distance 0 and left out; a corner or edge that several triangles
/// share is measured by one of them only: the first of those with the largest member error
/// (`triangle_errors`, per input triangle).
///
/// With `level0_samples` (the input is level-0 triangles whose samples the caller keeps only
/// where owned), every input sample is measured but the corners the output kept, and every
/// output triangle but those among the `members`' triangles (and the edges of those); see below.
fn duties(
    mesh: &WeldedMesh,
    (input, members): (&[u32], &[u32]),
    output: &[u32],
    triangle_errors: &[f32],
    level0_samples: bool,
) -> (Vec<u8>, Vec<u8>) {
    let id = |v: u32| mesh.position_ids[v as usize];
    // (key, slot = 3 × triangle + corner), sorted: equal keys are adjacent, first slot first.
    let edges = |indices: &[u32]| -> Vec<(u64, u32)> {
        let mut e: Vec<(u64, u32)> = (0..indices.len())
            .map(|s| (edge_key(id(indices[s]), id(indices[s - s % 3 + (s + 1) % 3])), s as u32))
            .collect();
        e.sort_unstable();
        e
    };
    // A triangle's key: its position ids, sorted.
    let key = |c: &[u32]| {
        let mut k = [id(c[0]), id(c[1]), id(c[2])];
        k.sort_unstable();
        k
    };
    let triangles = |indices: &[u32]| -> Vec<([u32; 3], u32)> {
        let mut keys: Vec<([u32; 3], u32)> =
            indices.chunks_exact(3).enumerate().map(|(t, c)| (key(c), t as u32)).collect();
        keys.sort_unstable();
        keys
    };
    let corners = |indices: &[u32]| -> Vec<(u32, u32)> {
        let mut c: Vec<(u32, u32)> = indices.iter().enumerate().map(|(s, &v)| (id(v), s as u32)).collect();
        c.sort_unstable();
        c
    };
    // Sets `bit(slot)` in `duty` for each key of `a` that `b` lacks, at the first of its slots
    // with the largest `rank`.
    fn mark<K: Ord + Copy>(
        a: &[(K, u32)],
        b: &[(K, u32)],
        duty: &mut [u8],
        rank: impl Fn(u32) -> f32,
        bit: impl Fn(u32) -> (usize, u8),
    ) {
        let mut j = 0;
        for run in a.chunk_by(|x, y| x.0 == y.0) {
            while j < b.len() && b[j].0 < run[0].0 {
                j += 1;
            }
            if j >= b.len() || b[j].0 != run[0].0 {
                let slot = run.iter().map(|x| x.1).fold(run[0].1, |s, x| if rank(x) > rank(s) { x } else { s });
                let (t, m) = bit(slot);
                duty[t] |= m;
            }
        }
    }
    let corner = |s: u32| ((s / 3) as usize, 1u8 << (s % 3));
    let edge = |s: u32| ((s / 3) as usize, 8u8 << (s % 3));
    let whole = |t: u32| (t as usize, 64u8);
    if level0_samples {
        // Level-0 samples against an upper level: they share hardly an edge or a triangle, so
        // only the corners the output kept are left out (a shared edge's midpoint measures 0
        // at once), and the level-0 edges need no sort.
        // The kept positions as bits: a flag byte per position of the mesh was, per group, a
        // fresh allocation of the whole mesh's size, zeroed page by page by the system.
        let mut kept = vec![0u64; mesh.position_count.div_ceil(64)];
        for &v in output {
            kept[id(v) as usize / 64] |= 1 << (id(v) % 64);
        }
        let is_kept = |v: u32| kept[id(v) as usize / 64] >> (id(v) % 64) & 1 != 0;
        let input_duty = input
            .par_chunks_exact(3)
            .with_min_len(4096)
            .map(|t| (0..3).filter(|&k| is_kept(t[k])).fold(0x7fu8, |d, k| d & !(1 << k)))
            .collect();
        // An output triangle the members had was measured when it was made (within its
        // member's error, which the stored error is at least), and its edges with it. The
        // members' triangles by key in a hash set: one pass, no sort of their keys.
        let had: rustc_hash::FxHashSet<[u32; 3]> = members.chunks_exact(3).map(key).collect();
        let unchanged: Vec<bool> = output.chunks_exact(3).map(|t| had.contains(&key(t))).collect();
        let mut output_duty: Vec<u8> = unchanged.iter().map(|&u| if u { 0 } else { 64 }).collect();
        for run in edges(output).chunk_by(|x, y| x.0 == y.0) {
            if !run.iter().any(|x| unchanged[x.1 as usize / 3]) {
                let (t, m) = edge(run[0].1);
                output_duty[t] |= m;
            }
        }
        return (input_duty, output_duty);
    }
    let (input_edges, output_edges) = (edges(input), edges(output));
    let (input_keys, output_keys) = (triangles(input), triangles(output));
    let mut input_duty = vec![0u8; input.len() / 3];
    let mut output_duty = vec![0u8; output.len() / 3];
    let by_slot = |s: u32| triangle_errors[s as usize / 3];
    let by_triangle = |t: u32| triangle_errors[t as usize];
    let none = |_: u32| 0.0;
    mark(&corners(input), &corners(output), &mut input_duty, by_slot, corner);
    mark(&input_edges, &output_edges, &mut input_duty, by_slot, edge);
    mark(&input_keys, &output_keys, &mut input_duty, by_triangle, whole);
    mark(&output_edges, &input_edges, &mut output_duty, none, edge);
    mark(&output_keys, &input_keys, &mut output_duty, none, whole);
    (input_duty, output_duty)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::samples::CENTROID;
    use crate::weld::weld;
    use mres_import::SourceMesh;

    /// A square fan around a centre raised by `h`, and the same square as two flat triangles.
    fn tent(h: f32) -> (WeldedMesh, Vec<u32>, Vec<u32>) {
        let mesh = SourceMesh::positions_only(
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, h]],
            vec![0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4],
        );
        let w = weld(&mesh, &BakeSettings::default()).unwrap();
        let input = w.indices.clone();
        // The welded ids of the corners, by position.
        let at = |p: [f32; 3]| (0..w.positions.len() as u32).find(|&v| w.positions[v as usize] == p).unwrap();
        let c = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]].map(at);
        let output = vec![c[0], c[1], c[2], c[0], c[2], c[3]];
        (w, input, output)
    }

    #[test]
    fn a_ball_bounds_every_point_of_its_triangles() {
        let (w, input, output) = tent(0.25);
        let sizes = part_sizes(&w);
        let h = w.positions.iter().map(|p| p[2]).fold(0.0f32, f32::max) as f64;
        let owned = every_sample(&input);
        let balls = crate::samples::gather(&w, owned, 10.0, &sizes);
        let [Owned { samples: Samples::Ball(ball), .. }] = &balls[..] else { panic!("one ball: {balls:?}") };
        let corners: Vec<u32> = balls.iter().flat_map(|o| o.corners()).collect();
        let errors = vec![0.0; balls.len()];
        let sides = Sides { input: &corners, triangle_errors: &errors, owned: Some(&balls), members: &input };
        let original = original_of(&w);
        // The peak is `h` above the flat output; the ball is measured at its centre only.
        let (worst, _, found) = measure(&w, &sides, &output, &sizes, 0.0, None, Some(&original));
        assert!(worst >= h && worst <= h + 2.0 * ball.radius as f64, "{worst} vs peak {h}, {ball:?}");
        assert_ne!(found[6], NOT_FOUND, "the centre's query names an output triangle");
    }

    #[test]
    fn measured_error_bounds_the_dropped_peak_and_adds_the_members() {
        let (w, input, output) = tent(0.25);
        let sizes = part_sizes(&w);
        let h = w.positions.iter().map(|p| p[2]).fold(0.0f32, f32::max);
        let e = group_error(&w, &input, &output, &sizes, 0.0, 0.0);
        assert!(e >= h && e < h * 1.001, "{e} vs peak {h}");
        let e = group_error(&w, &input, &output, &sizes, 0.5, 0.0);
        assert!(e >= 0.5 + h && e < (0.5 + h) * 1.001, "{e}");
        // The simplifier's estimate wins when larger; an unchanged group measures 0.
        assert_eq!(group_error(&w, &input, &output, &sizes, 0.0, 2.0), 2.0);
        assert_eq!(group_error(&w, &input, &input, &sizes, 0.0, 0.0), 0.0);
    }

    /// The welded vertex nearest to `p` (weld snaps positions to its grid).
    fn welded_at(w: &WeldedMesh, p: [f32; 3]) -> u32 {
        nearest_vertex(w, 0..w.positions.len() as u32, p).unwrap()
    }

    /// A bumpy `n` × `n` grid (welded) and a coarse output over every other vertex of it.
    fn bumpy(n: u32) -> (WeldedMesh, Vec<u32>) {
        let at = |x: u32, y: u32| y * (n + 1) + x;
        let height = |x: u32, y: u32| ((x * 7 + y * 3) % 5) as f32 * 0.15;
        let positions = (0..=n).flat_map(|y| (0..=n).map(move |x| [x as f32, y as f32, height(x, y)])).collect();
        let quads = |step: u32| {
            let mut indices = Vec::new();
            for y in (0..n).step_by(step as usize) {
                for x in (0..n).step_by(step as usize) {
                    let (a, b) = (at(x, y), at(x + step, y));
                    let (c, d) = (at(x + step, y + step), at(x, y + step));
                    indices.extend([a, b, c, a, c, d]);
                }
            }
            indices
        };
        let mesh = SourceMesh::positions_only(positions, quads(1));
        let w = weld(&mesh, &BakeSettings::default()).unwrap();
        // Welded ids of the source's vertices: the nearest welded position (weld snaps them).
        let id = |v: u32| welded_at(&w, mesh.positions[v as usize]);
        let output = quads(2).into_iter().map(id).collect();
        (w, output)
    }

    #[test]
    fn the_original_surface_measure_is_exact_from_any_start() {
        let (w, output) = bumpy(8);
        let original = original_of(&w);
        // Each position's starting triangle uses it.
        for (p, &t) in original.at_position.iter().enumerate() {
            let corners = original.corners(&w, t as usize);
            assert!(corners.iter().any(|&v| w.position_ids[v as usize] as usize == p), "position {p}");
        }
        // Every output edge midpoint and centroid, against every level-0 triangle.
        let tris: Vec<Triangle<f32>> =
            w.indices.chunks_exact(3).map(|t| [0, 1, 2].map(|k| w.positions[t[k] as usize])).collect();
        let mut exact = 0.0f64;
        for t in output.chunks_exact(3) {
            let tri = [0, 1, 2].map(|k| w.positions[t[k] as usize]);
            for b in 3..7 {
                let p = sample_point(&tri, b);
                let d2 = tris.iter().map(|q| mres_geom::bvh::point_triangle_distance2(p, q)).fold(f32::MAX, f32::min);
                exact = exact.max((d2 as f64).sqrt());
            }
        }
        assert!(exact > 0.1, "the coarse output misses the bumps: {exact}");
        let duty = vec![0x78u8; output.len() / 3];
        let (worst, _) = original.measure(&w, (&output, &duty), 0.0, None);
        assert!(worst >= exact && worst <= exact + 1e-4, "{worst} vs {exact}");
    }

    #[test]
    fn output_triangles_the_members_had_are_not_measured_again() {
        let (w, input, _) = tent(0.25);
        let id = |v: u32| w.position_ids[v as usize];
        // The fan's first two triangles kept, and a new one joining the second's far corner to
        // the first corner: only its centroid and its new edge (corner 1 to 2) are measured.
        let corner = |t: usize, k: usize| input[3 * t + k];
        let (apex, a, c) = (corner(0, 2), corner(0, 0), corner(1, 1));
        assert_eq!([id(corner(1, 2)), id(corner(0, 1))], [id(apex), id(corner(1, 0))]);
        let mut output = input[..6].to_vec();
        output.extend([apex, c, a]);
        let errors = vec![0.0; input.len() / 3];
        let (_, duty) = duties(&w, (&input, &input), &output, &errors, true);
        assert_eq!(duty, vec![0, 0, CENTROID | 16]);
    }

    /// The whole level-0 surface of `w`, in its triangle order, as a build makes it.
    fn original_of(w: &WeldedMesh) -> Original {
        Original::new(w, &crate::partition::triangle_order(w))
    }

    /// Every sample of each triangle of `indices`, one entry per triangle.
    fn every_sample(indices: &[u32]) -> Vec<Owned> {
        indices.chunks_exact(3).map(|t| Owned::triangle(0, [t[0], t[1], t[2]], 0x7f)).collect()
    }

    /// [`bumpy`] measured as a group of level 1 is: its level-0 samples against its output.
    struct Level1 {
        w: WeldedMesh,
        output: Vec<u32>,
        owned: Vec<Owned>,
        errors: Vec<f32>,
        sizes: Vec<f32>,
        original: Original,
    }

    impl Level1 {
        fn new(n: u32) -> Level1 {
            let (w, output) = bumpy(n);
            let (sizes, original) = (part_sizes(&w), original_of(&w));
            let owned = every_sample(&w.indices);
            let errors = vec![0.0; owned.len()];
            Level1 { w, output, owned, errors, sizes, original }
        }

        /// The measure from the starting bound `floor`: the error and each sample's triangle.
        fn measure(&self, floor: f64) -> (f64, Vec<u32>) {
            let input = &self.w.indices;
            let sides = Sides { input, triangle_errors: &self.errors, owned: Some(&self.owned), members: input };
            let (worst, _, found) =
                measure(&self.w, &sides, &self.output, &self.sizes, floor, None, Some(&self.original));
            (worst, found)
        }
    }

    #[test]
    fn the_starting_bound_only_decides_where_queries_stop() {
        let group = Level1::new(8);
        let total = |floor: f64| group.measure(floor).0;
        // A group stores at least its members' error: measuring from it gives the same value.
        let exact = total(0.0);
        assert!(exact > 0.1, "{exact}");
        for floor in [0.25 * exact, 0.9 * exact] {
            assert_eq!(total(floor), exact);
        }
        assert_eq!(total(2.0 * exact), 2.0 * exact);
    }

    #[test]
    fn a_sample_settled_by_the_last_query_lies_within_the_bound_of_its_triangle() {
        // Points near a tilted triangle, pairs of them as (last query, next sample): whenever
        // the next is settled, its true distance to the triangle is within the bound.
        let tri: Triangle<f32> = [[0.0, 0.0, 0.0], [1.0, 0.2, 0.1], [0.3, 1.0, -0.2]];
        let mut state = 11u64;
        let mut unit = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let distance = |p: [f32; 3]| mres_geom::bvh::point_triangle_distance2(p, &tri).sqrt();
        let (mut settled, mut refused) = (0, 0);
        for _ in 0..20_000 {
            let q = [0, 1, 2].map(|_| 1.6 * unit() - 0.3);
            let p = [0, 1, 2].map(|k| q[k] + 0.2 * unit() - 0.1);
            let bound = 0.5 * unit();
            let last = Last { point: q, distance: distance(q) };
            if last.settles(p, bound * bound) {
                settled += 1;
                assert!(distance(p) <= bound, "{p:?} from {q:?}: {} beyond {bound}", distance(p));
            } else if distance(p) <= bound {
                refused += 1;
            }
        }
        // Not vacuous: many settle, and some within the bound are left to a query.
        assert!(settled > 1_000 && refused > 0, "{settled} settled, {refused} refused");
    }

    #[test]
    fn every_sample_found_at_a_triangle_lies_within_the_error_of_it() {
        // The hand-down gives each measured sample to the cluster of the triangle it was found
        // at, which must be within the group's error of it, also where the last query settled it.
        let group = Level1::new(16);
        let (w, output, input) = (&group.w, &group.output, &group.w.indices);
        let at = |v: u32| w.positions[v as usize];
        let exact = group.measure(0.0).0;
        for floor in [0.0, 0.5 * exact, 3.0 * exact] {
            let (worst, found) = group.measure(floor);
            let mut checked = 0;
            for (i, t) in input.chunks_exact(3).enumerate() {
                let tri = [at(t[0]), at(t[1]), at(t[2])];
                for (b, &f) in found[7 * i..7 * i + 7].iter().enumerate().filter(|(_, &f)| f < VANISHED) {
                    let o = [0, 1, 2].map(|k| at(output[3 * f as usize + k]));
                    let d2 = mres_geom::bvh::point_triangle_distance2(sample_point(&tri, b), &o);
                    assert!((d2 as f64).sqrt() <= worst * 1.0001, "entry {i} sample {b}: {} > {worst}", d2.sqrt());
                    checked += 1;
                }
            }
            assert!(checked > input.len(), "{checked} samples found at floor {floor}");
        }
    }

    #[test]
    fn far_samples_name_the_spot_that_sets_the_error() {
        let (w, input, output) = tent(0.25);
        let sizes = part_sizes(&w);
        let id = |v: u32| w.position_ids[v as usize];
        let peak = (0..w.positions.len() as u32).find(|&v| w.positions[v as usize][2] > 0.0).unwrap();
        let errors = vec![0.0; input.len() / 3];
        let sides = Sides { input: &input, triangle_errors: &errors, owned: None, members: &input };
        let (worst, far, _) = measure(&w, &sides, &output, &sizes, 0.0, Some(0.1), None);
        // The peak (0.25 above the output) was found beyond the bound, so it is recorded; the
        // hot positions are the peak's and those of every input triangle using it (all four).
        let hot = far.hot(&w, &input, 0.2);
        let mut all: Vec<u32> = input.iter().map(|&v| id(v)).collect();
        all.sort_unstable();
        all.dedup();
        assert!(hot.binary_search(&id(peak)).is_ok() && hot == all, "{hot:?}");
        // Nothing is farther than the error itself, nor recorded without a threshold.
        assert!(far.hot(&w, &input, worst).is_empty());
        let (_, none, _) = measure(&w, &sides, &output, &sizes, 0.0, None, None);
        assert!(none.hot(&w, &input, 0.0).is_empty());
    }

    #[test]
    fn far_level0_samples_name_the_group_input_around_them() {
        // Above level 1 a group's input is its members' triangles and its level-0 samples lie
        // on triangles whose corners that input has mostly lost: here a small level-0 triangle
        // under a tent whose peak is the only input position near it. A retry must lock the
        // input there (the peak and its ring), not the lost corners, which lock nothing.
        let small = [[0.45, 0.45, 0.9], [0.55, 0.45, 0.9], [0.5, 0.55, 0.9]];
        let square = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let mut positions = square.to_vec();
        positions.push([0.5, 0.5, 1.0]);
        positions.extend(small);
        let mesh = SourceMesh::positions_only(positions, vec![0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4, 5, 6, 7]);
        let w = weld(&mesh, &BakeSettings::default()).unwrap();
        let at = |p: [f32; 3]| welded_at(&w, p);
        let (c, peak, level0) = (square.map(at), at([0.5, 0.5, 1.0]), small.map(at));
        let input: Vec<u32> = (0..4).flat_map(|k| [c[k], c[(k + 1) % 4], peak]).collect();
        let output = vec![c[0], c[1], c[2], c[0], c[2], c[3]];
        let owned = [Owned::triangle(0, level0, 0x7f)];
        let sides = Sides { input: &level0, triangle_errors: &[0.0], owned: Some(&owned), members: &input };
        let sizes = vec![10.0; w.position_count];
        let original = original_of(&w);
        let (worst, far, _) = measure(&w, &sides, &output, &sizes, 0.0, Some(0.1), Some(&original));
        assert!(worst > 0.85, "{worst}");
        // Only the level-0 samples are that far: the output is within 0.5 of the tent.
        let hot = far.hot(&w, &input, 0.6);
        let id = |v: u32| w.position_ids[v as usize];
        let mut all: Vec<u32> = input.iter().map(|&v| id(v)).collect();
        all.sort_unstable();
        all.dedup();
        assert!(all.iter().all(|p| hot.binary_search(p).is_ok()), "{hot:?} lacks some of {all:?}");
    }

    #[test]
    fn a_vanished_part_within_the_bound_is_measured_no_more() {
        // The tent (peak 0.25 above the flat output), then two small triangles far above it,
        // each its own part, that the output dropped: a (0.07 across) and b (0.57 across).
        let mut positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, 0.25]];
        positions.extend([[0.0, 0.0, 3.0], [0.05, 0.0, 3.0], [0.0, 0.05, 3.0]]);
        positions.extend([[0.0, 0.0, 5.0], [0.4, 0.0, 5.0], [0.0, 0.4, 5.0]]);
        let indices = vec![0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4, 5, 6, 7, 8, 9, 10];
        let w = weld(&SourceMesh::positions_only(positions.clone(), indices), &BakeSettings::default()).unwrap();
        // Welded ids by nearest position (weld snaps to its grid).
        let at = |p: [f32; 3]| welded_at(&w, p);
        let input: Vec<u32> =
            [0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4, 5, 6, 7, 8, 9, 10].map(|v| at(positions[v])).to_vec();
        let output: Vec<u32> = [0, 1, 2, 0, 2, 3].map(|v| at(positions[v])).to_vec();
        let sizes = part_sizes(&w);
        let owned = every_sample(&input);
        let errors = vec![0.0; owned.len()];
        let sides = Sides { input: &input, triangle_errors: &errors, owned: Some(&owned), members: &input };
        let original = original_of(&w);
        let (worst, _, found) = measure(&w, &sides, &output, &sizes, 0.0, None, Some(&original));
        // a counts for its size at most, 0.07, within the peak's 0.25 by the time its corners
        // are met: it is marked without a query. b counts for its size, 0.57: its corners are
        // measured and set the error (so b was not marked before), and then its other samples
        // are within the bound and it is marked too. Neither is handed down; the tent is.
        let size = |v: usize| sizes[w.position_ids[at(positions[v]) as usize] as usize] as f64;
        assert!(size(5) < 0.25 && size(8) > 0.25);
        assert!(worst >= size(8) && worst < size(8) * 1.001, "{worst} vs b's size {}", size(8));
        let vanished = |e: usize| found[7 * e..7 * e + 7].contains(&VANISHED);
        assert!(vanished(4) && vanished(5), "a and b are marked: {:?}", &found[28..]);
        assert!((0..4).all(|e| !vanished(e)), "the tent is not: {found:?}");
        let (kept, _) = crate::samples::without_vanished(owned.clone(), found);
        assert_eq!(kept, &owned[..4]);
    }
}
