//! The fixed-size records of `docs/FORMAT.md` §2–4, with each field's offset named row for row
//! as in the spec's tables. Encoding and decoding only move bytes: whether the values make
//! sense is checked by the reader ([`crate::read`]), so that the writer, the reader and tools
//! that patch files (the fuzz harness's `reseal.rs`) share one statement of the layout.

use super::*;

/// `N` bytes of `b` at `at`. Record offsets are constants inside fixed-size arrays, so the
/// indexing cannot fail on any input.
fn take<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    std::array::from_fn(|i| b[at + i])
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes(take(b, at))
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(take(b, at))
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(take(b, at))
}

fn f32s_at<const N: usize>(b: &[u8], at: usize) -> [f32; N] {
    std::array::from_fn(|k| f32::from_bits(u32_at(b, at + 4 * k)))
}

fn put(b: &mut [u8], at: usize, bytes: &[u8]) {
    b[at..at + bytes.len()].copy_from_slice(bytes);
}

fn put_f32s(b: &mut [u8], at: usize, values: &[f32]) {
    for (k, v) in values.iter().enumerate() {
        put(b, at + 4 * k, &v.to_le_bytes());
    }
}

/// The file header (FORMAT.md §2), every field as stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeaderRecord {
    /// Should be [`MAGIC`].
    pub magic: [u8; 4],
    /// Should be [`VERSION`].
    pub version: u32,
    /// Should be [`HEADER_SIZE`].
    pub header_size: u32,
    /// Combination of `FLAG_*`.
    pub flags: u32,
    /// Object-space position of grid point (0, 0, 0).
    pub grid_origin: [f32; 3],
    /// Distance between grid points.
    pub grid_step: f32,
    /// Smallest u, v.
    pub uv_min: [f32; 2],
    /// max − min of u, v.
    pub uv_extent: [f32; 2],
    /// Bits per octahedral coordinate.
    pub normal_bits: u32,
    /// Grid precision setting (informative).
    pub position_bits: u32,
    /// Number of DAG levels.
    pub level_count: u32,
    /// G.
    pub group_count: u32,
    /// C.
    pub cluster_count: u32,
    /// P.
    pub page_count: u32,
    /// Triangles in the source mesh.
    pub source_triangles: u64,
    /// Should be [`HEADER_SIZE`].
    pub hierarchy_offset: u64,
    /// Should be G·40 + C·16.
    pub hierarchy_size: u64,
    /// Should be `hierarchy_offset + hierarchy_size`.
    pub page_table_offset: u64,
    /// P·72 + 4·D.
    pub page_table_size: u64,
    /// BLAKE3 of header bytes `0..META_CHECKSUM`, the hierarchy and the page table.
    pub meta_checksum: [u8; 32],
    /// Should be zero.
    pub reserved: [u8; 16],
}

impl HeaderRecord {
    /// Offset of `magic`.
    pub const MAGIC: usize = 0;
    /// Offset of `version`.
    pub const VERSION: usize = 4;
    /// Offset of `header_size`.
    pub const HEADER_SIZE: usize = 8;
    /// Offset of `flags`.
    pub const FLAGS: usize = 12;
    /// Offset of `grid_origin`.
    pub const GRID_ORIGIN: usize = 16;
    /// Offset of `grid_step`.
    pub const GRID_STEP: usize = 28;
    /// Offset of `uv_min`.
    pub const UV_MIN: usize = 32;
    /// Offset of `uv_extent`.
    pub const UV_EXTENT: usize = 40;
    /// Offset of `normal_bits`.
    pub const NORMAL_BITS: usize = 48;
    /// Offset of `position_bits`.
    pub const POSITION_BITS: usize = 52;
    /// Offset of `level_count`.
    pub const LEVEL_COUNT: usize = 56;
    /// Offset of `group_count`.
    pub const GROUP_COUNT: usize = 60;
    /// Offset of `cluster_count`.
    pub const CLUSTER_COUNT: usize = 64;
    /// Offset of `page_count`.
    pub const PAGE_COUNT: usize = 68;
    /// Offset of `source_triangles`.
    pub const SOURCE_TRIANGLES: usize = 72;
    /// Offset of `hierarchy_offset`.
    pub const HIERARCHY_OFFSET: usize = 80;
    /// Offset of `hierarchy_size`.
    pub const HIERARCHY_SIZE: usize = 88;
    /// Offset of `page_table_offset`.
    pub const PAGE_TABLE_OFFSET: usize = 96;
    /// Offset of `page_table_size`.
    pub const PAGE_TABLE_SIZE: usize = 104;
    /// Offset of `meta_checksum`; the checksum covers the header bytes before it.
    pub const META_CHECKSUM: usize = 112;
    /// Offset of `reserved`.
    pub const RESERVED: usize = 144;

