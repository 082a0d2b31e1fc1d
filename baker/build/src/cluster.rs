//! Cluster: split a triangle list into clusters of at most `max_triangles` triangles and
//! `max_vertices` vertices with meshopt's meshlet builder, and bound them.
//!
//! Clusters come from `meshopt_buildMeshletsSpatial` (SAH-driven). Level 0 asks for full
//! clusters (min = max = 128 triangles): measured on the Stanford dragon and the 1,600-box
//! scene, that fills level 0 to 128.0 where the default minimum (32) gives 123.5 and 96.0 and
//! the greedy `meshopt_buildMeshlets` gives 128.0 with 1–40% larger files (docs/BENCHMARKS.md).
//! Higher levels keep the smaller minimum, which gives tighter clusters.

use crate::settings::BakeSettings;
use meshopt::VertexDataAdapter;
use mres_format::Sphere;

/// Splits `indices` (a triangle list into `positions`) into clusters of `min_triangles` (a
/// multiple of 4) to `settings.max_triangles` triangles, except the last; each returned
/// cluster is a triangle list into the same vertex array.
pub fn split(indices: &[u32], positions: &[[f32; 3]], min_triangles: usize, settings: &BakeSettings) -> Vec<Vec<u32>> {
    if indices.is_empty() {
        return Vec::new();
    }
    let bytes = meshopt::typed_to_bytes(positions);
    let Ok(adapter) = VertexDataAdapter::new(bytes, 12, 0) else {
        return Vec::new();
    };
    let max_t = settings.max_triangles as usize;
    let max_vertices = settings.max_vertices as usize;
    let meshlets = meshopt::build_meshlets_spatial(indices, &adapter, max_vertices, min_triangles, max_t, 0.5);
    meshlets.iter().map(|m| m.triangles.iter().map(|&t| m.vertices[t as usize]).collect()).collect()
}

/// Bounding sphere of the vertices a triangle list uses (meshopt's Ritter-style bound).
pub fn bounding_sphere(indices: &[u32], positions: &[[f32; 3]]) -> Sphere {
    let bytes = meshopt::typed_to_bytes(positions);
    match VertexDataAdapter::new(bytes, 12, 0) {
        Ok(adapter) => {
            let b = meshopt::compute_cluster_bounds(indices, &adapter);
            // meshopt's sphere is exact up to float rounding; pad by one ulp-scale so that it
            // provably contains every vertex.
            let mut radius = b.radius;
            for &i in indices {
                radius = radius.max(distance(b.center, positions[i as usize]));
            }
            Sphere { center: b.center, radius: radius * (1.0 + 1e-6) }
        }
        Err(_) => Sphere { center: [0.0; 3], radius: 0.0 },
    }
}

/// Relative margin by which a group's sphere exceeds what containing its members' spheres
/// needs. Projected errors are evaluated in f32 (FORMAT.md §6), and `|centre − eye|` of two
/// different centres rounds differently by a few ulps of the distance; with this margin a
/// parent's distance stays below its child's for eyes up to ~4,000 radii away, where any group
/// whose error is below its radius projects under 0.25 px at 1080p. (Equal centres need no
/// margin: both distances round alike, so the largest member's centre is kept when it can be.)
pub const NESTING_MARGIN: f64 = 1e-3;

/// Sphere enclosing `spheres` with [`NESTING_MARGIN`]: centred on the largest sphere when that
/// one contains the others, else on the centre of their bounding box.
pub fn enclosing_sphere(spheres: impl Iterator<Item = Sphere> + Clone) -> Sphere {
    let dist = |a: [f32; 3], b: [f32; 3]| (0..3).map(|k| (a[k] as f64 - b[k] as f64).powi(2)).sum::<f64>().sqrt();
    let reach =
        |center: [f32; 3]| spheres.clone().map(|s| dist(center, s.center) + s.radius as f64).fold(0.0f64, f64::max);
    let largest = spheres.clone().fold(None::<Sphere>, |best, s| match best {
        Some(b) if b.radius >= s.radius => Some(b),
        _ => Some(s),
    });
    let Some(largest) = largest else { return Sphere { center: [0.0; 3], radius: 0.0 } };
    let center = if reach(largest.center) <= largest.radius as f64 {
        largest.center
    } else {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for s in spheres.clone() {
            for k in 0..3 {
                lo[k] = lo[k].min(s.center[k] as f64 - s.radius as f64);
                hi[k] = hi[k].max(s.center[k] as f64 + s.radius as f64);
            }
        }
        [((lo[0] + hi[0]) * 0.5) as f32, ((lo[1] + hi[1]) * 0.5) as f32, ((lo[2] + hi[2]) * 0.5) as f32]
    };
    let radius = (reach(center) * (1.0 + NESTING_MARGIN)) as f32;
    // Round up so that the f32 radius still holds the f64 bound.
    Sphere { center, radius: radius.next_up() }
}

/// Euclidean distance.
pub fn distance(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enclosing_sphere_contains_inputs() {
        let spheres = [
            Sphere { center: [0.0, 0.0, 0.0], radius: 1.0 },
            Sphere { center: [5.0, 1.0, 0.0], radius: 0.5 },
            Sphere { center: [2.0, -3.0, 1.0], radius: 2.0 },
        ];
        let s = enclosing_sphere(spheres.iter().copied());
        for c in spheres {
            assert!(distance(s.center, c.center) + c.radius <= s.radius);
        }
    }
}
