//! The page encoding on disk (FORMAT.md §4.3): a page's clusters as prediction residuals in
//! byte planes, which zstd then compresses, instead of the bit-packed GPU layout (§5) that
//! zstd cannot shrink. Decoding gives back the quantized values exactly; the reader goes
//! straight to the GPU layout ([`crate::decode`]), and the straightforward decoder here, to
//! quantized values, is kept as the reference the tests hold it to.
//!
//! Indices are meshoptimizer's index codec (format version 1, `encode_index_buffer`), which
//! codes each triangle against the edges and vertices of the triangles before it and keeps
//! their order (it may rotate a triangle's corners: the writer stores triangles as the codec
//! gives them back, with their open-edge marks rotated to match). Attributes are hand-written:
//! meshoptimizer's vertex codec codes each vertex against the one before it in the buffer,
//! byte by byte, while predicting across an edge of the triangles already decoded
//! (parallelogram) halves the residuals on smooth surfaces; the figures that chose this are in
//! docs/BENCHMARKS.md ("Page encoding").
//!
//! Vertices are predicted in the order the triangles first use them (the writer also numbers
//! them so, which helps the index codec): across an edge of an earlier triangle, from a
//! vertex of the same triangle, or from the previous vertex.
//!
//! A vertex equal in every attribute to one decoded before it in the page (a cluster-border
//! vertex shared with a neighbouring cluster, mostly: about a quarter of a scan's stored
//! vertices) is a copy: a reference flag and a delta-coded target instead of its residuals.
//! Flags plus targets coded against the previous copy's target measured smallest of the codings
//! tried: on a 100 K-triangle scan the references cost 74 KB after zstd, against 90 KB as byte
//! planes of the distance back, 94 KB as LEB128 of it and 82 KB as flags plus the distance.
//!
//! A vertex that is not such a copy but equals a vertex of one of the page's **sources** (its
//! dependencies stored before it: the pages of its clusters' coarser parents, whose vertices
//! are level-0 vertices that survived simplification) is a **far copy**: flag 2 and a
//! delta-coded source vertex number (FORMAT.md §4.3). Decoding it reads the source page's GPU
//! layout, which a streamer holds already; the page's GPU layout does not change.

use super::*;

/// One cluster's attributes as quantized integers: what the GPU layout stores (FORMAT.md §5).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Quantized {
    /// Grid coordinates, one per vertex.
    pub positions: Vec<[i32; 3]>,
    /// Octahedral values, one pair per vertex (with `NORMALS`).
    pub normals: Vec<[u16; 2]>,
    /// Quantized UVs, one pair per vertex (with `UVS`).
    pub uvs: Vec<[u16; 2]>,
    /// Local indices, three per triangle.
    pub indices: Vec<u8>,
    /// Material per triangle (with `MATERIALS`).
    pub materials: Vec<u16>,
    /// Open-edge marks, one 3-bit mask per triangle (always one per triangle).
    pub marks: Vec<u8>,
}

/// How a vertex is predicted from the vertices decoded before it (FORMAT.md §4.3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Predictor {
    /// `a + b − d`: across the edge (a, b) from the last earlier triangle that used it.
    Parallelogram(u8, u8, u8),
    /// A vertex decoded before: one of the same triangle, or the previous one.
    Neighbour(u8),
    /// The cluster's first vertex: from the previous cluster's first, or zero.
    Anchor,
}

/// Why a page's encoded bytes do not decode.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Invalid(pub String);

pub(crate) fn invalid<T>(what: impl Into<String>) -> Result<T, Invalid> {
    Err(Invalid(what.into()))
}

/// The permutation that puts a cluster's vertices in first-use order: `order[new] = old`.
/// Vertices no triangle uses keep their relative order, after the used ones.
pub(crate) fn first_use_order(indices: &[u8], vertex_count: usize) -> Vec<u8> {
    let mut seen = vec![false; vertex_count];
    let mut order = Vec::with_capacity(vertex_count);
    let all = (0..vertex_count).map(|v| v as u8);
    for i in indices.iter().copied().chain(all) {
        if let Some(s) = seen.get_mut(i as usize).filter(|s| !**s) {
            *s = true;
            order.push(i);
        }
    }
    order
}

/// Edges of the triangles seen so far → the vertex opposite the edge in the last triangle
/// that used it: a direct table over every pair of 8-bit indices, each entry a stamp and the
/// opposite vertex in one word, so that clearing it per cluster is one increment (decoding then
/// allocates nothing per cluster) and a lookup or insert is one load or store, where a hash
/// table cost a quarter of the decoding time.
pub(crate) struct EdgeTable {
    /// Per directed edge: `stamp << 8 | opposite`.
    entries: Box<[u32; 1 << 16]>,
    /// The stamp of the current cluster's entries (below 2^24).
    current: u32,
}

impl EdgeTable {
    pub(crate) fn new() -> EdgeTable {
        EdgeTable { entries: Box::new([0; 1 << 16]), current: 1 }
    }

    /// Forgets every edge.
    fn clear(&mut self) {
        self.current += 1;
        if self.current == 1 << 24 {
            self.entries.fill(0);
            self.current = 1;
        }
    }

    /// Entry of the directed edge (a, b). An edge is stored under both directions, so that a
    /// lookup needs no ordering of its ends (which cost more than the second store).
    fn key(a: u8, b: u8) -> usize {
        (a as usize) << 8 | b as usize
    }

    fn insert(&mut self, a: u8, b: u8, opposite: u8) {
        let e = self.current << 8 | opposite as u32;
        self.entries[Self::key(a, b)] = e;
        self.entries[Self::key(b, a)] = e;
    }

    fn get(&self, a: u8, b: u8) -> Option<u8> {
        let e = self.entries[Self::key(a, b)];
        (e >> 8 == self.current).then_some(e as u8)
    }
}

/// Each vertex of a cluster with its predictor, in decoding order (see [`walk`]).
fn predictors(indices: &[u8], vertex_count: usize, edges: &mut EdgeTable) -> Vec<(u8, Predictor)> {
    let mut out = Vec::with_capacity(vertex_count);
    walk(indices, vertex_count, edges, |v, p| out.push((v, p)));
    out
}