    /// The header's bytes.
    pub fn encode(&self) -> [u8; HEADER_SIZE] {
        let mut b = [0u8; HEADER_SIZE];
        put(&mut b, Self::MAGIC, &self.magic);
        put(&mut b, Self::VERSION, &self.version.to_le_bytes());
        put(&mut b, Self::HEADER_SIZE, &self.header_size.to_le_bytes());
        put(&mut b, Self::FLAGS, &self.flags.to_le_bytes());
        put_f32s(&mut b, Self::GRID_ORIGIN, &self.grid_origin);
        put_f32s(&mut b, Self::GRID_STEP, &[self.grid_step]);
        put_f32s(&mut b, Self::UV_MIN, &self.uv_min);
        put_f32s(&mut b, Self::UV_EXTENT, &self.uv_extent);
        put(&mut b, Self::NORMAL_BITS, &self.normal_bits.to_le_bytes());
        put(&mut b, Self::POSITION_BITS, &self.position_bits.to_le_bytes());
        put(&mut b, Self::LEVEL_COUNT, &self.level_count.to_le_bytes());
        put(&mut b, Self::GROUP_COUNT, &self.group_count.to_le_bytes());
        put(&mut b, Self::CLUSTER_COUNT, &self.cluster_count.to_le_bytes());
        put(&mut b, Self::PAGE_COUNT, &self.page_count.to_le_bytes());
        put(&mut b, Self::SOURCE_TRIANGLES, &self.source_triangles.to_le_bytes());
        put(&mut b, Self::HIERARCHY_OFFSET, &self.hierarchy_offset.to_le_bytes());
        put(&mut b, Self::HIERARCHY_SIZE, &self.hierarchy_size.to_le_bytes());
        put(&mut b, Self::PAGE_TABLE_OFFSET, &self.page_table_offset.to_le_bytes());
        put(&mut b, Self::PAGE_TABLE_SIZE, &self.page_table_size.to_le_bytes());
        put(&mut b, Self::META_CHECKSUM, &self.meta_checksum);
        put(&mut b, Self::RESERVED, &self.reserved);
        b
    }

    /// The fields of a header's bytes, unchecked.
    pub fn decode(b: &[u8; HEADER_SIZE]) -> HeaderRecord {
        HeaderRecord {
            magic: take(b, Self::MAGIC),
            version: u32_at(b, Self::VERSION),
            header_size: u32_at(b, Self::HEADER_SIZE),
            flags: u32_at(b, Self::FLAGS),
            grid_origin: f32s_at(b, Self::GRID_ORIGIN),
            grid_step: f32::from_bits(u32_at(b, Self::GRID_STEP)),
            uv_min: f32s_at(b, Self::UV_MIN),
            uv_extent: f32s_at(b, Self::UV_EXTENT),
            normal_bits: u32_at(b, Self::NORMAL_BITS),
            position_bits: u32_at(b, Self::POSITION_BITS),
            level_count: u32_at(b, Self::LEVEL_COUNT),
            group_count: u32_at(b, Self::GROUP_COUNT),
            cluster_count: u32_at(b, Self::CLUSTER_COUNT),
            page_count: u32_at(b, Self::PAGE_COUNT),
            source_triangles: u64_at(b, Self::SOURCE_TRIANGLES),
            hierarchy_offset: u64_at(b, Self::HIERARCHY_OFFSET),
            hierarchy_size: u64_at(b, Self::HIERARCHY_SIZE),
            page_table_offset: u64_at(b, Self::PAGE_TABLE_OFFSET),
            page_table_size: u64_at(b, Self::PAGE_TABLE_SIZE),
            meta_checksum: take(b, Self::META_CHECKSUM),
            reserved: take(b, Self::RESERVED),
        }
    }

