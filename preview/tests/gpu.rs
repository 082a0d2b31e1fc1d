//! GPU tests on a small closed model written with the reference writer. Each skips (with a
//! printed note) where no Vulkan device exists; where `VK_LAYER_KHRONOS_validation` is
//! installed, it is on and any message fails the test.

use std::sync::Arc;

use mres_format::{write_mres, Dag, DagCluster, Grid, Group, Header, MresFile, Sphere, UvQuant, NO_GROUP};
use preview::camera::Camera;
use preview::gpu_types::{FLAG_DROP_SOME, FLAG_FRUSTUM_CULL, MODE_CLUSTER, MODE_LEVEL, MODE_SHADED};
use preview::image::{count_flagged, count_model};
use preview::scene::SceneData;
use preview::verify::{verify, VerifyOptions};
use preview::vk::{validation_available, ContextOptions, Device, DrawPath, MessageCounts, Renderer, RendererOptions};

/// A closed cube: six n×n-quad faces (one level-0 cluster each) in one group with error 0.05,
/// simplified into one 12-triangle root cluster. Faces share their edge vertices' grid
/// coordinates, so both cuts are watertight.
fn cube_dag(n: i32) -> Dag {
    box_dag(n, false)
}

/// [`cube_dag`], or with `open` the same box without its top (+y) face at either level: an open
/// box whose inside (back faces) shows through the top.
fn box_dag(n: i32, open: bool) -> Dag {
    let mut clusters = Vec::new();
    for axis in 0..3 {
        for positive in [false, true] {
            if open && axis == 1 && positive {
                continue;
            }
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut positions = Vec::new();
            for j in 0..=n {
                for i in 0..=n {
                    let mut q = [0; 3];
                    q[axis] = if positive { n } else { 0 };
                    q[u] = i;
                    q[v] = j;
                    positions.push(q);
                }
            }
            let at = |i: i32, j: i32| (j * (n + 1) + i) as u8;
            let mut indices = Vec::new();
            for j in 0..n {
                for i in 0..n {
                    // Counter-clockwise seen from outside (+axis for the positive face).
                    let quad = [[at(i, j), at(i + 1, j), at(i + 1, j + 1)], [at(i, j), at(i + 1, j + 1), at(i, j + 1)]];
                    for t in quad {
                        indices.extend(if positive { t } else { [t[0], t[2], t[1]] });
                    }
                }
            }
            clusters.push(DagCluster {
                group: 0,
                own_group: NO_GROUP,
                positions,
                normals: vec![],
                uvs: vec![],
                indices,
                materials: vec![],
                open_edges: vec![],
            });
        }
    }
    let corners: Vec<[i32; 3]> = (0..8).map(|c| [(c & 1) * n, ((c >> 1) & 1) * n, ((c >> 2) & 1) * n]).collect();
    // The 12 triangles of the cube over `corners`, counter-clockwise from outside.
    let faces = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
    // [2, 6, 7, 3] is the top: corners with y = 1.
    let indices =
        faces.iter().filter(|f| !open || f[0] != 2).flat_map(|f| [f[0], f[1], f[2], f[0], f[2], f[3]]).collect();
    clusters.push(DagCluster {
        group: 1,
        own_group: 0,
        positions: corners,
        normals: vec![],
        uvs: vec![],
        indices,
        materials: vec![],
        open_edges: vec![],
    });
    let step = 2.0 / n as f32;
    let sphere = |r: f32| Sphere { center: [0.0; 3], radius: r };
    Dag {
        header: Header {
            flags: 0,
            grid: Grid { origin: [-1.0; 3], step },
            uv: UvQuant { min: [0.0; 2], extent: [0.0; 2] },
            normal_bits: 0,
            position_bits: 16,
            level_count: 0,
            source_triangles: if open { 10 } else { 12 } * (n * n) as u64,
        },
        groups: vec![
            Group { sphere: sphere(1.75), error: 0.05, level: 0, first_cluster: 0, cluster_count: 0, page: 0 },
            Group { sphere: sphere(1.76), error: f32::INFINITY, level: 1, first_cluster: 0, cluster_count: 0, page: 0 },
        ],
        clusters,
    }
}

