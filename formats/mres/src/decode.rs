//! The page decoder: a page's encoded bytes (FORMAT.md §4.3) straight to its GPU layout (§5),
//! the layout the writer lays out ([`crate::write`]), byte for byte.
//!
//! One pass rebuilds every vertex of the page into flat buffers reused from page to page (no
//! allocation per cluster or vertex but the index codec's output); a second lays the page out
//! into one buffer of the size the page table gives, allocated once its size is known to match.
//! The writer decodes every page it writes here and compares the result with the page it laid
//! out itself, so the two layouts cannot drift apart.

use super::codec::{encoded_len, index_bound, invalid, preamble, reference_counts, totals, unzigzag16, unzigzag32};
use super::codec::{walk, EdgeTable, Invalid, Lanes, Predictor, Shape, Targets, VertexKey, PREAMBLE};
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
    /// The far copies' values, in decoding order.
    far: Vec<VertexKey>,
    /// The copies' and the far copies' coded targets.
    coded: (Vec<u32>, Vec<u32>),
    /// The stored vertices' residuals in decoding order, then a zero: a copy's residual.
    residuals: Columns,
    /// One cluster's predictors and its values by slot (see [`Sources::rebuild`]); never
    /// cleared, as each cluster writes what it reads.
    sources: Sources,
    /// A cluster's values by slot while it is rebuilt: positions alone (a file without
    /// normals or UVs), or every attribute.
    wide: Box<[[i32; 3]; SLOTS]>,
    all: Box<[VertexKey; SLOTS]>,
}

/// One value per vertex of each attribute: positions, normals, UVs.
type Columns = (Vec<[i32; 3]>, Vec<[u16; 2]>, Vec<[u16; 2]>);

/// The copies' targets as the page's clusters follow them, in order (FORMAT.md §4.3).
struct Copies<'a> {
    /// Their coded targets.
    coded: &'a [u32],
    follow: Targets,
    /// The next copy's and far copy's numbers.
    next: usize,
    next_far: usize,
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
        // One branch-free pass over every mark; the offender is looked for only then.
        if marks.iter().fold(0, |acc, &m| acc | m) > 7 {
            let m = marks.iter().find(|&&m| m > 7).copied().unwrap_or_default();
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
            far: Vec::new(),
            coded: Default::default(),
            residuals: Default::default(),
            sources: Sources::default(),
            wide: Box::new([Default::default(); SLOTS]),
            all: Box::new([Default::default(); SLOTS]),
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
        self.far_copies(s, far)?;
        plane_values(s.targets, s.target_planes, s.copies, &mut self.coded.0);
        let mut copies = Copies { coded: &self.coded.0, follow: Targets::new(), next: 0, next_far: 0 };
        position_residuals(s, &mut self.residuals.0);
        if normals {
            pair_residuals(s.normals, s.stored, &mut self.residuals.1);
        }
        if uvs {
            pair_residuals(s.uvs, s.stored, &mut self.residuals.2);
        }
        let mut anchor = VertexKey::default();
        let (mut vo, mut so, mut io) = (0usize, 0usize, 0usize);
        let (sources, wide, all) = (&mut self.sources, &mut *self.wide, &mut *self.all);
        let residuals = &self.residuals;
        for (r, len) in records.iter().zip(s.lengths.chunks_exact(2)) {
            let (vc, tc) = (r.vertex_count as usize, r.triangle_count as usize);
            let len = u16::from_le_bytes([len[0], len[1]]) as usize;
            let start = self.indices.len();
            decode_indices(&s.coded[io..io + len], vc, tc, &mut self.indices)?;
            sources.walk(&self.indices[start..], vc, &mut self.edges);
            let sc = sources.link(s, vo, so, &mut self.order[..v_total], &mut copies)?;
            let far = |g: u32| self.far.get(g as usize).copied().unwrap_or_default();
            let n = vc.min(MAX_CLUSTER_VERTICES);
            let here = vo..vo + n;
            if !normals && !uvs {
                let earlier = |k| at(&self.positions, k);
                anchor.0 = sources.rebuild(wide, vc, anchor.0, |k| at(&residuals.0, k), earlier, |g| far(g).0);
                if let Some(page) = self.positions.get_mut(here) {
                    page.copy_from_slice(&wide[..n]);
                }
            } else {
                // Every attribute in one pass (the ones the file lacks come out zero).
                let p = &self.positions[..];
                let nr = if normals { &self.normals[..] } else { &[] };
                let u = if uvs { &self.uvs[..] } else { &[] };
                let earlier = |k| (at(p, k), at(nr, k), at(u, k));
                let residual = |k| (at(&residuals.0, k), at(&residuals.1, k), at(&residuals.2, k));
                anchor = sources.rebuild(all, vc, anchor, residual, earlier, far);
                column(&mut self.positions, here.clone(), &all[..n], |v| v.0);
                if normals {
                    column(&mut self.normals, here.clone(), &all[..n], |v| v.1);
                }
                if uvs {
                    column(&mut self.uvs, here, &all[..n], |v| v.2);
                }
            }
            (vo, so, io) = (vo + vc, so + sc, io + len);
        }
        let max_normal = ((1u32 << normal_bits.min(16)) - 1) as u16;
        if let Some(n) = self.normals[..if normals { v_total } else { 0 }].iter().flatten().find(|&&n| n > max_normal) {
            return invalid(format!("octahedral value {n} above {max_normal}"));
        }
        Ok(())
    }

    /// The values of the page's far copies (FORMAT.md §4.3), in order, read from its sources,
    /// every source vertex number checked.
    fn far_copies(&mut self, s: &Sections, sources: Option<&SourceVertices>) -> Result<(), Invalid> {
        self.far.clear();
        let Some(sources) = sources.filter(|_| s.far > 0) else { return Ok(()) };
        plane_values(s.far_targets, s.far_planes, s.far, &mut self.coded.1);
        let (mut follow, mut near) = (Targets::new(), 0);
        for &z in &self.coded.1 {
            let u = follow.follow_far(z, sources.total)?;
            self.far.push(sources.vertex(u, &mut near)?);
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
            let (low, high) = s.materials.split_at(s.materials.len() / 2);
            let r = block(ClusterHeader::MATERIALS);
            let pairs = low[to..to + tc].iter().zip(&high[to..to + tc]);
            for (out, (&l, &h)) in raw[r].as_chunks_mut::<2>().0.iter_mut().zip(pairs) {
                *out = [l, h];
            }
        }
    }
}

