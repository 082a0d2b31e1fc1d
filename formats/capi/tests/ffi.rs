//! The C ABI called from Rust: every status code a caller can meet, the buffer and null-pointer
//! rules, and the records against `mres_format`'s own reader.

mod common;

use mres::*;
use mres_format::records::HeaderRecord;
use mres_format::{MresIndex as RustIndex, HEADER_SIZE};
use std::ffi::CStr;
use std::ptr::{null, null_mut};

fn last_error() -> String {
    // SAFETY: the library returns a valid C string.
    unsafe { CStr::from_ptr(mres_last_error_message()) }.to_string_lossy().into_owned()
}

fn open(prefix: &[u8]) -> Result<*mut MresIndex, MresStatus> {
    let mut index = null_mut();
    // SAFETY: valid slice and output.
    match unsafe { mres_index_open(prefix.as_ptr(), prefix.len(), &mut index) } {
        MresStatus::MRES_OK => Ok(index),
        status => {
            assert!(index.is_null(), "a failed open leaves null in *out");
            Err(status)
        }
    }
}

fn decode(index: *const MresIndex, page: u32, bytes: &[u8]) -> Result<*mut MresPage, MresStatus> {
    decode_with(index, page, bytes, &[])
}

/// Decodes page `page` given the pages `sources` (live handles) as its sources.
fn decode_with(
    index: *const MresIndex,
    page: u32,
    bytes: &[u8],
    sources: &[*mut MresPage],
) -> Result<*mut MresPage, MresStatus> {
    let mut out = null_mut();
    let sources: Vec<*const MresPage> = sources.iter().map(|&s| s as *const MresPage).collect();
    // SAFETY: valid pointers.
    match unsafe {
        mres_page_decode(index, page, bytes.as_ptr(), bytes.len(), sources.as_ptr(), sources.len(), &mut out)
    } {
        MresStatus::MRES_OK => Ok(out),
        status => {
            assert!(out.is_null());
            Err(status)
        }
    }
}

fn page_bytes(file: &[u8], rust: &RustIndex, p: u32) -> Vec<u8> {
    let r = rust.page_range(p).unwrap();
    file[r.start as usize..r.end as usize].to_vec()
}

/// Page `p`'s sources through the C ABI.
fn sources_of(index: *const MresIndex, p: u32) -> Vec<u32> {
    let mut sources = [0u32; 64];
    let mut n = 0;
    // SAFETY: valid pointers and lengths.
    assert_eq!(
        unsafe { mres_page_sources(index, p, sources.as_mut_ptr(), sources.len(), &mut n) },
        MresStatus::MRES_OK
    );
    sources[..n].to_vec()
}

/// Every page decoded in file order, each given its sources decoded before it.
fn decode_in_order(index: *const MresIndex, file: &[u8], rust: &RustIndex) -> Vec<*mut MresPage> {
    let mut pages: Vec<*mut MresPage> = Vec::new();
    for p in 0..rust.pages.len() as u32 {
        let sources: Vec<*mut MresPage> = sources_of(index, p).iter().map(|&s| pages[s as usize]).collect();
        pages.push(decode_with(index, p, &page_bytes(file, rust, p), &sources).unwrap());
    }
    pages
}

fn free_all(pages: Vec<*mut MresPage>) {
    for page in pages {
        // SAFETY: from mres_page_decode, freed once.
        unsafe { mres_page_free(page) };
    }
}