fn cube_file() -> MresFile {
    MresFile::parse(write_mres(&cube_dag(6), 3).expect("write")).expect("parse")
}

/// Whether a Vulkan device and the validation layer are required (CI sets
/// `MRES_PREVIEW_REQUIRE_GPU=1`, so that a missing driver fails instead of skipping).
fn gpu_required() -> bool {
    std::env::var("MRES_PREVIEW_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

/// A device with validation where the layer exists, or None (and a note) without Vulkan.
fn device(test: &str) -> Option<(Arc<Device>, Arc<MessageCounts>)> {
    let validation = validation_available();
    assert!(
        validation || !gpu_required(),
        "MRES_PREVIEW_REQUIRE_GPU=1 but VK_LAYER_KHRONOS_validation is not installed"
    );
    match Device::new(&ContextOptions { validation, allow_mesh_shaders: true, ..Default::default() }) {
        Ok(d) => {
            assert!(
                d.info.mesh_shader_enabled || std::env::var("MRES_PREVIEW_REQUIRE_MESH").as_deref() != Ok("1"),
                "MRES_PREVIEW_REQUIRE_MESH=1 but {} has no VK_EXT_mesh_shader",
                d.info.name
            );
            println!(
                "{test}: on {} ({}; validation {}; mesh shaders {})",
                d.info.name,
                d.info.driver,
                if validation { "on" } else { "not installed" },
                if d.info.mesh_shader_enabled { "on" } else { "not available" }
            );
            let counts = d.counts.clone();
            Some((d, counts))
        }
        Err(e) if gpu_required() => panic!("{test}: MRES_PREVIEW_REQUIRE_GPU=1 but no Vulkan device: {e:#}"),
        Err(e) => {
            println!("{test}: SKIPPED, no Vulkan device: {e:#}");
            None
        }
    }
}

fn assert_silent(counts: &MessageCounts) {
    assert_eq!((counts.errors(), counts.warnings()), (0, 0), "validation messages: {:#?}", counts.first_messages());
}

#[test]
fn gpu_selection_equals_cpu_and_the_closed_cube_shows_no_back_face() {
    let Some((device, counts)) = device("verify") else { return };
    let file = cube_file();
    let scene = SceneData::from_file(&file).unwrap();
    let mut renderer = Renderer::new(&device, &scene, RendererOptions::default()).unwrap();
    let options =
        VerifyOptions { selection_cameras: 60, crack_cameras: 6, width: 128, height: 128, ..Default::default() };
    let report = verify(&mut renderer, &file, &scene, &options).unwrap();
    println!("{}", report.to_json());
    assert!(report.passed(), "{:#?}", report.to_json());
    assert_eq!(report.selection_runs, 240);
    // Both cuts occur: the root cube (1 cluster) and the six faces.
    assert_eq!((report.min_selected, report.max_selected), (1, 6));
    assert!(report.min_model_pixels > 100);
    drop(renderer);
    drop(device);
    assert_silent(&counts);
}

#[test]
fn verify_fails_on_holes_but_not_on_folds() {
    // Holes (every fifth selected cluster dropped) show back faces far behind the surface:
    // verify must count them as hole pixels and fail.
    let Some((device, counts)) = device("verify holes") else { return };
    let file = cube_file();
    let scene = SceneData::from_file(&file).unwrap();
    let mut renderer = Renderer::new(&device, &scene, RendererOptions::default()).unwrap();
    let options = VerifyOptions {
        selection_cameras: 4,
        crack_cameras: 6,
        crack_taus: vec![0.0],
        width: 128,
        height: 128,
        crack_flags: FLAG_DROP_SOME,
        ..Default::default()
    };
    let report = verify(&mut renderer, &file, &scene, &options).unwrap();
    assert!(report.max_hole_pixels > 100, "{:#?}", report.to_json());
    assert!(!report.passed());
    drop(renderer);
    drop(device);
    assert_silent(&counts);
}

#[test]
fn open_box_passes_with_its_inside_seen_and_fails_with_clusters_dropped() {
    // Seen through the open top, the inside of the box is the full-detail surface itself seen
    // from behind: flagged, no hole. With every fifth cluster dropped, the inside shows through
    // a missing wall as well, behind the wall's front face: holes, as on the closed cube.
    let Some((device, counts)) = device("open box") else { return };
    let file = MresFile::parse(write_mres(&box_dag(6, true), 3).expect("write")).expect("parse");
    let scene = SceneData::from_file(&file).unwrap();
    let mut renderer = Renderer::new(&device, &scene, RendererOptions::default()).unwrap();
    let options = VerifyOptions {
        selection_cameras: 4,
        crack_cameras: 12,
        crack_taus: vec![0.0],
        width: 128,
        height: 128,
        ..Default::default()
    };
    let report = verify(&mut renderer, &file, &scene, &options).unwrap();
    println!("{}", report.to_json());
    assert!(report.passed(), "{:#?}", report.to_json());
    assert!(report.max_flagged_pixels > 100, "the inside was never seen: {:#?}", report.to_json());
    let dropped =
        verify(&mut renderer, &file, &scene, &VerifyOptions { crack_flags: FLAG_DROP_SOME, ..options }).unwrap();
    println!("{}", dropped.to_json());
    assert!(dropped.max_hole_pixels > 100, "{:#?}", dropped.to_json());
    assert!(!dropped.passed());
    drop(renderer);
    drop(device);
    assert_silent(&counts);
}

#[test]
fn crack_test_sees_a_hole() {
    let Some((device, counts)) = device("holes") else { return };
    let file = cube_file();
    let scene = SceneData::from_file(&file).unwrap();
    let mut renderer = Renderer::new(&device, &scene, RendererOptions::default()).unwrap();
    let (mut whole, mut holed) = (0, 0);
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut eye = [0.1, 0.2, 0.3];
            eye[axis] = 3.0 * sign;
            let camera = Camera::looking_at(eye, &scene.bounds, 96, 96);
            // tau 0: every projected error exceeds it, so the six level-0 faces are drawn.
            let frame = renderer.render(&camera.gpu_view(0.0, &scene.grid, 7, FLAG_FRUSTUM_CULL), 96, 96).unwrap();
            assert_eq!(frame.clusters, 6);
            whole += count_flagged(&frame.rgba);
            let frame = renderer
                .render(&camera.gpu_view(0.0, &scene.grid, 7, FLAG_FRUSTUM_CULL | FLAG_DROP_SOME), 96, 96)
                .unwrap();
            assert_eq!(frame.clusters, 5);
            holed += count_flagged(&frame.rgba);
        }
    }
    assert_eq!(whole, 0);
    // One face is missing: seen from its side, the inside (back faces) shows through.
    assert!(holed > 1000, "only {holed} flagged pixels with a face dropped");
    drop(renderer);
    drop(device);
    assert_silent(&counts);
}

