//! `preview FILE.mres`: the windowed viewer, and the headless render, verify, screenshot and
//! benchmark modes of the mres preview.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context as _, Result};
use clap::Parser;
use mres_format::MresFile;
use preview::camera::Camera;
use preview::coverage::{coverage, CoverageRow};
use preview::gpu_types::FLAG_FRUSTUM_CULL;
use preview::image::write_png;
use preview::scene::SceneData;
use preview::verify::{verify, VerifyOptions};
use preview::vk::{ContextOptions, Device, DrawPath, Renderer, RendererOptions};
use serde_json::json;

/// Render a .mres file through the GPU selection path: view it in a window, verify it, write a
/// screenshot, or benchmark it.
#[derive(Parser, Debug)]
#[command(version, after_help = WINDOW_KEYS)]
struct Args {
    /// The .mres file, or a scene file (NAME.scene.json, docs/FORMAT.md "Scene file"): every
    /// mesh it lists drawn by each of its instances (headless only).
    file: PathBuf,
    /// Render offscreen (no window): needed for --verify and --bench, and where no display is.
    /// Without it, a window opens (X11 DISPLAY or WAYLAND_DISPLAY must be set).
    #[arg(long)]
    headless: bool,
    /// Check GPU selection against the CPU reference and run the crack test; exit 1 on failure.
    #[arg(long)]
    verify: bool,
    /// Enable VK_LAYER_KHRONOS_validation (with synchronization validation); any warning or
    /// error message fails the run.
    #[arg(long)]
    validate: bool,
    /// Write a screenshot PNG. In the window: of the last frame shown (read back from the
    /// presented swapchain image) when it closes, and on P.
    #[arg(long, value_name = "PNG")]
    out: Option<PathBuf>,
    /// Selection threshold of the screenshot (initial value in the window), pixels.
    #[arg(long, default_value_t = 1.0)]
    tau: f32,
    /// Eye position of the screenshot (initial one in the window), `x,y,z` (object space); it
    /// looks at the model's centre.
    /// Default: a three-quarter view framing the root bounding sphere.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    camera: Option<String>,
    /// Image size, `WxH` (verify renders use it too). Default: 512x512 headless, 1920x1080 for
    /// --bench, 1280x720 for the window.
    #[arg(long)]
    size: Option<String>,
    /// Cameras of the selection check (each with 4 thresholds: 0.25, 1, 4, 16 px).
    #[arg(long, default_value_t = 200)]
    cameras: usize,
    /// Cameras of the crack test (each with 3 thresholds: 0.5, 2, 8 px), and of --coverage.
    #[arg(long, default_value_t = 16)]
    crack_cameras: usize,
    /// How much of the model's projected area the cuts keep: renders from --crack-cameras
    /// cameras at three times the bounding radius, at tau 0 and at 1, 4, 16, 64, 256, 1024 px,
    /// and prints per tau the mean triangles drawn and the mean of the model pixels over those
    /// of the tau 0 render (occlusion included; `mres inspect` gives uniform cuts' surface area).
    #[arg(long)]
    coverage: bool,
    /// Write the verify report (and device facts) as JSON.
    #[arg(long, value_name = "JSON")]
    report: Option<PathBuf>,
    /// Write PNGs of crack renders with flagged pixels into this directory.
    #[arg(long, value_name = "DIR")]
    failure_dir: Option<PathBuf>,
    /// Use the first Vulkan device whose name contains this.
    #[arg(long)]
    device: Option<String>,
    /// Diagnostic: select with the driver's own f32 division and sqrt (Vulkan allows them a few
    /// ulp of error) instead of the exact ones, and report how often that changes the result.
    #[arg(long)]
    naive_arithmetic: bool,
    /// Draw path: `mesh` (VK_EXT_mesh_shader: task + mesh shaders; fails without it),
    /// `fallback` (compute-expanded index buffer + indirect indexed draw), or `auto` (mesh
    /// shaders where the device has them).
    #[arg(long, value_enum, default_value_t = PathArg::Auto)]
    path: PathArg,
    /// Benchmark: an N×N grid of instances (--grid) along a fixed camera path (--frames), drawn
    /// with the DAG, at full resolution, and with a discrete LOD chain; prints GPU times per
    /// pass, clusters and triangles drawn (uses --size, default 1920x1080 here, and --tau).
    #[arg(long)]
    bench: bool,
    /// Benchmark grid side (1..=100): N×N instances.
    #[arg(long, default_value_t = 10)]
    grid: u32,
    /// Benchmark frames per method (default 60); in the window, quit after this many frames
    /// (default: run until Esc or closed), e.g. for a test under Xvfb.
    #[arg(long)]
    frames: Option<u32>,
    /// Benchmark frames of the full-resolution method when it draws over 10^9 triangles.
    #[arg(long, default_value_t = 5)]
    full_frames: u32,
    /// Write the benchmark report as JSON.
    #[arg(long, value_name = "JSON")]
    json: Option<PathBuf>,
    /// What the screenshot shows on front faces (initial mode in the window: keys 1-5).
    #[arg(long, value_enum, default_value_t = ModeArg::Shaded)]
    mode: ModeArg,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum PathArg {
    Auto,
    Mesh,
    Fallback,
}

/// Visualisation modes (back faces are always pure red).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum ModeArg {
    /// Grey headlight shading.
    Shaded,
    /// A colour per cluster.
    Cluster,
    /// A colour per group (the cluster's parent group).
    Group,
    /// DAG level, blue (0) to orange (12 and above).
    Level,
    /// The cluster's own projected error over tau, blue (0) to orange (tau).
    Error,
}

