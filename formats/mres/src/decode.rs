//! The page decoder: a page's encoded bytes (FORMAT.md §4.3) straight to its GPU layout (§5),
//! the layout the writer lays out ([`crate::write`]), byte for byte.
//!
//! One pass rebuilds every vertex of the page into flat buffers reused from page to page (no
//! allocation per cluster or vertex but the index codec's output); a second lays the page out
//! into one buffer of the size the page table gives, allocated once its size is known to match.
//! The writer decodes every page it writes here and compares the result with the page it laid
//! out itself, so the two layouts cannot drift apart.

use super::codec::{encoded_len, index_bound, invalid, preamble, reference_counts, totals, unzigzag16, unzigzag32};
use super::codec::{walk, EdgeTable, Invalid, Lanes, PlaneReader, Predictor, Shape, Targets, VertexKey, PREAMBLE};
use super::records::ClusterHeader;
use super::*;
use std::cell::RefCell;

/// Buffers the decoder reuses from page to page (one set per thread).
struct Scratch {
    edges: EdgeTable,
    positions: Vec<[i32; 3]>,
    normals: Vec<[u16; 2]>,
    uvs: Vec<[u16; 2]>,
    indices: Vec<u8>,
    /// Per vertex of the page in decoding order, its place in the page (the references'
    /// targets).
    order: Vec<u32>,
    /// One cluster's predictors, then its residuals in decoding order and its values by slot
    /// (see [`Sources::rebuild`]); never cleared, as each cluster writes what it reads.
    sources: Sources,
    wide: Box<Residuals<[i32; 3]>>,
    pairs: Box<Residuals<[u16; 2]>>,
}

/// One attribute of one cluster while it is rebuilt: its residuals in decoding order and its
/// values by slot.
struct Residuals<T> {
    /// In decoding order (a copied vertex's is zero).
    residuals: [T; MAX_CLUSTER_VERTICES],
    values: [T; SLOTS],
}

impl<T: Lanes> Residuals<T> {
    fn new() -> Box<Residuals<T>> {
        Box::new(Residuals { residuals: [T::default(); MAX_CLUSTER_VERTICES], values: [T::default(); SLOTS] })
    }
}

thread_local! {
    static SCRATCH: RefCell<Option<Scratch>> = const { RefCell::new(None) };
}

/// The sections of an encoded page (FORMAT.md §4.3), their lengths checked against the
/// page's counts.
struct Sections<'a> {
    lengths: &'a [u8],
    coded: &'a [u8],
    marks: &'a [u8],
    /// Reference flags, one per vertex in decoding order.
    references: &'a [u8],
    /// The copies' coded targets: `target_planes` planes of `copies` bytes.
    targets: &'a [u8],
    target_planes: usize,
    copies: usize,
    /// The far copies' coded source vertex numbers: `far_planes` planes of `far` bytes.
    far_targets: &'a [u8],
    far_planes: usize,
    far: usize,
    /// Position planes, each `3 × stored` bytes.
    positions: &'a [u8],
    planes: usize,
    /// Vertices stored with residuals (reference 0).
    stored: usize,
    normals: &'a [u8],
    uvs: &'a [u8],
    materials: &'a [u8],
}

impl<'a> Sections<'a> {
    fn split(bytes: &'a [u8], records: &[ClusterInfo], flags: u32) -> Result<Sections<'a>, Invalid> {
        let (v, t) = totals(records);
        if bytes.len() < PREAMBLE + 2 * records.len() {
            return invalid("encoded page ends early");
        }
        let (head, rest) = bytes.split_at(PREAMBLE);
        let (planes, target_planes, far_planes) = preamble(head)?;
        let (lengths, rest) = rest.split_at(2 * records.len());
        let index_bytes: usize = lengths.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]]) as usize).sum();
        // The reference flags say how many vertices carry residuals, so they are read first.
        let Some(references) = rest.get(index_bytes + t..index_bytes + t + v) else {
            return invalid("encoded page ends early");
        };
        let (copies, far) = reference_counts(references)?;
        let shape = Shape { index_bytes, planes, target_planes, copies, far_planes, far };
        let stored = shape.stored(v);
        let expected = encoded_len(flags, records.len(), (v, t), shape);
        if bytes.len() != expected {
            return invalid(format!(
                "{} encoded bytes, its counts, lengths and references need {expected}",
                bytes.len()
            ));
        }
        // The total length matches every section below, so none of these splits runs short.
        let with = |flag: u32, n: usize| if flags & flag != 0 { n } else { 0 };
        let (coded, rest) = rest.split_at(index_bytes);
        let (marks, rest) = rest.split_at(t);
        let (_, rest) = rest.split_at(v);
        let (targets, rest) = rest.split_at(target_planes * copies);
        let (far_targets, rest) = rest.split_at(far_planes * far);
        let (positions, rest) = rest.split_at(planes * 3 * stored);
        let (normals, rest) = rest.split_at(with(FLAG_NORMALS, 4 * stored));
        let (uvs, materials) = rest.split_at(with(FLAG_UVS, 4 * stored));
        if let Some(m) = marks.iter().find(|&&m| m > 7) {
            return invalid(format!("open-edge mark {m} has bits above bit 2"));
        }
        Ok(Sections {
            lengths,
            coded,
            marks,
            references,
            targets,
            target_planes,
            copies,
            far_targets,
            far_planes,
            far,
            positions,
            planes,
            stored,
            normals,
            uvs,
            materials,
        })
    }
}

