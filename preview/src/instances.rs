//! Instances: a mesh of a [`SceneData`] placed by a transform, as the GPU's [`GpuInstance`],
//! with the CPU twin of the shaders' selection under a transform, and the loading of a scene
//! file (docs/FORMAT.md "Scene file") into merged GPU inputs plus instances.
//!
//! The rule (docs/FORMAT.md "Scene file" says why it is conservative and keeps cuts
//! consistent): the eye moves into the mesh's object space by the inverse transform, FORMAT.md
//! §6 runs there on the file's own spheres and errors with `z_near / s_min`, and the result is
//! multiplied by `s_max / s_min`, the extreme singular values of the upper 3×3. A pure
//! translation stores exact factors of 1 and an inverse of `-t`, so its arithmetic is exactly
//! `eye - t` (what the grid of copies used before transforms).

use std::path::Path;

use anyhow::{bail, Context as _, Result};
use mres_format::select::{projected_error, ViewParams};
use mres_format::{MresFile, Sphere};
use mres_import::SceneFile;

use crate::gpu_types::GpuInstance;
use crate::scene::SceneData;

/// Relative padding of the singular values (and so of the factors): covers the f64 eigen
/// solve and the f32 roundings of the factors, so that they never understate.
const SCALE_PAD: f64 = 1e-6;

/// Mesh `mesh` of `scene` moved by `t`: identity rotation, exact inverse, factors 1.
pub fn translated(scene: &SceneData, mesh: usize, t: [f32; 3]) -> GpuInstance {
    let mut model = IDENTITY;
    model[3] = [t[0], t[1], t[2], 1.0];
    let mut inst = base(scene, mesh, model);
    inst.inverse_row0 = [1.0, 0.0, 0.0, -t[0]];
    inst.inverse_row1 = [0.0, 1.0, 0.0, -t[1]];
    inst.inverse_row2 = [0.0, 0.0, 1.0, -t[2]];
    (inst.error_scale, inst.near_scale, inst.radius_scale) = (1.0, 1.0, 1.0);
    inst
}

/// Mesh `mesh` of `scene` placed by `transform` (16 floats, column-major, affine). A transform
/// whose upper 3×3 is exactly the identity is a [`translated`] instance.
pub fn placed(scene: &SceneData, mesh: usize, transform: &[f32; 16]) -> Result<GpuInstance> {
    let column = |c: usize| [transform[c * 4], transform[c * 4 + 1], transform[c * 4 + 2]];
    let a = [column(0), column(1), column(2)];
    let t = column(3);
    if a == [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
        return Ok(translated(scene, mesh, t));
    }
    let a64 = a.map(|c| c.map(f64::from));
    let (inverse, determinant) = invert(&a64).context("the transform is singular (its 3x3 part has no inverse)")?;
    let (s_min, s_max) = singular_range(&a64);
    if !(s_min > 0.0 && s_max.is_finite()) {
        bail!("the transform is singular (scale factors {s_min} .. {s_max})");
    }
    let (s_min, s_max) = (s_min * (1.0 - SCALE_PAD), s_max * (1.0 + SCALE_PAD));
    let mut model = IDENTITY;
    for (c, col) in model.iter_mut().enumerate() {
        col.copy_from_slice(&transform[c * 4..c * 4 + 4]);
    }
    let mut inst = base(scene, mesh, model);
    // Rows of the inverse: object = A⁻¹ (world - t) = A⁻¹ world - A⁻¹ t.
    let rows: [[f32; 4]; 3] = std::array::from_fn(|r| {
        let row = inverse[r];
        let offset = -(row[0] * t[0] as f64 + row[1] * t[1] as f64 + row[2] * t[2] as f64);
        [row[0] as f32, row[1] as f32, row[2] as f32, offset as f32]
    });
    (inst.inverse_row0, inst.inverse_row1, inst.inverse_row2) = (rows[0], rows[1], rows[2]);
    inst.error_scale = (s_max / s_min * (1.0 + SCALE_PAD)) as f32;
    inst.near_scale = (1.0 / s_min * (1.0 + SCALE_PAD)) as f32;
    inst.radius_scale = (s_max * (1.0 + SCALE_PAD)) as f32;
    inst.mirrored = u32::from(determinant < 0.0);
    Ok(inst)
}