impl ModeArg {
    fn gpu(self) -> u32 {
        use preview::gpu_types::*;
        match self {
            ModeArg::Shaded => MODE_SHADED,
            ModeArg::Cluster => MODE_CLUSTER,
            ModeArg::Group => MODE_GROUP,
            ModeArg::Level => MODE_LEVEL,
            ModeArg::Error => MODE_ERROR,
        }
    }
}

fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s.split_once(['x', 'X']).context("--size wants WxH, e.g. 512x512")?;
    let (w, h) = (w.trim().parse::<u32>()?, h.trim().parse::<u32>()?);
    if !(1..=16384).contains(&w) || !(1..=16384).contains(&h) {
        bail!("--size {w}x{h}: each side must be 1..=16384");
    }
    Ok((w, h))
}

fn parse_vec3(s: &str) -> Result<[f32; 3]> {
    let v: Vec<f32> =
        s.split(',').map(|x| x.trim().parse::<f32>()).collect::<Result<_, _>>().context("--camera wants x,y,z")?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => bail!("--camera wants three finite numbers x,y,z"),
    }
}

const WINDOW_KEYS: &str = "Window keys: hold the right mouse button (or press Tab to toggle) to look \
around; W/A/S/D fly, E or Space up, Q or Ctrl down, Shift 5x faster (speed scales with the model's \
bounds); + and - or the mouse wheel scale tau; 1-5: shaded, cluster, group, level, error; R resets \
the camera; P writes a screenshot (--out, else preview-NNNNN.png); Esc quits. The title shows \
clusters and triangles drawn, GPU ms per pass and the frame rate.";

fn path_choice(arg: PathArg) -> DrawPath {
    match arg {
        PathArg::Auto => DrawPath::Auto,
        PathArg::Mesh => DrawPath::Mesh,
        PathArg::Fallback => DrawPath::Fallback,
    }
}

