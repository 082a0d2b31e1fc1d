//! Bench: our builder and meshoptimizer's clusterlod (`meshopt::clusterlod::clod_build`) on the
//! same input, each run by `mres bench` in its own child process so that peak RSS is per
//! builder.
//!
//! Quality is compared at equal *measured* error, never at equal stored error (ours are
//! bounds, clusterlod's estimates, so equal stored numbers mean different surfaces). Each
//! builder's DAG is cut uniformly at [`relative_thresholds`] × the bounding-box diagonal and at
//! its coarsest cut; every cut's two-sided distance to the input mesh is measured with
//! [`mres_check::distance`]. From those (measured error, triangles) points, [`compare`]
//! reads off the triangles each builder needs at [`TARGET_ERRORS`].

use meshopt::clusterlod::{clod_build, clod_default_config, ClodMesh};
use mres_build::bake::bake;
use mres_build::settings::BakeSettings;
use mres_check::distance::{two_sided_with, Distance, Surface, Triangle};
use mres_format::{rewrite, select, MresFile, PageCoding, FLAG_LAYOUT_PAGES, NO_GROUP};
use mres_import::SourceMesh;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Default bound on the points sampled per direction and cut (centroids and edge midpoints,
/// thinned by an even stride), so that big meshes stay affordable.
pub const DEFAULT_SAMPLES: usize = 200_000;

/// Measured errors (× diagonal) at which the builders' triangle counts are compared.
pub const TARGET_ERRORS: [f64; 5] = [1e-4, 3e-4, 1e-3, 3e-3, 1e-2];

/// Measured errors (× diagonal) below this count as exact in [`triangles_at`]: a tenth of the
/// finest target. The full-detail cut measures about 1e-16 (rounding) for clusterlod and up to
/// about 1e-5 for us (the 16-bit position grid); neither is a point of the error-triangles
/// curve, and taken as one, log-log interpolation from it jumps to almost the next cut's count.
pub const EXACT_BELOW: f64 = 1e-5;

/// Uniform-cut thresholds (× diagonal) every builder is cut at: 0 (the finest cut) and 24
/// log-spaced values from 1e-5 to 1e-1. The coarsest cut is added per builder.
pub fn relative_thresholds() -> Vec<f64> {
    let steps = 24;
    std::iter::once(0.0).chain((0..steps).map(|i| 10f64.powf(-5.0 + 4.0 * i as f64 / (steps - 1) as f64))).collect()
}

/// One uniform cut of a builder's DAG and its measured distance to the input.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct CutPoint {
    /// Stored-error threshold of the cut (× diagonal).
    pub threshold: f64,
    /// Whether this is the coarsest cut (the top groups' clusters).
    pub coarsest: bool,
    /// Triangles drawn.
    pub triangles: u64,
    /// Two-sided distance to the input (× diagonal).
    pub distance: Distance,
}

