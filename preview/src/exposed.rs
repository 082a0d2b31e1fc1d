//! Whether the full-detail surface is itself seen from behind: the crack test's rule for open
//! geometry (one-sided walls, holes, cards, parts with open rims).
//!
//! On a closed mesh seen from outside, a ray first crosses a front face (it enters the solid),
//! so a back face can only show through a hole. On open geometry the full-detail surface itself
//! shows back faces: through a window, past a card, through the gap between a lid and its box.
//! A cut that moves a closed part within its error (a thin lip seen edge-on slips by a fraction
//! of a pixel) then uncovers such a back face where the full-detail render still had the part
//! in front; that is no hole.
//!
//! The rule, per flagged pixel whose depth lies beyond the depth tolerance (a candidate hole):
//! it is **exposed**, not a hole, when along the ray of some pixel within the depth check's
//! window the full-detail (τ = 0) triangles have a back-facing crossing within the tolerance of
//! the pixel's depth, and the crossings in front of it sum to zero (+1 entering a front face,
//! −1 leaving through a back face): every surface in front of it is entered and left again,
//! so nothing of the full-detail surface encloses it. A dropped cluster of a closed mesh
//! leaves the inner far wall behind one front crossing (sum 1); a dropped one-sided wall
//! leaves ±1 too: both stay holes. A closed part that vanishes or slips is passed (sum 0):
//! what that does to the image is the depth check's to judge, not the crack test's.
//!
//! The crossings are exact ray casts on the CPU in f64 (the candidates are few: none on a
//! closed mesh that passes), over the full-detail triangles binned by screen tile per camera.
//! Hand-written because the question (signed crossings of one ray through a given pixel) is
//! tiny and the preview depends on `mres-format` only; a ray-tracing library would bring an
//! acceleration structure the tiles already are.

use crate::camera::Camera;