/// The error of a page with far copies decoded without its sources.
pub(crate) const NEEDS_SOURCES: &str = "the page copies vertices of its sources, whose layouts were not given";

/// A source of the page being decoded (FORMAT.md §4.3): a page stored before it that it
/// depends on, as its decoded GPU layout, which far copies read their values from.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SourcePage<'a> {
    /// Page index (for messages).
    pub index: u32,
    /// Its GPU layout (§5), as given: every read from it is bounds-checked.
    pub layout: &'a [u8],
    /// Its cluster records, in cluster order.
    pub records: &'a [ClusterInfo],
}

/// Decodes a page's encoded bytes (FORMAT.md §4.3) to its GPU layout (§5), which must be
/// exactly `raw_size` bytes; `records` are the page's cluster records and `sources` its
/// sources in order, or `None` if the caller has none to give: a page without far copies
/// decodes alone, one with them is then refused with [`NEEDS_SOURCES`]. Every index, octahedral value,
/// mark and far copy's source vertex is checked against its range, the section lengths
/// against the counts; nothing is allocated beyond the page's counts and `raw_size`.
pub(crate) fn decode_page_gpu(
    bytes: &[u8],
    records: &[ClusterInfo],
    flags: u32,
    normal_bits: u32,
    raw_size: usize,
    sources: Option<&[SourcePage]>,
) -> Result<Vec<u8>, Invalid> {
    SCRATCH.with(|cell| {
        let mut cell = cell.borrow_mut();
        let scratch = cell.get_or_insert_with(|| Scratch {
            edges: EdgeTable::new(),
            positions: Vec::new(),
            normals: Vec::new(),
            uvs: Vec::new(),
            indices: Vec::new(),
            order: Vec::new(),
            sources: Sources::default(),
            wide: Residuals::new(),
            pairs: Residuals::new(),
        });
        let s = Sections::split(bytes, records, flags)?;
        let far = match (s.far, sources) {
            (0, _) => None,
            (_, Some(sources)) => Some(SourceVertices::new(sources, flags)?),
            (_, None) => return invalid(NEEDS_SOURCES),
        };
        scratch.rebuild(&s, records, flags, normal_bits, far.as_ref())?;
        scratch.lay_out(&s, records, flags, raw_size)
    })
}

impl Scratch {
    /// Every vertex's values and every cluster's indices, page-wide and in cluster order
    /// (vertices at their local index within their cluster's range).
    fn rebuild(
        &mut self,
        s: &Sections,
        records: &[ClusterInfo],
        flags: u32,
        normal_bits: u32,
        far: Option<&SourceVertices>,
    ) -> Result<(), Invalid> {
        let (v_total, t_total) = totals(records);
        let (normals, uvs) = (flags & FLAG_NORMALS != 0, flags & FLAG_UVS != 0);
        // Every vertex is written before it is read (see `Sources`), so only growth zeroes.
        grow(&mut self.positions, v_total);
        grow(&mut self.normals, if normals { v_total } else { 0 });
        grow(&mut self.uvs, if uvs { v_total } else { 0 });
        self.indices.clear();
        self.indices.reserve(3 * t_total);
        grow(&mut self.order, v_total);
        let mut anchors = (<[i32; 3]>::default(), <[u16; 2]>::default(), <[u16; 2]>::default());
        let (mut vo, mut so, mut io) = (0usize, 0usize, 0usize);
        let mut targets = Copies {
            coded: PlaneReader { bytes: s.targets, planes: s.target_planes, count: s.copies, at: 0 },
            follow: Targets::new(),
            far_coded: PlaneReader { bytes: s.far_targets, planes: s.far_planes, count: s.far, at: 0 },
            follow_far: Targets::new(),
            sources: far,
            near: 0,
        };
        let (sources, wide, pairs) = (&mut self.sources, &mut *self.wide, &mut *self.pairs);
        for (r, len) in records.iter().zip(s.lengths.chunks_exact(2)) {
            let (vc, tc) = (r.vertex_count as usize, r.triangle_count as usize);
            let len = u16::from_le_bytes([len[0], len[1]]) as usize;
            let start = self.indices.len();
            decode_indices(&s.coded[io..io + len], vc, tc, &mut self.indices)?;
            sources.walk(&self.indices[start..], vc, &mut self.edges);
            let sc = sources.link(s, vo, &mut self.order[..v_total], &mut targets)?;
            position_residuals(s, so, sc, &mut wide.residuals);
            sources.spread(&mut wide.residuals, sc);
            let far = |f: &(u16, VertexKey)| (f.0, f.1 .0);
            anchors.0 = sources.rebuild(wide, vc, anchors.0, &mut self.positions[..v_total], vo, far);
            if normals {
                pair_residuals(s.normals, so, sc, s.stored, &mut pairs.residuals);
                sources.spread(&mut pairs.residuals, sc);
                let far = |f: &(u16, VertexKey)| (f.0, f.1 .1);
                anchors.1 = sources.rebuild(pairs, vc, anchors.1, &mut self.normals[..v_total], vo, far);
            }
            if uvs {
                pair_residuals(s.uvs, so, sc, s.stored, &mut pairs.residuals);
                sources.spread(&mut pairs.residuals, sc);
                let far = |f: &(u16, VertexKey)| (f.0, f.1 .2);
                anchors.2 = sources.rebuild(pairs, vc, anchors.2, &mut self.uvs[..v_total], vo, far);
            }
            (vo, so, io) = (vo + vc, so + sc, io + len);
        }
        let max_normal = ((1u32 << normal_bits.min(16)) - 1) as u16;
        if let Some(n) = self.normals[..if normals { v_total } else { 0 }].iter().flatten().find(|&&n| n > max_normal) {
            return invalid(format!("octahedral value {n} above {max_normal}"));
        }
        Ok(())
    }