#[test]
fn pages_take_their_sources() {
    let file = common::file();
    let rust = RustIndex::parse(&file).unwrap();
    let index = open(&file).unwrap();
    let pages = decode_in_order(index, &file, &rust);
    let mut needing = 0;
    for p in 0..rust.pages.len() as u32 {
        let sources = sources_of(index, p);
        assert_eq!(sources, rust.page_sources(p).unwrap());
        let bytes = page_bytes(&file, &rust, p);
        let handles: Vec<*mut MresPage> = sources.iter().map(|&s| pages[s as usize]).collect();
        if sources.is_empty() {
            continue;
        }
        // Too many sources, another page in a source's place, or none at all when the page
        // copies from them: argument errors.
        let mut more = handles.clone();
        more.push(handles[0]);
        assert_eq!(decode_with(index, p, &bytes, &more), Err(MresStatus::MRES_ERR_ARG));
        let mut wrong = handles.clone();
        wrong[0] = pages[p as usize];
        assert_eq!(decode_with(index, p, &bytes, &wrong), Err(MresStatus::MRES_ERR_ARG));
        assert!(last_error().contains("sources are"), "{}", last_error());
        match decode(index, p, &bytes) {
            Ok(page) => free_all(vec![page]),
            Err(status) => {
                assert_eq!(status, MresStatus::MRES_ERR_ARG);
                needing += 1;
            }
        }
    }
    assert!(needing > 0, "no page of the test file copies from its sources");
    free_all(pages);
    // SAFETY: from mres_index_open.
    unsafe { mres_index_free(index) };
}

#[test]
fn prefix_len_asks_for_the_header_then_gives_the_prefix() {
    let file = common::file();
    let mut n = 0u64;
    // SAFETY: valid slices and outputs throughout.
    unsafe {
        assert_eq!(mres_prefix_len(file.as_ptr(), HEADER_SIZE - 1, &mut n), MresStatus::MRES_ERR_TRUNCATED);
        assert_eq!(n, HEADER_SIZE as u64, "a short start says how many bytes are needed");
        assert_eq!(mres_prefix_len(null(), 0, &mut n), MresStatus::MRES_ERR_TRUNCATED);
        assert_eq!(mres_header_size(), HEADER_SIZE);
        assert_eq!(mres_prefix_len(file.as_ptr(), HEADER_SIZE, &mut n), MresStatus::MRES_OK);
        assert_eq!(n, RustIndex::prefix_len(&file).unwrap());
        assert_eq!(mres_prefix_len(file.as_ptr(), HEADER_SIZE, null_mut()), MresStatus::MRES_ERR_ARG);
        assert_eq!(mres_prefix_len(null(), 5, &mut n), MresStatus::MRES_ERR_ARG);
    }
    assert!(last_error().starts_with("mres_prefix_len: start is null"), "{}", last_error());
}

#[test]
fn a_damaged_prefix_gives_its_status() {
    let file = common::file();
    let prefix_len = RustIndex::prefix_len(&file).unwrap() as usize;
    assert_eq!(open(&file[..prefix_len - 1]), Err(MresStatus::MRES_ERR_TRUNCATED));
    assert!(last_error().starts_with("mres_index_open: truncated"), "{}", last_error());
    let damaged = |offset: usize, value: u8| {
        let mut bytes = file[..prefix_len].to_vec();
        bytes[offset] = value;
        open(&bytes)
    };
    assert_eq!(damaged(0, b'X'), Err(MresStatus::MRES_ERR_BAD_MAGIC));
    assert_eq!(damaged(HeaderRecord::VERSION, 99), Err(MresStatus::MRES_ERR_VERSION));
    // header_size is checked before the checksum: a wrong one is a corrupt header.
    assert_eq!(damaged(HeaderRecord::HEADER_SIZE, 161), Err(MresStatus::MRES_ERR_CORRUPT));
    assert_eq!(damaged(prefix_len - 1, file[prefix_len - 1] ^ 1), Err(MresStatus::MRES_ERR_CHECKSUM));
    // SAFETY: checks the null output.
    assert_eq!(unsafe { mres_index_open(file.as_ptr(), prefix_len, null_mut()) }, MresStatus::MRES_ERR_ARG);
    let index = open(&file[..prefix_len]).expect("the prefix alone opens");
    // SAFETY: from mres_index_open.
    unsafe { mres_index_free(index) };
    // SAFETY: null is allowed.
    unsafe { mres_index_free(null_mut()) };
}