/// What one builder run measured.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct BuilderRun {
    /// "mres" or "clusterlod".
    pub builder: String,
    /// Seconds to build (ours: weld + DAG + compressed file; clusterlod: clod_build).
    pub seconds: f64,
    /// Seconds to build the DAG in memory, the part comparable to clod_build (ours: weld + DAG,
    /// without encoding and compressing the file; clusterlod: the same as `seconds`).
    #[serde(default)]
    pub dag_seconds: f64,
    /// Peak resident set of the whole child process (import and build; read before the
    /// quality measurement), bytes.
    pub peak_rss_bytes: u64,
    /// Input triangles: the source's triangles after triangulation, before degenerate ones
    /// are dropped (what a bake's `.mres` header calls `source_triangles`).
    pub input_triangles: u64,
    /// Triangles of the builder's level 0 (for ours the welded source, without degenerates).
    #[serde(default)]
    pub level0_triangles: u64,
    /// Input triangles dropped as degenerate: `input_triangles - level0_triangles`.
    #[serde(default)]
    pub degenerate_dropped: u64,
    /// DAG levels.
    pub levels: u32,
    /// Clusters in the top (infinite-error) groups.
    pub root_clusters: u64,
    /// Mean triangles per level-0 cluster.
    pub level0_fill: f64,
    /// Size of the `.mres` file (ours only).
    pub bytes: u64,
    /// Page decoding speed (ours only): MB (10^6 bytes) of GPU layout (docs/FORMAT.md §5) per
    /// second, decoding every page of the file on one thread, best of three passes.
    #[serde(default)]
    pub decode_mb_per_s: f64,
    /// The same file with layout pages (docs/FORMAT.md §4.4, `mres repack --pages layout`;
    /// the file itself if it has them): its size, and its decoding speed measured as
    /// `decode_mb_per_s` is.
    #[serde(default)]
    pub layout_bytes: u64,
    /// See `layout_bytes`.
    #[serde(default)]
    pub layout_decode_mb_per_s: f64,
    /// Bounding-box diagonal of the input, the unit of every relative figure.
    #[serde(default)]
    pub diagonal: f64,
    /// Bound on the points sampled per direction and cut (0: quality not measured).
    #[serde(default)]
    pub samples_per_direction: u64,
    /// Seconds the quality measurement took (not part of `seconds`).
    #[serde(default)]
    pub measure_seconds: f64,
    /// The uniform cuts and their measured distances, finest first.
    #[serde(default)]
    pub cuts: Vec<CutPoint>,
    /// What a renderer draws of our file at 1 px beside the LOD chain ([`crate::view_cost`];
    /// ours only, with the quality measure).
    #[serde(default)]
    pub view: Option<crate::view_cost::ViewCost>,
}

/// A built DAG that can be cut: the run's figures, the largest finite stored error, and the
/// triangles of the uniform cut at an object-space threshold.
pub struct Built {
    /// The figures so far (no cuts yet).
    pub run: BuilderRun,
    /// The largest finite stored group error: the threshold of the coarsest cut.
    pub coarsest: f32,
    /// Triangles of the uniform cut at a threshold.
    pub cut: Box<dyn Fn(f32) -> Vec<Triangle<f64>>>,
    /// The baked file (ours only), for [`crate::view_cost::of_file`].
    pub file: Option<std::rc::Rc<MresFile>>,
}

/// Peak RSS of this process (`VmHWM`), bytes.
pub fn peak_rss() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map_or(0, |kb| kb * 1024)
}

/// Bounding-box diagonal of `mesh`'s positions (0 for an empty mesh).
pub fn diagonal(mesh: &SourceMesh) -> f64 {
    mesh.bounds().map_or(0.0, |(lo, hi)| (0..3).map(|k| (hi[k] as f64 - lo[k] as f64).powi(2)).sum::<f64>().sqrt())
}

/// `mesh`'s triangles as corner positions: the surface every cut is measured against.
pub fn triangles(mesh: &SourceMesh) -> Vec<Triangle<f64>> {
    let p = |i: u32| mesh.positions[i as usize].map(f64::from);
    mesh.indices.chunks_exact(3).map(|t| [p(t[0]), p(t[1]), p(t[2])]).collect()
}

