//! Cameras: view and projection matrices (right-handed view space looking down −z, reverse-Z
//! with an infinite far plane, Vulkan clip space), frustum planes, and the camera sets the
//! verify mode uses.

use mres_format::{select::ViewParams, Grid, Sphere};

use crate::gpu_types::GpuView;

/// A perspective camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position, object space.
    pub eye: [f32; 3],
    /// Point looked at, object space.
    pub target: [f32; 3],
    /// `proj[1][1]` = 1 / tan(fov_y / 2): computed once, so that the matrix and the selection
    /// see the same f32 (`f32::tan` can round differently where the compiler folds it).
    pub proj_y: f32,
    /// Near plane distance, object space (> 0); also the selection's distance clamp.
    pub z_near: f32,
    /// Viewport width in pixels.
    pub width: u32,
    /// Viewport height in pixels.
    pub height: u32,
}

/// Default vertical field of view: 60°.
pub const DEFAULT_FOV_Y: f32 = std::f32::consts::FRAC_PI_3;

/// `proj[1][1]` for a vertical field of view in radians: 1 / tan(fov_y / 2), in f64 and then
/// rounded once to f32.
pub fn proj_y(fov_y: f32) -> f32 {
    (1.0 / (fov_y as f64 * 0.5).tan()) as f32
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn normalize(a: [f32; 3]) -> [f32; 3] {
    let l = dot(a, a).sqrt();
    if l > 0.0 {
        [a[0] / l, a[1] / l, a[2] / l]
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// Column-major 4×4 matrix product `a * b` (`m[col][row]`).
pub fn mul(a: &[[f32; 4]; 4], b: &[[f32; 4]; 4]) -> [[f32; 4]; 4] {
    let mut out = [[0.0f32; 4]; 4];
    for c in 0..4 {
        for r in 0..4 {
            out[c][r] = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    out
}

impl Camera {
    /// A camera at `eye` looking at the centre of `bounds`, with the near plane scaled to it.
    pub fn looking_at(eye: [f32; 3], bounds: &Sphere, width: u32, height: u32) -> Camera {
        Camera {
            eye,
            target: bounds.center,
            proj_y: proj_y(DEFAULT_FOV_Y),
            z_near: bounds.radius * 1e-3,
            width,
            height,
        }
    }

    /// A camera that frames `bounds` from a fixed three-quarter direction.
    pub fn framing(bounds: &Sphere, width: u32, height: u32) -> Camera {
        let dir = normalize([0.55, 0.35, 1.0]);
        let aspect = width as f32 / height.max(1) as f32;
        let half = (DEFAULT_FOV_Y * 0.5).tan() * aspect.min(1.0);
        let distance = bounds.radius / half.atan().sin() * 1.05;
        let c = bounds.center;
        let eye = [c[0] + dir[0] * distance, c[1] + dir[1] * distance, c[2] + dir[2] * distance];
        Camera::looking_at(eye, bounds, width, height)
    }

    /// The world-to-view matrix (right-handed, looking down −z, y up).
    pub fn view_matrix(&self) -> [[f32; 4]; 4] {
        let f = normalize(sub(self.target, self.eye));
        let up =
            if cross(f, [0.0, 1.0, 0.0]).iter().all(|v| v.abs() < 1e-4) { [0.0, 0.0, 1.0] } else { [0.0, 1.0, 0.0] };
        let s = normalize(cross(f, up));
        let u = cross(s, f);
        let e = self.eye;
        [
            [s[0], u[0], -f[0], 0.0],
            [s[1], u[1], -f[1], 0.0],
            [s[2], u[2], -f[2], 0.0],
            [-dot(s, e), -dot(u, e), dot(f, e), 1.0],
        ]
    }

    /// The projection: reverse-Z (depth = z_near / distance along −z), infinite far plane. The
    /// renderer flips y with a negative viewport height, so `proj[1][1]` stays positive.
    pub fn projection(&self) -> [[f32; 4]; 4] {
        let f = self.proj_y;
        let aspect = self.width as f32 / self.height.max(1) as f32;
        [[f / aspect, 0.0, 0.0, 0.0], [0.0, f, 0.0, 0.0], [0.0, 0.0, 0.0, -1.0], [0.0, 0.0, self.z_near, 0.0]]
    }

    /// The selection's view of this camera (FORMAT.md §6).
    pub fn view_params(&self) -> ViewParams {
        ViewParams { eye: self.eye, proj_y: self.proj_y, viewport_height: self.height as f32, z_near: self.z_near }
    }

    /// The GPU view block for this camera at threshold `tau` pixels.
    pub fn gpu_view(&self, tau: f32, grid: &Grid, cluster_count: u32, flags: u32) -> GpuView {
        let vp = mul(&self.projection(), &self.view_matrix());
        let row = |r: usize| [vp[0][r], vp[1][r], vp[2][r], vp[3][r]];
        let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
        let add =
            |a: [f32; 4], b: [f32; 4], s: f32| [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2], a[3] + s * b[3]];
        // Vulkan clip space: −w ≤ x, y ≤ w and 0 ≤ z ≤ w; with reverse-Z, z ≤ w is the near
        // plane and z ≥ 0 holds everywhere (no far plane).
        let planes = [add(r3, r0, 1.0), add(r3, r0, -1.0), add(r3, r1, 1.0), add(r3, r1, -1.0), add(r3, r2, -1.0), r2];
        let frustum = planes.map(|p| {
            let l = dot([p[0], p[1], p[2]], [p[0], p[1], p[2]]).sqrt();
            if l > 0.0 {
                [p[0] / l, p[1] / l, p[2] / l, p[3] / l]
            } else {
                [0.0, 0.0, 0.0, 1.0]
            }
        });
        let params = self.view_params();
        GpuView {
            view_proj: vp,
            frustum,
            eye: params.eye,
            proj_y: params.proj_y,
            viewport_height: params.viewport_height,
            z_near: params.z_near,
            tau,
            flags,
            grid_origin: grid.origin,
            grid_step: grid.step,
            cluster_count,
            // Filled in by the renderer, which knows the scene and the device.
            max_groups: 0,
            instance_count: 0,
            bin_count: 0,
            model_center: [0.0; 3],
            model_far: 0.0,
            model_near: 0.0,
            mode: crate::gpu_types::MODE_SHADED,
            visible_capacity: 0,
            index_capacity: 0,
        }
    }
}

/// Deterministic pseudo-random numbers in [0, 1) (splitmix64), so camera sets repeat exactly.
pub struct Rng(u64);

impl Rng {
    /// A generator from `seed`.
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }
    /// The next number in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32
    }
    /// A uniformly distributed unit vector.
    pub fn direction(&mut self) -> [f32; 3] {
        let z = self.next_f32() * 2.0 - 1.0;
        let a = self.next_f32() * std::f32::consts::TAU;
        let r = (1.0 - z * z).max(0.0).sqrt();
        [r * a.cos(), r * a.sin(), z]
    }
}

/// `n` eyes for the selection check: a fifth inside the bounds, the rest outside at distances
/// from just outside to 200 radii (cut from finest to coarsest).
pub fn selection_eyes(bounds: &Sphere, n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|i| {
            let dir = rng.direction();
            let t = rng.next_f32();
            let factor = match i % 5 {
                0 => 0.95 * t,
                1 => 1.0 + 0.5 * t,
                2 => 1.5 + 2.5 * t,
                3 => 4.0 + 16.0 * t,
                _ => 20.0 + 180.0 * t,
            };
            let d = bounds.radius * factor;
            let c = bounds.center;
            [c[0] + dir[0] * d, c[1] + dir[1] * d, c[2] + dir[2] * d]
        })
        .collect()
}

/// `n` eyes for the crack test: outside the bounds (so outside a closed mesh), close enough
/// that the model fills much of the view.
pub fn crack_eyes(bounds: &Sphere, n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let dir = rng.direction();
            let d = bounds.radius * (1.1 + 1.9 * rng.next_f32());
            let c = bounds.center;
            [c[0] + dir[0] * d, c[1] + dir[1] * d, c[2] + dir[2] * d]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn apply(m: &[[f32; 4]; 4], p: [f32; 3]) -> [f32; 4] {
        let mut out = [0.0f32; 4];
        for r in 0..4 {
            out[r] = m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r];
        }
        out
    }

    #[test]
    fn target_projects_to_the_centre_and_depth_is_reversed() {
        let bounds = Sphere { center: [1.0, 2.0, 3.0], radius: 2.0 };
        let cam = Camera::framing(&bounds, 640, 480);
        let vp = mul(&cam.projection(), &cam.view_matrix());
        let c = apply(&vp, bounds.center);
        assert!((c[0] / c[3]).abs() < 1e-5 && (c[1] / c[3]).abs() < 1e-5, "{c:?}");
        let depth_centre = c[2] / c[3];
        let d = dot(sub(bounds.center, cam.eye), sub(bounds.center, cam.eye)).sqrt();
        assert!((depth_centre - cam.z_near / d).abs() < 1e-6);
        // A point at the near plane has depth 1.
        let f = normalize(sub(cam.target, cam.eye));
        let near = [cam.eye[0] + f[0] * cam.z_near, cam.eye[1] + f[1] * cam.z_near, cam.eye[2] + f[2] * cam.z_near];
        let n = apply(&vp, near);
        assert!((n[2] / n[3] - 1.0).abs() < 1e-3);
        // The framed sphere is inside the frustum, a point behind the eye is not.
        let view = cam.gpu_view(1.0, &Grid { origin: [0.0; 3], step: 1.0 }, 0, 0);
        let inside = |p: [f32; 3], r: f32| {
            view.frustum.iter().all(|pl| pl[0] * p[0] + pl[1] * p[1] + pl[2] * p[2] + pl[3] >= -r)
        };
        assert!(inside(bounds.center, bounds.radius));
        let behind = [cam.eye[0] - f[0] * 10.0, cam.eye[1] - f[1] * 10.0, cam.eye[2] - f[2] * 10.0];
        assert!(!inside(behind, 1.0));
    }

    #[test]
    fn eye_sets_are_deterministic_and_placed() {
        let b = Sphere { center: [0.0; 3], radius: 1.0 };
        assert_eq!(selection_eyes(&b, 50, 7), selection_eyes(&b, 50, 7));
        let eyes = selection_eyes(&b, 200, 7);
        let dist = |e: &[f32; 3]| dot(*e, *e).sqrt();
        assert!(eyes.iter().filter(|e| dist(e) < 1.0).count() >= 40);
        assert!(crack_eyes(&b, 50, 3).iter().all(|e| dist(e) > 1.09));
    }
}