#[test]
fn records_match_the_rust_reader() {
    let file = common::file();
    let rust = RustIndex::parse(&file).unwrap();
    let index = open(&file).unwrap();
    // SAFETY: a live index and valid outputs throughout.
    unsafe {
        let mut info = MresInfo::default();
        assert_eq!(mres_index_info(index, &mut info), MresStatus::MRES_OK);
        assert_eq!((info.group_count, info.cluster_count), (rust.groups.len() as u32, rust.clusters.len() as u32));
        assert_eq!((info.page_count, info.level_count), (rust.pages.len() as u32, rust.header.level_count));
        assert_eq!(
            (info.flags, info.grid_origin, info.grid_step),
            (rust.header.flags, rust.header.grid.origin, rust.header.grid.step)
        );
        assert_eq!((info.uv_min, info.uv_extent), (rust.header.uv.min, rust.header.uv.extent));
        assert_eq!((info.source_triangles, info.file_size), (rust.header.source_triangles, file.len() as u64));
        for (g, want) in rust.groups.iter().enumerate() {
            let mut got = MresGroup::default();
            assert_eq!(mres_index_group(index, g as u32, &mut got), MresStatus::MRES_OK);
            assert_eq!((got.center, got.radius, got.error), (want.sphere.center, want.sphere.radius, want.error));
            assert_eq!(
                [got.level, got.first_cluster, got.cluster_count, got.page],
                [want.level, want.first_cluster, want.cluster_count, want.page]
            );
        }
        for (c, want) in rust.clusters.iter().enumerate() {
            let mut got = MresCluster::default();
            assert_eq!(mres_index_cluster(index, c as u32, &mut got), MresStatus::MRES_OK);
            let counts = [u32::from(want.vertex_count), u32::from(want.triangle_count)];
            assert_eq!([got.group, got.own_group, got.page_offset], [want.group, want.own_group, want.page_offset]);
            assert_eq!([got.vertex_count, got.triangle_count], counts);
            assert_eq!(got.page, rust.groups[want.group as usize].page);
        }
        for (p, want) in rust.pages.iter().enumerate() {
            let mut got = MresPageInfo::default();
            assert_eq!(mres_index_page(index, p as u32, &mut got), MresStatus::MRES_OK);
            assert_eq!(
                (got.offset, got.compressed_size, got.raw_size),
                (want.offset, want.compressed_size, want.raw_size)
            );
            assert_eq!([got.first_cluster, got.cluster_count], [want.first_cluster, want.cluster_count]);
            assert_eq!([got.first_group, got.group_count], [want.first_group, want.group_count]);
            assert_eq!((got.dependency_count as usize, got.checksum), (want.dependencies.len(), want.checksum));
            let (mut offset, mut size) = (0, 0);
            assert_eq!(mres_page_range(index, p as u32, &mut offset, &mut size), MresStatus::MRES_OK);
            assert_eq!(offset..offset + size, rust.page_range(p as u32).unwrap());
            let mut deps = vec![u32::MAX; want.dependencies.len() + 1];
            let mut n = 0;
            assert_eq!(
                mres_page_dependencies(index, p as u32, deps.as_mut_ptr(), deps.len(), &mut n),
                MresStatus::MRES_OK
            );
            assert_eq!(&deps[..n], &want.dependencies[..]);
        }
        // Indices past the end are argument errors.
        let mut group = MresGroup::default();
        assert_eq!(mres_index_group(index, info.group_count, &mut group), MresStatus::MRES_ERR_ARG);
        assert!(last_error().contains(&format!("group {} does not exist", info.group_count)), "{}", last_error());
        let mut cluster = MresCluster::default();
        assert_eq!(mres_index_cluster(index, info.cluster_count, &mut cluster), MresStatus::MRES_ERR_ARG);
        let mut page = MresPageInfo::default();
        assert_eq!(mres_index_page(index, info.page_count, &mut page), MresStatus::MRES_ERR_ARG);
        let (mut offset, mut size) = (0, 0);
        assert_eq!(mres_page_range(index, info.page_count, &mut offset, &mut size), MresStatus::MRES_ERR_ARG);
        assert_eq!(mres_index_info(null(), &mut info), MresStatus::MRES_ERR_ARG);
        assert_eq!(mres_index_info(index, null_mut()), MresStatus::MRES_ERR_ARG);
        mres_index_free(index);
    }
}

