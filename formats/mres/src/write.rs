//! Writer: a logical [`Dag`] to `.mres` bytes (FORMAT.md). Deterministic: the same `Dag`
//! always gives the same bytes.

use super::bits::{bits_for, oct_encode, read_bits, BitWriter};
use super::codec::{self, first_use_order, Quantized};
use super::decode;
use super::layout_pages;
use super::records::{meta_checksum, ClusterHeader, ClusterRecord, GroupRecord, HeaderRecord, PageRecord};
use super::*;
use rayon::prelude::*;
use std::cell::RefCell;
use std::sync::OnceLock;

/// Why a [`Dag`] cannot be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// A cluster breaks a format limit.
    #[error("cluster {cluster}: {problem}")]
    BadCluster {
        /// Index into `Dag::clusters`.
        cluster: usize,
        /// What is wrong.
        problem: String,
    },
    /// A group or reference is inconsistent.
    #[error("{0}")]
    BadDag(String),
    /// zstd failed.
    #[error("zstd: {0}")]
    Compress(#[from] std::io::Error),
    /// The file being rewritten ([`rewrite`]) does not read.
    #[error(transparent)]
    Read(#[from] MresError),
}

/// How pages are encoded (FORMAT.md §4.3).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PageCoding {
    /// A vertex equal to one of the page's sources (its dependencies stored before it) is a
    /// far copy of it: smaller files, and decoding a page needs its sources' layouts.
    #[default]
    FarCopies,
    /// No far copies: every page decodes alone (larger files).
    Independent,
    /// Every page stored as its GPU layout, one LZ4 block (FORMAT.md §4.4, flag
    /// [`FLAG_LAYOUT_PAGES`]): pages decode alone at memory speed, in about twice the bytes.
    Layout,
}

/// Serializes `dag` to a complete `.mres` file; pages are compressed with zstd at `level`.
pub fn write_mres(dag: &Dag, level: i32) -> Result<Vec<u8>, WriteError> {
    write_mres_with(dag, level, PageCoding::default())
}

/// [`write_mres`] with the pages encoded as `coding` says.
pub fn write_mres_with(dag: &Dag, level: i32, coding: PageCoding) -> Result<Vec<u8>, WriteError> {
    let clusters: Vec<EncodedCluster> = dag
        .clusters
        .par_iter()
        .enumerate()
        .map(|(i, c)| EncodedCluster::new(c, &dag.header, i))
        .collect::<Result<_, _>>()?;
    write_encoded_with(&dag.header, &dag.groups, clusters, level, coding)
}

/// [`write_mres`] for clusters already encoded with [`EncodedCluster::new`] (a large bake
/// keeps its finished clusters in this compact form). Consumes them: the hierarchy and page
/// table are laid out first (their sizes do not depend on compression), then pages are
/// compressed a batch at a time straight into the file, and each batch's clusters are freed,
/// so that the encoded clusters and the file are never both held whole.
pub fn write_encoded(
    header: &Header,
    groups: &[Group],
    encoded: Vec<EncodedCluster>,
    level: i32,
) -> Result<Vec<u8>, WriteError> {
    write_encoded_with(header, groups, encoded, level, PageCoding::default())
}

/// [`write_encoded`] with the pages encoded as `coding` says.
pub fn write_encoded_with(
    header: &Header,
    groups: &[Group],
    encoded: Vec<EncodedCluster>,
    level: i32,
    coding: PageCoding,
) -> Result<Vec<u8>, WriteError> {
    write_paged(header, groups, encoded, (level, coding), None)
}

/// [`write_encoded_with`], the pages holding `kept` groups each where given (see
/// [`page_spans`]).
pub(crate) fn write_paged(
    header: &Header,
    groups: &[Group],
    encoded: Vec<EncodedCluster>,
    (level, coding): (i32, PageCoding),
    kept: Option<&[u32]>,
) -> Result<Vec<u8>, WriteError> {
    let layout_flag = if coding == PageCoding::Layout { FLAG_LAYOUT_PAGES } else { 0 };
    let header = &Header { flags: (header.flags & !FLAG_LAYOUT_PAGES) | layout_flag, ..*header };
    let layout = Layout::new(groups, &encoded)?;
    let pages = page_spans(&layout, &encoded, kept, header.flags);
    let (groups, clusters) = renumber(&layout, &pages, groups, &encoded);
    let dependencies = page_dependencies(&pages, &groups, &clusters);
    let hierarchy = encode_hierarchy(&groups, &clusters);
    let page_table_offset = (HEADER_SIZE + hierarchy.len()) as u64;
    let dependency_total: usize = dependencies.iter().map(Vec::len).sum();
    let page_table_size = (pages.len() * PAGE_RECORD_SIZE + dependency_total * 4) as u64;

    // The pages, straight into the file after room for the header, hierarchy and table.
    let mut out = vec![0u8; (page_table_offset + page_table_size) as usize];
    let sources: Vec<Vec<u32>> = match coding {
        PageCoding::FarCopies => dependencies
            .iter()
            .enumerate()
            .map(|(p, d)| d.iter().copied().filter(|&s| (s as usize) < p).collect())
            .collect(),
        PageCoding::Independent | PageCoding::Layout => vec![Vec::new(); pages.len()],
    };
    let frames = compress_pages(header, &layout, &pages, &sources, encoded, level, &mut out)?;
    let table = encode_page_table(&pages, &dependencies, &frames);

    let sizes = [groups.len(), clusters.len(), pages.len()].map(|n| n as u32);
    let levels = groups.iter().map(|g| g.level + 1).max().unwrap_or(0);
    let mut head = header_record(header, levels, sizes, hierarchy.len() as u64, page_table_size);
    head.meta_checksum = meta_checksum(&head.encode(), &hierarchy, &table);
    out[..HEADER_SIZE].copy_from_slice(&head.encode());
    out[HEADER_SIZE..][..hierarchy.len()].copy_from_slice(&hierarchy);
    out[page_table_offset as usize..][..table.len()].copy_from_slice(&table);
    Ok(out)
}

/// The blocks of the cluster with header `head` as page layout `raw` stores them (each with
/// its padding), or `None` if one lies outside `raw`.
pub(crate) fn stored_blocks(raw: &[u8], head: &ClusterHeader) -> Option<Blocks> {
    let mut blocks: Blocks = Default::default();
    for (slot, block) in blocks.iter_mut().enumerate() {
        let at = head.block_offsets[slot] as usize;
        if at != 0 {
            *block = Some(raw.get(at..at + layout_pages::block_len(slot, head))?.to_vec());
        }
    }
    Some(blocks)
}

