//! Reader: parses and checks a `.mres` file. Every offset, length, reference and checksum is
//! checked before use; corrupt input gives a typed [`MresError`], never a panic.

use super::bits::{oct_decode, read_bits};
use super::write::meta_checksum;
use super::*;

/// What is wrong with a `.mres` file.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MresError {
    /// The file ends before a section it declares.
    #[error("truncated: {what} needs bytes {start}..{end} but the file has {len}")]
    Truncated {
        /// The section.
        what: String,
        /// First byte needed.
        start: u64,
        /// One past the last byte needed.
        end: u64,
        /// File length.
        len: u64,
    },
    /// The file could not be read.
    #[error("{0}")]
    Io(String),
    /// Not a `.mres` file.
    #[error("not a .mres file (bad magic)")]
    BadMagic,
    /// A version this reader does not know.
    #[error("unsupported .mres version {found} (this reader reads version {VERSION})")]
    WrongVersion {
        /// Version in the file.
        found: u32,
    },
    /// A checksum does not match.
    #[error("checksum mismatch in {0}")]
    Checksum(String),
    /// A value or reference is out of range or inconsistent.
    #[error("corrupt {0}")]
    Corrupt(String),
    /// A page does not decompress to its declared size.
    #[error("page {page}: {problem}")]
    Decompress {
        /// Page index.
        page: u32,
        /// What went wrong.
        problem: String,
    },
}

/// A parsed `.mres` file: the resident hierarchy plus the raw bytes the pages are read from.
#[derive(Debug, Clone)]
pub struct MresFile {
    /// File-wide parameters.
    pub header: Header,
    /// Groups, coarse to fine.
    pub groups: Vec<Group>,
    /// Clusters, in page order.
    pub clusters: Vec<ClusterInfo>,
    /// Page table.
    pub pages: Vec<PageInfo>,
    bytes: Vec<u8>,
}

/// One decoded cluster.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedCluster {
    /// Positions on the global grid (decode with [`Grid::decode`]).
    pub positions: Vec<[i32; 3]>,
    /// Unit normals (empty without [`FLAG_NORMALS`]).
    pub normals: Vec<[f32; 3]>,
    /// UVs (empty without [`FLAG_UVS`]).
    pub uvs: Vec<[f32; 2]>,
    /// Local triangle indices.
    pub indices: Vec<u8>,
    /// Material per triangle (empty without [`FLAG_MATERIALS`]).
    pub materials: Vec<u16>,
}

/// Bounds-checked little-endian reads from a section of the file.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn u16(&mut self) -> u16 {
        let v = u16::from_le_bytes([self.bytes[self.at], self.bytes[self.at + 1]]);
        self.at += 2;
        v
    }
    fn u32(&mut self) -> u32 {
        let b = &self.bytes[self.at..self.at + 4];
        self.at += 4;
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }
    fn u64(&mut self) -> u64 {
        let lo = self.u32() as u64;
        lo | (self.u32() as u64) << 32
    }
    fn f32(&mut self) -> f32 {
        f32::from_bits(self.u32())
    }
    fn f32s<const N: usize>(&mut self) -> [f32; N] {
        std::array::from_fn(|_| self.f32())
    }
}

/// Returns `bytes[start..start+len]` or a `Truncated` error naming `what`.
fn section<'a>(bytes: &'a [u8], start: u64, len: u64, what: &str) -> Result<&'a [u8], MresError> {
    let end = start.saturating_add(len);
    if end > bytes.len() as u64 {
        return Err(MresError::Truncated { what: what.into(), start, end, len: bytes.len() as u64 });
    }
    Ok(&bytes[start as usize..end as usize])
}

fn corrupt(msg: String) -> MresError {
    MresError::Corrupt(msg)
}

impl MresFile {
    /// Reads and parses a file from disk.
    pub fn open(path: &std::path::Path) -> Result<MresFile, MresError> {
        let bytes = std::fs::read(path).map_err(|e| MresError::Io(e.to_string()))?;
        MresFile::parse(bytes)
    }

