//! The index handle: opening the resident prefix and querying the header, hierarchy and page
//! table, plus the selection rule (docs/FORMAT.md §6) over it.

use crate::ffi::{bytes, call, copy_out, get, put, Failure, MresStatus};
use mres_format as format;

/// An opened index: the header, hierarchy and page table of one `.mres` file, checked.
///
/// Opaque. Created by `mres_index_open`, freed by `mres_index_free`. Immutable: any number of
/// threads may query one index, and decode pages against it, at the same time.
pub struct MresIndex {
    pub(crate) inner: format::MresIndex,
}

/// File-wide parameters and counts, from `mres_index_info`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MresInfo {
    /// Triangles of the source mesh (before welding and dropping degenerates).
    pub source_triangles: u64,
    /// Length of the whole file in bytes, as the page table implies.
    pub file_size: u64,
    /// Combination of `MRES_FLAG_NORMALS`, `MRES_FLAG_UVS`, `MRES_FLAG_MATERIALS`,
    /// `MRES_FLAG_LAYOUT_PAGES`.
    pub flags: u32,
    /// Groups in the hierarchy.
    pub group_count: u32,
    /// Clusters in the hierarchy.
    pub cluster_count: u32,
    /// Pages in the page table.
    pub page_count: u32,
    /// DAG levels (level 0 is the original geometry).
    pub level_count: u32,
    /// Bits per octahedral normal component (with `MRES_FLAG_NORMALS`).
    pub normal_bits: u32,
    /// Grid precision the file was baked with (bits along the largest extent).
    pub position_bits: u32,
    /// Object-space position of grid point (0, 0, 0).
    pub grid_origin: [f32; 3],
    /// Object-space distance between neighbouring grid points: a grid position `q` is
    /// `grid_origin[k] + (float)q[k] * grid_step` in f32 (docs/FORMAT.md §5.3).
    pub grid_step: f32,
    /// Smallest u and v of the mesh (with `MRES_FLAG_UVS`).
    pub uv_min: [f32; 2],
    /// Range of u and v (max - min).
    pub uv_extent: [f32; 2],
}

/// One group of the DAG, from `mres_index_group`: the clusters merged and simplified together.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MresGroup {
    /// Bounding sphere centre, object space.
    pub center: [f32; 3],
    /// Bounding sphere radius.
    pub radius: f32,
    /// Object-space simplification error (+infinity for the root).
    pub error: f32,
    /// DAG level of the member clusters.
    pub level: u32,
    /// First member cluster (members are contiguous).
    pub first_cluster: u32,
    /// Number of member clusters.
    pub cluster_count: u32,
    /// Page holding the member clusters.
    pub page: u32,
}

/// One cluster's resident record, from `mres_index_cluster`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MresCluster {
    /// The group the cluster belongs to (its parent pair in the selection rule).
    pub group: u32,
    /// The group whose simplification produced it, or `MRES_NO_GROUP` at level 0.
    pub own_group: u32,
    /// Page holding the cluster (its group's page).
    pub page: u32,
    /// Byte offset of the cluster's header within its decompressed page.
    pub page_offset: u32,
    /// Vertices (1..=256).
    pub vertex_count: u32,
    /// Triangles (1..=128).
    pub triangle_count: u32,
}

/// One page's entry in the page table, from `mres_index_page`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MresPageInfo {
    /// File offset of the page's compressed bytes.
    pub offset: u64,
    /// Length of the compressed bytes: fetch file bytes `[offset, offset + compressed_size)`.
    pub compressed_size: u32,
    /// Length of the decompressed page (the GPU layout) in bytes.
    pub raw_size: u32,
    /// First cluster in the page.
    pub first_cluster: u32,
    /// Clusters in the page.
    pub cluster_count: u32,
    /// First group in the page.
    pub first_group: u32,
    /// Groups in the page.
    pub group_count: u32,
    /// Pages that must be resident before this one is used (`mres_page_dependencies`).
    pub dependency_count: u32,
    /// BLAKE3 of the compressed bytes (`mres_page_decode` checks it).
    pub checksum: [u8; 32],
}

/// A camera for `mres_select_view`, as the selection rule sees it (docs/FORMAT.md §6).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MresView {
    /// Eye position, object space.
    pub eye: [f32; 3],
    /// `proj[1][1]` of the projection matrix (1 / tan(fov_y / 2)).
    pub proj_y: f32,
    /// Viewport height in pixels.
    pub viewport_height: f32,
    /// Near plane distance, object space (> 0); distances are clamped to it.
    pub z_near: f32,
}

