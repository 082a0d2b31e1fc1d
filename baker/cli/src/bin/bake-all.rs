//! `bake-all`: bake every OBJ/glTF/GLB/PLY under a directory into `.mres` files, in parallel,
//! skipping what the content-addressed cache already holds.

use anyhow::{Context, Result};
use clap::Parser;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use mres_cli::batch::{AssetReport, Batch};
use mres_cli::config::{discover, PipelineConfig, DEFAULT_PIPELINE_TOML};
use mres_cli::tree::{find_assets, stale_outputs, Found};
use std::collections::{HashMap, HashSet};
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "bake-all",
    version,
    about = "Bake every OBJ, glTF, GLB and PLY under a directory into .mres cluster-DAG files",
    long_about = "Bake every OBJ, glTF, GLB and PLY under a directory into .mres cluster-DAG files.\n\n\
        Assets bake in parallel; each one is looked up first in a content-addressed cache keyed by its bytes, \
        the files it references, its effective settings and the format and baker versions, so an unchanged tree \
        bakes nothing.\n\n\
        Settings: the nearest pipeline.toml in the input's directory or above it, up to the first directory \
        holding .git or the filesystem root (like cargo's Cargo.toml); --config FILE replaces it; with neither, \
        the embedded defaults. The directory of that file is the asset root when the input lies inside it \
        (else the input directory): outputs mirror the tree below the asset root and [[override]] globs match \
        paths below it, so baking a subfolder or one file writes what baking the whole tree writes.\n\n\
        In a glTF scene where a mesh is placed by two or more nodes, each mesh is baked once into \
        NAME.meshN.mres (else the scene is flattened into NAME.mres); NAME.scene.json lists the .mres files, material names and instances (written \
        whenever an asset has instances or material names; docs/FORMAT.md, \"Scene file\").\n\n\
        After a directory's batch, .mres and scene files in the output directory that no current asset \
        produces (renamed or deleted assets) are listed; --prune deletes them.\n\n\
        Exit codes: 0 every asset baked; 1 some assets failed (the others are still written) or no assets \
        were found; 2 usage, settings or I/O error (nothing baked)."
)]
struct Cli {
    /// Asset directory, or a single mesh file.
    input: PathBuf,
    /// Output directory, mirroring the asset tree; created if missing, and checked to be
    /// writable before anything bakes. Default: [output] dir of the settings ("out").
    #[arg(short, long, value_name = "DIR")]
    output: Option<PathBuf>,
    /// Settings file, instead of the pipeline.toml found above the input.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Cache directory. Default: [cache] dir of the settings (".mres-cache").
    #[arg(long, value_name = "DIR")]
    cache_dir: Option<PathBuf>,
    /// Bake everything, neither reading nor writing the cache.
    #[arg(long)]
    no_cache: bool,
    /// Worker threads, shared by assets and by the groups of each DAG build (default: all cores).
    #[arg(short, long, value_name = "N")]
    jobs: Option<usize>,
    /// Write a JSON report to FILE: per asset (status, input and level-0 triangles, degenerate
    /// triangles dropped, levels, clusters, bytes, seconds, cache hit, scene and mesh files), the settings file used,
    /// skipped files with the reason, stale and pruned outputs, unmatched override globs.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Delete the stale .mres and scene files of the output directory: those that no asset under
    /// the input produces. Only .mres and .scene.json files, only under the output directory (the part of it that
    /// mirrors the input), which is taken to hold this tree's outputs alone: bake a subfolder
    /// into the tree's output directory only where a pipeline.toml marks the tree's root.
    #[arg(long)]
    prune: bool,
    /// Only print failures, warnings and the summary.
    #[arg(short, long, conflicts_with = "verbose")]
    quiet: bool,
    /// Also print every asset's line on a terminal, and name every skipped file with the reason.
    #[arg(short, long)]
    verbose: bool,
    /// Format of the tracing log on stderr (spans per asset and stage; filter with RUST_LOG,
    /// e.g. RUST_LOG=info). Colours only when stderr is a terminal.
    #[arg(long, value_enum, default_value = "text")]
    log_format: LogFormat,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum LogFormat {
    Text,
    Json,
}

/// Assets with at least this many triangles get their stages printed when stderr is not a
/// terminal (a terminal shows every baking asset's stage in its own line).
const LARGE_ASSET_TRIANGLES: u64 = 1_000_000;

/// Stale outputs named in the warning; the rest are counted.
const STALE_LISTED: usize = 5;

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// Everything decided before the first asset bakes; any problem here exits 2 with nothing baked.
struct Setup {
    /// Where the assets were found (a single file's directory).
    input_root: PathBuf,
    /// `input_root` under the asset root (see [`Batch::prefix`]).
    prefix: PathBuf,
    /// The settings file in use; `None`: the embedded defaults.
    config_path: Option<PathBuf>,
    config: PipelineConfig,
    found: Found,
    /// Whether the input is a directory (stale outputs and unmatched globs need a whole tree).
    directory: bool,
    out_dir: PathBuf,
    cache: Option<cache::LocalDisk>,
    /// The report file, opened (and so checked) before baking.
    report: Option<std::fs::File>,
}

impl Setup {
    fn new(cli: &Cli) -> Result<Setup> {
        if !cli.input.exists() {
            anyhow::bail!("{}: no such file or directory", cli.input.display());
        }
        let directory = cli.input.is_dir();
        let input_root = if directory {
            cli.input.clone()
        } else {
            Some(cli.input.parent().unwrap_or(Path::new("")))
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(Path::new("."))
                .to_path_buf()
        };
        let config_path = match &cli.config {
            Some(path) => Some(path.clone()),
            None => discover(&cli.input)?,
        };
        let config = match &config_path {
            Some(path) => PipelineConfig::load(path),
            None => PipelineConfig::parse(DEFAULT_PIPELINE_TOML, "embedded pipeline.toml"),
        }
        .map_err(anyhow::Error::msg)?;
        let prefix = prefix_under_config(&input_root, config_path.as_deref())?;
        let out_dir = cli.output.clone().unwrap_or_else(|| PathBuf::from(&config.output.dir));
        check_output_dir(&out_dir)?;
        let report = match &cli.report {
            Some(path) => Some(std::fs::File::create(path).with_context(|| format!("report {}", path.display()))?),
            None => None,
        };
        let cache_dir = cli.cache_dir.clone().unwrap_or_else(|| PathBuf::from(&config.cache.dir));
        let found = if directory {
            find_assets(&cli.input, &[out_dir.clone(), cache_dir.clone()], config_path.as_deref())?
        } else {
            Found { assets: vec![cli.input.clone()], ..Found::default() }
        };
        let cache = if cli.no_cache || !config.cache.enabled {
            None
        } else {
            Some(cache::LocalDisk::open(&cache_dir).with_context(|| format!("cache {}", cache_dir.display()))?)
        };
        Ok(Setup { input_root, prefix, config_path, config, found, directory, out_dir, cache, report })
    }

