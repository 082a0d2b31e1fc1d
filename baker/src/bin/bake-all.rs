//! `bake-all`: bake every OBJ/glTF/GLB under a directory into `.mres` files.

use anyhow::{Context, Result};
use baker::bake::bake_file;
use baker::config::{PipelineConfig, DEFAULT_PIPELINE_TOML};
use clap::Parser;
use formats::import::InputKind;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "bake-all",
    version,
    about = "Bake every OBJ, glTF and GLB under a directory into .mres cluster-DAG files"
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
    /// Worker threads for the DAG build (default: all cores).
    #[arg(short, long)]
    jobs: Option<usize>,
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

/// Mesh files under `root`, sorted; other files are counted.
fn walk(root: &Path, found: &mut Vec<PathBuf>, skipped: &mut usize) -> Result<()> {
    let mut entries: Vec<_> =
        std::fs::read_dir(root).with_context(|| format!("{}", root.display()))?.collect::<Result<_, _>>()?;
    entries.sort_by_key(|e| e.path());
    for e in entries {
        let path = e.path();
        if path.is_dir() {
            walk(&path, found, skipped)?;
        } else if InputKind::from_path(&path).is_some() {
            found.push(path);
        } else {
            *skipped += 1;
        }
    }
    Ok(())
}

fn run(cli: Cli) -> Result<ExitCode> {
    if let Some(jobs) = cli.jobs {
        rayon::ThreadPoolBuilder::new().num_threads(jobs.max(1)).build_global()?;
    }
    let root_config = cli.input.join("pipeline.toml");
    let config = match (&cli.config, root_config.is_file()) {
        (Some(path), _) => PipelineConfig::load(path),
        (None, true) => PipelineConfig::load(&root_config),
        (None, false) => PipelineConfig::parse(DEFAULT_PIPELINE_TOML, "embedded pipeline.toml"),
    }
    .map_err(anyhow::Error::msg)?;
    let out_dir = cli.output.clone().unwrap_or_else(|| PathBuf::from(&config.output.dir));

    let (root, files, skipped) = if cli.input.is_file() {
        (cli.input.parent().unwrap_or(Path::new(".")).to_path_buf(), vec![cli.input.clone()], 0)
    } else {
        let mut files = Vec::new();
        let mut skipped = 0;
        walk(&cli.input, &mut files, &mut skipped)?;
        (cli.input.clone(), files, skipped)
    };
    let start = Instant::now();
    let (mut baked, mut failed, mut tris_in, mut bytes_out) = (0, 0, 0u64, 0u64);
    for (i, file) in files.iter().enumerate() {
        let rel = file.strip_prefix(&root).unwrap_or(file);
        let target = out_dir.join(rel).with_extension("mres");
        let t0 = Instant::now();
        match bake_file(file, &config.bake).and_then(|b| Ok(b)) {
            Ok(b) => {
                let write = || -> Result<()> {
                    if let Some(dir) = target.parent() {
                        std::fs::create_dir_all(dir)?;
                    }
                    let tmp = target.with_extension("mres.tmp");
                    std::fs::write(&tmp, &b.bytes)?;
                    std::fs::rename(&tmp, &target)?;
                    Ok(())
                };
                if let Err(e) = write() {
                    failed += 1;
                    eprintln!(
                        "[{}/{}] FAILED {}: writing {}: {e:#}",
                        i + 1,
                        files.len(),
                        file.display(),
                        target.display()
                    );
                    continue;
                }
                baked += 1;
                tris_in += b.stats.source_triangles;
                bytes_out += b.stats.bytes;
                eprintln!(
                    "[{}/{}] {} -> {}: {} triangles, {} clusters, {} groups, {:.2} B/tri, {:.2}s",
                    i + 1,
                    files.len(),
                    file.display(),
                    target.display(),
                    b.stats.source_triangles,
                    b.stats.clusters,
                    b.stats.groups,
                    b.stats.bytes as f64 / b.stats.source_triangles.max(1) as f64,
                    t0.elapsed().as_secs_f64()
                );
            }
            Err(e) => {
                failed += 1;
                eprintln!("[{}/{}] FAILED {}: {e}", i + 1, files.len(), file.display());
            }
        }
    }
    eprintln!(
        "baked {baked}, failed {failed}, skipped {skipped} non-mesh files; {tris_in} triangles in, {bytes_out} bytes out; {:.1}s",
        start.elapsed().as_secs_f64()
    );
    Ok(if failed == 0 { ExitCode::SUCCESS } else { ExitCode::from(1) })
}