#[test]
fn command_line_verify_and_screenshot() {
    if let Err(e) = Device::new(&ContextOptions::default()) {
        assert!(!gpu_required(), "MRES_PREVIEW_REQUIRE_GPU=1 but no Vulkan device: {e:#}");
        println!("cli: SKIPPED, no Vulkan device");
        return;
    }
    let dir = std::env::temp_dir().join(format!("mres-preview-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mres = dir.join("cube.mres");
    std::fs::write(&mres, write_mres(&cube_dag(6), 3).unwrap()).unwrap();
    let png = dir.join("shot.png");
    let report = dir.join("report.json");
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_preview"));
    cmd.arg(&mres).args(["--headless", "--verify", "--cameras", "20", "--crack-cameras", "3", "--size", "160x120"]);
    cmd.arg("--out").arg(&png).arg("--report").arg(&report);
    if validation_available() {
        cmd.arg("--validate");
    }
    let out = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success());
    assert!(stdout.contains("PASS"));
    let png_bytes = std::fs::read(&png).unwrap();
    assert_eq!(&png_bytes[1..4], b"PNG");
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(json["passed"], true);
    assert_eq!(json["verify"]["selection"]["runs"], 80);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The shade `draw.frag.glsl` gives a front face with unit normal `n` at `p` seen from `eye`.
fn expected_shade(n: [f32; 3], p: [f32; 3], eye: [f32; 3]) -> [f32; 3] {
    let t = [eye[0] - p[0], eye[1] - p[1], eye[2] - p[2]];
    let l = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    let lambert = ((n[0] * t[0] + n[1] * t[1] + n[2] * t[2]) / l).abs();
    [0.08 + 0.85 * lambert, 0.08 + 0.80 * lambert, 0.08 + 0.72 * lambert]
}

/// A CPU reference image of the cube `[-1, 1]^3` (the surface `cube_dag` describes): one ray per
/// pixel centre, analytic intersection, the fragment shader's shading; background elsewhere.
fn reference_cube_image(camera: &Camera) -> Vec<[f32; 3]> {
    let (w, h) = (camera.width, camera.height);
    let vm = camera.view_matrix();
    // Rows of the view matrix: side, up, -forward.
    let s = [vm[0][0], vm[1][0], vm[2][0]];
    let u = [vm[0][1], vm[1][1], vm[2][1]];
    let f = [-vm[0][2], -vm[1][2], -vm[2][2]];
    let aspect = w as f32 / h as f32;
    let bg = preview::vk::CLEAR_RGBA;
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let nx = (2.0 * (x as f32 + 0.5) / w as f32 - 1.0) * aspect / camera.proj_y;
            let ny = (1.0 - 2.0 * (y as f32 + 0.5) / h as f32) / camera.proj_y;
            let d: [f32; 3] = std::array::from_fn(|k| s[k] * nx + u[k] * ny + f[k]);
            // Slab test against the unit cube; the entry face gives the normal.
            let (mut t0, mut t1, mut axis) = (f32::NEG_INFINITY, f32::INFINITY, 0);
            #[allow(clippy::needless_range_loop)] // k is also the axis recorded
            for k in 0..3 {
                let (a, b) = ((-1.0 - camera.eye[k]) / d[k], (1.0 - camera.eye[k]) / d[k]);
                let (near, far) = (a.min(b), a.max(b));
                if near > t0 {
                    t0 = near;
                    axis = k;
                }
                t1 = t1.min(far);
            }
            if t0 <= t1 && t0 > 0.0 {
                let p: [f32; 3] = std::array::from_fn(|k| camera.eye[k] + d[k] * t0);
                let mut n = [0.0; 3];
                n[axis] = if d[axis] > 0.0 { -1.0 } else { 1.0 };
                out.push(expected_shade(n, p, camera.eye));
            } else {
                out.push([bg[0], bg[1], bg[2]]);
            }
        }
    }
    out
}

