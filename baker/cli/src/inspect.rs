//! `mres inspect`: what a `.mres` file holds, read in full (every page's checksum verified and
//! every cluster decoded), summarised to help choose a cut: per level its groups, clusters,
//! triangles and group errors, and the triangles of uniform cuts at fractions of the bounds.

use crate::batch::level0_triangles;
use mres_format::{select, MresError, MresFile, FLAG_MATERIALS, FLAG_NORMALS, FLAG_UVS, NO_GROUP};
use mres_geom::parts::triangle_area;
use serde::Serialize;
use std::fmt::Write as _;

/// Fractions of the bounds diagonal at which the triangles of uniform cuts are counted.
pub const CUT_FRACTIONS: [f32; 12] = [0.0, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1, 0.3, 1.0];

/// The attributes a file stores, decoded from the header flags.
#[derive(Clone, Debug, Serialize)]
pub struct Attributes {
    /// Octahedral normals.
    pub normals: bool,
    /// Texture coordinates.
    pub uvs: bool,
    /// Per-triangle material indices.
    pub materials: bool,
}

/// One DAG level.
#[derive(Clone, Debug, Serialize)]
pub struct Level {
    /// Level number (0: the original triangles).
    pub level: u32,
    /// Groups formed at this level (group `level`).
    pub groups: u64,
    /// Of which root groups (infinite error: never replaced).
    pub root_groups: u64,
    /// Clusters of this level (0 for original clusters, else their own group's level + 1).
    pub clusters: u64,
    /// Triangles of those clusters.
    pub triangles: u64,
    /// Smallest finite error of this level's groups, object units; `null` when none is finite.
    pub error_min: Option<f32>,
    /// Largest finite error of this level's groups, object units.
    pub error_max: Option<f32>,
    /// `error_min` as a fraction of the bounds diagonal.
    pub error_min_fraction: Option<f64>,
    /// `error_max` as a fraction of the bounds diagonal.
    pub error_max_fraction: Option<f64>,
}

/// The triangles of one uniform cut (`mres export --error E`).
#[derive(Clone, Debug, Serialize)]
pub struct Cut {
    /// The error as a fraction of the bounds diagonal.
    pub fraction_of_diagonal: f32,
    /// The error E, object units.
    pub error: f32,
    /// Triangles drawn.
    pub triangles: u64,
    /// Surface area of the cut over the level-0 area: how much of the model's extent (and,
    /// for randomly oriented foliage cards, of its projected area) survives.
    pub area_fraction: f64,
}

/// Everything `mres inspect` prints.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// File size, bytes.
    pub file_bytes: u64,
    /// Format version (the reader reads only this one).
    pub format_version: u32,
    /// Input triangles: the source's triangles after triangulation, before degenerate ones
    /// were dropped (the header's `source_triangles`).
    pub input_triangles: u64,
    /// Triangles of level 0, the welded source.
    pub level0_triangles: u64,
    /// Input triangles dropped as degenerate: `input_triangles - level0_triangles`.
    pub degenerate_dropped: u64,
    /// Raw header flags.
    pub flags: u32,
    /// The flags decoded.
    pub attributes: Attributes,
    /// Bits of the position grid along the largest extent.
    pub position_bits: u32,
    /// Bits per octahedral normal component.
    pub normal_bits: u32,
    /// Position grid origin, object units.
    pub grid_origin: [f32; 3],
    /// Position grid step, object units.
    pub grid_step: f32,
    /// Lower corner of the level-0 positions, object units.
    pub bounds_min: [f32; 3],
    /// Upper corner of the level-0 positions, object units.
    pub bounds_max: [f32; 3],
    /// Length of the bounds diagonal, object units.
    pub diagonal: f32,
    /// DAG levels.
    pub levels: u32,
    /// Groups.
    pub groups: u64,
    /// Root groups (infinite error).
    pub root_groups: u64,
    /// Clusters.
    pub clusters: u64,
    /// Clusters of level 0.
    pub level0_clusters: u64,
    /// Clusters in root groups.
    pub root_clusters: u64,
    /// Pages.
    pub pages: u64,
    /// How the pages are stored: `"compact"` (docs/FORMAT.md §4.3) or `"layout"` (§4.4).
    pub page_encoding: &'static str,
    /// Decompressed size of all pages, bytes.
    pub raw_page_bytes: u64,
    /// Per level, finest first.
    pub per_level: Vec<Level>,
    /// Uniform cuts at [`CUT_FRACTIONS`] of the diagonal.
    pub uniform_cuts: Vec<Cut>,
    /// (fraction, triangles) of uniform cuts at fractions of the grid's largest extent, as
    /// docs/BENCHMARKS.md compares sharded and whole bakes.
    pub cut_triangles_at_extent_fraction: Vec<(f32, u64)>,
}

