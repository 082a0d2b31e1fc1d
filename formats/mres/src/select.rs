//! The LOD selection rule shared by the validator, the CPU reference and the GPU path
//! (`docs/FORMAT.md` §6 gives the rule and its exact f32 operations).
//!
//! A cluster is drawn iff `projected(own) <= tau < projected(parent)`, where *own* is the
//! group that produced it (error 0 at level 0) and *parent* the group it belongs to. Both
//! functions take the resident hierarchy only, so a streamer can pick a cut from an
//! [`MresIndex`](crate::MresIndex) before fetching any page.
//!
//! ```
//! use mres_format::{uniform_cut, view_cut, write_mres, Dag, MresFile, ViewParams};
//!
//! // Four level-0 clusters simplified (error 0.01) into one root cluster.
//! let file = MresFile::parse(write_mres(&Dag::sample(), 3)?)?;
//! let (groups, clusters) = (&file.groups, &file.clusters);
//! // At threshold 0 the original clusters are drawn; past the error, the root.
//! assert_eq!(uniform_cut(groups, clusters, 0.0), vec![1, 2, 3, 4]);
//! assert_eq!(uniform_cut(groups, clusters, 0.02), vec![0]);
//!
//! // A camera 1000 units away sees 0.01 as well under a pixel: the root suffices.
//! let far = ViewParams { eye: [0.0, 0.0, 1000.0], proj_y: 1.0, viewport_height: 1080.0, z_near: 0.01 };
//! assert_eq!(view_cut(groups, clusters, &far, 1.0), vec![0]);
//! // Close up, the same error is many pixels: the original clusters are drawn.
//! let near = ViewParams { eye: [0.2, 0.05, 3.0], ..far };
//! assert_eq!(view_cut(groups, clusters, &near, 1.0), vec![1, 2, 3, 4]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use super::{ClusterInfo, Group, Sphere, NO_GROUP};

/// A camera as the selection rule sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewParams {
    /// Eye position, object space.
    pub eye: [f32; 3],
    /// `proj[1][1]` of the projection matrix (= 1 / tan(fov_y / 2)).
    pub proj_y: f32,
    /// Viewport height in pixels.
    pub viewport_height: f32,
    /// Near plane distance, object space (> 0); distances are clamped to it.
    pub z_near: f32,
}

/// Error in pixels of an object-space `error` at a group with bounds `sphere`, conservative
/// (measured at the sphere's nearest point). Infinite errors stay infinite.
pub fn projected_error(view: &ViewParams, sphere: &Sphere, error: f32) -> f32 {
    if error == 0.0 {
        return 0.0;
    }
    let dx = sphere.center[0] - view.eye[0];
    let dy = sphere.center[1] - view.eye[1];
    let dz = sphere.center[2] - view.eye[2];
    let distance = (dx * dx + dy * dy + dz * dz).sqrt();
    let d = (distance - sphere.radius).max(view.z_near);
    error / d * (view.viewport_height * 0.5) * view.proj_y
}

/// The (own, parent) errors of a cluster under `metric`.
fn cluster_errors(groups: &[Group], c: &ClusterInfo, metric: impl Fn(&Group) -> f32) -> (f32, f32) {
    let own = if c.own_group == NO_GROUP { 0.0 } else { metric(&groups[c.own_group as usize]) };
    (own, metric(&groups[c.group as usize]))
}

/// Clusters of the uniform cut at object-space error `threshold`: own ≤ threshold < parent.
/// Indices into `clusters`, ascending. See the [module example](self).
pub fn uniform_cut(groups: &[Group], clusters: &[ClusterInfo], threshold: f32) -> Vec<u32> {
    select(clusters, |c| cluster_errors(groups, c, |g| g.error), threshold)
}

/// Clusters of the view-dependent cut for `view` at `tau` pixels. Indices into `clusters`,
/// ascending. See the [module example](self).
pub fn view_cut(groups: &[Group], clusters: &[ClusterInfo], view: &ViewParams, tau: f32) -> Vec<u32> {
    select(clusters, |c| cluster_errors(groups, c, |g| projected_error(view, &g.sphere, g.error)), tau)
}

fn select(clusters: &[ClusterInfo], errors: impl Fn(&ClusterInfo) -> (f32, f32), tau: f32) -> Vec<u32> {
    clusters
        .iter()
        .enumerate()
        .filter(|(_, c)| {
            let (own, parent) = errors(c);
            own <= tau && tau < parent
        })
        .map(|(i, _)| i as u32)
        .collect()
}
