//! The GPU inputs of one `.mres` file, built on the CPU: the flattened hierarchy (one
//! [`GpuCluster`] per cluster) and every decompressed page as is (FORMAT.md §5) with a table
//! of page base offsets. The inputs of several files (a scene file's meshes) are concatenated
//! by [`SceneData::merge`], each file one [`MeshPart`].

use anyhow::{bail, Context as _, Result};
use mres_format::{Grid, MresFile, Sphere, NO_GROUP};

use crate::gpu_types::{GpuCluster, GpuLevelBin};

/// Largest cluster index an index-buffer entry `(cluster << 8) | vertex` can carry.
pub const MAX_CLUSTERS: usize = 1 << 24;

/// Where one file's data lies in a [`SceneData`], and what instances of it need.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshPart {
    /// First cluster (index into [`SceneData::clusters`]).
    pub cluster_first: u32,
    /// Its clusters.
    pub cluster_count: u32,
    /// First level bin (index into [`SceneData::bins`]).
    pub bin_first: u32,
    /// Its level bins.
    pub bin_count: u32,
    /// The file's position grid.
    pub grid: Grid,
    /// The file's [`SceneData::bounds`] (object space).
    pub bounds: Sphere,
    /// The file's [`SceneData::model_far`].
    pub model_far: f32,
    /// The file's [`SceneData::model_near`].
    pub model_near: f32,
}

/// What the GPU needs of a file (or of several, [`SceneData::merge`]).
#[derive(Clone, Debug)]
pub struct SceneData {
    /// One record per cluster, in file order.
    pub clusters: Vec<GpuCluster>,
    /// Byte offset of each page in [`SceneData::pages`] (multiples of 4).
    pub page_bases: Vec<u32>,
    /// All decompressed pages, each padded to a multiple of 4 bytes.
    pub pages: Vec<u8>,
    /// Indices of all clusters together: an upper bound on any cut's index count, since a
    /// cut selects each cluster at most once.
    pub index_capacity: u64,
    /// The position grid.
    pub grid: Grid,
    /// A sphere enclosing the root groups' spheres (or all groups' without a root), object
    /// space. Group spheres are conservative, so this can be much larger than the model.
    pub root_bounds: Sphere,
    /// A sphere enclosing every level-0 vertex (centred on their bounding box), object space:
    /// an eye outside it is outside the mesh. Cameras frame this one.
    pub bounds: Sphere,
    /// Triangles of the finest (level-0) clusters.
    pub level0_triangles: u64,
    /// Cluster indices sorted by DAG level (stable: file order within a level).
    pub level_order: Vec<u32>,
    /// One bin per DAG level over `level_order`, with its error range.
    pub bins: Vec<GpuLevelBin>,
    /// Largest `|c - bounds.center| - r` over the group spheres (c, r), padded (object space).
    pub model_far: f32,
    /// Largest `|c - bounds.center| + r` over the group spheres, padded: a sphere of this radius
    /// around `bounds.center` holds every group sphere (object space).
    pub model_near: f32,
    /// One part per file: one for [`SceneData::from_file`]. The single-file fields above
    /// (grid, bounds, model extent) are the first part's.
    pub parts: Vec<MeshPart>,
}

/// The level order and one bin per level (levels without clusters get empty bins).
pub fn level_bins(clusters: &[GpuCluster]) -> (Vec<u32>, Vec<GpuLevelBin>) {
    let mut order: Vec<u32> = (0..clusters.len() as u32).collect();
    order.sort_by_key(|&i| clusters[i as usize].level);
    let levels = clusters.iter().map(|c| c.level as usize + 1).max().unwrap_or(0);
    let mut bins =
        vec![GpuLevelBin { first: 0, count: 0, min_own_error: f32::INFINITY, max_parent_error: 0.0 }; levels];
    for (k, &i) in order.iter().enumerate() {
        let c = &clusters[i as usize];
        let bin = &mut bins[c.level as usize];
        if bin.count == 0 {
            bin.first = k as u32;
        }
        bin.count += 1;
        bin.min_own_error = bin.min_own_error.min(c.own_error);
        bin.max_parent_error = bin.max_parent_error.max(c.parent_error);
    }
    (order, bins)
}