    /// Parses the header, hierarchy and page table and checks their consistency and checksum.
    /// Pages are checked when read ([`MresFile::page`]) or all at once ([`MresFile::decode_all`]).
    pub fn parse(bytes: Vec<u8>) -> Result<MresFile, MresError> {
        let head = section(&bytes, 0, HEADER_SIZE as u64, "header")?;
        if head[0..4] != MAGIC {
            return Err(MresError::BadMagic);
        }
        let mut c = Cursor { bytes: head, at: 4 };
        let version = c.u32();
        if version != VERSION {
            return Err(MresError::WrongVersion { found: version });
        }
        let header_size = c.u32();
        if header_size as usize != HEADER_SIZE {
            return Err(corrupt(format!("header: size {header_size}, expected {HEADER_SIZE}")));
        }
        let flags = c.u32();
        let origin = c.f32s::<3>();
        let step = c.f32();
        let uv_min = c.f32s::<2>();
        let uv_extent = c.f32s::<2>();
        let normal_bits = c.u32();
        let position_bits = c.u32();
        let level_count = c.u32();
        let group_count = c.u32();
        let cluster_count = c.u32();
        let page_count = c.u32();
        let source_triangles = c.u64();
        let hierarchy_offset = c.u64();
        let hierarchy_size = c.u64();
        let page_table_offset = c.u64();
        let page_table_size = c.u64();
        let stored_checksum: [u8; 32] = head[112..144].try_into().map_err(|_| corrupt("header".into()))?;
        if head[144..HEADER_SIZE].iter().any(|&b| b != 0) {
            return Err(corrupt("header: reserved bytes are not zero".into()));
        }

        if flags & !(FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS) != 0 {
            return Err(corrupt(format!("header: unknown flags {flags:#x}")));
        }
        if !(step.is_finite() && step > 0.0 && origin.iter().chain(&uv_min).chain(&uv_extent).all(|v| v.is_finite())) {
            return Err(corrupt("header: non-finite or non-positive quantization parameters".into()));
        }
        if flags & FLAG_NORMALS != 0 && !(4..=16).contains(&normal_bits) {
            return Err(corrupt(format!("header: normal_bits {normal_bits} outside 4..=16")));
        }
        let expected_hierarchy =
            group_count as u64 * GROUP_RECORD_SIZE as u64 + cluster_count as u64 * CLUSTER_RECORD_SIZE as u64;
        if hierarchy_offset != HEADER_SIZE as u64 || hierarchy_size != expected_hierarchy {
            return Err(corrupt(format!(
                "header: hierarchy at {hierarchy_offset} size {hierarchy_size}, expected {HEADER_SIZE} and {expected_hierarchy}"
            )));
        }
        if page_table_offset != hierarchy_offset + hierarchy_size {
            return Err(corrupt("header: page table does not follow the hierarchy".into()));
        }
        let min_table = page_count as u64 * PAGE_RECORD_SIZE as u64;
        if page_table_size < min_table || !(page_table_size - min_table).is_multiple_of(4) {
            return Err(corrupt(format!("header: page table size {page_table_size} for {page_count} pages")));
        }
        let hierarchy = section(&bytes, hierarchy_offset, hierarchy_size, "hierarchy")?;
        let table = section(&bytes, page_table_offset, page_table_size, "page table")?;
        if meta_checksum(head, hierarchy, table) != stored_checksum {
            return Err(MresError::Checksum("header, hierarchy or page table".into()));
        }
        let pages_start = page_table_offset + page_table_size;

        let mut c = Cursor { bytes: hierarchy, at: 0 };
        let mut groups = Vec::with_capacity(group_count as usize);
        for g in 0..group_count {
            let center = c.f32s::<3>();
            let [radius, error] = c.f32s::<2>();
            let (level, first_cluster, count, page, _reserved) = (c.u32(), c.u32(), c.u32(), c.u32(), c.u32());
            let finite = center.iter().all(|v| v.is_finite()) && radius.is_finite() && radius >= 0.0;
            if !finite || error.is_nan() || error < 0.0 {
                return Err(corrupt(format!("group {g}: bad sphere or error")));
            }
            if count == 0
                || first_cluster as u64 + count as u64 > cluster_count as u64
                || page >= page_count
                || level >= level_count
            {
                return Err(corrupt(format!("group {g}: cluster range, page or level out of range")));
            }
            groups.push(Group {
                sphere: Sphere { center, radius },
                error,
                level,
                first_cluster,
                cluster_count: count,
                page,
            });
        }
        let mut clusters = Vec::with_capacity(cluster_count as usize);
        for i in 0..cluster_count {
            let (group, own_group) = (c.u32(), c.u32());
            let (vertex_count, triangle_count) = (c.u16(), c.u16());
            let page_offset = c.u32();
            let in_group = groups
                .get(group as usize)
                .is_some_and(|g| (g.first_cluster..g.first_cluster + g.cluster_count).contains(&i));
            if !in_group || (own_group != NO_GROUP && own_group >= group_count) {
                return Err(corrupt(format!("cluster {i}: group reference out of range")));
            }
            if vertex_count == 0
                || vertex_count as usize > MAX_CLUSTER_VERTICES
                || triangle_count == 0
                || triangle_count as usize > MAX_CLUSTER_TRIANGLES
            {
                return Err(corrupt(format!("cluster {i}: {vertex_count} vertices, {triangle_count} triangles")));
            }
            clusters.push(ClusterInfo { group, own_group, vertex_count, triangle_count, page_offset });
        }

        let mut c = Cursor { bytes: table, at: 0 };
        let dep_count = (page_table_size - min_table) / 4;
        let mut pages = Vec::with_capacity(page_count as usize);
        let mut raw_records = Vec::with_capacity(page_count as usize);
        for p in 0..page_count {
            let offset = c.u64();
            let (compressed_size, raw_size) = (c.u32(), c.u32());
            let checksum: [u8; 32] = std::array::from_fn(|_| {
                c.at += 1;
                table[c.at - 1]
            });
            let (first_cluster, count, first_group, group_count_here, dep_first, deps) =
                (c.u32(), c.u32(), c.u32(), c.u32(), c.u32(), c.u32());
            let end = offset.checked_add(compressed_size as u64);
            if offset < pages_start || end.is_none_or(|e| e > bytes.len() as u64) {
                return Err(MresError::Truncated {
                    what: format!("page {p}"),
                    start: offset,
                    end: end.unwrap_or(u64::MAX),
                    len: bytes.len() as u64,
                });
            }
            if raw_size as usize > MAX_PAGE_RAW_SIZE {
                return Err(corrupt(format!(
                    "page {p}: claims {raw_size} decompressed bytes (limit {MAX_PAGE_RAW_SIZE})"
                )));
            }
            let clusters_ok = first_cluster as u64 + count as u64 <= cluster_count as u64;
            let groups_ok = first_group as u64 + group_count_here as u64 <= group_count as u64;
            if !clusters_ok || !groups_ok || dep_first as u64 + deps as u64 > dep_count {
                return Err(corrupt(format!("page {p}: cluster, group or dependency range out of range")));
            }
            raw_records.push((dep_first, deps));
            pages.push(PageInfo {
                offset,
                compressed_size,
                raw_size,
                checksum,
                first_cluster,
                cluster_count: count,
                first_group,
                group_count: group_count_here,
                dependencies: Vec::new(),
            });
        }
        for (p, (dep_first, deps)) in raw_records.into_iter().enumerate() {
            let mut list = Vec::with_capacity(deps as usize);
            c.at = PAGE_RECORD_SIZE * page_count as usize + dep_first as usize * 4;
            for _ in 0..deps {
                let d = c.u32();
                if d >= page_count {
                    return Err(corrupt(format!("page {p}: dependency {d} out of range")));
                }
                list.push(d);
            }
            pages[p].dependencies = list;
        }
        // Group ranges tile the clusters in order; pages tile the page data.
        let mut next_cluster = 0u64;
        for (g, group) in groups.iter().enumerate() {
            if group.first_cluster as u64 != next_cluster {
                return Err(corrupt(format!("group {g}: clusters do not follow the previous group's")));
            }
            next_cluster += group.cluster_count as u64;
        }
        if next_cluster != cluster_count as u64 {
            return Err(corrupt("groups do not cover every cluster".into()));
        }
        let mut next_offset = pages_start;
        for (p, page) in pages.iter().enumerate() {
            if page.offset != next_offset {
                return Err(corrupt(format!(
                    "page {p}: data at {} but the previous page ends at {next_offset}",
                    page.offset
                )));
            }
            next_offset += page.compressed_size as u64;
        }
        if next_offset != bytes.len() as u64 {
            return Err(corrupt(format!("page data ends at {next_offset} but the file has {} bytes", bytes.len())));
        }
        // Each group's clusters must lie in the page it names.
        for (g, group) in groups.iter().enumerate() {
            let page = &pages[group.page as usize];
            let inside = group.first_cluster >= page.first_cluster
                && group.first_cluster + group.cluster_count <= page.first_cluster + page.cluster_count;
            if !inside {
                return Err(corrupt(format!("group {g}: clusters not within page {}", group.page)));
            }
        }

        let header = Header {
            flags,
            grid: Grid { origin, step },
            uv: UvQuant { min: uv_min, extent: uv_extent },
            normal_bits,
            position_bits,
            level_count,
            source_triangles,
        };
        Ok(MresFile { header, groups, clusters, pages, bytes })
    }

