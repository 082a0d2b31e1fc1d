//! `bake-all`: bake every OBJ/glTF/GLB under a directory into `.mres` files, in parallel,
//! skipping what the content-addressed cache already holds.

use anyhow::{Context, Result};
use clap::Parser;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use mres_cli::batch::{find_assets, AssetReport, Batch};
use mres_cli::config::{PipelineConfig, DEFAULT_PIPELINE_TOML};
use std::collections::{HashMap, HashSet};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "bake-all",
    version,
    about = "Bake every OBJ, glTF and GLB under a directory into .mres cluster-DAG files",
    long_about = "Bake every OBJ, glTF and GLB under a directory into .mres cluster-DAG files.\n\n\
        Assets bake in parallel; each one is looked up first in a content-addressed cache keyed by its bytes, \
        the files it references, its effective settings and the format and baker versions, so an unchanged tree \
        bakes nothing. Outputs mirror the asset tree. Exit code 0 when every asset baked, 1 when some failed \
        (the others are still written), 2 on a usage or set-up error."
)]
struct Cli {
    /// Asset directory (or a single mesh file).
    input: PathBuf,
    /// Output directory; mirrors the asset tree. Default: [output] dir of the config ("out").
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Settings file. Default: pipeline.toml at the root of the asset tree, else the embedded defaults.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Cache directory. Default: [cache] dir of the config (".mres-cache").
    #[arg(long)]
    cache_dir: Option<PathBuf>,
    /// Bake everything, neither reading nor writing the cache.
    #[arg(long)]
    no_cache: bool,
    /// Worker threads, shared by assets and by the groups of each DAG build (default: all cores).
    #[arg(short, long)]
    jobs: Option<usize>,
    /// Write per-asset figures (triangles, levels, clusters, bytes, seconds, cache hit) as JSON.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Only print failures and the summary.
    #[arg(short, long)]
    quiet: bool,
    /// Format of the tracing log on stderr (spans per asset and stage; filter with RUST_LOG,
    /// e.g. RUST_LOG=info).
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

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn load_config(cli: &Cli, root: &Path) -> Result<PipelineConfig> {
    let root_config = root.join("pipeline.toml");
    match (&cli.config, root_config.is_file()) {
        (Some(path), _) => PipelineConfig::load(path),
        (None, true) => PipelineConfig::load(&root_config),
        (None, false) => PipelineConfig::parse(DEFAULT_PIPELINE_TOML, "embedded pipeline.toml"),
    }
    .map_err(anyhow::Error::msg)
}

fn init_tracing(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let builder = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr);
    match format {
        LogFormat::Text => builder.init(),
        LogFormat::Json => builder.json().init(),
    }
}

