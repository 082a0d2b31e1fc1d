//! The .mres container: byte-exact round trips, corrupt input always gives an error
//! (truncation at every length, every byte flipped), never a panic, and the page-level API
//! decodes exactly what the whole-file reader does.

use mres_format::{
    rewrite, write_mres, write_mres_with, ClusterHeader, Dag, DagCluster, Grid, Group, Header, MresError, MresFile,
    MresIndex, Page, PageCoding, Sphere, UvQuant, CLUSTER_HEADER_SIZE, FLAG_LAYOUT_PAGES, FLAG_MATERIALS, HEADER_SIZE,
    NO_GROUP,
};

fn sample_dag() -> Dag {
    Dag::sample()
}

#[test]
fn round_trip_is_exact() {
    let dag = sample_dag();
    let bytes = write_mres(&dag, 3).unwrap();
    let file = MresFile::parse(bytes.clone()).unwrap();
    // Coarse to fine: the root group comes first.
    assert_eq!(file.groups[0].error, f32::INFINITY);
    assert_eq!(file.header.level_count, 2);
    let decoded = file.decode_all().unwrap();
    // Map back: file cluster 0 is the root cluster, then the four level-0 clusters.
    let order = [4usize, 0, 1, 2, 3];
    for (i, d) in decoded.iter().enumerate() {
        let c = &dag.clusters[order[i]];
        assert_eq!(d.positions, c.positions);
        // The same triangles in the same order with the same marked edges; a triangle's corners
        // may be rotated (docs/FORMAT.md §4.3).
        assert_eq!(triangles(&d.indices, &d.open_edges), triangles(&c.indices, &c.open_edges));
        assert_eq!(d.materials, c.materials);
        assert_eq!(d.uvs, c.uvs);
        assert_eq!(d.normals, c.normals);
    }
    // Writing what was read gives the same bytes.
    let again = Dag {
        header: file.header,
        groups: file.groups.clone(),
        clusters: decoded.into_iter().zip(&file.clusters).map(|(d, info)| DagCluster::from_decoded(d, info)).collect(),
    };
    assert_eq!(write_mres(&again, 3).unwrap(), bytes);
}

/// Each triangle with its open-edge marks, rotated so that its smallest index comes first
/// (bit k of a mark is the edge from corner k to k + 1, so it rotates with the corners).
fn triangles(indices: &[u8], marks: &[u8]) -> Vec<([u8; 3], u8)> {
    indices
        .chunks_exact(3)
        .zip(marks)
        .map(|(t, &m)| {
            let r = (0..3).min_by_key(|&k| t[k]).unwrap();
            let corners = [t[r], t[(r + 1) % 3], t[(r + 2) % 3]];
            let mark = (0..3).fold(0, |acc, k| acc | ((m >> ((k + r) % 3)) & 1) << k);
            (corners, mark)
        })
        .collect()
}

fn parse_and_decode(bytes: Vec<u8>) -> Result<(), MresError> {
    let file = MresFile::parse(bytes)?;
    file.decode_all().map(|_| ())
}

#[test]
fn every_truncation_is_an_error() {
    for coding in [PageCoding::FarCopies, PageCoding::Layout] {
        let bytes = write_mres_with(&sample_dag(), 3, coding).unwrap();
        for len in 0..bytes.len() {
            let result = parse_and_decode(bytes[..len].to_vec());
            assert!(result.is_err(), "{coding:?}: truncated to {len} of {} bytes was accepted", bytes.len());
        }
        assert!(parse_and_decode(bytes).is_ok());
    }
}

#[test]
fn every_flipped_byte_is_an_error() {
    for coding in [PageCoding::FarCopies, PageCoding::Layout] {
        let bytes = write_mres_with(&sample_dag(), 3, coding).unwrap();
        for at in 0..bytes.len() {
            for mask in [0x01u8, 0x80, 0xff] {
                let mut corrupt = bytes.clone();
                corrupt[at] ^= mask;
                let result = parse_and_decode(corrupt);
                assert!(result.is_err(), "{coding:?}: flipping byte {at} with {mask:#x} was accepted");
            }
        }
    }
}