/// `preview FILE.mres` without `--headless`: the window.
fn run_window(args: &Args) -> Result<ExitCode> {
    if args.verify || args.bench || args.coverage {
        bail!("--verify, --bench and --coverage render offscreen: add --headless");
    }
    if !preview::viewer::display_available() {
        bail!("no display (neither DISPLAY nor WAYLAND_DISPLAY is set): add --headless to render offscreen (with --out, --verify or --bench)");
    }
    let size = parse_size(args.size.as_deref().unwrap_or("1280x720"))?;
    let file = MresFile::open(&args.file).with_context(|| format!("cannot read {}", args.file.display()))?;
    let scene = SceneData::from_file(&file).with_context(|| format!("{}", args.file.display()))?;
    let options = preview::viewer::ViewerOptions {
        label: args
            .file
            .file_name()
            .map_or_else(|| args.file.display().to_string(), |n| n.to_string_lossy().into_owned()),
        size,
        tau: args.tau,
        mode: args.mode.gpu(),
        eye: args.camera.as_deref().map(parse_vec3).transpose()?,
        frames: args.frames.map(|n| n.max(1)),
        screenshot: args.out.clone(),
        renderer: RendererOptions {
            naive_arithmetic: args.naive_arithmetic,
            path: path_choice(args.path),
            ..Default::default()
        },
        context: ContextOptions {
            validation: args.validate,
            device_name: args.device.clone(),
            allow_mesh_shaders: args.path != PathArg::Fallback,
            display: None,
        },
    };
    let report = preview::viewer::run(&scene, file.clusters.len() as u32, options)?;
    let mut ok = true;
    if args.validate {
        let counts = &report.counts;
        println!("validation messages: {} errors, {} warnings", counts.errors(), counts.warnings());
        ok = counts.errors() == 0 && counts.warnings() == 0;
        println!("{}", if ok { "PASS" } else { "FAIL" });
    }
    Ok(if ok { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

fn is_scene_file(path: &std::path::Path) -> bool {
    path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.ends_with(mres_import::scene::SCENE_SUFFIX))
}

/// `preview NAME.scene.json --headless`: a screenshot, the DAG frames of the benchmark path,
/// and the instanced selection check, for every instance of every mesh of the scene.
fn run_scene(args: &Args) -> Result<ExitCode> {
    if !args.headless {
        bail!("{}: scene files are drawn headless only (give --headless)", args.file.display());
    }
    if !args.verify && args.out.is_none() && !args.bench {
        bail!("nothing to do: give --verify, --out PNG and/or --bench");
    }
    let size = args.size.as_deref().unwrap_or(if args.bench { "1920x1080" } else { "512x512" });
    let (width, height) = parse_size(size)?;
    let scene = preview::instances::load_scene(&args.file)?;
    let device = Device::new(&ContextOptions {
        validation: args.validate,
        device_name: args.device.clone(),
        allow_mesh_shaders: args.path != PathArg::Fallback,
        display: None,
    })?;
    let counts = device.counts.clone();
    println!("device: {}", device.info.summary());
    println!(
        "scene: {} meshes, {} instances, {} clusters, {} level-0 triangles in the meshes",
        scene.files.len(),
        scene.instances.len(),
        scene.data.clusters.len(),
        scene.data.level0_triangles
    );
    let options = RendererOptions {
        naive_arithmetic: args.naive_arithmetic,
        path: path_choice(args.path),
        instances: scene.instances.clone(),
        ..Default::default()
    };
    let mut renderer = Renderer::new(&device, &scene.data, options)?;
    println!("draw path: {}", renderer.path_name());
    let n = scene.data.clusters.len() as u32;
    let mut ok = true;
    let mut report_json = json!({"file": args.file.display().to_string(), "path": renderer.path_name()});
    if let Some(out) = &args.out {
        let camera = match &args.camera {
            Some(c) => Camera::looking_at(parse_vec3(c)?, &scene.bounds, width, height),
            None => Camera::framing(&scene.bounds, width, height),
        };
        let mut view = camera.gpu_view(args.tau, &scene.data.grid, n, FLAG_FRUSTUM_CULL);
        view.mode = args.mode.gpu();
        let frame = renderer.render(&view, width, height)?;
        write_png(out, frame.width, frame.height, &frame.rgba)?;
        println!(
            "screenshot: {} ({}x{}, eye {:?}, tau {} px): {} clusters, {} triangles",
            out.display(),
            frame.width,
            frame.height,
            camera.eye,
            args.tau,
            frame.clusters,
            frame.triangles
        );
    }
    if args.bench {
        let frames = args.frames.unwrap_or(60).max(1);
        let bench = preview::bench::run_scene_bench(&mut renderer, &scene, frames, width, height, args.tau)?;
        println!("bench: {}", serde_json::to_string(&bench)?);
        if let Some(path) = &args.json {
            std::fs::write(path, serde_json::to_string_pretty(&bench)? + "\n")
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        report_json["bench"] = bench;
    }
    if args.verify {
        let options = VerifyOptions { selection_cameras: args.cameras, width, height, ..VerifyOptions::default() };
        let report = preview::verify::verify_scene(&mut renderer, &scene, &options)?;
        println!(
            "instanced selection: {} runs, {} mismatched runs, {} mismatched (cluster, instance) entries, {} lists with duplicates; {}..{} entries per run",
            report.runs,
            report.mismatched_runs,
            report.mismatched_entries,
            report.duplicate_lists,
            report.min_selected,
            report.max_selected
        );
        ok &= report.passed();
        report_json["verify"] = json!({"runs": report.runs, "mismatched_runs": report.mismatched_runs,
            "mismatched_entries": report.mismatched_entries, "duplicate_lists": report.duplicate_lists});
    }
    drop(renderer);
    drop(device);
    if args.validate {
        println!("validation messages: {} errors, {} warnings", counts.errors(), counts.warnings());
        ok &= counts.errors() == 0 && counts.warnings() == 0;
    }
    report_json["passed"] = json!(ok);
    if let Some(path) = &args.report {
        std::fs::write(path, serde_json::to_string_pretty(&report_json)? + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if args.verify || args.validate {
        println!("{}", if ok { "PASS" } else { "FAIL" });
    }
    Ok(if ok { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

fn run(args: Args) -> Result<ExitCode> {
    if is_scene_file(&args.file) {
        return run_scene(&args);
    }
    if !args.headless {
        return run_window(&args);
    }
    if !args.verify && args.out.is_none() && !args.bench && !args.coverage {
        bail!("nothing to do: give --verify, --out PNG, --bench and/or --coverage");
    }
    if !(1..=100).contains(&args.grid) {
        bail!("--grid {}: must be 1..=100", args.grid);
    }
    let size = args.size.as_deref().unwrap_or(if args.bench { "1920x1080" } else { "512x512" });
    let (width, height) = parse_size(size)?;
    let file = MresFile::open(&args.file).with_context(|| format!("cannot read {}", args.file.display()))?;
    let scene = SceneData::from_file(&file).with_context(|| format!("{}", args.file.display()))?;
    let device = Device::new(&ContextOptions {
        validation: args.validate,
        device_name: args.device.clone(),
        allow_mesh_shaders: args.path != PathArg::Fallback,
        display: None,
    })?;
    let info = device.info.clone();
    let counts = device.counts.clone();
    println!("device: {}", info.summary());
    println!("validation: {}", if args.validate { "on" } else { "off" });
    println!(
        "file: {} clusters, {} groups, {} pages ({} bytes decompressed), {} level-0 triangles",
        file.clusters.len(),
        file.groups.len(),
        file.pages.len(),
        scene.pages.len(),
        scene.level0_triangles
    );
    let path = path_choice(args.path);
    if args.bench {
        let instances = preview::bench::grid_instances(&scene, args.grid);
        let started = std::time::Instant::now();
        let chain = preview::lod_chain::LodChain::build(&file, 128, usize::MAX)
            .with_context(|| format!("{}", args.file.display()))?;
        println!(
            "LOD chain: {} levels ({} .. {} triangles) in {:.1} s",
            chain.levels.len(),
            chain.levels.first().map_or(0, |l| l.index_count / 3),
            chain.levels.last().map_or(0, |l| l.index_count / 3),
            started.elapsed().as_secs_f64()
        );
        let mut dag = Renderer::new(
            &device,
            &scene,
            RendererOptions {
                path,
                instances: instances.iter().map(|&t| preview::instances::translated(&scene, 0, t)).collect(),
                ..Default::default()
            },
        )?;
        println!("draw path: {}", dag.path_name());
        let mut chain_renderer = preview::vk::ChainRenderer::new(&device, &chain, &instances)?;
        let options = preview::bench::BenchOptions {
            grid: args.grid,
            frames: args.frames.unwrap_or(60).max(1),
            full_frames_when_huge: args.full_frames.max(1),
            width,
            height,
            tau: args.tau,
        };
        println!(
            "bench: {}x{} instances of {} triangles ({} source triangles), {}x{}, tau {} px, {} frames",
            args.grid,
            args.grid,
            scene.level0_triangles,
            scene.level0_triangles * (args.grid as u64).pow(2),
            width,
            height,
            args.tau,
            options.frames
        );
        let mut report = preview::bench::run_bench(&mut dag, &mut chain_renderer, &chain, &scene, &options)?;
        report["device"] = json!({ "name": info.name, "driver": info.driver, "api_version": info.api_version });
        report["file"] = json!(args.file.display().to_string());
        drop(dag);
        drop(chain_renderer);
        if let Some(path) = &args.json {
            std::fs::write(path, serde_json::to_string_pretty(&report)? + "\n")
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        if !args.verify && args.out.is_none() {
            drop(device);
            if args.validate {
                println!("validation messages: {} errors, {} warnings", counts.errors(), counts.warnings());
                return Ok(if counts.errors() + counts.warnings() == 0 {
                    ExitCode::SUCCESS
                } else {
                    ExitCode::FAILURE
                });
            }
            return Ok(ExitCode::SUCCESS);
        }
    }
    let mut renderer = Renderer::new(
        &device,
        &scene,
        RendererOptions { naive_arithmetic: args.naive_arithmetic, path, ..Default::default() },
    )?;
    println!("draw path: {}", renderer.path_name());
    let mut ok = true;
    let mut report_json = json!({
        "file": args.file.display().to_string(),
        "device": { "name": info.name, "driver": info.driver, "api_version": info.api_version,
                    "subgroup_size": info.subgroup_size, "mesh_shader_available": info.mesh_shader_available },
        "path": renderer.path_name(),
        "selection_arithmetic": if args.naive_arithmetic { "naive (driver division and sqrt)" } else { "exact (FORMAT.md §6)" },
        "clusters": file.clusters.len(),
    });

    if let Some(out) = &args.out {
        let camera = match &args.camera {
            Some(c) => Camera::looking_at(parse_vec3(c)?, &scene.bounds, width, height),
            None => Camera::framing(&scene.bounds, width, height),
        };
        let mut view = camera.gpu_view(args.tau, &scene.grid, file.clusters.len() as u32, FLAG_FRUSTUM_CULL);
        view.mode = args.mode.gpu();
        let frame = renderer.render(&view, width, height)?;
        write_png(out, frame.width, frame.height, &frame.rgba)?;
        let times = frame
            .times
            .map(|t| {
                format!("; GPU select {:.3} ms, expand {:.3} ms, draw {:.3} ms", t.select_ms, t.expand_ms, t.draw_ms)
            })
            .unwrap_or_default();
        println!(
            "screenshot: {} ({}x{}, eye {:?}, tau {} px): {} clusters, {} triangles{times}",
            out.display(),
            frame.width,
            frame.height,
            camera.eye,
            args.tau,
            frame.clusters,
            frame.triangles
        );
    }

    if args.coverage {
        let seed = VerifyOptions::default().seed;
        let rows = coverage(&mut renderer, &scene, args.crack_cameras, (width, height), seed)?;
        println!(
            "coverage ({} cameras at 3x the bounding radius, {width}x{height}): model pixels over the tau 0 render's, mean over the cameras",
            args.crack_cameras
        );
        for r in &rows {
            println!("  tau {:>6} px: {:>12.0} triangles, {:6.1}% covered", r.tau, r.triangles, r.covered * 100.0);
        }
        report_json["coverage"] = json!(rows.iter().map(CoverageRow::to_json).collect::<Vec<_>>());
    }

    if args.verify {
        let options = VerifyOptions {
            selection_cameras: args.cameras,
            crack_cameras: args.crack_cameras,
            width,
            height,
            failure_dir: args.failure_dir.clone(),
            ..VerifyOptions::default()
        };
        let started = std::time::Instant::now();
        let report = verify(&mut renderer, &file, &scene, &options)?;
        println!(
            "selection: {} runs ({} cameras x {:?} px), {} mismatched runs, {} mismatched clusters, {} lists with duplicates; {} clusters selected per run (min..max {}..{})",
            report.selection_runs,
            options.selection_cameras,
            options.taus,
            report.selection_mismatched_runs,
            report.selection_mismatched_clusters,
            report.duplicate_lists,
            if report.selection_runs > 0 { "" } else { "no" },
            report.min_selected,
            report.max_selected
        );
        println!(
            "projected errors: {} values compared bit for bit with the CPU, {} differ",
            report.projected_compared, report.projected_differences
        );
        for d in &report.disagreements {
            println!("  disagreement: {}", d.to_json());
        }
        println!(
            "cracks: {} renders ({} cameras x {:?} px, {}x{}), max hole pixels {} (back faces beyond the depth tolerance, enclosed by the full-detail surface), max exposed pixels {} (beyond it, but the full-detail surface seen from behind), max flagged pixels {}, renders with flagged pixels {}, min model pixels {}",
            report.crack_renders,
            options.crack_cameras,
            options.crack_taus,
            width,
            height,
            report.max_hole_pixels,
            report.max_exposed_pixels,
            report.max_flagged_pixels,
            report.flagged_renders,
            report.min_model_pixels
        );
        println!(
            "depth: {} model pixels against the tau 0 render, max difference / error bound {}, {} pixels ({:.4}%) over {} x the bound (allowed {}%)",
            report.depth_model_pixels,
            if report.depth_max_ratio.is_finite() { format!("{:.2}", report.depth_max_ratio) } else { "inf".into() },
            report.depth_violations,
            report.depth_violation_fraction() * 100.0,
            report.depth_limit,
            report.depth_max_fraction * 100.0
        );
        println!("verify time: {:.1} s", started.elapsed().as_secs_f64());
        ok &= report.passed();
        report_json["verify"] = report.to_json();
    }

    // Destroy everything first so that messages about destruction are counted too.
    drop(renderer);
    drop(device);
    if args.validate {
        println!("validation messages: {} errors, {} warnings", counts.errors(), counts.warnings());
        ok &= counts.errors() == 0 && counts.warnings() == 0;
        report_json["validation"] =
            json!({"errors": counts.errors(), "warnings": counts.warnings(), "first": counts.first_messages()});
    }
    report_json["passed"] = json!(ok);
    if let Some(path) = &args.report {
        std::fs::write(path, serde_json::to_string_pretty(&report_json)? + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if args.verify || args.validate {
        println!("{}", if ok { "PASS" } else { "FAIL" });
    }
    Ok(if ok { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("preview: {e:#}");
            ExitCode::from(2)
        }
    }
}
