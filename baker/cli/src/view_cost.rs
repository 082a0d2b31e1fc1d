//! What a renderer draws of a baked file, on the CPU: the triangles of the view-dependent cut
//! at τ = 1 px (FORMAT.md §6, the rule the GPU path applies) for copies of the mesh seen from
//! near to far, beside the discrete LOD chain ([`LodChain`], honest level errors) and full
//! detail. The stand-in for `preview --bench --grid 100 --tau 1` (NVIDIA H100: 4.33 M
//! triangles for the Stanford dragon's 10,000 copies against the chain's 28.26 M) that needs no
//! GPU.
//!
//! `mres bench` compares builders at equal *measured* error, which says nothing of the stored
//! errors a renderer selects by: a build whose errors grew looser drew 1.5× the triangles on
//! the GPU grid while every figure of the quality comparison stayed put. This figure moves with
//! the stored errors.
//!
//! The copies: the mesh's bounding sphere (radius r, over the level-0 positions) seen from 14
//! directions (the axes and the cube's diagonals) at [`DISTANCES`] distances from 3 r to 230 r
//! (the range the preview's 100 × 100 grid shows, spaced 2.5 r), log-spaced and weighted as
//! copies on a ground plane are (their number grows with the distance: weight ∝ distance² per
//! log step). Per copy the DAG draws its view cut and the chain its coarsest level whose
//! projected error is at most τ at the sphere's nearest point. Each copy is whole in view: the
//! grid's nearest copies are partly off screen, where the GPU culls the DAG's clusters one by
//! one and the chain's copies whole, so this counts against the DAG where near copies weigh
//! most (a card field: 1.25 of the chain here, about 0.5 on the grid; docs/BENCHMARKS.md).

use mres_check::lod_chain::LodChain;
use mres_format::select::{projected_error, view_cut, ViewParams};
use mres_format::{MresFile, Sphere};
use mres_import::mesh::bounds;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Threshold in pixels.
pub const TAU_PX: f32 = 1.0;

/// Viewport height in pixels (a 1920 × 1080 view).
pub const HEIGHT_PX: f32 = 1080.0;

/// Vertical field of view in degrees (the preview's).
pub const FOV_Y_DEGREES: f32 = 60.0;

/// Nearest and farthest copy, in bounding-sphere radii from its centre.
pub const RANGE_RADII: (f64, f64) = (3.0, 230.0);

/// Distances per direction, log-spaced over [`RANGE_RADII`].
pub const DISTANCES: usize = 48;

/// The figure for one file.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct ViewCost {
    /// Triangles per copy the DAG draws, weighted mean over the copies.
    pub dag_triangles: f64,
    /// Triangles per copy the LOD chain draws, the same copies.
    pub chain_triangles: f64,
    /// Triangles of full detail (the level-0 mesh).
    pub full_triangles: u64,
    /// Levels of the chain (the original included) and their errors (object space).
    pub chain_errors: Vec<f32>,
    /// Per distance (radii): the DAG's and the chain's triangles, mean over the directions.
    pub per_distance: Vec<(f64, f64, f64)>,
}

impl ViewCost {
    /// DAG ÷ chain (below 1: the DAG draws fewer).
    pub fn ratio(&self) -> f64 {
        self.dag_triangles / self.chain_triangles.max(1.0)
    }
}

/// The view cost of `file` beside its LOD chain (down to 128 triangles), each chain level's
/// error measured with at most `max_samples` points per direction.
pub fn of_file(file: &MresFile, max_samples: usize) -> anyhow::Result<ViewCost> {
    Ok(view_cost(file, &LodChain::build(file, 128, max_samples)?))
}

/// The view cost of `file` beside `chain` (built from the same file).
pub fn view_cost(file: &MresFile, chain: &LodChain) -> ViewCost {
    let bounds = bounding_sphere(&chain.positions);
    let r = bounds.radius.max(f32::MIN_POSITIVE) as f64;
    let (near, far) = RANGE_RADII;
    let distances: Vec<f64> =
        (0..DISTANCES).map(|i| near * (far / near).powf(i as f64 / (DISTANCES - 1) as f64)).collect();
    let proj_y = 1.0 / (FOV_Y_DEGREES.to_radians() * 0.5).tan();
    let dag = |view: &ViewParams| -> u64 {
        let cut = view_cut(&file.groups, &file.clusters, view, TAU_PX);
        cut.iter().map(|&c| file.clusters[c as usize].triangle_count as u64).sum()
    };
    let levels = &chain.levels;
    let coarsest = |view: &ViewParams| levels.iter().rposition(|l| projected_error(view, &bounds, l.error) <= TAU_PX);
    let chain_draw = |view: &ViewParams| coarsest(view).map_or(levels[0].index_count, |l| levels[l].index_count) / 3;
    let per_distance: Vec<(f64, f64, f64)> = distances
        .par_iter()
        .map(|&d| {
            let (mut ours, mut theirs) = (0u64, 0u64);
            for dir in DIRECTIONS.iter().map(|d| normalized(*d)) {
                let eye = [0, 1, 2].map(|k| bounds.center[k] + (dir[k] as f64 * d * r) as f32);
                let view = ViewParams { eye, proj_y, viewport_height: HEIGHT_PX, z_near: (r * 1e-2) as f32 };
                ours += dag(&view);
                theirs += chain_draw(&view) as u64;
            }
            let n = DIRECTIONS.len() as f64;
            (d, ours as f64 / n, theirs as f64 / n)
        })
        .collect();
    // Copies on a plane: their number at distance d grows as d, and log spacing puts d per
    // step: weight d² per distance.
    let total: f64 = distances.iter().map(|d| d * d).sum();
    let mean = |f: fn(&(f64, f64, f64)) -> f64| per_distance.iter().map(|p| p.0 * p.0 * f(p)).sum::<f64>() / total;
    ViewCost {
        dag_triangles: mean(|p| p.1),
        chain_triangles: mean(|p| p.2),
        full_triangles: (levels[0].index_count / 3) as u64,
        chain_errors: levels.iter().map(|l| l.error).collect(),
        per_distance,
    }
}

/// The axes and the cube's diagonals.
const DIRECTIONS: [[f32; 3]; 14] = [
    [1.0, 0.0, 0.0],
    [-1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, 0.0, -1.0],
    [1.0, 1.0, 1.0],
    [1.0, 1.0, -1.0],
    [1.0, -1.0, 1.0],
    [1.0, -1.0, -1.0],
    [-1.0, 1.0, 1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
    [-1.0, -1.0, -1.0],
];

fn normalized(v: [f32; 3]) -> [f32; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / l)
}

/// The sphere around the centre of `points`' box reaching the farthest of them.
fn bounding_sphere(points: &[[f32; 3]]) -> Sphere {
    let Some((lo, hi)) = bounds(points) else { return Sphere { center: [0.0; 3], radius: 0.0 } };
    let center = [0, 1, 2].map(|k| lo[k] * 0.5 + hi[k] * 0.5);
    let d2 = |p: &[f32; 3]| (0..3).map(|k| (p[k] - center[k]) as f64 * (p[k] - center[k]) as f64).sum::<f64>();
    let radius = points.iter().map(d2).fold(0.0, f64::max).sqrt() as f32;
    Sphere { center, radius }
}