    /// The GPU layout of the rebuilt page, as the writer lays it out: every cluster header,
    /// then each kind of block for every cluster in turn, each block padded to 4 bytes.
    fn lay_out(&self, s: &Sections, records: &[ClusterInfo], flags: u32, raw_size: usize) -> Result<Vec<u8>, Invalid> {
        let mut headers = self.headers(s, records, flags);
        let end = place_blocks(&mut headers, flags);
        if end != raw_size {
            return invalid(format!("decodes to {end} bytes, table says {raw_size}"));
        }
        let mut raw = vec![0u8; raw_size];
        let (mut vo, mut to) = (0usize, 0usize);
        for (i, h) in headers.iter().enumerate() {
            raw[i * CLUSTER_HEADER_SIZE..][..CLUSTER_HEADER_SIZE].copy_from_slice(&h.encode());
            let (vc, tc) = (h.vertex_count as usize, h.triangle_count as usize);
            self.write_blocks(&mut raw, h, s, (vo, vc), (to, tc), flags);
            (vo, to) = (vo + vc, to + tc);
        }
        Ok(raw)
    }

    /// Each cluster's header, block offsets not yet set: value ranges and bit widths of its
    /// positions and normals, and whether it has an open-edge block.
    fn headers(&self, s: &Sections, records: &[ClusterInfo], flags: u32) -> Vec<ClusterHeader> {
        let (mut vo, mut to) = (0usize, 0usize);
        let mut out = Vec::with_capacity(records.len());
        for r in records {
            let (vc, tc) = (r.vertex_count as usize, r.triangle_count as usize);
            let (position_min, position_bits) = ranges(self.positions[vo..vo + vc].iter().map(|p| p.map(i64::from)));
            let mut h = ClusterHeader {
                vertex_count: r.vertex_count,
                triangle_count: r.triangle_count,
                position_min: position_min.map(|v| v as i32),
                position_bits,
                block_offsets: [0; 5],
                normal_min: [0; 2],
                normal_bits: [0; 2],
                edge_flags: 0,
            };
            if flags & FLAG_NORMALS != 0 {
                let (lo, bits) = ranges(self.normals[vo..vo + vc].iter().map(|n| n.map(i64::from)));
                (h.normal_min, h.normal_bits) = (lo.map(|v| v as u16), bits);
            }
            if s.marks[to..to + tc].iter().any(|&m| m != 0) {
                h.edge_flags = ClusterHeader::OPEN_EDGES;
            }
            out.push(h);
            (vo, to) = (vo + vc, to + tc);
        }
        out
    }