/// The header record of a file with these counts and section sizes; its checksum is left zero.
fn header_record(
    header: &Header,
    level_count: u32,
    [group_count, cluster_count, page_count]: [u32; 3],
    hierarchy_size: u64,
    page_table_size: u64,
) -> HeaderRecord {
    HeaderRecord {
        magic: MAGIC,
        version: VERSION,
        header_size: HEADER_SIZE as u32,
        flags: header.flags,
        grid_origin: header.grid.origin,
        grid_step: header.grid.step,
        uv_min: header.uv.min,
        uv_extent: header.uv.extent,
        normal_bits: header.normal_bits,
        position_bits: header.position_bits,
        level_count,
        group_count,
        cluster_count,
        page_count,
        source_triangles: header.source_triangles,
        hierarchy_offset: HEADER_SIZE as u64,
        hierarchy_size,
        page_table_offset: HEADER_SIZE as u64 + hierarchy_size,
        page_table_size,
        meta_checksum: [0; 32],
        reserved: [0; 16],
    }
}

/// The groups and cluster records in file order, with their ranges, pages and page offsets
/// (a cluster's header sits at its index in its page × header size).
fn renumber(
    layout: &Layout,
    pages: &[PageSpan],
    groups: &[Group],
    encoded: &[EncodedCluster],
) -> (Vec<Group>, Vec<ClusterInfo>) {
    let mut page_offsets = vec![0u32; encoded.len()];
    for page in pages {
        for c in 0..page.cluster_count {
            page_offsets[(page.first_cluster + c) as usize] = c * CLUSTER_HEADER_SIZE as u32;
        }
    }
    let new_groups = layout
        .group_order
        .iter()
        .enumerate()
        .map(|(new_g, &old_g)| {
            let (first_cluster, cluster_count) = layout.group_ranges[new_g];
            Group { first_cluster, cluster_count, page: layout.group_page(pages, new_g), ..groups[old_g] }
        })
        .collect();
    let renamed = |g: u32| if g == NO_GROUP { NO_GROUP } else { layout.group_new[g as usize] };
    let clusters = layout
        .cluster_order
        .iter()
        .zip(page_offsets)
        .map(|(&old_c, page_offset)| {
            let c = &encoded[old_c];
            ClusterInfo {
                group: renamed(c.group),
                own_group: renamed(c.own_group),
                vertex_count: c.header.vertex_count,
                triangle_count: c.header.triangle_count,
                page_offset,
            }
        })
        .collect();
    (new_groups, clusters)
}

/// The hierarchy section: group records, then cluster records (FORMAT.md §3).
fn encode_hierarchy(groups: &[Group], clusters: &[ClusterInfo]) -> Vec<u8> {
    let mut out = Vec::with_capacity(groups.len() * GROUP_RECORD_SIZE + clusters.len() * CLUSTER_RECORD_SIZE);
    for g in groups {
        out.extend_from_slice(&GroupRecord::encode(g));
    }
    for c in clusters {
        out.extend_from_slice(&ClusterRecord::encode(c));
    }
    out
}

/// Where a page's compressed bytes went in the file.
struct Frame {
    offset: u64,
    size: u32,
    checksum: [u8; 32],
}

/// Compresses the pages in parallel batches, appending each to `out` in page order and freeing
/// its clusters' data once written and no later page's source (`sources`: per page, the
/// pages it may copy vertices from).
fn compress_pages(
    header: &Header,
    layout: &Layout,
    pages: &[PageSpan],
    sources: &[Vec<u32>],
    mut encoded: Vec<EncodedCluster>,
    level: i32,
    out: &mut Vec<u8>,
) -> Result<Vec<Frame>, WriteError> {
    let members = |p: usize| {
        let page = &pages[p];
        &layout.cluster_order[page.first_cluster as usize..][..page.cluster_count as usize]
    };
    // The last page that reads each page: itself, or the last page it is a source of.
    let mut last_use: Vec<usize> = (0..pages.len()).collect();
    for (p, s) in sources.iter().enumerate() {
        for &s in s {
            last_use[s as usize] = last_use[s as usize].max(p);
        }
    }
    // What later pages read of each source page, made once by the first page that needs it
    // (a page is the source of its siblings' and children's pages, often several) and dropped
    // with the page's data.
    let mut kept: Vec<OnceLock<SourceData>> = (0..pages.len()).map(|_| OnceLock::new()).collect();
    let mut frames = Vec::with_capacity(pages.len());
    let (mut freed, mut untrimmed) = (0, 0);
    for start in (0..pages.len()).step_by(PAGE_BATCH) {
        let batch = start..(start + PAGE_BATCH).min(pages.len());
        let compressed: Vec<Vec<u8>> = batch
            .clone()
            .into_par_iter()
            .map(|p| {
                let of = |p: usize| -> Vec<&EncodedCluster> { members(p).iter().map(|&c| &encoded[c]).collect() };
                let source_pages: Vec<&SourceData> = sources[p]
                    .iter()
                    .map(|&s| kept[s as usize].get_or_init(|| SourceData::new(&of(s as usize), header.flags)))
                    .collect();
                compress_page(&of(p), &source_pages, header, level)
            })
            .collect::<Result<_, _>>()?;
        for frame in compressed {
            frames.push(Frame {
                offset: out.len() as u64,
                size: frame.len() as u32,
                checksum: *blake3::hash(&frame).as_bytes(),
            });
            out.extend_from_slice(&frame);
        }
        // Pages before `freed` are freed; every page whose last reader is done goes now.
        for p in (freed..batch.end).filter(|&p| last_use[p] < batch.end) {
            for &c in members(p) {
                untrimmed += std::mem::take(&mut encoded[c].data).len();
            }
            kept[p] = OnceLock::new();
        }
        while freed < batch.end && last_use[freed] < batch.end {
            freed += 1;
        }
        if untrimmed >= TRIM_BYTES {
            release_freed_memory();
            untrimmed = 0;
        }
    }
    Ok(frames)
}

/// The page table: page records, then the dependency array (FORMAT.md §4).
fn encode_page_table(pages: &[PageSpan], dependencies: &[Vec<u32>], frames: &[Frame]) -> Vec<u8> {
    let mut table = Vec::new();
    let mut dependency_first = 0u32;
    for ((page, deps), frame) in pages.iter().zip(dependencies).zip(frames) {
        let record = PageRecord {
            offset: frame.offset,
            compressed_size: frame.size,
            raw_size: page.raw_size as u32,
            checksum: frame.checksum,
            first_cluster: page.first_cluster,
            cluster_count: page.cluster_count,
            first_group: page.first_group,
            group_count: page.group_count,
            dependency_first,
            dependency_count: deps.len() as u32,
        };
        table.extend_from_slice(&record.encode());
        dependency_first += deps.len() as u32;
    }
    for d in dependencies.iter().flatten() {
        table.extend_from_slice(&d.to_le_bytes());
    }
    table
}

/// Pages compressed at a time: enough for every thread, few enough that the batch's frames
/// and raw pages stay small.
const PAGE_BATCH: usize = 64;

/// Cluster bytes freed before they are given back ([`release_freed_memory`]): it walks the
/// whole heap, so once per batch cost a large mesh's writer more than its batches' tails.
const TRIM_BYTES: usize = 32 << 20;