/// The bounds of the level-0 positions and each cluster's surface area.
type Scan = ([f32; 3], [f32; 3], Vec<f64>);

/// Reads every page of `file` (checksum and decompression) and decodes every cluster, and
/// returns the bounds of the level-0 positions and each cluster's area; any damage is an
/// error.
fn verify_and_bound(file: &MresFile) -> Result<Scan, MresError> {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    let mut decoded = 0usize;
    let mut areas = vec![0.0f64; file.clusters.len()];
    for (p, page) in file.pages.iter().enumerate() {
        let raw = file.page(p as u32)?;
        for c in page.first_cluster..page.first_cluster.saturating_add(page.cluster_count) {
            let cluster = file.decode_cluster(&raw, c)?;
            decoded += 1;
            if let Some(a) = areas.get_mut(c as usize) {
                *a = area(file, &cluster);
            }
            if file.clusters[c as usize].own_group != NO_GROUP {
                continue;
            }
            for q in &cluster.positions {
                let v = file.header.grid.decode(*q);
                for k in 0..3 {
                    lo[k] = lo[k].min(v[k]);
                    hi[k] = hi[k].max(v[k]);
                }
            }
        }
    }
    if decoded != file.clusters.len() {
        return Err(MresError::Corrupt(format!(
            "pages hold {decoded} clusters, the hierarchy has {}",
            file.clusters.len()
        )));
    }
    if lo[0] > hi[0] {
        return Ok(([0.0; 3], [0.0; 3], areas));
    }
    Ok((lo, hi, areas))
}

/// Surface area of a decoded cluster, object units.
fn area(file: &MresFile, cluster: &mres_format::DecodedCluster) -> f64 {
    let p: Vec<[f64; 3]> = cluster.positions.iter().map(|q| file.header.grid.decode(*q).map(f64::from)).collect();
    cluster.indices.chunks_exact(3).map(|t| triangle_area([0, 1, 2].map(|k| p[t[k] as usize]))).sum()
}

/// The surface area of the uniform cut at each of `errors` (object units) over the level-0
/// area: how much of a card field's (projected) area a coarse cut keeps. Reads and decodes
/// every page; any damage is an error.
pub fn cut_area_fractions(file: &MresFile, errors: &[f32]) -> Result<Vec<f64>, MresError> {
    let (_, _, areas) = verify_and_bound(file)?;
    Ok(errors.iter().map(|&e| cut_area_fraction(file, &areas, e)).collect())
}

/// Area of the uniform cut at `error` over the level-0 area.
fn cut_area_fraction(file: &MresFile, areas: &[f64], error: f32) -> f64 {
    let level0: f64 =
        (0..file.clusters.len()).filter(|&c| file.clusters[c].own_group == NO_GROUP).map(|c| areas[c]).sum();
    let cut = select::uniform_cut(&file.groups, &file.clusters, error);
    cut.iter().map(|&c| areas[c as usize]).sum::<f64>() / level0.max(f64::MIN_POSITIVE)
}

fn cut_triangles(file: &MresFile, error: f32) -> u64 {
    let cut = select::uniform_cut(&file.groups, &file.clusters, error);
    cut.iter().map(|&c| file.clusters[c as usize].triangle_count as u64).sum()
}