    /// Writes one cluster's blocks at its header's offsets; `vertices` and `triangles` are
    /// (first, count) in the page.
    fn write_blocks(
        &self,
        raw: &mut [u8],
        h: &ClusterHeader,
        s: &Sections,
        (vo, vc): (usize, usize),
        (to, tc): (usize, usize),
        flags: u32,
    ) {
        let lens = block_lengths(h);
        let block = |slot: usize| {
            let at = h.block_offsets[slot] as usize;
            at..at + lens[slot]
        };
        let lo = h.position_min;
        let bits = h.position_bits.map(u32::from);
        let deltas =
            self.positions[vo..vo + vc].iter().map(|p| std::array::from_fn(|k| p[k].wrapping_sub(lo[k]) as u32));
        let r = block(ClusterHeader::POSITIONS);
        pack(&mut raw[r], deltas, bits);
        if flags & FLAG_NORMALS != 0 {
            let lo = h.normal_min;
            let deltas =
                self.normals[vo..vo + vc].iter().map(|n| std::array::from_fn(|k| n[k].wrapping_sub(lo[k]) as u32));
            let r = block(ClusterHeader::NORMALS);
            pack(&mut raw[r], deltas, h.normal_bits.map(u32::from));
        }
        if flags & FLAG_UVS != 0 {
            let r = block(ClusterHeader::UVS);
            for (out, uv) in raw[r].chunks_exact_mut(4).zip(&self.uvs[vo..vo + vc]) {
                out[..2].copy_from_slice(&uv[0].to_le_bytes());
                out[2..].copy_from_slice(&uv[1].to_le_bytes());
            }
        }
        let r = block(ClusterHeader::INDICES);
        let indices = &mut raw[r];
        indices[..3 * tc].copy_from_slice(&self.indices[3 * to..3 * (to + tc)]);
        if h.edge_flags & ClusterHeader::OPEN_EDGES != 0 {
            let marks = s.marks[to..to + tc].iter().map(|&m| [m as u32]);
            pack(&mut indices[(3 * tc).next_multiple_of(4)..], marks, [3]);
        }
        if flags & FLAG_MATERIALS != 0 {
            let t_total = s.materials.len() / 2;
            let r = block(ClusterHeader::MATERIALS);
            for (i, out) in raw[r].chunks_exact_mut(2).enumerate() {
                out.copy_from_slice(&[s.materials[to + i], s.materials[t_total + to + i]]);
            }
        }
    }
}

/// `v` at least `len` long, reusing its allocation (what it holds is overwritten).
fn grow<T: Default + Clone>(v: &mut Vec<T>, len: usize) {
    if v.len() < len {
        v.resize(len, T::default());
    }
}

/// The copies' targets and the far copies' source vertices as the page's clusters read them,
/// in order.
struct Copies<'a> {
    coded: PlaneReader<'a>,
    follow: Targets,
    far_coded: PlaneReader<'a>,
    follow_far: Targets,
    /// The page's source vertices (present iff the page has far copies).
    sources: Option<&'a SourceVertices<'a>>,
    /// The source cluster of the last far copy (see [`SourceVertices::vertex`]).
    near: usize,
}

/// Slot of a cluster's anchor (the previous cluster's first vertex) in [`Sources::rebuild`]'s
/// values, after the 256 vertex slots.
const ANCHOR: u16 = 256;
/// Slot of zero, which a one-vertex prediction adds and subtracts.
const ZERO: u16 = 257;
/// First of the slots that hold the values of earlier clusters' (or source pages') vertices
/// that this cluster's vertices copy: `COPIES + i` for the vertex decoded `i`-th.
const COPIES: u16 = 512;
/// Value slots: a power of two, so that a slot index masks into range without a check.
const SLOTS: usize = 1024;

/// A cluster's vertices in decoding order, each with the three value slots its prediction
/// `a + b − d` reads: a parallelogram reads three decoded vertices, a neighbour `(n, ZERO,
/// ZERO)`, the anchor `(ANCHOR, ZERO, ZERO)`, and a vertex that copies an earlier one
/// (FORMAT.md §4.3, references) `(n, ZERO, ZERO)` or `(COPIES + i, ZERO, ZERO)` with a zero
/// residual. One branch-free form for every vertex, so that each attribute is rebuilt in one
/// tight loop.
struct Sources {
    vertex: [u8; MAX_CLUSTER_VERTICES],
    slots: [[u16; 3]; MAX_CLUSTER_VERTICES],
    /// Per vertex in decoding order: it copies an earlier vertex (no residuals stored).
    copied: [bool; MAX_CLUSTER_VERTICES],
    /// Whether any vertex of the cluster is copied.
    copies: bool,
    /// The copied vertices of earlier clusters: (slot, place in the page).
    links: Vec<(u16, u32)>,
    /// The far-copied vertices: (slot, their values read from the source layout).
    far: Vec<(u16, VertexKey)>,
    len: usize,
}

impl Default for Sources {
    fn default() -> Sources {
        Sources {
            vertex: [0; MAX_CLUSTER_VERTICES],
            slots: [[0; 3]; MAX_CLUSTER_VERTICES],
            copied: [false; MAX_CLUSTER_VERTICES],
            copies: false,
            links: Vec::with_capacity(MAX_CLUSTER_VERTICES),
            far: Vec::with_capacity(MAX_CLUSTER_VERTICES),
            len: 0,
        }
    }
}