/// Gives freed heap memory back to the system. The freed clusters are many small blocks that
/// glibc keeps for reuse, while the file grows in one large block it cannot reuse them for: so
/// without this, peak memory would be the encoded clusters plus the whole file.
fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free memory to the system; it has no preconditions.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// The coarse-to-fine order of groups and clusters.
struct Layout {
    /// New group index → old.
    group_order: Vec<usize>,
    /// Old group index → new.
    group_new: Vec<u32>,
    /// New cluster index → old.
    cluster_order: Vec<usize>,
    /// Per new group: (first cluster, count).
    group_ranges: Vec<(u32, u32)>,
}

impl Layout {
    fn new(groups: &[Group], clusters: &[EncodedCluster]) -> Result<Layout, WriteError> {
        let n = groups.len();
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (i, c) in clusters.iter().enumerate() {
            let g = c.group as usize;
            if g >= n || (c.own_group != NO_GROUP && c.own_group as usize >= n) {
                return Err(WriteError::BadDag(format!("cluster {i} refers to a missing group")));
            }
            members[g].push(i);
        }
        let mut group_order: Vec<usize> = (0..n).collect();
        // Coarse to fine: a prefix of the file is a valid coarse model.
        group_order.sort_by_key(|&g| (std::cmp::Reverse(groups[g].level), g));
        let mut group_new = vec![0u32; n];
        let mut cluster_order = Vec::with_capacity(clusters.len());
        let mut group_ranges = Vec::with_capacity(n);
        for (new_g, &g) in group_order.iter().enumerate() {
            if members[g].is_empty() {
                return Err(WriteError::BadDag(format!("group {g} has no clusters")));
            }
            group_new[g] = new_g as u32;
            group_ranges.push((cluster_order.len() as u32, members[g].len() as u32));
            cluster_order.extend_from_slice(&members[g]);
        }
        Ok(Layout { group_order, group_new, cluster_order, group_ranges })
    }

    fn group_page(&self, pages: &[PageSpan], new_g: usize) -> u32 {
        let g = new_g as u32;
        pages.partition_point(|p| p.first_group + p.group_count <= g) as u32
    }
}

/// Encodes a page (FORMAT.md §4.3) and compresses each of its streams as its own zstd frame,
/// so that each gets its own entropy tables (the low bytes of residuals are near-random, the
/// high ones nearly all zero). The encoding is decoded again and must give back the page's GPU
/// layout byte for byte: a writer bug is an error here, never a file that reads differently.
/// `sources` are the page's sources, in order (FORMAT.md §4.3): their vertices are what far
/// copies name, and their laid-out pages what the check decodes them from.
fn compress_page(
    clusters: &[&EncodedCluster],
    sources: &[&SourceData],
    header: &Header,
    level: i32,
) -> Result<Vec<u8>, WriteError> {
    let (raw, _) = assemble_page(clusters);
    if header.flags & FLAG_LAYOUT_PAGES != 0 {
        return layout_page(raw, clusters, header);
    }
    let records = page_records(clusters);
    let most = codec::max_encoded_len(header.flags, &records);
    if most > MAX_PAGE_ENCODED_SIZE {
        return Err(WriteError::BadDag(format!(
            "a page's {} clusters could encode to {most} bytes, over the {MAX_PAGE_ENCODED_SIZE} bytes readers \
             accept (FORMAT.md §4.3): store it in smaller pages or as layout pages",
            clusters.len()
        )));
    }
    let quantized: Vec<Quantized> = clusters.iter().map(|c| c.quantized(header.flags)).collect();
    let index = codec::SourceIndex::new(sources.iter().map(|s| &s.keys));
    let codec_bug = || WriteError::BadDag("the page encoding does not decode to the page (a writer bug)".into());
    let streams = codec::encode_page(&quantized, header.flags, &index).ok_or_else(codec_bug)?;
    let encoded = streams.concat();
    if encoded.len() > MAX_PAGE_ENCODED_SIZE {
        return Err(WriteError::BadDag(format!(
            "a page encodes to {} bytes, over the {MAX_PAGE_ENCODED_SIZE}-byte limit",
            encoded.len()
        )));
    }
    // The sources as a reader holds them: their laid-out pages and cluster records (none
    // without far copies, reference 2 in the references stream: the page then decodes alone;
    // not the far-target plane count, which is 0 where every far target codes as 0).
    let far_copies = streams[codec::REFERENCES_STREAM].contains(&2);
    let read: &[&SourceData] = if far_copies { sources } else { &[] };
    let source_pages: Vec<decode::SourcePage> = read
        .iter()
        .enumerate()
        .map(|(i, s)| decode::SourcePage { index: i as u32, layout: &s.layout, records: &s.records })
        .collect();
    let decoded =
        decode::decode_page_gpu(&encoded, &records, header.flags, header.normal_bits, raw.len(), Some(&source_pages));
    if decoded.ok() != Some(raw) {
        return Err(codec_bug());
    }
    COMPRESSOR.with_borrow_mut(|cell| {
        let zstd = match cell {
            Some((l, zstd)) if *l == level => zstd,
            _ => &mut cell.insert((level, zstd::bulk::Compressor::new(level)?)).1,
        };
        let mut out = Vec::new();
        for stream in streams.iter().filter(|s| !s.is_empty()) {
            out.extend_from_slice(&zstd.compress(stream)?);
        }
        Ok(out)
    })
}

/// A page stored as its layout `raw` (FORMAT.md §4.4), one LZ4 block, checked like
/// [`compress_page`]'s: decompressed and checked as a reader does, it must give `raw` back.
fn layout_page(raw: Vec<u8>, clusters: &[&EncodedCluster], header: &Header) -> Result<Vec<u8>, WriteError> {
    let block = layout_pages::compress(&raw)?;
    let back = layout_pages::decompress(header, &page_records(clusters), 0, 0, &block, raw.len());
    if back.ok() != Some(raw) {
        return Err(WriteError::BadDag("the page's layout does not read back (a writer bug)".into()));
    }
    Ok(block)
}