    /// Total file size in bytes.
    pub fn file_size(&self) -> usize {
        self.bytes.len()
    }

    /// Verifies page `p`'s checksum and returns its decompressed bytes (the GPU layout).
    pub fn page(&self, p: u32) -> Result<Vec<u8>, MresError> {
        let info = self.pages.get(p as usize).ok_or_else(|| corrupt(format!("page {p} does not exist")))?;
        let frame = section(&self.bytes, info.offset, info.compressed_size as u64, &format!("page {p}"))?;
        if blake3::hash(frame).as_bytes() != &info.checksum {
            return Err(MresError::Checksum(format!("page {p}")));
        }
        let raw = zstd::bulk::decompress(frame, info.raw_size as usize)
            .map_err(|e| MresError::Decompress { page: p, problem: e.to_string() })?;
        if raw.len() != info.raw_size as usize {
            return Err(MresError::Decompress {
                page: p,
                problem: format!("{} bytes, table says {}", raw.len(), info.raw_size),
            });
        }
        Ok(raw)
    }

    /// Decodes cluster `index` from its page's decompressed bytes.
    pub fn decode_cluster(&self, page_raw: &[u8], index: u32) -> Result<DecodedCluster, MresError> {
        let info =
            self.clusters.get(index as usize).ok_or_else(|| corrupt(format!("cluster {index} does not exist")))?;
        decode_cluster(&self.header, page_raw, info, index)
    }