    /// Whether the batch covers the whole tree the settings apply to.
    fn whole_tree(&self) -> bool {
        self.directory && self.prefix.as_os_str().is_empty()
    }
}

/// Where `input_root` lies below the settings file's directory; empty when the settings file
/// is elsewhere (the input directory is then the asset root).
fn prefix_under_config(input_root: &Path, config: Option<&Path>) -> Result<PathBuf> {
    let Some(config_dir) = config.and_then(|c| c.canonicalize().ok()).and_then(|c| c.parent().map(Path::to_path_buf))
    else {
        return Ok(PathBuf::new());
    };
    let input = input_root.canonicalize().with_context(|| format!("{}", input_root.display()))?;
    Ok(input.strip_prefix(&config_dir).map(Path::to_path_buf).unwrap_or_default())
}

/// Creates the output directory and checks that a file can be written in it.
fn check_output_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("output directory {}: cannot create it", dir.display()))?;
    tempfile::Builder::new()
        .prefix(".bake-all-check")
        .tempfile_in(dir)
        .with_context(|| format!("output directory {}: cannot write to it", dir.display()))?;
    Ok(())
}

fn run(cli: Cli) -> Result<ExitCode> {
    mres_cli::log::init(matches!(cli.log_format, LogFormat::Json));
    if let Some(jobs) = cli.jobs {
        rayon::ThreadPoolBuilder::new().num_threads(jobs.max(1)).build_global()?;
    }
    let mut setup = Setup::new(&cli)?;
    if !cli.quiet {
        match &setup.config_path {
            Some(path) => eprintln!("config: {}", path.display()),
            None => eprintln!("config: embedded defaults"),
        }
    }
    if setup.found.assets.is_empty() {
        print_skipped(&cli, &setup.found);
        eprintln!(
            "error: no assets found under {} ({} files skipped{})",
            cli.input.display(),
            setup.found.skipped.len(),
            if cli.verbose || setup.found.skipped.is_empty() { "" } else { "; --verbose names them" }
        );
        return Ok(ExitCode::from(1));
    }
    let unmatched = unmatched_globs(&setup);
    let start = Instant::now();
    let batch = Batch {
        input_root: &setup.input_root,
        prefix: &setup.prefix,
        out_dir: &setup.out_dir,
        config: &setup.config,
        cache: setup.cache.as_ref(),
        stage: &|_, _| {},
    };
    let reports = bake(&cli, &batch, &setup.found.assets);
    let seconds = start.elapsed().as_secs_f64();
    print_summary(&cli, &setup.found, &reports, seconds);
    for glob in &unmatched {
        eprintln!("warning: {glob}");
    }
    let (stale, pruned) =
        if setup.directory { stale(&cli, &setup, &batch, &reports)? } else { (Vec::new(), Vec::new()) };
    if let Some(mut file) = setup.report.take() {
        let json = report_json(&setup, &reports, seconds, &unmatched, &stale, &pruned);
        let text = serde_json::to_string_pretty(&json)?;
        let path = cli.report.as_deref().unwrap_or(Path::new(""));
        file.write_all(text.as_bytes()).with_context(|| format!("report {}", path.display()))?;
    }
    let failed = reports.iter().any(|r| r.error.is_some());
    Ok(if failed { ExitCode::from(1) } else { ExitCode::SUCCESS })
}