thread_local! {
    /// A zstd context per thread and level, reused from stream to stream (the same frames as
    /// a fresh one): a fresh context per stream set up and zeroed its tables every time, for
    /// streams of a few kilobytes.
    static COMPRESSOR: RefCell<Option<(i32, zstd::bulk::Compressor<'static>)>> = const { RefCell::new(None) };
}

/// What the pages that copy vertices of a page read of it (FORMAT.md §4.3): its vertices'
/// keys in source numbering, and its GPU layout and cluster records, as a reader holds them.
struct SourceData {
    /// Its vertices by key, for the far copies of the pages it is a source of.
    keys: codec::PageKeys,
    layout: Vec<u8>,
    records: Vec<ClusterInfo>,
}

impl SourceData {
    fn new(clusters: &[&EncodedCluster], flags: u32) -> SourceData {
        let quantized: Vec<Quantized> = clusters.iter().map(|c| c.quantized(flags)).collect();
        SourceData {
            keys: codec::PageKeys::new(&codec::source_keys(&quantized)),
            layout: assemble_page(clusters).0,
            records: page_records(clusters),
        }
    }
}

/// The cluster records of a page of these clusters, as far as decoding reads them (counts,
/// and each header's place in the page).
fn page_records(clusters: &[&EncodedCluster]) -> Vec<ClusterInfo> {
    clusters
        .iter()
        .enumerate()
        .map(|(i, c)| ClusterInfo {
            group: 0,
            own_group: NO_GROUP,
            vertex_count: c.header.vertex_count,
            triangle_count: c.header.triangle_count,
            page_offset: (i * CLUSTER_HEADER_SIZE) as u32,
        })
        .collect()
}

/// The GPU layout (FORMAT.md §5) of a page of quantized clusters, laid out as the writer lays
/// out every page: what the page decoder ([`crate::decode`]) must give back.
#[cfg(test)]
pub(crate) fn gpu_page(clusters: &[Quantized], flags: u32) -> Vec<u8> {
    let encoded: Vec<EncodedCluster> = clusters
        .iter()
        .map(|q| {
            let (header, blocks) = gpu_blocks(q, flags);
            EncodedCluster::from_blocks(0, NO_GROUP, header, blocks)
        })
        .collect();
    let refs: Vec<&EncodedCluster> = encoded.iter().collect();
    assemble_page(&refs).0
}

/// A page's layout `raw` laid out again from the values it holds, as the writer lays out a
/// page of them (FORMAT.md §4.4: a layout page must be exactly that); `headers` are its
/// cluster headers, whose blocks [`layout_pages::check`] has found in place. Where the values
/// are not what the writer stores, the page's cluster at fault and what is wrong: vertices
/// not in first-use order, corners not as the index codec gives them back, octahedral values
/// over `2^normal_bits − 1`.
pub(crate) fn relaid(
    raw: &[u8],
    headers: &[ClusterHeader],
    flags: u32,
    normal_bits: u32,
) -> Result<Vec<u8>, (usize, &'static str)> {
    let clusters: Vec<EncodedCluster> = headers
        .iter()
        .enumerate()
        .map(|(i, h)| {
            let blocks = stored_blocks(raw, h).ok_or((i, "a block lies outside the page"))?;
            let q = EncodedCluster::from_blocks(0, NO_GROUP, *h, blocks).quantized(flags);
            if let Some(fault) = canonical_fault(&q, normal_bits) {
                return Err((i, fault));
            }
            let (header, blocks) = gpu_blocks(&q, flags);
            Ok(EncodedCluster::from_blocks(0, NO_GROUP, header, blocks))
        })
        .collect::<Result<_, _>>()?;
    Ok(assemble_page(&clusters.iter().collect::<Vec<_>>()).0)
}

/// One page's place: its clusters and groups (in the new order) and its decompressed size.
struct PageSpan {
    first_cluster: u32,
    cluster_count: u32,
    first_group: u32,
    group_count: u32,
    raw_size: usize,
}

/// Pages of whole groups in coarse-to-fine order: `kept` groups each where given and they fit
/// (a rewritten file keeps its pages: the groups already in this order, all of them held, and
/// for compact pages every page within the encoded-size limit readers accept, `E_max`;
/// pages of no group are dropped), else filled greedily up to [`PAGE_TARGET_RAW_SIZE`].
fn page_spans(layout: &Layout, encoded: &[EncodedCluster], kept: Option<&[u32]>, flags: u32) -> Vec<PageSpan> {
    let n = layout.group_ranges.len();
    let sizes: Vec<usize> = layout
        .group_ranges
        .iter()
        .map(|&(first, count)| (first..first + count).map(|c| encoded[layout.cluster_order[c as usize]].size()).sum())
        .collect();
    let in_order = layout.group_order.iter().enumerate().all(|(new, &old)| new == old);
    let kept: Vec<usize> = kept.unwrap_or_default().iter().filter(|&&c| c > 0).map(|&c| c as usize).collect();
    if in_order && !kept.is_empty() && kept.iter().sum::<usize>() == n {
        let spans = spans_ending(layout, &sizes, kept.iter().scan(0, |end, &c| Some(*end + c).inspect(|&e| *end = e)));
        let within = |p: &PageSpan| {
            let clusters = &layout.cluster_order[p.first_cluster as usize..][..p.cluster_count as usize];
            let records: Vec<&EncodedCluster> = clusters.iter().map(|&c| &encoded[c]).collect();
            codec::max_encoded_len(flags, &page_records(&records)) <= MAX_PAGE_ENCODED_SIZE
        };
        if flags & FLAG_LAYOUT_PAGES != 0 || spans.iter().all(within) {
            return spans;
        }
    }
    let mut ends = Vec::new();
    let mut raw_size = 0;
    for (g, &group_size) in sizes.iter().enumerate() {
        if ends.last().copied().unwrap_or(0) < g && raw_size + group_size > PAGE_TARGET_RAW_SIZE {
            ends.push(g);
            raw_size = 0;
        }
        raw_size += group_size;
    }
    if n > 0 {
        ends.push(n);
    }
    spans_ending(layout, &sizes, ends.into_iter())
}

/// The pages ending before the groups `ends` (ascending, the last the group count), with
/// `sizes[g]` the layout bytes of group `g`.
fn spans_ending(layout: &Layout, sizes: &[usize], ends: impl Iterator<Item = usize>) -> Vec<PageSpan> {
    let mut start_group = 0;
    ends.map(|end_group| {
        let first_cluster = layout.group_ranges[start_group].0;
        let (last_first, last_count) = layout.group_ranges[end_group - 1];
        let span = PageSpan {
            first_cluster,
            cluster_count: last_first + last_count - first_cluster,
            first_group: start_group as u32,
            group_count: (end_group - start_group) as u32,
            raw_size: sizes[start_group..end_group].iter().sum(),
        };
        start_group = end_group;
        span
    })
    .collect()
}

/// Lays out a page: all cluster headers first, then the data blocks grouped by kind (every
/// cluster's positions, then every cluster's normals, UVs, indices, materials), so that zstd
/// sees like data together. Header offsets are rebased from cluster-relative to page-relative.
/// Returns the page and its section boundaries (0, end of headers, end of each block kind).
fn assemble_page(clusters: &[&EncodedCluster]) -> (Vec<u8>, Vec<usize>) {
    let mut raw = vec![0u8; clusters.len() * CLUSTER_HEADER_SIZE];
    let mut headers: Vec<ClusterHeader> = clusters.iter().map(|c| c.header).collect();
    let mut sections = vec![0, raw.len()];
    for slot in 0..BLOCK_KINDS {
        for (c, header) in clusters.iter().zip(&mut headers) {
            if let Some(block) = c.block(slot) {
                header.block_offsets[slot] = raw.len() as u32;
                raw.extend_from_slice(block);
                raw.resize(raw.len().next_multiple_of(4), 0);
            }
        }
        sections.push(raw.len());
    }
    for (i, header) in headers.iter().enumerate() {
        raw[i * CLUSTER_HEADER_SIZE..][..CLUSTER_HEADER_SIZE].copy_from_slice(&header.encode());
    }
    (raw, sections)
}

/// Data block kinds, in page order: positions, normals, UVs, indices, materials.
const BLOCK_KINDS: usize = 5;

/// A cluster's data blocks by kind, unpadded; `None` for a kind the file does not carry.
pub(crate) type Blocks = [Option<Vec<u8>>; BLOCK_KINDS];

/// One cluster encoded for its page: header (block offsets not yet set) and data blocks, with
/// the cluster's place in the DAG. Compact: a large bake holds its finished clusters so.
pub struct EncodedCluster {
    /// Index of the group it belongs to.
    pub group: u32,
    /// Index of the group that produced it, or [`NO_GROUP`].
    pub own_group: u32,
    header: ClusterHeader,
    /// The blocks, one after the other (each padded to 4 bytes).
    data: Box<[u8]>,
    /// End of each block in `data`.
    ends: [u32; BLOCK_KINDS],
    /// Bit `k`: the cluster has a block of kind `k` (possibly empty).
    present: u8,
}

impl EncodedCluster {
    /// Encodes `c` for a file with `header`; `index` names the cluster in errors.
    pub fn new(c: &DagCluster, header: &Header, index: usize) -> Result<EncodedCluster, WriteError> {
        let (header_bytes, blocks) = encode_blocks(c, header, index)?;
        Ok(EncodedCluster::from_blocks(c.group, c.own_group, header_bytes, blocks))
    }

    /// A cluster from its GPU-layout header and blocks.
    pub(crate) fn from_blocks(
        group: u32,
        own_group: u32,
        header_bytes: ClusterHeader,
        blocks: Blocks,
    ) -> EncodedCluster {
        let mut data = Vec::new();
        let mut ends = [0u32; BLOCK_KINDS];
        let mut present = 0u8;
        for (slot, block) in blocks.iter().enumerate() {
            if let Some(b) = block {
                data.extend_from_slice(b);
                data.resize(data.len().next_multiple_of(4), 0);
                present |= 1 << slot;
            }
            ends[slot] = data.len() as u32;
        }
        EncodedCluster { group, own_group, header: header_bytes, data: data.into(), ends, present }
    }

    /// The block of kind `slot` (padded), if the cluster has one.
    fn block(&self, slot: usize) -> Option<&[u8]> {
        let start = if slot == 0 { 0 } else { self.ends[slot - 1] as usize };
        let end = self.ends[slot] as usize;
        (self.present & (1 << slot) != 0).then(|| &self.data[start..end])
    }

    fn size(&self) -> usize {
        CLUSTER_HEADER_SIZE + self.data.len()
    }

    /// The quantized values its blocks hold (the writer's own blocks: always well formed).
    pub(crate) fn quantized(&self, flags: u32) -> Quantized {
        let h = &self.header;
        let (v, t) = (h.vertex_count as usize, h.triangle_count as usize);
        let block = |slot: usize| self.block(slot).unwrap_or_default();
        let positions = unpack(block(ClusterHeader::POSITIONS), h.position_bits.map(u32::from), v);
        let indices = block(ClusterHeader::INDICES)[..3 * t].to_vec();
        let marks_at = (3 * t).next_multiple_of(4) as u64 * 8;
        let marks = (0..t as u64)
            .map(|k| match h.edge_flags & ClusterHeader::OPEN_EDGES {
                0 => 0,
                _ => read_bits(block(ClusterHeader::INDICES), marks_at + 3 * k, 3).unwrap_or(0) as u8,
            })
            .collect();
        let with = |flag: u32| flags & flag != 0;
        let pairs = |bytes: &[u8], n: usize| -> Vec<[u16; 2]> {
            bytes
                .chunks_exact(4)
                .take(n)
                .map(|b| [u16::from_le_bytes([b[0], b[1]]), u16::from_le_bytes([b[2], b[3]])])
                .collect()
        };
        Quantized {
            positions: positions
                .iter()
                .map(|d| std::array::from_fn(|k| h.position_min[k].wrapping_add(d[k] as i32)))
                .collect(),
            normals: if with(FLAG_NORMALS) {
                unpack(block(ClusterHeader::NORMALS), h.normal_bits.map(u32::from), v)
                    .iter()
                    .map(|d| std::array::from_fn(|k| h.normal_min[k].wrapping_add(d[k] as u16)))
                    .collect()
            } else {
                Vec::new()
            },
            uvs: if with(FLAG_UVS) { pairs(block(ClusterHeader::UVS), v) } else { Vec::new() },
            indices,
            materials: if with(FLAG_MATERIALS) {
                block(ClusterHeader::MATERIALS)
                    .chunks_exact(2)
                    .take(t)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
                    .collect()
            } else {
                Vec::new()
            },
            marks,
        }
    }
}

/// Encodes one cluster: its header (block offsets filled in by [`assemble_page`]) and blocks,
/// with its vertices in first-use order (FORMAT.md §4.3).
fn encode_blocks(c: &DagCluster, h: &Header, index: usize) -> Result<(ClusterHeader, Blocks), WriteError> {
    check_cluster(c, h.flags, index)?;
    let q = quantize(c, h).ok_or_else(|| WriteError::BadCluster {
        cluster: index,
        problem: "meshoptimizer's index codec does not give the triangles back".into(),
    })?;
    Ok(gpu_blocks(&q, h.flags))
}

/// A cluster's limits (FORMAT.md §3.2, §5): counts, indices in range, one value per vertex or
/// triangle of each attribute the file carries.
fn check_cluster(c: &DagCluster, flags: u32, index: usize) -> Result<(), WriteError> {
    let bad = |problem: String| WriteError::BadCluster { cluster: index, problem };
    let vertex_count = c.positions.len();
    let triangle_count = c.indices.len() / 3;
    if vertex_count == 0 || vertex_count > MAX_CLUSTER_VERTICES {
        return Err(bad(format!("{vertex_count} vertices (1..=256 allowed)")));
    }
    if triangle_count == 0 || triangle_count > MAX_CLUSTER_TRIANGLES || !c.indices.len().is_multiple_of(3) {
        return Err(bad(format!("{} indices (3..=384, multiple of 3)", c.indices.len())));
    }
    if let Some(i) = c.indices.iter().find(|&&i| i as usize >= vertex_count) {
        return Err(bad(format!("index {i} out of {vertex_count} vertices")));
    }
    if !c.open_edges.is_empty() && (c.open_edges.len() != triangle_count || c.open_edges.iter().any(|&m| m > 7)) {
        return Err(bad("open-edge marks: one 3-bit mask per triangle expected".into()));
    }
    let with = |flag: u32, len: usize, per: usize| (flags & flag == 0) || len == per;
    if !with(FLAG_NORMALS, c.normals.len(), vertex_count)
        || !with(FLAG_UVS, c.uvs.len(), vertex_count)
        || !with(FLAG_MATERIALS, c.materials.len(), triangle_count)
    {
        return Err(bad("attribute count does not match the vertex/triangle count".into()));
    }
    Ok(())
}

/// A checked cluster's quantized values in the canonical form (FORMAT.md §4.3).
fn quantize(c: &DagCluster, h: &Header) -> Option<Quantized> {
    let with = |flag: u32| h.flags & flag != 0;
    canonical(Quantized {
        positions: c.positions.clone(),
        normals: if with(FLAG_NORMALS) {
            c.normals.iter().map(|&n| oct_encode(n, h.normal_bits).map(|v| v as u16)).collect()
        } else {
            Vec::new()
        },
        uvs: if with(FLAG_UVS) { c.uvs.iter().map(|&uv| h.uv.quantize(uv)).collect() } else { Vec::new() },
        indices: c.indices.clone(),
        materials: if with(FLAG_MATERIALS) { c.materials.clone() } else { Vec::new() },
        marks: if c.open_edges.is_empty() { vec![0; c.indices.len() / 3] } else { c.open_edges.clone() },
    })
}

/// `q` in the writer's canonical form: its vertices renumbered in first-use order and its
/// triangles as meshoptimizer's index codec gives them back (FORMAT.md §4.3), or `None` where
/// the codec does not give them back. The values stay the same.
pub(crate) fn canonical(q: Quantized) -> Option<Quantized> {
    let v = q.positions.len();
    let order = first_use_order(&q.indices, v);
    let mut new_index = vec![0u8; v];
    for (new, &old) in order.iter().enumerate() {
        new_index[old as usize] = new as u8;
    }
    let indices: Vec<u8> = q.indices.iter().map(|&i| new_index[i as usize]).collect();
    let (indices, marks) = codec::canonical_triangles(&indices, &q.marks, v)?;
    Some(Quantized {
        positions: reordered(&q.positions, &order),
        normals: reordered(&q.normals, &order),
        uvs: reordered(&q.uvs, &order),
        indices,
        materials: q.materials,
        marks,
    })
}

/// Per-vertex `values` (none where the file has no such attribute) in the vertex `order`.
fn reordered<T: Copy>(values: &[T], order: &[u8]) -> Vec<T> {
    if values.is_empty() {
        return Vec::new();
    }
    order.iter().map(|&o| values[o as usize]).collect()
}

/// What keeps `q` from being values the writer stores (FORMAT.md §4.4), if anything: an
/// octahedral value over `2^normal_bits − 1`, vertices not in first-use order, or triangles
/// not as the index codec gives them back.
pub(crate) fn canonical_fault(q: &Quantized, normal_bits: u32) -> Option<&'static str> {
    // `normal_bits` is 4..=16 in a file with normals and unchecked in one without (which has
    // no octahedral values to bound), so the shift is done wide.
    let most = (1u64 << normal_bits.min(32)) - 1;
    if q.normals.iter().flatten().any(|&n| n as u64 > most) {
        return Some("an octahedral value is over 2^normal_bits - 1");
    }
    let v = q.positions.len();
    let in_order = first_use_order(&q.indices, v).iter().enumerate().all(|(i, &o)| i == o as usize);
    let stable = codec::canonical_triangles(&q.indices, &q.marks, v) == Some((q.indices.clone(), q.marks.clone()));
    (!(in_order && stable))
        .then_some("its vertices are not in first-use order or its triangles not as the index codec gives them back")
}