    /// The file-wide parameters the header carries.
    pub fn header(&self) -> Header {
        Header {
            flags: self.flags,
            grid: Grid { origin: self.grid_origin, step: self.grid_step },
            uv: UvQuant { min: self.uv_min, extent: self.uv_extent },
            normal_bits: self.normal_bits,
            position_bits: self.position_bits,
            level_count: self.level_count,
            source_triangles: self.source_triangles,
        }
    }

    /// Length of the resident prefix the header declares: header, hierarchy and page table
    /// (the file offset of the first page). `None` when the declared sizes overflow.
    pub fn prefix_len(&self) -> Option<u64> {
        self.page_table_offset.checked_add(self.page_table_size)
    }
}

/// BLAKE3 over the header bytes before the checksum, the hierarchy section and the page table
/// (FORMAT.md §2, `meta_checksum`).
pub fn meta_checksum(header: &[u8; HEADER_SIZE], hierarchy: &[u8], table: &[u8]) -> [u8; 32] {
    let mut hasher = blake3::Hasher::new();
    hasher.update(&header[..HeaderRecord::META_CHECKSUM]);
    hasher.update(hierarchy);
    hasher.update(table);
    *hasher.finalize().as_bytes()
}

/// The group record (FORMAT.md §3.1), stored from and decoded to a [`Group`].
pub struct GroupRecord;

impl GroupRecord {
    /// Offset of `center`.
    pub const CENTER: usize = 0;
    /// Offset of `radius`.
    pub const RADIUS: usize = 12;
    /// Offset of `error`.
    pub const ERROR: usize = 16;
    /// Offset of `level`.
    pub const LEVEL: usize = 20;
    /// Offset of `first_cluster`.
    pub const FIRST_CLUSTER: usize = 24;
    /// Offset of `cluster_count`.
    pub const CLUSTER_COUNT: usize = 28;
    /// Offset of `page`.
    pub const PAGE: usize = 32;
    /// Offset of `reserved` (zero; readers ignore it).
    pub const RESERVED: usize = 36;

    /// The record's bytes.
    pub fn encode(g: &Group) -> [u8; GROUP_RECORD_SIZE] {
        let mut b = [0u8; GROUP_RECORD_SIZE];
        put_f32s(&mut b, Self::CENTER, &g.sphere.center);
        put_f32s(&mut b, Self::RADIUS, &[g.sphere.radius]);
        put_f32s(&mut b, Self::ERROR, &[g.error]);
        put(&mut b, Self::LEVEL, &g.level.to_le_bytes());
        put(&mut b, Self::FIRST_CLUSTER, &g.first_cluster.to_le_bytes());
        put(&mut b, Self::CLUSTER_COUNT, &g.cluster_count.to_le_bytes());
        put(&mut b, Self::PAGE, &g.page.to_le_bytes());
        b
    }

    /// The group a record's bytes describe, unchecked.
    pub fn decode(b: &[u8; GROUP_RECORD_SIZE]) -> Group {
        Group {
            sphere: Sphere { center: f32s_at(b, Self::CENTER), radius: f32::from_bits(u32_at(b, Self::RADIUS)) },
            error: f32::from_bits(u32_at(b, Self::ERROR)),
            level: u32_at(b, Self::LEVEL),
            first_cluster: u32_at(b, Self::FIRST_CLUSTER),
            cluster_count: u32_at(b, Self::CLUSTER_COUNT),
            page: u32_at(b, Self::PAGE),
        }
    }
}