#[test]
fn typed_errors() {
    let bytes = write_mres(&sample_dag(), 3).unwrap();
    let mut v = bytes.clone();
    v[4] = 1; // version 1 had no open-edge marks
    assert_eq!(MresFile::parse(v).unwrap_err(), MresError::WrongVersion { found: 1 });
    // Version 2 stored the GPU layout itself (docs/FORMAT.md §8): refused, never misread.
    let mut v = bytes.clone();
    v[4] = 2;
    assert_eq!(MresFile::parse(v).unwrap_err(), MresError::WrongVersion { found: 2 });
    // Version 3 stored every vertex with residuals, without copies (§8): refused too, and the
    // message says which version the reader reads.
    let mut v = bytes.clone();
    v[4] = 3;
    let error = MresFile::parse(v).unwrap_err();
    assert_eq!(error, MresError::WrongVersion { found: 3 });
    assert_eq!(error.to_string(), "unsupported .mres version 3 (this reader reads version 6)");
    // Version 4 had no far copies (§8): its pages would decode, but it is refused like the rest.
    let mut v = bytes.clone();
    v[4] = 4;
    let error = MresFile::parse(v).unwrap_err();
    assert!(error.to_string().starts_with("unsupported .mres version 4"), "{error}");
    // Version 5 had no layout pages (§8): refused, as its readers refuse version 6.
    let mut v = bytes.clone();
    v[4] = 5;
    assert_eq!(MresFile::parse(v).unwrap_err(), MresError::WrongVersion { found: 5 });
    let mut v = bytes.clone();
    v[0] = b'X';
    assert_eq!(MresFile::parse(v).unwrap_err(), MresError::BadMagic);
    assert!(matches!(MresFile::parse(bytes[..100].to_vec()), Err(MresError::Truncated { .. })));
    let mut v = bytes.clone();
    let last = v.len() - 1;
    v[last] ^= 1;
    let file = MresFile::parse(v).unwrap();
    let last_page = file.pages.len() as u32 - 1;
    assert_eq!(file.page(last_page).unwrap_err(), MresError::Checksum(format!("page {last_page}")));
}

/// A page whose table entry claims a huge decompressed size is rejected before any allocation.
#[test]
fn huge_claimed_page_size_is_rejected() {
    let bytes = write_mres(&sample_dag(), 3).unwrap();
    let file = MresFile::parse(bytes.clone()).unwrap();
    let table = 160 + file.groups.len() * 40 + file.clusters.len() * 16;
    let mut v = bytes;
    v[table + 12..table + 16].copy_from_slice(&u32::MAX.to_le_bytes());
    // Fix the meta checksum so that only the size check can catch it.
    let hierarchy_end = table;
    let table_size = u64::from_le_bytes(v[104..112].try_into().unwrap()) as usize;
    let mut h = blake3::Hasher::new();
    h.update(&v[..112]);
    h.update(&v[160..hierarchy_end]);
    h.update(&v[table..table + table_size]);
    let sum = *h.finalize().as_bytes();
    v[112..144].copy_from_slice(&sum);
    let err = MresFile::parse(v).unwrap_err();
    assert!(matches!(err, MresError::Corrupt(ref m) if m.contains("decompressed")), "{err}");
}

/// A xorshift32 stream from `state` (nonzero): the tests' reproducible pseudo-random bits.
fn xorshift(mut state: u32) -> impl FnMut() -> u32 {
    move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state
    }
}

/// A DAG spread over several pages: `n` level-0 groups of one cluster each, every one
/// simplified into a cluster of the single root group. Positions are spread over 20 bits per
/// axis so that clusters are large and pages fill up.
fn multi_page_dag(n: u32) -> Dag {
    let mut bits = xorshift(0x2545_f491);
    let mut next = move || (bits() >> 12) as i32;
    let mut cluster = |group: u32, own_group: u32| DagCluster {
        group,
        own_group,
        positions: (0..256).map(|_| [next(), next(), next()]).collect(),
        normals: Vec::new(),
        uvs: Vec::new(),
        indices: (0..384).map(|i| ((i * 7) % 256) as u8).collect(),
        materials: (0..128).map(|t| t as u16).collect(),
        open_edges: (0..128).map(|t| (t % 8) as u8).collect(),
    };
    let mut clusters: Vec<DagCluster> = (0..n).map(|g| cluster(g, NO_GROUP)).collect();
    clusters.extend((0..n).map(|g| cluster(n, g)));
    let sphere = Sphere { center: [1.0; 3], radius: 2.0 };
    let group = |error, level| Group { sphere, error, level, first_cluster: 0, cluster_count: 0, page: 0 };
    let mut groups: Vec<Group> = (0..n).map(|_| group(0.01, 0)).collect();
    groups.push(group(f32::INFINITY, 1));
    Dag {
        header: Header {
            flags: FLAG_MATERIALS,
            grid: Grid { origin: [0.0; 3], step: 1e-6 },
            uv: UvQuant { min: [0.0; 2], extent: [0.0; 2] },
            normal_bits: 0,
            position_bits: 20,
            level_count: 0,
            source_triangles: 128 * n as u64,
        },
        groups,
        clusters,
    }
}