impl Sources {
    /// The predictors of a cluster whose indices are all below `vertex_count`.
    fn walk(&mut self, indices: &[u8], vertex_count: usize, edges: &mut EdgeTable) {
        self.len = 0;
        walk(indices, vertex_count, edges, |v, p| {
            if let (Some(vertex), Some(slots)) = (self.vertex.get_mut(self.len), self.slots.get_mut(self.len)) {
                *vertex = v;
                *slots = match p {
                    Predictor::Parallelogram(a, b, d) => [a as u16, b as u16, d as u16],
                    Predictor::Neighbour(a) => [a as u16, ZERO, ZERO],
                    Predictor::Anchor => [ANCHOR, ZERO, ZERO],
                };
            }
            self.len += 1;
        });
        self.len = self.len.min(MAX_CLUSTER_VERTICES);
    }

    /// Reads the references of the walked cluster, whose vertices start at page vertex `vo`
    /// (which is also where the cluster starts in decoding order): records each vertex's
    /// place in `order` (page decoding order → place in the page) and points each copied
    /// vertex at the slot of the vertex it copies, one of this cluster's or one filled from an
    /// earlier cluster's. Returns how many of its vertices are stored with residuals.
    fn link(&mut self, s: &Sections, vo: usize, order: &mut [u32], targets: &mut Copies) -> Result<usize, Invalid> {
        let n = self.len;
        self.links.clear();
        self.far.clear();
        self.copies = false;
        if s.copies == 0 && s.far == 0 {
            return Ok(n);
        }
        self.copied[..n].fill(false);
        for (&v, place) in self.vertex[..n].iter().zip(&mut order[vo..]) {
            *place = (vo + v as usize) as u32;
        }
        let flags = &s.references[vo..][..n.min(order.len() - vo)];
        let mut copies = 0;
        for (i, &flag) in flags.iter().enumerate().filter(|(_, &f)| f != 0) {
            (self.copied[i], self.copies) = (true, true);
            copies += 1;
            if flag == 2 {
                let Some(far) = targets.sources else { return invalid("a far copy in a page without far copies") };
                let u = targets.follow_far.follow_far(targets.far_coded.next(), far.total)?;
                self.far.push((COPIES + i as u16, far.vertex(u, &mut targets.near)?));
                self.slots[i] = [COPIES + i as u16, ZERO, ZERO];
                continue;
            }
            let j = vo + i;
            let target = targets.follow.follow(targets.coded.next(), j)?;
            self.slots[i] = if target >= vo {
                [self.vertex[target - vo] as u16, ZERO, ZERO]
            } else {
                self.links.push((COPIES + i as u16, order[target]));
                [COPIES + i as u16, ZERO, ZERO]
            };
        }
        Ok(n - copies)
    }

    /// Moves the `stored` residuals read for the stored vertices to their places in decoding
    /// order, zero for the copied ones (in place, from the end: a stored vertex's place is at
    /// or after its residual's).
    fn spread<T: Lanes>(&self, residuals: &mut [T; MAX_CLUSTER_VERTICES], stored: usize) {
        if !self.copies {
            return;
        }
        let mut k = stored;
        for i in (0..self.len).rev() {
            if self.copied[i] {
                residuals[i] = T::default();
            } else {
                k = k.saturating_sub(1);
                residuals[i] = residuals[k];
            }
        }
    }

    /// Each vertex's value (prediction plus residual, `residuals` in decoding order) into
    /// the page's values `page`, the cluster's starting at `vo`; returns the first decoded
    /// vertex's value, the next cluster's anchor. Every slot a prediction reads was written
    /// before: the walk predicts only from vertices it has visited, and a copy reads a vertex
    /// decoded before it.
    #[allow(clippy::too_many_arguments)]
    fn rebuild<T: Lanes>(
        &self,
        r: &mut Residuals<T>,
        vc: usize,
        anchor: T,
        page: &mut [T],
        vo: usize,
        far: impl Fn(&(u16, VertexKey)) -> (u16, T),
    ) -> T {
        let (before, here) = page.split_at_mut(vo);
        let values = &mut r.values;
        values[ANCHOR as usize] = anchor;
        values[ZERO as usize] = T::default();
        for &(slot, at) in &self.links {
            values[slot as usize % SLOTS] = before.get(at as usize).copied().unwrap_or_default();
        }
        for (slot, value) in self.far.iter().map(far) {
            values[slot as usize % SLOTS] = value;
        }
        let n = self.len.min(vc);
        for ((&v, s), &r) in self.vertex[..n].iter().zip(&self.slots[..n]).zip(&r.residuals[..n]) {
            let at = |i: u16| values[i as usize % SLOTS];
            values[v as usize] = at(s[0]).add(at(s[1])).sub(at(s[2])).add(r);
        }
        let len = vc.min(here.len()).min(MAX_CLUSTER_VERTICES);
        here[..len].copy_from_slice(&values[..len]);
        values[self.vertex[0] as usize]
    }
}