type V = [f64; 3];

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V, b: V) -> V {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Screen tile side of the bins, pixels.
const TILE: usize = 8;

/// The full-detail triangles of one camera, binned by the screen tiles their projection's
/// bounding box touches.
pub struct ExposureTest {
    eye: V,
    /// Camera basis: right, up, forward (object space).
    basis: [V; 3],
    /// `aspect / proj_y` and `1 / proj_y`: pixel centre to view-space direction.
    scale: [f64; 2],
    width: usize,
    height: usize,
    tiles_x: usize,
    triangles: Vec<[V; 3]>,
    /// Triangle indices per tile; triangles reaching behind the eye are in `everywhere`.
    bins: Vec<Vec<u32>>,
    everywhere: Vec<u32>,
}

impl ExposureTest {
    /// Bins `triangles` (object space, counter-clockwise seen from the front) for `camera`.
    pub fn new(camera: &Camera, triangles: Vec<[V; 3]>) -> ExposureTest {
        let m = camera.view_matrix();
        let row = |r: usize| [m[0][r] as f64, m[1][r] as f64, m[2][r] as f64];
        let (s, u, back) = (row(0), row(1), row(2));
        let f = [-back[0], -back[1], -back[2]];
        let (width, height) = (camera.width as usize, camera.height as usize);
        let aspect = width as f64 / height.max(1) as f64;
        let proj_y = camera.proj_y as f64;
        let tiles_x = width.div_ceil(TILE);
        let mut test = ExposureTest {
            eye: camera.eye.map(|v| v as f64),
            basis: [s, u, f],
            scale: [aspect / proj_y, 1.0 / proj_y],
            width,
            height,
            tiles_x,
            triangles,
            bins: vec![Vec::new(); tiles_x * height.div_ceil(TILE)],
            everywhere: Vec::new(),
        };
        test.bin();
        test
    }

    fn bin(&mut self) {
        let (w, h) = (self.width as f64, self.height as f64);
        for (i, t) in self.triangles.iter().enumerate() {
            let mut lo = [f64::INFINITY; 2];
            let mut hi = [f64::NEG_INFINITY; 2];
            let mut behind = false;
            for p in t {
                let d = sub(*p, self.eye);
                let z = dot(d, self.basis[2]);
                if z <= 0.0 {
                    behind = true;
                    break;
                }
                let px = (dot(d, self.basis[0]) / z / self.scale[0] + 1.0) * 0.5 * w;
                let py = (1.0 - dot(d, self.basis[1]) / z / self.scale[1]) * 0.5 * h;
                lo = [lo[0].min(px), lo[1].min(py)];
                hi = [hi[0].max(px), hi[1].max(py)];
            }
            if behind {
                self.everywhere.push(i as u32);
                continue;
            }
            // Pixel centres x + 0.5 inside [lo, hi], one pixel of slack for rounding.
            if hi[0] < -1.0 || hi[1] < -1.0 || lo[0] > w + 1.0 || lo[1] > h + 1.0 {
                continue;
            }
            let clamp = |v: f64, n: usize| (v.max(0.0) as usize).min(n - 1);
            let (x0, x1) = (clamp(lo[0] - 1.0, self.width) / TILE, clamp(hi[0] + 1.0, self.width) / TILE);
            let (y0, y1) = (clamp(lo[1] - 1.0, self.height) / TILE, clamp(hi[1] + 1.0, self.height) / TILE);
            for ty in y0..=y1 {
                for tx in x0..=x1 {
                    self.bins[ty * self.tiles_x + tx].push(i as u32);
                }
            }
        }
    }

    /// The unit ray direction through the centre of pixel (x, y) and the factor from view depth
    /// to distance along it.
    fn ray(&self, x: usize, y: usize) -> (V, f64) {
        let nx = (2.0 * (x as f64 + 0.5) / self.width as f64 - 1.0) * self.scale[0];
        let ny = (1.0 - 2.0 * (y as f64 + 0.5) / self.height as f64) * self.scale[1];
        let [s, u, f] = self.basis;
        let d = [0, 1, 2].map(|k| f[k] + nx * s[k] + ny * u[k]);
        let len = dot(d, d).sqrt();
        (d.map(|v| v / len), len)
    }

    /// Signed crossings (distance along the ray, +1 front / −1 back) of pixel (x, y)'s ray, by
    /// distance; two triangles that share an edge under the ray count once.
    fn crossings(&self, x: usize, y: usize) -> Vec<(f64, i32)> {
        let (d, _) = self.ray(x, y);
        let tile = (y / TILE) * self.tiles_x + x / TILE;
        let mut hits: Vec<(f64, i32)> = self.bins[tile]
            .iter()
            .chain(&self.everywhere)
            .filter_map(|&i| ray_triangle(self.eye, d, &self.triangles[i as usize]))
            .collect();
        hits.sort_by(|a, b| a.0.total_cmp(&b.0));
        hits.dedup_by(|b, a| a.1 == b.1 && (b.0 - a.0).abs() <= 1e-9 * b.0.max(1.0));
        hits
    }

    /// The view depth of the first crossing of pixel (x, y)'s ray if it is a back face: what the
    /// pixel centre sees of these triangles when they are the drawn cut.
    pub fn first_back_depth(&self, x: usize, y: usize) -> Option<f32> {
        let (_, len) = self.ray(x, y);
        self.crossings(x, y).first().filter(|c| c.1 < 0).map(|c| (c.0 / len) as f32)
    }

    /// Whether the flagged pixel (x, y), at view depths `depths` (its own and its neighbours':
    /// an edge-on triangle's interpolated depth can be far off its plane at a silhouette), shows
    /// a full-detail back face that nothing encloses: see the module docs. `tolerance(t)` is
    /// the allowed distance along the ray at distance t; rays of pixels within `radius` are
    /// tried (the centre first, the window sampled at most 7 × 7).
    pub fn exposed(&self, x: usize, y: usize, depths: &[f32], radius: usize, tolerance: impl Fn(f64) -> f64) -> bool {
        let (_, len) = self.ray(x, y);
        let targets: Vec<f64> = depths.iter().map(|&z| z as f64 * len).collect();
        let stride = radius.div_ceil(3).max(1);
        let offsets = std::iter::once((0i64, 0i64)).chain(
            (-(radius as i64)..=radius as i64)
                .step_by(stride)
                .flat_map(move |dy| (-(radius as i64)..=radius as i64).step_by(stride).map(move |dx| (dx, dy))),
        );
        offsets.into_iter().any(|(dx, dy)| {
            let (qx, qy) = (x as i64 + dx, y as i64 + dy);
            if qx < 0 || qy < 0 || qx >= self.width as i64 || qy >= self.height as i64 {
                return false;
            }
            let mut winding = 0;
            self.crossings(qx as usize, qy as usize).into_iter().any(|(t, sign)| {
                let unenclosed_back = sign < 0 && winding == 0;
                winding += sign;
                unenclosed_back && targets.iter().any(|&tc| (t - tc).abs() <= tolerance(tc))
            })
        })
    }
}

/// Distance along the unit ray (o, d) to triangle t and +1 if it faces the ray's origin
/// (counter-clockwise seen from it), −1 if not. Edges count as inside, so that a ray through a
/// shared edge hits at least one of its triangles (the duplicate is removed by the caller).
fn ray_triangle(o: V, d: V, t: &[V; 3]) -> Option<(f64, i32)> {
    let e1 = sub(t[1], t[0]);
    let e2 = sub(t[2], t[0]);
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det == 0.0 {
        return None;
    }
    let to = sub(o, t[0]);
    let a = dot(to, p) / det;
    let q = cross(to, e1);
    let b = dot(d, q) / det;
    let eps = 1e-12;
    if a < -eps || b < -eps || a + b > 1.0 + eps {
        return None;
    }
    let dist = dot(e2, q) / det;
    (dist > 0.0).then_some((dist, if dot(cross(e1, e2), d) < 0.0 { 1 } else { -1 }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mres_format::Sphere;

    /// The two triangles of the axis-aligned square at `z`, spanning [-s, s]², facing +z if
    /// `towards_plus`.
    fn square(z: f64, s: f64, towards_plus: bool) -> Vec<[V; 3]> {
        let (a, b, c, d) = ([-s, -s, z], [s, -s, z], [s, s, z], [-s, s, z]);
        if towards_plus {
            vec![[a, b, c], [a, c, d]]
        } else {
            vec![[a, c, b], [a, d, c]]
        }
    }

    fn camera() -> Camera {
        // On the +z axis looking at the origin: view depth = 5 − z on the axis.
        Camera::looking_at([0.0, 0.0, 5.0], &Sphere { center: [0.0; 3], radius: 1.0 }, 16, 16)
    }

    fn exposed_at(triangles: Vec<[V; 3]>, depth: f32) -> bool {
        let test = ExposureTest::new(&camera(), triangles);
        test.exposed(8, 8, &[depth], 1, |_| 0.05)
    }

    #[test]
    fn a_back_face_behind_nothing_or_behind_a_closed_part_is_exposed() {
        // A one-sided wall facing away from the eye (its back is seen): exposed at its depth.
        assert!(exposed_at(square(-1.0, 2.0, false), 6.0));
        // The same wall behind a thin closed slab (entered and left): still exposed.
        let mut t = square(-1.0, 2.0, false);
        t.extend(square(1.1, 0.5, true));
        t.extend(square(1.0, 0.5, false));
        assert!(exposed_at(t, 6.0));
        // Not at another depth.
        assert!(!exposed_at(square(-1.0, 2.0, false), 5.0));
    }

    #[test]
    fn a_back_face_enclosed_by_the_full_detail_surface_is_a_hole() {
        // Inside a closed box seen from outside (a front face in front of the far wall).
        let mut t = square(1.0, 2.0, true);
        t.extend(square(-1.0, 2.0, false));
        assert!(!exposed_at(t, 6.0));
        // Behind a one-sided wall seen from behind (−1 in front): a dropped wall, a hole.
        let mut t = square(1.0, 2.0, false);
        t.extend(square(-1.0, 2.0, false));
        assert!(!exposed_at(t, 6.0));
    }

    #[test]
    fn a_ray_through_a_shared_edge_crosses_once() {
        // The pixel (8, 8) ray of the 16-pixel camera runs along x = y = 0 slightly off centre;
        // put the shared diagonal of the square under the ray instead.
        let test = ExposureTest::new(&camera(), square(0.0, 2.0, true));
        let (d, _) = test.ray(8, 8);
        let hit = [test.eye[0] + d[0] * 5.0 / -d[2], test.eye[1] + d[1] * 5.0 / -d[2], 0.0];
        // The square's diagonal through `hit`: triangles (a, b, c) and (a, c, d) share a–c.
        let (a, c) = ([hit[0] - 1.0, hit[1] - 1.0, 0.0], [hit[0] + 1.0, hit[1] + 1.0, 0.0]);
        let (b, dd) = ([hit[0] + 1.0, hit[1] - 1.0, 0.0], [hit[0] - 1.0, hit[1] + 1.0, 0.0]);
        let test = ExposureTest::new(&camera(), vec![[a, b, c], [a, c, dd]]);
        assert_eq!(test.crossings(8, 8).len(), 1);
    }
}
