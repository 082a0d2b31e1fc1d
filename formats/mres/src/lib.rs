//! The `.mres` container: a multiresolution cluster DAG in streamable, checksummed pages.
//!
//! The byte-level specification is `docs/FORMAT.md`; this module is its reference
//! implementation. [`write::write_mres`] turns a logical [`Dag`] into bytes, [`read::MresFile`]
//! parses and checks them, and [`select`] is the CPU reference of the LOD selection rule that
//! the validator and the GPU path share.

#![deny(missing_docs)]

pub mod bits;
pub mod read;
pub mod select;
pub mod write;

pub use read::{DecodedCluster, MresError, MresFile};
pub use select::{uniform_cut, view_cut, ViewParams};
pub use write::write_mres;

/// File magic, the first four bytes.
pub const MAGIC: [u8; 4] = *b"MRES";
/// Format version written by this crate; readers reject any other.
pub const VERSION: u32 = 1;
/// Size of the fixed header in bytes.
pub const HEADER_SIZE: usize = 160;
/// Size of one group record in the hierarchy section.
pub const GROUP_RECORD_SIZE: usize = 40;
/// Size of one cluster record in the hierarchy section.
pub const CLUSTER_RECORD_SIZE: usize = 16;
/// Size of one page record in the page table (dependencies follow the records).
pub const PAGE_RECORD_SIZE: usize = 72;
/// Size of one cluster header at the start of a decompressed page.
pub const CLUSTER_HEADER_SIZE: usize = 48;
/// Target upper bound of a page before compression (Nanite's choice). A page that holds a
/// single group larger than this may exceed it, up to [`MAX_PAGE_RAW_SIZE`].
pub const PAGE_TARGET_RAW_SIZE: usize = 128 * 1024;
/// Hard limit on a page's decompressed size; readers reject larger claims before allocating.
pub const MAX_PAGE_RAW_SIZE: usize = 16 * 1024 * 1024;
/// Most triangles in one cluster.
pub const MAX_CLUSTER_TRIANGLES: usize = 128;
/// Most vertices in one cluster (8-bit local indices).
pub const MAX_CLUSTER_VERTICES: usize = 256;
/// `own_group` of a level-0 cluster: it was not produced by any simplification (error 0).
pub const NO_GROUP: u32 = u32::MAX;

/// Header flag: clusters carry octahedral normals.
pub const FLAG_NORMALS: u32 = 1;
/// Header flag: clusters carry quantized UVs.
pub const FLAG_UVS: u32 = 2;
/// Header flag: clusters carry a material index per triangle.
pub const FLAG_MATERIALS: u32 = 4;

/// The global integer grid every position is quantized to, so that a vertex shared by two
/// clusters decodes bit-identically. Decoding is `origin[k] + (q[k] as f32) * step` in f32.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Object-space position of grid point (0, 0, 0).
    pub origin: [f32; 3],
    /// Object-space distance between neighbouring grid points (> 0).
    pub step: f32,
}

impl Grid {
    /// A grid covering `[lo, hi]` with `bits` bits along the largest extent (1..=24).
    pub fn covering(lo: [f32; 3], hi: [f32; 3], bits: u32) -> Grid {
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f32, f32::max);
        let cells = ((1u64 << bits.clamp(1, 24)) - 1) as f32;
        let step = if extent > 0.0 { extent / cells } else { 1.0 };
        Grid { origin: lo, step }
    }

    /// The grid point nearest to `p`.
    pub fn quantize(&self, p: [f32; 3]) -> [i32; 3] {
        let q = |k: usize| ((p[k] - self.origin[k]) / self.step).round() as i32;
        [q(0), q(1), q(2)]
    }

    /// The object-space position of grid point `q` (the exact f32 formula of the spec).
    pub fn decode(&self, q: [i32; 3]) -> [f32; 3] {
        let d = |k: usize| self.origin[k] + (q[k] as f32) * self.step;
        [d(0), d(1), d(2)]
    }
}

/// Quantization of texture coordinates: 16 bits per component over the mesh's UV range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvQuant {
    /// Smallest u and v of the mesh.
    pub min: [f32; 2],
    /// Range of u and v (max − min; 0 when constant).
    pub extent: [f32; 2],
}

impl UvQuant {
    /// Quantizes one UV to two 16-bit unsigned values.
    pub fn quantize(&self, uv: [f32; 2]) -> [u16; 2] {
        let q = |k: usize| {
            if self.extent[k] > 0.0 {
                ((uv[k] - self.min[k]) / self.extent[k] * 65535.0).round().clamp(0.0, 65535.0) as u16
            } else {
                0
            }
        };
        [q(0), q(1)]
    }

