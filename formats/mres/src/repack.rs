//! Rewriting a file in another page coding (what `mres repack` does): every cluster taken
//! from its page's GPU layout as stored and laid out in the writer's canonical form, the
//! groups and, where they fit, the pages kept, and the file written again by [`crate::write`].

use super::records::ClusterHeader;
use super::write::{canonical, canonical_fault, gpu_blocks, stored_blocks, write_paged, EncodedCluster, WriteError};
use super::*;

/// `file` written again with its pages stored as `coding` says (what `mres repack` does): the
/// same groups, clusters and values in other page bytes. Each cluster is taken from its page's
/// layout as stored (every page read and checked first), never through decoded floats, whose
/// normals and UVs would quantize back only nearly, and laid out in the writer's canonical
/// form (vertices in first-use order, triangles as the index codec gives them back; FORMAT.md
/// §4.4 requires it of layout pages). Our writer's files are canonical already, so rewriting
/// one with its own coding and zstd level gives its bytes; a compact file from another writer
/// may number a cluster's vertices otherwise (§4.3 allows it) and gets them renumbered.
pub fn rewrite(file: &MresFile, level: i32, coding: PageCoding) -> Result<Vec<u8>, WriteError> {
    let kept: Vec<u32> = file.pages.iter().map(|p| p.group_count).collect();
    rewrite_paged(file, (level, coding), &kept)
}

