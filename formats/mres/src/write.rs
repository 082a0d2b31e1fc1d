//! Writer: a logical [`Dag`] to `.mres` bytes (FORMAT.md). Deterministic: the same `Dag`
//! always gives the same bytes.

use super::bits::{bits_for, oct_encode, BitWriter};
use super::*;
use rayon::prelude::*;

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
}

/// Serializes `dag` to a complete `.mres` file; pages are compressed with zstd at `level`.
pub fn write_mres(dag: &Dag, level: i32) -> Result<Vec<u8>, WriteError> {
    let clusters: Vec<EncodedCluster> = dag
        .clusters
        .par_iter()
        .enumerate()
        .map(|(i, c)| EncodedCluster::new(c, &dag.header, i))
        .collect::<Result<_, _>>()?;
    write_encoded(&dag.header, &dag.groups, clusters, level)
}

/// [`write_mres`] for clusters already encoded with [`EncodedCluster::new`] (a large bake
/// keeps its finished clusters in this compact form). Consumes them: the hierarchy and page
/// table are laid out first (their sizes do not depend on compression), then pages are
/// compressed a batch at a time straight into the file, and each batch's clusters are freed,
/// so that the encoded clusters and the file are never both held whole.
pub fn write_encoded(
    header: &Header,
    groups: &[Group],
    mut encoded: Vec<EncodedCluster>,
    level: i32,
) -> Result<Vec<u8>, WriteError> {
    let layout = Layout::new(groups, &encoded)?;
    let pages = page_spans(&layout, &encoded);

    // Renumbered hierarchy. A cluster's header sits at its index in its page × header size.
    let mut new_groups = Vec::with_capacity(groups.len());
    let mut clusters = Vec::with_capacity(encoded.len());
    let mut page_offsets = vec![0u32; encoded.len()];
    for page in &pages {
        for c in 0..page.cluster_count {
            page_offsets[(page.first_cluster + c) as usize] = c * CLUSTER_HEADER_SIZE as u32;
        }
    }
    for (new_g, &old_g) in layout.group_order.iter().enumerate() {
        let g = &groups[old_g];
        let (first, count) = layout.group_ranges[new_g];
        new_groups.push(Group {
            first_cluster: first,
            cluster_count: count,
            page: layout.group_page(&pages, new_g),
            ..*g
        });
    }
    for (new_c, &old_c) in layout.cluster_order.iter().enumerate() {
        let c = &encoded[old_c];
        clusters.push(ClusterInfo {
            group: layout.group_new[c.group as usize],
            own_group: if c.own_group == NO_GROUP { NO_GROUP } else { layout.group_new[c.own_group as usize] },
            vertex_count: u16::from_le_bytes([c.header[0], c.header[1]]),
            triangle_count: u16::from_le_bytes([c.header[2], c.header[3]]),
            page_offset: page_offsets[new_c],
        });
    }
    let groups = new_groups;
    let dependencies = page_dependencies(&pages, &groups, &clusters);

    let mut hierarchy = Vec::new();
    for g in &groups {
        put_f32s(&mut hierarchy, &g.sphere.center);
        put_f32s(&mut hierarchy, &[g.sphere.radius, g.error]);
        for v in [g.level, g.first_cluster, g.cluster_count, g.page, 0] {
            hierarchy.extend_from_slice(&v.to_le_bytes());
        }
    }
    for c in &clusters {
        hierarchy.extend_from_slice(&c.group.to_le_bytes());
        hierarchy.extend_from_slice(&c.own_group.to_le_bytes());
        hierarchy.extend_from_slice(&c.vertex_count.to_le_bytes());
        hierarchy.extend_from_slice(&c.triangle_count.to_le_bytes());
        hierarchy.extend_from_slice(&c.page_offset.to_le_bytes());
    }
    let hierarchy_offset = HEADER_SIZE as u64;
    let page_table_offset = hierarchy_offset + hierarchy.len() as u64;
    let dep_total: usize = dependencies.iter().map(Vec::len).sum();
    let page_table_size = (pages.len() * PAGE_RECORD_SIZE + dep_total * 4) as u64;

    // The pages, straight into the file after room for the header, hierarchy and table.
    let mut out = vec![0u8; (page_table_offset + page_table_size) as usize];
    let mut frames: Vec<(u64, u32, [u8; 32])> = Vec::with_capacity(pages.len());
    for batch in pages.chunks(PAGE_BATCH) {
        let compressed: Vec<Vec<u8>> = batch
            .par_iter()
            .map(|page| {
                let members = &layout.cluster_order[page.first_cluster as usize..][..page.cluster_count as usize];
                let members: Vec<&EncodedCluster> = members.iter().map(|&c| &encoded[c]).collect();
                compress_page(&members, level)
            })
            .collect::<Result<_, _>>()?;
        for frame in compressed {
            frames.push((out.len() as u64, frame.len() as u32, *blake3::hash(&frame).as_bytes()));
            out.extend_from_slice(&frame);
        }
        for page in batch {
            for &c in &layout.cluster_order[page.first_cluster as usize..][..page.cluster_count as usize] {
                encoded[c].data = Box::default();
            }
        }
        release_freed_memory();
    }
    drop(encoded);

    let mut table = Vec::with_capacity(page_table_size as usize);
    let mut dep_first = 0u32;
    for ((page, deps), (offset, length, checksum)) in pages.iter().zip(&dependencies).zip(&frames) {
        table.extend_from_slice(&offset.to_le_bytes());
        table.extend_from_slice(&length.to_le_bytes());
        table.extend_from_slice(&(page.raw_size as u32).to_le_bytes());
        table.extend_from_slice(checksum);
        for v in
            [page.first_cluster, page.cluster_count, page.first_group, page.group_count, dep_first, deps.len() as u32]
        {
            table.extend_from_slice(&v.to_le_bytes());
        }
        dep_first += deps.len() as u32;
    }
    for d in dependencies.iter().flatten() {
        table.extend_from_slice(&d.to_le_bytes());
    }

    let level_count = groups.iter().map(|g| g.level + 1).max().unwrap_or(0);
    let h = header;
    let mut head = Vec::with_capacity(HEADER_SIZE);
    head.extend_from_slice(&MAGIC);
    for v in [VERSION, HEADER_SIZE as u32, h.flags] {
        head.extend_from_slice(&v.to_le_bytes());
    }
    put_f32s(&mut head, &h.grid.origin);
    put_f32s(&mut head, &[h.grid.step]);
    put_f32s(&mut head, &h.uv.min);
    put_f32s(&mut head, &h.uv.extent);
    for v in
        [h.normal_bits, h.position_bits, level_count, groups.len() as u32, clusters.len() as u32, pages.len() as u32]
    {
        head.extend_from_slice(&v.to_le_bytes());
    }
    for v in [h.source_triangles, hierarchy_offset, hierarchy.len() as u64, page_table_offset, page_table_size] {
        head.extend_from_slice(&v.to_le_bytes());
    }
    debug_assert_eq!(head.len(), 112);
    let checksum = meta_checksum(&head, &hierarchy, &table);
    head.extend_from_slice(&checksum);
    out[..head.len()].copy_from_slice(&head);
    out[HEADER_SIZE..][..hierarchy.len()].copy_from_slice(&hierarchy);
    out[page_table_offset as usize..][..table.len()].copy_from_slice(&table);
    Ok(out)
}