fn per_level(file: &MresFile, diagonal: f32) -> Vec<Level> {
    let groups = &file.groups;
    let cluster_level = |own: u32| if own == NO_GROUP { 0 } else { groups[own as usize].level + 1 };
    let count = file
        .clusters
        .iter()
        .map(|c| cluster_level(c.own_group) + 1)
        .chain(groups.iter().map(|g| g.level + 1))
        .max()
        .unwrap_or(0);
    let fraction = |e: Option<f32>| e.filter(|_| diagonal > 0.0).map(|e| e as f64 / diagonal as f64);
    (0..count)
        .map(|level| {
            let of_level = || groups.iter().filter(move |g| g.level == level);
            let finite = || of_level().map(|g| g.error).filter(|e| e.is_finite());
            let of_clusters = || file.clusters.iter().filter(move |c| cluster_level(c.own_group) == level);
            let (error_min, error_max) = (finite().reduce(f32::min), finite().reduce(f32::max));
            Level {
                level,
                groups: of_level().count() as u64,
                root_groups: of_level().filter(|g| g.error.is_infinite()).count() as u64,
                clusters: of_clusters().count() as u64,
                triangles: of_clusters().map(|c| c.triangle_count as u64).sum(),
                error_min,
                error_max,
                error_min_fraction: fraction(error_min),
                error_max_fraction: fraction(error_max),
            }
        })
        .collect()
}

/// Reads and verifies all of `file` and summarises it.
pub fn summarize(file: &MresFile) -> Result<Summary, MresError> {
    let (lo, hi, areas) = verify_and_bound(file)?;
    let h = &file.header;
    let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f32>().sqrt();
    let level0 = level0_triangles(file);
    let extent = h.grid.step * ((1u64 << h.position_bits.min(31)) - 1) as f32;
    let roots = || file.groups.iter().filter(|g| g.error.is_infinite());
    Ok(Summary {
        file_bytes: file.file_size() as u64,
        format_version: mres_format::VERSION,
        input_triangles: h.source_triangles,
        level0_triangles: level0,
        degenerate_dropped: h.source_triangles.saturating_sub(level0),
        flags: h.flags,
        attributes: Attributes {
            normals: h.flags & FLAG_NORMALS != 0,
            uvs: h.flags & FLAG_UVS != 0,
            materials: h.flags & FLAG_MATERIALS != 0,
        },
        position_bits: h.position_bits,
        normal_bits: h.normal_bits,
        grid_origin: h.grid.origin,
        grid_step: h.grid.step,
        bounds_min: lo,
        bounds_max: hi,
        diagonal,
        levels: h.level_count,
        groups: file.groups.len() as u64,
        root_groups: roots().count() as u64,
        clusters: file.clusters.len() as u64,
        level0_clusters: file.clusters.iter().filter(|c| c.own_group == NO_GROUP).count() as u64,
        root_clusters: roots().map(|g| g.cluster_count as u64).sum(),
        pages: file.pages.len() as u64,
        page_encoding: if h.flags & mres_format::FLAG_LAYOUT_PAGES != 0 { "layout" } else { "compact" },
        raw_page_bytes: file.pages.iter().map(|p| p.raw_size as u64).sum(),
        per_level: per_level(file, diagonal),
        uniform_cuts: CUT_FRACTIONS
            .iter()
            .map(|&f| Cut {
                fraction_of_diagonal: f,
                error: f * diagonal,
                triangles: cut_triangles(file, f * diagonal),
                area_fraction: cut_area_fraction(file, &areas, f * diagonal),
            })
            .collect(),
        cut_triangles_at_extent_fraction: CUT_FRACTIONS.iter().map(|&f| (f, cut_triangles(file, f * extent))).collect(),
    })
}

/// `n` with thousands separators: 1234567 → "1,234,567".
pub fn count(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::new();
    for (i, d) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(d);
    }
    out
}

/// `x` to 3 significant digits, without float noise: 0.0012345 → "0.00123", 1.5e-4 → "1.50e-4".
pub fn sig(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    // Rounded first, so that 0.01f32 (0.00999999977) prints as 0.0100, not 0.01000.
    let x: f64 = format!("{x:.2e}").parse().unwrap_or(x);
    let exponent = x.abs().log10().floor() as i32;
    if (-3..6).contains(&exponent) {
        format!("{:.*}", (2 - exponent).max(0) as usize, x)
    } else {
        format!("{x:.2e}")
    }
}

fn point(p: [f32; 3]) -> String {
    format!("({}, {}, {})", sig(p[0] as f64), sig(p[1] as f64), sig(p[2] as f64))
}

fn range(lo: Option<impl Into<f64>>, hi: Option<impl Into<f64>>) -> String {
    match (lo, hi) {
        (Some(lo), Some(hi)) => format!("{} .. {}", sig(lo.into()), sig(hi.into())),
        _ => "-".into(),
    }
}

