//! Settling a measure's input samples a patch at a time (docs/INVARIANTS.md §4): where a
//! sphere around a run of input entries lies so close to the output that no point in it can
//! raise the group's error, one query at its centre stands for all of their samples.
//!
//! Distance to a surface is 1-Lipschitz: every point within `R` of a centre whose distance is
//! `d` lies within `d + R`. The runs are the entries in Morton order (see
//! [`crate::samples::Owned`]), their boxes kept in a pyramid built in linear time, and a run is
//! halved until it settles or is one entry; what is left is measured sample by sample
//! (`deviation::InputSide`). No library settles point sets against a surface this way (a
//! hierarchy's nearest query answers one point), so it is written here.

use crate::samples::set_bits;
use mres_geom::bvh::Triangle;
use mres_geom::walk::{Surface, STEPS};
use rayon::prelude::*;

/// Input → output, a patch at a time: where a sphere around several input entries (level-0
/// triangles, or balls grown by their `reach`: see [`crate::samples`]) lies so
/// close to the output that no point in it can raise the error, one query at its centre
/// settles all of their samples. Distance to a surface is 1-Lipschitz, so every point within
/// `R` of the centre is within `d + R` of the output; a patch is settled when `d + R` is below
/// `bound(e)` (the distance under which a sample of member error `e` cannot raise the current
/// maximum). Its triangles' duties are cleared and their measured samples `found` at the
/// triangle the centre's query stopped at, within the bound of each of them (a corner the
/// output kept stays unfound: the hand-down gives it to a cluster using it, which keeps the
/// next level's errors tight). Patches are runs of `input`
/// (in Morton order, see [`Owned`](crate::samples::Owned)), halved until they settle or hold one triangle; what is left is
/// measured sample by sample. At upper levels, whose errors dwarf the level-0 triangles, this
/// replaces most of the three queries per level-0 triangle by one per patch. At the lower
/// levels, where hardly an entry is small enough to settle (see [`FEW_SMALL`]), it does
/// nothing: building and walking the pyramid there cost more than the queries it spared.
pub(crate) fn accept_patches(
    (input, reach): (&[Triangle<f32>], &[f32]),
    (duty, found): (&mut [u8], &mut [u32]),
    output: &Surface<f32>,
    triangle_errors: &[f32],
    bound: impl Fn(f32) -> f32 + Sync,
) {
    if input.is_empty() {
        return;
    }
    // A patch settles only if each of its entries' boxes is as small as it must be, for the
    // smallest member error: count those (an upper bound on what patches can settle) among
    // the entries to measure (those with a box), before building anything (at the lower
    // levels hardly any is).
    let half = 0.5 * bound(0.0);
    let count = |b: Box3| half_diagonal(&b).map_or((0, 0), |r| (1, usize::from(r < half)));
    let entries = || input.par_iter().zip(&duty[..]).zip(reach).with_min_len(4096);
    let (measured, small) = entries().map(|e| count(leaf(e))).reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    if small * FEW_SMALL < measured {
        return;
    }
    let boxes = BoxPyramid::new(entries().map(leaf).collect(), triangle_errors);
    let patches = Patches { boxes: &boxes, output, bound: &bound };
    // The patches above runs of 2^PATCH_RUN entries first, then each such run left unsettled
    // on its own, side by side (a group's runs are many only at the top levels, where one group
    // holds every level-0 triangle); the same for any thread count.
    let top = boxes.levels.len() - 1;
    if top <= PATCH_RUN {
        patches.settle((top, 0), 0, (duty, found), 0, |_| {});
        return;
    }
    let mut open = vec![false; input.len().div_ceil(1 << PATCH_RUN)];
    patches.settle((top, 0), PATCH_RUN, (duty, found), 0, |k| open[k] = true);
    let runs = duty.par_chunks_mut(1 << PATCH_RUN).zip(found.par_chunks_mut(7 << PATCH_RUN));
    runs.enumerate().filter(|(k, _)| open[*k]).for_each(|(k, (duty, found))| {
        patches.settle((PATCH_RUN, k), 0, (duty, found), k << PATCH_RUN, |_| {});
    });
}

/// Entries of a run whose patches [`accept_patches`] tries on its own: 2^12, as the
/// measure's runs of input triangles (`deviation::RUN_TRIANGLES`).
const PATCH_RUN: usize = 12;

/// [`accept_patches`] tries no patch where fewer than one in this many of the entries to
/// measure could settle at all: it would spare at most that share of the queries. Measured on
/// the Stanford dragon (one thread): its first five levels settle 1-6 % of their entries by
/// patches, and skipping them there saves 2-3 % of the bake; see docs/BENCHMARKS.md.
const FEW_SMALL: usize = 8;