/// The `[[override]]` globs that match no asset, as warning texts; only when the batch covers
/// the whole tree (a subfolder's batch leaves the other folders' globs unmatched on purpose).
fn unmatched_globs(setup: &Setup) -> Vec<String> {
    if !setup.whole_tree() {
        return Vec::new();
    }
    let relatives: Vec<PathBuf> =
        setup.found.assets.iter().map(|a| a.strip_prefix(&setup.input_root).unwrap_or(a).to_path_buf()).collect();
    let origin = setup.config_path.as_deref().map_or("embedded pipeline.toml".into(), |p| p.display().to_string());
    setup
        .config
        .unmatched_overrides(&relatives)
        .iter()
        .map(|o| {
            format!("{origin}: [[override]] glob {:?} matches no asset under {}", o.glob, setup.input_root.display())
        })
        .collect()
}

/// Bakes the batch behind a progress display that is gone before this returns, so that
/// nothing printed afterwards is drawn over.
fn bake(cli: &Cli, batch: &Batch, assets: &[PathBuf]) -> Vec<AssetReport> {
    let display = Display::new(cli, assets.len());
    let stage = |asset: &Path, line: &str| display.stage(asset, line);
    let batch = Batch { stage: &stage, ..*batch };
    let reports = batch.run(assets, |r| display.finished(r));
    display.close();
    reports
}

/// What the user sees while a batch runs: on a terminal a bar for the batch and a spinner per
/// baking asset (failures printed above them); otherwise plain lines, with the stages of large
/// assets.
struct Display {
    multi: MultiProgress,
    bar: Option<ProgressBar>,
    spinners: Mutex<HashMap<PathBuf, ProgressBar>>,
    large: Mutex<HashSet<PathBuf>>,
    done: AtomicUsize,
    cached: AtomicUsize,
    total: usize,
    quiet: bool,
    verbose: bool,
}