/// The position residuals of the `sc` stored vertices of a cluster, the page's stored
/// vertices from `so` on, from the page's byte planes (in decoding order; [`Sources::spread`]
/// then puts them in place).
fn position_residuals(s: &Sections, so: usize, sc: usize, out: &mut [[i32; 3]]) {
    let out = &mut out[..sc];
    let plane = |p: usize| s.positions[p * 3 * s.stored + 3 * so..][..3 * sc].chunks_exact(3);
    for (o, b) in out.iter_mut().zip(plane(0)) {
        *o = [b[0] as i32, b[1] as i32, b[2] as i32];
    }
    for p in 1..s.planes {
        for (o, b) in out.iter_mut().zip(plane(p)) {
            for k in 0..3 {
                o[k] |= (b[k] as i32) << (8 * p);
            }
        }
    }
    for o in out.iter_mut() {
        *o = o.map(|z| unzigzag32(z as u32));
    }
}

/// The residuals of a two-plane pair section (normals or UVs) for the `sc` stored vertices of
/// a cluster, the page's stored vertices (`stored` in all) from `so` on.
fn pair_residuals(planes: &[u8], so: usize, sc: usize, stored: usize, out: &mut [[u16; 2]]) {
    let low = &planes[2 * so..][..2 * sc];
    let high = &planes[2 * stored + 2 * so..][..2 * sc];
    for ((out, l), h) in out.iter_mut().zip(low.chunks_exact(2)).zip(high.chunks_exact(2)) {
        *out = [unzigzag16(u16::from_le_bytes([l[0], h[0]])), unzigzag16(u16::from_le_bytes([l[1], h[1]]))];
    }
}

/// A cluster's local indices from meshoptimizer's index codec, each checked to name a vertex
/// of the cluster, appended to `out`.
fn decode_indices(coded: &[u8], vertex_count: usize, triangle_count: usize, out: &mut Vec<u8>) -> Result<(), Invalid> {
    if coded.len() > index_bound(triangle_count) {
        return invalid(format!("{} bytes of coded indices for {triangle_count} triangles", coded.len()));
    }
    let wide: Vec<u16> =
        meshopt::decode_index_buffer(coded, 3 * triangle_count).map_err(|e| Invalid(format!("index codec: {e}")))?;
    // The largest index alone decides (a branch-free scan, where finding the first
    // offender branched per index).
    if let Some(&i) = wide.iter().max().filter(|&&i| i as usize >= vertex_count) {
        return invalid(format!("local index {i} out of {vertex_count} vertices"));
    }
    out.extend(wide.iter().map(|&i| i as u8));
    Ok(())
}