/// The GPU-layout header (block offsets left zero) and blocks of a quantized cluster
/// (FORMAT.md §5): the writer and the page decoder both lay clusters out here.
pub(crate) fn gpu_blocks(q: &Quantized, flags: u32) -> (ClusterHeader, Blocks) {
    let (lo, bits, packed) = pack_ranges(q.positions.iter().map(|p| p.map(|v| v as i64)));
    let mut header = ClusterHeader {
        vertex_count: q.positions.len() as u16,
        triangle_count: (q.indices.len() / 3) as u16,
        position_min: lo.map(|v| v as i32),
        position_bits: bits.map(|b| b as u8),
        block_offsets: [0; BLOCK_KINDS],
        normal_min: [0; 2],
        normal_bits: [0; 2],
        edge_flags: 0,
    };
    let mut blocks: Blocks = Default::default();
    blocks[ClusterHeader::POSITIONS] = Some(packed);
    if flags & FLAG_NORMALS != 0 {
        let (lo, bits, packed) = pack_ranges(q.normals.iter().map(|n| n.map(|v| v as i64)));
        header.normal_min = lo.map(|v| v as u16);
        header.normal_bits = bits.map(|b| b as u8);
        blocks[ClusterHeader::NORMALS] = Some(packed);
    }
    if flags & FLAG_UVS != 0 {
        blocks[ClusterHeader::UVS] = Some(q.uvs.iter().flatten().flat_map(|v| v.to_le_bytes()).collect());
    }
    blocks[ClusterHeader::INDICES] = Some(indices_block(&q.indices, &q.marks, &mut header));
    if flags & FLAG_MATERIALS != 0 {
        blocks[ClusterHeader::MATERIALS] = Some(q.materials.iter().flat_map(|m| m.to_le_bytes()).collect());
    }
    (header, blocks)
}

