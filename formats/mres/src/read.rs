//! Reader: parses and checks a `.mres` file, whole ([`MresFile`]) or as its resident prefix
//! ([`MresIndex`]) with pages fetched by the caller ([`MresIndex::decode_page`]). Both use the
//! same steps: decode the records ([`crate::records`]), then check them. Every offset,
//! length, reference and checksum is checked before use; corrupt input gives a typed
//! [`MresError`], never a panic.

pub use super::error::MresError;
use super::error::{corrupt, section};
use super::page::{decompress_page, page_from_layout, read_cluster, sources, Page};
use super::records::{meta_checksum, ClusterRecord, GroupRecord, HeaderRecord, PageRecord};
use super::*;
use std::ops::Range;
use std::sync::OnceLock;

/// The resident part of a `.mres` file — header, hierarchy and page table — parsed and checked
/// from a prefix of the file, for a streamer that fetches pages itself.
///
/// The prefix runs from byte 0 to the first page. Its length is in the fixed-size header:
/// read [`HEADER_SIZE`] bytes and pass them to [`MresIndex::prefix_len`]. (A prefix that is
/// too short also gives [`MresError::Truncated`], whose `end` is the length needed.) Page `p`
/// is then the byte range [`MresIndex::page_range`] of the file, and
/// [`MresIndex::decode_page`] checks and decodes it, given the GPU layouts of its sources
/// ([`MresIndex::page_sources`]: pages stored before it, which a streamer loading in file
/// order has decoded already).
///
/// ```
/// # fn main() -> Result<(), mres_format::MresError> {
/// # let file = mres_format::write_mres(&mres_format::Dag::sample(), 3).expect("writes");
/// use mres_format::{MresIndex, HEADER_SIZE};
/// // Stands for reading a byte range of the file from disk or the network.
/// let fetch = |r: std::ops::Range<u64>| file[r.start as usize..r.end as usize].to_vec();
///
/// let prefix_len = MresIndex::prefix_len(&fetch(0..HEADER_SIZE as u64))?;
/// let index = MresIndex::parse(&fetch(0..prefix_len))?;
/// assert_eq!(index.file_size(), file.len() as u64);
/// // Pages are stored coarse to fine: page 0 holds the root.
/// assert!(index.page_sources(0)?.is_empty());
/// let page = index.decode_page(0, &fetch(index.page_range(0)?), &[])?;
/// for (i, cluster) in page.clusters.iter().enumerate() {
///     let record = &index.clusters[page.first_cluster as usize + i];
///     assert_eq!(cluster.indices.len(), 3 * record.triangle_count as usize);
/// }
/// // The GPU layout: cluster headers, then data blocks at the headers' offsets.
/// assert_eq!(page.bytes.len(), index.pages[0].raw_size as usize);
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct MresIndex {
    /// File-wide parameters.
    pub header: Header,
    /// Groups, coarse to fine.
    pub groups: Vec<Group>,
    /// Clusters, in page order.
    pub clusters: Vec<ClusterInfo>,
    /// Page table.
    pub pages: Vec<PageInfo>,
    /// End of the last page: the length of the whole file.
    file_size: u64,
}

impl MresIndex {
    /// The length of the resident prefix (header, hierarchy and page table; the file offset of
    /// the first page), from the start of the file: at least its first [`HEADER_SIZE`] bytes.
    /// The header's fields are checked; a shorter `start` gives [`MresError::Truncated`].
    pub fn prefix_len(start: &[u8]) -> Result<u64, MresError> {
        let (record, _) = read_header(start)?;
        Ok(record.prefix_len().unwrap_or(u64::MAX))
    }

    /// Parses and checks the header, hierarchy and page table from `prefix`, the first
    /// [`MresIndex::prefix_len`] bytes of the file (or more: the rest is ignored).
    pub fn parse(prefix: &[u8]) -> Result<MresIndex, MresError> {
        let (r, head) = read_header(prefix)?;
        let resident_len = r.prefix_len().unwrap_or(u64::MAX);
        let resident = section(prefix, 0, resident_len, "header, hierarchy and page table")?;
        // read_header checked that the hierarchy follows the header and the table follows it,
        // with sizes that hold the records the header counts.
        let (hierarchy, table) = split(&resident[HEADER_SIZE..], r.hierarchy_size, "hierarchy")?;
        if meta_checksum(head, hierarchy, table) != r.meta_checksum {
            return Err(MresError::Checksum("header, hierarchy or page table".into()));
        }
        let group_bytes = r.group_count as u64 * GROUP_RECORD_SIZE as u64;
        let (group_bytes, cluster_bytes) = split(hierarchy, group_bytes, "group records")?;
        let groups = decode_groups(group_bytes, &r)?;
        let clusters = decode_clusters(cluster_bytes, &groups)?;
        let pages = decode_page_table(table, &r)?;
        check_group_tiling(&groups, clusters.len())?;
        let file_size = check_page_tiling(&pages, resident_len)?;
        check_group_pages(&groups, &clusters, &pages)?;
        Ok(MresIndex { header: r.header(), groups, clusters, pages, file_size })
    }

