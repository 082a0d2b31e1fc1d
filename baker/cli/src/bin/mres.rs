//! `mres`: validate, inspect, export and benchmark `.mres` files; maintain the bake cache;
//! generate test meshes. One function per subcommand.

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};
use mres_build::BakeSettings;
use mres_check::validate::{validate, Thresholds, ValidateOptions};
use mres_cli::bench::{self, compare, measure, run_clusterlod, run_mres, BuilderRun, Report};
use mres_cli::inspect::summarize;
use mres_cli::view_cost;
use mres_format::{select, MresFile};
use mres_import::SourceMesh;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "mres",
    version,
    about = "Validate, inspect, export and benchmark .mres cluster-DAG files; maintain the bake cache",
    long_about = "Validate, inspect, export and benchmark .mres cluster-DAG files; maintain the bake cache; \
        generate test meshes.\n\n\
        Read-only commands print text, or JSON on stdout with --json. Commands that bake write a JSON \
        report with --report FILE. Output files are checked to be writable before any work and written \
        whole (through a temporary file) or not at all.\n\n\
        Exit codes: 0 ok; 1 violations (validate) or corrupt entries (cache verify); 2 usage error, \
        unreadable or damaged file, or I/O error."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Check a file against docs/INVARIANTS.md §1-§5: checksums and references, monotone
    /// errors and nested spheres, crack-free cuts at every uniform threshold and at random
    /// cameras, DAG conditioning (depth, edge age, group sizes, same-boundary clusters) and
    /// error honesty (thresholds: `mres_check::validate::Thresholds`). Exit 1 on any violation.
    Validate(ValidateArgs),
    /// Summarise a file to help choose a cut: size, input and level-0 triangles, attributes,
    /// grid and bounds, then per level the groups, clusters, triangles and group errors (object
    /// units and a fraction of the bounds diagonal), and the triangles of uniform cuts. Reads
    /// and verifies every page: a damaged file exits 2.
    Inspect(InspectArgs),
    /// Write a cut of the DAG as an OBJ mesh: the uniform cut at object-space error E, or the
    /// view-dependent cut seen from a camera at a pixel threshold. Materials are named by the
    /// scene file beside the .mres (NAME.scene.json), if there is one.
    Export(ExportArgs),
    /// Bake INPUT with mres and with meshoptimizer's clusterlod (each in its own child process)
    /// and compare time, peak memory and quality: the triangles each needs at equal measured
    /// distance to the input (mean and max, over uniform cuts; docs/BENCHMARKS.md, "Quality at
    /// equal measured error").
    Bench(BenchArgs),
    /// Store a file's pages the other way, without baking again (docs/FORMAT.md §4.3, §4.4):
    /// `--pages layout` stores each page's GPU layout in LZ4 (about twice the bytes; pages
    /// decode at memory speed, each alone), `--pages compact` predicts and zstd-codes them (the
    /// bake's default, the smallest files). Every page is read and checked first; groups,
    /// clusters, their values and the pages (the groups each holds) are unchanged, so every
    /// cut draws the same triangles. Files mres wrote keep every GPU layout, and repacking back
    /// gives their bytes; a compact file from another writer gets each cluster in the
    /// canonical layout (what layout pages require: vertices renumbered in first-use order),
    /// and pages are filled anew where its groups are not coarse to fine or a layout page is
    /// too large for a compact one (docs/FORMAT.md §4.4).
    Repack(RepackArgs),
    /// Maintain the bake cache of `bake-all`.
    Cache(CacheArgs),
    /// One builder run of `bench` (internal): prints a JSON BuilderRun.
    #[command(hide = true)]
    BenchChild(BenchChildArgs),
    /// Write a generated test mesh as OBJ.
    Generate(GenerateArgs),
}