/// Runs our builder.
pub fn run_mres(mesh: SourceMesh, settings: &BakeSettings) -> anyhow::Result<Built> {
    let input_triangles = mesh.triangle_count() as u64 + mesh.degenerate_dropped;
    let diagonal = diagonal(&mesh);
    let start = Instant::now();
    let baked = bake(mesh, settings, &|_| {})?;
    let seconds = start.elapsed().as_secs_f64();
    let dag_seconds =
        baked.stats.build.stage_seconds.iter().filter(|(s, _)| s != "write" && s != "encode").map(|(_, t)| t).sum();
    let file = MresFile::parse(baked.bytes)?;
    // The bake's peak, before the repacking below.
    let peak_rss_bytes = peak_rss();
    let layout = match file.header.flags & FLAG_LAYOUT_PAGES {
        0 => MresFile::parse(rewrite(&file, settings.zstd_level, PageCoding::Layout)?)?,
        _ => MresFile::parse(file.bytes().to_vec())?,
    };
    let level0: Vec<_> = file.clusters.iter().filter(|c| c.own_group == NO_GROUP).collect();
    let level0_triangles = crate::batch::level0_triangles(&file);
    let run = BuilderRun {
        builder: "mres".into(),
        seconds,
        dag_seconds,
        peak_rss_bytes,
        input_triangles,
        level0_triangles,
        degenerate_dropped: input_triangles.saturating_sub(level0_triangles),
        levels: file.header.level_count,
        root_clusters: baked.stats.build.root_clusters,
        level0_fill: level0.iter().map(|c| c.triangle_count as f64).sum::<f64>() / level0.len().max(1) as f64,
        bytes: file.file_size() as u64,
        decode_mb_per_s: decode_speed(&file)?,
        layout_bytes: layout.file_size() as u64,
        layout_decode_mb_per_s: decode_speed(&layout)?,
        diagonal,
        ..Default::default()
    };
    let coarsest = file.groups.iter().map(|g| g.error).filter(|e| e.is_finite()).fold(0.0, f32::max);
    let decoded = file.decode_all()?;
    let file = std::rc::Rc::new(file);
    let kept = Some(file.clone());
    let cut = move |t: f32| {
        let mut tris = Vec::new();
        for c in select::uniform_cut(&file.groups, &file.clusters, t) {
            let d = &decoded[c as usize];
            let p: Vec<[f64; 3]> = d.positions.iter().map(|q| file.header.grid.decode(*q).map(f64::from)).collect();
            tris.extend(d.indices.chunks_exact(3).map(|t| [p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]]));
        }
        tris
    };
    Ok(Built { run, coarsest, cut: Box::new(cut), file: kept })
}

/// MB of GPU layout per second decoding every page of `file` ([`MresFile::page`]: checksum,
/// zstd, page decoding, each page's sources first) on this thread, best of three passes; each
/// pass on a fresh copy, as `MresFile` keeps the pages that are sources once decoded.
fn decode_speed(file: &MresFile) -> anyhow::Result<f64> {
    let mut best = f64::INFINITY;
    let mut bytes = 0usize;
    for _ in 0..3 {
        let fresh = MresFile::parse(file.bytes().to_vec())?;
        let start = Instant::now();
        bytes = 0;
        for p in 0..fresh.pages.len() as u32 {
            bytes += fresh.page(p)?.len();
        }
        best = best.min(start.elapsed().as_secs_f64());
    }
    Ok(bytes as f64 / 1e6 / best.max(1e-9))
}

/// clusterlod's DAG as the bench keeps it: per group (depth, error), per cluster (group,
/// refined group or -1, range of `indices`).
struct ClodDag {
    groups: Vec<(i32, f32)>,
    clusters: Vec<(usize, i32, std::ops::Range<usize>)>,
    indices: Vec<u32>,
}

impl ClodDag {
    /// A cluster's own error: that of the group it was simplified from (0 at level 0).
    fn own(&self, refined: i32) -> f32 {
        usize::try_from(refined).map_or(0.0, |g| self.groups[g].1)
    }

    /// Clusters of the uniform cut at `t`: drawn iff own error ≤ t < their group's error, the
    /// rule `select::uniform_cut` applies to ours.
    fn cut(&self, t: f32) -> impl Iterator<Item = &(usize, i32, std::ops::Range<usize>)> {
        self.clusters.iter().filter(move |(g, refined, _)| self.own(*refined) <= t && t < self.groups[*g].1)
    }
}

