//! Layout pages (FORMAT.md §4.4, header flag [`FLAG_LAYOUT_PAGES`]): each page stored as its
//! GPU layout (§5) itself, one LZ4 block. Decoding is LZ4 and a structural check of the
//! layout, a few instructions per byte, so pages stream at memory speed and each decodes alone;
//! the price is about twice the bytes of the compact encoding (§4.3), whose prediction and
//! entropy coding cost 40–65 instructions per byte of layout to undo.
//!
//! The LZ4 block format is the library's (liblz4 through the `lz4` crate, the reference
//! implementation every engine already links); the check is ours, as no library knows the layout.

use super::error::{corrupt, MresError};
use super::records::ClusterHeader;
use super::*;

/// liblz4's high-compression level for layout pages: its largest, as the writer compresses
/// once and readers decompress at the same speed whatever the level.
const HC_LEVEL: i32 = 12;

/// One LZ4 block of `raw`, a page's GPU layout.
pub(crate) fn compress(raw: &[u8]) -> std::io::Result<Vec<u8>> {
    lz4::block::compress(raw, Some(lz4::block::CompressionMode::HIGHCOMPRESSION(HC_LEVEL)), false)
}

/// The longest LZ4 block a page of `raw_size` bytes may have (FORMAT.md §4.4): liblz4's
/// `LZ4_compressBound`, the most its compressor ever writes.
pub(crate) fn compress_bound(raw_size: usize) -> usize {
    raw_size + raw_size / 255 + 16
}

/// Page `p`'s layout from its LZ4 block: exactly `raw_size` bytes, checked by [`check`].
pub(crate) fn decompress(
    header: &Header,
    records: &[ClusterInfo],
    first_cluster: u32,
    p: u32,
    compressed: &[u8],
    raw_size: usize,
) -> Result<Vec<u8>, MresError> {
    let problem = |problem: String| MresError::Decompress { page: p, problem };
    if compressed.len() > compress_bound(raw_size) {
        return Err(problem(format!(
            "an LZ4 block of {} bytes for {raw_size} bytes of layout (at most {} allowed)",
            compressed.len(),
            compress_bound(raw_size)
        )));
    }
    let mut raw = vec![0u8; raw_size];
    // liblz4's safe decoder never writes past `raw`; fewer bytes than `raw_size` is an error too.
    let len = lz4::block::decompress_to_buffer(compressed, Some(raw_size as i32), &mut raw)
        .map_err(|e| problem(format!("LZ4: {e}")))?;
    if len != raw_size {
        return Err(problem(format!("LZ4 block decompresses to {len} bytes, raw_size says {raw_size}")));
    }
    check(header, records, first_cluster, &raw).map_err(|e| corrupt(format!("page {p}: {e}")))?;
    Ok(raw)
}

/// What a renderer relies on in a layout it uploads as is (FORMAT.md §4.4, §7): every header
/// agrees with its cluster record and the header flags, its blocks sit exactly where §5 lays
/// them out (so they lie inside the page and never overlap), local indices are in range, and
/// padding and unused bits are zero. What needs every value unpacked (minima and widths
/// exact, octahedral values in range, the vertex order) is left to [`crate::write::relaid`].
/// Errors name clusters by their file index (`records` are clusters `first_cluster..`).
pub(crate) fn check(header: &Header, records: &[ClusterInfo], first_cluster: u32, raw: &[u8]) -> Result<(), String> {
    if records.len() > raw.len() / CLUSTER_HEADER_SIZE {
        return Err(format!("{} cluster headers do not fit in {} bytes", records.len(), raw.len()));
    }
    let headers: Vec<ClusterHeader> = records
        .iter()
        .enumerate()
        .map(|(i, record)| {
            let at = i * CLUSTER_HEADER_SIZE;
            let bytes = raw[at..at + CLUSTER_HEADER_SIZE].first_chunk().ok_or("header")?;
            check_header(header, record, &ClusterHeader::decode(bytes), bytes)
                .map_err(|e| format!("cluster {}: {e}", first_cluster as usize + i))
        })
        .collect::<Result<_, String>>()?;
    let end = check_blocks(header.flags, &headers, raw)
        .map_err(|(i, e)| format!("cluster {}: {e}", first_cluster as usize + i))?;
    if end != raw.len() {
        return Err(format!("its blocks end at byte {end}, its layout has {} bytes", raw.len()));
    }
    Ok(())
}

/// One cluster header against its record and the file's flags: [`header_limits`], plus what
/// only a canonical layout promises (no normal fields without normals, reserved bytes zero).
fn check_header(
    header: &Header,
    record: &ClusterInfo,
    head: &ClusterHeader,
    bytes: &[u8; CLUSTER_HEADER_SIZE],
) -> Result<ClusterHeader, String> {
    header_limits(header, record, head)?;
    if header.flags & FLAG_NORMALS == 0 && (head.normal_bits != [0; 2] || head.normal_min != [0; 2]) {
        return Err("normal fields set in a file without normals".into());
    }
    if bytes[ClusterHeader::RESERVED_2..] != [0, 0] {
        return Err("reserved bytes are not zero".into());
    }
    Ok(*head)
}

