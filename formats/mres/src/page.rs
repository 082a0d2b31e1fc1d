//! Pages: checking, decompressing and decoding a page's bytes (FORMAT.md §4.3) to the GPU
//! layout, and decoding its clusters from the GPU layout (§5). The whole-file reader and the page-level API both decode here.

use super::bits::{oct_decode, read_bits};
use super::codec;
use super::decode;
use super::error::{corrupt, section, MresError};
use super::layout_pages;
use super::records::ClusterHeader;
use super::write;
use super::*;
use std::cell::RefCell;

/// One page, checked and decompressed: its bytes in the GPU layout (FORMAT.md §5), uploaded as
/// is, and the same clusters decoded.
///
/// Every cluster of the page has been checked (counts against its record, bit widths, blocks
/// inside the page, local indices in range), so a renderer may read the bytes through the
/// headers' offsets without further checks.
#[derive(Clone, Debug, PartialEq)]
pub struct Page {
    /// Page index in the page table.
    pub index: u32,
    /// Index of the page's first cluster; cluster `first_cluster + i` has header `headers[i]`
    /// at byte `i * CLUSTER_HEADER_SIZE` of `bytes`.
    pub first_cluster: u32,
    /// The decompressed page.
    pub bytes: Vec<u8>,
    /// The cluster headers at the start of `bytes`, one per cluster, in cluster order.
    pub headers: Vec<ClusterHeader>,
    /// The clusters decoded: grid positions, normals, UVs, indices and materials.
    pub clusters: Vec<DecodedCluster>,
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
    /// Open-edge marks, one per triangle (bit k: the edge from corner k to corner (k+1) mod 3
    /// is marked; all zero when the cluster has no open-edge block).
    pub open_edges: Vec<u8>,
}

/// Page `p`'s sources (FORMAT.md §4.3): its dependencies stored before it, in order; none
/// in a file of layout pages (`flags` with [`FLAG_LAYOUT_PAGES`], §4.4).
pub(crate) fn sources(flags: u32, info: &PageInfo, p: u32) -> impl Iterator<Item = u32> + '_ {
    let layout_pages = flags & FLAG_LAYOUT_PAGES != 0;
    info.dependencies.iter().copied().filter(move |&d| d < p && !layout_pages)
}

/// Checks page `p`'s compressed bytes against its table entry (length, then checksum),
/// decompresses them to the page's encoded bytes and decodes those (FORMAT.md §4.3) to the GPU
/// layout (§5), which must be exactly `raw_size` bytes; `clusters` and `pages` are the whole
/// file's, `layouts` the GPU layouts of page `p`'s sources, in order: their count and each
/// one's length are checked against the page table (none at all: enough for a page without
/// far copies).
pub(crate) fn decompress_page(
    header: &Header,
    clusters: &[ClusterInfo],
    pages: &[PageInfo],
    p: u32,
    compressed: &[u8],
    layouts: &[&[u8]],
) -> Result<Vec<u8>, MresError> {
    let info = pages.get(p as usize).ok_or_else(|| corrupt(format!("page {p} does not exist")))?;
    if compressed.len() as u64 != info.compressed_size as u64 {
        return Err(MresError::PageLength { page: p, len: compressed.len() as u64, expected: info.compressed_size });
    }
    if blake3::hash(compressed).as_bytes() != &info.checksum {
        return Err(MresError::Checksum(format!("page {p}")));
    }
    let records = page_records(clusters, info, p)?;
    if header.flags & FLAG_LAYOUT_PAGES != 0 {
        if !layouts.is_empty() {
            return Err(MresError::SourceCount { page: p, given: layouts.len(), expected: 0 });
        }
        return layout_pages::decompress(header, records, info.first_cluster, p, compressed, info.raw_size as usize);
    }
    let sources = source_pages(header.flags, clusters, pages, p, layouts)?;
    // The counts bound the encoded size before anything is allocated; the capacity bounds the
    // output: zstd fails rather than write more.
    let most = codec::max_encoded_len(header.flags, records);
    if most > MAX_PAGE_ENCODED_SIZE {
        return Err(corrupt(format!(
            "page {p}: its clusters could encode to {most} bytes (limit {MAX_PAGE_ENCODED_SIZE})"
        )));
    }
    let problem = |problem: String| MresError::Decompress { page: p, problem };
    ZSTD.with(|cell| {
        let mut cell = cell.borrow_mut();
        if cell.is_none() {
            *cell = Some((zstd::bulk::Decompressor::new().map_err(|e| problem(e.to_string()))?, Vec::new()));
        }
        let Some((zstd, encoded)) = cell.as_mut() else { return Err(problem("no zstd context".into())) };
        encoded.clear();
        encoded.reserve(most);
        zstd.decompress_to_buffer(compressed, encoded).map_err(|e| problem(e.to_string()))?;
        let raw_size = info.raw_size as usize;
        decode::decode_page_gpu(encoded, records, header.flags, header.normal_bits, raw_size, sources.as_deref())
            .map_err(|e| match e.0.as_str() {
                decode::NEEDS_SOURCES => {
                    MresError::SourceCount { page: p, given: 0, expected: sources_of(header.flags, info, p) }
                }
                _ => problem(e.0),
            })
    })
}

