//! Bake settings: every knob of the DAG build, with the defaults `pipeline.toml` documents.

use serde::{Deserialize, Serialize};

/// How a group's stored error is obtained (docs/INVARIANTS.md §4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ErrorBound {
    /// Measured: the sampled two-sided distance between the group's output and the original
    /// level-0 surface it replaces (`deviation.rs`), outlier groups simplified again: a bound
    /// the validator checks at ratio 1, and tight (docs/INVARIANTS.md §4). Costs bake time.
    Measured,
    /// meshoptimizer's estimate made monotone, as clusterlod stores it: fast and tight, but not
    /// a bound (the validator measured up to 2.6× it on scans, 40–130× at single spots).
    Simplifier,
}

/// How pages are stored (docs/FORMAT.md §4.3, §4.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PageEncoding {
    /// Predicted and entropy-coded: the smallest files (about 5 B per input triangle on
    /// scans), decoding at 100–200 MB of GPU layout per second per core.
    Compact,
    /// The GPU layout itself, one LZ4 block per page: about twice the bytes, decoding at
    /// memory speed, every page alone (what a streamer that decodes on the fly wants).
    Layout,
}

/// Whether foliage keeps its area ([`BakeSettings::preserve_area`]): `false`, `true` or
/// `"auto"` in `pipeline.toml` (`false` and `true` are how it was written before `"auto"`, so
/// that the settings of a cache key read as they did).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PreserveArea {
    /// Never: every part simplifies as it is.
    Off,
    /// Always: the small open parts a group keeps grow (see `area.rs`).
    On,
    /// Where small open parts hold at least [`crate::area::AUTO_SHARE`] of the mesh's surface
    /// area (a card field, a tree's leaves), as `On`; elsewhere as `Off`.
    Auto,
}

impl Serialize for PreserveArea {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            PreserveArea::Off => s.serialize_bool(false),
            PreserveArea::On => s.serialize_bool(true),
            PreserveArea::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for PreserveArea {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Written;
        impl serde::de::Visitor<'_> for Written {
            type Value = PreserveArea;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("true, false or \"auto\"")
            }
            fn visit_bool<E: serde::de::Error>(self, on: bool) -> Result<PreserveArea, E> {
                Ok(if on { PreserveArea::On } else { PreserveArea::Off })
            }
            fn visit_str<E: serde::de::Error>(self, word: &str) -> Result<PreserveArea, E> {
                match word {
                    "auto" => Ok(PreserveArea::Auto),
                    _ => Err(E::invalid_value(serde::de::Unexpected::Str(word), &self)),
                }
            }
        }
        d.deserialize_any(Written)
    }
}

/// Settings of one bake. Each field says which step it feeds; [`BakeSettings::default`]
/// gives the defaults and why.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BakeSettings {
    /// Weld/quantize: bits of the global position grid along the mesh's largest extent
    /// (8..=24). 16 gives a step of 1/65535 of the extent (≈ 0.03 mm on a 2 m object).
    pub position_bits: u32,
    /// Encode: bits per octahedral normal component (4..=16).
    pub normal_bits: u32,
    /// Cluster: most triangles per cluster (≤ 128, multiple of 4).
    pub max_triangles: u32,
    /// Cluster: most vertices per cluster (≤ 256; 8-bit local indices).
    pub max_vertices: u32,
    /// Partition: target clusters per group; groups fall in `[target/2, 3*target/2]`.
    pub group_size: u32,
    /// Simplify: each group aims at this fraction of its triangles.
    pub simplify_ratio: f32,
    /// Simplify: a group that keeps more than this fraction is stuck; it tries the permissive
    /// and then the sloppy fallback, and if still stuck its clusters wait for the next level.
    pub stuck_ratio: f32,
    /// Simplify: weight of normals against positions in the attribute-aware quadric.
    pub normal_weight: f32,
    /// Simplify: weight of UVs against positions in the attribute-aware quadric.
    pub uv_weight: f32,
    /// Simplify: how group errors are obtained, `"measured"` (honest) or `"simplifier"`.
    pub error_bound: ErrorBound,
    /// Write: zstd level of the pages (1..=22).
    pub zstd_level: i32,
    /// Shard: a mesh with more triangles than this is split spatially into shards of about
    /// this many, built one after the other and merged in the upper levels (≥ 1000).
    pub shard_triangles: u64,
    /// Keep normals from the source (if it has them).
    pub keep_normals: bool,
    /// Keep UVs from the source (if it has them).
    pub keep_uvs: bool,
    /// Write: encode every page to decode alone, without copies of its sources' vertices
    /// (docs/FORMAT.md §4.3, far copies): larger files, for a reader that decodes pages out
    /// of file order.
    pub independent_pages: bool,
    /// Write: how pages are stored, `"compact"` or `"layout"` (every page then decodes alone,
    /// whatever `independent_pages` says).
    pub page_encoding: PageEncoding,
    /// Simplify: foliage keeps its area. Where a group removes small open parts (cards,
    /// leaves), the open parts it keeps grow about their centres so that the group's
    /// open-part area stays about the same (docs/INVARIANTS.md §4). The stored errors grow
    /// with the dilation, so it is for meshes whose coverage matters more than their shape:
    /// `On` for those, `Auto` to let each mesh's share of small open parts decide.
    pub preserve_area: PreserveArea,
}