/// Runs clusterlod with its default configuration for 128-triangle clusters, with the same
/// attribute weights we use (normals and UVs when present).
pub fn run_clusterlod(mesh: SourceMesh, settings: &BakeSettings) -> anyhow::Result<Built> {
    let input_triangles = mesh.triangle_count() as u64 + mesh.degenerate_dropped;
    let diagonal = diagonal(&mesh);
    let start = Instant::now();
    let bytes = meshopt::typed_to_bytes(&mesh.positions);
    let adapter = meshopt::VertexDataAdapter::new(bytes, 12, 0)?;
    let mut attributes = Vec::new();
    let mut weights = Vec::new();
    if let Some(n) = &mesh.normals {
        weights.extend_from_slice(&[settings.normal_weight; 3]);
        attributes.push(n.iter().map(|v| v.to_vec()).collect::<Vec<_>>());
    }
    if let Some(uv) = &mesh.uvs {
        weights.extend_from_slice(&[settings.uv_weight; 2]);
        attributes.push(uv.iter().map(|v| v.to_vec()).collect::<Vec<_>>());
    }
    let rows: Vec<f32> =
        (0..mesh.positions.len()).flat_map(|v| attributes.iter().flat_map(move |a| a[v].clone())).collect();
    drop(attributes);
    let mut clod_mesh = ClodMesh::new(&mesh.indices, &adapter);
    if !weights.is_empty() {
        clod_mesh.vertex_attributes = &rows;
        clod_mesh.vertex_attributes_stride = weights.len() * 4;
        clod_mesh.attribute_weights = &weights;
    }
    let config = clod_default_config(settings.max_triangles as usize);
    // The clusters' indices are kept (the builder's output, as ours keeps its file) so that
    // cuts can be measured.
    let mut dag = ClodDag { groups: Vec::new(), clusters: Vec::new(), indices: Vec::new() };
    clod_build(config, &clod_mesh, |group, out| {
        let id = dag.groups.len();
        dag.groups.push((group.depth, group.simplified.error));
        for c in out {
            let start = dag.indices.len();
            dag.indices.extend_from_slice(c.indices);
            dag.clusters.push((id, c.refined, start..dag.indices.len()));
        }
        id as i32
    });
    let seconds = start.elapsed().as_secs_f64();
    let tris = |r: &std::ops::Range<usize>| (r.len() / 3) as u64;
    let level0: Vec<_> = dag.clusters.iter().filter(|c| c.1 < 0).collect();
    let level0_triangles = level0.iter().map(|c| tris(&c.2)).sum::<u64>();
    let run = BuilderRun {
        builder: "clusterlod".into(),
        seconds,
        dag_seconds: seconds,
        peak_rss_bytes: peak_rss(),
        input_triangles,
        level0_triangles,
        degenerate_dropped: input_triangles.saturating_sub(level0_triangles),
        levels: dag.groups.iter().map(|g| g.0 + 1).max().unwrap_or(0) as u32,
        root_clusters: dag.clusters.iter().filter(|c| dag.groups[c.0].1 == f32::MAX).count() as u64,
        level0_fill: level0.iter().map(|c| tris(&c.2) as f64).sum::<f64>() / level0.len().max(1) as f64,
        bytes: 0,
        diagonal,
        ..Default::default()
    };
    // clusterlod marks the top groups with f32::MAX, not infinity.
    let coarsest = dag.groups.iter().map(|g| g.1).filter(|e| *e < f32::MAX).fold(0.0, f32::max);
    let positions = mesh.positions;
    let cut = move |t: f32| {
        let p = |i: u32| positions[i as usize].map(f64::from);
        dag.cut(t).flat_map(|c| dag.indices[c.2.clone()].chunks_exact(3).map(|t| [p(t[0]), p(t[1]), p(t[2])])).collect()
    };
    Ok(Built { run, coarsest, cut: Box::new(cut), file: None })
}