impl Display {
    fn new(cli: &Cli, total: usize) -> Display {
        let multi = MultiProgress::new();
        let bar = (std::io::stderr().is_terminal() && !cli.quiet).then(|| {
            let bar = multi.add(ProgressBar::new(total as u64));
            bar.set_style(
                ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} assets {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar())
                    .progress_chars("=> "),
            );
            bar
        });
        Display {
            multi,
            bar,
            spinners: Mutex::default(),
            large: Mutex::default(),
            done: AtomicUsize::new(0),
            cached: AtomicUsize::new(0),
            total,
            quiet: cli.quiet,
            verbose: cli.verbose,
        }
    }

    /// A stage line of a baking asset.
    fn stage(&self, asset: &Path, line: &str) {
        if self.quiet {
            return;
        }
        if self.bar.is_some() {
            let mut spinners = self.spinners.lock().unwrap_or_else(|e| e.into_inner());
            let spinner = spinners.entry(asset.to_path_buf()).or_insert_with(|| {
                let s = self.multi.add(ProgressBar::new_spinner());
                s.enable_steady_tick(std::time::Duration::from_millis(200));
                s
            });
            spinner.set_message(format!("{}: {line}", asset.display()));
            return;
        }
        let mut large = self.large.lock().unwrap_or_else(|e| e.into_inner());
        // "weld: N triangles" (built whole) or "shard: N triangles, …" (sharded).
        let triangles = line
            .strip_prefix("weld: ")
            .or_else(|| line.strip_prefix("shard: "))
            .and_then(|t| t.split(' ').next())
            .and_then(|n| n.parse::<u64>().ok());
        if triangles.is_some_and(|n| n >= LARGE_ASSET_TRIANGLES) {
            large.insert(asset.to_path_buf());
        }
        if large.contains(asset) {
            eprintln!("  {}: {line}", asset.display());
        }
    }

    /// An asset is done, baked, cached or failed: its spinner goes, its line is printed.
    fn finished(&self, r: &AssetReport) {
        let n = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        let c = self.cached.fetch_add(r.cache_hit as usize, Ordering::Relaxed) + r.cache_hit as usize;
        if let Some(spinner) = self.spinners.lock().unwrap_or_else(|e| e.into_inner()).remove(&r.input) {
            spinner.finish_and_clear();
            self.multi.remove(&spinner);
        }
        let line = asset_line(r, n, self.total);
        match &self.bar {
            Some(bar) => {
                bar.set_message(format!("({c} cached, {} baked)", n - c));
                if r.error.is_some() || self.verbose {
                    // Printed above the bars, which are then redrawn below it.
                    let _ = self.multi.println(line);
                }
                bar.inc(1);
            }
            None if !self.quiet || r.error.is_some() => eprintln!("{line}"),
            None => {}
        }
    }

    /// Clears every bar and spinner and stops drawing, so that later output stays visible.
    fn close(self) {
        for (_, spinner) in self.spinners.into_inner().unwrap_or_else(|e| e.into_inner()) {
            spinner.finish_and_clear();
        }
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
        let _ = self.multi.clear();
        self.multi.set_draw_target(ProgressDrawTarget::hidden());
    }
}

fn asset_line(r: &AssetReport, n: usize, total: usize) -> String {
    match &r.error {
        Some(e) => format!("[{n}/{total}] FAILED {e}"),
        None => format!(
            "[{n}/{total}] {} {}: {} input triangles{}, {} levels{}, {} clusters, {:.2} B/input triangle, {:.2}s",
            r.status,
            r.input.display(),
            r.input_triangles,
            match r.degenerate_dropped {
                0 => String::new(),
                d => format!(" ({d} degenerate or duplicate dropped)"),
            },
            r.levels,
            match r.shards {
                Some(s) if s > 0 => format!(" ({s} shards)"),
                _ => String::new(),
            },
            r.clusters,
            r.bytes_per_input_triangle,
            r.seconds
        ),
    }
}

fn print_skipped(cli: &Cli, found: &Found) {
    if cli.verbose {
        for s in &found.skipped {
            eprintln!("skipped: {}: {}", s.path.display(), s.reason);
        }
    }
}