#[test]
fn buffers_are_checked_and_sized() {
    let file = common::file();
    let rust = RustIndex::parse(&file).unwrap();
    let index = open(&file).unwrap();
    let p = (0..rust.pages.len()).find(|&p| !rust.pages[p].dependencies.is_empty()).expect("a page with dependencies");
    let want = rust.pages[p].dependencies.len();
    let mut deps = vec![0u32; want];
    let mut n = 0usize;
    // SAFETY: a live index; buffers of the lengths passed.
    unsafe {
        assert_eq!(mres_page_dependencies(index, p as u32, null_mut(), 0, &mut n), MresStatus::MRES_OK);
        assert_eq!(n, want, "a size query gives the count");
        n = 0;
        assert_eq!(
            mres_page_dependencies(index, p as u32, deps.as_mut_ptr(), want - 1, &mut n),
            MresStatus::MRES_ERR_BUFFER_TOO_SMALL
        );
        assert_eq!(n, want, "a short buffer still learns the count");
        assert_eq!(deps, vec![0; want], "nothing written into a short buffer");
        assert_eq!(mres_page_dependencies(index, p as u32, null_mut(), want, &mut n), MresStatus::MRES_ERR_ARG);
        assert_eq!(
            mres_page_dependencies(index, p as u32, deps.as_mut_ptr(), want, null_mut()),
            MresStatus::MRES_ERR_ARG
        );

        let bytes = page_bytes(&file, &rust, 0);
        let page = decode(index, 0, &bytes).unwrap();
        let c = rust.pages[0].first_cluster;
        let vertices = rust.clusters[c as usize].vertex_count as usize;
        let mut positions = vec![0i32; 3 * vertices];
        assert_eq!(
            mres_page_cluster_positions(page, c, positions.as_mut_ptr(), 3 * vertices - 1, &mut n),
            MresStatus::MRES_ERR_BUFFER_TOO_SMALL
        );
        assert_eq!(n, 3 * vertices);
        assert_eq!(
            mres_page_cluster_positions(page, c, positions.as_mut_ptr(), 3 * vertices, &mut n),
            MresStatus::MRES_OK
        );
        let decoded = rust.decode_page(0, &bytes, &[]).unwrap();
        assert_eq!(positions, decoded.clusters[0].positions.as_flattened());
        // A cluster of another page is an argument error, naming the page's range.
        let other = rust.pages[1].first_cluster;
        assert_eq!(
            mres_page_cluster_positions(page, other, positions.as_mut_ptr(), positions.len(), &mut n),
            MresStatus::MRES_ERR_ARG
        );
        assert!(last_error().contains(&format!("cluster {other} is not in page 0")), "{}", last_error());
        assert_eq!(mres_page_cluster_indices(null(), c, null_mut(), 0, &mut n), MresStatus::MRES_ERR_ARG);
        mres_page_free(page);
        mres_index_free(index);
    }
}

