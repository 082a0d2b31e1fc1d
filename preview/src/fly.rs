//! The windowed viewer's fly camera: a position and a yaw/pitch direction, moved with speeds
//! scaled to the model's bounding sphere, turned into the same [`Camera`] the headless renders
//! and the selection use.

use mres_format::Sphere;

use crate::camera::{proj_y, Camera, DEFAULT_FOV_Y};

/// Radians of turn per pixel of mouse motion.
const LOOK_RADIANS_PER_PIXEL: f32 = 0.003;
/// Pitch limit, radians: just short of straight up or down, where the view matrix's up vector
/// would be parallel to the view direction.
const MAX_PITCH: f32 = 1.55;
/// Base speed in bounding-sphere radii per second: crosses the model in about four seconds.
const RADII_PER_SECOND: f32 = 0.5;
/// Speed factor while Shift is held.
const FAST_FACTOR: f32 = 5.0;

/// Movement asked for by the keys held, each in −1..=1 (view-relative; up is world +y).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Movement {
    /// Along the view direction (W +, S −).
    pub forward: f32,
    /// Sideways (D +, A −).
    pub right: f32,
    /// World up (E or Space +, Q or Ctrl −).
    pub up: f32,
    /// Shift: `FAST_FACTOR` times faster.
    pub fast: bool,
}

/// A free-flying camera; y is up, yaw 0 looks down −z (as [`Camera::view_matrix`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlyCamera {
    /// Eye position, object space.
    pub position: [f32; 3],
    /// Turn about +y, radians.
    pub yaw: f32,
    /// Elevation, radians, within ±`MAX_PITCH`.
    pub pitch: f32,
    /// The model's bounds: they set the speed and the near plane.
    pub bounds: Sphere,
    /// The point given to [`FlyCamera::looking_at`], kept until the camera turns or moves: the
    /// view matrix then comes from the same eye and target as the headless camera's, so the
    /// first frame in the window equals the headless render bit for bit (yaw and pitch alone
    /// round the direction differently).
    pub target: Option<[f32; 3]>,
}

