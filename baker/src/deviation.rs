//! The honest group error (DESIGN.md invariant 4): a group's stored error must bound the
//! distance between its simplified triangles and the level-0 surface they replace, both ways.
//!
//! meshoptimizer reports an estimate for one simplification step, measured against the step's
//! input rather than the original, and a group's error was that estimate made monotone; the
//! validator measured up to 2.6× more than it on the sample assets and 40× at one spot of the
//! Stanford dragon. Here each group measures, locally, the sampled two-sided distance `d`
//! between its output triangles S and its input triangles C (its members' triangles), and
//! stores `members' largest error + d`: by the triangle inequality, if every point of C is
//! within the members' error of the original surface (and back), every point of S is within
//! that plus `d`. Measuring against C, not the original, keeps the cost local (a few thousand
//! triangles per group), so the bake pays a small fraction of what measuring against the
//! original did.

use crate::bvh::{point_triangle_distance, Bvh};
use crate::parts::{diagonals, UnionFind};
use crate::weld::WeldedMesh;

/// The sampled distance is scaled by this before it is added: the samples (vertices, edge
/// midpoints, centroids) miss the largest distance between them, and the next level's samples
/// fall elsewhere. Measured: see docs/BENCHMARKS.md (honesty).
pub const SAMPLING_MARGIN: f64 = 1.0;

/// Per position id, the bounding-box diagonal of the original (level-0) connected part it
/// belongs to: how far off a point of that part can be when the part vanishes.
pub fn part_sizes(mesh: &WeldedMesh) -> Vec<f32> {
    let id = |v: u32| mesh.position_ids[v as usize];
    let mut sets = UnionFind::new(mesh.position_count);
    for t in mesh.indices.chunks_exact(3) {
        sets.union(id(t[0]), id(t[1]));
        sets.union(id(t[0]), id(t[2]));
    }
    let points = mesh.positions.iter().enumerate().map(|(v, p)| (id(v as u32), p.map(f64::from)));
    let diagonal = diagonals(&mut sets, points);
    (0..mesh.position_count as u32).map(|p| diagonal[sets.find(p) as usize] as f32).collect()
}

/// A group's stored error (object space): its members' largest error plus the margin-scaled
/// sampled distance between `input` (the members' triangles) and `output` (the simplified
/// ones), and at least `simplifier_error`, meshoptimizer's estimate. Both triangle lists are in
/// welded vertex ids; `part_size` is [`part_sizes`]. A point of the input that is farther from
/// the output than its part's size counts as its part's size (the part vanished).
pub fn group_error(
    mesh: &WeldedMesh,
    input: &[u32],
    output: &[u32],
    part_size: &[f32],
    members_error: f32,
    simplifier_error: f32,
) -> f32 {
    // Distances that would not raise the result above the simplifier's estimate need not be
    // found exactly: a query stops at the first triangle within the larger of them.
    let mut worst = ((simplifier_error as f64 - members_error as f64) / SAMPLING_MARGIN).max(0.0);
    let triangles = |indices: &[u32]| -> Vec<[[f64; 3]; 3]> {
        indices.chunks_exact(3).map(|t| [0, 1, 2].map(|k| mesh.positions[t[k] as usize].map(f64::from))).collect()
    };
    let (input_tris, output_tris) = (triangles(input), triangles(output));
    // Output → input: each output triangle's centroid and edge midpoints (its corners are input
    // vertices). Neighbouring samples are near the same triangle: try the last one found first.
    let input_bvh = Bvh::new(&input_tris);
    let mut last = 0;
    for t in &output_tris {
        for p in interior_samples(t) {
            if point_triangle_distance(p, &input_tris[last]) > worst {
                let (d, nearest) = input_bvh.nearest_beyond(&input_tris, p, worst);
                (worst, last) = (worst.max(d), nearest);
            }
        }
    }
    // Input → output: the input vertices the output dropped, and the centroid and edge
    // midpoints of each input triangle that lost a corner.
    let id = |v: u32| mesh.position_ids[v as usize];
    let mut kept: Vec<u32> = output.iter().map(|&v| id(v)).collect();
    kept.sort_unstable();
    kept.dedup();
    let output_bvh = Bvh::new(&output_tris);
    let mut last = 0;
    let mut far = |p: [f64; 3], v: u32| {
        if point_triangle_distance(p, &output_tris[last]) > worst {
            let (d, nearest) = output_bvh.nearest_beyond(&output_tris, p, worst);
            (worst, last) = (worst.max(d.min(part_size[id(v) as usize] as f64)), nearest);
        }
    };
    let mut dropped: Vec<u32> = input.iter().copied().filter(|&v| kept.binary_search(&id(v)).is_err()).collect();
    dropped.sort_unstable_by_key(|&v| (id(v), v));
    dropped.dedup_by_key(|v| id(*v));
    for v in dropped {
        far(mesh.positions[v as usize].map(f64::from), v);
    }
    for (t, tri) in input.chunks_exact(3).zip(&input_tris) {
        if t.iter().any(|&v| kept.binary_search(&id(v)).is_err()) {
            for p in interior_samples(tri) {
                far(p, t[0]);
            }
        }
    }
    // Rounded up to f32, so that the stored error is never below the measured sum.
    let error = members_error as f64 + SAMPLING_MARGIN * worst;
    let rounded = error as f32;
    let rounded = if (rounded as f64) < error { f32::from_bits(rounded.to_bits() + 1) } else { rounded };
    rounded.max(simplifier_error)
}

/// A triangle's centroid and edge midpoints: where the validator samples too.
fn interior_samples(t: &[[f64; 3]; 3]) -> [[f64; 3]; 4] {
    let mix =
        |a: [f64; 3], b: [f64; 3], c: [f64; 3], w: [f64; 3]| [0, 1, 2].map(|k| a[k] * w[0] + b[k] * w[1] + c[k] * w[2]);
    let (a, b, c) = (t[0], t[1], t[2]);
    let third = 1.0 / 3.0;
    [
        mix(a, b, c, [third; 3]),
        mix(a, b, c, [0.5, 0.5, 0.0]),
        mix(a, b, c, [0.0, 0.5, 0.5]),
        mix(a, b, c, [0.5, 0.0, 0.5]),
    ]
}