/// Calls `visit` with each vertex of a cluster and its predictor, in decoding order: the order
/// in which the triangles first use them, then the vertices no triangle uses in index order
/// (FORMAT.md §4.3). Computed from the indices alone: the decoder knows them before any
/// attribute. The encoder and the decoder both walk here, so they cannot disagree. Every
/// index must be below `vertex_count` (at most 256).
pub(crate) fn walk(indices: &[u8], vertex_count: usize, edges: &mut EdgeTable, mut visit: impl FnMut(u8, Predictor)) {
    edges.clear();
    let mut seen = [false; MAX_CLUSTER_VERTICES];
    let mut last: Option<u8> = None;
    let previous = |last: Option<u8>| last.map_or(Predictor::Anchor, Predictor::Neighbour);
    for &t in indices.as_chunks::<3>().0 {
        for k in 0..3 {
            let v = t[k];
            if seen[v as usize] {
                continue;
            }
            let (a, b) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            let pred = match (seen[a as usize], seen[b as usize]) {
                (true, true) => edges.get(a, b).map_or(Predictor::Neighbour(a), |d| Predictor::Parallelogram(a, b, d)),
                (true, false) => Predictor::Neighbour(a),
                (false, true) => Predictor::Neighbour(b),
                (false, false) => previous(last),
            };
            seen[v as usize] = true;
            visit(v, pred);
            last = Some(v);
        }
        for k in 0..3 {
            edges.insert(t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
        }
    }
    for v in (0..vertex_count.min(MAX_CLUSTER_VERTICES)).filter(|&v| !seen[v]) {
        visit(v as u8, previous(last));
        last = Some(v as u8);
    }
}

/// Integer vectors the predictors work on: wrapping arithmetic, so that every residual of every
/// value is defined and decoding never overflows.
pub(crate) trait Lanes: Copy + Default {
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
}

impl Lanes for [i32; 3] {
    fn add(self, o: Self) -> Self {
        std::array::from_fn(|k| self[k].wrapping_add(o[k]))
    }
    fn sub(self, o: Self) -> Self {
        std::array::from_fn(|k| self[k].wrapping_sub(o[k]))
    }
}

impl Lanes for [u16; 2] {
    fn add(self, o: Self) -> Self {
        std::array::from_fn(|k| self[k].wrapping_add(o[k]))
    }
    fn sub(self, o: Self) -> Self {
        std::array::from_fn(|k| self[k].wrapping_sub(o[k]))
    }
}

/// All of a vertex's attributes at once (see [`VertexKey`]), so that a cluster's are rebuilt in
/// one pass.
impl<A: Lanes, B: Lanes, C: Lanes> Lanes for (A, B, C) {
    fn add(self, o: Self) -> Self {
        (self.0.add(o.0), self.1.add(o.1), self.2.add(o.2))
    }
    fn sub(self, o: Self) -> Self {
        (self.0.sub(o.0), self.1.sub(o.1), self.2.sub(o.2))
    }
}

/// The predicted value from the values decoded so far; `anchor` is the previous cluster's
/// first vertex (zero for the page's first cluster).
pub(crate) fn predict<T: Lanes>(p: Predictor, values: &[T], anchor: T) -> T {
    let at = |i: u8| values.get(i as usize).copied().unwrap_or_default();
    match p {
        Predictor::Parallelogram(a, b, d) => at(a).add(at(b)).sub(at(d)),
        Predictor::Neighbour(a) => at(a),
        Predictor::Anchor => anchor,
    }
}

fn zigzag32(r: i32) -> u32 {
    ((r << 1) ^ (r >> 31)) as u32
}

pub(crate) fn unzigzag32(z: u32) -> i32 {
    ((z >> 1) as i32) ^ -((z & 1) as i32)
}

fn zigzag16(r: u16) -> u16 {
    let r = r as i16;
    ((r << 1) ^ (r >> 15)) as u16
}

pub(crate) fn unzigzag16(z: u16) -> u16 {
    ((z >> 1) as i16 ^ -((z & 1) as i16)) as u16
}

/// Size of the page preamble: the position plane count, the target plane count, the far
/// target plane count, then a zero byte.
pub(crate) const PREAMBLE: usize = 4;

/// Most byte planes of the copies' targets: a coded target fits in a u32.
pub(crate) const MAX_TARGET_PLANES: usize = 4;

/// The most bytes meshoptimizer's index codec writes for `triangles` triangles of a cluster
/// (`meshopt_encodeIndexBufferBound` for at most 256 vertices: a header byte, at most 8 bytes
/// per triangle, a 16-byte table).
pub(crate) fn index_bound(triangles: usize) -> usize {
    17 + 8 * triangles
}

/// Vertex and triangle totals of a page's clusters, from their records.
pub(crate) fn totals(records: &[ClusterInfo]) -> (usize, usize) {
    let v = records.iter().map(|c| c.vertex_count as usize).sum();
    let t = records.iter().map(|c| c.triangle_count as usize).sum();
    (v, t)
}

/// The shape of a page's encoding beyond its records: what the preamble, the index lengths
/// and the reference stream say (FORMAT.md §4.3).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Shape {
    /// Bytes of coded indices (the sum of the index lengths).
    pub index_bytes: usize,
    /// Position byte planes, `P`.
    pub planes: usize,
    /// Byte planes of the copies' targets, `R`.
    pub target_planes: usize,
    /// Vertices that copy an earlier one (reference flag 1), `C`.
    pub copies: usize,
    /// Byte planes of the far copies' source vertex numbers, `F`.
    pub far_planes: usize,
    /// Vertices that copy a source page's vertex (reference flag 2), `G`; the others,
    /// `V − C − G`, are stored with residuals.
    pub far: usize,
}

impl Shape {
    /// Vertices stored with residuals, `S = V − C − G`, out of `v`.
    pub(crate) fn stored(&self, v: usize) -> usize {
        v.saturating_sub(self.copies + self.far)
    }
}