impl FlyCamera {
    /// At `eye`, looking at the centre of `bounds`.
    pub fn looking_at(eye: [f32; 3], bounds: &Sphere) -> FlyCamera {
        let c = bounds.center;
        let d = [c[0] - eye[0], c[1] - eye[1], c[2] - eye[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let (yaw, pitch) =
            if len > 0.0 { (d[0].atan2(-d[2]), (d[1] / len).clamp(-1.0, 1.0).asin()) } else { (0.0, 0.0) };
        let pitch_clamped = pitch.clamp(-MAX_PITCH, MAX_PITCH);
        let target = (len > 0.0 && pitch == pitch_clamped).then_some(c);
        FlyCamera { position: eye, yaw, pitch: pitch_clamped, bounds: *bounds, target }
    }

    /// The headless default view ([`Camera::framing`]) for a `width` × `height` viewport.
    pub fn framing(bounds: &Sphere, width: u32, height: u32) -> FlyCamera {
        FlyCamera::looking_at(Camera::framing(bounds, width, height).eye, bounds)
    }

    /// Unit view direction.
    pub fn forward(&self) -> [f32; 3] {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        [cp * sy, sp, -cp * cy]
    }

    /// Unit horizontal right vector.
    pub fn right(&self) -> [f32; 3] {
        let (sy, cy) = self.yaw.sin_cos();
        [cy, 0.0, sy]
    }

    /// Turns by a mouse motion of (`dx`, `dy`) pixels (right and down positive).
    pub fn look(&mut self, dx: f32, dy: f32) {
        if dx != 0.0 || dy != 0.0 {
            self.target = None;
        }
        self.yaw += dx * LOOK_RADIANS_PER_PIXEL;
        self.pitch = (self.pitch - dy * LOOK_RADIANS_PER_PIXEL).clamp(-MAX_PITCH, MAX_PITCH);
    }

    /// Speed in object-space units per second.
    pub fn speed(&self, fast: bool) -> f32 {
        self.bounds.radius * RADII_PER_SECOND * if fast { FAST_FACTOR } else { 1.0 }
    }

    /// Moves for `seconds` as `movement` asks.
    pub fn fly(&mut self, movement: Movement, seconds: f32) {
        let step = self.speed(movement.fast) * seconds;
        if step * (movement.forward.abs() + movement.right.abs() + movement.up.abs()) != 0.0 {
            self.target = None;
        }
        let (f, r) = (self.forward(), self.right());
        for i in 0..3 {
            let up = if i == 1 { movement.up } else { 0.0 };
            self.position[i] += step * (f[i] * movement.forward + r[i] * movement.right + up);
        }
    }

    /// The camera for a `width` × `height` viewport (60° vertical field of view, near plane at
    /// 10⁻³ radii, as [`Camera::looking_at`]).
    pub fn camera(&self, width: u32, height: u32) -> Camera {
        let f = self.forward();
        let p = self.position;
        Camera {
            eye: p,
            target: self.target.unwrap_or([p[0] + f[0], p[1] + f[1], p[2] + f[2]]),
            proj_y: proj_y(DEFAULT_FOV_Y),
            z_near: self.bounds.radius * 1e-3,
            width,
            height,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    }

    #[test]
    fn framing_looks_at_the_centre_like_the_headless_camera() {
        let bounds = Sphere { center: [1.0, -2.0, 3.0], radius: 4.0 };
        let fly = FlyCamera::framing(&bounds, 800, 600);
        let headless = Camera::framing(&bounds, 800, 600);
        let cam = fly.camera(800, 600);
        assert_eq!(cam.eye, headless.eye);
        // The view direction points at the centre: the centre lies on the forward ray.
        let f = fly.forward();
        let d = dist(cam.eye, bounds.center);
        let along = [cam.eye[0] + f[0] * d, cam.eye[1] + f[1] * d, cam.eye[2] + f[2] * d];
        assert!(dist(along, bounds.center) < 1e-4 * d, "{along:?}");
        // Until it turns or moves, the camera is the headless one exactly.
        assert_eq!(cam, headless);
        let mut turned = fly;
        turned.look(1.0, 0.0);
        assert_ne!(turned.camera(800, 600).target, headless.target);
    }

    #[test]
    fn flying_forward_approaches_and_speed_scales_with_the_bounds() {
        let bounds = Sphere { center: [0.0; 3], radius: 10.0 };
        let mut fly = FlyCamera::looking_at([0.0, 0.0, 50.0], &bounds);
        fly.fly(Movement { forward: 1.0, ..Default::default() }, 1.0);
        assert!((dist(fly.position, bounds.center) - 45.0).abs() < 1e-4, "{:?}", fly.position);
        fly.fly(Movement { forward: 1.0, fast: true, ..Default::default() }, 1.0);
        assert!((dist(fly.position, bounds.center) - 20.0).abs() < 1e-3, "{:?}", fly.position);
        // Up is world +y whatever the view direction; right is horizontal.
        fly.look(0.0, -200.0);
        let y = fly.position[1];
        fly.fly(Movement { up: 1.0, ..Default::default() }, 1.0);
        assert!((fly.position[1] - y - 5.0).abs() < 1e-4);
        assert_eq!(fly.right()[1], 0.0);
    }

    #[test]
    fn pitch_stays_short_of_vertical() {
        let bounds = Sphere { center: [0.0; 3], radius: 1.0 };
        let mut fly = FlyCamera::looking_at([0.0, 0.0, 5.0], &bounds);
        fly.look(0.0, -1e6);
        assert_eq!(fly.pitch, MAX_PITCH);
        fly.look(0.0, 1e6);
        assert_eq!(fly.pitch, -MAX_PITCH);
        // A camera straight above still gets a usable direction.
        let above = FlyCamera::looking_at([0.0, 5.0, 0.0], &bounds);
        assert_eq!(above.pitch, -MAX_PITCH);
        assert!(above.camera(10, 10).view_matrix().iter().flatten().all(|v| v.is_finite()));
    }
}
