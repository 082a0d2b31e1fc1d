//! Two-sided distance between two triangle surfaces, measured as the validator measures error
//! honesty (docs/INVARIANTS.md §4): points sampled on one surface (every triangle's centroid
//! and edge midpoints, thinned deterministically) and their exact distance to the nearest
//! triangle of the other, found with [`mres_geom::bvh::Bvh`].
//!
//! `mres bench` uses it to compare builders at equal measured error: a cut of a DAG against
//! the input mesh it was built from.

use mres_geom::bvh::Bvh;
pub use mres_geom::bvh::Triangle;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Distances between a surface `A` (a cut) and a surface `B` (the input), in the triangles'
/// units. Forward is A → B (how far the cut strays from the input), backward B → A (how far
/// the input is from the cut: holes and lost parts show here).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Distance {
    /// The mean of the two directions' means (each direction weighs the same, however many
    /// points it sampled).
    pub mean: f64,
    /// The larger of the two maxima: the sampled Hausdorff distance.
    pub max: f64,
    /// Mean distance from A's samples to B.
    pub forward_mean: f64,
    /// Largest distance from A's samples to B.
    pub forward_max: f64,
    /// Mean distance from B's samples to A.
    pub backward_mean: f64,
    /// Largest distance from B's samples to A.
    pub backward_max: f64,
    /// Points sampled on A.
    pub forward_samples: u64,
    /// Points sampled on B.
    pub backward_samples: u64,
}

impl Distance {
    /// Every distance divided by `scale` (e.g. the bounding-box diagonal); counts unchanged.
    pub fn scaled(self, scale: f64) -> Distance {
        let s = |v: f64| v / scale;
        Distance {
            mean: s(self.mean),
            max: s(self.max),
            forward_mean: s(self.forward_mean),
            forward_max: s(self.forward_max),
            backward_mean: s(self.backward_mean),
            backward_max: s(self.backward_max),
            ..self
        }
    }
}

/// One direction's figures: mean, max and the number of points.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OneSided {
    /// Mean distance (infinite when the target is empty and there are samples).
    pub mean: f64,
    /// Largest distance.
    pub max: f64,
    /// Points measured.
    pub samples: u64,
}

/// Deterministic sample points on `tris`: every triangle's centroid and edge midpoints, in
/// triangle order, thinned by an even stride to at most `max` points. With each point, the
/// triangle it lies on. The same points the validator's honesty measure uses.
pub fn samples(tris: &[Triangle<f64>], max: usize) -> Vec<([f64; 3], usize)> {
    let stride = (tris.len() * 4).div_ceil(max.max(1)).max(1);
    let mid = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|k| (a[k] + b[k]) / 2.0);
    let mut out = Vec::with_capacity((tris.len() * 4).div_ceil(stride));
    for (i, t) in tris.iter().enumerate() {
        let centroid = [0, 1, 2].map(|k| (t[0][k] + t[1][k] + t[2][k]) / 3.0);
        for (k, p) in [centroid, mid(t[0], t[1]), mid(t[1], t[2]), mid(t[2], t[0])].into_iter().enumerate() {
            if (i * 4 + k) % stride == 0 {
                out.push((p, i));
            }
        }
    }
    out
}

/// Distance from at most `max_samples` points of `from` (see [`samples`]) to the surface
/// `to`, whose hierarchy `to_bvh` is. Parallel over chunks of points; the sums are added in
/// chunk order, so the result does not depend on the thread count.
pub fn one_sided(from: &[Triangle<f64>], to: &[Triangle<f64>], to_bvh: &Bvh<f64>, max_samples: usize) -> OneSided {
    let points = samples(from, max_samples);
    if points.is_empty() {
        return OneSided::default();
    }
    if to.is_empty() {
        return OneSided { mean: f64::INFINITY, max: f64::INFINITY, samples: points.len() as u64 };
    }
    // Consecutive points lie on neighbouring triangles of `from`, so the previous point's
    // nearest triangle is a good first guess (a hint only: the answer stays exact).
    let chunks: Vec<(f64, f64)> = points
        .par_chunks(1024)
        .map(|chunk| {
            let (mut sum, mut max, mut hint) = (0.0f64, 0.0f64, usize::MAX);
            for (p, _) in chunk {
                let (d2, t) = to_bvh.nearest_squared(to, *p, 0.0, hint);
                let d = d2.sqrt();
                sum += d;
                max = max.max(d);
                hint = t;
            }
            (sum, max)
        })
        .collect();
    let sum: f64 = chunks.iter().map(|c| c.0).sum();
    let max = chunks.iter().map(|c| c.1).fold(0.0, f64::max);
    OneSided { mean: sum / points.len() as f64, max, samples: points.len() as u64 }
}