/// Header flag: clusters carry normals.
pub const MRES_FLAG_NORMALS: u32 = 1;
/// Header flag: clusters carry UVs.
pub const MRES_FLAG_UVS: u32 = 2;
/// Header flag: clusters carry a material per triangle.
pub const MRES_FLAG_MATERIALS: u32 = 4;
/// Header flag: every page is stored as its GPU layout, one LZ4 block (docs/FORMAT.md §4.4):
/// `mres_page_layout` gives their layouts at memory speed, and they have no sources (each
/// decodes alone).
pub const MRES_FLAG_LAYOUT_PAGES: u32 = 8;
/// `MresCluster::own_group` of a level-0 cluster.
pub const MRES_NO_GROUP: u32 = 0xFFFF_FFFF;

// cbindgen writes the literals above into the header; these keep them equal to the format's.
const _: () = assert!(MRES_FLAG_NORMALS == format::FLAG_NORMALS);
const _: () = assert!(MRES_FLAG_UVS == format::FLAG_UVS);
const _: () = assert!(MRES_FLAG_MATERIALS == format::FLAG_MATERIALS);
const _: () = assert!(MRES_FLAG_LAYOUT_PAGES == format::FLAG_LAYOUT_PAGES);
const _: () = assert!(MRES_NO_GROUP == format::NO_GROUP);

/// The `.mres` format version this library reads (files of any other version give
/// `MRES_ERR_VERSION`).
#[no_mangle]
pub extern "C" fn mres_format_version() -> u32 {
    format::VERSION
}

/// The size of the fixed header: the fewest bytes from the start of the file that
/// `mres_prefix_len` needs.
#[no_mangle]
pub extern "C" fn mres_header_size() -> usize {
    format::HEADER_SIZE
}

/// How many bytes from the start of the file the index needs (the resident prefix: header,
/// hierarchy and page table), from the first `len` bytes of the file at `start`.
///
/// Pass at least `mres_header_size()` bytes (more is fine). With fewer, returns
/// `MRES_ERR_TRUNCATED` and stores the number of bytes needed in `*out`, so a caller may read
/// that many and call again. The header's fields are checked (magic, version, sizes).
///
/// # Safety
/// `start` must point to `len` readable bytes (or be null with `len` 0); `out` must be valid
/// for a write.
#[no_mangle]
pub unsafe extern "C" fn mres_prefix_len(start: *const u8, len: usize, out: *mut u64) -> MresStatus {
    call("mres_prefix_len", || {
        // SAFETY: the caller's contract, as documented.
        let start = unsafe { bytes(start, len, "start")? };
        match format::MresIndex::prefix_len(start) {
            // SAFETY: as above.
            Ok(n) => unsafe { put(out, "out", n) },
            Err(e) => {
                if let format::MresError::Truncated { end, .. } = e {
                    // SAFETY: as above.
                    unsafe { put(out, "out", end)? };
                }
                Err(e.into())
            }
        }
    })
}

/// Parses and checks the resident prefix: the first `len` bytes of the file at `prefix`, at
/// least `mres_prefix_len` of them. On success stores a new index in `*out`; on failure stores
/// null there (when `out` is not null).
///
/// The library keeps no pointer into `prefix`: the caller may free it once this returns.
///
/// # Safety
/// `prefix` must point to `len` readable bytes; `out` must be valid for a write.
#[no_mangle]
pub unsafe extern "C" fn mres_index_open(prefix: *const u8, len: usize, out: *mut *mut MresIndex) -> MresStatus {
    if !out.is_null() {
        // SAFETY: `out` is non-null and writable (the caller's contract).
        unsafe { out.write(std::ptr::null_mut()) };
    }
    call("mres_index_open", || {
        // SAFETY: the caller's contract, as documented.
        let prefix = unsafe { bytes(prefix, len, "prefix")? };
        if out.is_null() {
            return Err(Failure::arg("out is null"));
        }
        let inner = format::MresIndex::parse(prefix)?;
        // SAFETY: as above; the box is freed by `mres_index_free`.
        unsafe { put(out, "out", Box::into_raw(Box::new(MresIndex { inner }))) }
    })
}

/// Frees an index. Null is allowed (nothing happens). Pages decoded against it stay valid
/// (they own their data), but the index must not be used after this call.
///
/// # Safety
/// `index` must be null or an index from `mres_index_open` not yet freed, that no other
/// thread is using.
#[no_mangle]
pub unsafe extern "C" fn mres_index_free(index: *mut MresIndex) {
    if !index.is_null() {
        // SAFETY: the caller's contract: the pointer came from `Box::into_raw` in
        // `mres_index_open` and is freed once. Dropping plain vectors cannot panic.
        drop(unsafe { Box::from_raw(index) });
    }
}