/// [`multi_page_dag`] with half the vertices of each level-0 cluster equal to vertices of the
/// coarser cluster its group produced (as simplification keeps them), which lies in an
/// earlier page: far copies (docs/FORMAT.md §4.3).
fn far_dag(n: u32) -> Dag {
    let mut dag = multi_page_dag(n);
    for g in 0..n as usize {
        let coarse = dag.clusters[n as usize + g].positions.clone();
        for v in (0..256).step_by(2) {
            dag.clusters[g].positions[v] = coarse[255 - v];
        }
    }
    dag
}

/// Decodes every page of `bytes` in file order through the page-level reader, each given its
/// sources' layouts decoded before it, as a streamer does.
fn decode_in_file_order(bytes: &[u8]) -> Vec<Page> {
    let index = index_of(bytes);
    let mut pages: Vec<Page> = Vec::new();
    for p in 0..index.pages.len() as u32 {
        let range = index.page_range(p).unwrap();
        let sources: Vec<&[u8]> =
            index.page_sources(p).unwrap().iter().map(|&s| &pages[s as usize].bytes[..]).collect();
        let page = index.decode_page(p, &bytes[range.start as usize..range.end as usize], &sources).unwrap();
        pages.push(page);
    }
    pages
}

#[test]
fn far_copies_decode_to_the_layout_of_independent_pages() {
    let dag = far_dag(120);
    let far = write_mres(&dag, 1).unwrap();
    let alone = write_mres_with(&dag, 1, PageCoding::Independent).unwrap();
    let (index, index_alone) = (index_of(&far), index_of(&alone));
    assert!(
        index.pages.len() >= 3 && (0..index.pages.len() as u32).any(|p| !index.page_sources(p).unwrap().is_empty())
    );
    // The same GPU layout page by page (the version-4 rule), in fewer bytes.
    let (pages, pages_alone) = (decode_in_file_order(&far), decode_in_file_order(&alone));
    assert_eq!(pages, pages_alone);
    assert!(far.len() + 10_000 < alone.len(), "{} bytes with far copies, {} without", far.len(), alone.len());
    // Independent pages hold no far copy: each decodes alone.
    let fetch = |bytes: &[u8], i: &MresIndex, p: u32| {
        let r = i.page_range(p).unwrap();
        bytes[r.start as usize..r.end as usize].to_vec()
    };
    for p in 0..index.pages.len() as u32 {
        assert_eq!(index_alone.decode_page(p, &fetch(&alone, &index_alone, p), &[]).unwrap(), pages_alone[p as usize]);
    }
    // With far copies, a page that has them needs its sources; the whole-file reader finds
    // them itself.
    let file = MresFile::parse(far.clone()).unwrap();
    let mut needing = 0;
    for p in 0..index.pages.len() as u32 {
        let sources = index.page_sources(p).unwrap();
        let expected = sources.len();
        match index.decode_page(p, &fetch(&far, &index, p), &[]) {
            Err(e) => {
                assert_eq!(e, MresError::SourceCount { page: p, given: 0, expected });
                needing += 1;
            }
            Ok(page) => assert_eq!(page, pages[p as usize]),
        }
        assert_eq!(file.decode_page(p).unwrap(), pages[p as usize]);
    }
    assert!(needing > 0, "no page has far copies");
}

fn as_slices(s: &[Vec<u8>]) -> Vec<&[u8]> {
    s.iter().map(Vec::as_slice).collect()
}