/// A surface to measure against, with its hierarchy built once (for many cuts against one
/// input).
pub struct Surface {
    tris: Vec<Triangle<f64>>,
    bvh: Bvh<f64>,
}

impl Surface {
    /// Builds the hierarchy over `tris`.
    pub fn new(tris: Vec<Triangle<f64>>) -> Surface {
        let bvh = Bvh::new(&tris);
        Surface { tris, bvh }
    }

    /// The triangles.
    pub fn triangles(&self) -> &[Triangle<f64>] {
        &self.tris
    }
}

/// Two-sided distance between `cut` and `input`, with at most `max_samples` points per
/// direction. Builds both hierarchies; to measure many cuts against one input, build a
/// [`Surface`] once and call [`two_sided_with`].
pub fn two_sided(cut: &[Triangle<f64>], input: &[Triangle<f64>], max_samples: usize) -> Distance {
    two_sided_with(cut, &Surface::new(input.to_vec()), max_samples)
}

/// [`two_sided`] against a prepared input surface.
pub fn two_sided_with(cut: &[Triangle<f64>], input: &Surface, max_samples: usize) -> Distance {
    let forward = one_sided(cut, &input.tris, &input.bvh, max_samples);
    let backward = one_sided(&input.tris, cut, &Bvh::new(cut), max_samples);
    Distance {
        mean: (forward.mean + backward.mean) / 2.0,
        max: forward.max.max(backward.max),
        forward_mean: forward.mean,
        forward_max: forward.max,
        backward_mean: backward.mean,
        backward_max: backward.max,
        forward_samples: forward.samples,
        backward_samples: backward.samples,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit square at height 0, two triangles.
    fn square() -> Vec<Triangle<f64>> {
        let (a, b, c, d) = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]);
        vec![[a, b, c], [a, c, d]]
    }

    /// A tent over the unit square: a ridge of height `h` along y = 0.5, two sloped roof
    /// halves (two triangles each) and two vertical gable ends.
    fn tent(h: f64) -> Vec<Triangle<f64>> {
        let (a, b, c, d) = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]);
        let (r0, r1) = ([0.0, 0.5, h], [1.0, 0.5, h]);
        vec![[a, b, r1], [a, r1, r0], [d, r0, r1], [d, r1, c], [a, r0, d], [b, c, r1]]
    }

    #[test]
    fn tent_against_square_measures_the_peak() {
        let h = 0.3;
        let d = two_sided(&tent(h), &square(), 1000);
        // The ridge's midpoint is sampled and lies h above the square's interior.
        assert!((d.forward_max - h).abs() < 1e-12, "{d:?}");
        assert_eq!(d.max, d.forward_max);
        assert_eq!((d.forward_samples, d.backward_samples), (24, 8));
        // The square's points lie under the sloped roof: nearer to it than h, but not on it.
        assert!(d.backward_max > 0.0 && d.backward_max < h, "{d:?}");
        assert!(d.forward_mean > 0.0 && d.forward_mean < h, "{d:?}");
        assert!((d.mean - (d.forward_mean + d.backward_mean) / 2.0).abs() < 1e-15);
        // Scaling divides distances only.
        let s = d.scaled(2.0);
        assert_eq!((s.max, s.forward_samples), (d.max / 2.0, 24));
        // A surface against itself is at distance 0 both ways.
        let same = two_sided(&square(), &square(), 1000);
        assert!(same.max < 1e-12, "{same:?}");
    }

    #[test]
    fn samples_are_thinned_evenly_and_bounded() {
        let tris = tent(1.0);
        assert_eq!(samples(&tris, 1000).len(), 24);
        // 24 candidates, at most 5: stride 5, points 0, 5, 10, 15, 20.
        let few = samples(&tris, 5);
        assert_eq!(few.iter().map(|s| s.1).collect::<Vec<_>>(), [0, 1, 2, 3, 5]);
        let d = two_sided(&tris, &square(), 5);
        assert!(d.forward_samples <= 5 && d.backward_samples <= 5, "{d:?}");
    }

    #[test]
    fn an_empty_cut_is_infinitely_far() {
        let d = two_sided(&[], &square(), 100);
        assert_eq!(d.forward_samples, 0);
        assert!(d.backward_max.is_infinite() && d.max.is_infinite());
    }
}
