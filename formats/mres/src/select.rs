//! The LOD selection rule shared by the validator, the CPU reference and the GPU path
//! (DESIGN.md "The selection rule"; FORMAT.md §6 gives the exact f32 operations).
//!
//! A cluster is drawn iff `projected(own) <= tau < projected(parent)`, where *own* is the
//! group that produced it (error 0 at level 0) and *parent* the group it belongs to.

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
pub fn uniform_cut(groups: &[Group], clusters: &[ClusterInfo], threshold: f32) -> Vec<u32> {
    select(clusters, |c| cluster_errors(groups, c, |g| g.error), threshold)
}

/// Clusters of the view-dependent cut for `view` at `tau` pixels.
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