/// Cuts `built` at [`relative_thresholds`] and at its coarsest cut, and measures each cut
/// against `input` (the input mesh) with at most `max_samples` points per
/// direction. Fills `run.cuts`, `samples_per_direction` and `measure_seconds`.
pub fn measure(built: Built, input: &Surface, max_samples: usize) -> BuilderRun {
    let start = Instant::now();
    let mut run = built.run;
    let diag = run.diagonal;
    let mut thresholds: Vec<(f64, bool)> = relative_thresholds().into_iter().map(|t| (t, false)).collect();
    if diag > 0.0 {
        thresholds.push((built.coarsest as f64 / diag, true));
    }
    for (t, coarsest) in thresholds {
        let tris = (built.cut)((t * diag) as f32);
        if tris.is_empty() {
            continue;
        }
        let distance = two_sided_with(&tris, input, max_samples).scaled(diag);
        run.cuts.push(CutPoint { threshold: t, coarsest, triangles: tris.len() as u64, distance });
    }
    run.samples_per_direction = max_samples as u64;
    run.measure_seconds = start.elapsed().as_secs_f64();
    run
}

/// The triangles a builder needs to reach measured error `target`, from its (measured
/// error, triangles) cut points: on the lower envelope of the points (sorted by error, each
/// kept only if it has fewer triangles than every finer one), interpolated log-log between
/// the two envelope points that bracket `target` — the count of the finer one where its
/// error is below [`EXACT_BELOW`] (an exact cut: no curve to follow from it). `None` where no
/// cut is that accurate; the coarsest envelope point's count beyond the coarsest cut. Monotone: never more triangles for a larger target.
pub fn triangles_at(points: &[(f64, u64)], target: f64) -> Option<f64> {
    let mut sorted: Vec<(f64, u64)> = points.iter().copied().filter(|p| p.0.is_finite()).collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut envelope: Vec<(f64, u64)> = Vec::new();
    for p in sorted {
        if envelope.last().is_none_or(|last| p.1 < last.1) {
            envelope.push(p);
        }
    }
    let i = envelope.iter().rposition(|p| p.0 <= target)?;
    let (e0, t0) = envelope[i];
    let Some(&(e1, t1)) = envelope.get(i + 1) else { return Some(t0 as f64) };
    if e0 < EXACT_BELOW || t1 == 0 || target == e0 {
        return Some(t0 as f64);
    }
    let f = (target.ln() - e0.ln()) / (e1.ln() - e0.ln());
    Some(((t0 as f64).ln() + f * ((t1 as f64).ln() - (t0 as f64).ln())).exp())
}

/// The two builders side by side for one measure (mean or max distance).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Versus {
    /// Our triangles at each target error (None: no cut reaches it).
    pub mres: Vec<Option<f64>>,
    /// clusterlod's triangles at each target error.
    pub clusterlod: Vec<Option<f64>>,
    /// mres / clusterlod at each target both reach (below 1: we need fewer triangles).
    pub ratio: Vec<Option<f64>>,
    /// Geometric mean of the ratios over the targets both reach.
    pub geomean_ratio: Option<f64>,
    /// The largest ratio (our worst point) and its target error.
    pub worst_ratio: Option<f64>,
    /// Target error (× diagonal) of `worst_ratio`.
    pub worst_target: Option<f64>,
    /// Targets both builders reach.
    pub compared: usize,
}

/// The quality comparison at equal measured error.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Quality {
    /// Target measured errors (× diagonal).
    pub targets: Vec<f64>,
    /// At equal mean distance (the mean of the two directions' means).
    pub mean: Versus,
    /// At equal max distance (the sampled two-sided Hausdorff distance).
    pub max: Versus,
}