/// Per-component minimum of a cluster's values and the bits that hold each component's range.
fn ranges<const N: usize>(values: impl Iterator<Item = [i64; N]>) -> ([i64; N], [u8; N]) {
    let mut lo = [i64::MAX; N];
    let mut hi = [i64::MIN; N];
    for v in values {
        for k in 0..N {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    (lo, std::array::from_fn(|k| bits::bits_for((hi[k] - lo[k]) as u32) as u8))
}

/// Unpadded length of each block of a cluster (FORMAT.md §5); the indices block includes its
/// padding and open-edge block when it has one.
fn block_lengths(h: &ClusterHeader) -> [usize; 5] {
    let (v, t) = (h.vertex_count as usize, h.triangle_count as usize);
    let words = |bits: usize| bits.div_ceil(32) * 4;
    let sum = |b: &[u8]| b.iter().map(|&b| b as usize).sum::<usize>();
    let indices = match h.edge_flags & ClusterHeader::OPEN_EDGES {
        0 => 3 * t,
        _ => (3 * t).next_multiple_of(4) + words(3 * t),
    };
    [words(v * sum(&h.position_bits)), words(v * sum(&h.normal_bits)), 4 * v, indices, 2 * t]
}

/// Sets each header's block offsets as the writer places blocks (every cluster's block of
/// one kind, then the next kind; each padded to 4 bytes; kinds the file does not carry
/// absent) and returns the page's length.
fn place_blocks(headers: &mut [ClusterHeader], flags: u32) -> usize {
    let present = [true, flags & FLAG_NORMALS != 0, flags & FLAG_UVS != 0, true, flags & FLAG_MATERIALS != 0];
    let mut end = headers.len() * CLUSTER_HEADER_SIZE;
    for slot in (0..5).filter(|&k| present[k]) {
        for h in headers.iter_mut() {
            h.block_offsets[slot] = end as u32;
            end += block_lengths(h)[slot].next_multiple_of(4);
        }
    }
    end
}

/// Packs records of bit fields of the given widths (each value below 2^width) LSB first into
/// little-endian u32 words (FORMAT.md §5.2); `out` is exactly the words' bytes, zeroed.
fn pack<const N: usize>(out: &mut [u8], values: impl Iterator<Item = [u32; N]>, widths: [u32; N]) {
    let (mut acc, mut fill, mut at) = (0u64, 0u32, 0usize);
    let mut flush = |word: u32, at: &mut usize| {
        if let Some(w) = out.get_mut(*at..*at + 4) {
            w.copy_from_slice(&word.to_le_bytes());
        }
        *at += 4;
    };
    for v in values {
        for k in 0..N {
            acc |= (v[k] as u64) << fill;
            fill += widths[k];
            if fill >= 32 {
                flush(acc as u32, &mut at);
                acc >>= 32;
                fill -= 32;
            }
        }
    }
    if fill > 0 {
        flush(acc as u32, &mut at);
    }
}

/// A page's source vertices in source numbering (FORMAT.md §4.3), read from the sources' GPU
/// layouts: each source cluster's header and block ranges once per page, then a vertex's values
/// from its blocks, every read bounds-checked (a malformed source layout is an error, never a
/// panic).
pub(crate) struct SourceVertices<'a> {
    /// Per source cluster: its first source vertex number; the last entry is `U`.
    starts: Vec<usize>,
    clusters: Vec<SourceCluster<'a>>,
    /// The number of source vertices, `U` (from the records, as the format defines it).
    pub total: usize,
}

/// One cluster of a source page as far copies read it: its header's ranges and its blocks,
/// each `None` if it does not lie inside the layout (an error only when a far copy reads it).
struct SourceCluster<'a> {
    page: u32,
    /// The file's `NORMALS` and `UVS` flags.
    with_normals: bool,
    with_uvs: bool,
    position_min: [i32; 3],
    positions: Records<'a, 3>,
    normal_min: [u16; 2],
    normals: Records<'a, 2>,
    uvs: Option<&'a [u8]>,
}

/// A block of bit-packed records of `N` fields (FORMAT.md §5.2), each at most 32 bits wide.
struct Records<'a, const N: usize> {
    block: Option<&'a [u8]>,
    widths: [u32; N],
    /// Bits per record.
    stride: u64,
}