impl Summary {
    /// The readable text `mres inspect` prints (after a line naming the file).
    pub fn render(&self) -> String {
        let mut s = String::new();
        let a = &self.attributes;
        let attributes: Vec<String> = [
            (a.normals, format!("normals ({}-bit octahedral)", self.normal_bits)),
            (a.uvs, "UVs".into()),
            (a.materials, "materials".into()),
        ]
        .into_iter()
        .map(|(on, name)| if on { name } else { format!("no {}", name.split(' ').next().unwrap_or("")) })
        .collect();
        let _ = writeln!(
            s,
            "  size        {} bytes in {} {} pages ({} bytes decompressed), format version {}",
            count(self.file_bytes),
            count(self.pages),
            self.page_encoding,
            count(self.raw_page_bytes),
            self.format_version
        );
        let _ = writeln!(
            s,
            "  triangles   {} input, {} at level 0, {} degenerate or duplicate dropped",
            count(self.input_triangles),
            count(self.level0_triangles),
            count(self.degenerate_dropped)
        );
        let _ = writeln!(s, "  attributes  {} (flags {:#x})", attributes.join(", "), self.flags);
        let _ = writeln!(
            s,
            "  positions   {}-bit grid, step {} object units, origin {}",
            self.position_bits,
            sig(self.grid_step as f64),
            point(self.grid_origin)
        );
        let _ = writeln!(
            s,
            "  bounds      {} .. {}, diagonal {} object units",
            point(self.bounds_min),
            point(self.bounds_max),
            sig(self.diagonal as f64)
        );
        let _ = writeln!(
            s,
            "  DAG         {} levels, {} groups ({} root), {} clusters ({} at level 0, {} in root groups)",
            self.levels,
            count(self.groups),
            self.root_groups,
            count(self.clusters),
            count(self.level0_clusters),
            self.root_clusters
        );
        self.render_levels(&mut s);
        self.render_cuts(&mut s);
        s
    }

    fn render_levels(&self, s: &mut String) {
        let _ = writeln!(s, "\nper level (a uniform cut at error E replaces a group's clusters once E >= its error):");
        let _ = writeln!(
            s,
            "{:>6} {:>12} {:>10} {:>12}  {:<24} {:<22}",
            "level", "groups", "clusters", "triangles", "group error (object)", "group error / diagonal"
        );
        for l in &self.per_level {
            let roots = if l.root_groups > 0 { format!(" ({} root)", l.root_groups) } else { String::new() };
            let _ = writeln!(
                s,
                "{:>6} {:>12} {:>10} {:>12}  {:<24} {:<22}",
                l.level,
                format!("{}{roots}", count(l.groups)),
                count(l.clusters),
                count(l.triangles),
                range(l.error_min, l.error_max),
                range(l.error_min_fraction, l.error_max_fraction)
            );
        }
    }

    fn render_cuts(&self, s: &mut String) {
        let _ = writeln!(s, "\ntriangles per uniform cut (`mres export --error E`):");
        let header = ["E / diagonal", "E (object)", "triangles", "of lvl 0", "area"];
        let _ = writeln!(s, "{:>12} {:>12} {:>12} {:>8} {:>8}", header[0], header[1], header[2], header[3], header[4]);
        for c in &self.uniform_cuts {
            let share = c.triangles as f64 / self.level0_triangles.max(1) as f64 * 100.0;
            let _ = writeln!(
                s,
                "{:>12} {:>12} {:>12} {:>7.1}% {:>7.1}%",
                sig(c.fraction_of_diagonal as f64),
                sig(c.error as f64),
                count(c.triangles),
                share,
                c.area_fraction * 100.0
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_without_noise() {
        assert_eq!(count(0), "0");
        assert_eq!(count(999), "999");
        assert_eq!(count(1_234_567), "1,234,567");
        assert_eq!(sig(0.0012345), "0.00123");
        assert_eq!(sig(1.5e-7), "1.50e-7");
        assert_eq!(sig(2.0), "2.00");
        assert_eq!(sig(12345.0), "12300");
        assert_eq!(sig(-0.5), "-0.500");
        assert_eq!(sig(0.1f32 as f64), "0.100");
        assert_eq!(sig(0.01f32 as f64), "0.0100");
        assert_eq!(sig(0.9996), "1.00");
    }
}