/// (pixels differing by more than `tolerance` in any channel, mean absolute difference).
fn image_difference(rgba: &[u8], reference: &[[f32; 3]], tolerance: f32) -> (usize, f32) {
    let mut bad = 0;
    let mut sum = 0.0;
    for (p, r) in rgba.chunks_exact(4).zip(reference) {
        let d = (0..3).map(|k| (p[k] as f32 / 255.0 - r[k]).abs()).fold(0.0f32, f32::max);
        sum += d;
        if d > tolerance {
            bad += 1;
        }
    }
    (bad, sum / reference.len() as f32)
}

/// Headless screenshots against a CPU reference image, with a tolerance (never golden bytes):
/// colours within 3/255 except along silhouette edges, where rasterization rules and f32
/// rounding decide pixel centres differently (at most 1% of the image); both cuts of the cube
/// (six 72-triangle faces, or the 12-triangle root) must look the same.
#[test]
fn screenshot_matches_a_cpu_reference_image() {
    let Some((device, counts)) = device("screenshot") else { return };
    let file = cube_file();
    let scene = SceneData::from_file(&file).unwrap();
    let mut renderer = Renderer::new(&device, &scene, RendererOptions::default()).unwrap();
    let (w, h) = (160, 120);
    for eye in [[2.6, 1.7, 3.1], [-3.0, -2.2, 1.2], [0.4, 4.0, -0.3]] {
        let camera = Camera::looking_at(eye, &scene.bounds, w, h);
        let reference = reference_cube_image(&camera);
        let mut frames = Vec::new();
        for tau in [0.0, 1e9] {
            let frame = renderer.render(&camera.gpu_view(tau, &scene.grid, 7, FLAG_FRUSTUM_CULL), w, h).unwrap();
            assert_eq!(frame.clusters, if tau == 0.0 { 6 } else { 1 });
            let (bad, mean) = image_difference(&frame.rgba, &reference, 3.0 / 255.0);
            println!("eye {eye:?} tau {tau}: {bad} pixels off by more than 3/255, mean difference {mean:.5}");
            assert!(bad <= (w * h / 100) as usize, "eye {eye:?} tau {tau}: {bad} pixels differ from the reference");
            assert!(mean < 0.004, "eye {eye:?} tau {tau}: mean difference {mean}");
            frames.push(frame.rgba);
        }
        let same = frames[0]
            .chunks_exact(4)
            .zip(frames[1].chunks_exact(4))
            .filter(|(a, b)| (0..3).all(|k| a[k].abs_diff(b[k]) <= 3))
            .count();
        assert!(
            same >= (w * h) as usize * 99 / 100,
            "eye {eye:?}: the two cuts differ in {} pixels",
            (w * h) as usize - same
        );
    }
    drop(renderer);
    drop(device);
    assert_silent(&counts);
}