/// Length of a page's encoded bytes of this shape (FORMAT.md §4.3).
pub(crate) fn encoded_len(flags: u32, clusters: usize, (v, t): (usize, usize), shape: Shape) -> usize {
    let with = |flag: u32, n: usize| if flags & flag != 0 { n } else { 0 };
    let s = shape.stored(v);
    PREAMBLE
        + 2 * clusters
        + shape.index_bytes
        + t
        + v
        + shape.target_planes * shape.copies
        + shape.far_planes * shape.far
        + shape.planes * 3 * s
        + with(FLAG_NORMALS, 4 * s)
        + with(FLAG_UVS, 4 * s)
        + with(FLAG_MATERIALS, 2 * t)
}

/// The most bytes a page of these clusters can encode to (`E_max`).
pub(crate) fn max_encoded_len(flags: u32, records: &[ClusterInfo]) -> usize {
    let (v, t) = totals(records);
    let index_bytes = records.iter().map(|r| index_bound(r.triangle_count as usize)).sum();
    // Every vertex stored: a copy's target (at most 4 bytes) is shorter than a stored vertex's
    // residuals (12 bytes with 4 planes).
    let shape = Shape { index_bytes, planes: 4, ..Shape::default() };
    encoded_len(flags, records.len(), (v, t), shape)
}

/// Checks a preamble and returns its position, target and far target plane counts.
pub(crate) fn preamble(bytes: &[u8]) -> Result<(usize, usize, usize), Invalid> {
    let most = MAX_TARGET_PLANES as u8;
    match *bytes {
        [p, r, f, 0] if (1..=4).contains(&p) && r <= most && f <= most => Ok((p as usize, r as usize, f as usize)),
        _ => invalid(format!(
            "preamble {bytes:02x?}: position planes outside 1..=4, target or far target planes over 4 \
             or reserved byte not zero"
        )),
    }
}

/// The numbers of copies (flag 1) and far copies (flag 2) among a page's reference flags,
/// each checked to be 0, 1 or 2.
pub(crate) fn reference_counts(flags: &[u8]) -> Result<(usize, usize), Invalid> {
    // Branch-free passes: a flag over 2 has a bit above bit 1 or both low bits set, which
    // `bad` collects; the offender is looked for only then. The bits are counted in bytes over
    // runs of 255 flags, which vectorize (16 flags per instruction), where usize counters
    // took ten instructions a flag.
    let (mut bad, mut ones, mut twos) = (0u8, 0usize, 0usize);
    for run in flags.chunks(255) {
        bad |= run.iter().fold(0, |bad, &f| bad | (f >> 2) | (f & (f >> 1)));
        ones += run.iter().map(|&f| f & 1).sum::<u8>() as usize;
        twos += run.iter().map(|&f| f >> 1 & 1).sum::<u8>() as usize;
    }
    if bad != 0 {
        let f = flags.iter().find(|&&f| f > 2).copied().unwrap_or(u8::MAX);
        return invalid(format!("reference flag {f} is not 0, 1 or 2"));
    }
    Ok((ones, twos))
}

/// Follows the copies' targets through a page (FORMAT.md §4.3): each target is coded as the
/// zigzag difference from the previous copy's target plus one.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Targets {
    /// The next target if its difference is zero: the previous target plus one (0 at first).
    next: i64,
}

impl Targets {
    pub(crate) fn new() -> Targets {
        Targets { next: 0 }
    }

    /// The target of the copy at page decoding position `j` whose coded difference is `z`;
    /// it must come before `j`.
    pub(crate) fn follow(&mut self, z: u32, j: usize) -> Result<usize, Invalid> {
        let t = self.next + unzigzag32(z) as i64;
        if t < 0 || t >= j as i64 {
            return invalid(format!("vertex {j} of the page copies vertex {t}, not one decoded before it"));
        }
        self.next = t + 1;
        Ok(t as usize)
    }

    /// The source vertex of the far copy whose coded difference is `z`; it must be below
    /// `sources`, the number of the page's source vertices (`U`).
    pub(crate) fn follow_far(&mut self, z: u32, sources: usize) -> Result<usize, Invalid> {
        let u = self.next + unzigzag32(z) as i64;
        if u < 0 || u >= sources as i64 {
            return invalid(format!("a far copy names source vertex {u}, outside the {sources} of its sources"));
        }
        self.next = u + 1;
        Ok(u as usize)
    }

    /// The coded difference of target `t` (the encoder's side of [`Targets::follow`]).
    fn code(&mut self, t: usize) -> u32 {
        let z = zigzag32((t as i64 - self.next) as i32);
        self.next = t as i64 + 1;
        z
    }
}

/// A cluster's triangles as meshoptimizer's index codec gives them back (the same triangles
/// in the same order, some with their corners rotated), with the open-edge marks rotated to
/// match: the form the writer stores, so that the page decodes to what was written.
/// `None` if the codec fails or does not settle (then the cluster cannot be written).
pub(crate) fn canonical_triangles(indices: &[u8], marks: &[u8], vertex_count: usize) -> Option<(Vec<u8>, Vec<u8>)> {
    let mut current: Vec<u32> = indices.iter().map(|&i| i as u32).collect();
    for _ in 0..4 {
        let encoded = meshopt::encode_index_buffer(&current, vertex_count).ok()?;
        let decoded: Vec<u32> = meshopt::decode_index_buffer(&encoded, current.len()).ok()?;
        if decoded == current {
            let marks = rotate_marks(indices, marks, &current)?;
            return Some((current.iter().map(|&i| i as u8).collect(), marks));
        }
        current = decoded;
    }
    None
}