    /// Decodes a quantized UV: `min + q / 65535 * extent`.
    pub fn decode(&self, q: [u16; 2]) -> [f32; 2] {
        let d = |k: usize| self.min[k] + (q[k] as f32 / 65535.0) * self.extent[k];
        [d(0), d(1)]
    }
}

/// A bounding sphere, object space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Centre.
    pub center: [f32; 3],
    /// Radius (≥ 0).
    pub radius: f32,
}

/// One group of the DAG: the clusters that were merged and simplified together.
///
/// For every cluster `c` of the group, the group is `c`'s **parent** (sphere, error) pair:
/// once the group's error projects above the threshold, `c` is drawn instead of the group's
/// coarser output. The root group has error `+inf`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Group {
    /// Bounds enclosing the group's geometry and every member cluster's own sphere.
    pub sphere: Sphere,
    /// Object-space simplification error, ≥ the own error of every member (monotone).
    pub error: f32,
    /// DAG level of the group's member clusters (0 = original geometry).
    pub level: u32,
    /// First member cluster (clusters of a group are contiguous).
    pub first_cluster: u32,
    /// Number of member clusters.
    pub cluster_count: u32,
    /// Page holding the member clusters.
    pub page: u32,
}

/// One cluster's always-resident record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterInfo {
    /// The group the cluster belongs to (its parent pair).
    pub group: u32,
    /// The group whose simplification produced the cluster (its own pair), or [`NO_GROUP`].
    pub own_group: u32,
    /// Vertices in the cluster (1..=256).
    pub vertex_count: u16,
    /// Triangles in the cluster (1..=128).
    pub triangle_count: u16,
    /// Byte offset of the cluster's header within its decompressed page.
    pub page_offset: u32,
}

/// One page's entry in the page table.
#[derive(Clone, Debug, PartialEq)]
pub struct PageInfo {
    /// File offset of the page's zstd frame.
    pub offset: u64,
    /// Length of the zstd frame in bytes.
    pub compressed_size: u32,
    /// Length of the decompressed page in bytes.
    pub raw_size: u32,
    /// blake3 of the compressed frame.
    pub checksum: [u8; 32],
    /// First cluster in the page.
    pub first_cluster: u32,
    /// Clusters in the page.
    pub cluster_count: u32,
    /// First group in the page.
    pub first_group: u32,
    /// Groups in the page.
    pub group_count: u32,
    /// Pages that must be resident before this one is used (coarser pages holding the
    /// parents of its clusters, and pages holding their siblings), ascending.
    pub dependencies: Vec<u32>,
}

/// File-wide parameters from the header.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    /// Combination of `FLAG_*`.
    pub flags: u32,
    /// The position grid.
    pub grid: Grid,
    /// The UV quantization (meaningful with [`FLAG_UVS`]).
    pub uv: UvQuant,
    /// Bits per octahedral normal component (meaningful with [`FLAG_NORMALS`]; 4..=16).
    pub normal_bits: u32,
    /// Grid precision setting the file was baked with (bits along the largest extent).
    pub position_bits: u32,
    /// Number of DAG levels (max group level + 1).
    pub level_count: u32,
    /// Triangles of the source mesh (before welding and dropping degenerates).
    pub source_triangles: u64,
}

/// A logical DAG ready to be written: what the baker produces.
#[derive(Clone, Debug, PartialEq)]
pub struct Dag {
    /// File-wide parameters (`level_count` is recomputed by the writer).
    pub header: Header,
    /// Groups, any order; `first_cluster`, `cluster_count` and `page` are filled by the writer.
    pub groups: Vec<Group>,
    /// Clusters, any order.
    pub clusters: Vec<DagCluster>,
}

/// One cluster of a logical [`Dag`].
#[derive(Clone, Debug, PartialEq)]
pub struct DagCluster {
    /// Index into [`Dag::groups`] of the group it belongs to.
    pub group: u32,
    /// Index into [`Dag::groups`] of the group that produced it, or [`NO_GROUP`].
    pub own_group: u32,
    /// Vertex positions on the global grid.
    pub positions: Vec<[i32; 3]>,
    /// Unit normals, one per vertex (with [`FLAG_NORMALS`]).
    pub normals: Vec<[f32; 3]>,
    /// UVs, one per vertex (with [`FLAG_UVS`]).
    pub uvs: Vec<[f32; 2]>,
    /// Local triangle indices, three per triangle.
    pub indices: Vec<u8>,
    /// Material per triangle (with [`FLAG_MATERIALS`]).
    pub materials: Vec<u16>,
}
