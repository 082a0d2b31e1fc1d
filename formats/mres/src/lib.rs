//! The `.mres` container: a multiresolution cluster DAG in streamable, checksummed pages.
//!
//! The byte-level specification is `docs/FORMAT.md`; this crate is its reference
//! implementation, and what an engine links to read `.mres` files:
//!
//! - [`write_mres`] turns a logical [`Dag`] into bytes;
//! - [`MresFile`] parses and checks a whole file held in memory;
//! - [`MresIndex`] parses the resident prefix (header, hierarchy, page table) alone, and
//!   decodes pages whose bytes the caller fetched itself ([`MresIndex::decode_page`]);
//! - [`select`] is the CPU reference of the LOD selection rule that the validator and the
//!   GPU path share;
//! - [`records`] names every field offset of the fixed-size records.
//!
//! Write a small DAG (one triangle, simplified into a root that is the same triangle) and
//! read it back:
//!
//! ```
//! use mres_format::*;
//!
//! let triangle = |group, own_group| DagCluster {
//!     group,
//!     own_group,
//!     positions: vec![[0, 0, 0], [1000, 0, 0], [0, 1000, 0]],
//!     normals: Vec::new(),
//!     uvs: Vec::new(),
//!     indices: vec![0, 1, 2],
//!     materials: Vec::new(),
//!     open_edges: vec![0b111], // a lone triangle: all three edges are open
//! };
//! let sphere = Sphere { center: [0.5, 0.5, 0.0], radius: 1.0 };
//! let group = |error, level| Group { sphere, error, level, first_cluster: 0, cluster_count: 0, page: 0 };
//! let dag = Dag {
//!     header: Header {
//!         flags: 0,
//!         grid: Grid { origin: [0.0; 3], step: 0.001 },
//!         uv: UvQuant { min: [0.0; 2], extent: [0.0; 2] },
//!         normal_bits: 0,
//!         position_bits: 10,
//!         level_count: 0, // the writer counts the levels
//!         source_triangles: 1,
//!     },
//!     // Group 0 holds the original cluster; group 1 is the root, holding its simplification.
//!     groups: vec![group(0.0, 0), group(f32::INFINITY, 1)],
//!     clusters: vec![triangle(0, NO_GROUP), triangle(1, 0)],
//! };
//! let bytes = write_mres(&dag, 3)?;
//!
//! let file = MresFile::parse(bytes)?;
//! assert_eq!(file.header.level_count, 2);
//! // Stored coarse to fine: the root group and its cluster first.
//! assert_eq!(file.groups[0].error, f32::INFINITY);
//! let clusters = file.decode_all()?;
//! assert_eq!(clusters[1].positions, dag.clusters[0].positions);
//! let corner = file.header.grid.decode(clusters[1].positions[1]);
//! assert_eq!(corner, [1000.0 * 0.001, 0.0, 0.0]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod bits;
mod codec;
mod decode;
pub mod error;
mod layout_pages;
pub mod page;
pub mod read;
pub mod records;
pub mod repack;
pub mod select;
pub mod write;

pub use page::{DecodedCluster, Page};
pub use read::{MresError, MresFile, MresIndex};
pub use records::ClusterHeader;
pub use repack::rewrite;
pub use select::{uniform_cut, view_cut, ViewParams};
pub use write::{write_mres, write_mres_with, PageCoding};

/// File magic, the first four bytes.
pub const MAGIC: [u8; 4] = *b"MRES";
/// Format version written by this crate; readers reject any other.
pub const VERSION: u32 = 6;
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
/// Hard limit on a page's encoded size (its compressed bytes decompressed, before decoding
/// to the GPU layout; FORMAT.md §4.3); readers reject pages whose counts need more.
pub const MAX_PAGE_ENCODED_SIZE: usize = 32 * 1024 * 1024;
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
/// Header flag: every page is stored as its GPU layout itself, one LZ4 block (FORMAT.md §4.4):
/// pages decode at memory speed and alone, in about twice the bytes of the compact encoding.
pub const FLAG_LAYOUT_PAGES: u32 = 8;
/// Every header flag this version defines.
pub const KNOWN_FLAGS: u32 = FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS | FLAG_LAYOUT_PAGES;

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
    /// Open-edge marks per triangle (bit k: the edge from corner k to corner (k+1) mod 3 lies
    /// on the cut's open border; docs/INVARIANTS.md §1), or empty when no edge is marked.
    pub open_edges: Vec<u8>,
}

impl DagCluster {
    /// The writer's form of a cluster read back from a file (decoded data and its hierarchy
    /// record). Writing it again gives the same bytes only where its decoded normals and UVs
    /// quantize back to the stored values, which floats do not promise (a few per page differ
    /// by one step); [`repack::rewrite`] rewrites a file exactly.
    pub fn from_decoded(d: DecodedCluster, info: &ClusterInfo) -> DagCluster {
        DagCluster {
            group: info.group,
            own_group: info.own_group,
            positions: d.positions,
            normals: d.normals,
            uvs: d.uvs,
            indices: d.indices,
            materials: d.materials,
            open_edges: d.open_edges,
        }
    }
}

impl Dag {
    /// A small valid DAG with every attribute: four level-0 clusters (a strip of quads) in one
    /// group, simplified into one root cluster. For examples and tests; its normals and UVs
    /// are exactly representable, so they survive a round trip unchanged.
    pub fn sample() -> Dag {
        let normal_bits = 10;
        let n = bits::oct_decode(bits::oct_encode([0.0, 0.0, 1.0], normal_bits), normal_bits);
        let uv = UvQuant { min: [0.0, 0.0], extent: [1.0, 1.0] };
        let cluster = |x0: i32, group: u32, own_group: u32, material: u16| {
            let positions = vec![[x0, 0, 5], [x0 + 100, 0, 5], [x0, 100, 5], [x0 + 100, 100, 7]];
            DagCluster {
                group,
                own_group,
                uvs: positions
                    .iter()
                    .map(|p| uv.decode(uv.quantize([p[0] as f32 / 1000.0, p[1] as f32 / 1000.0])))
                    .collect(),
                normals: vec![n; 4],
                positions,
                indices: vec![0, 1, 2, 1, 3, 2],
                materials: vec![material, material + 1],
                open_edges: vec![0b101, 0b011],
            }
        };
        let mut clusters: Vec<DagCluster> = (0..4).map(|i| cluster(i * 100, 0, NO_GROUP, i as u16)).collect();
        clusters.push(cluster(0, 1, 0, 9));
        let sphere = |r| Sphere { center: [0.2, 0.05, 0.005], radius: r };
        let group = |radius, error, level| Group {
            sphere: sphere(radius),
            error,
            level,
            first_cluster: 0,
            cluster_count: 0,
            page: 0,
        };
        Dag {
            header: Header {
                flags: FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS,
                grid: Grid { origin: [0.0; 3], step: 0.001 },
                uv,
                normal_bits,
                position_bits: 16,
                level_count: 0,
                source_triangles: 8,
            },
            groups: vec![group(1.0, 0.01, 0), group(2.0, f32::INFINITY, 1)],
            clusters,
        }
    }
}