/// Value `k` of `values`, or zero past them (an attribute the file lacks).
fn at<T: Copy + Default>(values: &[T], k: u32) -> T {
    values.get(k as usize).copied().unwrap_or_default()
}

/// One attribute of rebuilt vertices (`value` of each of `all`) into the page's values at
/// `places`.
fn column<T>(page: &mut [T], places: std::ops::Range<usize>, all: &[VertexKey], value: fn(&VertexKey) -> T) {
    if let Some(out) = page.get_mut(places) {
        out.iter_mut().zip(all).for_each(|(o, v)| *o = value(v));
    }
}

/// `v` at least `len` long, reusing its allocation (what it holds is overwritten).
fn grow<T: Default + Clone>(v: &mut Vec<T>, len: usize) {
    if v.len() < len {
        v.resize(len, T::default());
    }
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
/// `a + b − d` reads and the place of its residuals: a parallelogram reads three decoded
/// vertices, a neighbour `(n, ZERO, ZERO)`, the anchor `(ANCHOR, ZERO, ZERO)`, and a vertex that
/// copies an earlier one (FORMAT.md §4.3, references) `(n, ZERO, ZERO)` or `(COPIES + i, ZERO,
/// ZERO)` with the zero residual. One branch-free form for every vertex, so that each attribute
/// is rebuilt in one tight loop.
struct Sources {
    vertex: [u8; MAX_CLUSTER_VERTICES],
    slots: [[u16; 3]; MAX_CLUSTER_VERTICES],
    /// Per vertex in decoding order: its residuals' place among the page's.
    residual: [u32; MAX_CLUSTER_VERTICES],
    /// The copied vertices of earlier clusters: (slot, place in the page).
    links: Vec<(u16, u32)>,
    /// The far-copied vertices: (slot, which far copy of the page).
    far: Vec<(u16, u32)>,
    len: usize,
}

impl Default for Sources {
    fn default() -> Sources {
        Sources {
            vertex: [0; MAX_CLUSTER_VERTICES],
            slots: [[0; 3]; MAX_CLUSTER_VERTICES],
            residual: [0; MAX_CLUSTER_VERTICES],
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
    /// (which is also where the cluster starts in decoding order) and its residuals at `so`
    /// of the page's: records each vertex's place in `order` (page decoding order → place in
    /// the page) and its residuals' place, and points each copied vertex at the slot of the
    /// vertex it copies, one of this cluster's or one filled from an earlier cluster's or a
    /// source page's. Returns how many of its vertices are stored with residuals.
    fn link(
        &mut self,
        s: &Sections,
        vo: usize,
        so: usize,
        order: &mut [u32],
        copies: &mut Copies,
    ) -> Result<usize, Invalid> {
        let n = self.len;
        self.links.clear();
        self.far.clear();
        if s.copies == 0 && s.far == 0 {
            for (i, r) in self.residual[..n].iter_mut().enumerate() {
                *r = (so + i) as u32;
            }
            return Ok(n);
        }
        for (&v, place) in self.vertex[..n].iter().zip(&mut order[vo..]) {
            *place = (vo + v as usize) as u32;
        }
        let zero = s.stored as u32;
        let mut k = so;
        for (i, &flag) in s.references[vo..][..n.min(order.len() - vo)].iter().enumerate() {
            let copy = COPIES + i as u16;
            (self.residual[i], self.slots[i]) = match flag {
                0 => {
                    k += 1;
                    ((k - 1) as u32, self.slots[i])
                }
                1 => {
                    let z = copies.coded.get(copies.next).copied().unwrap_or(0);
                    copies.next += 1;
                    match copies.follow.follow(z, vo + i)? {
                        t if t >= vo => (zero, [self.vertex[(t - vo) % MAX_CLUSTER_VERTICES] as u16, ZERO, ZERO]),
                        t => {
                            self.links.push((copy, order[t]));
                            (zero, [copy, ZERO, ZERO])
                        }
                    }
                }
                _ => {
                    self.far.push((copy, copies.next_far as u32));
                    copies.next_far += 1;
                    (zero, [copy, ZERO, ZERO])
                }
            };
        }
        Ok(k - so)
    }

    /// Each vertex's value (prediction plus residual) into `values`, at its local index:
    /// `residual` gives the residuals at a place among the page's (the zero past them for a
    /// copy), `earlier` the values of a vertex of an earlier cluster at its place in the page,
    /// `far` the values of the page's far copies; returns the first decoded vertex's value, the
    /// next cluster's anchor. Every slot a prediction reads was written before: the walk
    /// predicts only from vertices it has visited, and a copy reads a vertex decoded before it.
    fn rebuild<T: Lanes>(
        &self,
        values: &mut [T; SLOTS],
        vc: usize,
        anchor: T,
        residual: impl Fn(u32) -> T,
        earlier: impl Fn(u32) -> T,
        far: impl Fn(u32) -> T,
    ) -> T {
        values[ANCHOR as usize] = anchor;
        values[ZERO as usize] = T::default();
        for &(slot, at) in &self.links {
            values[slot as usize % SLOTS] = earlier(at);
        }
        for &(slot, g) in &self.far {
            values[slot as usize % SLOTS] = far(g);
        }
        let n = self.len.min(vc);
        for ((&v, s), &k) in self.vertex[..n].iter().zip(&self.slots[..n]).zip(&self.residual[..n]) {
            let at = |i: u16| values[i as usize % SLOTS];
            values[v as usize] = at(s[0]).add(at(s[1])).sub(at(s[2])).add(residual(k));
        }
        values[self.vertex[0] as usize]
    }
}

/// The `count` values of `planes` byte planes (FORMAT.md §4.3, byte planes) into `out`.
fn plane_values(bytes: &[u8], planes: usize, count: usize, out: &mut Vec<u32>) {
    out.clear();
    out.resize(count, 0);
    for p in 0..planes {
        let plane = bytes.get(p * count..(p + 1) * count).unwrap_or_default();
        for (o, &b) in out.iter_mut().zip(plane) {
            *o |= (b as u32) << (8 * p);
        }
    }
}

/// The position residuals of the page's stored vertices from its byte planes, in decoding
/// order, then a zero (a copy's).
fn position_residuals(s: &Sections, out: &mut Vec<[i32; 3]>) {
    out.clear();
    out.resize(s.stored + 1, [0; 3]);
    let flat = &mut out.as_flattened_mut()[..3 * s.stored];
    for p in 0..s.planes {
        let plane = s.positions.get(p * 3 * s.stored..(p + 1) * 3 * s.stored).unwrap_or_default();
        for (o, &b) in flat.iter_mut().zip(plane) {
            *o |= (b as i32) << (8 * p);
        }
    }
    for o in flat {
        *o = unzigzag32(*o as u32);
    }
}

/// The residuals of a two-plane pair section (normals or UVs) of the page's `stored`
/// vertices, in decoding order, then a zero.
fn pair_residuals(planes: &[u8], stored: usize, out: &mut Vec<[u16; 2]>) {
    out.clear();
    out.resize(stored + 1, [0; 2]);
    let (low, high) = planes.split_at(planes.len() / 2);
    for ((o, &l), &h) in out.as_flattened_mut().iter_mut().zip(low).zip(high) {
        *o = unzigzag16(u16::from_le_bytes([l, h]));
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
    // offender branched per index), taken over the narrowed indices with their high bytes
    // apart: a byte-wide maximum takes one SSE2 instruction per 16 indices, a u16 one none.
    let start = out.len();
    out.extend(wide.iter().map(|&i| i as u8));
    let high = wide.iter().fold(0, |acc, &i| acc | i) >> 8;
    let largest = out[start..].iter().fold(0, |acc, &i| acc.max(i));
    if high != 0 || largest as usize >= vertex_count {
        let i = wide.iter().max().copied().unwrap_or_default();
        return invalid(format!("local index {i} out of {vertex_count} vertices"));
    }
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

/// Packs records of bit fields of the given widths (each value below 2^width, at most 32
/// bits) LSB first into little-endian u32 words (FORMAT.md §5.2); `out` is exactly the words'
/// bytes. A record of at most 32 bits is put together first and pushed at once: one push per
/// record instead of one per field (normals, open-edge marks, small clusters' positions); a
/// wider one is pushed field by field, which measured cheaper than a 128-bit accumulator.
fn pack<const N: usize>(out: &mut [u8], values: impl Iterator<Item = [u32; N]>, widths: [u32; N]) {
    let mut packer = Packer { words: out.chunks_exact_mut(4), acc: 0, fill: 0 };
    let stride: u32 = widths.iter().sum();
    if stride <= 32 {
        let shifts: [u32; N] = std::array::from_fn(|k| widths[..k].iter().sum());
        for v in values {
            packer.push((0..N).fold(0, |record, k| record | (v[k] as u64) << shifts[k]), stride);
        }
    } else {
        for v in values {
            for k in 0..N {
                packer.push(v[k] as u64, widths[k]);
            }
        }
    }
    packer.finish();
}

/// A bit stream being written into words, fewer than 32 bits pending.
struct Packer<'a> {
    words: std::slice::ChunksExactMut<'a, u8>,
    acc: u64,
    fill: u32,
}

impl Packer<'_> {
    /// Appends `value`, below 2^`bits`, `bits` at most 32.
    fn push(&mut self, value: u64, bits: u32) {
        self.acc |= value << self.fill;
        self.fill += bits;
        if self.fill >= 32 {
            self.flush();
            self.acc >>= 32;
            self.fill -= 32;
        }
    }

    fn flush(&mut self) {
        if let Some(word) = self.words.next() {
            word.copy_from_slice(&(self.acc as u32).to_le_bytes());
        }
    }

    /// Writes the last, partial word.
    fn finish(mut self) {
        if self.fill > 0 {
            self.flush();
        }
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
        // shift of at most 7): one load instead of a checked read per field; eight bytes for
        // a record of at most 57 bits (most), which then splits in 64-bit arithmetic.
        let tail = block.get((at / 8) as usize..).unwrap_or_default();
        let mask = |w: u32| (1u64 << w) - 1;
        if let (true, Some(window)) = (self.stride <= 57, tail.first_chunk::<8>()) {
            let mut record = u64::from_le_bytes(*window) >> (at % 8);
            return Some(self.widths.map(|w| {
                let field = (record & mask(w)) as u32;
                record >>= w;
                field
            }));
        }
        let mut window = [0u8; 16];
        match tail.first_chunk::<16>() {
            Some(w) => window = *w,
            None => window.iter_mut().zip(tail).for_each(|(w, &b)| *w = b),
        }
        let mut record = u128::from_le_bytes(window) >> (at % 8);
        Some(self.widths.map(|w| {
            let field = (record as u64 & mask(w)) as u32;
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
            for ((value, &min), &d) in key.1.iter_mut().zip(&self.normal_min).zip(&deltas) {
                *value = u16::try_from(min as u32 + d).map_err(|_| outside())?;
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

    /// Every record of a block reads as [`bits::read_bits`] reads its fields, narrow records
    /// and wide ones, the last ones too (fewer than sixteen bytes from their start to the
    /// block's end); one past them is `None`.
    #[test]
    fn records_read_as_their_bit_fields() {
        for widths in [[13, 32, 7], [32, 31, 30]] {
            let mut writer = bits::BitWriter::default();
            for v in 0..9u32 {
                for (k, &w) in widths.iter().enumerate() {
                    writer.push(v.wrapping_mul(2654435761) >> k, w);
                }
            }
            let block: Vec<u8> = writer.finish().iter().flat_map(|w| w.to_le_bytes()).collect();
            let records = Records::new(|len| block.get(..len), 9, widths);
            let stride: u32 = widths.iter().sum();
            for v in 0..9u64 {
                let at = |k: usize| v * stride as u64 + widths[..k].iter().sum::<u32>() as u64;
                let fields: [u32; 3] = std::array::from_fn(|k| bits::read_bits(&block, at(k), widths[k]).unwrap());
                assert_eq!(records.get(v), Some(fields), "widths {widths:?}, record {v}");
            }
            assert_eq!(records.get(9), None);
        }
    }
}