#[test]
fn pages_decode_from_fetched_bytes_only() {
    let file = common::file();
    let rust = RustIndex::parse(&file).unwrap();
    let prefix_len = RustIndex::prefix_len(&file).unwrap() as usize;
    let index = open(&file[..prefix_len]).unwrap();
    let mut pages: Vec<*mut MresPage> = Vec::new();
    let mut layouts: Vec<Vec<u8>> = Vec::new();
    for p in 0..rust.pages.len() as u32 {
        let bytes = page_bytes(&file, &rust, p);
        let sources = rust.page_sources(p).unwrap();
        let source_layouts: Vec<&[u8]> = sources.iter().map(|&s| layouts[s as usize].as_slice()).collect();
        let want = rust.decode_page(p, &bytes, &source_layouts).unwrap();
        layouts.push(want.bytes.clone());
        let handles: Vec<*mut MresPage> = sources.iter().map(|&s| pages[s as usize]).collect();
        let page = decode_with(index, p, &bytes, &handles).unwrap();
        pages.push(page);
        // SAFETY: a live page; outputs of the lengths passed.
        unsafe {
            let (mut data, mut len) = (null(), 0usize);
            assert_eq!(mres_page_bytes(page, &mut data, &mut len), MresStatus::MRES_OK);
            assert_eq!(std::slice::from_raw_parts(data, len), &want.bytes[..], "the GPU layout, as is");
            let (mut first, mut count) = (0u32, 0u32);
            assert_eq!(mres_page_clusters(page, &mut first, &mut count), MresStatus::MRES_OK);
            assert_eq!((first, count as usize), (want.first_cluster, want.clusters.len()));
            for (i, c) in want.clusters.iter().enumerate() {
                let id = first + i as u32;
                let mut f32s = [0f32; 3 * 256];
                let mut n = 0;
                assert_eq!(
                    mres_page_cluster_positions_f32(page, id, f32s.as_mut_ptr(), f32s.len(), &mut n),
                    MresStatus::MRES_OK
                );
                let decoded: Vec<f32> = c.positions.iter().flat_map(|&q| rust.header.grid.decode(q)).collect();
                assert_eq!(&f32s[..n], &decoded[..]);
                assert_eq!(
                    mres_page_cluster_normals(page, id, f32s.as_mut_ptr(), f32s.len(), &mut n),
                    MresStatus::MRES_OK
                );
                assert_eq!(&f32s[..n], c.normals.as_flattened());
                assert_eq!(mres_page_cluster_uvs(page, id, f32s.as_mut_ptr(), f32s.len(), &mut n), MresStatus::MRES_OK);
                assert_eq!(&f32s[..n], c.uvs.as_flattened());
                let mut u8s = [0u8; 3 * 128];
                assert_eq!(
                    mres_page_cluster_indices(page, id, u8s.as_mut_ptr(), u8s.len(), &mut n),
                    MresStatus::MRES_OK
                );
                assert_eq!(&u8s[..n], &c.indices[..]);
                assert_eq!(
                    mres_page_cluster_open_edges(page, id, u8s.as_mut_ptr(), u8s.len(), &mut n),
                    MresStatus::MRES_OK
                );
                assert_eq!(&u8s[..n], &c.open_edges[..]);
                let mut u16s = [0u16; 128];
                assert_eq!(
                    mres_page_cluster_materials(page, id, u16s.as_mut_ptr(), u16s.len(), &mut n),
                    MresStatus::MRES_OK
                );
                assert_eq!(&u16s[..n], &c.materials[..]);
            }
        }
    }
    free_all(pages);
    // SAFETY: from mres_index_open.
    unsafe { mres_index_free(index) };
}

#[test]
fn damaged_page_bytes_give_their_status() {
    let file = common::file();
    let rust = RustIndex::parse(&file).unwrap();
    let index = open(&file).unwrap();
    let bytes = page_bytes(&file, &rust, 1);
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 2] ^= 0x10;
    assert_eq!(decode(index, 1, &flipped), Err(MresStatus::MRES_ERR_CHECKSUM));
    assert_eq!(last_error(), "mres_page_decode: checksum mismatch in page 1");
    assert_eq!(decode(index, 1, &bytes[..bytes.len() - 1]), Err(MresStatus::MRES_ERR_PAGE_LENGTH));
    // Another page's bytes for page 1: wrong length, or (same length) wrong checksum.
    assert!(decode(index, 1, &page_bytes(&file, &rust, 0)).is_err());
    assert_eq!(decode(index, rust.pages.len() as u32, &bytes), Err(MresStatus::MRES_ERR_ARG));
    assert_eq!(decode(null(), 1, &bytes), Err(MresStatus::MRES_ERR_ARG));
    // SAFETY: checks the null input with a non-zero length.
    let mut out = null_mut();
    assert_eq!(
        unsafe { mres_page_decode(index, 1, null(), bytes.len(), null(), 0, &mut out) },
        MresStatus::MRES_ERR_ARG
    );
    // SAFETY: null is allowed.
    unsafe { mres_page_free(null_mut()) };
    let pages = decode_in_order(index, &file, &rust);
    let sources: Vec<*mut MresPage> = sources_of(index, 1).iter().map(|&s| pages[s as usize]).collect();
    let page = decode_with(index, 1, &bytes, &sources).expect("the undamaged bytes decode");
    free_all(pages);
    free_all(vec![page]);
    // SAFETY: from mres_index_open.
    unsafe { mres_index_free(index) };
}