/// Compares `mres` and `clusterlod` at [`TARGET_ERRORS`].
pub fn compare(mres: &BuilderRun, clusterlod: &BuilderRun) -> Quality {
    let side = |measure: fn(&Distance) -> f64| {
        let at = |r: &BuilderRun| {
            let points: Vec<(f64, u64)> = r.cuts.iter().map(|c| (measure(&c.distance), c.triangles)).collect();
            TARGET_ERRORS.iter().map(|&t| triangles_at(&points, t)).collect::<Vec<_>>()
        };
        let (ours, theirs) = (at(mres), at(clusterlod));
        let ratio: Vec<Option<f64>> = ours
            .iter()
            .zip(&theirs)
            .map(|(a, b)| match (a, b) {
                (Some(a), Some(b)) if *b > 0.0 => Some(a / b),
                _ => None,
            })
            .collect();
        let both: Vec<(f64, f64)> = ratio.iter().zip(TARGET_ERRORS).filter_map(|(r, t)| r.map(|r| (r, t))).collect();
        let worst = both.iter().copied().max_by(|a, b| a.0.total_cmp(&b.0));
        Versus {
            geomean_ratio: (!both.is_empty())
                .then(|| (both.iter().map(|r| r.0.ln()).sum::<f64>() / both.len() as f64).exp()),
            worst_ratio: worst.map(|w| w.0),
            worst_target: worst.map(|w| w.1),
            compared: both.len(),
            mres: ours,
            clusterlod: theirs,
            ratio,
        }
    };
    Quality { targets: TARGET_ERRORS.to_vec(), mean: side(|d| d.mean), max: side(|d| d.max) }
}

/// Everything `mres bench` measured, as `--report` writes it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Report {
    /// The input file, as given.
    pub input: String,
    /// Our run, then clusterlod's.
    pub runs: [BuilderRun; 2],
    /// The comparison at equal measured error.
    pub quality: Quality,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangles_at_reads_the_lower_envelope() {
        // (error, triangles); (2e-3, 900) is dominated by (1e-3, 500).
        let points = [(0.0, 1000), (1e-3, 500), (2e-3, 900), (1e-2, 50)];
        assert_eq!(triangles_at(&points, -1.0), None);
        assert_eq!(triangles_at(&points, 0.0), Some(1000.0));
        // Between an exact cut and the next: the exact cut's count.
        assert_eq!(triangles_at(&points, 5e-4), Some(1000.0));
        // Also where "exact" is rounding noise or the position grid (below EXACT_BELOW).
        for exact in [7.6e-17, 7.3e-6] {
            let noisy = [(exact, 1000), (1e-3, 500)];
            assert_eq!(triangles_at(&noisy, 1e-4), Some(1000.0), "{exact}");
        }
        assert_eq!(triangles_at(&points, 1e-3), Some(500.0));
        // Halfway in log error between 1e-3 and 1e-2: the geometric mean of 500 and 50.
        let mid = triangles_at(&points, 10f64.powf(-2.5)).unwrap();
        assert!((mid - (500.0f64 * 50.0).sqrt()).abs() < 1e-6, "{mid}");
        assert_eq!(triangles_at(&points, 1.0), Some(50.0));
        assert_eq!(triangles_at(&[(1e-3, 10)], 1e-4), None);
        // Monotone over a sweep.
        let sweep: Vec<f64> = (0..100).filter_map(|i| triangles_at(&points, 1e-4 * 1.1f64.powi(i))).collect();
        assert!(sweep.windows(2).all(|w| w[1] <= w[0]), "{sweep:?}");
    }

    #[test]
    fn compare_takes_ratios_where_both_reach() {
        let run = |cuts: &[(f64, u64)]| BuilderRun {
            cuts: cuts
                .iter()
                .map(|&(e, n)| CutPoint {
                    triangles: n,
                    distance: Distance { mean: e, max: 2.0 * e, ..Default::default() },
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        };
        // Ours needs half the triangles at every error; clusterlod's finest cut is at 1e-3.
        let ours = run(&[(0.0, 2000), (1e-4, 1000), (1e-2, 10)]);
        let theirs = run(&[(1e-3, 2000), (1e-2, 20)]);
        let q = compare(&ours, &theirs);
        assert_eq!(q.mean.ratio[0], None, "clusterlod does not reach 1e-4");
        assert_eq!(q.mean.compared, 3);
        assert!((q.mean.ratio[4].unwrap() - 0.5).abs() < 1e-12, "{q:?}");
        assert!(q.mean.geomean_ratio.is_some_and(|g| g > 0.0 && g <= q.mean.worst_ratio.unwrap()));
        // Max is twice the mean here: fewer targets reached.
        assert_eq!(q.max.compared, 2);
    }
}