/// The cluster record (FORMAT.md §3.2), stored from and decoded to a [`ClusterInfo`].
pub struct ClusterRecord;

impl ClusterRecord {
    /// Offset of `group`.
    pub const GROUP: usize = 0;
    /// Offset of `own_group`.
    pub const OWN_GROUP: usize = 4;
    /// Offset of `vertex_count`.
    pub const VERTEX_COUNT: usize = 8;
    /// Offset of `triangle_count`.
    pub const TRIANGLE_COUNT: usize = 10;
    /// Offset of `page_offset`.
    pub const PAGE_OFFSET: usize = 12;

    /// The record's bytes.
    pub fn encode(c: &ClusterInfo) -> [u8; CLUSTER_RECORD_SIZE] {
        let mut b = [0u8; CLUSTER_RECORD_SIZE];
        put(&mut b, Self::GROUP, &c.group.to_le_bytes());
        put(&mut b, Self::OWN_GROUP, &c.own_group.to_le_bytes());
        put(&mut b, Self::VERTEX_COUNT, &c.vertex_count.to_le_bytes());
        put(&mut b, Self::TRIANGLE_COUNT, &c.triangle_count.to_le_bytes());
        put(&mut b, Self::PAGE_OFFSET, &c.page_offset.to_le_bytes());
        b
    }

    /// The cluster a record's bytes describe, unchecked.
    pub fn decode(b: &[u8; CLUSTER_RECORD_SIZE]) -> ClusterInfo {
        ClusterInfo {
            group: u32_at(b, Self::GROUP),
            own_group: u32_at(b, Self::OWN_GROUP),
            vertex_count: u16_at(b, Self::VERTEX_COUNT),
            triangle_count: u16_at(b, Self::TRIANGLE_COUNT),
            page_offset: u32_at(b, Self::PAGE_OFFSET),
        }
    }
}

/// The page record (FORMAT.md §4.1), every field as stored. Its dependencies are a range of
/// the dependency array that follows the records (§4.2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PageRecord {
    /// File offset of the compressed bytes.
    pub offset: u64,
    /// Length of the compressed bytes.
    pub compressed_size: u32,
    /// Length after decompression.
    pub raw_size: u32,
    /// BLAKE3 of the compressed bytes.
    pub checksum: [u8; 32],
    /// First cluster stored in the page.
    pub first_cluster: u32,
    /// Clusters stored in the page.
    pub cluster_count: u32,
    /// First group whose members are in the page.
    pub first_group: u32,
    /// Groups in the page.
    pub group_count: u32,
    /// Index of the page's first entry in the dependency array.
    pub dependency_first: u32,
    /// Number of dependency entries.
    pub dependency_count: u32,
}

impl PageRecord {
    /// Offset of `offset`.
    pub const OFFSET: usize = 0;
    /// Offset of `compressed_size`.
    pub const COMPRESSED_SIZE: usize = 8;
    /// Offset of `raw_size`.
    pub const RAW_SIZE: usize = 12;
    /// Offset of `checksum`.
    pub const CHECKSUM: usize = 16;
    /// Offset of `first_cluster`.
    pub const FIRST_CLUSTER: usize = 48;
    /// Offset of `cluster_count`.
    pub const CLUSTER_COUNT: usize = 52;
    /// Offset of `first_group`.
    pub const FIRST_GROUP: usize = 56;
    /// Offset of `group_count`.
    pub const GROUP_COUNT: usize = 60;
    /// Offset of `dependency_first`.
    pub const DEPENDENCY_FIRST: usize = 64;
    /// Offset of `dependency_count`.
    pub const DEPENDENCY_COUNT: usize = 68;