/// [`rewrite`] with pages of `kept` groups each (see [`crate::write`]'s page filling).
fn rewrite_paged(file: &MresFile, (level, coding): (i32, PageCoding), kept: &[u32]) -> Result<Vec<u8>, WriteError> {
    let mut clusters = Vec::with_capacity(file.clusters.len());
    for (p, info) in file.pages.iter().enumerate() {
        let layout = file.decode_page(p as u32)?.bytes;
        let first = info.first_cluster as usize;
        // The reader checked every header and block, so these reads cannot miss; if one did,
        // it is an error, not a panic.
        let missing = || WriteError::BadDag(format!("page {p}: a cluster's blocks are not where its header says"));
        let records = file.clusters.get(first..first + info.cluster_count as usize).ok_or_else(missing)?;
        for (i, record) in records.iter().enumerate() {
            let head = layout.get(i * CLUSTER_HEADER_SIZE..).and_then(|h| h.first_chunk()).ok_or_else(missing)?;
            let head = ClusterHeader::decode(head);
            let stored =
                EncodedCluster::from_blocks(0, NO_GROUP, head, stored_blocks(&layout, &head).ok_or_else(missing)?);
            let bad =
                |problem: &str| WriteError::BadCluster { cluster: first + i, problem: format!("page {p}: {problem}") };
            let q = canonical(stored.quantized(file.header.flags))
                .ok_or_else(|| bad("meshoptimizer's index codec does not give its triangles back"))?;
            if let Some(fault) = canonical_fault(&q, file.header.normal_bits) {
                return Err(bad(fault));
            }
            let (head, blocks) = gpu_blocks(&q, file.header.flags);
            clusters.push(EncodedCluster::from_blocks(record.group, record.own_group, head, blocks));
        }
    }
    write_paged(&file.header, &file.groups, clusters, (level, coding), Some(kept))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::{self, Quantized};
    use crate::records::{meta_checksum, HeaderRecord, PageRecord};
    use crate::write::{gpu_page, write_mres, write_mres_with};

    /// `bytes` (a one-page file) with its page encoded from `clusters` (FORMAT.md §4.3, no
    /// sources), compressed, and the page record and meta checksum sealed again.
    fn with_page_of(bytes: &[u8], clusters: &[Quantized], flags: u32) -> Vec<u8> {
        let streams = codec::encode_page(clusters, flags, &codec::SourceIndex::new([])).unwrap();
        let frame: Vec<u8> =
            streams.iter().filter(|s| !s.is_empty()).flat_map(|s| zstd::bulk::compress(s, 3).unwrap()).collect();
        let file = MresFile::parse(bytes.to_vec()).unwrap();
        let start = file.pages[0].offset as usize;
        let mut out = bytes[..start].to_vec();
        out.extend_from_slice(&frame);
        let rec = start - PAGE_RECORD_SIZE;
        out[rec + PageRecord::COMPRESSED_SIZE..][..4].copy_from_slice(&(frame.len() as u32).to_le_bytes());
        out[rec + PageRecord::RAW_SIZE..][..4].copy_from_slice(&(gpu_page(clusters, flags).len() as u32).to_le_bytes());
        out[rec + PageRecord::CHECKSUM..][..32].copy_from_slice(blake3::hash(&frame).as_bytes());
        let head: [u8; HEADER_SIZE] = out[..HEADER_SIZE].try_into().unwrap();
        let table = HEADER_SIZE + file.groups.len() * GROUP_RECORD_SIZE + file.clusters.len() * CLUSTER_RECORD_SIZE;
        let sum = meta_checksum(&head, &out[HEADER_SIZE..table], &out[table..start]);
        out[HeaderRecord::META_CHECKSUM..][..32].copy_from_slice(&sum);
        out
    }

    /// A compact page need not be canonical (FORMAT.md §4.3: any vertex order decodes), but a
    /// layout page must be (§4.4): `rewrite` lays out each cluster canonically, so repacking a
    /// compact page whose vertices are out of first-use order gives the file our writer makes,
    /// in either coding, not a layout file that its readers refuse.
    #[test]
    fn rewrite_lays_out_non_canonical_pages_canonically() {
        let dag = Dag::sample();
        let compact = write_mres_with(&dag, 3, PageCoding::Independent).unwrap();
        let file = MresFile::parse(compact.clone()).unwrap();
        let (flags, layout) = (file.header.flags, file.decode_page(0).unwrap().bytes);
        let swapped: Vec<Quantized> = (0..file.clusters.len())
            .map(|i| {
                let head = ClusterHeader::decode(layout[i * CLUSTER_HEADER_SIZE..].first_chunk().unwrap());
                let mut q = EncodedCluster::from_blocks(0, NO_GROUP, head, stored_blocks(&layout, &head).unwrap())
                    .quantized(flags);
                // The last two vertices change places (both are used, so the order is no
                // longer first-use).
                let v = q.positions.len() as u8;
                let swap = |i: u8| {
                    if i == v - 1 {
                        v - 2
                    } else if i == v - 2 {
                        v - 1
                    } else {
                        i
                    }
                };
                q.indices.iter_mut().for_each(|i| *i = swap(*i));
                for values in [&mut q.normals, &mut q.uvs] {
                    values.swap(v as usize - 1, v as usize - 2);
                }
                q.positions.swap(v as usize - 1, v as usize - 2);
                q
            })
            .collect();
        let odd = MresFile::parse(with_page_of(&compact, &swapped, flags)).unwrap();
        assert_ne!(odd.decode_page(0).unwrap().bytes, layout, "the page reads, in another vertex order");
        let layout_file = write_mres_with(&dag, 3, PageCoding::Layout).unwrap();
        assert_eq!(rewrite(&odd, 3, PageCoding::Layout).unwrap(), layout_file);
        assert_eq!(rewrite(&odd, 3, PageCoding::Independent).unwrap(), compact);
        MresFile::parse(layout_file).unwrap().decode_all().unwrap();
    }

    /// `rewrite` keeps the input's pages (the groups each holds), not the writer's fill: a
    /// file of one group per page repacks to one group per page, and back to its own bytes.
    /// The sample's level-0 page then copies every vertex of its first cluster from the root's
    /// page with far targets that all code as 0 (no far-target byte plane): the writer's check
    /// once took that for "no far copies", decoded without the sources and failed.
    #[test]
    fn rewrite_keeps_the_pages() {
        let greedy = MresFile::parse(write_mres(&Dag::sample(), 3).unwrap()).unwrap();
        let one_each = vec![1u32; greedy.groups.len()];
        assert!(greedy.pages.len() < one_each.len(), "the writer's own fill puts groups together");
        let write =
            |coding| rewrite_paged(&greedy, (3, coding), &one_each).unwrap_or_else(|e| panic!("{coding:?}: {e}"));
        let (compact, layout) = (write(PageCoding::FarCopies), write(PageCoding::Layout));
        assert_eq!(MresFile::parse(layout.clone()).unwrap().pages.len(), one_each.len());
        assert_eq!(rewrite(&MresFile::parse(compact.clone()).unwrap(), 3, PageCoding::Layout).unwrap(), layout);
        assert_eq!(rewrite(&MresFile::parse(layout).unwrap(), 3, PageCoding::FarCopies).unwrap(), compact);
    }

    /// A two-level DAG of `n` level-0 groups of one cluster each and a root group of `n`
    /// clusters, with normals, UVs and materials; each level-0 cluster repeats some vertices of
    /// a root cluster (far copies, when their pages differ) and of its neighbour before it
    /// (copies). Pseudo-random from `seed`.
    fn shared_vertex_dag(n: u32, seed: u64) -> Dag {
        let mut state = seed;
        let mut next = move |m: u32| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 33) as u32) % m
        };
        let cluster = |group: u32, own_group: u32, next: &mut dyn FnMut(u32) -> u32| {
            let v = 8 + next(56) as usize;
            let t = 4 + next(60) as usize;
            DagCluster {
                group,
                own_group,
                positions: (0..v).map(|_| [next(4000) as i32, next(4000) as i32, next(50) as i32]).collect(),
                normals: (0..v).map(|_| [0.0, 0.6, 0.8]).collect(),
                uvs: (0..v).map(|_| [next(1000) as f32 / 1000.0, 0.5]).collect(),
                indices: (0..t)
                    .flat_map(|k| {
                        // Three distinct corners (the codec keeps no degenerate triangle);
                        // the first triangles use every vertex.
                        if 3 * k + 2 < v {
                            return [3 * k, 3 * k + 1, 3 * k + 2].map(|i| i as u8);
                        }
                        let a = next(v as u32);
                        let b = (a + 1 + next(v as u32 - 1)) % v as u32;
                        let c = (a + next(v as u32)..).map(|c| c % v as u32).find(|&c| c != a && c != b).unwrap_or(0);
                        [a, b, c].map(|i| i as u8)
                    })
                    .collect(),
                materials: (0..t).map(|_| next(3) as u16).collect(),
                open_edges: Vec::new(),
            }
        };
        let mut clusters: Vec<DagCluster> = (0..n).map(|g| cluster(g, NO_GROUP, &mut next)).collect();
        let coarse: Vec<DagCluster> = (0..n).map(|g| cluster(n, g, &mut next)).collect();
        for g in 0..n as usize {
            let (v, w) = (clusters[g].positions.len(), coarse[g].positions.len());
            for k in 0..v.min(w) / (1 + next(3) as usize) {
                let (from, to) = (next(w as u32) as usize, next(v as u32) as usize);
                clusters[g].positions[to] = coarse[g].positions[from];
                clusters[g].uvs[to] = coarse[g].uvs[from];
                if g > 0 && k % 4 == 0 {
                    let before = &clusters[g - 1];
                    let at = next(before.positions.len() as u32) as usize;
                    let (p, uv) = (before.positions[at], before.uvs[at]);
                    (clusters[g].positions[to], clusters[g].uvs[to]) = (p, uv);
                }
            }
        }
        clusters.extend(coarse);
        let sphere = Sphere { center: [1.0; 3], radius: 2.0 };
        let group = |error, level| Group { sphere, error, level, first_cluster: 0, cluster_count: 0, page: 0 };
        let mut groups: Vec<Group> = (0..n).map(|_| group(0.01, 0)).collect();
        groups.push(group(f32::INFINITY, 1));
        let uv = UvQuant { min: [0.0; 2], extent: [1.0; 2] };
        let flags = FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS;
        let grid = Grid { origin: [0.0; 3], step: 0.001 };
        let header =
            Header { flags, grid, uv, normal_bits: 10, position_bits: 16, level_count: 0, source_triangles: 0 };
        Dag { header, groups, clusters }
    }

    /// Any pagination writes and reads in every coding: for pseudo-random DAGs cut into
    /// pseudo-random runs of groups, the compact (far copies), independent and layout files
    /// decode to the same GPU layouts, page by page, and `rewrite` turns each into the others
    /// byte for byte.
    #[test]
    fn any_pagination_round_trips_in_every_coding() {
        let mut copying = 0;
        for seed in 0..24u64 {
            let greedy =
                MresFile::parse(write_mres(&shared_vertex_dag(6 + seed as u32 % 7, seed), 3).unwrap()).unwrap();
            let n = greedy.groups.len() as u32;
            let mut state = seed;
            let mut kept = Vec::new();
            while kept.iter().sum::<u32>() < n {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let left = n - kept.iter().sum::<u32>();
                kept.push(1 + ((state >> 33) as u32) % left.min(4));
            }
            let files: Vec<Vec<u8>> = [PageCoding::FarCopies, PageCoding::Independent, PageCoding::Layout]
                .iter()
                .map(|&coding| {
                    rewrite_paged(&greedy, (3, coding), &kept)
                        .unwrap_or_else(|e| panic!("seed {seed}, {coding:?}: {e}"))
                })
                .collect();
            copying += (files[0].len() < files[1].len()) as usize; // far copies made it smaller
            let read: Vec<MresFile> = files.iter().map(|f| MresFile::parse(f.clone()).unwrap()).collect();
            for p in 0..kept.len() as u32 {
                let layout = read[0].page(p).unwrap();
                assert!(read[1..].iter().all(|r| r.page(p).unwrap() == layout), "seed {seed}, page {p}");
            }
            assert_eq!(read[0].decode_all().unwrap(), greedy.decode_all().unwrap(), "seed {seed}");
            for (from, f) in read.iter().enumerate() {
                for (to, coding) in
                    [PageCoding::FarCopies, PageCoding::Independent, PageCoding::Layout].into_iter().enumerate()
                {
                    assert_eq!(rewrite(f, 3, coding).unwrap(), files[to], "seed {seed}: {from} → {to}");
                }
            }
        }
        assert!(copying >= 12, "far copies in only {copying} of 24 files");
    }

    /// A layout page may hold more clusters than a compact page can (its counts' `E_max` over
    /// the 32 MiB readers accept of a compact page): repacked to compact, such a page is
    /// refilled instead of kept (which would write a page every reader refuses).
    #[test]
    fn kept_pages_over_the_compact_limit_are_refilled() {
        let n = 5300u32;
        let mut state = 7u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        let mut cluster = |group: u32, own_group: u32| DagCluster {
            group,
            own_group,
            // Few position bits: a small layout, while `E_max` counts 12 bytes a vertex.
            positions: (0..255).map(|_| [(next() % 4) as i32, (next() % 4) as i32, (next() % 4) as i32]).collect(),
            normals: vec![[0.0, 0.6, 0.8]; 255],
            uvs: (0..255).map(|_| [(next() % 1000) as f32 / 1000.0, 0.5]).collect(),
            indices: (0..128u32).flat_map(|t| [t, t + 1, t + 2].map(|i| (i * 2 % 255) as u8)).collect(),
            materials: Vec::new(),
            open_edges: Vec::new(),
        };
        // Coarse to fine already (the root group first), so that pages can be kept.
        let mut clusters = vec![cluster(0, 1)];
        clusters.extend((1..=n).map(|g| cluster(g, NO_GROUP)));
        let sphere = Sphere { center: [1.0; 3], radius: 2.0 };
        let group = |error, level| Group { sphere, error, level, first_cluster: 0, cluster_count: 0, page: 0 };
        let mut groups = vec![group(f32::INFINITY, 1)];
        groups.extend((0..n).map(|_| group(0.01, 0)));
        let uv = UvQuant { min: [0.0; 2], extent: [1.0; 2] };
        let grid = Grid { origin: [0.0; 3], step: 1e-6 };
        let flags = FLAG_NORMALS | FLAG_UVS;
        let header =
            Header { flags, grid, uv, normal_bits: 10, position_bits: 20, level_count: 0, source_triangles: 0 };
        let dag = Dag { header, groups, clusters };
        let encoded = dag.clusters.iter().enumerate().map(|(i, c)| EncodedCluster::new(c, &dag.header, i).unwrap());
        let one_page = [1, n];
        let layout = write_paged(&dag.header, &dag.groups, encoded.collect(), (3, PageCoding::Layout), Some(&one_page));
        let layout = MresFile::parse(layout.unwrap()).unwrap();
        let records = &layout.clusters[1..];
        assert_eq!(layout.pages.len(), 2, "the level-0 groups in one layout page");
        assert!(codec::max_encoded_len(flags, records) > MAX_PAGE_ENCODED_SIZE, "a page over the compact limit");
        let compact = MresFile::parse(rewrite(&layout, 3, PageCoding::Independent).unwrap()).unwrap();
        assert!(compact.pages.len() > 2, "refilled");
        compact.decode_all().unwrap();
        // Asked again for the one page, the writer refills it too.
        let again = MresFile::parse(rewrite_paged(&compact, (3, PageCoding::FarCopies), &[1, n]).unwrap()).unwrap();
        assert_eq!(again.pages.len(), compact.pages.len());
    }
}
