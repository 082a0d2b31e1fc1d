//! How much of the model's projected area a cut keeps (`preview FILE --headless --coverage`):
//! the model drawn from cameras around it at three times its bounding radius (the whole model
//! in view) at τ = 0 (full detail) and at larger thresholds, and the pixels it covers at each τ
//! over those of the full-detail render of the same camera, averaged over the cameras. Surface
//! area alone overstates what a viewer sees where parts overlap (a card field); this counts
//! the pixels, occlusion included.

use crate::camera::{crack_eyes, Camera};
use crate::gpu_types::FLAG_FRUSTUM_CULL;
use crate::image::count_model;
use crate::scene::SceneData;
use crate::vk::Renderer;
use anyhow::Result;
use serde_json::{json, Value};

/// Thresholds (pixels) at which coverage is counted: from what the crack test uses up to a
/// cut that holds a handful of clusters at 512 pixels.
pub const TAUS: [f32; 6] = [1.0, 4.0, 16.0, 64.0, 256.0, 1024.0];

/// Coverage at one threshold, over every camera.
#[derive(Clone, Debug)]
pub struct CoverageRow {
    /// Threshold, pixels.
    pub tau: f32,
    /// Mean triangles drawn per render.
    pub triangles: f64,
    /// Model pixels at `tau` over model pixels at τ = 0, the mean over the cameras.
    pub covered: f64,
}

impl CoverageRow {
    /// The row as JSON.
    pub fn to_json(&self) -> Value {
        json!({"tau": self.tau, "triangles": self.triangles, "covered": self.covered})
    }
}

/// Renders the model from `cameras` eyes (the crack test's directions, seed `seed`, at three
/// times the bounding radius) at τ = 0 and at each of [`TAUS`], `width` × `height` pixels; the
/// first row is τ = 0 itself. A camera that sees no model pixel at τ = 0 is left out.
pub fn coverage(
    renderer: &mut Renderer,
    scene: &SceneData,
    cameras: usize,
    (width, height): (u32, u32),
    seed: u64,
) -> Result<Vec<CoverageRow>> {
    let n = scene.clusters.len() as u32;
    let taus: Vec<f32> = std::iter::once(0.0).chain(TAUS).collect();
    let (mut covered, mut triangles, mut seen) = (vec![0.0f64; taus.len()], vec![0u64; taus.len()], 0usize);
    let (c, r) = (scene.bounds.center, scene.bounds.radius);
    for eye in crack_eyes(&scene.bounds, cameras, seed) {
        let d = [0, 1, 2].map(|k| eye[k] - c[k]);
        let scale = 3.0 * r / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(f32::MIN_POSITIVE);
        let camera = Camera::looking_at([0, 1, 2].map(|k| c[k] + d[k] * scale), &scene.bounds, width, height);
        let mut full = 0;
        for (k, &tau) in taus.iter().enumerate() {
            let frame = renderer.render(&camera.gpu_view(tau, &scene.grid, n, FLAG_FRUSTUM_CULL), width, height)?;
            let model = count_model(&frame.rgba);
            if k == 0 {
                full = model;
                if full == 0 {
                    break;
                }
                seen += 1;
            }
            covered[k] += model as f64 / full as f64;
            triangles[k] += frame.triangles;
        }
    }
    let seen = seen.max(1) as f64;
    Ok(taus
        .iter()
        .enumerate()
        .map(|(k, &tau)| CoverageRow { tau, triangles: triangles[k] as f64 / seen, covered: covered[k] / seen })
        .collect())
}