#[derive(Args)]
struct ValidateArgs {
    /// The .mres file.
    file: PathBuf,
    /// Random view-dependent cuts to check.
    #[arg(long, default_value_t = 1000, value_name = "N")]
    random_cuts: usize,
    /// Most uniform cuts to check: every distinct group error by default (0); with N, N
    /// thresholds spread evenly over the sorted errors, the finest and coarsest included (for
    /// files of tens of millions of triangles).
    #[arg(long, default_value_t = 0, value_name = "N")]
    uniform_cuts: usize,
    /// Seed of the random cameras.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Uniform cuts the honesty check measures (thresholds at quantiles of the stored errors).
    #[arg(long, default_value_t = 6, value_name = "N")]
    honesty_cuts: usize,
    /// Points the honesty check samples per cut and direction (more: slower, a finer look at
    /// how tight each group's error is).
    #[arg(long, default_value_t = 20_000, value_name = "N")]
    honesty_samples: usize,
    /// Print the report as JSON on stdout instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct InspectArgs {
    /// The .mres file.
    file: PathBuf,
    /// Print the same summary as JSON on stdout instead of text.
    #[arg(long)]
    json: bool,
    /// Also what a renderer draws of the file at 1 px beside a discrete LOD chain of its
    /// level-0 mesh (triangles per copy over copies seen from near to far; as `mres bench`
    /// reports it). Builds and measures the chain: seconds on a million triangles.
    #[arg(long)]
    view: bool,
}

#[derive(Args)]
struct ExportArgs {
    /// The .mres file.
    file: PathBuf,
    /// Object-space error of the uniform cut (a finite number >= 0; 0 = the original
    /// geometry). `mres inspect` lists the triangles of uniform cuts per error.
    #[arg(long, value_name = "E", conflicts_with = "camera", allow_negative_numbers = true, value_parser = parse_error)]
    error: Option<f32>,
    /// Eye position "x,y,z" of a view-dependent cut (60° vertical field of view, looking at
    /// the whole file).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, requires = "tau", allow_hyphen_values = true)]
    camera: Option<[f32; 3]>,
    /// Pixel threshold of the view-dependent cut (a finite number > 0).
    #[arg(long, value_name = "PIXELS", allow_negative_numbers = true, value_parser = parse_positive)]
    tau: Option<f32>,
    /// Viewport height in pixels of the view-dependent cut (a finite number > 0).
    #[arg(long, default_value_t = 1080.0, allow_negative_numbers = true, value_parser = parse_positive)]
    height: f32,
    /// Output OBJ file.
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
}

#[derive(Args)]
struct BenchArgs {
    /// Mesh file (OBJ, glTF, GLB, PLY).
    input: PathBuf,
    /// Runs per builder; the minimum time and RSS are reported.
    #[arg(long, default_value_t = 1, value_name = "N")]
    repeat: usize,
    /// Bake settings from this pipeline.toml's [bake] table (default: the compiled-in ones),
    /// e.g. to compare `error_bound` modes.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Also write both builders' figures as JSON to FILE: timings, memory, every cut's
    /// measured distances and the comparison at equal measured error.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Points sampled per direction and cut for the quality measure (triangle centroids and
    /// edge midpoints, thinned by an even stride); 0 skips the quality measure.
    #[arg(long, default_value_t = bench::DEFAULT_SAMPLES, value_name = "N")]
    samples: usize,
}

#[derive(Args)]
struct RepackArgs {
    /// The .mres file.
    file: PathBuf,
    /// How the output stores its pages.
    #[arg(long, value_enum, value_name = "ENCODING")]
    pages: PagesArg,
    /// zstd level of compact pages (1..=22; pipeline.toml's `zstd_level`).
    #[arg(long, default_value_t = 9, value_parser = clap::value_parser!(i32).range(1..=22))]
    zstd_level: i32,
    /// Output file (may be FILE itself: it is replaced whole once written).
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
}