#[test]
fn wrong_sources_are_errors() {
    let far = write_mres(&far_dag(120), 1).unwrap();
    let index = index_of(&far);
    let pages = decode_in_file_order(&far);
    // The last page with far copies: one that needs its sources.
    let fetch = |p: u32| {
        let r = index.page_range(p).unwrap();
        &far[r.start as usize..r.end as usize]
    };
    let p = (0..index.pages.len() as u32).rev().find(|&p| index.decode_page(p, fetch(p), &[]).is_err()).unwrap();
    let compressed = fetch(p);
    let sources: Vec<Vec<u8>> =
        index.page_sources(p).unwrap().iter().map(|&s| pages[s as usize].bytes.clone()).collect();
    assert_eq!(index.decode_page(p, compressed, &as_slices(&sources)).unwrap(), pages[p as usize]);
    // One source too many.
    let mut more = sources.clone();
    more.push(sources[0].clone());
    let expected = sources.len();
    assert_eq!(
        index.decode_page(p, compressed, &as_slices(&more)).unwrap_err(),
        MresError::SourceCount { page: p, given: expected + 1, expected }
    );
    // A source one byte short.
    let s = index.page_sources(p).unwrap()[0];
    let mut short = sources.clone();
    short[0].pop();
    assert_eq!(
        index.decode_page(p, compressed, &as_slices(&short)).unwrap_err(),
        MresError::SourceLength {
            page: p,
            source_page: s,
            len: sources[0].len() - 1,
            expected: sources[0].len() as u32
        }
    );
    // Source layouts of the right length whose headers point outside them, or that are all
    // zero: errors, never a panic (nor a page that decodes to other values).
    let mut bad = sources.clone();
    for (layout, &s) in bad.iter_mut().zip(&index.page_sources(p).unwrap()) {
        for h in layout.chunks_exact_mut(CLUSTER_HEADER_SIZE).take(index.pages[s as usize].cluster_count as usize) {
            h[20..24].copy_from_slice(&u32::MAX.to_le_bytes());
        }
    }
    let zero: Vec<Vec<u8>> = sources.iter().map(|s| vec![0; s.len()]).collect();
    for bad in [bad, zero] {
        match index.decode_page(p, compressed, &as_slices(&bad)) {
            Err(MresError::Decompress { page, problem }) => {
                assert!(page == p && problem.contains("source page"), "{problem}")
            }
            Err(other) => panic!("{other:?}"),
            Ok(_) => panic!("page {p} decoded from corrupt sources"),
        }
    }
}

/// Parses the prefix the way a streamer does: the header first, then the length it declares.
fn index_of(bytes: &[u8]) -> MresIndex {
    let prefix_len = MresIndex::prefix_len(&bytes[..HEADER_SIZE]).unwrap();
    MresIndex::parse(&bytes[..prefix_len as usize]).unwrap()
}

#[test]
fn pages_fetched_separately_decode_as_the_whole_file() {
    let bytes = write_mres(&far_dag(120), 1).unwrap();
    let file = MresFile::parse(bytes.clone()).unwrap();
    assert!(file.pages.len() >= 3, "only {} pages: the test needs several", file.pages.len());
    let mut layouts: Vec<Vec<u8>> = Vec::new();
    let index = index_of(&bytes);
    assert_eq!(index.header, file.header);
    assert_eq!(index.groups, file.groups);
    assert_eq!(index.clusters, file.clusters);
    assert_eq!(index.pages, file.pages);
    assert_eq!(index.file_size(), bytes.len() as u64);

    let whole = file.decode_all().unwrap();
    let mut from_pages = Vec::new();
    for p in 0..index.pages.len() as u32 {
        let range = index.page_range(p).unwrap();
        // Bytes the caller fetched itself, not a view of the parsed prefix.
        let fetched = bytes[range.start as usize..range.end as usize].to_vec();
        let sources: Vec<&[u8]> =
            index.page_sources(p).unwrap().iter().map(|&s| layouts[s as usize].as_slice()).collect();
        let page = index.decode_page(p, &fetched, &sources).unwrap();
        layouts.push(page.bytes.clone());
        assert_eq!(page, file.decode_page(p).unwrap());
        assert_eq!(page.bytes, file.page(p).unwrap());
        assert_eq!(page.index, p);
        assert_eq!(page.first_cluster, index.pages[p as usize].first_cluster);
        assert_eq!(page.headers.len(), index.pages[p as usize].cluster_count as usize);
        for (i, head) in page.headers.iter().enumerate() {
            let c = page.first_cluster + i as u32;
            let at = index.clusters[c as usize].page_offset as usize;
            assert_eq!(at, i * CLUSTER_HEADER_SIZE);
            let raw: &[u8; CLUSTER_HEADER_SIZE] = page.bytes[at..at + CLUSTER_HEADER_SIZE].try_into().unwrap();
            assert_eq!(*head, ClusterHeader::decode(raw));
            assert_eq!(index.decode_cluster(&page.bytes, c).unwrap(), page.clusters[i]);
        }
        from_pages.extend(page.clusters);
    }
    assert_eq!(from_pages, whole);
}