    /// The record's bytes.
    pub fn encode(&self) -> [u8; PAGE_RECORD_SIZE] {
        let mut b = [0u8; PAGE_RECORD_SIZE];
        put(&mut b, Self::OFFSET, &self.offset.to_le_bytes());
        put(&mut b, Self::COMPRESSED_SIZE, &self.compressed_size.to_le_bytes());
        put(&mut b, Self::RAW_SIZE, &self.raw_size.to_le_bytes());
        put(&mut b, Self::CHECKSUM, &self.checksum);
        put(&mut b, Self::FIRST_CLUSTER, &self.first_cluster.to_le_bytes());
        put(&mut b, Self::CLUSTER_COUNT, &self.cluster_count.to_le_bytes());
        put(&mut b, Self::FIRST_GROUP, &self.first_group.to_le_bytes());
        put(&mut b, Self::GROUP_COUNT, &self.group_count.to_le_bytes());
        put(&mut b, Self::DEPENDENCY_FIRST, &self.dependency_first.to_le_bytes());
        put(&mut b, Self::DEPENDENCY_COUNT, &self.dependency_count.to_le_bytes());
        b
    }

    /// The fields of a record's bytes, unchecked.
    pub fn decode(b: &[u8; PAGE_RECORD_SIZE]) -> PageRecord {
        PageRecord {
            offset: u64_at(b, Self::OFFSET),
            compressed_size: u32_at(b, Self::COMPRESSED_SIZE),
            raw_size: u32_at(b, Self::RAW_SIZE),
            checksum: take(b, Self::CHECKSUM),
            first_cluster: u32_at(b, Self::FIRST_CLUSTER),
            cluster_count: u32_at(b, Self::CLUSTER_COUNT),
            first_group: u32_at(b, Self::FIRST_GROUP),
            group_count: u32_at(b, Self::GROUP_COUNT),
            dependency_first: u32_at(b, Self::DEPENDENCY_FIRST),
            dependency_count: u32_at(b, Self::DEPENDENCY_COUNT),
        }
    }
}

/// The cluster header at the start of a decompressed page (FORMAT.md §5.1), every field as
/// stored. Block offsets are relative to the start of the page; 0 means absent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClusterHeader {
    /// Vertices (equals the cluster record's).
    pub vertex_count: u16,
    /// Triangles (equals the cluster record's).
    pub triangle_count: u16,
    /// Per-axis minimum grid coordinate.
    pub position_min: [i32; 3],
    /// Bits per position axis.
    pub position_bits: [u8; 3],
    /// Offsets of the positions, normals, UVs, indices and materials blocks, in that order.
    pub block_offsets: [u32; 5],
    /// Per-coordinate minimum octahedral value.
    pub normal_min: [u16; 2],
    /// Bits per octahedral coordinate.
    pub normal_bits: [u8; 2],
    /// Bit 0 ([`ClusterHeader::OPEN_EDGES`]): an open-edge block follows the indices block.
    pub edge_flags: u8,
}

impl ClusterHeader {
    /// Offset of `vertex_count`.
    pub const VERTEX_COUNT: usize = 0;
    /// Offset of `triangle_count`.
    pub const TRIANGLE_COUNT: usize = 2;
    /// Offset of `position_min`.
    pub const POSITION_MIN: usize = 4;
    /// Offset of `position_bits`.
    pub const POSITION_BITS: usize = 16;
    /// Offset of `positions_offset`, the first of the five block offsets.
    pub const POSITIONS_OFFSET: usize = 20;
    /// Offset of `normal_min`.
    pub const NORMAL_MIN: usize = 40;
    /// Offset of `normal_bits`.
    pub const NORMAL_BITS: usize = 44;
    /// Offset of `edge_flags`.
    pub const EDGE_FLAGS: usize = 19;
    /// `edge_flags` bit: the cluster has an open-edge block (FORMAT.md §5.7).
    pub const OPEN_EDGES: u8 = 1;
    /// Offset of the reserved u16 at the end (zero).
    pub const RESERVED_2: usize = 46;
    /// Index in `block_offsets` of the positions block.
    pub const POSITIONS: usize = 0;
    /// Index in `block_offsets` of the normals block.
    pub const NORMALS: usize = 1;
    /// Index in `block_offsets` of the UVs block.
    pub const UVS: usize = 2;
    /// Index in `block_offsets` of the indices block.
    pub const INDICES: usize = 3;
    /// Index in `block_offsets` of the materials block.
    pub const MATERIALS: usize = 4;