/// (model_far, model_near) of the group spheres around `center` (see [`SceneData`]), in f64
/// and padded by 10⁻³ of the radius so that the GPU's f32 distance bounds stay conservative.
fn model_extent(file: &MresFile, center: [f32; 3]) -> (f32, f32) {
    let (mut far, mut near) = (f64::NEG_INFINITY, 0.0f64);
    for g in &file.groups {
        let d = (0..3).map(|k| (g.sphere.center[k] as f64 - center[k] as f64).powi(2)).sum::<f64>().sqrt();
        far = far.max(d - g.sphere.radius as f64);
        near = near.max(d + g.sphere.radius as f64);
    }
    if file.groups.is_empty() {
        return (0.0, 0.0);
    }
    let pad = near * 1e-3 + 1e-6;
    ((far + pad) as f32, (near + pad) as f32)
}

impl SceneData {
    /// Flattens `file`'s hierarchy and reads every page. Every cluster is decoded once with the
    /// reference reader, which checks each block offset, bit width and local index, so the
    /// shaders only ever read inside the page buffer.
    pub fn from_file(file: &MresFile) -> Result<SceneData> {
        if file.clusters.len() >= MAX_CLUSTERS {
            bail!("{} clusters: the fallback index encoding holds at most {}", file.clusters.len(), MAX_CLUSTERS - 1);
        }
        let mut pages = Vec::new();
        let mut page_bases = Vec::with_capacity(file.pages.len());
        let mut level0_positions = Vec::new();
        for (p, info) in file.pages.iter().enumerate() {
            let raw = file.page(p as u32).with_context(|| format!("page {p}"))?;
            for c in info.first_cluster..info.first_cluster + info.cluster_count {
                let decoded = file.decode_cluster(&raw, c).with_context(|| format!("page {p}"))?;
                if file.clusters[c as usize].own_group == NO_GROUP {
                    level0_positions.extend(decoded.positions.iter().map(|&q| file.header.grid.decode(q)));
                }
            }
            page_bases.push(u32::try_from(pages.len()).context("decompressed pages exceed 4 GiB")?);
            pages.extend_from_slice(&raw);
            pages.resize(pages.len().next_multiple_of(4), 0);
        }
        u32::try_from(pages.len()).context("decompressed pages exceed 4 GiB")?;

        let mut clusters = Vec::with_capacity(file.clusters.len());
        let mut index_capacity = 0u64;
        let mut level0_triangles = 0u64;
        for c in &file.clusters {
            let parent = &file.groups[c.group as usize];
            let (own_sphere, own_error) = if c.own_group == NO_GROUP {
                level0_triangles += c.triangle_count as u64;
                ([0.0; 4], 0.0)
            } else {
                let own = &file.groups[c.own_group as usize];
                (sphere4(&own.sphere), own.error)
            };
            clusters.push(GpuCluster {
                own_sphere,
                parent_sphere: sphere4(&parent.sphere),
                own_error,
                parent_error: parent.error,
                page: parent.page,
                header_offset: c.page_offset,
                vertex_count: c.vertex_count as u32,
                triangle_count: c.triangle_count as u32,
                group: c.group,
                level: parent.level,
            });
            index_capacity += 3 * c.triangle_count as u64;
        }
        let bounds = points_bounds(&level0_positions).unwrap_or_else(|| model_bounds(file));
        let (level_order, bins) = level_bins(&clusters);
        let (model_far, model_near) = model_extent(file, bounds.center);
        let part = MeshPart {
            cluster_first: 0,
            cluster_count: clusters.len() as u32,
            bin_first: 0,
            bin_count: bins.len() as u32,
            grid: file.header.grid,
            bounds,
            model_far,
            model_near,
        };
        Ok(SceneData {
            parts: vec![part],
            level_order,
            bins,
            model_far,
            model_near,
            clusters,
            page_bases,
            pages,
            index_capacity,
            grid: file.header.grid,
            root_bounds: model_bounds(file),
            bounds,
            level0_triangles,
        })
    }
}

