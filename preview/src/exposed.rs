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
//! A second way not to be a hole covers what the rays of the window miss: a slip at grazing
//! incidence or an open rim that simplification moved. The drawn cut's own first crossing along
//! the pixel centre's ray is a back face at P, and every full-detail crossing in front of P lies
//! within the error τ allows (`τ · t / k` at distance t: an upper bound of the stored error of
//! any selected cluster with a point there) of the drawn cut, and P within it of the full-detail
//! surface. Errors are two-sided (docs/INVARIANTS.md §4), so every full-detail point lies that
//! close to the cut: the surface that hides P at full detail is drawn, moved by no more than the
//! error, only the ray passes it ([`ExposureTest::moved_within`]). Through a dropped cluster the
//! full-detail crossings in front lie farther from the cut than the error; along the hole's rim,
//! where they do not, the rim is a crack of the cut (an edge used an odd number of times
//! unmarked, or marked twice: the validator's rule (c) of docs/INVARIANTS.md §1), and no crack
//! may lie within the error of P or of those crossings. Holes, and gaps between levels that
//! are narrower than the error, stay holes.
//!
//! The crossings are exact ray casts on the CPU in f64 (the candidates are few: none on a
//! closed mesh that passes), over the full-detail triangles binned by screen tile per camera.
//! Hand-written because the question (signed crossings of one ray through a given pixel) is
//! tiny and the preview depends on `mres-format` only; a ray-tracing library would bring an
//! acceleration structure the tiles already are.

use crate::camera::Camera;
use mres_geom::bvh::point_triangle_distance;
use std::collections::HashMap;

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
    /// Cracks of a drawn cut ([`ExposureTest::with_cracks`]), binned the same way.
    cracks: Vec<[V; 2]>,
    crack_bins: Vec<Vec<u32>>,
    cracks_everywhere: Vec<u32>,
}