/// Pages compressed at a time: enough for every thread, few enough that the batch's frames
/// and raw pages stay small.
const PAGE_BATCH: usize = 64;

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

/// blake3 over the first 112 header bytes, the hierarchy section and the page table.
pub(crate) fn meta_checksum(header: &[u8], hierarchy: &[u8], table: &[u8]) -> [u8; 32] {
    let mut hasher = blake3::Hasher::new();
    hasher.update(&header[..112]);
    hasher.update(hierarchy);
    hasher.update(table);
    *hasher.finalize().as_bytes()
}

fn put_f32s(out: &mut Vec<u8>, values: &[f32]) {
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
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

/// Compresses a page as one zstd frame per section (headers, then each block kind), so that
/// each section gets its own entropy tables: in one frame, zstd's 128 KiB blocks would make
/// the well-compressing indices share tables with the near-random bit-packed positions.
/// The bit-packed positions and normals (sections 1 and 2) are near-random: they get zstd's
/// fastest level, which compresses them as well as level 19 does.
fn compress_page(clusters: &[&EncodedCluster], level: i32) -> std::io::Result<Vec<u8>> {
    let (raw, sections) = assemble_page(clusters);
    let mut out = Vec::new();
    for (section, w) in sections.windows(2).enumerate() {
        if w[1] > w[0] {
            let level = if section == 1 || section == 2 { 1 } else { level };
            out.extend_from_slice(&zstd::bulk::compress(&raw[w[0]..w[1]], level)?);
        }
    }
    Ok(out)
}

/// One page's place: its clusters and groups (in the new order) and its decompressed size.
struct PageSpan {
    first_cluster: u32,
    cluster_count: u32,
    first_group: u32,
    group_count: u32,
    raw_size: usize,
}

/// Greedily fills pages with whole groups in coarse-to-fine order.
fn page_spans(layout: &Layout, encoded: &[EncodedCluster]) -> Vec<PageSpan> {
    let size = |g: usize| -> usize {
        let (first, count) = layout.group_ranges[g];
        (first..first + count).map(|c| encoded[layout.cluster_order[c as usize]].size()).sum()
    };
    let mut spans = Vec::new();
    let mut start_group = 0usize;
    while start_group < layout.group_ranges.len() {
        let mut end_group = start_group;
        let mut raw_size = 0usize;
        while end_group < layout.group_ranges.len() {
            let group_size = size(end_group);
            if end_group > start_group && raw_size + group_size > PAGE_TARGET_RAW_SIZE {
                break;
            }
            raw_size += group_size;
            end_group += 1;
        }
        let first_cluster = layout.group_ranges[start_group].0;
        let (last_first, last_count) = layout.group_ranges[end_group - 1];
        spans.push(PageSpan {
            first_cluster,
            cluster_count: last_first + last_count - first_cluster,
            first_group: start_group as u32,
            group_count: (end_group - start_group) as u32,
            raw_size,
        });
        start_group = end_group;
    }
    spans
}

/// Lays out a page: all cluster headers first, then the data blocks grouped by kind (every
/// cluster's positions, then every cluster's normals, UVs, indices, materials), so that zstd
/// sees like data together. Header offsets are rebased from cluster-relative to page-relative.
/// Returns the page and its section boundaries (0, end of headers, end of each block kind).
fn assemble_page(clusters: &[&EncodedCluster]) -> (Vec<u8>, Vec<usize>) {
    let mut raw = vec![0u8; clusters.len() * CLUSTER_HEADER_SIZE];
    let mut headers: Vec<[u8; CLUSTER_HEADER_SIZE]> = clusters.iter().map(|c| c.header).collect();
    let mut sections = vec![0, raw.len()];
    for slot in 0..BLOCK_KINDS {
        for (c, header) in clusters.iter().zip(&mut headers) {
            if let Some(block) = c.block(slot) {
                let at = 20 + slot * 4;
                header[at..at + 4].copy_from_slice(&(raw.len() as u32).to_le_bytes());
                raw.extend_from_slice(block);
                raw.resize(raw.len().next_multiple_of(4), 0);
            }
        }
        sections.push(raw.len());
    }
    for (i, header) in headers.iter().enumerate() {
        raw[i * CLUSTER_HEADER_SIZE..][..CLUSTER_HEADER_SIZE].copy_from_slice(header);
    }
    (raw, sections)
}

/// Data block kinds, in page order: positions, normals, UVs, indices, materials.
const BLOCK_KINDS: usize = 5;

/// One cluster encoded for its page: header (block offsets not yet set) and data blocks, with
/// the cluster's place in the DAG. Compact: a large bake holds its finished clusters so.
pub struct EncodedCluster {
    /// Index of the group it belongs to.
    pub group: u32,
    /// Index of the group that produced it, or [`NO_GROUP`].
    pub own_group: u32,
    header: [u8; CLUSTER_HEADER_SIZE],
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
        Ok(EncodedCluster {
            group: c.group,
            own_group: c.own_group,
            header: header_bytes,
            data: data.into(),
            ends,
            present,
        })
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
}

/// Encodes one cluster: its header (block offsets filled in by [`assemble_page`]) and blocks.
#[allow(clippy::type_complexity)]
fn encode_blocks(
    c: &DagCluster,
    h: &Header,
    index: usize,
) -> Result<([u8; CLUSTER_HEADER_SIZE], [Option<Vec<u8>>; BLOCK_KINDS]), WriteError> {
    let flags = h.flags;
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
    let with = |flag: u32, len: usize, per: usize| (flags & flag == 0) || len == per;
    if !with(FLAG_NORMALS, c.normals.len(), vertex_count)
        || !with(FLAG_UVS, c.uvs.len(), vertex_count)
        || !with(FLAG_MATERIALS, c.materials.len(), triangle_count)
    {
        return Err(bad("attribute count does not match the vertex/triangle count".into()));
    }

    let mut header = [0u8; CLUSTER_HEADER_SIZE];
    header[0..2].copy_from_slice(&(vertex_count as u16).to_le_bytes());
    header[2..4].copy_from_slice(&(triangle_count as u16).to_le_bytes());
    let mut blocks: [Option<Vec<u8>>; BLOCK_KINDS] = Default::default();

    let (lo, bits, packed) = pack_ranges(c.positions.iter().map(|p| p.map(|v| v as i64)));
    for k in 0..3 {
        header[4 + k * 4..8 + k * 4].copy_from_slice(&(lo[k] as i32).to_le_bytes());
        header[16 + k] = bits[k] as u8;
    }
    blocks[0] = Some(packed);
    if flags & FLAG_NORMALS != 0 {
        let (lo, bits, packed) = pack_ranges(c.normals.iter().map(|n| oct_encode(*n, h.normal_bits).map(|v| v as i64)));
        header[40..42].copy_from_slice(&(lo[0] as u16).to_le_bytes());
        header[42..44].copy_from_slice(&(lo[1] as u16).to_le_bytes());
        header[44] = bits[0] as u8;
        header[45] = bits[1] as u8;
        blocks[1] = Some(packed);
    }
    if flags & FLAG_UVS != 0 {
        blocks[2] = Some(c.uvs.iter().flat_map(|uv| h.uv.quantize(*uv)).flat_map(u16::to_le_bytes).collect());
    }
    blocks[3] = Some(c.indices.clone());
    if flags & FLAG_MATERIALS != 0 {
        blocks[4] = Some(c.materials.iter().flat_map(|m| m.to_le_bytes()).collect());
    }
    Ok((header, blocks))
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
    let mut w = BitWriter::default();
    for v in values {
        for k in 0..N {
            w.push((v[k] - lo[k]) as u32, bits[k]);
        }
    }
    (lo, bits, words_to_bytes(&w.finish()))
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