    /// The length of the whole file, as the page table implies (the end of the last page).
    pub fn file_size(&self) -> u64 {
        self.file_size
    }

    /// The byte range of the file holding page `p`'s compressed bytes.
    pub fn page_range(&self, p: u32) -> Result<Range<u64>, MresError> {
        let info = page_info(&self.pages, p)?;
        Ok(info.offset..info.offset + info.compressed_size as u64)
    }

    /// Page `p`'s sources (FORMAT.md §4.3): the pages among its dependencies stored before it,
    /// ascending. Their vertices may be copied into page `p`, so decoding it needs their GPU
    /// layouts ([`MresIndex::decode_page`]). None in a file of layout pages (§4.4): each
    /// decodes alone.
    pub fn page_sources(&self, p: u32) -> Result<Vec<u32>, MresError> {
        Ok(sources(self.header.flags, page_info(&self.pages, p)?, p).collect())
    }

    /// Checks `compressed`, the bytes of [`MresIndex::page_range`] the caller fetched, against
    /// page `p`'s table entry (length and checksum), decompresses them and decodes the page's
    /// clusters, checking each. `sources` are the decoded GPU layouts ([`Page::bytes`]) of
    /// [`MresIndex::page_sources`], in that order: exactly one per source, each of its
    /// `raw_size` ([`MresError::SourceCount`], [`MresError::SourceLength`] otherwise). A
    /// layout is only read where the page copies a vertex of it, every read bounds-checked.
    pub fn decode_page(&self, p: u32, compressed: &[u8], sources: &[&[u8]]) -> Result<Page, MresError> {
        let bytes = self.page_layout(p, compressed, sources)?;
        page_from_layout(&self.header, &self.clusters, page_info(&self.pages, p)?, p, bytes)
    }

    /// [`MresIndex::decode_page`] up to the GPU layout only ([`Page::bytes`], what a streamer
    /// uploads and later pages take as a source), without decoding the clusters from it: the
    /// same checks of the bytes, the sources and the encoding, a compact page's layout valid by
    /// construction (FORMAT.md §7). A layout page gets §4.4's structural checks (what a
    /// renderer relies on), not the rest of the canonical form, which needs every value
    /// unpacked ([`MresIndex::decode_page`] checks it).
    pub fn page_layout(&self, p: u32, compressed: &[u8], sources: &[&[u8]]) -> Result<Vec<u8>, MresError> {
        decompress_page(&self.header, &self.clusters, &self.pages, p, compressed, sources)
    }

    /// Decodes cluster `index` from its page's decompressed bytes ([`Page::bytes`]).
    pub fn decode_cluster(&self, page_raw: &[u8], index: u32) -> Result<DecodedCluster, MresError> {
        decode_one(&self.header, &self.clusters, page_raw, index)
    }
}

/// A parsed `.mres` file: the resident hierarchy plus the raw bytes the pages are read from.
/// Built on [`MresIndex`]: the same records, checks and page decoding, with the file's
/// length checked against the page table.
///
/// A page's sources (FORMAT.md §4.3) are decoded first, in file order; the layout of every
/// page that is some page's source is kept once decoded (one slot per page, shared between
/// threads), so that no page is decoded twice to serve as a source. Pages that are no page's
/// source (most of a file: the finest level) are not kept.
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
    /// Per page: whether it is some page's source, and then its layout once decoded.
    kept: Vec<Option<OnceLock<Vec<u8>>>>,
}

impl MresFile {
    /// Reads and parses a file from disk.
    pub fn open(path: &std::path::Path) -> Result<MresFile, MresError> {
        let bytes = std::fs::read(path).map_err(|e| MresError::Io(e.to_string()))?;
        MresFile::parse(bytes)
    }