impl<'a, const N: usize> Records<'a, N> {
    fn new(block: impl FnOnce(usize) -> Option<&'a [u8]>, vertex_count: usize, widths: [u32; N]) -> Records<'a, N> {
        let stride: u32 = widths.iter().sum();
        let block = block((vertex_count * stride as usize).div_ceil(32) * 4);
        Records { block, widths, stride: stride as u64 }
    }

    /// Record `v`'s fields; `None` if they lie outside the block (as [`bits::read_bits`] reads
    /// them: the block is whole words, so a field lies inside if its last bit does).
    fn get(&self, v: u64) -> Option<[u32; N]> {
        let block = self.block?;
        let at = v.checked_mul(self.stride)?;
        if self.stride > 0 && at + self.stride > 8 * block.len() as u64 {
            return None;
        }
        // Sixteen bytes from the record's first byte hold all of it (at most 96 bits after a
        // shift of at most 7): one load instead of a checked read per field.
        let tail = block.get((at / 8) as usize..).unwrap_or_default();
        let mut window = [0u8; 16];
        match tail.first_chunk::<16>() {
            Some(w) => window = *w,
            None => window.iter_mut().zip(tail).for_each(|(w, &b)| *w = b),
        }
        let mut record = u128::from_le_bytes(window) >> (at % 8);
        Some(self.widths.map(|w| {
            let field = (record as u64 & ((1u64 << w) - 1)) as u32;
            record >>= w;
            field
        }))
    }
}

impl<'a> SourceVertices<'a> {
    pub(crate) fn new(sources: &[SourcePage<'a>], flags: u32) -> Result<SourceVertices<'a>, Invalid> {
        let mut starts = vec![0];
        let mut clusters = Vec::new();
        for s in sources {
            for r in s.records {
                clusters.push(SourceCluster::new(s, r, flags)?);
                starts.push(starts[starts.len() - 1] + r.vertex_count as usize);
            }
        }
        Ok(SourceVertices { total: starts[starts.len() - 1], starts, clusters })
    }

    /// The values of source vertex `u` (below [`SourceVertices::total`]); `near` is the source
    /// cluster of the previous far copy, and becomes `u`'s.
    fn vertex(&self, u: usize, near: &mut usize) -> Result<VertexKey, Invalid> {
        let c = self.cluster_of(u, *near);
        *near = c;
        match (self.clusters.get(c), self.starts.get(c)) {
            (Some(cluster), Some(&start)) => cluster.vertex(u - start),
            _ => invalid(format!("source vertex {u} out of range")),
        }
    }

    /// The source cluster holding source vertex `u`. A page's far copies name source vertices
    /// in mostly increasing order, so the cluster `near` or the one after it is tried before a
    /// binary search, which cost a seventh of the decoding time.
    fn cluster_of(&self, u: usize, near: usize) -> usize {
        let holds = |c: usize| matches!(self.starts.get(c..c + 2), Some(&[a, b]) if a <= u && u < b);
        match (holds(near), holds(near + 1)) {
            (true, _) => near,
            (_, true) => near + 1,
            _ => self.starts.partition_point(|&s| s <= u).saturating_sub(1),
        }
    }
}

impl<'a> SourceCluster<'a> {
    /// The cluster of record `r` in source page `s`.
    fn new(s: &SourcePage<'a>, r: &ClusterInfo, flags: u32) -> Result<SourceCluster<'a>, Invalid> {
        let at = r.page_offset as usize;
        let Some(bytes) = s.layout.get(at..at.saturating_add(CLUSTER_HEADER_SIZE)).and_then(|b| b.first_chunk()) else {
            return invalid(format!("source page {}: a cluster header lies outside its layout", s.index));
        };
        let h = ClusterHeader::decode(bytes);
        if h.vertex_count != r.vertex_count
            || h.position_bits.iter().any(|&b| b > 32)
            || h.normal_bits.iter().any(|&b| b > 16)
        {
            return invalid(format!("source page {}: a cluster header disagrees with its record", s.index));
        }
        let vc = h.vertex_count as usize;
        let block = |slot: usize| {
            move |len: usize| {
                let at = h.block_offsets[slot] as usize;
                (at != 0).then(|| s.layout.get(at..at.saturating_add(len))).flatten()
            }
        };
        let with = |flag: u32| flags & flag != 0;
        Ok(SourceCluster {
            page: s.index,
            with_normals: with(FLAG_NORMALS),
            with_uvs: with(FLAG_UVS),
            position_min: h.position_min,
            positions: Records::new(block(ClusterHeader::POSITIONS), vc, h.position_bits.map(u32::from)),
            normal_min: h.normal_min,
            normals: Records::new(block(ClusterHeader::NORMALS), vc, h.normal_bits.map(u32::from)),
            uvs: block(ClusterHeader::UVS)(4 * vc),
        })
    }

    /// The values of vertex `v` of the cluster (normals and UVs zero where the file has none).
    fn vertex(&self, v: usize) -> Result<VertexKey, Invalid> {
        let outside =
            || Invalid(format!("source page {}: a far copy's source vertex lies outside its layout", self.page));
        let deltas = self.positions.get(v as u64).ok_or_else(outside)?;
        let mut position = [0i32; 3];
        for k in 0..3 {
            position[k] = i32::try_from(self.position_min[k] as i64 + deltas[k] as i64)
                .map_err(|_| Invalid(format!("source page {}: a position overflows i32", self.page)))?;
        }
        let mut key: VertexKey = (position, [0; 2], [0; 2]);
        if self.with_normals {
            let deltas = self.normals.get(v as u64).ok_or_else(outside)?;
            for k in 0..2 {
                key.1[k] = u16::try_from(self.normal_min[k] as u32 + deltas[k]).map_err(|_| outside())?;
            }
        }
        if self.with_uvs {
            let q = self.uvs.and_then(|b| b.get(4 * v..4 * v + 4)).ok_or_else(outside)?;
            key.2 = [u16::from_le_bytes([q[0], q[1]]), u16::from_le_bytes([q[2], q[3]])];
        }
        Ok(key)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every record of a block reads as [`bits::read_bits`] reads its fields, the last ones too
    /// (fewer than sixteen bytes from their start to the block's end); one past them is `None`.
    #[test]
    fn records_read_as_their_bit_fields() {
        let widths = [13, 32, 7];
        let mut writer = bits::BitWriter::default();
        for v in 0..9u32 {
            for (k, &w) in widths.iter().enumerate() {
                writer.push(v.wrapping_mul(2654435761) >> k, w);
            }
        }
        let block: Vec<u8> = writer.finish().iter().flat_map(|w| w.to_le_bytes()).collect();
        let records = Records::new(|len| block.get(..len), 9, widths);
        for v in 0..9u64 {
            let at = |k: usize| v * 52 + widths[..k].iter().sum::<u32>() as u64;
            let fields: [u32; 3] = std::array::from_fn(|k| bits::read_bits(&block, at(k), widths[k]).unwrap());
            assert_eq!(records.get(v), Some(fields), "record {v}");
        }
        assert_eq!(records.get(9), None);
    }
}