/// The marks of `original`'s triangles for the same triangles rotated as in `rotated`: bit k
/// of a mark is the edge from corner k to corner k + 1, so it moves with the corners.
fn rotate_marks(original: &[u8], marks: &[u8], rotated: &[u32]) -> Option<Vec<u8>> {
    original
        .chunks_exact(3)
        .zip(rotated.chunks_exact(3))
        .zip(marks)
        .map(|((o, r), &m)| {
            let shift = (0..3).find(|&s| (0..3).all(|k| r[k] == o[(k + s) % 3] as u32))?;
            Some((0..3).fold(0u8, |acc, k| acc | ((m >> ((k + shift) % 3)) & 1) << k))
        })
        .collect()
}

/// A vertex's attributes together (normals and UVs zero where the file has none): two
/// vertices of a page with the same key are exact repeats.
pub(crate) type VertexKey = ([i32; 3], [u16; 2], [u16; 2]);

/// The key of vertex `v` of a cluster.
pub(crate) fn key(c: &Quantized, v: usize) -> VertexKey {
    let pair = |values: &[[u16; 2]]| values.get(v).copied().unwrap_or_default();
    (c.positions[v], pair(&c.normals), pair(&c.uvs))
}

/// The keys of a page's source vertices in source numbering (FORMAT.md §4.3): source page by
/// source page, cluster by cluster, each cluster's vertices by index.
pub(crate) fn source_keys<'a>(sources: impl IntoIterator<Item = &'a Quantized>) -> Vec<VertexKey> {
    sources.into_iter().flat_map(|c| (0..c.positions.len()).map(move |v| key(c, v))).collect()
}

/// One source page's vertices by key: the numbers of equal vertices together, ascending, and
/// where each key's numbers lie. Made once per source page (a page is the source of several
/// others) rather than once per page that reads it; a page looks up each of its new vertices in
/// every source, so a lookup is one hash probe. Built by counting, not sorting: the keys are
/// numbered by first appearance, and each key's numbers are laid out in the order they come.
pub(crate) struct PageKeys {
    /// Every vertex's number in the page, grouped by key.
    numbers: Vec<u32>,
    /// Per key, where its numbers start in `numbers` and how many there are.
    runs: rustc_hash::FxHashMap<VertexKey, (u32, u32)>,
}

impl PageKeys {
    /// The index of one source page's vertex `keys` (in its own numbering).
    pub(crate) fn new(keys: &[VertexKey]) -> PageKeys {
        let mut runs: rustc_hash::FxHashMap<VertexKey, (u32, u32)> = rustc_hash::FxHashMap::default();
        runs.reserve(keys.len());
        // Count each key's vertices, then give each key its range (in first-appearance order).
        let mut group = Vec::with_capacity(keys.len());
        let mut counts: Vec<u32> = Vec::new();
        for k in keys {
            let next = counts.len() as u32;
            let g = runs.entry(*k).or_insert((next, 0)).0;
            if g == next {
                counts.push(0);
            }
            counts[g as usize] += 1;
            group.push(g);
        }
        let mut starts = Vec::with_capacity(counts.len());
        let mut at = 0u32;
        for &c in &counts {
            starts.push(at);
            at += c;
        }
        let mut fill = starts.clone();
        let mut numbers = vec![0u32; keys.len()];
        for (u, &g) in group.iter().enumerate() {
            numbers[fill[g as usize] as usize] = u as u32;
            fill[g as usize] += 1;
        }
        for run in runs.values_mut() {
            *run = (starts[run.0 as usize], counts[run.0 as usize]);
        }
        PageKeys { numbers, runs }
    }

    /// How many vertices it has.
    fn len(&self) -> u32 {
        self.numbers.len() as u32
    }

    /// The numbers of the vertices equal to `k`, ascending.
    fn run(&self, k: &VertexKey) -> impl DoubleEndedIterator<Item = u32> + Clone + '_ {
        let (start, count) = self.runs.get(k).copied().unwrap_or((0, 0));
        self.numbers[start as usize..(start + count) as usize].iter().copied()
    }
}

/// A page's source vertices found by key: its source pages' [`PageKeys`] in order, each
/// numbered from the sum of the vertex counts before it (the source numbering of FORMAT.md
/// §4.3).
pub(crate) struct SourceIndex<'a> {
    sources: Vec<(&'a PageKeys, u32)>,
}

impl<'a> SourceIndex<'a> {
    /// The index of the source pages `sources`, in order.
    pub(crate) fn new(sources: impl IntoIterator<Item = &'a PageKeys>) -> SourceIndex<'a> {
        let mut first = 0u32;
        let sources = sources
            .into_iter()
            .map(|s| {
                let at = first;
                first += s.len();
                (s, at)
            })
            .collect();
        SourceIndex { sources }
    }

    /// The source vertex equal to `k` whose coded difference from `next` (the decoder's
    /// expectation, the previous far copy's number plus one) is smallest, if any is equal; of
    /// two equally small, the lower number.
    pub(crate) fn nearest(&self, k: &VertexKey, next: i64) -> Option<usize> {
        // The equal vertices on either side of `next`, over all sources (numbers ascend with
        // the source order); zigzag codes −d one smaller than +d.
        let (mut below, mut above): (Option<u32>, Option<u32>) = (None, None);
        for &(keys, first) in &self.sources {
            let mut run = keys.run(k).map(|u| u + first);
            if above.is_none() {
                above = run.clone().find(|&u| u as i64 >= next);
            }
            if let Some(u) = run.rfind(|&u| (u as i64) < next) {
                below = Some(u);
            }
        }
        let cost = |u: u32| zigzag32((u as i64 - next) as i32);
        [below, above].into_iter().flatten().min_by_key(|&u| cost(u)).map(|u| u as usize)
    }
}

/// Byte planes of `values`, each `N` lanes wide: plane 0 (every lane's low byte), then plane 1,
/// and so on, `planes` in all.
fn byte_planes<const N: usize>(values: &[[u32; N]], planes: usize) -> impl Iterator<Item = Vec<u8>> + '_ {
    (0..planes).map(move |p| values.iter().flatten().map(|&z| (z >> (8 * p)) as u8).collect())
}