/// `--pages` of `mres repack`.
#[derive(Clone, Copy, ValueEnum)]
enum PagesArg {
    /// Predicted and zstd-coded, decoding against the page's sources (the smallest files).
    Compact,
    /// Compact pages that each decode alone (no copies of their sources' vertices).
    Independent,
    /// The GPU layout in LZ4: decodes at memory speed, each page alone.
    Layout,
}

#[derive(Args)]
struct CacheArgs {
    #[command(subcommand)]
    action: CacheAction,
    /// Cache directory.
    #[arg(long, default_value = ".mres-cache", global = true, value_name = "DIR")]
    cache_dir: PathBuf,
    /// Print the result as JSON on stdout instead of text.
    #[arg(long, global = true)]
    json: bool,
}

#[derive(Subcommand)]
enum CacheAction {
    /// Entries, bytes and temporary files.
    Stats,
    /// Read every entry and check its header and content hash; exit 1 if any is corrupt
    /// (unless --repair removed them).
    Verify {
        /// Remove corrupt entries.
        #[arg(long)]
        repair: bool,
    },
    /// Remove stale temporary files, then least recently used entries until the cache holds at
    /// most SIZE.
    Gc {
        /// Largest total size to keep, e.g. 500M or 2G (K, M, G, T are powers of 1024).
        #[arg(long, value_parser = cache::parse_size, value_name = "SIZE")]
        max_size: u64,
    },
}

/// The builders `bench` compares.
#[derive(Clone, Copy, ValueEnum)]
enum Builder {
    /// This repository's baker.
    Mres,
    /// meshoptimizer's clusterlod.
    Clusterlod,
}

#[derive(Args)]
struct BenchChildArgs {
    /// The builder to run.
    #[arg(value_enum)]
    builder: Builder,
    /// Mesh file.
    input: PathBuf,
    /// pipeline.toml whose [bake] settings to use.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Points per direction and cut for the quality measure; 0 skips it.
    #[arg(long, default_value_t = 0)]
    samples: usize,
}

/// The generated test meshes.
#[derive(Clone, Copy, ValueEnum)]
enum MeshKind {
    /// A closed cube-sphere, 12·N² triangles, with normals.
    Sphere,
    /// An open height field, 2·N² triangles, with UVs.
    Terrain,
    /// N disconnected closed boxes of 192 triangles.
    Boxes,
    /// A sphere whose 6 faces are separate UV charts and materials (attribute seams).
    SeamedSphere,
    /// N disconnected open quads, like foliage cards.
    Cards,
    /// Sphere N with holes, duplicate triangles and non-manifold fins.
    Defects,
    /// N rooms: one-sided walls with window holes, open crates and cards (796 triangles each).
    Rooms,
    /// A floor of N × N quads with two crossing walls standing inside it: non-manifold edges
    /// where the parts meet, 4·N² triangles (N even).
    Walls,
}

#[derive(Args)]
struct GenerateArgs {
    /// Which mesh.
    #[arg(value_enum)]
    kind: MeshKind,
    /// Size parameter (see each kind).
    n: u32,
    /// Output OBJ file.
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
}

fn parse_number(s: &str) -> Result<f32, String> {
    let x: f32 = s.trim().parse().map_err(|e| format!("{s:?} is not a number: {e}"))?;
    if !x.is_finite() {
        return Err(format!("{s} is not a finite number"));
    }
    Ok(x)
}

fn parse_error(s: &str) -> Result<f32, String> {
    let e = parse_number(s)?;
    if e < 0.0 {
        return Err(format!("{s} is negative: an error is a distance in object units, >= 0"));
    }
    Ok(e)
}

fn parse_positive(s: &str) -> Result<f32, String> {
    let x = parse_number(s)?;
    if x <= 0.0 {
        return Err(format!("{s} must be > 0"));
    }
    Ok(x)
}

fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s.split(',').map(parse_number).collect::<Result<_, _>>()?;
    v.try_into().map_err(|_| format!("{s:?}: expected three numbers x,y,z"))
}