const IDENTITY: [[f32; 4]; 4] =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// The instance fields that come from the mesh.
fn base(scene: &SceneData, mesh: usize, model: [[f32; 4]; 4]) -> GpuInstance {
    let part = &scene.parts[mesh];
    let g = &part.grid;
    GpuInstance {
        model,
        grid: [g.origin[0], g.origin[1], g.origin[2], g.step],
        center: [part.bounds.center[0], part.bounds.center[1], part.bounds.center[2], part.model_far],
        model_near: part.model_near,
        bin_first: part.bin_first,
        bin_count: part.bin_count,
        mesh: mesh as u32,
        ..GpuInstance::default()
    }
}

/// The inverse of a 3×3 matrix given as columns, as rows (`inverse[row][col]`), and its
/// determinant; `None` if singular or not finite.
fn invert(a: &[[f64; 3]; 3]) -> Option<([[f64; 3]; 3], f64)> {
    let cross =
        |u: [f64; 3], v: [f64; 3]| [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    let (c0, c1, c2) = (a[0], a[1], a[2]);
    // For M = [c0 c1 c2], the rows of M⁻¹ are (c1×c2, c2×c0, c0×c1) / det.
    let rows = [cross(c1, c2), cross(c2, c0), cross(c0, c1)];
    let determinant = c0[0] * rows[0][0] + c0[1] * rows[0][1] + c0[2] * rows[0][2];
    if determinant == 0.0 || !determinant.is_finite() {
        return None;
    }
    Some((rows.map(|r| r.map(|x| x / determinant)), determinant))
}

/// (smallest, largest) singular value of the 3×3 matrix with columns `a`: square roots of the
/// eigenvalues of AᵀA, by cyclic Jacobi rotations (a few sweeps converge to f64 precision for
/// a symmetric 3×3; hand-written because no dependency of the preview offers it).
fn singular_range(a: &[[f64; 3]; 3]) -> (f64, f64) {
    let mut m = [[0.0f64; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, value) in row.iter_mut().enumerate() {
            *value = (0..3).map(|k| a[i][k] * a[j][k]).sum();
        }
    }
    for _ in 0..32 {
        let off = m[0][1].abs() + m[0][2].abs() + m[1][2].abs();
        if off <= 1e-300 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if m[p][q] == 0.0 {
                continue;
            }
            let theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let (c, s) = (1.0 / (t * t + 1.0).sqrt(), t / (t * t + 1.0).sqrt());
            // m = Jᵀ m J for the rotation J in the (p, q) plane: columns, then rows.
            for row in m.iter_mut() {
                let (mkp, mkq) = (row[p], row[q]);
                row[p] = c * mkp - s * mkq;
                row[q] = s * mkp + c * mkq;
            }
            let (row_p, row_q) = (m[p], m[q]);
            for k in 0..3 {
                m[p][k] = c * row_p[k] - s * row_q[k];
                m[q][k] = s * row_p[k] + c * row_q[k];
            }
        }
    }
    let eigen = [m[0][0], m[1][1], m[2][2]].map(|x| x.max(0.0).sqrt());
    (eigen.iter().copied().fold(f64::INFINITY, f64::min), eigen.iter().copied().fold(0.0, f64::max))
}

/// The view's eye in the instance's object space, with the shaders' operation order.
pub fn eye_in_object(inst: &GpuInstance, eye: [f32; 3]) -> [f32; 3] {
    let rows = [inst.inverse_row0, inst.inverse_row1, inst.inverse_row2];
    rows.map(|r| ((r[0] * eye[0] + r[1] * eye[1]) + r[2] * eye[2]) + r[3])
}

/// The CPU twin of the selection shader's projected error of (`sphere`, `error`) under `inst`.
pub fn instance_projected(inst: &GpuInstance, view: &ViewParams, sphere: &Sphere, error: f32) -> f32 {
    let local = ViewParams { eye: eye_in_object(inst, view.eye), z_near: view.z_near * inst.near_scale, ..*view };
    projected_error(&local, sphere, error) * inst.error_scale
}

/// A world-space sphere holding `sphere` (object space) under `inst`.
pub fn world_sphere(inst: &GpuInstance, sphere: &Sphere) -> Sphere {
    let m = &inst.model;
    let c = sphere.center;
    let center = std::array::from_fn(|r| ((m[0][r] * c[0] + m[1][r] * c[1]) + m[2][r] * c[2]) + m[3][r]);
    Sphere { center, radius: sphere.radius * inst.radius_scale }
}