impl SceneData {
    /// The files of `parts` (each from [`SceneData::from_file`]) in one set of buffers: clusters,
    /// pages, level order and bins concatenated, each cluster's page and group and each bin's
    /// level-order range moved by what comes before it. The single-file fields are the first
    /// file's.
    pub fn merge(parts: Vec<SceneData>) -> Result<SceneData> {
        let mut parts = parts.into_iter();
        let Some(mut out) = parts.next() else { bail!("a scene needs at least one mesh") };
        for part in parts {
            let cluster_offset = out.clusters.len() as u32;
            let page_offset = out.page_bases.len() as u32;
            let group_offset = out.clusters.iter().map(|c| c.group + 1).max().unwrap_or(0);
            let byte_offset = u32::try_from(out.pages.len()).context("decompressed pages exceed 4 GiB")?;
            let order_offset = out.level_order.len() as u32;
            let bin_offset = out.bins.len() as u32;
            out.clusters.extend(part.clusters.iter().map(|c| GpuCluster {
                page: c.page + page_offset,
                group: c.group + group_offset,
                ..*c
            }));
            if out.clusters.len() >= MAX_CLUSTERS {
                bail!(
                    "{} clusters: the fallback index encoding holds at most {}",
                    out.clusters.len(),
                    MAX_CLUSTERS - 1
                );
            }
            for base in &part.page_bases {
                out.page_bases.push(base.checked_add(byte_offset).context("decompressed pages exceed 4 GiB")?);
            }
            out.pages.extend_from_slice(&part.pages);
            u32::try_from(out.pages.len()).context("decompressed pages exceed 4 GiB")?;
            out.level_order.extend(part.level_order.iter().map(|&i| i + cluster_offset));
            out.bins.extend(part.bins.iter().map(|b| GpuLevelBin { first: b.first + order_offset, ..*b }));
            out.index_capacity += part.index_capacity;
            out.level0_triangles += part.level0_triangles;
            out.parts.extend(part.parts.iter().map(|p| MeshPart {
                cluster_first: p.cluster_first + cluster_offset,
                bin_first: p.bin_first + bin_offset,
                ..*p
            }));
        }
        Ok(out)
    }
}

fn sphere4(s: &Sphere) -> [f32; 4] {
    [s.center[0], s.center[1], s.center[2], s.radius]
}

/// A sphere enclosing the root groups' spheres (all groups' when no group is a root).
pub fn model_bounds(file: &MresFile) -> Sphere {
    let roots: Vec<Sphere> = file.groups.iter().filter(|g| g.error.is_infinite()).map(|g| g.sphere).collect();
    let spheres = if roots.is_empty() { file.groups.iter().map(|g| g.sphere).collect() } else { roots };
    enclosing_sphere(&spheres)
}

/// A sphere around `points`, centred on their bounding box (None without points).
pub fn points_bounds(points: &[[f32; 3]]) -> Option<Sphere> {
    let first = *points.first()?;
    let (mut lo, mut hi) = (first, first);
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let c: [f64; 3] = std::array::from_fn(|k| (lo[k] as f64 + hi[k] as f64) * 0.5);
    let r =
        points.iter().map(|p| (0..3).map(|k| (p[k] as f64 - c[k]).powi(2)).sum::<f64>().sqrt()).fold(0.0f64, f64::max);
    Some(Sphere { center: c.map(|v| v as f32), radius: (r * 1.0001 + 1e-6) as f32 })
}

/// A sphere enclosing all `spheres` (not minimal: centred on the mean of their centres).
pub fn enclosing_sphere(spheres: &[Sphere]) -> Sphere {
    if spheres.is_empty() {
        return Sphere { center: [0.0; 3], radius: 1.0 };
    }
    let n = spheres.len() as f64;
    let mut c = [0.0f64; 3];
    for s in spheres {
        for (ck, &sk) in c.iter_mut().zip(&s.center) {
            *ck += sk as f64 / n;
        }
    }
    let radius = spheres
        .iter()
        .map(|s| {
            let d: f64 = (0..3).map(|k| (s.center[k] as f64 - c[k]).powi(2)).sum::<f64>().sqrt();
            d + s.radius as f64
        })
        .fold(0.0f64, f64::max);
    Sphere { center: [c[0] as f32, c[1] as f32, c[2] as f32], radius: (radius * 1.0001).max(1e-6) as f32 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enclosing_sphere_contains_inputs() {
        let s = [
            Sphere { center: [0.0, 0.0, 0.0], radius: 1.0 },
            Sphere { center: [4.0, 0.0, 0.0], radius: 0.5 },
            Sphere { center: [0.0, -3.0, 1.0], radius: 2.0 },
        ];
        let e = enclosing_sphere(&s);
        for x in &s {
            let d = (0..3).map(|k| (x.center[k] - e.center[k]).powi(2)).sum::<f32>().sqrt();
            assert!(d + x.radius <= e.radius, "{x:?} not inside {e:?}");
        }
        let pts = [[0.0, 0.0, 0.0], [2.0, 1.0, -1.0], [1.0, 3.0, 0.5]];
        let b = points_bounds(&pts).unwrap();
        assert!(pts.iter().all(|p| (0..3).map(|k| (p[k] - b.center[k]).powi(2)).sum::<f32>().sqrt() <= b.radius));
        assert!(points_bounds(&[]).is_none());
    }
}