/// Where a primitive's projection falls.
enum Reach {
    /// It reaches behind the eye: every tile.
    Behind,
    /// Outside the image.
    Off,
    /// These tiles.
    Tiles(Box<dyn Iterator<Item = usize>>),
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
            cracks: Vec::new(),
            crack_bins: vec![Vec::new(); tiles_x * height.div_ceil(TILE)],
            cracks_everywhere: Vec::new(),
        };
        test.bin();
        test
    }

    fn bin(&mut self) {
        for i in 0..self.triangles.len() {
            match self.reach(&self.triangles[i]) {
                Reach::Behind => self.everywhere.push(i as u32),
                Reach::Tiles(tiles) => tiles.for_each(|tile| self.bins[tile].push(i as u32)),
                Reach::Off => {}
            }
        }
    }

    /// The tiles whose pixel centres the projection of `points`' bounding box may cover.
    fn reach(&self, points: &[V]) -> Reach {
        let (w, h) = (self.width as f64, self.height as f64);
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in points {
            let d = sub(*p, self.eye);
            let z = dot(d, self.basis[2]);
            if z <= 0.0 {
                return Reach::Behind;
            }
            let px = (dot(d, self.basis[0]) / z / self.scale[0] + 1.0) * 0.5 * w;
            let py = (1.0 - dot(d, self.basis[1]) / z / self.scale[1]) * 0.5 * h;
            lo = [lo[0].min(px), lo[1].min(py)];
            hi = [hi[0].max(px), hi[1].max(py)];
        }
        // Pixel centres x + 0.5 inside [lo, hi], one pixel of slack for rounding.
        if hi[0] < -1.0 || hi[1] < -1.0 || lo[0] > w + 1.0 || lo[1] > h + 1.0 {
            return Reach::Off;
        }
        let clamp = |v: f64, n: usize| (v.max(0.0) as usize).min(n - 1);
        let (x0, x1) = (clamp(lo[0] - 1.0, self.width) / TILE, clamp(hi[0] + 1.0, self.width) / TILE);
        let (y0, y1) = (clamp(lo[1] - 1.0, self.height) / TILE, clamp(hi[1] + 1.0, self.height) / TILE);
        let tiles_x = self.tiles_x;
        Reach::Tiles(Box::new((y0..=y1).flat_map(move |ty| (x0..=x1).map(move |tx| ty * tiles_x + tx))))
    }

    /// Adds the cut's cracks: the edges of these triangles (welded by position, as the grid
    /// decodes them) used an odd number of times unmarked or marked more than once, the
    /// validator's rule (c) of docs/INVARIANTS.md §1. `open` holds each triangle's open-edge
    /// marks (bit k: the edge from corner k to corner k + 1). A crack near a pixel keeps
    /// [`ExposureTest::moved_within`] from excusing it.
    pub fn with_cracks(mut self, open: &[u8]) -> ExposureTest {
        let key = |p: V| p.map(f64::to_bits);
        // Per edge (its ends' bits, ordered): unmarked uses, marked uses, the segment.
        type Uses = (u32, u32, [V; 2]);
        let mut uses: HashMap<([u64; 3], [u64; 3]), Uses> = HashMap::new();
        for (t, marks) in self.triangles.iter().zip(open.iter().chain(std::iter::repeat(&0))) {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let (ka, kb) = (key(a), key(b));
                let entry = uses.entry(if ka < kb { (ka, kb) } else { (kb, ka) }).or_insert((0, 0, [a, b]));
                if marks >> k & 1 == 1 {
                    entry.1 += 1;
                } else {
                    entry.0 += 1;
                }
            }
        }
        let mut cracks: Vec<[V; 2]> =
            uses.into_values().filter(|(unmarked, marked, _)| unmarked % 2 == 1 || *marked > 1).map(|u| u.2).collect();
        cracks.sort_by(|a, b| a.map(|p| p.map(f64::to_bits)).cmp(&b.map(|p| p.map(f64::to_bits))));
        for (i, c) in cracks.iter().enumerate() {
            match self.reach(c) {
                Reach::Behind => self.cracks_everywhere.push(i as u32),
                Reach::Tiles(tiles) => tiles.for_each(|tile| self.crack_bins[tile].push(i as u32)),
                Reach::Off => {}
            }
        }
        self.cracks = cracks;
        self
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

    /// Whether pixel (x, y)'s ray crosses none of these triangles: when they are the drawn cut,
    /// the pixel centre lies outside its silhouette, and a face the GPU drew there covers the
    /// pixel only through the rasterizer's snapping of vertices to its sub-pixel grid.
    pub fn misses(&self, x: usize, y: usize) -> bool {
        self.crossings(x, y).is_empty()
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

impl ExposureTest {
    /// Whether the back face that the drawn cut `cut` (binned for the same camera) shows at the
    /// centre of pixel (x, y) is this full-detail surface moved within `error(t)` (the allowed
    /// object-space error at distance t): the cut's first crossing there is a back face at P,
    /// P lies within the error of these triangles, and so does the drawn cut of every crossing
    /// of these triangles in front of P (module docs). Triangles are looked for in the tiles
    /// within `radius` pixels (the error τ allows projects to τ pixels).
    pub fn moved_within(
        &self,
        cut: &ExposureTest,
        x: usize,
        y: usize,
        radius: usize,
        error: impl Fn(f64) -> f64,
    ) -> bool {
        let Some(&(drawn, sign)) = cut.crossings(x, y).first() else { return false };
        let p = self.along(x, y, drawn);
        if sign > 0
            || self.distance_near(p, x, y, radius) > error(drawn)
            || cut.crack_near(p, x, y, radius, error(drawn))
        {
            return false;
        }
        self.crossings(x, y).into_iter().take_while(|c| c.0 < drawn).all(|(t, _)| {
            let q = self.along(x, y, t);
            cut.distance_near(q, x, y, radius) <= error(t) && !cut.crack_near(q, x, y, radius, error(t))
        })
    }

    /// Whether a crack of the cut ([`ExposureTest::with_cracks`]) binned in the tiles within
    /// `radius` pixels of (x, y) lies within `error` of `p`.
    fn crack_near(&self, p: V, x: usize, y: usize, radius: usize, error: f64) -> bool {
        self.near_tiles(x, y, radius)
            .flat_map(|tile| &self.crack_bins[tile])
            .chain(&self.cracks_everywhere)
            .any(|&i| point_segment_distance(p, &self.cracks[i as usize]) <= error)
    }

    /// The tiles within `radius` pixels of (x, y).
    fn near_tiles(&self, x: usize, y: usize, radius: usize) -> impl Iterator<Item = usize> + '_ {
        let (tx0, tx1) = (x.saturating_sub(radius) / TILE, (x + radius).min(self.width - 1) / TILE);
        let (ty0, ty1) = (y.saturating_sub(radius) / TILE, (y + radius).min(self.height - 1) / TILE);
        (ty0..=ty1).flat_map(move |ty| (tx0..=tx1).map(move |tx| ty * self.tiles_x + tx))
    }

    /// The point at distance `t` along pixel (x, y)'s centre ray.
    fn along(&self, x: usize, y: usize, t: f64) -> V {
        let (d, _) = self.ray(x, y);
        [0, 1, 2].map(|k| self.eye[k] + d[k] * t)
    }

    /// Distance from `p` to the nearest triangle binned in the tiles within `radius` pixels of
    /// (x, y) or reaching behind the eye (infinite if none).
    fn distance_near(&self, p: V, x: usize, y: usize, radius: usize) -> f64 {
        self.near_tiles(x, y, radius)
            .flat_map(|tile| &self.bins[tile])
            .chain(&self.everywhere)
            .map(|&i| point_triangle_distance(p, &self.triangles[i as usize]))
            .fold(f64::INFINITY, f64::min)
    }
}