fn open(path: &Path) -> Result<MresFile> {
    MresFile::open(path).with_context(|| format!("{}", path.display()))
}

/// A file written whole or not at all: a temporary file beside `path`, created before any work
/// so that an unwritable destination fails first, renamed onto `path` by [`Output::finish`].
struct Output<'a> {
    path: &'a Path,
    tmp: tempfile::NamedTempFile,
}

impl<'a> Output<'a> {
    fn create(path: &'a Path) -> Result<Output<'a>> {
        if path.is_dir() {
            bail!("{}: is a directory", path.display());
        }
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let mut builder = tempfile::Builder::new();
        // Read/write for everyone the umask lets through (as any new file), not the temporary
        // file's owner-only default: the output is an ordinary file once renamed.
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let tmp = builder
            .prefix(".mres-output")
            .tempfile_in(dir)
            .with_context(|| format!("{}: cannot write in {}", path.display(), dir.display()))?;
        Ok(Output { path, tmp })
    }

    fn finish(self) -> Result<()> {
        let path = self.path;
        self.tmp.persist(path).with_context(|| format!("{}", path.display()))?;
        Ok(())
    }
}

fn write_obj(mesh: &SourceMesh, out: Output) -> Result<()> {
    write_obj_named(mesh, &[], out)
}

/// Writes `mesh` as OBJ, `usemtl` lines naming the materials `names` names.
fn write_obj_named(mesh: &SourceMesh, names: &[Option<String>], out: Output) -> Result<()> {
    let mut writer = std::io::BufWriter::new(out.tmp.as_file());
    mres_import::obj_write::write_obj_named(mesh, names, &mut writer)
        .with_context(|| format!("{}", out.path.display()))?;
    writer.flush().with_context(|| format!("{}", out.path.display()))?;
    drop(writer);
    out.finish()
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    mres_cli::log::init(false);
    let result = match cli.command {
        Command::Validate(a) => validate_cmd(a),
        Command::Inspect(a) => inspect_cmd(a),
        Command::Export(a) => export_cmd(a),
        Command::Bench(a) => bench_cmd(a),
        Command::Repack(a) => repack_cmd(a),
        Command::Cache(a) => cache_cmd(a),
        Command::BenchChild(a) => bench_child_cmd(a),
        Command::Generate(a) => generate_cmd(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn validate_cmd(a: ValidateArgs) -> Result<ExitCode> {
    let f = open(&a.file)?;
    let options = ValidateOptions {
        random_cuts: a.random_cuts,
        uniform_cuts: a.uniform_cuts,
        seed: a.seed,
        thresholds: Thresholds {
            honesty_cuts: a.honesty_cuts,
            honesty_samples: a.honesty_samples,
            ..Default::default()
        },
        ..Default::default()
    };
    let report = validate(&f, &options).with_context(|| format!("{}", a.file.display()))?;
    let level0 = mres_cli::batch::level0_triangles(&f);
    if a.json {
        let mut value = serde_json::to_value(&report)?;
        if let Some(object) = value.as_object_mut() {
            object.insert("input_triangles".into(), report.source_triangles.into());
            object.insert("level0_triangles".into(), level0.into());
        }
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        print_validate(&a.file, &report, level0);
    }
    Ok(if report.ok() { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

fn print_validate(file: &Path, report: &mres_check::validate::Report, level0: u64) {
    println!(
        "{}: {} bytes, {} input triangles ({} at level 0, {} degenerate or duplicate dropped), {:.2} bytes/input triangle, {} pages",
        file.display(),
        report.bytes,
        report.source_triangles,
        level0,
        report.source_triangles.saturating_sub(level0),
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
    let chain = report.levels.saturating_sub(c.depth);
    let chain = if chain > 0 { format!(" (then {chain} root-chain levels)") } else { String::new() };
    println!(
        "depth {}{chain} vs log2(level-0 clusters) {:.1} (ratio {:.2}); reduction per level {}",
        c.depth,
        c.log2_level0_clusters,
        c.depth_ratio,
        c.reduction_per_level.iter().map(|r| format!("{r:.2}")).collect::<Vec<_>>().join(" ")
    );
    println!(
        "edge age mean {:.2} max {} ({} locked original edges); same-boundary clusters {}; group sizes {:?}",
        c.edge_age_mean, c.edge_age_max, c.locked_original_edges, c.same_boundary_clusters, c.group_size_histogram
    );
    println!("edges by age (levels survived): {:?}", c.edge_age_histogram);
    let h = &report.honesty;
    println!(
        "error honesty: worst {:.2} p99 {:.2} (measured distance / stored error, {} cuts, {} points); worst at {}",
        h.worst_ratio, h.p99_ratio, h.cuts, h.samples, h.worst
    );
    println!(
        "error tightness: per group largest measured/stored, median {:.2} p10 {:.2} over {} groups",
        h.group_median_ratio, h.group_p10_ratio, h.groups_measured
    );
    for v in &report.violations {
        println!("VIOLATION {}: {v}", file.display());
    }
    println!("{}", if report.ok() { "OK" } else { "FAILED" });
}

fn inspect_cmd(a: InspectArgs) -> Result<ExitCode> {
    let f = open(&a.file)?;
    let summary = summarize(&f).with_context(|| format!("{}", a.file.display()))?;
    let view = match a.view {
        true => Some(view_cost::of_file(&f, bench::DEFAULT_SAMPLES).with_context(|| format!("{}", a.file.display()))?),
        false => None,
    };
    if a.json {
        let mut value = serde_json::to_value(&summary)?;
        if let Some(object) = value.as_object_mut() {
            object.insert("file".into(), a.file.display().to_string().into());
            if let Some(v) = &view {
                object.insert("view".into(), serde_json::to_value(v)?);
            }
        }
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        println!("{}", a.file.display());
        print!("{}", summary.render());
        if let Some(v) = &view {
            print_view(v);
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn export_cmd(a: ExportArgs) -> Result<ExitCode> {
    let out = Output::create(&a.output)?;
    let f = open(&a.file)?;
    let cut = match (a.error, a.camera, a.tau) {
        (Some(e), None, _) => select::uniform_cut(&f.groups, &f.clusters, e),
        (None, Some(eye), Some(tau)) => {
            let radius = f.groups.first().map_or(1.0, |g| g.sphere.radius);
            let view = select::ViewParams {
                eye,
                proj_y: 1.0 / 30f32.to_radians().tan(),
                viewport_height: a.height,
                z_near: radius * 1e-3,
            };
            select::view_cut(&f.groups, &f.clusters, &view, tau)
        }
        _ => bail!("give --error E, or --camera x,y,z with --tau T"),
    };
    let mesh = mres_cli::export::cut_mesh(&f, &cut).with_context(|| format!("{}", a.file.display()))?;
    let names = mres_cli::export::material_names_for(&a.file)?;
    write_obj_named(&mesh, &names, out)?;
    eprintln!("{}: {} clusters, {} triangles", a.output.display(), cut.len(), mesh.triangle_count());
    Ok(ExitCode::SUCCESS)
}

fn repack_cmd(a: RepackArgs) -> Result<ExitCode> {
    use mres_format::PageCoding;
    let out = Output::create(&a.output)?;
    let f = open(&a.file)?;
    let coding = match a.pages {
        PagesArg::Compact => PageCoding::FarCopies,
        PagesArg::Independent => PageCoding::Independent,
        PagesArg::Layout => PageCoding::Layout,
    };
    let bytes = mres_format::rewrite(&f, a.zstd_level, coding).with_context(|| format!("{}", a.file.display()))?;
    std::fs::write(out.tmp.path(), &bytes).with_context(|| format!("{}", a.output.display()))?;
    out.finish()?;
    eprintln!(
        "{}: {} pages, {} -> {} bytes ({:.2} B per input triangle)",
        a.output.display(),
        f.pages.len(),
        f.file_size(),
        bytes.len(),
        bytes.len() as f64 / f.header.source_triangles.max(1) as f64
    );
    Ok(ExitCode::SUCCESS)
}

fn generate_cmd(a: GenerateArgs) -> Result<ExitCode> {
    use mres_cli::generate;
    let out = Output::create(&a.output)?;
    let mesh = match a.kind {
        MeshKind::Sphere => generate::sphere(a.n),
        MeshKind::Terrain => generate::terrain(a.n),
        MeshKind::Boxes => generate::boxes(a.n, 4),
        MeshKind::SeamedSphere => generate::seamed_sphere(a.n),
        MeshKind::Cards => generate::cards(a.n),
        MeshKind::Defects => generate::defects(a.n),
        MeshKind::Rooms => generate::rooms(a.n),
        MeshKind::Walls => generate::walls(a.n),
    };
    let triangles = mesh.triangle_count();
    write_obj(&mesh, out)?;
    eprintln!("{}: {triangles} triangles", a.output.display());
    Ok(ExitCode::SUCCESS)
}

fn cache_cmd(a: CacheArgs) -> Result<ExitCode> {
    let dir = &a.cache_dir;
    let disk = cache::LocalDisk::open(dir).with_context(|| format!("cache {}", dir.display()))?;
    let (value, text, code) = match a.action {
        CacheAction::Stats => {
            let s = disk.stats()?;
            let value = serde_json::json!({ "entries": s.entries, "bytes": s.bytes, "temp_files": s.temp_files });
            let text = format!(
                "{}: {} entries, {} bytes, {} temporary files",
                dir.display(),
                s.entries,
                s.bytes,
                s.temp_files
            );
            (value, text, ExitCode::SUCCESS)
        }
        CacheAction::Verify { repair } => {
            let r = disk.verify(repair)?;
            let corrupt: Vec<_> = r
                .corrupt
                .iter()
                .map(|c| serde_json::json!({ "path": c.path, "problem": c.problem.to_string(), "removed": c.removed }))
                .collect();
            let value = serde_json::json!({
                "checked": r.checked, "valid": r.valid, "valid_bytes": r.valid_bytes, "corrupt": corrupt,
            });
            let mut text = format!(
                "{}: {} entries checked, {} valid ({} bytes), {} corrupt",
                dir.display(),
                r.checked,
                r.valid,
                r.valid_bytes,
                r.corrupt.len()
            );
            for c in &r.corrupt {
                let removed = if c.removed { " (removed)" } else { "" };
                text.push_str(&format!("\ncorrupt: {}: {}{removed}", c.path.display(), c.problem));
            }
            let code = if !r.is_clean() && !repair { ExitCode::from(1) } else { ExitCode::SUCCESS };
            (value, text, code)
        }
        CacheAction::Gc { max_size } => {
            let r = disk.gc(max_size)?;
            let value = serde_json::json!({
                "entries_removed": r.entries_removed, "bytes_removed": r.bytes_removed,
                "temp_removed": r.temp_removed, "temp_bytes_removed": r.temp_bytes_removed,
                "entries_kept": r.entries_kept, "bytes_kept": r.bytes_kept,
            });
            let text = format!(
                "{}: removed {} entries ({} bytes) and {} temporary files; kept {} entries ({} bytes)",
                dir.display(),
                r.entries_removed,
                r.bytes_removed,
                r.temp_removed,
                r.entries_kept,
                r.bytes_kept
            );
            (value, text, ExitCode::SUCCESS)
        }
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        println!("{text}");
    }
    Ok(code)
}

fn bench_child_cmd(a: BenchChildArgs) -> Result<ExitCode> {
    let settings = match &a.config {
        Some(path) => mres_cli::config::PipelineConfig::load(path).map_err(anyhow::Error::msg)?.bake,
        None => BakeSettings::default(),
    };
    let import = || mres_import::import_file(&a.input, &Default::default());
    let built = match a.builder {
        Builder::Mres => run_mres(import()?, &settings)?,
        Builder::Clusterlod => run_clusterlod(import()?, &settings)?,
    };
    let run = if a.samples == 0 {
        built.run
    } else {
        // Imported again after the build so that the reference surface stays out of the
        // builder's peak RSS (read before this).
        let input = mres_check::distance::Surface::new(bench::triangles(&import()?));
        let file = built.file.clone();
        let mut run = measure(built, &input, a.samples);
        if let Some(file) = file {
            run.view = Some(view_cost::of_file(&file, a.samples)?);
        }
        run
    };
    println!("{}", serde_json::to_string(&run)?);
    Ok(ExitCode::SUCCESS)
}

/// Runs `builder` `repeat` times in child processes and keeps the minimum time and RSS; the
/// first run also measures quality (it does not depend on the run).
fn bench_builder(builder: Builder, a: &BenchArgs) -> Result<BuilderRun> {
    let exe = std::env::current_exe()?;
    let name = builder.to_possible_value().map(|v| v.get_name().to_owned()).unwrap_or_default();
    let mut runs = Vec::new();
    for i in 0..a.repeat.max(1) {
        let mut child = std::process::Command::new(&exe);
        child.args(["bench-child", &name]).arg(&a.input);
        child.arg("--samples").arg(if i == 0 { a.samples } else { 0 }.to_string());
        if let Some(path) = &a.config {
            child.arg("--config").arg(path);
        }
        let out = child.output()?;
        if !out.status.success() {
            bail!("{name} on {}: {}", a.input.display(), String::from_utf8_lossy(&out.stderr).trim());
        }
        // The child's log (RUST_LOG), if any, after its run.
        std::io::stderr().write_all(&out.stderr)?;
        runs.push(serde_json::from_slice::<BuilderRun>(&out.stdout)?);
    }
    let min = |f: fn(&BuilderRun) -> f64| runs.iter().map(f).fold(f64::INFINITY, f64::min);
    let (seconds, dag_seconds) = (min(|r| r.seconds), min(|r| r.dag_seconds));
    let peak_rss_bytes = runs.iter().map(|r| r.peak_rss_bytes).min().unwrap_or(0);
    let first = runs.swap_remove(0);
    Ok(BuilderRun { seconds, dag_seconds, peak_rss_bytes, ..first })
}

fn bench_cmd(a: BenchArgs) -> Result<ExitCode> {
    let report = match &a.report {
        Some(path) => Some(Output::create(path)?),
        None => None,
    };
    let runs = [bench_builder(Builder::Mres, &a)?, bench_builder(Builder::Clusterlod, &a)?];
    let quality = compare(&runs[0], &runs[1]);
    let result = Report { input: a.input.display().to_string(), runs, quality };
    print_bench(&a, &result);
    if let Some(out) = report {
        serde_json::to_writer_pretty(out.tmp.as_file(), &result).with_context(|| format!("{}", out.path.display()))?;
        out.finish()?;
    }
    Ok(ExitCode::SUCCESS)
}

fn print_bench(a: &BenchArgs, r: &Report) {
    let best = &r.runs;
    println!(
        "{} ({} input triangles, {} degenerate or duplicate dropped on import), min over {} run(s)",
        a.input.display(),
        best[0].input_triangles,
        best[1].degenerate_dropped,
        a.repeat.max(1)
    );
    println!(
        "{:<11} {:>8} {:>8} {:>10} {:>9} {:>6} {:>6} {:>6} {:>11}",
        "builder", "total s", "DAG s", "peak MiB", "RSS B/tri", "levels", "roots", "fill", "level-0 tri"
    );
    for r in best {
        println!(
            "{:<11} {:>8.3} {:>8.3} {:>10.1} {:>9.1} {:>6} {:>6} {:>6.1} {:>11}{}",
            r.builder,
            r.seconds,
            r.dag_seconds,
            r.peak_rss_bytes as f64 / 1048576.0,
            r.peak_rss_bytes as f64 / r.input_triangles.max(1) as f64,
            r.levels,
            r.root_clusters,
            r.level0_fill,
            r.level0_triangles,
            if r.bytes > 0 {
                format!(
                    "  file {:.2} B/input tri, pages decode at {:.0} MB/s of GPU layout (1 thread); \
                     as layout pages {:.2} B/input tri at {:.0} MB/s",
                    r.bytes as f64 / r.input_triangles.max(1) as f64,
                    r.decode_mb_per_s,
                    r.layout_bytes as f64 / r.input_triangles.max(1) as f64,
                    r.layout_decode_mb_per_s
                )
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
    if a.samples > 0 {
        print_quality(a, r);
    }
    if let Some(v) = &r.runs[0].view {
        print_view(v);
    }
}

/// What a renderer draws of our file beside the LOD chain.
fn print_view(v: &view_cost::ViewCost) {
    use view_cost::{FOV_Y_DEGREES, HEIGHT_PX, RANGE_RADII, TAU_PX};
    println!(
        "\nview cost at {TAU_PX} px ({HEIGHT_PX} px high, {FOV_Y_DEGREES} degree fov; copies {}-{} radii away, \
         weighted as on a ground grid; selection by stored errors): mres {:.0} triangles per copy, \
         LOD chain {:.0} ({} levels, measured errors): ratio {:.3}; full detail {}",
        RANGE_RADII.0,
        RANGE_RADII.1,
        v.dag_triangles,
        v.chain_triangles,
        v.chain_errors.len(),
        v.ratio(),
        v.full_triangles
    );
}

/// The triangles both builders need at equal measured error, per measure.
fn print_quality(a: &BenchArgs, r: &Report) {
    println!(
        "\nquality at equal measured error: {} uniform cuts per builder, each measured against the input \
         (distance / bounding-box diagonal; triangle centroids and edge midpoints, at most {} per direction, \
         even stride; {:.1} s and {:.1} s to measure)",
        r.runs[0].cuts.len(),
        a.samples,
        r.runs[0].measure_seconds,
        r.runs[1].measure_seconds
    );
    let count = |v: &Option<f64>| v.map_or("-".to_owned(), |n| format!("{n:.0}"));
    let ratio = |v: &Option<f64>| v.map_or("-".to_owned(), |n| format!("{n:.3}"));
    println!(
        "{:>8}  {:>10} {:>10} {:>6}   {:>10} {:>10} {:>6}",
        "error", "mean: mres", "clusterlod", "ratio", "max: mres", "clusterlod", "ratio"
    );
    let q = &r.quality;
    for (i, t) in q.targets.iter().enumerate() {
        println!(
            "{:>8.0e}  {:>10} {:>10} {:>6}   {:>10} {:>10} {:>6}",
            t,
            count(&q.mean.mres[i]),
            count(&q.mean.clusterlod[i]),
            ratio(&q.mean.ratio[i]),
            count(&q.max.mres[i]),
            count(&q.max.clusterlod[i]),
            ratio(&q.max.ratio[i])
        );
    }
    for (name, v) in [("mean", &q.mean), ("max", &q.max)] {
        println!(
            "triangles mres/clusterlod at equal {name} error: geomean {} over {} target(s), worst {} at {}",
            ratio(&v.geomean_ratio),
            v.compared,
            ratio(&v.worst_ratio),
            v.worst_target.map_or("-".to_owned(), |t| format!("{t:.0e}"))
        );
    }
}