/// The limits every reader checks of a cluster header (FORMAT.md §5.1, §7), whatever the page
/// encoding: counts equal to the cluster record's, bit widths within their limits, no unknown
/// `edge_flags` bit.
pub(crate) fn header_limits(header: &Header, record: &ClusterInfo, head: &ClusterHeader) -> Result<(), &'static str> {
    if head.vertex_count != record.vertex_count || head.triangle_count != record.triangle_count {
        return Err("counts differ from the hierarchy");
    }
    if head.position_bits.iter().any(|&b| b > 32) {
        return Err("position bit width over 32");
    }
    if header.flags & FLAG_NORMALS != 0 && head.normal_bits.iter().any(|&b| b as u32 > header.normal_bits) {
        return Err("normal bit width over the header's normal_bits");
    }
    if head.edge_flags & !ClusterHeader::OPEN_EDGES != 0 {
        return Err("unknown edge_flags bits");
    }
    Ok(())
}

/// Walks the blocks in §5's order (every cluster's positions, then normals, UVs, indices with
/// their open-edge blocks, materials), checking each header's offsets and each block's
/// contents; returns where the last block ends, or the page's cluster at fault and what is wrong.
fn check_blocks(flags: u32, headers: &[ClusterHeader], raw: &[u8]) -> Result<usize, (usize, String)> {
    let mut at = CLUSTER_HEADER_SIZE * headers.len();
    for slot in 0..5 {
        let present = match slot {
            ClusterHeader::NORMALS => flags & FLAG_NORMALS != 0,
            ClusterHeader::UVS => flags & FLAG_UVS != 0,
            ClusterHeader::MATERIALS => flags & FLAG_MATERIALS != 0,
            _ => true,
        };
        for (i, head) in headers.iter().enumerate() {
            let offset = head.block_offsets[slot] as usize;
            let expected = if present { at } else { 0 };
            if offset != expected {
                return Err((i, format!("block {slot} at byte {offset}, the layout puts it at {expected}")));
            }
            if present {
                let len = block_len(slot, head);
                let block = raw.get(at..at + len).ok_or_else(|| (i, format!("block {slot} ends past the page")))?;
                check_block(slot, head, block).map_err(|e| (i, e))?;
                at += len;
            }
        }
    }
    Ok(at)
}

/// The padded length of block `slot` of the cluster with header `head` (FORMAT.md §5).
pub(crate) fn block_len(slot: usize, head: &ClusterHeader) -> usize {
    let (v, t) = (head.vertex_count as usize, head.triangle_count as usize);
    let words = |bits: usize| bits.div_ceil(32) * 4;
    let sum = |bits: &[u8]| bits.iter().map(|&b| b as usize).sum::<usize>();
    match slot {
        ClusterHeader::POSITIONS => words(v * sum(&head.position_bits)),
        ClusterHeader::NORMALS => words(v * sum(&head.normal_bits)),
        ClusterHeader::UVS => 4 * v,
        ClusterHeader::INDICES => {
            let marks = if head.edge_flags & ClusterHeader::OPEN_EDGES != 0 { words(3 * t) } else { 0 };
            (3 * t).next_multiple_of(4) + marks
        }
        _ => (2 * t).next_multiple_of(4),
    }
}

/// One block's contents: indices in range, some mark set where the header says so, and zero
/// padding and unused bits.
fn check_block(slot: usize, head: &ClusterHeader, block: &[u8]) -> Result<(), String> {
    let (v, t) = (head.vertex_count as usize, head.triangle_count as usize);
    let sum = |bits: &[u8]| bits.iter().map(|&b| b as usize).sum::<usize>();
    let used = match slot {
        ClusterHeader::POSITIONS => v * sum(&head.position_bits),
        ClusterHeader::NORMALS => v * sum(&head.normal_bits),
        ClusterHeader::UVS => 32 * v,
        ClusterHeader::INDICES => 24 * t,
        _ => 16 * t,
    };
    if slot == ClusterHeader::INDICES {
        // One pass for the largest index: branch-free over the block.
        if block[..3 * t].iter().fold(0, |m, &i| m.max(i)) as usize >= v {
            return Err("local index out of range".into());
        }
        let marks = &block[(3 * t).next_multiple_of(4)..];
        if !marks.is_empty() && marks.iter().all(|&b| b == 0) {
            return Err("open-edge block without a marked edge".into());
        }
        zero_after(&block[..(3 * t).next_multiple_of(4)], used, "index padding")?;
        return zero_after(marks, 3 * t, "open-edge bits");
    }
    zero_after(block, used, "padding")
}

/// Every bit of `block` from bit `used` on is zero.
fn zero_after(block: &[u8], used: usize, what: &str) -> Result<(), String> {
    let (whole, part) = (used / 8, used % 8);
    let partial = block.get(whole).is_some_and(|&b| b >> part != 0);
    let tail = block.get(whole + (part != 0) as usize..).unwrap_or_default();
    if partial || tail.iter().any(|&b| b != 0) {
        return Err(format!("{what} not zero"));
    }
    Ok(())
}