#[test]
fn a_corrupt_fetched_page_gives_the_right_error() {
    let bytes = write_mres(&multi_page_dag(40), 1).unwrap();
    let index = index_of(&bytes);
    let p = index.pages.len() as u32 - 1;
    let range = index.page_range(p).unwrap();
    let page = &bytes[range.start as usize..range.end as usize];
    let expected = index.pages[p as usize].compressed_size;
    assert_eq!(
        index.decode_page(p, &page[..page.len() - 1], &[]).unwrap_err(),
        MresError::PageLength { page: p, len: expected as u64 - 1, expected }
    );
    let mut longer = page.to_vec();
    longer.push(0);
    assert_eq!(
        index.decode_page(p, &longer, &[]).unwrap_err(),
        MresError::PageLength { page: p, len: expected as u64 + 1, expected }
    );
    for at in [0, page.len() / 2, page.len() - 1] {
        let mut flipped = page.to_vec();
        flipped[at] ^= 0x10;
        assert_eq!(index.decode_page(p, &flipped, &[]).unwrap_err(), MresError::Checksum(format!("page {p}")));
    }
    // Another page's bytes, of the same length or not, are never taken for this page's.
    let other = index.page_range(0).unwrap();
    assert!(index.decode_page(p, &bytes[other.start as usize..other.end as usize], &[]).is_err());
    let missing = index.pages.len() as u32;
    assert!(matches!(index.page_range(missing), Err(MresError::Corrupt(_))));
    assert!(matches!(index.decode_page(missing, page, &[]), Err(MresError::Corrupt(_))));
}

#[test]
fn a_short_prefix_says_how_many_bytes_it_needs() {
    let bytes = write_mres(&multi_page_dag(40), 1).unwrap();
    let needs = |len: usize, end: u64| MresError::Truncated {
        what: if end == HEADER_SIZE as u64 { "header" } else { "header, hierarchy and page table" }.into(),
        start: 0,
        end,
        len: len as u64,
    };
    for len in [0, 4, HEADER_SIZE - 1] {
        assert_eq!(MresIndex::prefix_len(&bytes[..len]).unwrap_err(), needs(len, HEADER_SIZE as u64));
        assert_eq!(MresIndex::parse(&bytes[..len]).unwrap_err(), needs(len, HEADER_SIZE as u64));
    }
    let prefix_len = MresIndex::prefix_len(&bytes[..HEADER_SIZE]).unwrap();
    let first_page = MresFile::parse(bytes.clone()).unwrap().pages[0].offset;
    assert_eq!(prefix_len, first_page);
    for len in [HEADER_SIZE, HEADER_SIZE + 1, prefix_len as usize - 1] {
        assert_eq!(MresIndex::parse(&bytes[..len]).unwrap_err(), needs(len, prefix_len));
    }
    assert!(MresIndex::parse(&bytes[..prefix_len as usize]).is_ok());
    // More than the prefix is fine: the rest is not looked at.
    assert_eq!(MresIndex::parse(&bytes).unwrap(), MresIndex::parse(&bytes[..prefix_len as usize]).unwrap());
    // The header is checked before its lengths are trusted.
    let mut bad = bytes[..HEADER_SIZE].to_vec();
    bad[0] = b'X';
    assert_eq!(MresIndex::prefix_len(&bad).unwrap_err(), MresError::BadMagic);
}

/// The whole-file reader still checks what only it can: the file's length.
#[test]
fn the_file_length_must_match_the_page_table() {
    let bytes = write_mres(&sample_dag(), 3).unwrap();
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(MresFile::parse(longer.clone()), Err(MresError::Corrupt(ref m)) if m.contains("page data ends")));
    // The prefix alone cannot know it; the index says where the file should end.
    assert_eq!(MresIndex::parse(&longer).unwrap().file_size(), bytes.len() as u64);
    let short = bytes[..bytes.len() - 1].to_vec();
    assert!(matches!(MresFile::parse(short), Err(MresError::Truncated { ref what, .. }) if what.starts_with("page")));
}

/// `bytes` (a one-page file) with its page's encoded bytes (docs/FORMAT.md §4.3) replaced by
/// `encoded`, compressed and checksummed again, and the meta checksum fixed: a file whose only
/// fault, if any, is in the encoding.
fn with_encoded_page(bytes: &[u8], encoded: &[u8]) -> Vec<u8> {
    with_page_bytes(bytes, &zstd::bulk::compress(encoded, 1).unwrap())
}

/// `bytes` (a one-page file) with its page's compressed bytes replaced by `frame`, the page
/// record's size and checksum and the meta checksum fixed.
fn with_page_bytes(bytes: &[u8], frame: &[u8]) -> Vec<u8> {
    use mres_format::records::{meta_checksum, PageRecord};
    let file = MresFile::parse(bytes.to_vec()).unwrap();
    assert_eq!(file.pages.len(), 1, "the sample is one page");
    let start = file.pages[0].offset as usize;
    let mut out = bytes[..start].to_vec();
    out.extend_from_slice(frame);
    let rec = start - mres_format::PAGE_RECORD_SIZE;
    out[rec + PageRecord::COMPRESSED_SIZE..][..4].copy_from_slice(&(frame.len() as u32).to_le_bytes());
    out[rec + PageRecord::CHECKSUM..][..32].copy_from_slice(blake3::hash(frame).as_bytes());
    let head: [u8; HEADER_SIZE] = out[..HEADER_SIZE].try_into().unwrap();
    let table = HEADER_SIZE + file.groups.len() * 40 + file.clusters.len() * 16;
    let sum = meta_checksum(&head, &out[HEADER_SIZE..table], &out[table..start]);
    out[112..144].copy_from_slice(&sum);
    out
}