/// Where the device has mesh shaders, the mesh path and the fallback draw the same cuts with
/// the same pixels (within 3/255 on 99.5% of them) and the same cluster and triangle counts.
#[test]
fn mesh_and_fallback_paths_agree() {
    let Some((device, counts)) = device("paths") else { return };
    if !device.info.mesh_shader_enabled {
        println!("paths: SKIPPED, {} has no VK_EXT_mesh_shader", device.info.name);
        return;
    }
    let file = cube_file();
    let scene = SceneData::from_file(&file).unwrap();
    let mut mesh =
        Renderer::new(&device, &scene, RendererOptions { path: DrawPath::Mesh, ..Default::default() }).unwrap();
    let mut fallback =
        Renderer::new(&device, &scene, RendererOptions { path: DrawPath::Fallback, ..Default::default() }).unwrap();
    assert!(mesh.mesh_path() && !fallback.mesh_path());
    let (w, h) = (128, 96);
    for eye in [[2.6, 1.7, 3.1], [-3.0, -2.2, 1.2]] {
        let camera = Camera::looking_at(eye, &scene.bounds, w, h);
        for tau in [0.0, 1e9] {
            for mode in [MODE_SHADED, MODE_CLUSTER, MODE_LEVEL] {
                let mut view = camera.gpu_view(tau, &scene.grid, 7, FLAG_FRUSTUM_CULL);
                view.mode = mode;
                let a = mesh.render(&view, w, h).unwrap();
                let b = fallback.render(&view, w, h).unwrap();
                assert_eq!((a.clusters, a.triangles), (b.clusters, b.triangles));
                let same = a
                    .rgba
                    .chunks_exact(4)
                    .zip(b.rgba.chunks_exact(4))
                    .filter(|(p, q)| (0..3).all(|k| p[k].abs_diff(q[k]) <= 3))
                    .count();
                assert!(
                    same * 1000 >= (w * h) as usize * 995,
                    "eye {eye:?} tau {tau} mode {mode}: {} pixels differ",
                    (w * h) as usize - same
                );
                assert_eq!(count_flagged(&a.rgba), 0);
            }
        }
    }
    drop((mesh, fallback));
    drop(device);
    assert_silent(&counts);
}

/// Decodes an RGBA8 PNG written by the preview.
fn read_png(path: &std::path::Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.color_type, info.bit_depth), (png::ColorType::Rgba, png::BitDepth::Eight));
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

