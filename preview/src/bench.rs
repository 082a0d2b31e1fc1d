//! Benchmark mode: an N×N grid of instances of the file's mesh seen along a fixed camera path,
//! drawn three ways in the same run: the DAG (GPU instance culling, per-cluster LOD selection,
//! mesh shaders or the fallback), every instance at full resolution, and a discrete LOD chain
//! (meshopt levels, one per instance by the same screen-space error rule). GPU timestamps per
//! pass, clusters and triangles drawn, and wall-clock frame times.

use std::time::Instant;

use anyhow::Result;
use serde_json::{json, Value};

use crate::camera::{proj_y, Camera, DEFAULT_FOV_Y};
use crate::gpu_types::{FLAG_FRUSTUM_CULL, FLAG_FULL_DETAIL};
use crate::lod_chain::LodChain;
use crate::scene::SceneData;
use crate::vk::{ChainRenderer, Renderer};

/// Benchmark settings.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Instances per grid side (1..=100).
    pub grid: u32,
    /// Measured frames per method (after 3 warm-up frames).
    pub frames: u32,
    /// Frames of the full-resolution method when it draws over 10⁹ triangles per frame.
    pub full_frames_when_huge: u32,
    /// Viewport size in pixels.
    pub width: u32,
    /// Viewport height in pixels.
    pub height: u32,
    /// Threshold in pixels.
    pub tau: f32,
}

/// Instance translations: an N×N grid in the xz plane, spaced 2.5 model radii apart.
pub fn grid_instances(scene: &SceneData, n: u32) -> Vec<[f32; 3]> {
    let spacing = scene.bounds.radius * 2.5;
    let half = (n as f32 - 1.0) * 0.5;
    (0..n * n).map(|i| [((i % n) as f32 - half) * spacing, 0.0, ((i / n) as f32 - half) * spacing]).collect()
}

/// Camera of frame `i` of `frames`: a quarter circle at 40% of the grid's half-extent, low
/// over the instances (the nearest a few radii away), looking across the grid's centre, so
/// that each frame sees instances from close by to the far edge.
pub fn path_camera(scene: &SceneData, n: u32, i: u32, frames: u32, width: u32, height: u32) -> Camera {
    let r = scene.bounds.radius;
    let half_extent = (n as f32 * 2.5 * r * 0.5).max(3.0 * r);
    let a = std::f32::consts::FRAC_PI_2 * i as f32 / frames.max(1) as f32;
    let c = scene.bounds.center;
    let orbit = half_extent * 0.4 + 2.0 * r;
    let eye = [c[0] + orbit * a.cos(), c[1] + 1.5 * r, c[2] + orbit * a.sin()];
    let target = [c[0] - orbit * 0.3 * a.cos(), c[1], c[2] - orbit * 0.3 * a.sin()];
    Camera { eye, target, proj_y: proj_y(DEFAULT_FOV_Y), z_near: r * 1e-2, width, height }
}

#[derive(Default)]
struct Stats {
    values: Vec<f64>,
}

impl Stats {
    fn push(&mut self, v: f64) {
        self.values.push(v);
    }
    fn json(&self) -> Value {
        if self.values.is_empty() {
            return Value::Null;
        }
        let mut v = self.values.clone();
        v.sort_by(f64::total_cmp);
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        json!({"mean": round(mean), "median": round(at(0.5)), "p95": round(at(0.95)), "min": round(v[0]), "max": round(v[v.len() - 1])})
    }
    fn mean(&self) -> f64 {
        self.values.iter().sum::<f64>() / self.values.len().max(1) as f64
    }
}