/// A scene file loaded for the GPU: every mesh file merged into one [`SceneData`], the
/// instances, and the files (for their figures).
pub struct LoadedScene {
    /// The merged GPU inputs, one part per mesh of the scene file.
    pub data: SceneData,
    /// One per instance of the scene file.
    pub instances: Vec<GpuInstance>,
    /// The mesh files, in scene order.
    pub files: Vec<MresFile>,
    /// A world-space sphere around every instance's mesh bounds.
    pub bounds: Sphere,
}

/// Reads the scene file at `path` and every `.mres` it lists; errors name the file at fault.
pub fn load_scene(path: &Path) -> Result<LoadedScene> {
    let scene = SceneFile::read(path)?;
    if scene.instances.is_empty() {
        bail!("{}: the scene has no instances", path.display());
    }
    let mut files = Vec::with_capacity(scene.meshes.len());
    let mut parts = Vec::with_capacity(scene.meshes.len());
    for i in 0..scene.meshes.len() {
        let mesh_path = scene.mesh_path(path, i);
        let file = MresFile::open(&mesh_path)
            .with_context(|| format!("{}: mesh {i}: cannot read {}", path.display(), mesh_path.display()))?;
        parts.push(SceneData::from_file(&file).with_context(|| format!("{}", mesh_path.display()))?);
        files.push(file);
    }
    let data = SceneData::merge(parts)?;
    let mut instances = Vec::with_capacity(scene.instances.len());
    for (j, instance) in scene.instances.iter().enumerate() {
        let placed = placed(&data, instance.mesh, &instance.transform)
            .with_context(|| format!("{}: instance {j} ({})", path.display(), instance.name))?;
        instances.push(placed);
    }
    let spheres: Vec<Sphere> =
        instances.iter().map(|inst| world_sphere(inst, &data.parts[inst.mesh as usize].bounds)).collect();
    let bounds = crate::scene::enclosing_sphere(&spheres);
    Ok(LoadedScene { data, instances, files, bounds })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu_types::GpuLevelBin;
    use crate::scene::MeshPart;
    use mres_format::Grid;

    fn scene() -> SceneData {
        let part = MeshPart {
            cluster_first: 0,
            cluster_count: 0,
            bin_first: 0,
            bin_count: 1,
            grid: Grid { origin: [0.0; 3], step: 1.0 },
            bounds: Sphere { center: [0.5, 0.5, 0.5], radius: 1.0 },
            model_far: 1.0,
            model_near: 2.0,
        };
        SceneData {
            clusters: Vec::new(),
            page_bases: Vec::new(),
            pages: Vec::new(),
            index_capacity: 0,
            grid: part.grid,
            root_bounds: part.bounds,
            bounds: part.bounds,
            level0_triangles: 0,
            level_order: Vec::new(),
            bins: vec![GpuLevelBin::default()],
            model_far: 1.0,
            model_near: 2.0,
            parts: vec![part],
        }
    }

    fn view(eye: [f32; 3]) -> ViewParams {
        ViewParams { eye, proj_y: 1.7, viewport_height: 1080.0, z_near: 0.01 }
    }

    /// Tiny deterministic generator (no test depends on a crate's random streams).
    fn numbers(seed: u64) -> impl FnMut() -> f32 {
        let mut x = seed;
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        }
    }

    #[test]
    fn a_translation_has_exactly_the_arithmetic_of_eye_minus_t() {
        let s = scene();
        let mut r = numbers(7);
        for _ in 0..1000 {
            let t = [r() * 100.0, r() * 100.0, r() * 100.0];
            let eye = [r() * 300.0, r() * 300.0, r() * 300.0];
            let mut transform = [0.0f32; 16];
            transform[..12].copy_from_slice(&[1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.]);
            transform[12..].copy_from_slice(&[t[0], t[1], t[2], 1.0]);
            let inst = placed(&s, 0, &transform).unwrap();
            assert_eq!(inst, translated(&s, 0, t));
            let sphere = Sphere { center: [r(), r(), r()], radius: r().abs() };
            let shifted = ViewParams { eye: [eye[0] - t[0], eye[1] - t[1], eye[2] - t[2]], ..view(eye) };
            let expected = projected_error(&shifted, &sphere, 0.3);
            assert_eq!(instance_projected(&inst, &view(eye), &sphere, 0.3).to_bits(), expected.to_bits());
        }
    }

    /// The world-space projected error of a sphere under `m`, estimated from below by sampling
    /// points of the transformed sphere (the true value is at the nearest point).
    fn world_projected(m: &[f32; 16], sphere: &Sphere, error_world_max: f32, v: &ViewParams) -> f32 {
        let mut nearest = f32::INFINITY;
        let mut r = numbers(99);
        for _ in 0..4000 {
            let d = [r(), r(), r()];
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-6);
            let p: [f32; 3] = std::array::from_fn(|k| sphere.center[k] + d[k] / n * sphere.radius);
            let w: [f32; 3] = std::array::from_fn(|k| m[k] * p[0] + m[4 + k] * p[1] + m[8 + k] * p[2] + m[12 + k]);
            let dist = ((w[0] - v.eye[0]).powi(2) + (w[1] - v.eye[1]).powi(2) + (w[2] - v.eye[2]).powi(2)).sqrt();
            nearest = nearest.min(dist);
        }
        error_world_max / nearest.max(v.z_near) * (v.viewport_height * 0.5) * v.proj_y
    }

    #[test]
    fn rotation_and_non_uniform_scale_never_understate_the_world_error() {
        let s = scene();
        let mut r = numbers(3);
        for _ in 0..50 {
            // Columns: a random rotation-ish basis scaled non-uniformly, plus a translation.
            let scale = [0.2 + 3.0 * r().abs(), 0.2 + 3.0 * r().abs(), 0.2 + 3.0 * r().abs()];
            let angle = r() * 3.0;
            let (c, sn) = (angle.cos(), angle.sin());
            let cols = [[c * scale[0], sn * scale[0], 0.0], [-sn * scale[1], c * scale[1], 0.0], [0.0, 0.0, scale[2]]];
            let mut m = [0.0f32; 16];
            for k in 0..3 {
                m[k * 4..k * 4 + 3].copy_from_slice(&cols[k]);
            }
            m[12..].copy_from_slice(&[r() * 10.0, r() * 10.0, r() * 10.0, 1.0]);
            let inst = placed(&s, 0, &m).unwrap();
            let smax = scale.iter().copied().fold(0.0f32, f32::max);
            let sphere = Sphere { center: [r(), r(), r()], radius: 0.5 };
            let v = view([r() * 40.0 + 20.0, r() * 40.0, r() * 40.0]);
            let ours = instance_projected(&inst, &v, &sphere, 0.1);
            let truth = world_projected(&m, &sphere, 0.1 * smax, &v);
            assert!(ours >= truth * 0.999, "{ours} < {truth} for scale {scale:?}");
            // A world sphere around the transformed one.
            let w = world_sphere(&inst, &sphere);
            assert!(w.radius >= 0.5 * smax * 0.9999);
        }
    }

    #[test]
    fn mirror_flag_and_singular_transforms() {
        let s = scene();
        let mut m = [0.0f32; 16];
        m[0] = -1.0;
        m[5] = 1.0;
        m[10] = 1.0;
        m[15] = 1.0;
        let inst = placed(&s, 0, &m).unwrap();
        assert_eq!(inst.mirrored, 1);
        assert!((inst.error_scale - 1.0).abs() < 1e-5);
        m[0] = 0.0;
        let message = format!("{:#}", placed(&s, 0, &m).unwrap_err());
        assert!(message.contains("singular"), "{message}");
    }

    #[test]
    fn a_truncated_scene_file_is_an_error_naming_it() {
        let dir = std::env::temp_dir().join(format!("preview-scene-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("x.scene.json");
        std::fs::write(&path, "{\"version\": 1, \"meshes\": [{\"file\": \"x.mres\", \"mat").unwrap();
        let message = format!("{:#}", load_scene(&path).err().unwrap());
        assert!(message.contains(&path.display().to_string()) && message.contains("invalid scene file"), "{message}");
        std::fs::write(&path, "{\"version\": 1, \"meshes\": [{\"file\": \"x.mres\", \"materials\": []}], \"instances\": [{\"name\": \"a\", \"mesh\": 0, \"transform\": [1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}]}").unwrap();
        let message = format!("{:#}", load_scene(&path).err().unwrap());
        assert!(message.contains("x.mres"), "a missing mesh file is named: {message}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