thread_local! {
    /// A zstd context and a buffer for a page's encoded bytes, reused from page to page: a
    /// fresh context per page costs more than decompressing a small page.
    static ZSTD: RefCell<Option<(zstd::bulk::Decompressor<'static>, Vec<u8>)>> = const { RefCell::new(None) };
}

/// The number of page `p`'s sources.
fn sources_of(flags: u32, info: &PageInfo, p: u32) -> usize {
    sources(flags, info, p).count()
}

/// Page `p`'s sources as the decoder reads them: `layouts`, checked to be one per source and
/// each as long as its page's `raw_size`, with their pages' cluster records; `None` if none
/// are given (a page without far copies decodes alone: FORMAT.md §4.3).
fn source_pages<'a>(
    flags: u32,
    clusters: &'a [ClusterInfo],
    pages: &'a [PageInfo],
    p: u32,
    layouts: &[&'a [u8]],
) -> Result<Option<Vec<decode::SourcePage<'a>>>, MresError> {
    let info = &pages[p as usize];
    let expected = sources_of(flags, info, p);
    if layouts.is_empty() {
        return Ok(None);
    }
    if layouts.len() != expected {
        return Err(MresError::SourceCount { page: p, given: layouts.len(), expected });
    }
    sources(flags, info, p)
        .zip(layouts)
        .map(|(s, &layout)| {
            let source = pages.get(s as usize).ok_or_else(|| corrupt(format!("page {p}: source {s} out of range")))?;
            if layout.len() != source.raw_size as usize {
                return Err(MresError::SourceLength {
                    page: p,
                    source_page: s,
                    len: layout.len(),
                    expected: source.raw_size,
                });
            }
            Ok(decode::SourcePage { index: s, layout, records: page_records(clusters, source, s)? })
        })
        .collect::<Result<_, _>>()
        .map(Some)
}

/// The records of page `p`'s clusters.
fn page_records<'a>(clusters: &'a [ClusterInfo], info: &PageInfo, p: u32) -> Result<&'a [ClusterInfo], MresError> {
    let first = info.first_cluster as usize;
    clusters
        .get(first..first + info.cluster_count as usize)
        .ok_or_else(|| corrupt(format!("page {p}: cluster range out of range")))
}

/// Decodes every cluster of page `p` from its GPU layout `bytes` (as [`decompress_page`]
/// gives it); `clusters` is the whole file's.
pub(crate) fn page_from_layout(
    header: &Header,
    clusters: &[ClusterInfo],
    info: &PageInfo,
    p: u32,
    bytes: Vec<u8>,
) -> Result<Page, MresError> {
    let records = page_records(clusters, info, p)?;
    let mut headers = Vec::with_capacity(records.len());
    let mut decoded = Vec::with_capacity(records.len());
    for (i, record) in records.iter().enumerate() {
        let (head, cluster) = read_cluster(header, &bytes, record, info.first_cluster + i as u32)?;
        headers.push(head);
        decoded.push(cluster);
    }
    check_open_blocks(&headers, p)?;
    if header.flags & FLAG_LAYOUT_PAGES != 0 {
        let not_canonical = |i: usize, what: &str| {
            let c = info.first_cluster as usize + i;
            corrupt(format!(
                "page {p}: cluster {c}: {what}: not the layout the writer lays its values out to (FORMAT.md §4.4)"
            ))
        };
        let again = write::relaid(&bytes, &headers, header.flags, header.normal_bits)
            .map_err(|(i, what)| not_canonical(i, what))?;
        if again != bytes {
            let at = again.iter().zip(&bytes).position(|(a, b)| a != b).unwrap_or(again.len().min(bytes.len()));
            return Err(not_canonical(
                cluster_at(&headers, at),
                &format!("byte {at} differs (minima or bit widths not exact)"),
            ));
        }
    }
    Ok(Page { index: p, first_cluster: info.first_cluster, bytes, headers, clusters: decoded })
}