/// Distance from `p` to the segment `s`.
fn point_segment_distance(p: V, s: &[V; 2]) -> f64 {
    let e = sub(s[1], s[0]);
    let len2 = dot(e, e);
    let f = if len2 > 0.0 { (dot(sub(p, s[0]), e) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let d = sub(p, [0, 1, 2].map(|k| s[0][k] + e[k] * f));
    dot(d, d).sqrt()
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

    /// The two triangles of the rectangle [x0, x1] × [y0, y1] at `z`, facing +z if
    /// `towards_plus`.
    fn rect(x: [f64; 2], y: [f64; 2], z: f64, towards_plus: bool) -> Vec<[V; 3]> {
        let (a, b, c, d) = ([x[0], y[0], z], [x[1], y[0], z], [x[1], y[1], z], [x[0], y[1], z]);
        if towards_plus {
            vec![[a, b, c], [a, c, d]]
        } else {
            vec![[a, c, b], [a, d, c]]
        }
    }

    /// A one-sided wall seen from behind at z = −1, and in front of it a one-sided sheet facing
    /// the eye at z = 1 whose open rim lies `gap` to the right of where pixel (8, 8)'s ray crosses
    /// it, as (full detail with the sheet across the ray, cut with the sheet's rim moved by
    /// `gap`): an open rim that simplification moved.
    fn moved_rim(gap: f64) -> (ExposureTest, ExposureTest) {
        let (d, _) = ExposureTest::new(&camera(), Vec::new()).ray(8, 8);
        // Where the ray from the eye (0, 0, 5) crosses z = 1.
        let h = [d[0] * (1.0 - 5.0) / d[2], d[1] * (1.0 - 5.0) / d[2]];
        let ys = [h[1] - 0.5, h[1] + 0.5];
        let mut full = square(-1.0, 2.0, false);
        full.extend(rect([h[0] - 0.5, h[0] + 0.5], ys, 1.0, true));
        let mut cut = square(-1.0, 2.0, false);
        cut.extend(rect([h[0] + gap, h[0] + 0.5], ys, 1.0, true));
        (ExposureTest::new(&camera(), full), ExposureTest::new(&camera(), cut))
    }

    #[test]
    fn a_rim_moved_within_the_error_uncovers_no_hole() {
        // The full detail encloses the wall's back face (the sheet in front, +1): the rays
        // alone call it a hole.
        let (full, cut) = moved_rim(0.02);
        assert!(!full.exposed(8, 8, &[6.0], 1, |_| 0.05));
        // The cut shows the wall there, the sheet moved by 0.02, within the error 0.05.
        assert!(cut.first_back_depth(8, 8).is_some());
        assert!(full.moved_within(&cut, 8, 8, 1, |_| 0.05));
        // Moved by 0.2: beyond the error, a hole.
        let (full, far) = moved_rim(0.2);
        assert!(!full.moved_within(&far, 8, 8, 1, |_| 0.05));
        // The same cut with the sheet's and the wall's outer edges marked open: still excused.
        // Unmarked, the sheet's moved edge is a crack (a gap between two levels looks so).
        let rims = [0b110, 0b011, 0b011, 0b110];
        let (full, cut) = moved_rim(0.02);
        assert!(full.moved_within(&cut.with_cracks(&rims), 8, 8, 1, |_| 0.05));
        let (full, cut) = moved_rim(0.02);
        assert!(!full.moved_within(&cut.with_cracks(&[0; 4]), 8, 8, 1, |_| 0.05));
    }

    #[test]
    fn cracks_are_the_unmarked_odd_and_twice_marked_edges() {
        // A square of two triangles: its 4 outer edges are used once, the diagonal twice.
        let test = |open: &[u8]| ExposureTest::new(&camera(), square(0.0, 1.0, true)).with_cracks(open).cracks.len();
        assert_eq!(test(&[0, 0]), 4);
        // [a, b, c] and [a, c, d]: outer edges a-b, b-c (bits 0, 1) and c-d, d-a (bits 1, 2).
        assert_eq!(test(&[0b011, 0b110]), 0);
        assert_eq!(test(&[0b011, 0b010]), 1);
        // The diagonal marked on both sides (bit 2 of the first, bit 0 of the second).
        assert_eq!(test(&[0b111, 0b111]), 1);
    }

    #[test]
    fn a_ray_beside_the_drawn_cut_misses_it() {
        // Pixel (8, 8) looks at the origin: a wall across it is crossed, one beside it is not.
        assert!(!ExposureTest::new(&camera(), square(-1.0, 2.0, false)).misses(8, 8));
        assert!(ExposureTest::new(&camera(), rect([0.5, 2.0], [-2.0, 2.0], -1.0, false)).misses(8, 8));
        // A box without its near wall: the ray through the gap crosses the far wall (a hole
        // is never missed this way).
        let mut open_box = square(-1.0, 2.0, false);
        open_box.extend(rect([-2.0, 2.0], [0.5, 2.0], 1.0, true));
        assert!(!ExposureTest::new(&camera(), open_box).misses(8, 8));
    }

    #[test]
    fn a_dropped_wall_is_not_moved_within_the_error() {
        // A closed box seen from outside, drawn without its near wall: the far wall's back face
        // shows, and the full detail's near wall is nowhere near the drawn cut.
        let mut full = square(1.0, 2.0, true);
        full.extend(square(-1.0, 2.0, false));
        let full = ExposureTest::new(&camera(), full);
        let cut = ExposureTest::new(&camera(), square(-1.0, 2.0, false));
        assert!(!full.moved_within(&cut, 8, 8, 1, |_| 0.05));
        // With the near wall drawn, the pixel shows a front face: nothing to excuse.
        assert!(!full.moved_within(&full, 8, 8, 1, |_| 0.05));
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