/// What [`accept_patches`] settles patches with.
struct Patches<'a, F> {
    boxes: &'a BoxPyramid,
    output: &'a Surface<f32>,
    bound: &'a F,
}

impl<F: Fn(f32) -> f32> Patches<'_, F> {
    /// Settles what it can of the subtree of pyramid node `root` (level, index), down to
    /// level `floor`, whose unsettled nodes go to `open` (by index); `duty` and `found` are
    /// the entries' from entry `first` on.
    fn settle(
        &self,
        root: (usize, usize),
        floor: usize,
        (duty, found): (&mut [u8], &mut [u32]),
        first: usize,
        mut open: impl FnMut(usize),
    ) {
        let boxes = self.boxes;
        let mut hint = usize::MAX;
        let mut stack = vec![root];
        // Most nodes share their error (level-0 entries have none): the bound is computed anew
        // only where it changes.
        let (mut error, mut limit) = (f32::NAN, 0.0);
        while let Some((level, k)) = stack.pop() {
            let b = &boxes.levels[level][k];
            let Some(r2) = half_diagonal2(b) else { continue };
            if boxes.errors[level][k].to_bits() != error.to_bits() {
                error = boxes.errors[level][k];
                limit = (self.bound)(error);
            }
            // Far too large to settle: no root to take (the upper levels of a large group).
            let too_large = r2 > 0.25 * limit * limit * (1.0 + 1e-4);
            let radius = if too_large { f32::INFINITY } else { padded(r2) };
            if radius < 0.5 * limit {
                let center = centre(b);
                let enough = (limit - radius) * (limit - radius);
                let (d2, nearest) = self.output.nearest_squared(center, enough, hint, STEPS);
                hint = nearest;
                if d2 <= enough {
                    let run = (k << level) - first..((k + 1) << level).min(first + duty.len()) - first;
                    for i in run {
                        for b in set_bits(duty[i]) {
                            found[7 * i + b] = nearest as u32;
                        }
                        duty[i] = 0;
                    }
                    continue;
                }
            }
            if level == floor {
                open(k);
            } else {
                let children = [(level - 1, 2 * k + 1), (level - 1, 2 * k)];
                stack.extend(children.into_iter().filter(|&(l, c)| c < boxes.levels[l].len()));
            }
        }
    }
}

/// The pyramid's level 0 for one entry: the box of a triangle grown by its `reach` (see
/// `InputSide::reach`); one whose duty is 0 has nothing to measure and gets an empty box.
fn leaf(((t, &duty), &reach): ((&Triangle<f32>, &u8), &f32)) -> Box3 {
    if duty == 0 {
        return ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    }
    let lo = [0, 1, 2].map(|k| lesser(lesser(t[0][k], t[1][k]), t[2][k]) - reach);
    let hi = [0, 1, 2].map(|k| greater(greater(t[0][k], t[1][k]), t[2][k]) + reach);
    (lo, hi)
}

/// Bounding boxes of runs of triangles: level 0 one per triangle, level j + 1 the union of
/// pairs of level j (runs of 2^j triangles), up to one box for all. Built in linear time, so
/// that trying patches costs little where none settles.
struct BoxPyramid {
    levels: Vec<Vec<Box3>>,
    /// The same pyramid of the runs' largest triangle errors (a patch's bound needs it: one
    /// lookup, not a pass over the run).
    errors: Vec<Vec<f32>>,
}

impl BoxPyramid {
    /// The pyramid over `leaves` (see [`leaf`]), with their entries' `errors`.
    fn new(leaves: Vec<Box3>, errors: &[f32]) -> BoxPyramid {
        let mut levels = vec![leaves];
        while levels[levels.len() - 1].len() > 1 {
            let union = |p: &[Box3]| {
                let (mut lo, mut hi) = p[0];
                for b in &p[1..] {
                    for k in 0..3 {
                        (lo[k], hi[k]) = (lesser(lo[k], b.0[k]), greater(hi[k], b.1[k]));
                    }
                }
                (lo, hi)
            };
            let next = levels[levels.len() - 1].par_chunks(2).with_min_len(2048).map(union).collect();
            levels.push(next);
        }
        let mut error_levels = vec![errors.to_vec()];
        while error_levels.len() < levels.len() {
            let largest = |p: &[f32]| p.iter().copied().fold(0.0, f32::max);
            let next = error_levels[error_levels.len() - 1].par_chunks(2).with_min_len(2048).map(largest).collect();
            error_levels.push(next);
        }
        BoxPyramid { levels, errors: error_levels }
    }
}

/// An axis-aligned box: lower and upper corner.
pub(crate) type Box3 = ([f32; 3], [f32; 3]);

