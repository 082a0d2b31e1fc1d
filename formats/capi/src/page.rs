//! The page handle: decoding a page from bytes the caller fetched, its GPU-layout bytes, and
//! each cluster's decoded arrays copied into caller buffers.

use crate::ffi::{call, copy_out, get, put, room, Failure, MresStatus, Outcome};
use crate::index::MresIndex;
use mres_format::{DecodedCluster, Grid, Page};

/// One decoded page: its bytes in the GPU layout and its clusters decoded.
///
/// Opaque. Created by `mres_page_decode`, freed by `mres_page_free`. It owns all its data (it
/// does not borrow the index or the input bytes) and is immutable: any number of threads may
/// read one page at the same time.
pub struct MresPage {
    page: Page,
    /// The file's position grid, to decode positions to floats.
    grid: Grid,
}

impl MresPage {
    /// Cluster `cluster` (a file-wide index) of this page.
    fn cluster(&self, cluster: u32) -> Result<&DecodedCluster, Failure> {
        let first = self.page.first_cluster;
        cluster.checked_sub(first).and_then(|i| self.page.clusters.get(i as usize)).ok_or_else(|| {
            let end = first as usize + self.page.clusters.len();
            Failure::arg(format!("cluster {cluster} is not in page {} (clusters {first}..{end})", self.page.index))
        })
    }
}

/// Checks `len` bytes at `bytes` (the caller's fetch of `mres_page_range(index, page)`)
/// against page `page`'s table entry (length, then BLAKE3 checksum), decompresses them and
/// decodes and checks every cluster. On success stores a new page in `*out`; on failure
/// stores null there (when `out` is not null).
///
/// `sources` is an array of `source_count` pages decoded before from the same file: the
/// page's sources (`mres_page_sources`, in that order), whose vertices the page may copy
/// (docs/FORMAT.md §4.3). Pages are stored coarse to fine and a page's sources come before
/// it, so a caller decoding in file order has them. Null with `source_count` 0 passes none:
/// enough for a page that copies nothing from its sources.
///
/// Fails with `MRES_ERR_PAGE_LENGTH` when `len` is not the page's compressed size,
/// `MRES_ERR_CHECKSUM` when the bytes are damaged, `MRES_ERR_CORRUPT` when they decode to
/// something inconsistent, `MRES_ERR_ARG` when `sources` are not the page's sources (or are
/// needed and missing). The library keeps no pointer into `bytes` or `sources`.
///
/// # Safety
/// `index` must be a live index; `bytes` must point to `len` readable bytes; `sources` to
/// `source_count` live pages (or be null with `source_count` 0); `out` must be valid for a
/// write.
#[no_mangle]
pub unsafe extern "C" fn mres_page_decode(
    index: *const MresIndex,
    page: u32,
    bytes: *const u8,
    len: usize,
    sources: *const *const MresPage,
    source_count: usize,
    out: *mut *mut MresPage,
) -> MresStatus {
    if !out.is_null() {
        // SAFETY: `out` is non-null and writable (the caller's contract).
        unsafe { out.write(std::ptr::null_mut()) };
    }
    call("mres_page_decode", || {
        // SAFETY: the caller's contract, as documented.
        let (index, compressed) = unsafe { (&get(index, "index")?.inner, crate::ffi::bytes(bytes, len, "bytes")?) };
        if out.is_null() {
            return Err(Failure::arg("out is null"));
        }
        crate::index::item(&index.pages, page, "page")?;
        // SAFETY: the caller's contract, as documented.
        let layouts = unsafe { source_layouts(index, page, sources, source_count)? };
        let decoded = MresPage { page: index.decode_page(page, compressed, &layouts)?, grid: index.header.grid };
        // SAFETY: as above; the box is freed by `mres_page_free`.
        unsafe { put(out, "out", Box::into_raw(Box::new(decoded))) }
    })
}