/// The fewest byte planes that hold every value (at least `least`).
fn planes_for<const N: usize>(values: &[[u32; N]], least: usize) -> usize {
    let widest = values.iter().flatten().map(|&z| 4 - z.leading_zeros() as usize / 8).max().unwrap_or(0);
    widest.max(least)
}

/// Where [`encode_page`]'s streams hold the references (0 a new vertex, 1 a copy, 2 a far
/// copy; FORMAT.md §4.3).
pub(crate) const REFERENCES_STREAM: usize = 4;

/// The encoded page as separate streams (preamble, index lengths, coded indices, marks, then
/// each byte plane of the references and of each attribute), which the writer compresses one
/// zstd frame each so that each gets its own entropy tables; their concatenation is the
/// encoded page. A vertex equal in every attribute to one decoded before it in the page (a
/// cluster-border vertex shared with a neighbour, mostly) is stored as a copy of the nearest
/// such one, without residuals; else one equal to a vertex of the page's sources (`sources`,
/// empty for a page that must decode alone) as a far copy of it. `None` if the index codec
/// fails.
pub(crate) fn encode_page(clusters: &[Quantized], flags: u32, sources: &SourceIndex<'_>) -> Option<Vec<Vec<u8>>> {
    let mut edges = EdgeTable::new();
    let (mut lengths, mut coded, mut marks) = (Vec::new(), Vec::new(), Vec::new());
    let (mut pos, mut nrm, mut uvs) = (Vec::new(), Vec::new(), Vec::new());
    let mut materials = Vec::new();
    let mut anchors = (<[i32; 3]>::default(), <[u16; 2]>::default(), <[u16; 2]>::default());
    // Each distinct vertex → its latest place in the page's decoding order.
    let mut latest: rustc_hash::FxHashMap<VertexKey, usize> = rustc_hash::FxHashMap::default();
    let (mut references, mut targets, mut follow) = (Vec::new(), Vec::new(), Targets::new());
    let (mut far, mut follow_far) = (Vec::new(), Targets::new());
    for c in clusters {
        let vertex_count = c.positions.len();
        let wide: Vec<u32> = c.indices.iter().map(|&i| i as u32).collect();
        let code = meshopt::encode_index_buffer(&wide, vertex_count).ok()?;
        lengths.extend_from_slice(&(u16::try_from(code.len()).ok()?).to_le_bytes());
        coded.extend_from_slice(&code);
        marks.extend_from_slice(&c.marks);
        let preds = predictors(&c.indices, vertex_count, &mut edges);
        let stored: Vec<(u8, Predictor)> = preds
            .iter()
            .filter(|&&(v, _)| {
                let k = key(c, v as usize);
                let earlier = latest.insert(k, references.len());
                let source = if earlier.is_none() { sources.nearest(&k, follow_far.next) } else { None };
                references.push(if earlier.is_some() {
                    1
                } else if source.is_some() {
                    2
                } else {
                    0
                });
                targets.extend(earlier.map(|t| [follow.code(t)]));
                far.extend(source.map(|u| [follow_far.code(u)]));
                earlier.is_none() && source.is_none()
            })
            .copied()
            .collect();
        let first = preds[0].0 as usize;
        residuals(&stored, &c.positions, anchors.0, |r| pos.push(r.map(zigzag32)));
        anchors.0 = c.positions[first];
        if flags & FLAG_NORMALS != 0 {
            residuals(&stored, &c.normals, anchors.1, |r| nrm.push(r.map(|x| zigzag16(x) as u32)));
            anchors.1 = c.normals[first];
        }
        if flags & FLAG_UVS != 0 {
            residuals(&stored, &c.uvs, anchors.2, |r| uvs.push(r.map(|x| zigzag16(x) as u32)));
            anchors.2 = c.uvs[first];
        }
        materials.extend(c.materials.iter().map(|&m| [m as u32]));
    }
    let planes = planes_for(&pos, 1);
    let target_planes = planes_for(&targets, 0);
    let far_planes = planes_for(&far, 0);
    let preamble = vec![planes as u8, target_planes as u8, far_planes as u8, 0];
    let mut streams = vec![preamble, lengths, coded, marks, references];
    debug_assert_eq!(streams.len() - 1, REFERENCES_STREAM);
    streams.extend(byte_planes(&targets, target_planes));
    streams.extend(byte_planes(&far, far_planes));
    streams.extend(byte_planes(&pos, planes));
    for (flag, values) in [(FLAG_NORMALS, &nrm), (FLAG_UVS, &uvs)] {
        if flags & flag != 0 {
            streams.extend(byte_planes(values, 2));
        }
    }
    if flags & FLAG_MATERIALS != 0 {
        streams.extend(byte_planes(&materials, 2));
    }
    Some(streams)
}

/// Feeds the residual of each vertex (value − prediction) to `out`, in decoding order.
fn residuals<T: Lanes>(preds: &[(u8, Predictor)], values: &[T], anchor: T, mut out: impl FnMut(T)) {
    for &(v, p) in preds {
        out(values[v as usize].sub(predict(p, values, anchor)));
    }
}

/// A reader over the encoded page's sections, each a byte slice taken in turn.
#[cfg(test)]
struct Sections<'a> {
    rest: &'a [u8],
}

#[cfg(test)]
impl<'a> Sections<'a> {
    fn take(&mut self, len: usize) -> Result<&'a [u8], Invalid> {
        if len > self.rest.len() {
            return invalid("encoded page ends early");
        }
        let (head, rest) = self.rest.split_at(len);
        self.rest = rest;
        Ok(head)
    }

    /// `count` values of `N` lanes of `planes` bytes each (plane-major), as u32 lanes.
    fn planes<const N: usize>(&mut self, count: usize, planes: usize) -> Result<Vec<[u32; N]>, Invalid> {
        let mut values = vec![[0u32; N]; count];
        for p in 0..planes {
            let bytes = self.take(count * N)?;
            for (value, lanes) in values.iter_mut().zip(bytes.chunks_exact(N)) {
                for k in 0..N {
                    value[k] |= (lanes[k] as u32) << (8 * p);
                }
            }
        }
        Ok(values)
    }
}