fn run(cli: Cli) -> Result<ExitCode> {
    init_tracing(cli.log_format);
    if let Some(jobs) = cli.jobs {
        rayon::ThreadPoolBuilder::new().num_threads(jobs.max(1)).build_global()?;
    }
    if !cli.input.exists() {
        anyhow::bail!("{}: no such file or directory", cli.input.display());
    }
    let (root, assets, skipped) = if cli.input.is_file() {
        (cli.input.parent().unwrap_or(Path::new(".")).to_path_buf(), vec![cli.input.clone()], 0)
    } else {
        let (assets, skipped) = find_assets(&cli.input)?;
        (cli.input.clone(), assets, skipped)
    };
    let config = load_config(&cli, &root)?;
    let out_dir = cli.output.clone().unwrap_or_else(|| PathBuf::from(&config.output.dir));
    let cache = if cli.no_cache || !config.cache.enabled {
        None
    } else {
        let dir = cli.cache_dir.clone().unwrap_or_else(|| PathBuf::from(&config.cache.dir));
        Some(cache::LocalDisk::open(&dir).with_context(|| format!("cache {}", dir.display()))?)
    };

    let start = Instant::now();
    let multi = MultiProgress::new();
    let bar = (std::io::stderr().is_terminal() && !cli.quiet).then(|| {
        let bar = multi.add(ProgressBar::new(assets.len() as u64));
        bar.set_style(
            ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} assets {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar
    });
    let (done, cached) = (AtomicUsize::new(0), AtomicUsize::new(0));
    let total = assets.len();
    // Per baking asset: a spinner with its stage on a terminal, else plain lines for large ones.
    let spinners: Mutex<HashMap<PathBuf, ProgressBar>> = Mutex::new(HashMap::new());
    let large: Mutex<HashSet<PathBuf>> = Mutex::new(HashSet::new());
    let stage = |asset: &Path, line: &str| {
        if cli.quiet {
            return;
        }
        if bar.is_some() {
            let mut spinners = spinners.lock().unwrap_or_else(|e| e.into_inner());
            let spinner = spinners.entry(asset.to_path_buf()).or_insert_with(|| {
                let s = multi.add(ProgressBar::new_spinner());
                s.enable_steady_tick(std::time::Duration::from_millis(200));
                s
            });
            spinner.set_message(format!("{}: {line}", asset.display()));
            if line == "write" {
                spinner.finish_and_clear();
                spinners.remove(asset);
            }
            return;
        }
        let mut large = large.lock().unwrap_or_else(|e| e.into_inner());
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
    };
    let batch = Batch { root: &root, out_dir: &out_dir, config: &config, cache: cache.as_ref(), stage: &stage };
    let reports = batch.run(&assets, |r: &AssetReport| {
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        let c = cached.fetch_add(r.cache_hit as usize, Ordering::Relaxed) + r.cache_hit as usize;
        let line = match &r.error {
            Some(e) => format!("[{n}/{total}] FAILED {}", e),
            None => format!(
                "[{n}/{total}] {} {}: {} triangles, {} levels{}, {} clusters, {:.2} B/tri, {:.2}s",
                r.status,
                r.input.display(),
                r.input_triangles,
                r.levels,
                match r.shards {
                    Some(s) if s > 0 => format!(" ({s} shards)"),
                    _ => String::new(),
                },
                r.clusters,
                r.bytes_per_input_triangle,
                r.seconds
            ),
        };
        match &bar {
            Some(bar) => {
                bar.set_message(format!("({c} cached, {} baked)", n - c));
                if r.error.is_some() {
                    bar.println(line);
                }
                bar.inc(1);
            }
            None if !cli.quiet || r.error.is_some() => eprintln!("{line}"),
            None => {}
        }
    });
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }

    let count = |s: &str| reports.iter().filter(|r| r.status == s).count();
    let (baked, hits, failed) = (count("baked"), count("cached"), count("failed"));
    let tris: u64 = reports.iter().map(|r| r.input_triangles).sum();
    let bytes: u64 = reports.iter().map(|r| r.bytes).sum();
    let repaired = reports.iter().filter(|r| r.cache_repaired).count();
    eprintln!(
        "{} assets: {baked} baked, {hits} cached, {failed} failed; {skipped} other files skipped; {tris} triangles in, {bytes} bytes out ({:.2} B/tri); {:.2}s{}",
        reports.len(),
        bytes as f64 / tris.max(1) as f64,
        start.elapsed().as_secs_f64(),
        if repaired > 0 { format!("; {repaired} corrupt cache entries re-baked") } else { String::new() }
    );
    for r in reports.iter().filter(|r| r.error.is_some()) {
        eprintln!("failed: {}", r.error.as_deref().unwrap_or(""));
    }
    if let Some(path) = &cli.report {
        let json = serde_json::json!({
            "assets": reports, "baked": baked, "cached": hits, "failed": failed, "skipped": skipped,
            "input_triangles": tris, "bytes": bytes, "seconds": start.elapsed().as_secs_f64(),
        });
        std::fs::write(path, serde_json::to_string_pretty(&json)?).with_context(|| format!("{}", path.display()))?;
    }
    Ok(if failed == 0 { ExitCode::SUCCESS } else { ExitCode::from(1) })
}