/// Past the checksums: every truncation of a page's encoded bytes is an error, and no flipped
/// byte panics; flipped preamble and index-length bytes are errors (they change the length the
/// page needs), and so are flipped bytes anywhere once the encoding is one byte too long.
#[test]
fn corrupt_page_encodings_are_errors_not_panics() {
    let bytes = write_mres(&sample_dag(), 3).unwrap();
    let file = MresFile::parse(bytes.clone()).unwrap();
    let info = &file.pages[0];
    let frame = &bytes[info.offset as usize..][..info.compressed_size as usize];
    let encoded = zstd::stream::decode_all(frame).unwrap();
    assert!(parse_and_decode(with_encoded_page(&bytes, &encoded)).is_ok(), "resealing alone breaks nothing");
    for len in 0..encoded.len() {
        assert!(parse_and_decode(with_encoded_page(&bytes, &encoded[..len])).is_err(), "encoding cut to {len} bytes");
    }
    let mut longer = encoded.clone();
    longer.push(0);
    assert!(parse_and_decode(with_encoded_page(&bytes, &longer)).is_err());
    let length_bytes = 4 + 2 * info.cluster_count as usize;
    for at in 0..encoded.len() {
        for mask in [0x01u8, 0x80, 0xff] {
            let mut flipped = encoded.clone();
            flipped[at] ^= mask;
            let result = parse_and_decode(with_encoded_page(&bytes, &flipped));
            // Byte 2 is the far target plane count F, which a page without far copies (this
            // one-page file) multiplies by zero: any F up to 4 is accepted (§4.3, §7).
            if at < length_bytes && !(at == 2 && flipped[2] <= 4) {
                assert!(result.is_err(), "flipping preamble/length byte {at} with {mask:#x} was accepted");
            }
        }
    }
}

/// [`far_dag`] with normals and UVs that are not exactly representable (pseudo-random): their
/// decoded floats would quantize back only nearly.
fn far_dag_with_normals(n: u32) -> Dag {
    let mut dag = far_dag(n);
    dag.header.flags |= mres_format::FLAG_NORMALS | mres_format::FLAG_UVS;
    dag.header.normal_bits = 10;
    dag.header.uv = UvQuant { min: [0.0; 2], extent: [1.0; 2] };
    let mut bits = xorshift(0x9e37_79b9);
    let mut next = move || (bits() >> 8) as f32 / (1u32 << 24) as f32;
    for c in &mut dag.clusters {
        c.normals = (0..c.positions.len())
            .map(|_| {
                let v = [next() - 0.5, next() - 0.5, next() - 0.5 + 1e-3];
                let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                v.map(|x| x / len)
            })
            .collect();
        c.uvs = (0..c.positions.len()).map(|_| [next(), next()]).collect();
    }
    dag
}

/// Layout pages (docs/FORMAT.md §4.4) hold the GPU layouts the compact pages decode to, each
/// page alone; rewriting either file with the other encoding gives the other file, byte for
/// byte (what `mres repack` does), normals and UVs included.
#[test]
fn layout_pages_hold_the_layouts_of_compact_pages() {
    for (dag, flags) in [(far_dag(120), FLAG_MATERIALS), (far_dag_with_normals(40), FLAG_MATERIALS | 3)] {
        let compact = write_mres(&dag, 1).unwrap();
        let layout = write_mres_with(&dag, 1, PageCoding::Layout).unwrap();
        let index = index_of(&layout);
        assert_eq!(index.header.flags, flags | FLAG_LAYOUT_PAGES);
        assert!(index.pages.len() >= 3);
        assert!((0..index.pages.len() as u32).all(|p| index.page_sources(p).unwrap().is_empty()));
        assert_eq!(decode_in_file_order(&layout), decode_in_file_order(&compact));
        let read = |bytes: &[u8]| MresFile::parse(bytes.to_vec()).unwrap();
        assert_eq!(rewrite(&read(&layout), 1, PageCoding::FarCopies).unwrap(), compact);
        assert_eq!(rewrite(&read(&compact), 1, PageCoding::Layout).unwrap(), layout);
        assert_eq!(rewrite(&read(&compact), 1, PageCoding::FarCopies).unwrap(), compact);
    }
    let dag = far_dag(120);
    let layout = write_mres_with(&dag, 1, PageCoding::Layout).unwrap();
    let index = index_of(&layout);
    // A layout page takes no sources.
    let r = index.page_range(1).unwrap();
    let page = &layout[r.start as usize..r.end as usize];
    let given = [&page[..0]];
    assert_eq!(index.page_layout(1, page, &given), Err(MresError::SourceCount { page: 1, given: 1, expected: 0 }));
}