/// The reference decoder, which the tests hold the fast one ([`crate::decode`]) to: decodes
/// a page's encoded bytes (FORMAT.md §4.3) into its clusters' quantized values;
/// `records` are the page's cluster records, `sources` its source vertices in source numbering
/// (their values as the sources' GPU layouts hold them). Every index, reference, octahedral
/// value and mark is checked against its range; the lengths must match the counts exactly.
#[cfg(test)]
pub(crate) fn decode_page(
    bytes: &[u8],
    records: &[ClusterInfo],
    flags: u32,
    normal_bits: u32,
    sources: &[VertexKey],
) -> Result<Vec<Quantized>, Invalid> {
    let (v_total, t_total) = totals(records);
    let mut s = Sections { rest: bytes };
    let (planes, target_planes, far_planes) = preamble(s.take(PREAMBLE)?)?;
    let lengths: Vec<usize> =
        s.take(2 * records.len())?.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]]) as usize).collect();
    let index_bytes: usize = lengths.iter().sum();
    let coded = s.take(index_bytes)?;
    let marks = s.take(t_total)?;
    let references = s.take(v_total)?;
    let (copies, far) = reference_counts(references)?;
    let targets: Vec<u32> = s.planes::<1>(copies, target_planes)?.iter().map(|z| z[0]).collect();
    let far_targets: Vec<u32> = s.planes::<1>(far, far_planes)?.iter().map(|z| z[0]).collect();
    let shape = Shape { index_bytes, planes, target_planes, copies, far_planes, far };
    let stored = shape.stored(v_total);
    let expected = encoded_len(flags, records.len(), (v_total, t_total), shape);
    if bytes.len() != expected {
        return invalid(format!("{} encoded bytes, its counts, lengths and references need {expected}", bytes.len()));
    }
    if let Some(m) = marks.iter().find(|&&m| m > 7) {
        return invalid(format!("open-edge mark {m} has bits above bit 2"));
    }
    let with = |flag: u32| flags & flag != 0;
    let half = |z: [u32; 2]| z.map(|x| unzigzag16(x as u16));
    let residuals = Stored {
        positions: s.planes::<3>(stored, planes)?.into_iter().map(|z| z.map(unzigzag32)).collect(),
        normals: if with(FLAG_NORMALS) { s.planes::<2>(stored, 2)?.into_iter().map(half).collect() } else { vec![] },
        uvs: if with(FLAG_UVS) { s.planes::<2>(stored, 2)?.into_iter().map(half).collect() } else { vec![] },
    };
    let materials = if with(FLAG_MATERIALS) { s.planes::<1>(t_total, 2)? } else { Vec::new() };

    let mut edges = EdgeTable::new();
    let mut out = Vec::with_capacity(records.len());
    let (mut to, mut io) = (0usize, 0usize);
    let mut page = Page {
        references,
        targets: targets.into_iter(),
        follow: Targets::new(),
        far_targets: far_targets.into_iter(),
        follow_far: Targets::new(),
        sources,
        decoded: Vec::new(),
        next_stored: 0,
        anchor: Default::default(),
    };
    let max_normal = ((1u32 << normal_bits.min(16)) - 1) as u16;
    for (r, &len) in records.iter().zip(&lengths) {
        let (vc, tc) = (r.vertex_count as usize, r.triangle_count as usize);
        let indices = decode_indices(&coded[io..io + len], vc, tc)?;
        let preds = predictors(&indices, vc, &mut edges);
        let mut q = Quantized { indices, marks: marks[to..to + tc].to_vec(), ..Quantized::default() };
        q.positions = vec![Default::default(); vc];
        q.normals = if with(FLAG_NORMALS) { vec![Default::default(); vc] } else { vec![] };
        q.uvs = if with(FLAG_UVS) { vec![Default::default(); vc] } else { vec![] };
        page.cluster(&preds, &residuals, &mut q)?;
        if q.normals.iter().flatten().any(|&n| n > max_normal) {
            return invalid(format!("octahedral value above {max_normal}"));
        }
        if with(FLAG_MATERIALS) {
            q.materials = materials[to..to + tc].iter().map(|m| m[0] as u16).collect();
        }
        out.push(q);
        (to, io) = (to + tc, io + len);
    }
    Ok(out)
}

/// The residuals of a page's stored vertices (reference 0), in decoding order.
#[cfg(test)]
struct Stored {
    positions: Vec<[i32; 3]>,
    normals: Vec<[u16; 2]>,
    uvs: Vec<[u16; 2]>,
}

/// The reference decoder's state across a page's clusters.
#[cfg(test)]
struct Page<'a> {
    /// Per vertex of the page in decoding order: 0 (stored) or 1 (a copy).
    references: &'a [u8],
    /// The copies' coded targets, in order.
    targets: std::vec::IntoIter<u32>,
    follow: Targets,
    /// The far copies' coded source vertex numbers, in order.
    far_targets: std::vec::IntoIter<u32>,
    follow_far: Targets,
    /// The page's source vertices, in source numbering.
    sources: &'a [VertexKey],
    /// Every vertex decoded so far, in decoding order.
    decoded: Vec<VertexKey>,
    /// Stored vertices decoded so far (the next one's place in [`Stored`]).
    next_stored: usize,
    /// The previous cluster's first vertex (zero for the first cluster).
    anchor: VertexKey,
}