/// Stores the file-wide parameters and counts in `*out`.
///
/// # Safety
/// `index` must be a live index; `out` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn mres_index_info(index: *const MresIndex, out: *mut MresInfo) -> MresStatus {
    call("mres_index_info", || {
        // SAFETY: the caller's contract, as documented.
        let index = unsafe { &get(index, "index")?.inner };
        // SAFETY: as above.
        unsafe { put(out, "out", info(index)) }
    })
}

fn info(index: &format::MresIndex) -> MresInfo {
    let h = &index.header;
    MresInfo {
        source_triangles: h.source_triangles,
        file_size: index.file_size(),
        flags: h.flags,
        group_count: index.groups.len() as u32,
        cluster_count: index.clusters.len() as u32,
        page_count: index.pages.len() as u32,
        level_count: h.level_count,
        normal_bits: h.normal_bits,
        position_bits: h.position_bits,
        grid_origin: h.grid.origin,
        grid_step: h.grid.step,
        uv_min: h.uv.min,
        uv_extent: h.uv.extent,
    }
}

/// Stores group `group`'s record in `*out`. Groups are stored coarse to fine.
///
/// # Safety
/// `index` must be a live index; `out` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn mres_index_group(index: *const MresIndex, group: u32, out: *mut MresGroup) -> MresStatus {
    call("mres_index_group", || {
        // SAFETY: the caller's contract, as documented.
        let index = unsafe { &get(index, "index")?.inner };
        let g = item(&index.groups, group, "group")?;
        let record = MresGroup {
            center: g.sphere.center,
            radius: g.sphere.radius,
            error: g.error,
            level: g.level,
            first_cluster: g.first_cluster,
            cluster_count: g.cluster_count,
            page: g.page,
        };
        // SAFETY: as above.
        unsafe { put(out, "out", record) }
    })
}

/// Stores cluster `cluster`'s record in `*out`. Clusters are numbered in page order.
///
/// # Safety
/// `index` must be a live index; `out` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn mres_index_cluster(
    index: *const MresIndex,
    cluster: u32,
    out: *mut MresCluster,
) -> MresStatus {
    call("mres_index_cluster", || {
        // SAFETY: the caller's contract, as documented.
        let index = unsafe { &get(index, "index")?.inner };
        let c = item(&index.clusters, cluster, "cluster")?;
        // The reader checked that every cluster's group exists.
        let page = item(&index.groups, c.group, "group")?.page;
        let record = MresCluster {
            group: c.group,
            own_group: c.own_group,
            page,
            page_offset: c.page_offset,
            vertex_count: c.vertex_count.into(),
            triangle_count: c.triangle_count.into(),
        };
        // SAFETY: as above.
        unsafe { put(out, "out", record) }
    })
}

/// Stores page `page`'s table entry in `*out`. Pages are stored coarse to fine: page 0 holds
/// the root.
///
/// # Safety
/// `index` must be a live index; `out` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn mres_index_page(index: *const MresIndex, page: u32, out: *mut MresPageInfo) -> MresStatus {
    call("mres_index_page", || {
        // SAFETY: the caller's contract, as documented.
        let index = unsafe { &get(index, "index")?.inner };
        let p = item(&index.pages, page, "page")?;
        let record = MresPageInfo {
            offset: p.offset,
            compressed_size: p.compressed_size,
            raw_size: p.raw_size,
            first_cluster: p.first_cluster,
            cluster_count: p.cluster_count,
            first_group: p.first_group,
            group_count: p.group_count,
            dependency_count: p.dependencies.len() as u32,
            checksum: p.checksum,
        };
        // SAFETY: as above.
        unsafe { put(out, "out", record) }
    })
}

/// The byte range of the file holding page `page`: the caller fetches `*size` bytes from file
/// offset `*offset` and passes them to `mres_page_decode`.
///
/// # Safety
/// `index` must be a live index; `offset` and `size` valid for writes.
#[no_mangle]
pub unsafe extern "C" fn mres_page_range(
    index: *const MresIndex,
    page: u32,
    offset: *mut u64,
    size: *mut u64,
) -> MresStatus {
    call("mres_page_range", || {
        // SAFETY: the caller's contract, as documented.
        let index = unsafe { &get(index, "index")?.inner };
        item(&index.pages, page, "page")?;
        let range = index.page_range(page)?;
        // SAFETY: as above.
        unsafe {
            put(offset, "offset", range.start)?;
            put(size, "size", range.end - range.start)
        }
    })
}