/// The page's cluster whose header or block holds byte `at` of a canonical layout.
fn cluster_at(headers: &[ClusterHeader], at: usize) -> usize {
    if at < CLUSTER_HEADER_SIZE * headers.len() {
        return at / CLUSTER_HEADER_SIZE;
    }
    let starts = headers.iter().enumerate().flat_map(|(i, h)| h.block_offsets.iter().map(move |&o| (o as usize, i)));
    starts.filter(|&(o, _)| o != 0 && o <= at).max().map_or(0, |(_, i)| i)
}

/// The byte range of each data block of the cluster with header `c` (FORMAT.md §5), and
/// whether it is its open-edge block.
fn block_ranges(c: &ClusterHeader) -> Vec<(u64, u64, bool)> {
    let (v, t) = (c.vertex_count as u64, c.triangle_count as u64);
    let words = |bits: u64| bits.div_ceil(32) * 4;
    let position_bits: u64 = c.position_bits.iter().map(|&b| b as u64).sum();
    let normal_bits: u64 = c.normal_bits.iter().map(|&b| b as u64).sum();
    let lengths = [words(v * position_bits), words(v * normal_bits), v * 4, 3 * t, 2 * t];
    let mut out: Vec<(u64, u64, bool)> = c
        .block_offsets
        .iter()
        .zip(lengths)
        .filter(|(&o, _)| o != 0)
        .map(|(&o, len)| (o as u64, o as u64 + len, false))
        .collect();
    if c.edge_flags & ClusterHeader::OPEN_EDGES != 0 {
        let start = c.block_offsets[ClusterHeader::INDICES] as u64 + (3 * t).next_multiple_of(4);
        out.push((start, start + words(3 * t), true));
    }
    out
}

/// An open-edge block, which no offset field points to, must not overlap any other block of
/// the page (FORMAT.md §7): otherwise another cluster's data would read as marks.
fn check_open_blocks(headers: &[ClusterHeader], p: u32) -> Result<(), MresError> {
    let mut ranges: Vec<(u64, u64, bool)> = headers.iter().flat_map(block_ranges).collect();
    if !ranges.iter().any(|r| r.2) {
        return Ok(());
    }
    ranges.sort_unstable();
    let mut end = 0u64;
    let mut end_open = false;
    for &(start, stop, open) in &ranges {
        if start < end && (open || end_open) && stop > start {
            return Err(corrupt(format!("page {p}: an open-edge block overlaps another block")));
        }
        if stop > end {
            (end, end_open) = (stop, open);
        }
    }
    Ok(())
}

/// Reads cluster `index` (whose record is `info`) from its decompressed page `raw`: its
/// header, checked, and its decoded data.
pub(crate) fn read_cluster(
    h: &Header,
    raw: &[u8],
    info: &ClusterInfo,
    index: u32,
) -> Result<(ClusterHeader, DecodedCluster), MresError> {
    let head = cluster_header(h, raw, info, index)?;
    let blocks = Blocks { h, raw, head: &head, index };
    let cluster = DecodedCluster {
        positions: blocks.positions()?,
        normals: if h.flags & FLAG_NORMALS != 0 { blocks.normals()? } else { Vec::new() },
        uvs: if h.flags & FLAG_UVS != 0 { blocks.uvs()? } else { Vec::new() },
        indices: blocks.indices()?,
        materials: if h.flags & FLAG_MATERIALS != 0 { blocks.materials()? } else { Vec::new() },
        open_edges: blocks.open_edges()?,
    };
    Ok((head, cluster))
}

/// The header of cluster `index` at its record's `page_offset`, with counts equal to the
/// record's and bit widths within their limits.
fn cluster_header(h: &Header, raw: &[u8], info: &ClusterInfo, index: u32) -> Result<ClusterHeader, MresError> {
    let bytes = section(raw, info.page_offset as u64, CLUSTER_HEADER_SIZE as u64, &format!("cluster {index} header"))?;
    let bytes = bytes.first_chunk::<CLUSTER_HEADER_SIZE>().ok_or_else(|| corrupt(format!("cluster {index} header")))?;
    let head = ClusterHeader::decode(bytes);
    layout_pages::header_limits(h, info, &head).map_err(|what| corrupt(format!("cluster {index}: {what}")))?;
    Ok(head)
}

/// The data blocks of one cluster, each checked to lie inside the page before it is read.
struct Blocks<'a> {
    h: &'a Header,
    raw: &'a [u8],
    head: &'a ClusterHeader,
    index: u32,
}