#[cfg(test)]
impl Page<'_> {
    /// Decodes one cluster's attributes into `q` (sized already, empty for those the file
    /// lacks): in decoding order, each vertex a copy of the one its target names, or its
    /// prediction plus its residuals.
    fn cluster(&mut self, preds: &[(u8, Predictor)], stored: &Stored, q: &mut Quantized) -> Result<(), Invalid> {
        for &(v, p) in preds {
            let (v, j) = (v as usize, self.decoded.len());
            if self.references[j] != 0 {
                let (position, normal, uv) = if self.references[j] == 1 {
                    self.decoded[self.follow.follow(self.targets.next().unwrap_or_default(), j)?]
                } else {
                    let z = self.far_targets.next().unwrap_or_default();
                    self.sources[self.follow_far.follow_far(z, self.sources.len())?]
                };
                q.positions[v] = position;
                if let Some(n) = q.normals.get_mut(v) {
                    *n = normal;
                }
                if let Some(u) = q.uvs.get_mut(v) {
                    *u = uv;
                }
            } else {
                let k = self.next_stored;
                self.next_stored += 1;
                q.positions[v] = predict(p, &q.positions, self.anchor.0).add(stored.positions[k]);
                if !q.normals.is_empty() {
                    q.normals[v] = predict(p, &q.normals, self.anchor.1).add(stored.normals[k]);
                }
                if !q.uvs.is_empty() {
                    q.uvs[v] = predict(p, &q.uvs, self.anchor.2).add(stored.uvs[k]);
                }
            }
            self.decoded.push(key(q, v));
        }
        self.anchor = key(q, preds[0].0 as usize);
        Ok(())
    }
}