/// The sample's one page as a layout page: its layout, and the file with it replaced by `raw`.
fn sample_layout() -> (Vec<u8>, Vec<u8>) {
    let bytes = write_mres_with(&sample_dag(), 3, PageCoding::Layout).unwrap();
    let raw = MresFile::parse(bytes.clone()).unwrap().page(0).unwrap();
    (bytes, raw)
}

fn with_layout(bytes: &[u8], raw: &[u8]) -> Vec<u8> {
    with_page_bytes(bytes, &lz4::block::compress(raw, None, false).unwrap())
}

/// The streaming reader's layout check of a layout page: the sample's page 0 with `raw` as its
/// layout, through [`MresIndex::page_layout`].
fn streamed_layout(bytes: &[u8], raw: &[u8]) -> Result<Vec<u8>, MresError> {
    let file = with_layout(bytes, raw);
    let index = index_of(&file);
    let r = index.page_range(0).unwrap();
    index.page_layout(0, &file[r.start as usize..r.end as usize], &[])
}

/// Past the checksums, a layout page's layout is checked: a layout of another length, an
/// index out of range, nonzero padding or a block out of place is refused by the streaming
/// reader; an octahedral value out of range by the whole-page decoder (which unpacks every
/// value); no flipped byte panics.
#[test]
fn corrupt_layout_pages_are_errors_not_panics() {
    let (bytes, raw) = sample_layout();
    assert_eq!(streamed_layout(&bytes, &raw).unwrap(), raw, "resealing alone breaks nothing");
    for len in 0..raw.len() {
        assert!(streamed_layout(&bytes, &raw[..len]).is_err(), "layout cut to {len} bytes");
    }
    let header = |raw: &[u8], c: usize| {
        ClusterHeader::decode(raw[c * CLUSTER_HEADER_SIZE..][..CLUSTER_HEADER_SIZE].try_into().unwrap())
    };
    let indices = header(&raw, 0).block_offsets[ClusterHeader::INDICES] as usize;
    let mut bad = raw.clone();
    bad[indices + 1] = 4; // cluster 0 has 4 vertices
    let error = streamed_layout(&bytes, &bad).unwrap_err().to_string();
    assert!(error.contains("local index out of range"), "{error}");
    let mut bad = raw.clone();
    bad[indices + 6] = 1; // the padding after 2 triangles' 6 indices
    let error = streamed_layout(&bytes, &bad).unwrap_err().to_string();
    assert!(error.contains("padding not zero"), "{error}");
    let mut bad = raw.clone();
    bad[ClusterHeader::POSITIONS_OFFSET] += 4;
    let error = streamed_layout(&bytes, &bad).unwrap_err().to_string();
    assert!(error.contains("the layout puts it at"), "{error}");
    // normal_min 2000 with 10-bit normals: in place, but not a value the writer stores.
    let mut bad = raw.clone();
    bad[ClusterHeader::NORMAL_MIN..][..2].copy_from_slice(&2000u16.to_le_bytes());
    assert!(streamed_layout(&bytes, &bad).is_ok());
    let error = parse_and_decode(with_layout(&bytes, &bad)).unwrap_err().to_string();
    assert!(error.contains("page 0: cluster 0: an octahedral value is over 2^normal_bits - 1"), "{error}");
    // A block longer than LZ4_compressBound(raw_size) is refused before LZ4 reads it.
    let mut long = lz4::block::compress(&raw, None, false).unwrap();
    long.resize(raw.len() + raw.len() / 255 + 17, 0);
    let error = parse_and_decode(with_page_bytes(&bytes, &long)).unwrap_err().to_string();
    assert!(error.contains(&format!("LZ4 block of {} bytes", long.len())) && error.contains("at most"), "{error}");
    for at in 0..raw.len() {
        for mask in [0x01u8, 0x80, 0xff] {
            let mut flipped = raw.clone();
            flipped[at] ^= mask;
            let _ = parse_and_decode(with_layout(&bytes, &flipped));
        }
    }
}