    /// Parses the header, hierarchy and page table and checks their consistency and checksum.
    /// Pages are checked when read ([`MresFile::page`], [`MresFile::decode_page`]) or all at
    /// once ([`MresFile::decode_all`]).
    pub fn parse(bytes: Vec<u8>) -> Result<MresFile, MresError> {
        let MresIndex { header, groups, clusters, pages, file_size } = MresIndex::parse(&bytes)?;
        check_file_len(&pages, file_size, bytes.len() as u64)?;
        let mut is_source = vec![false; pages.len()];
        for (p, info) in pages.iter().enumerate() {
            for s in sources(header.flags, info, p as u32) {
                is_source[s as usize] = true;
            }
        }
        let kept = is_source.into_iter().map(|s| s.then(OnceLock::new)).collect();
        Ok(MresFile { header, groups, clusters, pages, bytes, kept })
    }

    /// Total file size in bytes.
    pub fn file_size(&self) -> usize {
        self.bytes.len()
    }

    /// The whole file's bytes, as parsed.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// Verifies page `p`'s checksum and returns its decompressed bytes (the GPU layout).
    /// Its clusters are checked when decoded ([`MresFile::decode_cluster`]); to check them
    /// all at once, use [`MresFile::decode_page`].
    /// Its sources are decoded (or taken from those kept) first.
    pub fn page(&self, p: u32) -> Result<Vec<u8>, MresError> {
        if let Some(layout) = self.kept_layout(p) {
            return Ok(layout.clone());
        }
        // Every page the page needs, directly or through its sources, not kept yet: all of
        // them sources, so each is kept once decoded; in ascending order, each finds its own
        // sources kept (a loop, not recursion: a chain of sources can be as long as the file).
        let mut needed = vec![p];
        let mut seen = std::collections::BTreeSet::new();
        while let Some(q) = needed.pop() {
            for s in sources(self.header.flags, page_info(&self.pages, q)?, q) {
                if self.kept_layout(s).is_none() && seen.insert(s) {
                    needed.push(s);
                }
            }
        }
        for &s in &seen {
            let layout = self.decode_layout(s)?;
            if let Some(Some(slot)) = self.kept.get(s as usize) {
                let _ = slot.set(layout);
            }
        }
        let layout = self.decode_layout(p)?;
        if let Some(Some(slot)) = self.kept.get(p as usize) {
            let _ = slot.set(layout.clone());
        }
        Ok(layout)
    }

    /// Page `p`'s layout if it is kept (a source, decoded already).
    fn kept_layout(&self, p: u32) -> Option<&Vec<u8>> {
        self.kept.get(p as usize)?.as_ref()?.get()
    }

    /// Decodes page `p`, whose sources are kept.
    fn decode_layout(&self, p: u32) -> Result<Vec<u8>, MresError> {
        let (info, frame) = self.frame(p)?;
        let layouts: Vec<&[u8]> = sources(self.header.flags, info, p)
            .map(|s| self.kept_layout(s).map(Vec::as_slice).ok_or_else(|| corrupt(format!("page {p}: source {s}"))))
            .collect::<Result<_, _>>()?;
        decompress_page(&self.header, &self.clusters, &self.pages, p, frame, &layouts)
    }

    /// Checks, decompresses and decodes page `p`, as [`MresIndex::decode_page`] does (its
    /// sources first, as [`MresFile::page`] does).
    pub fn decode_page(&self, p: u32) -> Result<Page, MresError> {
        let bytes = self.page(p)?;
        page_from_layout(&self.header, &self.clusters, page_info(&self.pages, p)?, p, bytes)
    }

    /// Decodes cluster `index` from its page's decompressed bytes.
    pub fn decode_cluster(&self, page_raw: &[u8], index: u32) -> Result<DecodedCluster, MresError> {
        decode_one(&self.header, &self.clusters, page_raw, index)
    }

    /// Reads every page and decodes every cluster, in cluster order.
    pub fn decode_all(&self) -> Result<Vec<DecodedCluster>, MresError> {
        let mut out = Vec::with_capacity(self.clusters.len());
        for p in 0..self.pages.len() as u32 {
            out.append(&mut self.decode_page(p)?.clusters);
        }
        if out.len() != self.clusters.len() {
            return Err(corrupt(format!("pages hold {} clusters, hierarchy has {}", out.len(), self.clusters.len())));
        }
        Ok(out)
    }