#[test]
fn window_without_a_display_suggests_headless() {
    let dir = std::env::temp_dir().join(format!("mres-preview-nodisplay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mres = dir.join("cube.mres");
    std::fs::write(&mres, write_mres(&cube_dag(2), 3).unwrap()).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_preview"))
        .arg(&mres)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("no display") && stderr.contains("--headless"), "{stderr}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The window path under Xvfb (`xvfb-run`; CI sets `MRES_PREVIEW_REQUIRE_WINDOW=1` so that a
/// missing Xvfb fails instead of skipping): a few frames with validation on, and the last
/// presented frame, read back from the swapchain image, equals the headless render of the same
/// camera, size and mode bit for bit (same renderer; blit into the swapchain).
#[test]
fn window_under_xvfb_shows_the_headless_image() {
    let window_required = std::env::var("MRES_PREVIEW_REQUIRE_WINDOW").is_ok_and(|v| v == "1");
    let has_xvfb = std::process::Command::new("sh")
        .args(["-c", "command -v xvfb-run && command -v xauth"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_xvfb {
        assert!(!window_required, "MRES_PREVIEW_REQUIRE_WINDOW=1 but xvfb-run or xauth is not installed");
        println!("window: SKIPPED, no xvfb-run");
        return;
    }
    if let Err(e) = Device::new(&ContextOptions::default()) {
        assert!(!gpu_required() && !window_required, "no Vulkan device: {e:#}");
        println!("window: SKIPPED, no Vulkan device");
        return;
    }
    let dir = std::env::temp_dir().join(format!("mres-preview-window-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mres = dir.join("cube.mres");
    std::fs::write(&mres, write_mres(&cube_dag(6), 3).unwrap()).unwrap();
    let (window_png, headless_png) = (dir.join("window.png"), dir.join("headless.png"));
    let common = ["--size", "200x150", "--mode", "cluster", "--tau", "0.5"];
    let validate = if validation_available() { &["--validate"][..] } else { &[] };
    let out = std::process::Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 640x480x24"])
        .arg(env!("CARGO_BIN_EXE_preview"))
        .arg(&mres)
        .args(common)
        .args(validate)
        .args(["--frames", "4", "--out"])
        .arg(&window_png)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success());
    assert!(stdout.contains("window: 4 frames at 200x150"), "{stdout}");
    if !validate.is_empty() {
        assert!(stdout.contains("validation messages: 0 errors, 0 warnings"), "{stdout}");
    }
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_preview"))
        .arg(&mres)
        .args(common)
        .arg("--headless")
        .arg("--out")
        .arg(&headless_png)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (window, headless) = (read_png(&window_png), read_png(&headless_png));
    assert_eq!((window.0, window.1), (200, 150));
    assert_eq!((window.0, window.1), (headless.0, headless.1));
    let differing = window.2.chunks(4).zip(headless.2.chunks(4)).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "{differing} pixels differ between the window and the headless render");
    // The cube is in view (more than background), with no back face showing.
    assert!(count_model(&window.2) > 5000, "{} model pixels", count_model(&window.2));
    assert_eq!(count_flagged(&window.2), 0);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A scene file of two cube meshes placed by 70 instances (more than one culling workgroup):
/// translations, rotations, non-uniform scales and mirrors. Returns the scene file's path.
fn write_cube_scene(dir: &std::path::Path) -> std::path::PathBuf {
    std::fs::write(dir.join("a.mres"), write_mres(&cube_dag(6), 3).unwrap()).unwrap();
    std::fs::write(dir.join("b.mres"), write_mres(&cube_dag(2), 3).unwrap()).unwrap();
    let mut instances = Vec::new();
    for i in 0..70 {
        let (x, z) = ((i % 10) as f32 * 3.0 - 15.0, (i / 10) as f32 * 3.0 - 10.0);
        let angle = i as f32 * 0.37;
        let (c, s) = (angle.cos(), angle.sin());
        let scale = [1.0 + (i % 3) as f32 * 0.5, 1.0, 0.5 + (i % 4) as f32 * 0.25];
        let mirror = if i % 7 == 0 { -1.0 } else { 1.0 };
        let m = [
            c * scale[0] * mirror,
            0.0,
            -s * scale[0] * mirror,
            0.0,
            0.0,
            scale[1],
            0.0,
            0.0,
            s * scale[2],
            0.0,
            c * scale[2],
            0.0,
            x,
            0.0,
            z,
            1.0,
        ];
        let t: Vec<String> = m.iter().map(|v| v.to_string()).collect();
        instances.push(format!(r#"{{"name":"i{i}","mesh":{},"transform":[{}]}}"#, i % 2, t.join(",")));
    }
    let text = format!(
        r#"{{"version":1,"meshes":[{{"file":"a.mres","materials":[]}},{{"file":"b.mres","materials":[]}}],"instances":[{}]}}"#,
        instances.join(",")
    );
    let path = dir.join("cubes.scene.json");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn instanced_selection_equals_the_cpu_twin_for_every_transform() {
    let Some((device, counts)) = device("scene") else { return };
    let dir = std::env::temp_dir().join(format!("mres-preview-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = preview::instances::load_scene(&write_cube_scene(&dir)).unwrap();
    assert_eq!(scene.instances.len(), 70);
    assert!(scene.instances.iter().any(|i| i.mirrored == 1) && scene.instances.iter().any(|i| i.error_scale > 1.5));
    for path in [DrawPath::Fallback, DrawPath::Mesh] {
        if path == DrawPath::Mesh && !device.info.mesh_shader_enabled {
            continue;
        }
        let options = RendererOptions { path, instances: scene.instances.clone(), ..Default::default() };
        let mut renderer = Renderer::new(&device, &scene.data, options).unwrap();
        let options = VerifyOptions { selection_cameras: 30, width: 128, height: 128, ..Default::default() };
        let report = preview::verify::verify_scene(&mut renderer, &scene, &options).unwrap();
        assert!(report.passed(), "{path:?}: {report:?}");
        assert_eq!(report.runs, 120);
        // Every instance is drawn (at least its root) where no frustum culling applies.
        assert!(report.min_selected >= 70, "{report:?}");
    }
    assert_silent(&counts);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_truncated_scene_file_fails_naming_it() {
    let dir = std::env::temp_dir().join(format!("mres-preview-bad-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = write_cube_scene(&dir);
    let text = std::fs::read(&path).unwrap();
    std::fs::write(&path, &text[..text.len() / 2]).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_preview"))
        .arg(&path)
        .args(["--headless", "--verify"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains(&path.display().to_string()) && stderr.contains("invalid scene file"), "{stderr}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn coverage_counts_the_pixels_a_coarse_cut_keeps() {
    let Some((device, counts)) = device("coverage") else { return };
    // The cube's root is the same box, so it covers what full detail covers; a root shrunk to
    // half the size covers about a quarter.
    let mut shrunk = cube_dag(8);
    for q in &mut shrunk.clusters.last_mut().unwrap().positions {
        *q = q.map(|x| 2 + x / 2);
    }
    for (dag, lo, hi) in [(cube_dag(8), 0.98, 1.02), (shrunk, 0.1, 0.5)] {
        let file = MresFile::parse(write_mres(&dag, 3).expect("write")).expect("parse");
        let scene = SceneData::from_file(&file).unwrap();
        let mut renderer = Renderer::new(&device, &scene, RendererOptions::default()).unwrap();
        let rows = preview::coverage::coverage(&mut renderer, &scene, 6, (128, 128), 7).unwrap();
        let (full, coarsest) = (&rows[0], rows.last().unwrap());
        assert_eq!((full.tau, full.covered, full.triangles), (0.0, 1.0, 768.0));
        assert_eq!(coarsest.triangles, 12.0, "the root alone at {} px", coarsest.tau);
        assert!((lo..hi).contains(&coarsest.covered), "covered {} not in {lo}..{hi}", coarsest.covered);
    }
    drop(device);
    assert_silent(&counts);
}