/// Checks `len` bytes at `bytes` (the caller's fetch of `mres_page_range(index, page)`) and
/// writes the page's GPU layout (docs/FORMAT.md §5, the bytes `mres_page_bytes` gives) to
/// `out`, without decoding its clusters into arrays: the path for a streamer that uploads
/// pages. The bytes are checked as `mres_page_decode` checks them (length, BLAKE3, the
/// encoding), but for layout pages (`MRES_FLAG_LAYOUT_PAGES`) only what a renderer relies on
/// (docs/FORMAT.md §4.4's list: counts, block places, indices in range, zero padding), not
/// the rest of the canonical form, which needs every value unpacked (`mres_page_decode` and
/// the validators check it). Layout pages take this path at over a gigabyte of layout per
/// second per core.
///
/// The layout is `raw_size` bytes (`mres_index_page`); `*count` receives that. With `out` null
/// and `cap` 0 nothing is decoded (a size query); a `cap` below it gives
/// `MRES_ERR_BUFFER_TOO_SMALL`, before anything is decoded.
///
/// `sources` and `source_lens` are arrays of `source_count` entries: the GPU layouts of the
/// page's sources (`mres_page_sources`, in that order; each what this function or
/// `mres_page_bytes` gave for that page) and their lengths. Null with `source_count` 0
/// passes none: enough for a page that copies nothing from its sources, and for every page of
/// a file with layout pages. Errors as for `mres_page_decode`. The library keeps no pointer
/// into `bytes`, `sources` or `out`.
///
/// # Safety
/// `index` must be a live index; `bytes` must point to `len` readable bytes; `sources` and
/// `source_lens` to `source_count` entries each (or be null with `source_count` 0), each
/// source to its length in readable bytes; `out` to `cap` writable bytes (or be null with
/// `cap` 0); `count` must be valid for a write.
#[no_mangle]
#[allow(clippy::too_many_arguments)] // A C signature: the buffers travel as pointer and length.
pub unsafe extern "C" fn mres_page_layout(
    index: *const MresIndex,
    page: u32,
    bytes: *const u8,
    len: usize,
    sources: *const *const u8,
    source_lens: *const usize,
    source_count: usize,
    out: *mut u8,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    call("mres_page_layout", || {
        // SAFETY: the caller's contract, as documented.
        let (index, compressed) = unsafe { (&get(index, "index")?.inner, crate::ffi::bytes(bytes, len, "bytes")?) };
        let raw_size = crate::index::item(&index.pages, page, "page")?.raw_size as usize;
        // The size and the room for it, before anything is decoded.
        // SAFETY: the caller's contract, as documented.
        if !unsafe { room(raw_size, out, cap, count)? } {
            return Ok(());
        }
        // SAFETY: the caller's contract, as documented.
        let layouts = unsafe { raw_sources(sources, source_lens, source_count)? };
        let layout = index.page_layout(page, compressed, &layouts)?;
        // SAFETY: as above.
        unsafe { copy_out(&layout, out, cap, count) }
    })
}

/// The GPU layouts of the `count` pages at `sources`, each checked to be the page's source of
/// its place (so that a wrong page is named, not only found too short).
///
/// # Safety
/// As for `mres_page_decode`'s `sources`.
unsafe fn source_layouts<'a>(
    index: &mres_format::MresIndex,
    page: u32,
    sources: *const *const MresPage,
    count: usize,
) -> Result<Vec<&'a [u8]>, Failure> {
    if count == 0 {
        return Ok(Vec::new());
    }
    if sources.is_null() {
        return Err(Failure::arg("sources is null"));
    }
    // SAFETY: `sources` points to `count` handles (the caller's contract).
    let handles = unsafe { std::slice::from_raw_parts(sources, count) };
    let expected = index.page_sources(page)?;
    let mut out = Vec::with_capacity(count);
    for (i, &h) in handles.iter().enumerate() {
        // SAFETY: each handle is a live page or null (the caller's contract).
        let source = unsafe { get(h, "a source")? };
        if expected.get(i) != Some(&source.page.index) {
            return Err(Failure::arg(format!(
                "source {i} is page {}; page {page}'s sources are {expected:?}",
                source.page.index
            )));
        }
        out.push(source.page.bytes.as_slice());
    }
    Ok(out)
}

/// The `count` source layouts at `sources`, of the lengths at `lens`.
///
/// # Safety
/// As for `mres_page_layout`'s `sources` and `source_lens`.
unsafe fn raw_sources<'a>(
    sources: *const *const u8,
    lens: *const usize,
    count: usize,
) -> Result<Vec<&'a [u8]>, Failure> {
    if count == 0 {
        return Ok(Vec::new());
    }
    if sources.is_null() || lens.is_null() {
        return Err(Failure::arg("sources or source_lens is null"));
    }
    // SAFETY: both point to `count` entries (the caller's contract).
    let (pointers, lens) =
        unsafe { (std::slice::from_raw_parts(sources, count), std::slice::from_raw_parts(lens, count)) };
    // SAFETY: each points to its length in readable bytes (the caller's contract).
    pointers
        .iter()
        .zip(lens)
        .enumerate()
        .map(|(i, (&p, &n))| unsafe { crate::ffi::bytes(p, n, &format!("source {i}")) })
        .collect()
}