    /// Page `p`'s table entry and compressed bytes.
    fn frame(&self, p: u32) -> Result<(&PageInfo, &[u8]), MresError> {
        let info = page_info(&self.pages, p)?;
        Ok((info, section(&self.bytes, info.offset, info.compressed_size as u64, &format!("page {p}"))?))
    }
}

/// `bytes` split after `len` bytes, or a `Truncated` error naming `what` (the first part).
fn split<'a>(bytes: &'a [u8], len: u64, what: &str) -> Result<(&'a [u8], &'a [u8]), MresError> {
    let first = section(bytes, 0, len, what)?;
    Ok((first, &bytes[first.len()..]))
}

fn page_info(pages: &[PageInfo], p: u32) -> Result<&PageInfo, MresError> {
    pages.get(p as usize).ok_or_else(|| corrupt(format!("page {p} does not exist")))
}

fn decode_one(h: &Header, clusters: &[ClusterInfo], raw: &[u8], index: u32) -> Result<DecodedCluster, MresError> {
    let info = clusters.get(index as usize).ok_or_else(|| corrupt(format!("cluster {index} does not exist")))?;
    Ok(read_cluster(h, raw, info, index)?.1)
}

/// The header record at the start of `bytes`, checked, and its bytes.
fn read_header(bytes: &[u8]) -> Result<(HeaderRecord, &[u8; HEADER_SIZE]), MresError> {
    let head = section(bytes, 0, HEADER_SIZE as u64, "header")?;
    let head = head.first_chunk::<HEADER_SIZE>().ok_or_else(|| corrupt("header".into()))?;
    let record = HeaderRecord::decode(head);
    check_header(&record)?;
    Ok((record, head))
}

fn check_header(r: &HeaderRecord) -> Result<(), MresError> {
    if r.magic != MAGIC {
        return Err(MresError::BadMagic);
    }
    if r.version != VERSION {
        return Err(MresError::WrongVersion { found: r.version });
    }
    if r.header_size as usize != HEADER_SIZE {
        return Err(corrupt(format!("header: size {}, expected {HEADER_SIZE}", r.header_size)));
    }
    if r.reserved.iter().any(|&b| b != 0) {
        return Err(corrupt("header: reserved bytes are not zero".into()));
    }
    check_quantization(r)?;
    check_sections(r)
}

fn check_quantization(r: &HeaderRecord) -> Result<(), MresError> {
    if r.flags & !KNOWN_FLAGS != 0 {
        return Err(corrupt(format!("header: unknown flags {:#x}", r.flags)));
    }
    let finite = r.grid_origin.iter().chain(&r.uv_min).chain(&r.uv_extent).all(|v| v.is_finite());
    if !(r.grid_step.is_finite() && r.grid_step > 0.0 && finite) {
        return Err(corrupt("header: non-finite or non-positive quantization parameters".into()));
    }
    if r.flags & FLAG_NORMALS != 0 && !(4..=16).contains(&r.normal_bits) {
        return Err(corrupt(format!("header: normal_bits {} outside 4..=16", r.normal_bits)));
    }
    Ok(())
}

/// The section offsets and sizes agree with the counts (FORMAT.md §2).
fn check_sections(r: &HeaderRecord) -> Result<(), MresError> {
    let expected_hierarchy =
        r.group_count as u64 * GROUP_RECORD_SIZE as u64 + r.cluster_count as u64 * CLUSTER_RECORD_SIZE as u64;
    if r.hierarchy_offset != HEADER_SIZE as u64 || r.hierarchy_size != expected_hierarchy {
        return Err(corrupt(format!(
            "header: hierarchy at {} size {}, expected {HEADER_SIZE} and {expected_hierarchy}",
            r.hierarchy_offset, r.hierarchy_size
        )));
    }
    if r.page_table_offset != r.hierarchy_offset + r.hierarchy_size {
        return Err(corrupt("header: page table does not follow the hierarchy".into()));
    }
    let min_table = r.page_count as u64 * PAGE_RECORD_SIZE as u64;
    if r.page_table_size < min_table || !(r.page_table_size - min_table).is_multiple_of(4) {
        return Err(corrupt(format!("header: page table size {} for {} pages", r.page_table_size, r.page_count)));
    }
    Ok(())
}