fn print_summary(cli: &Cli, found: &Found, reports: &[AssetReport], seconds: f64) {
    print_skipped(cli, found);
    let count = |s: &str| reports.iter().filter(|r| r.status == s).count();
    let sum = |f: fn(&AssetReport) -> u64| reports.iter().map(f).sum::<u64>();
    let (tris, dropped, bytes) = (sum(|r| r.input_triangles), sum(|r| r.degenerate_dropped), sum(|r| r.bytes));
    let repaired = reports.iter().filter(|r| r.cache_repaired).count();
    let skipped = found.skipped.len();
    eprintln!(
        "{} assets: {} baked, {} cached, {} failed; {tris} input triangles ({dropped} degenerate or duplicate dropped), \
         {bytes} bytes out ({:.2} B/input triangle); {skipped} files skipped{}; {:.2}s{}",
        reports.len(),
        count("baked"),
        count("cached"),
        count("failed"),
        bytes as f64 / tris.max(1) as f64,
        if skipped > 0 && !cli.verbose { " (--verbose names them)" } else { "" },
        seconds,
        if repaired > 0 { format!("; {repaired} corrupt cache entries re-baked") } else { String::new() }
    );
    for r in reports {
        if let Some(e) = &r.error {
            eprintln!("failed: {e}");
        }
    }
}

/// Finds the stale outputs of a directory's batch; warns about them, or deletes them with
/// `--prune`. Returns (stale, pruned).
fn stale(cli: &Cli, setup: &Setup, batch: &Batch, reports: &[AssetReport]) -> Result<(Vec<PathBuf>, Vec<PathBuf>)> {
    let expected: HashSet<PathBuf> = batch.expected_outputs(reports);
    let dir = setup.out_dir.join(&setup.prefix);
    let stale = stale_outputs(&dir, &expected)?;
    if stale.is_empty() {
        return Ok((stale, Vec::new()));
    }
    if !cli.prune {
        let listed: Vec<String> = stale.iter().take(STALE_LISTED).map(|p| p.display().to_string()).collect();
        let more = stale.len().saturating_sub(STALE_LISTED);
        eprintln!(
            "warning: {} stale .mres/scene files in {} that no asset produces (renamed or deleted assets?): {}{}; \
             `bake-all --prune` deletes them",
            stale.len(),
            dir.display(),
            listed.join(", "),
            if more > 0 { format!(" and {more} more") } else { String::new() }
        );
        return Ok((stale, Vec::new()));
    }
    let mut pruned = Vec::new();
    for path in &stale {
        std::fs::remove_file(path).with_context(|| format!("pruning {}", path.display()))?;
        if cli.verbose {
            eprintln!("pruned: {}", path.display());
        }
        pruned.push(path.clone());
    }
    eprintln!("pruned {} stale .mres/scene files from {}", pruned.len(), dir.display());
    Ok((stale, pruned))
}

fn report_json(
    setup: &Setup,
    reports: &[AssetReport],
    seconds: f64,
    unmatched: &[String],
    stale: &[PathBuf],
    pruned: &[PathBuf],
) -> serde_json::Value {
    let count = |s: &str| reports.iter().filter(|r| r.status == s).count();
    let sum = |f: fn(&AssetReport) -> u64| reports.iter().map(f).sum::<u64>();
    serde_json::json!({
        "config": setup.config_path,
        "assets": reports,
        "baked": count("baked"), "cached": count("cached"), "failed": count("failed"),
        "skipped": setup.found.skipped.len(),
        "skipped_files": setup.found.skipped,
        "companion_files": setup.found.companions,
        "input_triangles": sum(|r| r.input_triangles),
        "level0_triangles": sum(|r| r.level0_triangles),
        "degenerate_dropped": sum(|r| r.degenerate_dropped),
        "bytes": sum(|r| r.bytes),
        "scene_bytes": sum(|r| r.scene_bytes),
        "seconds": seconds,
        "unmatched_overrides": unmatched,
        "stale": stale,
        "pruned": pruned,
    })
}