#[test]
fn selection_matches_the_rust_rule() {
    let file = common::file();
    let rust = RustIndex::parse(&file).unwrap();
    let index = open(&file).unwrap();
    let mut cut = vec![0u32; rust.clusters.len()];
    let mut n = 0;
    let view = MresView { eye: [1.0, 1.5, 0.8], proj_y: 1.0, viewport_height: 1080.0, z_near: 0.01 };
    let rust_view = mres_format::ViewParams { eye: view.eye, proj_y: 1.0, viewport_height: 1080.0, z_near: 0.01 };
    // SAFETY: a live index; buffers of the lengths passed.
    unsafe {
        for error in [0.0, 0.0105, 1.0] {
            assert_eq!(mres_select_uniform(index, error, cut.as_mut_ptr(), cut.len(), &mut n), MresStatus::MRES_OK);
            assert_eq!(&cut[..n], mres_format::uniform_cut(&rust.groups, &rust.clusters, error));
        }
        let mut sizes = Vec::new();
        for tau in [0.5, 20.0, 1000.0] {
            assert_eq!(mres_select_view(index, &view, tau, cut.as_mut_ptr(), cut.len(), &mut n), MresStatus::MRES_OK);
            assert_eq!(&cut[..n], mres_format::view_cut(&rust.groups, &rust.clusters, &rust_view, tau));
            sizes.push(n);
        }
        assert!(sizes[0] > sizes[2], "a coarser threshold draws fewer clusters: {sizes:?}");
        assert_eq!(mres_select_view(index, null(), 1.0, cut.as_mut_ptr(), cut.len(), &mut n), MresStatus::MRES_ERR_ARG);
        mres_index_free(index);
    }
}

#[test]
fn one_index_serves_many_threads() {
    fn shareable<T: Send + Sync>() {}
    shareable::<mres_format::MresIndex>();
    shareable::<mres_format::Page>();
    let file = common::file();
    let rust = RustIndex::parse(&file).unwrap();
    let index = open(&file).unwrap() as usize;
    // The sources, decoded once and read by every thread at once.
    let pages: Vec<usize> =
        decode_in_order(index as *const MresIndex, &file, &rust).iter().map(|&p| p as usize).collect();
    std::thread::scope(|s| {
        for p in 0..rust.pages.len() as u32 {
            let bytes = page_bytes(&file, &rust, p);
            let sources: Vec<usize> = rust.page_sources(p).unwrap().iter().map(|&s| pages[s as usize]).collect();
            s.spawn(move || {
                let sources: Vec<*mut MresPage> = sources.iter().map(|&s| s as *mut MresPage).collect();
                let page = decode_with(index as *const MresIndex, p, &bytes, &sources).unwrap();
                // SAFETY: from mres_page_decode.
                unsafe { mres_page_free(page) };
                // A failure on this thread sets this thread's message only.
                assert_eq!(decode(index as *const MresIndex, p, &[]), Err(MresStatus::MRES_ERR_PAGE_LENGTH));
                assert!(last_error().starts_with(&format!("mres_page_decode: page {p}:")), "{}", last_error());
            });
        }
    });
    free_all(pages.iter().map(|&p| p as *mut MresPage).collect());
    // SAFETY: every thread is done with it.
    unsafe { mres_index_free(index as *mut MresIndex) };
}