/// The indices block: the local indices, followed (after padding to 4 bytes) by the open-edge
/// block when any edge is marked, which `edge_flags` then announces (FORMAT.md §5.7). The marks sit right after the indices, so they need no offset field of their own.
fn indices_block(indices: &[u8], marks: &[u8], header: &mut ClusterHeader) -> Vec<u8> {
    let mut block = indices.to_vec();
    if marks.iter().any(|&m| m != 0) {
        header.edge_flags |= ClusterHeader::OPEN_EDGES;
        block.resize(block.len().next_multiple_of(4), 0);
        let mut bits = BitWriter::default();
        for &m in marks {
            bits.push(m as u32, 3);
        }
        block.extend(words_to_bytes(&bits.finish()));
    }
    block
}

/// Packs N-component integer vectors as offsets from their per-component minimum, each
/// component with the fewest bits that hold its range. Returns (minimum, bits, packed bytes).
fn pack_ranges<const N: usize>(values: impl Iterator<Item = [i64; N]> + Clone) -> ([i64; N], [u32; N], Vec<u8>) {
    let mut lo = [i64::MAX; N];
    let mut hi = [i64::MIN; N];
    for v in values.clone() {
        for k in 0..N {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    let bits: [u32; N] = std::array::from_fn(|k| bits_for((hi[k] - lo[k]) as u32));
    let count = values.clone().count() as u64;
    let mut w = BitWriter::with_capacity(count * bits.iter().map(|&b| b as u64).sum::<u64>());
    for v in values {
        for k in 0..N {
            w.push((v[k] - lo[k]) as u32, bits[k]);
        }
    }
    (lo, bits, words_to_bytes(&w.finish()))
}

/// `count` records of bit-packed fields of the given widths (FORMAT.md §5.2).
fn unpack<const N: usize>(bytes: &[u8], widths: [u32; N], count: usize) -> Vec<[u32; N]> {
    let stride: u64 = widths.iter().map(|&w| w as u64).sum();
    (0..count as u64)
        .map(|v| {
            let mut at = v * stride;
            std::array::from_fn(|k| {
                let value = read_bits(bytes, at, widths[k]).unwrap_or(0);
                at += widths[k] as u64;
                value
            })
        })
        .collect()
}

fn words_to_bytes(words: &[u32]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

/// Per page, the other pages it depends on: those holding its clusters' parents (the clusters
/// produced by its groups) and those holding their siblings (produced by the same group).
fn page_dependencies(pages: &[PageSpan], groups: &[Group], clusters: &[ClusterInfo]) -> Vec<Vec<u32>> {
    // Pages holding the output of each group.
    let mut output_pages: Vec<Vec<u32>> = vec![Vec::new(); groups.len()];
    for c in clusters {
        if c.own_group != NO_GROUP {
            output_pages[c.own_group as usize].push(groups[c.group as usize].page);
        }
    }
    for p in &mut output_pages {
        p.sort_unstable();
        p.dedup();
    }
    pages
        .iter()
        .enumerate()
        .map(|(i, page)| {
            let mut deps = Vec::new();
            let groups_here = page.first_group..page.first_group + page.group_count;
            for g in groups_here {
                deps.extend_from_slice(&output_pages[g as usize]);
            }
            for c in page.first_cluster..page.first_cluster + page.cluster_count {
                let own = clusters[c as usize].own_group;
                if own != NO_GROUP {
                    deps.extend_from_slice(&output_pages[own as usize]);
                }
            }
            deps.sort_unstable();
            deps.dedup();
            deps.retain(|&d| d as usize != i);
            deps
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::tests::{records, repeating_page, sample, with_first_target};

    /// The fast decoder against this reference one and the writer's layout: the same GPU
    /// bytes for a well-formed page, and for every corruption either both refuse it or both
    /// give the same bytes. `raw_size` is the intact page's: what the page table would say.
    fn agree(bytes: &[u8], records: &[ClusterInfo], flags: u32, normal_bits: u32, raw_size: usize) -> bool {
        agree_with(bytes, records, flags, normal_bits, raw_size, &Sources::default())
    }

    /// A page's sources as both decoders take them: the source pages' clusters and, from
    /// them, the keys in source numbering, the laid-out pages and their records.
    #[derive(Default)]
    struct Sources {
        keys: Vec<codec::VertexKey>,
        pages: Vec<(Vec<u8>, Vec<ClusterInfo>)>,
    }

    impl Sources {
        fn new(pages: &[Vec<Quantized>], flags: u32) -> Sources {
            let at = |clusters: &[Quantized]| {
                let mut r = records(clusters);
                for (i, r) in r.iter_mut().enumerate() {
                    r.page_offset = (i * CLUSTER_HEADER_SIZE) as u32;
                }
                r
            };
            Sources {
                keys: codec::source_keys(pages.iter().flatten()),
                pages: pages.iter().map(|p| (gpu_page(p, flags), at(p))).collect(),
            }
        }

        fn fast(&self) -> Vec<decode::SourcePage<'_>> {
            let mut out = Vec::new();
            for (i, (layout, records)) in self.pages.iter().enumerate() {
                out.push(decode::SourcePage { index: i as u32, layout, records });
            }
            out
        }
    }

    /// [`agree`] for a page with sources.
    fn agree_with(
        bytes: &[u8],
        records: &[ClusterInfo],
        flags: u32,
        normal_bits: u32,
        raw_size: usize,
        sources: &Sources,
    ) -> bool {
        let reference =
            codec::decode_page(bytes, records, flags, normal_bits, &sources.keys).map(|q| gpu_page(&q, flags));
        let len = reference.as_ref().map_or(raw_size, Vec::len);
        let fast = decode::decode_page_gpu(bytes, records, flags, normal_bits, len, Some(&sources.fast()));
        reference.is_ok() == fast.is_ok() && reference.ok() == fast.ok()
    }

    #[test]
    fn the_fast_decoder_agrees_with_the_reference() {
        let clusters = [sample(3, 5), sample(256, -7), sample(40, 1 << 30)];
        for flags in [0, FLAG_NORMALS, FLAG_UVS | FLAG_MATERIALS, FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS] {
            let clusters: Vec<Quantized> = clusters
                .iter()
                .map(|c| Quantized {
                    normals: if flags & FLAG_NORMALS != 0 { c.normals.clone() } else { vec![] },
                    uvs: if flags & FLAG_UVS != 0 { c.uvs.clone() } else { vec![] },
                    materials: if flags & FLAG_MATERIALS != 0 { c.materials.clone() } else { vec![] },
                    ..c.clone()
                })
                .collect();
            let records = records(&clusters);
            let bytes: Vec<u8> = codec::encode_page(&clusters, flags, &codec::SourceIndex::new([])).unwrap().concat();
            let gpu = gpu_page(&clusters, flags);
            assert_eq!(decode::decode_page_gpu(&bytes, &records, flags, 10, gpu.len(), None), Ok(gpu.clone()));
            // Any other raw size is refused.
            assert!(decode::decode_page_gpu(&bytes, &records, flags, 10, gpu.len() + 4, None).is_err());
            for i in 0..bytes.len() {
                let mut bad = bytes.clone();
                bad[i] ^= 1 << (i % 8);
                assert!(agree(&bad, &records, flags, 10, gpu.len()), "flags {flags}: byte {i} flipped");
            }
            for cut in (0..bytes.len()).step_by(7) {
                assert!(agree(&bytes[..cut], &records, flags, 10, gpu.len()), "flags {flags}: cut at {cut}");
            }
            assert!(agree(&bytes, &records, flags, 9, gpu.len()));
        }
    }
    /// With copies (FORMAT.md §4.3, references) too: the same bytes, and the same verdict on
    /// every corrupted byte; a bad target is an error for both, never a panic.
    #[test]
    fn the_fast_decoder_agrees_on_copies() {
        let flags = FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS;
        let (clusters, streams) = repeating_page();
        let records = records(&clusters);
        let bytes: Vec<u8> = streams.concat();
        let gpu = gpu_page(&clusters, flags);
        assert_eq!(decode::decode_page_gpu(&bytes, &records, flags, 10, gpu.len(), None), Ok(gpu.clone()));
        for low_byte in [0xfe, 0xff] {
            let bad =
                decode::decode_page_gpu(&with_first_target(&streams, low_byte), &records, flags, 10, gpu.len(), None);
            assert!(bad.unwrap_err().0.contains("copies vertex"));
        }
        for i in 0..bytes.len() {
            let mut bad = bytes.clone();
            bad[i] ^= 1 << (i % 8);
            assert!(agree(&bad, &records, flags, 10, gpu.len()), "byte {i} flipped");
        }
    }

    /// Two source pages (the second repeating a cluster of the first, so that some vertices
    /// have two source numbers) and a page repeating vertices of both and of itself.
    fn far_pages() -> (Vec<Vec<Quantized>>, Vec<Quantized>) {
        let sources = vec![vec![sample(50, 3), sample(30, -11)], vec![sample(50, 3)]];
        let copy = |to: &mut Quantized, v: usize, from: &Quantized, w: usize| {
            to.positions[v] = from.positions[w];
            to.normals[v] = from.normals[w];
            to.uvs[v] = from.uvs[w];
        };
        let mut a = sample(40, 77);
        for v in (0..30).step_by(2) {
            copy(&mut a, v, &sources[0][1], 29 - v);
        }
        for v in 33..40 {
            copy(&mut a, v, &sources[1][0], v);
        }
        let mut b = sample(60, 9);
        for v in (0..40).step_by(3) {
            copy(&mut b, v, &a, v); // within the page
        }
        for v in (41..60).step_by(2) {
            copy(&mut b, v, &sources[0][0], v - 10);
        }
        (sources, vec![a, b])
    }

    /// Far copies round-trip byte-exactly: the page decodes, with its sources, to the layout
    /// of its clusters as written (the same as without far copies), both decoders agree on
    /// every corruption, and a bad flag or source number is an error.
    #[test]
    fn far_copies_round_trip() {
        let flags = FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS;
        let (source_pages, clusters) = far_pages();
        let sources = Sources::new(&source_pages, flags);
        let records = records(&clusters);
        let streams =
            codec::encode_page(&clusters, flags, &codec::SourceIndex::new([&codec::PageKeys::new(&sources.keys)]))
                .unwrap();
        let bytes = streams.concat();
        let references = &streams[4];
        // Four of the second cluster's source vertices are in the first cluster too (copied
        // from the same vertex of the repeated source cluster): copies, not far copies.
        assert_eq!(references.iter().filter(|&&f| f == 2).count(), 15 + 7 + 10 - 4);
        assert_eq!(references.iter().filter(|&&f| f == 1).count(), 14 + 4);
        let gpu = gpu_page(&clusters, flags);
        let decoded = decode::decode_page_gpu(&bytes, &records, flags, 10, gpu.len(), Some(&sources.fast()));
        assert_eq!(decoded, Ok(gpu.clone()));
        assert_eq!(codec::decode_page(&bytes, &records, flags, 10, &sources.keys), Ok(clusters.clone()));
        // Without far copies: the same layout, more bytes; and no sources are needed.
        let alone = codec::encode_page(&clusters, flags, &codec::SourceIndex::new([])).unwrap().concat();
        assert!(alone.len() >= bytes.len() + 32 * 8, "{} bytes, {} alone", bytes.len(), alone.len());
        assert_eq!(decode::decode_page_gpu(&alone, &records, flags, 10, gpu.len(), None), Ok(gpu.clone()));
        // Without its sources the page is refused.
        let none = decode::decode_page_gpu(&bytes, &records, flags, 10, gpu.len(), None);
        assert_eq!(none.unwrap_err().0, decode::NEEDS_SOURCES);
        for i in 0..bytes.len() {
            let mut bad = bytes.clone();
            bad[i] ^= 1 << (i % 8);
            assert!(agree_with(&bad, &records, flags, 10, gpu.len(), &sources), "byte {i} flipped");
        }
        for cut in (0..bytes.len()).step_by(5) {
            assert!(agree_with(&bytes[..cut], &records, flags, 10, gpu.len(), &sources), "cut at {cut}");
        }
        // The first far copy names a source vertex before the first (−1), or past the last
        // when the page is given fewer source vertices (U = 50: vertex 79 is the 30th of the
        // first source's second cluster).
        let at = streams[..5 + streams[0][1] as usize].iter().map(Vec::len).sum::<usize>();
        assert_eq!(streams[0][2], 1, "one far target plane");
        let mut bad = bytes.clone();
        bad[at] = 1;
        let fewer = Sources::new(&source_pages[1..], flags);
        for (bad, sources) in [(&bad, &sources), (&bytes, &fewer)] {
            let fast = decode::decode_page_gpu(bad, &records, flags, 10, gpu.len(), Some(&sources.fast()));
            assert!(fast.unwrap_err().0.contains("source vertex"));
            let reference = codec::decode_page(bad, &records, flags, 10, &sources.keys);
            assert!(reference.unwrap_err().0.contains("source vertex"));
        }
        // A reference flag of 3.
        let flags_at = streams[..4].iter().map(Vec::len).sum::<usize>();
        let mut bad = bytes.clone();
        bad[flags_at + 1] = 3;
        let fast = decode::decode_page_gpu(&bad, &records, flags, 10, gpu.len(), Some(&sources.fast()));
        assert!(fast.unwrap_err().0.contains("reference flag 3"));
    }

    /// Equal source vertices: the writer names the one whose coded difference is smallest.
    #[test]
    fn far_copies_name_the_nearest_equal_source_vertex() {
        let keys: Vec<codec::VertexKey> = [5, 7, 5, 9, 5].iter().map(|&x| ([x, 0, 0], [0; 2], [0; 2])).collect();
        let page = codec::PageKeys::new(&keys);
        let index = codec::SourceIndex::new([&page]);
        let five = ([5, 0, 0], [0; 2], [0; 2]);
        assert_eq!(index.nearest(&five, 0), Some(0));
        assert_eq!(index.nearest(&five, 2), Some(2));
        assert_eq!(index.nearest(&five, 3), Some(2)); // −1 codes smaller than +1
        assert_eq!(index.nearest(&five, 9), Some(4));
        assert_eq!(index.nearest(&([6, 0, 0], [0; 2], [0; 2]), 0), None);
        // The same vertices as the pages of several sources: numbered on across them, and the
        // same answers, wherever the split falls.
        for split in 0..=keys.len() {
            let (a, b) = (codec::PageKeys::new(&keys[..split]), codec::PageKeys::new(&keys[split..]));
            let two = codec::SourceIndex::new([&a, &b]);
            for x in 4..=10 {
                for next in -2..12 {
                    let k = ([x, 0, 0], [0; 2], [0; 2]);
                    assert_eq!(two.nearest(&k, next), index.nearest(&k, next), "split {split}, {x}, {next}");
                }
            }
        }
    }
}