fn decode_groups(bytes: &[u8], r: &HeaderRecord) -> Result<Vec<Group>, MresError> {
    let (records, _) = bytes.as_chunks::<GROUP_RECORD_SIZE>();
    let groups: Vec<Group> = records.iter().map(GroupRecord::decode).collect();
    for (g, group) in groups.iter().enumerate() {
        check_group(g, group, r)?;
    }
    Ok(groups)
}

fn check_group(g: usize, group: &Group, r: &HeaderRecord) -> Result<(), MresError> {
    let Sphere { center, radius } = group.sphere;
    let finite = center.iter().all(|v| v.is_finite()) && radius.is_finite() && radius >= 0.0;
    if !finite || group.error.is_nan() || group.error < 0.0 {
        return Err(corrupt(format!("group {g}: bad sphere or error")));
    }
    if group.cluster_count == 0
        || group.first_cluster as u64 + group.cluster_count as u64 > r.cluster_count as u64
        || group.page >= r.page_count
        || group.level >= r.level_count
    {
        return Err(corrupt(format!("group {g}: cluster range, page or level out of range")));
    }
    Ok(())
}

fn decode_clusters(bytes: &[u8], groups: &[Group]) -> Result<Vec<ClusterInfo>, MresError> {
    let (records, _) = bytes.as_chunks::<CLUSTER_RECORD_SIZE>();
    let clusters: Vec<ClusterInfo> = records.iter().map(ClusterRecord::decode).collect();
    for (i, cluster) in clusters.iter().enumerate() {
        check_cluster(i as u32, cluster, groups)?;
    }
    Ok(clusters)
}

fn check_cluster(i: u32, c: &ClusterInfo, groups: &[Group]) -> Result<(), MresError> {
    let in_group =
        groups.get(c.group as usize).is_some_and(|g| (g.first_cluster..g.first_cluster + g.cluster_count).contains(&i));
    if !in_group || (c.own_group != NO_GROUP && c.own_group as usize >= groups.len()) {
        return Err(corrupt(format!("cluster {i}: group reference out of range")));
    }
    let (v, t) = (c.vertex_count as usize, c.triangle_count as usize);
    if v == 0 || v > MAX_CLUSTER_VERTICES || t == 0 || t > MAX_CLUSTER_TRIANGLES {
        return Err(corrupt(format!("cluster {i}: {v} vertices, {t} triangles")));
    }
    Ok(())
}

/// The page records and the dependency array after them (FORMAT.md §4).
fn decode_page_table(table: &[u8], r: &HeaderRecord) -> Result<Vec<PageInfo>, MresError> {
    let (records, dependencies) = split(table, r.page_count as u64 * PAGE_RECORD_SIZE as u64, "page records")?;
    let (records, _) = records.as_chunks::<PAGE_RECORD_SIZE>();
    let (dependencies, _) = dependencies.as_chunks::<4>();
    let pages_start = r.page_table_offset + r.page_table_size;
    let mut pages = Vec::with_capacity(records.len());
    for (p, bytes) in records.iter().enumerate() {
        let record = PageRecord::decode(bytes);
        check_page_record(p, &record, r, dependencies.len() as u64, pages_start)?;
        let deps = &dependencies[record.dependency_first as usize..][..record.dependency_count as usize];
        let deps: Vec<u32> = deps.iter().map(|&d| u32::from_le_bytes(d)).collect();
        if let Some(d) = deps.iter().find(|&&d| d >= r.page_count) {
            return Err(corrupt(format!("page {p}: dependency {d} out of range")));
        }
        pages.push(PageInfo {
            offset: record.offset,
            compressed_size: record.compressed_size,
            raw_size: record.raw_size,
            checksum: record.checksum,
            first_cluster: record.first_cluster,
            cluster_count: record.cluster_count,
            first_group: record.first_group,
            group_count: record.group_count,
            dependencies: deps,
        });
    }
    Ok(pages)
}