    /// The header's bytes.
    pub fn encode(&self) -> [u8; CLUSTER_HEADER_SIZE] {
        let mut b = [0u8; CLUSTER_HEADER_SIZE];
        put(&mut b, Self::VERTEX_COUNT, &self.vertex_count.to_le_bytes());
        put(&mut b, Self::TRIANGLE_COUNT, &self.triangle_count.to_le_bytes());
        for k in 0..3 {
            put(&mut b, Self::POSITION_MIN + 4 * k, &self.position_min[k].to_le_bytes());
        }
        put(&mut b, Self::POSITION_BITS, &self.position_bits);
        for (k, o) in self.block_offsets.iter().enumerate() {
            put(&mut b, Self::POSITIONS_OFFSET + 4 * k, &o.to_le_bytes());
        }
        for k in 0..2 {
            put(&mut b, Self::NORMAL_MIN + 2 * k, &self.normal_min[k].to_le_bytes());
        }
        put(&mut b, Self::NORMAL_BITS, &self.normal_bits);
        b[Self::EDGE_FLAGS] = self.edge_flags;
        b
    }

    /// The fields of a cluster header's bytes, unchecked.
    pub fn decode(b: &[u8; CLUSTER_HEADER_SIZE]) -> ClusterHeader {
        ClusterHeader {
            vertex_count: u16_at(b, Self::VERTEX_COUNT),
            triangle_count: u16_at(b, Self::TRIANGLE_COUNT),
            position_min: std::array::from_fn(|k| u32_at(b, Self::POSITION_MIN + 4 * k) as i32),
            position_bits: take(b, Self::POSITION_BITS),
            block_offsets: std::array::from_fn(|k| u32_at(b, Self::POSITIONS_OFFSET + 4 * k)),
            normal_min: std::array::from_fn(|k| u16_at(b, Self::NORMAL_MIN + 2 * k)),
            normal_bits: take(b, Self::NORMAL_BITS),
            edge_flags: b[Self::EDGE_FLAGS],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every byte of a record lands in a field: decode then encode gives the bytes back, so
    /// the named offsets neither overlap nor leave gaps the encoder would zero.
    #[test]
    fn records_round_trip_their_bytes() {
        fn pattern<const N: usize>() -> [u8; N] {
            std::array::from_fn(|i| (i * 37 + 11) as u8)
        }
        let h = pattern::<HEADER_SIZE>();
        assert_eq!(HeaderRecord::decode(&h).encode(), h);
        let p = pattern::<PAGE_RECORD_SIZE>();
        assert_eq!(PageRecord::decode(&p).encode(), p);
        let c = pattern::<CLUSTER_RECORD_SIZE>();
        assert_eq!(ClusterRecord::encode(&ClusterRecord::decode(&c)), c);
        // The group record's reserved word is not part of Group: it encodes as zero.
        let mut g = pattern::<GROUP_RECORD_SIZE>();
        g[GroupRecord::RESERVED..].fill(0);
        assert_eq!(GroupRecord::encode(&GroupRecord::decode(&g)), g);
        // Likewise the cluster header's reserved field.
        let mut ch = pattern::<CLUSTER_HEADER_SIZE>();
        ch[ClusterHeader::RESERVED_2..].fill(0);
        assert_eq!(ClusterHeader::decode(&ch).encode(), ch);
    }
}
