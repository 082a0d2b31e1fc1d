//! `mres`: validate, inspect, export and benchmark `.mres` files.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use mres_build::BakeSettings;
use mres_check::validate::{validate, ValidateOptions};
use mres_cli::bench::{run_clusterlod, run_mres, BuilderRun, CUT_THRESHOLDS};
use mres_format::{select, MresFile, NO_GROUP};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "mres", version, about = "Validate, inspect, export and benchmark .mres cluster-DAG files")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Check a file (DESIGN.md invariants 1–5): checksums and references, monotone errors and
    /// nested spheres, crack-free cuts at every uniform threshold and at random cameras, DAG
    /// conditioning (depth, edge age, group sizes, same-boundary clusters) and error honesty.
    /// Thresholds are documented in `mres_check::validate::Thresholds`. Exit 1 on any violation.
    Validate {
        /// The .mres file.
        file: PathBuf,
        /// Random view-dependent cuts to check.
        #[arg(long, default_value_t = 1000)]
        random_cuts: usize,
        /// Most uniform cuts to check: every distinct group error by default (0); with N,
        /// N thresholds spread evenly over the sorted errors, the finest and coarsest included
        /// (for files of tens of millions of triangles).
        #[arg(long, default_value_t = 0)]
        uniform_cuts: usize,
        /// Seed of the random cameras.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Print a file's header, levels, groups, pages and sizes.
    Inspect {
        /// The .mres file.
        file: PathBuf,
        /// Print as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write a cut of the DAG as an OBJ mesh: the uniform cut at object-space error E, or the
    /// view-dependent cut seen from a camera at a pixel threshold.
    Export {
        /// The .mres file.
        file: PathBuf,
        /// Object-space error of the uniform cut (0 = original geometry).
        #[arg(long, conflicts_with = "camera")]
        error: Option<f32>,
        /// Eye position "x,y,z" of a view-dependent cut (60° vertical field of view).
        #[arg(long, value_parser = parse_vec3, requires = "tau")]
        camera: Option<[f32; 3]>,
        /// Pixel threshold of the view-dependent cut.
        #[arg(long)]
        tau: Option<f32>,
        /// Viewport height in pixels for the view-dependent cut.
        #[arg(long, default_value_t = 1080.0)]
        height: f32,
        /// Output OBJ path.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Bake INPUT with mres and with meshoptimizer's clusterlod in the same run (each in its own
    /// child process) and compare time, peak memory and quality.
    Bench {
        /// Mesh file (OBJ, glTF, GLB).
        input: PathBuf,
        /// Runs per builder; the minimum time and RSS are reported.
        #[arg(long, default_value_t = 1)]
        repeat: usize,
        /// Bake settings from this pipeline.toml's [bake] table (default: the compiled-in ones),
        /// e.g. to compare `error_bound` modes.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Maintain the bake cache: stats, verify (check every entry; --repair removes corrupt
    /// ones), gc --max-size SIZE (drop least recently used entries until the cache fits).
    Cache {
        #[command(subcommand)]
        action: CacheAction,
        /// Cache directory.
        #[arg(long, default_value = ".mres-cache", global = true)]
        cache_dir: PathBuf,
    },
    /// One builder run of `bench` (internal).
    #[command(hide = true)]
    BenchChild {
        /// "mres" or "clusterlod".
        builder: String,
        /// Mesh file.
        input: PathBuf,
        /// pipeline.toml whose [bake] settings to use.
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Write a generated test mesh as OBJ: sphere N (12·N² triangles, closed), terrain N
    /// (2·N² triangles, open), boxes N (N disconnected boxes of 192 triangles), seamed-sphere N
    /// (a sphere whose 6 faces are separate UV charts and materials), cards N (N disconnected
    /// open quads, like foliage), defects N (sphere N with holes, duplicate triangles and
    /// non-manifold fins).
    Generate {
        /// sphere, terrain, boxes, seamed-sphere, cards or defects.
        kind: String,
        /// Size parameter.
        n: u32,
        /// Output OBJ path.
        #[arg(short, long)]
        output: PathBuf,
    },
}

#[derive(Subcommand)]
enum CacheAction {
    /// Entries, bytes, temporary files, oldest and newest entry.
    Stats,
    /// Read every entry and check its header and content hash; exit 1 if any is corrupt.
    Verify {
        /// Remove corrupt entries.
        #[arg(long)]
        repair: bool,
    },
    /// Remove stale temporary files, then least recently used entries until the cache holds at
    /// most SIZE (e.g. 500M, 2G; K/M/G/T are powers of 1024).
    Gc {
        /// Largest total size to keep.
        #[arg(long, value_parser = cache::parse_size)]
        max_size: u64,
    },
}

fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> =
        s.split(',').map(|x| x.trim().parse::<f32>()).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
    v.try_into().map_err(|_| "expected x,y,z".to_string())
}

fn open(path: &Path) -> Result<MresFile> {
    MresFile::open(path).with_context(|| format!("{}", path.display()))
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Validate { file, random_cuts, uniform_cuts, seed, json } => {
            let f = open(&file)?;
            let report = validate(&f, &ValidateOptions { random_cuts, uniform_cuts, seed, ..Default::default() })
                .with_context(|| format!("{}", file.display()))?;
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                println!(
                    "{}: {} bytes, {} source triangles, {:.2} bytes/input triangle, {} pages",
                    file.display(),
                    report.bytes,
                    report.source_triangles,
                    report.bytes_per_input_triangle,
                    report.pages
                );
                println!(
                    "levels {}  root groups {}  root clusters {}  level-0 fill {:.1}",
                    report.levels, report.root_groups, report.root_clusters, report.level0_fill
                );
                println!("{:>5} {:>9} {:>8} {:>11}", "level", "clusters", "groups", "triangles");
                for l in &report.per_level {
                    println!("{:>5} {:>9} {:>8} {:>11}", l.level, l.clusters, l.groups, l.triangles);
                }
                println!(
                    "cuts checked: {} uniform, {} random; cracked {}; relations checked {}; most pinched edges in a cut {}",
                    report.uniform_cuts,
                    report.random_cuts,
                    report.cracked_cuts,
                    report.relations_checked,
                    report.max_pinched_edges
                );
                let c = &report.conditioning;
                println!(
                    "depth {} vs log2(level-0 clusters) {:.1} (ratio {:.2}); reduction per level {}",
                    report.levels,
                    c.log2_level0_clusters,
                    c.depth_ratio,
                    c.reduction_per_level.iter().map(|r| format!("{r:.2}")).collect::<Vec<_>>().join(" ")
                );
                println!(
                    "edge age mean {:.2} max {} ({} locked original edges); same-boundary clusters {}; group sizes {:?}",
                    c.edge_age_mean, c.edge_age_max, c.locked_original_edges, c.same_boundary_clusters, c.group_size_histogram
                );
                println!("edges by age (levels survived): {:?}", c.edge_age_histogram);
                println!(
                    "error honesty: worst {:.2} p99 {:.2} (measured distance / stored error, {} cuts, {} points); worst at {}",
                    report.honesty.worst_ratio, report.honesty.p99_ratio, report.honesty.cuts, report.honesty.samples, report.honesty.worst
                );
                for v in &report.violations {
                    println!("VIOLATION {}: {v}", file.display());
                }
                println!("{}", if report.ok() { "OK" } else { "FAILED" });
            }
            Ok(if report.ok() { ExitCode::SUCCESS } else { ExitCode::from(1) })
        }
        Command::Inspect { file, json } => {
            let f = open(&file)?;
            inspect(&f, json)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Export { file, error, camera, tau, height, output } => {
            let f = open(&file)?;
            let cut = match (error, camera, tau) {
                (Some(e), None, _) => select::uniform_cut(&f.groups, &f.clusters, e),
                (None, Some(eye), Some(tau)) => {
                    let radius = f.groups.first().map_or(1.0, |g| g.sphere.radius);
                    let view = select::ViewParams {
                        eye,
                        proj_y: 1.0 / 30f32.to_radians().tan(),
                        viewport_height: height,
                        z_near: radius * 1e-3,
                    };
                    select::view_cut(&f.groups, &f.clusters, &view, tau)
                }
                _ => bail!("give --error E, or --camera x,y,z with --tau T"),
            };
            let mesh = mres_cli::export::cut_mesh(&f, &cut)?;
            let mut out = std::io::BufWriter::new(
                std::fs::File::create(&output).with_context(|| format!("{}", output.display()))?,
            );
            mres_import::obj_write::write_obj(&mesh, &mut out).with_context(|| format!("{}", output.display()))?;
            eprintln!("{}: {} clusters, {} triangles", output.display(), cut.len(), mesh.triangle_count());
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { input, repeat, config, json } => bench(&input, repeat.max(1), config.as_deref(), json),
        Command::Cache { action, cache_dir } => {
            let disk = cache::LocalDisk::open(&cache_dir).with_context(|| format!("cache {}", cache_dir.display()))?;
            match action {
                CacheAction::Stats => {
                    let s = disk.stats()?;
                    println!(
                        "{}: {} entries, {} bytes, {} temporary files",
                        cache_dir.display(),
                        s.entries,
                        s.bytes,
                        s.temp_files
                    );
                }
                CacheAction::Verify { repair } => {
                    let r = disk.verify(repair)?;
                    println!(
                        "{}: {} entries checked, {} valid ({} bytes), {} corrupt",
                        cache_dir.display(),
                        r.checked,
                        r.valid,
                        r.valid_bytes,
                        r.corrupt.len()
                    );
                    for c in &r.corrupt {
                        println!(
                            "corrupt: {}: {}{}",
                            c.path.display(),
                            c.problem,
                            if c.removed { " (removed)" } else { "" }
                        );
                    }
                    if !r.is_clean() && !repair {
                        return Ok(ExitCode::from(1));
                    }
                }
                CacheAction::Gc { max_size } => {
                    let r = disk.gc(max_size)?;
                    println!(
                        "{}: removed {} entries ({} bytes) and {} temporary files; kept {} entries ({} bytes)",
                        cache_dir.display(),
                        r.entries_removed,
                        r.bytes_removed,
                        r.temp_removed,
                        r.entries_kept,
                        r.bytes_kept
                    );
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::BenchChild { builder, input, config } => {
            let settings = match config {
                Some(path) => mres_cli::config::PipelineConfig::load(&path).map_err(anyhow::Error::msg)?.bake,
                None => BakeSettings::default(),
            };
            let mesh = mres_import::import_file(&input, &Default::default())?;
            let run = match builder.as_str() {
                "mres" => run_mres(mesh, &settings)?,
                "clusterlod" => run_clusterlod(mesh, &settings)?,
                other => bail!("unknown builder {other}"),
            };
            println!("{}", serde_json::to_string(&run)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::Generate { kind, n, output } => {
            let mesh = match kind.as_str() {
                "sphere" => mres_cli::generate::sphere(n),
                "terrain" => mres_cli::generate::terrain(n),
                "boxes" => mres_cli::generate::boxes(n, 4),
                "seamed-sphere" => mres_cli::generate::seamed_sphere(n),
                "cards" => mres_cli::generate::cards(n),
                "defects" => mres_cli::generate::defects(n),
                other => bail!("unknown kind {other} (sphere, terrain, boxes, seamed-sphere, cards, defects)"),
            };
            let mut out = std::io::BufWriter::new(
                std::fs::File::create(&output).with_context(|| format!("{}", output.display()))?,
            );
            mres_import::obj_write::write_obj(&mesh, &mut out)?;
            eprintln!("{}: {} triangles", output.display(), mesh.triangle_count());
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// Fractions of the largest extent at which `inspect` counts the triangles of uniform cuts:
/// 0, then half-decades from 1e-5 to 1e-1.
const INSPECT_CUTS: [f32; 10] = [0.0, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1];

fn inspect(f: &MresFile, json: bool) -> Result<()> {
    let h = &f.header;
    let level0 = f.clusters.iter().filter(|c| c.own_group == NO_GROUP).count();
    let raw: u64 = f.pages.iter().map(|p| p.raw_size as u64).sum();
    let value = serde_json::json!({
        "flags": h.flags, "grid_origin": h.grid.origin, "grid_step": h.grid.step,
        "position_bits": h.position_bits, "normal_bits": h.normal_bits, "levels": h.level_count,
        "source_triangles": h.source_triangles, "groups": f.groups.len(), "clusters": f.clusters.len(),
        "level0_clusters": level0, "pages": f.pages.len(), "file_bytes": f.file_size(), "raw_page_bytes": raw,
        "stored_triangles": f.clusters.iter().map(|c| c.triangle_count as u64).sum::<u64>(),
        "root_groups": f.groups.iter().filter(|g| g.error.is_infinite()).count(),
        // Triangles drawn by uniform cuts at fixed fractions of the largest extent: comparable
        // between two bakes of one mesh (e.g. sharded and whole).
        "cut_triangles_at_extent_fraction": INSPECT_CUTS.iter().map(|&t| {
            let extent = h.grid.step * ((1u64 << h.position_bits) - 1) as f32;
            let cut = select::uniform_cut(&f.groups, &f.clusters, t * extent);
            (t, cut.iter().map(|&c| f.clusters[c as usize].triangle_count as u64).sum::<u64>())
        }).collect::<Vec<_>>(),
    });
    if json {
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        for (k, v) in value.as_object().into_iter().flatten() {
            println!("{k:>18}: {v}");
        }
    }
    Ok(())
}

fn bench(input: &Path, repeat: usize, config: Option<&Path>, json: bool) -> Result<ExitCode> {
    let exe = std::env::current_exe()?;
    let mut best: Vec<BuilderRun> = Vec::new();
    for builder in ["mres", "clusterlod"] {
        let mut runs = Vec::new();
        for _ in 0..repeat {
            let mut child = std::process::Command::new(&exe);
            child.args(["bench-child", builder]).arg(input);
            if let Some(path) = config {
                child.arg("--config").arg(path);
            }
            let out = child.output()?;
            if !out.status.success() {
                bail!("{builder} on {}: {}", input.display(), String::from_utf8_lossy(&out.stderr));
            }
            runs.push(serde_json::from_slice::<BuilderRun>(&out.stdout)?);
        }
        let mut run = runs[0].clone();
        run.seconds = runs.iter().map(|r| r.seconds).fold(f64::INFINITY, f64::min);
        run.dag_seconds = runs.iter().map(|r| r.dag_seconds).fold(f64::INFINITY, f64::min);
        run.peak_rss_bytes = runs.iter().map(|r| r.peak_rss_bytes).min().unwrap_or(0);
        best.push(run);
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&best)?);
        return Ok(ExitCode::SUCCESS);
    }
    println!("{} ({} triangles), min over {repeat} run(s)", input.display(), best[0].input_triangles);
    println!(
        "{:<11} {:>8} {:>8} {:>10} {:>8} {:>6} {:>6} {:>6}  triangles per uniform cut at {:?} × diagonal",
        "builder", "total s", "DAG s", "peak MiB", "RSS B/tri", "levels", "roots", "fill", CUT_THRESHOLDS
    );
    for r in &best {
        println!(
            "{:<11} {:>8.3} {:>8.3} {:>10.1} {:>8.1} {:>6} {:>6} {:>6.1}  {:?}{}",
            r.builder,
            r.seconds,
            r.dag_seconds,
            r.peak_rss_bytes as f64 / 1048576.0,
            r.peak_rss_bytes as f64 / r.input_triangles.max(1) as f64,
            r.levels,
            r.root_clusters,
            r.level0_fill,
            r.cut_triangles,
            if r.bytes > 0 {
                format!("  file {:.2} B/input tri", r.bytes as f64 / r.input_triangles.max(1) as f64)
            } else {
                String::new()
            }
        );
    }
    println!(
        "time ratio mres/clusterlod {:.2} (DAG only {:.2}), peak RSS ratio {:.2}",
        best[0].seconds / best[1].seconds,
        best[0].dag_seconds / best[1].dag_seconds,
        best[0].peak_rss_bytes as f64 / best[1].peak_rss_bytes.max(1) as f64
    );
    Ok(ExitCode::SUCCESS)
}