/// Copies the pages that must be resident before page `page` is used (coarser pages holding
/// its clusters' parents, and pages holding their siblings; ascending) into `out`, an array of
/// `cap` elements, and stores their number in `*count`.
///
/// `out` null with `cap` 0 asks for the count alone. A smaller `cap` than the count gives
/// `MRES_ERR_BUFFER_TOO_SMALL` (with `*count` set).
///
/// # Safety
/// `index` must be a live index; `out` valid for writes of `cap` elements (or null with
/// `cap` 0); `count` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn mres_page_dependencies(
    index: *const MresIndex,
    page: u32,
    out: *mut u32,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    call("mres_page_dependencies", || {
        // SAFETY: the caller's contract, as documented.
        let index = unsafe { &get(index, "index")?.inner };
        let p = item(&index.pages, page, "page")?;
        // SAFETY: as above.
        unsafe { copy_out(&p.dependencies, out, cap, count) }
    })
}

/// Copies page `page`'s sources (the pages among its dependencies stored before it, ascending;
/// docs/FORMAT.md §4.3; none with `MRES_FLAG_LAYOUT_PAGES`) into `out`, an array of `cap` elements, and stores their number in
/// `*count`: the pages `mres_page_decode` takes, decoded, as its `sources`. Buffer rules as
/// for `mres_page_dependencies`.
///
/// # Safety
/// As for `mres_page_dependencies`.
#[no_mangle]
pub unsafe extern "C" fn mres_page_sources(
    index: *const MresIndex,
    page: u32,
    out: *mut u32,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    call("mres_page_sources", || {
        // SAFETY: the caller's contract, as documented.
        let index = unsafe { &get(index, "index")?.inner };
        item(&index.pages, page, "page")?;
        let sources = index.page_sources(page)?;
        // SAFETY: as above.
        unsafe { copy_out(&sources, out, cap, count) }
    })
}

/// The clusters of the uniform cut at object-space error `error` (those whose own error is at
/// most `error` and whose parent's is above it; docs/FORMAT.md §6), ascending, into `out`, an
/// array of `cap` elements; their number in `*count`. Buffer rules as for
/// `mres_page_dependencies`; `cap` = cluster count always suffices.
///
/// # Safety
/// As for `mres_page_dependencies`.
#[no_mangle]
pub unsafe extern "C" fn mres_select_uniform(
    index: *const MresIndex,
    error: f32,
    out: *mut u32,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    call("mres_select_uniform", || {
        // SAFETY: the caller's contract, as documented.
        let index = unsafe { &get(index, "index")?.inner };
        let cut = format::uniform_cut(&index.groups, &index.clusters, error);
        // SAFETY: as above.
        unsafe { copy_out(&cut, out, cap, count) }
    })
}

/// The clusters of the view-dependent cut for camera `*view` at `tau` pixels of projected
/// error (docs/FORMAT.md §6), ascending, into `out`; buffer rules as for
/// `mres_select_uniform`. The same f32 operations as the GPU path of docs/FORMAT.md §6.
///
/// # Safety
/// As for `mres_page_dependencies`; `view` must point to a readable `MresView`.
#[no_mangle]
pub unsafe extern "C" fn mres_select_view(
    index: *const MresIndex,
    view: *const MresView,
    tau: f32,
    out: *mut u32,
    cap: usize,
    count: *mut usize,
) -> MresStatus {
    call("mres_select_view", || {
        // SAFETY: the caller's contract, as documented.
        let (index, view) = unsafe { (&get(index, "index")?.inner, get(view, "view")?) };
        let view = format::ViewParams {
            eye: view.eye,
            proj_y: view.proj_y,
            viewport_height: view.viewport_height,
            z_near: view.z_near,
        };
        let cut = format::view_cut(&index.groups, &index.clusters, &view, tau);
        // SAFETY: as above.
        unsafe { copy_out(&cut, out, cap, count) }
    })
}

/// Element `i` of a hierarchy array, or an `MRES_ERR_ARG` failure naming `what`.
pub(crate) fn item<'a, T>(items: &'a [T], i: u32, what: &str) -> Result<&'a T, Failure> {
    items
        .get(i as usize)
        .ok_or_else(|| Failure::arg(format!("{what} {i} does not exist ({} in the file)", items.len())))
}