/// Frees a page. Null is allowed (nothing happens). Pointers from `mres_page_bytes` dangle
/// afterwards.
///
/// # Safety
/// `page` must be null or a page from `mres_page_decode` not yet freed, that no other thread
/// is using.
#[no_mangle]
pub unsafe extern "C" fn mres_page_free(page: *mut MresPage) {
    if !page.is_null() {
        // SAFETY: the caller's contract: the pointer came from `Box::into_raw` in
        // `mres_page_decode` and is freed once.
        drop(unsafe { Box::from_raw(page) });
    }
}

/// The decompressed page in the GPU layout (docs/FORMAT.md §5: cluster headers, then the
/// data blocks at the headers' offsets), to upload as is: stores a pointer to its first byte
/// in `*data` and its length (the page's `raw_size`) in `*len`.
///
/// The bytes belong to the page: valid, unchanged, until `mres_page_free(page)`.
///
/// # Safety
/// `page` must be a live page; `data` and `len` valid for writes.
#[no_mangle]
pub unsafe extern "C" fn mres_page_bytes(page: *const MresPage, data: *mut *const u8, len: *mut usize) -> MresStatus {
    call("mres_page_bytes", || {
        // SAFETY: the caller's contract, as documented.
        let page = unsafe { get(page, "page")? };
        let raw = &page.page.bytes;
        // SAFETY: as above.
        unsafe {
            put(data, "data", raw.as_ptr())?;
            put(len, "len", raw.len())
        }
    })
}

/// The page's clusters: file-wide indices `*first_cluster .. *first_cluster + *cluster_count`,
/// the ones the per-cluster functions below accept for this page.
///
/// # Safety
/// `page` must be a live page; `first_cluster` and `cluster_count` valid for writes.
#[no_mangle]
pub unsafe extern "C" fn mres_page_clusters(
    page: *const MresPage,
    first_cluster: *mut u32,
    cluster_count: *mut u32,
) -> MresStatus {
    call("mres_page_clusters", || {
        // SAFETY: the caller's contract, as documented.
        let page = unsafe { &get(page, "page")?.page };
        // SAFETY: as above.
        unsafe {
            put(first_cluster, "first_cluster", page.first_cluster)?;
            put(cluster_count, "cluster_count", page.clusters.len() as u32)
        }
    })
}

/// Runs `f` on cluster `cluster` of `page` and copies the array it returns into the caller's
/// buffer: the shared body of the per-cluster functions.
///
/// # Safety
/// `page` a live page or null; `out`, `cap`, `count` as for [`copy_out`].
unsafe fn cluster_array<T: Copy>(
    name: &str,
    page: *const MresPage,
    cluster: u32,
    (out, cap, count): (*mut T, usize, *mut usize),
    f: impl FnOnce(&MresPage, &DecodedCluster) -> Vec<T>,
) -> MresStatus {
    call(name, || -> Outcome {
        // SAFETY: the caller's contract.
        let page = unsafe { get(page, "page")? };
        let values = f(page, page.cluster(cluster)?);
        // SAFETY: the caller's contract.
        unsafe { copy_out(&values, out, cap, count) }
    })
}

/// Copies cluster `cluster`'s vertex positions on the global grid, three `int32_t` per
/// vertex (x, y, z), into `out`; stores the number of `int32_t` values in `*count`.
///
/// Every per-cluster function shares these rules: `cluster` is a file-wide index within
/// `mres_page_clusters`; `cap` and `*count` count elements of the pointed-to type (here
/// `int32_t`, not vertices); `out` null with `cap` 0 asks for the count alone; a `cap` below
/// the count gives `MRES_ERR_BUFFER_TOO_SMALL` with `*count` set. No cluster needs more than
/// 3 * 256 (positions, normals) or 3 * 128 (indices) elements.
///
/// # Safety
/// `page` must be a live page; `out` valid for writes of `cap` elements (or null with `cap`
/// 0); `count` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn mres_page_cluster_positions(
    page: *const MresPage,
    cluster: u32,
    out: *mut i32,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    // SAFETY: the caller's contract, as documented.
    unsafe {
        cluster_array("mres_page_cluster_positions", page, cluster, (out, cap, count), |_, c| {
            c.positions.as_flattened().to_vec()
        })
    }
}