/// Page `p`'s layout through `mres_page_layout`, given `sources` (layouts) as its sources.
fn layout_with(
    index: *const MresIndex,
    p: u32,
    bytes: &[u8],
    sources: &[&[u8]],
    cap: usize,
) -> Result<Vec<u8>, MresStatus> {
    let pointers: Vec<*const u8> = sources.iter().map(|s| s.as_ptr()).collect();
    let lens: Vec<usize> = sources.iter().map(|s| s.len()).collect();
    let mut out = vec![0u8; cap];
    let mut count = usize::MAX;
    // SAFETY: valid pointers and lengths.
    let status = unsafe {
        let (data, n) = (bytes.as_ptr(), bytes.len());
        mres_page_layout(
            index,
            p,
            data,
            n,
            pointers.as_ptr(),
            lens.as_ptr(),
            sources.len(),
            out.as_mut_ptr(),
            cap,
            &mut count,
        )
    };
    match status {
        MresStatus::MRES_OK => {
            out.truncate(count);
            Ok(out)
        }
        status => Err(status),
    }
}

/// `mres_page_layout` gives each page's layout as the Rust reader does, from the fetched bytes
/// and its sources' layouts; a size query decodes nothing, and a short buffer, wrong sources
/// and damaged bytes give their statuses.
#[test]
fn page_layouts_stream_without_handles() {
    let file = common::file();
    let rust = RustIndex::parse(&file).unwrap();
    let index = open(&file).unwrap();
    let mut layouts: Vec<Vec<u8>> = Vec::new();
    let mut checked_sources = 0;
    for p in 0..rust.pages.len() as u32 {
        let bytes = page_bytes(&file, &rust, p);
        let sources: Vec<&[u8]> = sources_of(index, p).iter().map(|&s| layouts[s as usize].as_slice()).collect();
        let raw_size = rust.pages[p as usize].raw_size as usize;
        let mut count = 0;
        // SAFETY: a size query: null output with capacity 0, and garbage page bytes (not read).
        assert_eq!(
            unsafe { mres_page_layout(index, p, null(), 0, null(), null(), 0, null_mut(), 0, &mut count) },
            MresStatus::MRES_OK
        );
        assert_eq!(count, raw_size);
        assert_eq!(layout_with(index, p, &bytes, &sources, raw_size - 1), Err(MresStatus::MRES_ERR_BUFFER_TOO_SMALL));
        // SAFETY: a null output with a capacity: refused before anything is decoded.
        let null_out =
            unsafe { mres_page_layout(index, p, null(), 0, null(), null(), 0, null_mut(), raw_size, &mut count) };
        assert_eq!(null_out, MresStatus::MRES_ERR_ARG);
        let layout = layout_with(index, p, &bytes, &sources, raw_size + 7).unwrap();
        assert_eq!(layout, rust.page_layout(p, &bytes, &sources).unwrap());
        if !sources.is_empty() {
            let mut more = sources.clone();
            more.push(sources[0]);
            assert_eq!(layout_with(index, p, &bytes, &more, raw_size), Err(MresStatus::MRES_ERR_ARG));
            checked_sources += 1;
        }
        let mut flipped = bytes.clone();
        flipped[bytes.len() / 2] ^= 0x10;
        assert_eq!(layout_with(index, p, &flipped, &sources, raw_size), Err(MresStatus::MRES_ERR_CHECKSUM));
        assert!(last_error().starts_with("mres_page_layout: checksum mismatch"), "{}", last_error());
        layouts.push(layout);
    }
    assert!(checked_sources > 0, "no page of the test file has sources");
    // SAFETY: from mres_index_open.
    unsafe { mres_index_free(index) };
}