impl Blocks<'_> {
    fn bad(&self, what: &str) -> MresError {
        corrupt(format!("cluster {}: {what}", self.index))
    }

    /// The `len` bytes of block `slot` (an index of [`ClusterHeader::block_offsets`]).
    fn block(&self, slot: usize, len: u64, what: &str) -> Result<&[u8], MresError> {
        let offset = self.head.block_offsets[slot];
        if offset == 0 {
            return Err(self.bad(&format!("{what} missing")));
        }
        section(self.raw, offset as u64, len, &format!("cluster {} {what}", self.index))
    }

    fn vertex_count(&self) -> u64 {
        self.head.vertex_count as u64
    }

    /// A bit stream of `vertex_count` records of the given field widths (FORMAT.md §5.2).
    fn bit_records<const N: usize>(&self, slot: usize, bits: [u32; N], what: &str) -> Result<Vec<[u32; N]>, MresError> {
        let stride: u64 = bits.iter().map(|&b| b as u64).sum();
        let bytes = self.block(slot, (self.vertex_count() * stride).div_ceil(32) * 4, what)?;
        let mut out = Vec::with_capacity(self.vertex_count() as usize);
        for v in 0..self.vertex_count() {
            let mut at = v * stride;
            let mut record = [0u32; N];
            for k in 0..N {
                record[k] = read_bits(bytes, at, bits[k]).ok_or_else(|| self.bad(what))?;
                at += bits[k] as u64;
            }
            out.push(record);
        }
        Ok(out)
    }

    fn positions(&self) -> Result<Vec<[i32; 3]>, MresError> {
        let deltas = self.bit_records(ClusterHeader::POSITIONS, self.head.position_bits.map(u32::from), "positions")?;
        let lo = self.head.position_min;
        let add = |k: usize, d: u32| i32::try_from(lo[k] as i64 + d as i64);
        deltas
            .iter()
            .map(|d| Ok([add(0, d[0])?, add(1, d[1])?, add(2, d[2])?]))
            .collect::<Result<_, std::num::TryFromIntError>>()
            .map_err(|_| self.bad("position overflows i32"))
    }

    fn normals(&self) -> Result<Vec<[f32; 3]>, MresError> {
        let lo = self.head.normal_min.map(u32::from);
        let values = self.bit_records(ClusterHeader::NORMALS, self.head.normal_bits.map(u32::from), "normals")?;
        Ok(values.iter().map(|q| oct_decode([lo[0] + q[0], lo[1] + q[1]], self.h.normal_bits)).collect())
    }

    fn uvs(&self) -> Result<Vec<[f32; 2]>, MresError> {
        let bytes = self.block(ClusterHeader::UVS, self.vertex_count() * 4, "uvs")?;
        let (quads, _) = bytes.as_chunks::<4>();
        Ok(quads
            .iter()
            .map(|q| self.h.uv.decode([u16::from_le_bytes([q[0], q[1]]), u16::from_le_bytes([q[2], q[3]])]))
            .collect())
    }

    fn indices(&self) -> Result<Vec<u8>, MresError> {
        let indices = self.block(ClusterHeader::INDICES, self.head.triangle_count as u64 * 3, "indices")?;
        if indices.iter().any(|&i| i as u16 >= self.head.vertex_count) {
            return Err(self.bad("local index out of range"));
        }
        Ok(indices.to_vec())
    }

    /// The open-edge block right after the indices block's padding (FORMAT.md §5.7): 3 bits per triangle, the last word's unused bits zero.
    fn open_edges(&self) -> Result<Vec<u8>, MresError> {
        let triangles = self.head.triangle_count as u64;
        if self.head.edge_flags & ClusterHeader::OPEN_EDGES == 0 {
            return Ok(vec![0; triangles as usize]);
        }
        let start = self.head.block_offsets[ClusterHeader::INDICES] as u64 + (triangles * 3).next_multiple_of(4);
        let len = (triangles * 3).div_ceil(32) * 4;
        let bytes = section(self.raw, start, len, &format!("cluster {} open edges", self.index))?;
        let marks: Vec<u8> = (0..triangles)
            .map(|t| read_bits(bytes, t * 3, 3).map(|m| m as u8).ok_or_else(|| self.bad("open edges")))
            .collect::<Result<_, _>>()?;
        let used = triangles * 3;
        if read_bits(bytes, used, (len * 8 - used) as u32 % 32).is_some_and(|rest| rest != 0) {
            return Err(self.bad("open edges: unused bits are not zero"));
        }
        Ok(marks)
    }

    fn materials(&self) -> Result<Vec<u16>, MresError> {
        let bytes = self.block(ClusterHeader::MATERIALS, self.head.triangle_count as u64 * 2, "materials")?;
        let (pairs, _) = bytes.as_chunks::<2>();
        Ok(pairs.iter().map(|&b| u16::from_le_bytes(b)).collect())
    }
}