/// Comparisons rather than `min`/`max` (their NaN rules cost instructions on every triangle):
/// on finite values the same bounds, up to the sign of a zero, which neither a centre's query
/// nor a radius sees.
fn lesser(a: f32, b: f32) -> f32 {
    if b < a {
        b
    } else {
        a
    }
}

/// See [`lesser`].
fn greater(a: f32, b: f32) -> f32 {
    if b > a {
        b
    } else {
        a
    }
}

/// The centre of box `b`.
fn centre((lo, hi): &Box3) -> [f32; 3] {
    [0, 1, 2].map(|k| lo[k] * 0.5 + hi[k] * 0.5)
}

/// Half the diagonal of box `b`, padded for rounding (every point in it is within that of its
/// [`centre`]); `None` for an empty box.
fn half_diagonal(b: &Box3) -> Option<f32> {
    half_diagonal2(b).map(padded)
}

/// The square of half the diagonal of box `b` (from its [`centre`]), unpadded; `None` for an
/// empty box.
fn half_diagonal2(b: &Box3) -> Option<f32> {
    let (lo, hi) = b;
    if lo[0] > hi[0] {
        return None;
    }
    let c = centre(b);
    Some((0..3).map(|k| (hi[k] - c[k]).max(c[k] - lo[k])).map(|d| d * d).sum())
}

/// [`half_diagonal`] from its square.
fn padded(r2: f32) -> f32 {
    r2.sqrt() * (1.0 + 1e-5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::samples::sample_point;
    use mres_geom::bvh::point_triangle_distance2;

    /// A flat 8 × 8 grid of unit squares at z = 0 (two triangles each) and its corners' ids.
    fn floor() -> (Vec<Triangle<f32>>, Vec<u32>) {
        let id = |x: u32, y: u32| y * 9 + x;
        let at = |v: u32| [(v % 9) as f32, (v / 9) as f32, 0.0];
        let mut corners = Vec::new();
        for y in 0..8 {
            for x in 0..8 {
                let (a, b, c, d) = (id(x, y), id(x + 1, y), id(x + 1, y + 1), id(x, y + 1));
                corners.extend_from_slice(&[a, b, c, a, c, d]);
            }
        }
        (corners.chunks_exact(3).map(|t| [at(t[0]), at(t[1]), at(t[2])]).collect(), corners)
    }

    /// 64 × 64 small triangles (0.04 across) over the floor, row by row, at heights 0-0.2 from
    /// a fixed pseudo-random sequence.
    fn entries() -> Vec<Triangle<f32>> {
        let mut state = 7u64;
        let mut height = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32 * 0.2
        };
        let mut tris = Vec::new();
        for y in 0..64 {
            for x in 0..64 {
                let (px, py, z) = (0.1 + x as f32 / 8.0, 0.1 + y as f32 / 8.0, height());
                tris.push([[px, py, z], [px + 0.04, py, z], [px, py + 0.04, z]]);
            }
        }
        tris
    }

    #[test]
    fn settled_samples_lie_within_the_bound_of_the_triangle_they_are_found_at() {
        let (floor, ids) = floor();
        let output = Surface::new(floor.clone(), &ids);
        let input = entries();
        let n = input.len();
        let (mut duty, mut found) = (vec![0b111_1111u8; n], vec![u32::MAX; 7 * n]);
        let limit = 0.1f32;
        accept_patches((&input, &vec![0.0; n]), (&mut duty, &mut found), &output, &vec![0.0; n], |_| limit);
        let settled: Vec<usize> = (0..n).filter(|&i| duty[i] == 0).collect();
        // Every sample of a settled entry lies within the bound of the floor triangle it was
        // found at (the floor is flat, so that is its height), and so does every point of it.
        for &i in &settled {
            for b in 0..7 {
                let t = found[7 * i + b] as usize;
                assert!(t < floor.len(), "entry {i} sample {b} not found");
                let d2 = point_triangle_distance2(sample_point(&input[i], b), &floor[t]);
                assert!(d2 <= limit * limit, "entry {i} at height {} settled", input[i][0][2]);
            }
        }
        // Far from vacuous: about half the entries are within the bound, and runs of them settle.
        let near = input.iter().filter(|t| t[0][2] < 0.5 * limit).count();
        assert!(settled.len() * 2 >= near, "{} of {near} entries well within the bound settled", settled.len());
        // An unsettled entry keeps its duty and has nothing found.
        for i in (0..n).filter(|&i| duty[i] != 0) {
            assert_eq!(duty[i], 0b111_1111);
            assert!(found[7 * i..7 * i + 7].iter().all(|&f| f == u32::MAX));
        }
    }
}