/// `bytes` changed by `edit` in its header, hierarchy or page table, and the meta checksum
/// sealed again: a file whose only fault, if any, is the edit.
fn with_meta(bytes: &[u8], edit: impl FnOnce(&mut [u8])) -> Vec<u8> {
    use mres_format::records::{meta_checksum, HeaderRecord};
    let mut v = bytes.to_vec();
    edit(&mut v);
    let u64_at = |at: usize| u64::from_le_bytes(v[at..at + 8].try_into().unwrap()) as usize;
    let table = u64_at(HeaderRecord::PAGE_TABLE_OFFSET);
    let table_end = table + u64_at(HeaderRecord::PAGE_TABLE_SIZE);
    let head: [u8; HEADER_SIZE] = v[..HEADER_SIZE].try_into().unwrap();
    let sum = meta_checksum(&head, &v[HEADER_SIZE..table], &v[table..table_end]);
    v[HeaderRecord::META_CHECKSUM..][..32].copy_from_slice(&sum);
    v
}

/// `normal_bits` means nothing in a file without normals (docs/FORMAT.md §2), so any value there
/// reads: a layout-page file with 40 in it decodes as with 0 (found by fuzzing: the canonical
/// check shifted by it).
#[test]
fn normal_bits_of_a_file_without_normals_are_ignored() {
    use mres_format::records::HeaderRecord;
    let bytes = write_mres_with(&multi_page_dag(8), 1, PageCoding::Layout).unwrap();
    let expected = MresFile::parse(bytes.clone()).unwrap().decode_all().unwrap();
    let forty = |v: &mut [u8]| v[HeaderRecord::NORMAL_BITS..][..4].copy_from_slice(&40u32.to_le_bytes());
    let mut unsealed = bytes.clone();
    forty(&mut unsealed);
    let file = MresFile::parse(unsealed).unwrap_err();
    assert!(matches!(file, MresError::Checksum(_)), "{file}");
    assert_eq!(MresFile::parse(with_meta(&bytes, forty)).unwrap().decode_all().unwrap(), expected);
}

/// The hierarchy and page table must agree on where things are (docs/FORMAT.md §4.1, §5):
/// a cluster header away from `48·i` of its page, a group naming another page than the one
/// that holds it, and pages that skip a group are each an error of the index itself, before
/// any page is read.
#[test]
fn pages_groups_and_cluster_offsets_must_agree() {
    use mres_format::records::{ClusterRecord, GroupRecord, PageRecord};
    use mres_format::{CLUSTER_RECORD_SIZE, GROUP_RECORD_SIZE, PAGE_RECORD_SIZE};
    let bytes = write_mres(&far_dag(120), 1).unwrap();
    let index = index_of(&bytes);
    assert!(index.pages.len() > 2, "the sample has several pages");
    let groups_at = HEADER_SIZE;
    let clusters_at = groups_at + index.groups.len() * GROUP_RECORD_SIZE;
    let table_at = clusters_at + index.clusters.len() * CLUSTER_RECORD_SIZE;
    // The second cluster of the last page.
    let c = index.pages.last().unwrap().first_cluster as usize + 1;
    let offset = clusters_at + c * CLUSTER_RECORD_SIZE + ClusterRecord::PAGE_OFFSET;
    let moved = with_meta(&bytes, |v| v[offset..][..4].copy_from_slice(&0u32.to_le_bytes()));
    let e = MresIndex::parse(&moved).unwrap_err();
    assert!(e.to_string().contains(&format!("cluster {c}: page_offset 0")), "{e}");
    assert!(matches!(MresFile::parse(moved), Err(MresError::Corrupt(_))));
    // The last group names page 0.
    let g = index.groups.len() - 1;
    let named = groups_at + g * GROUP_RECORD_SIZE + GroupRecord::PAGE;
    assert_ne!(index.groups[g].page, 0);
    let e = MresIndex::parse(&with_meta(&bytes, |v| v[named..][..4].copy_from_slice(&0u32.to_le_bytes()))).unwrap_err();
    assert!(e.to_string().contains(&format!("group {g}: in page")), "{e}");
    // Page 1 starts one group late.
    let first_group = table_at + PAGE_RECORD_SIZE + PageRecord::FIRST_GROUP;
    let late = (index.pages[1].first_group + 1).to_le_bytes();
    let e = MresIndex::parse(&with_meta(&bytes, |v| v[first_group..][..4].copy_from_slice(&late))).unwrap_err();
    assert!(e.to_string().contains("page 1: groups from"), "{e}");
    assert!(MresIndex::parse(&with_meta(&bytes, |_| ())).is_ok(), "resealing alone breaks nothing");
}