    /// Reads every page and decodes every cluster, in cluster order.
    pub fn decode_all(&self) -> Result<Vec<DecodedCluster>, MresError> {
        let mut out = Vec::with_capacity(self.clusters.len());
        for (p, page) in self.pages.iter().enumerate() {
            let raw = self.page(p as u32)?;
            for c in page.first_cluster..page.first_cluster + page.cluster_count {
                out.push(self.decode_cluster(&raw, c)?);
            }
        }
        if out.len() != self.clusters.len() {
            return Err(corrupt(format!("pages hold {} clusters, hierarchy has {}", out.len(), self.clusters.len())));
        }
        Ok(out)
    }
}

fn decode_cluster(h: &Header, raw: &[u8], info: &ClusterInfo, index: u32) -> Result<DecodedCluster, MresError> {
    let bad = |what: &str| corrupt(format!("cluster {index}: {what}"));
    let head = section(raw, info.page_offset as u64, CLUSTER_HEADER_SIZE as u64, &format!("cluster {index} header"))?;
    let mut c = Cursor { bytes: head, at: 0 };
    let (vertex_count, triangle_count) = (c.u16() as usize, c.u16() as usize);
    if vertex_count != info.vertex_count as usize || triangle_count != info.triangle_count as usize {
        return Err(bad("counts differ from the hierarchy"));
    }
    let lo = [c.u32() as i32, c.u32() as i32, c.u32() as i32];
    let bits = [head[16] as u32, head[17] as u32, head[18] as u32];
    c.at = 20;
    let offsets: [u32; 5] = std::array::from_fn(|_| c.u32());
    if bits.iter().any(|&b| b > 32) {
        return Err(bad("position bit width over 32"));
    }
    let block = |slot: usize, len: u64, what: &str| -> Result<&[u8], MresError> {
        if offsets[slot] == 0 {
            return Err(bad(&format!("{what} missing")));
        }
        section(raw, offsets[slot] as u64, len, &format!("cluster {index} {what}"))
    };
    let stride: u64 = bits.iter().map(|&b| b as u64).sum();
    let pos_bytes = block(0, (vertex_count as u64 * stride).div_ceil(32) * 4, "positions")?;
    let mut positions = Vec::with_capacity(vertex_count);
    for v in 0..vertex_count as u64 {
        let mut p = [0i32; 3];
        let mut at = v * stride;
        for k in 0..3 {
            let d = read_bits(pos_bytes, at, bits[k]).ok_or_else(|| bad("positions"))?;
            p[k] = i32::try_from(lo[k] as i64 + d as i64).map_err(|_| bad("position overflows i32"))?;
            at += bits[k] as u64;
        }
        positions.push(p);
    }
    let mut normals = Vec::new();
    if h.flags & FLAG_NORMALS != 0 {
        let nlo = [u16::from_le_bytes([head[40], head[41]]) as u32, u16::from_le_bytes([head[42], head[43]]) as u32];
        let nbits = [head[44] as u32, head[45] as u32];
        if nbits.iter().any(|&b| b > h.normal_bits) {
            return Err(bad("normal bit width over the header's normal_bits"));
        }
        let stride = (nbits[0] + nbits[1]) as u64;
        let bytes = block(1, (vertex_count as u64 * stride).div_ceil(32) * 4, "normals")?;
        for v in 0..vertex_count as u64 {
            let x = read_bits(bytes, v * stride, nbits[0]).ok_or_else(|| bad("normals"))?;
            let y = read_bits(bytes, v * stride + nbits[0] as u64, nbits[1]).ok_or_else(|| bad("normals"))?;
            normals.push(oct_decode([nlo[0] + x, nlo[1] + y], h.normal_bits));
        }
    }
    let mut uvs = Vec::new();
    if h.flags & FLAG_UVS != 0 {
        let bytes = block(2, vertex_count as u64 * 4, "uvs")?;
        for q in bytes.chunks_exact(4) {
            uvs.push(h.uv.decode([u16::from_le_bytes([q[0], q[1]]), u16::from_le_bytes([q[2], q[3]])]));
        }
    }
    let indices = block(3, triangle_count as u64 * 3, "indices")?.to_vec();
    if indices.iter().any(|&i| i as usize >= vertex_count) {
        return Err(bad("local index out of range"));
    }
    let mut materials = Vec::new();
    if h.flags & FLAG_MATERIALS != 0 {
        let bytes = block(4, triangle_count as u64 * 2, "materials")?;
        materials = bytes.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect();
    }
    Ok(DecodedCluster { positions, normals, uvs, indices, materials })
}