fn round(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Runs the three methods and returns the report.
pub fn run_bench(
    dag: &mut Renderer,
    chain_renderer: &mut ChainRenderer,
    chain: &LodChain,
    scene: &SceneData,
    options: &BenchOptions,
) -> Result<Value> {
    let n = options.grid;
    let instances = (n * n) as u64;
    let (w, h) = (options.width, options.height);
    let camera = |i: u32| path_camera(scene, n, i, options.frames, w, h);
    let clusters = scene.clusters.len() as u32;

    // DAG.
    let (mut select, mut expand, mut raster, mut total, mut wall, mut drawn_clusters, mut tris, mut dropped) = (
        Stats::default(),
        Stats::default(),
        Stats::default(),
        Stats::default(),
        Stats::default(),
        Stats::default(),
        Stats::default(),
        0u64,
    );
    for i in 0..options.frames + 3 {
        let view = camera(i.saturating_sub(3)).gpu_view(options.tau, &scene.grid, clusters, FLAG_FRUSTUM_CULL);
        let started = Instant::now();
        let frame = dag.render_without_readback(&view, w, h)?;
        let elapsed = started.elapsed().as_secs_f64() * 1e3;
        if i < 3 {
            continue;
        }
        wall.push(elapsed);
        drawn_clusters.push(frame.clusters as f64);
        tris.push(frame.triangles as f64);
        dropped += frame.dropped as u64;
        if let Some(t) = frame.times {
            select.push(t.select_ms);
            expand.push(t.expand_ms);
            raster.push(t.draw_ms);
            total.push(t.select_ms + t.expand_ms + t.draw_ms);
        }
    }
    let dag_json = json!({
        "path": dag.path_name(),
        "gpu_ms": {"selection": select.json(), "expand": expand.json(), "raster": raster.json(), "total": total.json()},
        "frame_wall_ms": wall.json(),
        "clusters_drawn": drawn_clusters.json(),
        "triangles_drawn": tris.json(),
        "dropped_clusters": dropped,
    });
    println!(
        "bench dag: GPU selection {:.3} ms, expand {:.3} ms, raster {:.3} ms (total {:.3} ms); {:.0} clusters, {:.0} triangles drawn; frame wall {:.2} ms{}",
        select.mean(), expand.mean(), raster.mean(), total.mean(), drawn_clusters.mean(), tris.mean(), wall.mean(),
        if dropped > 0 { format!("; {dropped} clusters dropped (visible list full)") } else { String::new() }
    );

    // Full resolution and the LOD chain.
    let mut alternative = |flags: u32, frames: u32, name: &str| -> Result<Value> {
        let (mut cull, mut raster, mut total, mut wall, mut tris) =
            (Stats::default(), Stats::default(), Stats::default(), Stats::default(), Stats::default());
        let mut per_level = vec![0u64; chain.levels.len()];
        for i in 0..frames + 1 {
            let view = camera(i.saturating_sub(1) * options.frames / frames.max(1)).gpu_view(
                options.tau,
                &scene.grid,
                clusters,
                FLAG_FRUSTUM_CULL | flags,
            );
            let started = Instant::now();
            let frame = chain_renderer.render(&view, w, h)?;
            let elapsed = started.elapsed().as_secs_f64() * 1e3;
            if i < 1 {
                continue;
            }
            wall.push(elapsed);
            tris.push(frame.triangles as f64);
            for (l, &k) in frame.instances_per_level.iter().enumerate() {
                per_level[l] += k as u64;
            }
            if let Some((c, r)) = frame.times {
                cull.push(c);
                raster.push(r);
                total.push(c + r);
            }
        }
        println!(
            "bench {name}: GPU culling {:.3} ms, raster {:.3} ms (total {:.3} ms); {:.0} triangles drawn; frame wall {:.2} ms ({frames} frames)",
            cull.mean(), raster.mean(), total.mean(), tris.mean(), wall.mean()
        );
        Ok(json!({
            "frames": frames,
            "gpu_ms": {"culling": cull.json(), "raster": raster.json(), "total": total.json()},
            "frame_wall_ms": wall.json(),
            "triangles_drawn": tris.json(),
            "instances_per_level_mean": per_level.iter().map(|&k| k as f64 / frames.max(1) as f64).collect::<Vec<_>>(),
        }))
    };
    let huge = instances * scene.level0_triangles > 1_000_000_000;
    let full_frames = if huge { options.full_frames_when_huge.min(options.frames) } else { options.frames };
    let full_json = alternative(FLAG_FULL_DETAIL, full_frames, "full resolution")?;
    let chain_json = alternative(0, options.frames, "LOD chain")?;
    Ok(json!({
        "grid": n,
        "instances": instances,
        "source_triangles_per_instance": scene.level0_triangles,
        "source_triangles": instances * scene.level0_triangles,
        "size": [w, h],
        "tau_px": options.tau,
        "frames": options.frames,
        "camera_path": "quarter circle at 40% of the grid half-extent + 2 radii, 1.5 radii above the centre, looking across the grid; 60° vertical fov",
        "dag": dag_json,
        "full_resolution": full_json,
        "lod_chain": chain_json,
        "lod_chain_levels": chain.levels.iter().map(|l| json!({"triangles": l.index_count / 3, "error": l.error})).collect::<Vec<_>>(),
    }))
}

/// The DAG frames of a scene file's instances along the benchmark's camera path around the
/// scene's world bounds: GPU pass times, clusters and triangles per frame (the discrete-LOD
/// alternatives need one mesh, so they are not run).
pub fn run_scene_bench(
    dag: &mut Renderer,
    scene: &crate::instances::LoadedScene,
    frames: u32,
    width: u32,
    height: u32,
    tau: f32,
) -> Result<Value> {
    let r = scene.bounds.radius;
    let c = scene.bounds.center;
    let (mut total, mut wall, mut clusters, mut tris) =
        (Stats::default(), Stats::default(), Stats::default(), Stats::default());
    let mut dropped = 0u64;
    for i in 0..frames + 3 {
        // A quarter circle at 1.5 to 3 radii, looking at the centre.
        let a = std::f32::consts::FRAC_PI_2 * i.saturating_sub(3) as f32 / frames.max(1) as f32;
        let orbit = r * (1.5 + 1.5 * a / std::f32::consts::FRAC_PI_2);
        let eye = [c[0] + orbit * a.cos(), c[1] + 0.5 * r, c[2] + orbit * a.sin()];
        let camera = Camera { eye, target: c, proj_y: proj_y(DEFAULT_FOV_Y), z_near: r * 1e-3, width, height };
        let view = camera.gpu_view(tau, &scene.data.grid, scene.data.clusters.len() as u32, FLAG_FRUSTUM_CULL);
        let started = Instant::now();
        let frame = dag.render_without_readback(&view, width, height)?;
        let elapsed = started.elapsed().as_secs_f64() * 1e3;
        if i < 3 {
            continue;
        }
        wall.push(elapsed);
        clusters.push(frame.clusters as f64);
        tris.push(frame.triangles as f64);
        dropped += frame.dropped as u64;
        if let Some(t) = frame.times {
            total.push(t.select_ms + t.expand_ms + t.draw_ms);
        }
    }
    Ok(json!({
        "path": dag.path_name(),
        "instances": scene.instances.len(),
        "meshes": scene.files.len(),
        "frames": frames,
        "gpu_ms_total": total.json(),
        "wall_ms": wall.json(),
        "clusters": clusters.json(),
        "triangles": tris.json(),
        "dropped_clusters": dropped,
    }))
}