/// A cluster's local indices from meshoptimizer's index codec, each checked to name a vertex
/// of the cluster.
#[cfg(test)]
fn decode_indices(coded: &[u8], vertex_count: usize, triangle_count: usize) -> Result<Vec<u8>, Invalid> {
    if coded.len() > index_bound(triangle_count) {
        return invalid(format!("{} bytes of coded indices for {triangle_count} triangles", coded.len()));
    }
    let wide: Vec<u32> =
        meshopt::decode_index_buffer(coded, 3 * triangle_count).map_err(|e| Invalid(format!("index codec: {e}")))?;
    if let Some(i) = wide.iter().find(|&&i| i as usize >= vertex_count) {
        return invalid(format!("local index {i} out of {vertex_count} vertices"));
    }
    Ok(wide.iter().map(|&i| i as u8).collect())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn record(vertex_count: u16, triangle_count: u16) -> ClusterInfo {
        ClusterInfo { group: 0, own_group: NO_GROUP, vertex_count, triangle_count, page_offset: 0 }
    }

    /// A strip of `n` vertices with every attribute, including extreme values that wrap, in
    /// the form the writer stores (triangles as the index codec gives them back).
    pub(crate) fn sample(n: usize, seed: i32) -> Quantized {
        let positions: Vec<[i32; 3]> = (0..n as i32)
            .map(|i| [i * 37 + seed, i32::MAX - i * i, if i % 5 == 0 { i32::MIN } else { i * 3 }])
            .collect();
        let mut indices = vec![0, 1, 2];
        for v in 3..n.min(130) as u8 {
            indices.extend_from_slice(&[v - 1, v - 2, v]);
        }
        // The vertices past the strip are used by no triangle.
        let t = indices.len() / 3;
        let marks: Vec<u8> = (0..t).map(|t| (t % 8) as u8).collect();
        let (indices, marks) = canonical_triangles(&indices, &marks, n).unwrap();
        Quantized {
            normals: (0..n).map(|i| [(i * 31 % 1024) as u16, 1023 - (i % 1024) as u16]).collect(),
            uvs: (0..n).map(|i| [u16::MAX - i as u16, (i * 977) as u16]).collect(),
            positions,
            indices,
            materials: (0..t).map(|t| (t / 7) as u16 * 1000).collect(),
            marks,
        }
    }

    pub(crate) fn records(clusters: &[Quantized]) -> Vec<ClusterInfo> {
        clusters.iter().map(|c| record(c.positions.len() as u16, c.marks.len() as u16)).collect()
    }

    #[test]
    fn pages_round_trip_exactly() {
        let clusters = vec![sample(3, 5), sample(256, -7), sample(40, 1 << 30)];
        let flags = FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS;
        let bytes: Vec<u8> = encode_page(&clusters, flags, &SourceIndex::new([])).unwrap().concat();
        assert_eq!(decode_page(&bytes, &records(&clusters), flags, 10, &[]), Ok(clusters.clone()));
        // A normal above the header's range is refused.
        assert!(decode_page(&bytes, &records(&clusters), flags, 9, &[]).is_err());
        // Without attributes, only positions, indices and marks are stored.
        let bare: Vec<Quantized> = clusters
            .iter()
            .map(|c| Quantized { normals: vec![], uvs: vec![], materials: vec![], ..c.clone() })
            .collect();
        let bytes: Vec<u8> = encode_page(&bare, 0, &SourceIndex::new([])).unwrap().concat();
        assert_eq!(decode_page(&bytes, &records(&bare), 0, 0, &[]), Ok(bare.clone()));
        // One byte more or less is refused.
        assert!(decode_page(&bytes[..bytes.len() - 1], &records(&bare), 0, 0, &[]).is_err());
        assert!(decode_page(&[&bytes[..], &[0]].concat(), &records(&bare), 0, 0, &[]).is_err());
    }

    /// A page whose vertices repeat earlier ones: the third cluster is the first again, every
    /// third vertex of the second repeats one of the first and one repeats a vertex of its own
    /// cluster; one has the position of an earlier vertex but another normal (not a repeat).
    pub(crate) fn repeating() -> Vec<Quantized> {
        let a = sample(40, 0);
        let mut b = sample(60, 9);
        let copy = |b: &mut Quantized, to: usize, from: &Quantized, v: usize| {
            b.positions[to] = from.positions[v];
            b.normals[to] = from.normals[v];
            b.uvs[to] = from.uvs[v];
        };
        for v in (0..40).step_by(3) {
            copy(&mut b, v, &a, v);
        }
        let own = b.clone();
        copy(&mut b, 50, &own, 1);
        b.positions[52] = a.positions[4];
        vec![a.clone(), b, a]
    }

    /// The encoded page of [`repeating`] with every attribute, and its copies' count.
    pub(crate) fn repeating_page() -> (Vec<Quantized>, Vec<Vec<u8>>) {
        let clusters = repeating();
        let streams = encode_page(&clusters, FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS, &SourceIndex::new([])).unwrap();
        (clusters, streams)
    }

    #[test]
    fn repeated_vertices_are_copies_and_round_trip() {
        let flags = FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS;
        let (clusters, streams) = repeating_page();
        let bytes: Vec<u8> = streams.concat();
        assert_eq!(decode_page(&bytes, &records(&clusters), flags, 10, &[]), Ok(clusters.clone()));
        // Stream 4 holds the reference flags: 14 copies in the second cluster, one within it,
        // and all 40 of the third; the same position with another normal is stored.
        let references = &streams[4];
        assert_eq!(references.len(), 140);
        assert_eq!(references.iter().filter(|&&f| f == 1).count(), 14 + 1 + 40);
        // Copies carry no residuals: the page is shorter than the same page stored whole.
        let unique: Vec<Quantized> = (0..3).map(|i| sample([40, 60, 40][i], 100 * i as i32 + 1)).collect();
        assert!(
            bytes.len() + 55 * 12 <= encode_page(&unique, flags, &SourceIndex::new([])).unwrap().concat().len() + 140
        );
    }

    /// The encoded bytes of [`repeating_page`] with the first copy's coded target replaced.
    pub(crate) fn with_first_target(streams: &[Vec<u8>], low_byte: u8) -> Vec<u8> {
        let mut streams = streams.to_vec();
        assert!(streams[0][1] >= 1, "the page has copies with nonzero targets");
        streams[5][0] = low_byte;
        streams.concat()
    }

    #[test]
    fn bad_references_are_errors() {
        let flags = FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS;
        let (clusters, streams) = repeating_page();
        let records = records(&clusters);
        let decode = |bytes: &[u8]| decode_page(bytes, &records, flags, 10, &[]);
        // The first copy (vertex 40 of the page) names vertex 127 (not decoded yet), or
        // vertex −128: the lengths still match, the target does not.
        for low_byte in [0xfe, 0xff] {
            let bad = decode(&with_first_target(&streams, low_byte)).unwrap_err();
            assert!(bad.0.contains("copies vertex"), "{bad:?}");
        }
        // A flag of 2, and a vertex turned into a copy (one stored vertex's residuals too many).
        let at = streams[..4].iter().map(Vec::len).sum::<usize>();
        let mut bytes = streams.concat();
        bytes[at] = 3;
        assert!(decode(&bytes).unwrap_err().0.contains("reference flag"));
        bytes[at] = 1;
        assert!(decode(&bytes).unwrap_err().0.contains("encoded bytes"));
    }

    #[test]
    fn coded_indices_are_checked() {
        let c = sample(40, 0);
        let wide: Vec<u32> = c.indices.iter().map(|&i| i as u32).collect();
        let coded = meshopt::encode_index_buffer(&wide, 40).unwrap();
        assert_eq!(decode_indices(&coded, 40, c.marks.len()).unwrap(), c.indices);
        // Fewer vertices than the indices name.
        assert!(decode_indices(&coded, 39, c.marks.len()).is_err());
        // A codec header of another version.
        let mut bad = coded.clone();
        bad[0] ^= 0x40;
        assert!(decode_indices(&bad, 40, c.marks.len()).is_err());
        assert!(decode_indices(&coded[..coded.len() - 1], 40, c.marks.len()).is_err());
    }

    /// The edges a cluster marks, as vertex pairs: what a rotation must keep.
    fn marked_edges(indices: &[u8], marks: &[u8]) -> Vec<(u8, u8)> {
        let mut edges: Vec<(u8, u8)> = indices
            .chunks_exact(3)
            .zip(marks)
            .flat_map(|(t, &m)| (0..3).filter(move |k| m >> k & 1 != 0).map(move |k| (t[k], t[(k + 1) % 3])))
            .collect();
        edges.sort_unstable();
        edges
    }

    #[test]
    fn rotated_triangles_keep_their_marks() {
        // A fan whose triangles the codec rotates.
        let indices: Vec<u8> = (1..20u8).flat_map(|v| [v, v + 1, 0]).collect();
        let marks: Vec<u8> = (0..19).map(|t| [1u8, 2, 4, 3, 6][t % 5]).collect();
        let (rotated, moved) = canonical_triangles(&indices, &marks, 21).unwrap();
        assert_ne!(rotated, indices, "the test needs a rotation");
        assert_eq!(marked_edges(&rotated, &moved), marked_edges(&indices, &marks));
        // Stable: the stored form comes back as is.
        assert_eq!(canonical_triangles(&rotated, &moved, 21).unwrap(), (rotated, moved));
    }

    #[test]
    fn first_use_order_follows_the_triangles() {
        assert_eq!(first_use_order(&[2, 0, 3, 3, 0, 1], 5), vec![2, 0, 3, 1, 4]);
    }

    #[test]
    fn smooth_vertices_use_the_parallelogram() {
        // Two triangles of a quad: vertex 3 is predicted across the edge (1, 2); vertex 4 is
        // used by no triangle and comes last, from the previous vertex.
        let mut edges = EdgeTable::new();
        let preds = predictors(&[0, 1, 2, 2, 1, 3], 5, &mut edges);
        assert_eq!(
            preds,
            vec![
                (0, Predictor::Anchor),
                (1, Predictor::Neighbour(0)),
                (2, Predictor::Neighbour(0)),
                (3, Predictor::Parallelogram(2, 1, 0)),
                (4, Predictor::Neighbour(3)),
            ]
        );
        // Decoding order is first use, whatever the numbering.
        let preds = predictors(&[2, 0, 1], 3, &mut edges);
        assert_eq!(preds[0], (2, Predictor::Anchor));
        assert_eq!(preds[1], (0, Predictor::Neighbour(2)));
    }

    #[test]
    fn zigzag_round_trips_the_extremes() {
        for r in [0, 1, -1, i32::MAX, i32::MIN] {
            assert_eq!(unzigzag32(zigzag32(r)), r);
        }
        for r in [0u16, 1, u16::MAX, 0x8000, 0x7fff] {
            assert_eq!(unzigzag16(zigzag16(r)), r);
        }
    }
}