impl Default for BakeSettings {
    fn default() -> Self {
        BakeSettings {
            // Fine enough for scans at 1:65535, and keeps per-cluster packed positions short.
            position_bits: 16,
            // 10 bits per octahedral coordinate: ≈ 0.1° mean normal error, at most 2.5 bytes per vertex.
            normal_bits: 10,
            // Nanite's cluster size; the mesh-shader limits are 256 vertices / 256 primitives.
            max_triangles: 128,
            max_vertices: 255,
            // ~16 clusters per group (Nanite uses 8–32): halving 2k triangles keeps borders short.
            group_size: 16,
            simplify_ratio: 0.5,
            // clusterlod's threshold: keeping over 85% is not worth a level.
            stuck_ratio: 0.85,
            normal_weight: 0.5,
            uv_weight: 0.5,
            // Honest by default: a renderer trusts the error to bound what it sees.
            error_bound: ErrorBound::Measured,
            // zstd 9 on headers and indices (positions and normals, near-random, always use level 1):
            // level 15 is 1.3% smaller but its binary-tree matcher costs ~10% of the bake time.
            zstd_level: 9,
            // A 2M-triangle shard takes about 0.3 GB to build: two at a time fit anywhere, and
            // larger shards would only lengthen the locked border band (see shard.rs).
            shard_triangles: 2_000_000,
            keep_normals: true,
            keep_uvs: true,
            // Far copies store about half the vertices of a scan in a byte or two each; a
            // streamer holds a page's sources anyway (they are its coarser dependencies).
            independent_pages: false,
            // Distribution and caches want the smaller files; `mres repack` turns them into
            // layout pages where decode speed matters more than bytes.
            page_encoding: PageEncoding::Compact,
            // Off: growing parts moves them off the surface (larger errors, more triangles at
            // a given error); foliage assets turn it on.
            preserve_area: PreserveArea::Off,
        }
    }
}

impl BakeSettings {
    /// Checks every value's range; the message names the key.
    pub fn check(&self) -> Result<(), String> {
        let range = |key: &str, v: u32, lo: u32, hi: u32| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(format!("{key} = {v} is outside {lo}..={hi}"))
            }
        };
        range("position_bits", self.position_bits, 8, 24)?;
        range("normal_bits", self.normal_bits, 4, 16)?;
        range("max_triangles", self.max_triangles, 8, 128)?;
        range("max_vertices", self.max_vertices, 3 * 4, 256)?;
        range("group_size", self.group_size, 2, 64)?;
        range("zstd_level", self.zstd_level.max(0) as u32, 1, 22)?;
        if self.shard_triangles < 1000 {
            return Err(format!("shard_triangles = {} must be at least 1000", self.shard_triangles));
        }
        if !self.max_triangles.is_multiple_of(4) {
            return Err(format!("max_triangles = {} must be a multiple of 4", self.max_triangles));
        }
        let unit = |key: &str, v: f32| {
            if v > 0.0 && v < 1.0 {
                Ok(())
            } else {
                Err(format!("{key} = {v} must be in (0, 1)"))
            }
        };
        unit("simplify_ratio", self.simplify_ratio)?;
        unit("stuck_ratio", self.stuck_ratio)?;
        if !(self.normal_weight >= 0.0 && self.uv_weight >= 0.0) {
            return Err("normal_weight and uv_weight must be ≥ 0".into());
        }
        Ok(())
    }
}