/// Copies cluster `cluster`'s vertex positions in object space, three floats per vertex,
/// decoded from the grid by the exact f32 formula of docs/FORMAT.md §5.3 (so a vertex shared
/// by two clusters decodes to the same bits). Rules as for `mres_page_cluster_positions`.
///
/// # Safety
/// As for `mres_page_cluster_positions`.
#[no_mangle]
pub unsafe extern "C" fn mres_page_cluster_positions_f32(
    page: *const MresPage,
    cluster: u32,
    out: *mut f32,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    // SAFETY: the caller's contract, as documented.
    unsafe {
        cluster_array("mres_page_cluster_positions_f32", page, cluster, (out, cap, count), |p, c| {
            c.positions.iter().flat_map(|&q| p.grid.decode(q)).collect()
        })
    }
}

/// Copies cluster `cluster`'s triangle indices, three local vertex indices (`uint8_t`, below
/// the vertex count) per triangle. Rules as for `mres_page_cluster_positions`.
///
/// # Safety
/// As for `mres_page_cluster_positions`.
#[no_mangle]
pub unsafe extern "C" fn mres_page_cluster_indices(
    page: *const MresPage,
    cluster: u32,
    out: *mut u8,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    // SAFETY: the caller's contract, as documented.
    unsafe { cluster_array("mres_page_cluster_indices", page, cluster, (out, cap, count), |_, c| c.indices.clone()) }
}

/// Copies cluster `cluster`'s unit normals, three floats per vertex; none (count 0) when the
/// file lacks `MRES_FLAG_NORMALS`. Rules as for `mres_page_cluster_positions`.
///
/// # Safety
/// As for `mres_page_cluster_positions`.
#[no_mangle]
pub unsafe extern "C" fn mres_page_cluster_normals(
    page: *const MresPage,
    cluster: u32,
    out: *mut f32,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    // SAFETY: the caller's contract, as documented.
    unsafe {
        cluster_array("mres_page_cluster_normals", page, cluster, (out, cap, count), |_, c| {
            c.normals.as_flattened().to_vec()
        })
    }
}

/// Copies cluster `cluster`'s UVs, two floats (u, v) per vertex, decoded; none when the file
/// lacks `MRES_FLAG_UVS`. Rules as for `mres_page_cluster_positions`.
///
/// # Safety
/// As for `mres_page_cluster_positions`.
#[no_mangle]
pub unsafe extern "C" fn mres_page_cluster_uvs(
    page: *const MresPage,
    cluster: u32,
    out: *mut f32,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    // SAFETY: the caller's contract, as documented.
    unsafe {
        cluster_array("mres_page_cluster_uvs", page, cluster, (out, cap, count), |_, c| c.uvs.as_flattened().to_vec())
    }
}

/// Copies cluster `cluster`'s materials, one `uint16_t` per triangle; none when the file
/// lacks `MRES_FLAG_MATERIALS`. Rules as for `mres_page_cluster_positions`.
///
/// # Safety
/// As for `mres_page_cluster_positions`.
#[no_mangle]
pub unsafe extern "C" fn mres_page_cluster_materials(
    page: *const MresPage,
    cluster: u32,
    out: *mut u16,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    // SAFETY: the caller's contract, as documented.
    unsafe {
        cluster_array("mres_page_cluster_materials", page, cluster, (out, cap, count), |_, c| c.materials.clone())
    }
}

/// Copies cluster `cluster`'s open-edge marks, one `uint8_t` per triangle: bit k set when the
/// edge from corner k to corner (k + 1) mod 3 lies on the cut's open border
/// (docs/FORMAT.md §5.7); all zero when the cluster has no open edge. Rules as for
/// `mres_page_cluster_positions`.
///
/// # Safety
/// As for `mres_page_cluster_positions`.
#[no_mangle]
pub unsafe extern "C" fn mres_page_cluster_open_edges(
    page: *const MresPage,
    cluster: u32,
    out: *mut u8,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    // SAFETY: the caller's contract, as documented.
    unsafe {
        cluster_array("mres_page_cluster_open_edges", page, cluster, (out, cap, count), |_, c| c.open_edges.clone())
    }
}