fn check_page_record(
    p: usize,
    rec: &PageRecord,
    r: &HeaderRecord,
    dependency_count: u64,
    pages_start: u64,
) -> Result<(), MresError> {
    if rec.offset < pages_start {
        return Err(corrupt(format!("page {p}: data at {} inside the page table (ends at {pages_start})", rec.offset)));
    }
    if rec.raw_size as usize > MAX_PAGE_RAW_SIZE {
        return Err(corrupt(format!(
            "page {p}: claims {} decompressed bytes (limit {MAX_PAGE_RAW_SIZE})",
            rec.raw_size
        )));
    }
    let clusters_ok = rec.first_cluster as u64 + rec.cluster_count as u64 <= r.cluster_count as u64;
    let groups_ok = rec.first_group as u64 + rec.group_count as u64 <= r.group_count as u64;
    let deps_ok = rec.dependency_first as u64 + rec.dependency_count as u64 <= dependency_count;
    if !clusters_ok || !groups_ok || !deps_ok {
        return Err(corrupt(format!("page {p}: cluster, group or dependency range out of range")));
    }
    Ok(())
}

/// Group ranges tile the clusters in order (FORMAT.md §3.1).
fn check_group_tiling(groups: &[Group], cluster_count: usize) -> Result<(), MresError> {
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
    Ok(())
}

/// Pages tile the page data from `pages_start` on (FORMAT.md §1); returns where it ends.
fn check_page_tiling(pages: &[PageInfo], pages_start: u64) -> Result<u64, MresError> {
    let mut next_offset = pages_start;
    for (p, page) in pages.iter().enumerate() {
        if page.offset != next_offset {
            return Err(corrupt(format!(
                "page {p}: data at {} but the previous page ends at {next_offset}",
                page.offset
            )));
        }
        next_offset = next_offset
            .checked_add(page.compressed_size as u64)
            .ok_or_else(|| corrupt(format!("page {p}: data ends past 2^64")))?;
    }
    Ok(next_offset)
}

/// Pages hold whole, consecutive groups and tile the groups and the clusters in order, every
/// group names the page that holds it, and each cluster's header sits at `48·i` of its page
/// (FORMAT.md §4.1, §5): the streaming reader and renderers follow `page_offset`, and the page
/// checks find headers at `48·i`.
fn check_group_pages(groups: &[Group], clusters: &[ClusterInfo], pages: &[PageInfo]) -> Result<(), MresError> {
    let (mut next_group, mut next_cluster) = (0u64, 0u64);
    for (p, page) in pages.iter().enumerate() {
        if page.first_group as u64 != next_group || page.first_cluster as u64 != next_cluster {
            return Err(corrupt(format!(
                "page {p}: groups from {} and clusters from {} but the pages before it end at group {next_group}, cluster {next_cluster}",
                page.first_group, page.first_cluster
            )));
        }
        // Ranges were checked against the counts when the records were read.
        let held = &groups[page.first_group as usize..][..page.group_count as usize];
        let held_clusters: u64 = held.iter().map(|g| g.cluster_count as u64).sum();
        if let Some(g) = held.iter().position(|g| g.page as usize != p) {
            return Err(corrupt(format!(
                "group {}: in page {p} but names page {}",
                page.first_group as usize + g,
                held[g].page
            )));
        }
        if held.first().is_some_and(|g| g.first_cluster != page.first_cluster)
            || held_clusters != page.cluster_count as u64
        {
            return Err(corrupt(format!("page {p}: its clusters are not exactly its groups' members")));
        }
        let first = page.first_cluster as usize;
        for (i, c) in clusters[first..][..page.cluster_count as usize].iter().enumerate() {
            if c.page_offset as u64 != (i * CLUSTER_HEADER_SIZE) as u64 {
                return Err(corrupt(format!(
                    "cluster {}: page_offset {} but it is cluster {i} of page {p} (header at {})",
                    first + i,
                    c.page_offset,
                    i * CLUSTER_HEADER_SIZE
                )));
            }
        }
        next_group += page.group_count as u64;
        next_cluster += page.cluster_count as u64;
    }
    if next_group != groups.len() as u64 || next_cluster != clusters.len() as u64 {
        return Err(corrupt("pages do not hold every group and cluster".into()));
    }
    Ok(())
}

/// Every page lies inside a file of `len` bytes, and the page data ends where the file does.
fn check_file_len(pages: &[PageInfo], data_end: u64, len: u64) -> Result<(), MresError> {
    for (p, page) in pages.iter().enumerate() {
        let end = page.offset.saturating_add(page.compressed_size as u64);
        if end > len {
            return Err(MresError::Truncated { what: format!("page {p}"), start: page.offset, end, len });
        }
    }
    if data_end != len {
        return Err(corrupt(format!("page data ends at {data_end} but the file has {len} bytes")));
    }
    Ok(())
}
