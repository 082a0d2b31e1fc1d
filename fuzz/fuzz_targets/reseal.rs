//! Shared by the `mres_reader_resealed` fuzz target and the `unseal` example: conversion
//! between a real `.mres` file and an "unsealed" one whose pages are stored as their encoded
//! bytes (`docs/FORMAT.md` §4.3, zstd undone; layout pages, §4.4: their GPU layout, LZ4 undone) and whose checksums are not checked, so that a
//! mutation of a hierarchy record, page-table field or encoded page byte reaches the reader's
//! consistency checks and page decoder instead of being stopped by blake3 or zstd. A page
//! record's `raw_size` (the size of the GPU layout its bytes decode to) is kept as it is. Field offsets are the reader's own (`mres_format::records`, which mirrors
//! `docs/FORMAT.md` §2 and §4.1).

use mres_format::records::{meta_checksum, HeaderRecord, PageRecord};
use mres_format::{FLAG_LAYOUT_PAGES, HEADER_SIZE, MAX_PAGE_ENCODED_SIZE, PAGE_RECORD_SIZE};

const PAGE_COUNT_AT: usize = HeaderRecord::PAGE_COUNT;
const HIERARCHY_OFFSET_AT: usize = HeaderRecord::HIERARCHY_OFFSET;
const HIERARCHY_SIZE_AT: usize = HeaderRecord::HIERARCHY_SIZE;
const TABLE_OFFSET_AT: usize = HeaderRecord::PAGE_TABLE_OFFSET;
const TABLE_SIZE_AT: usize = HeaderRecord::PAGE_TABLE_SIZE;
const CHECKSUM_AT: usize = HeaderRecord::META_CHECKSUM;
const REC_OFFSET: usize = PageRecord::OFFSET;
const REC_COMPRESSED: usize = PageRecord::COMPRESSED_SIZE;
const REC_CHECKSUM: usize = PageRecord::CHECKSUM;
const REC_RAW: usize = PageRecord::RAW_SIZE;
const FLAGS_AT: usize = HeaderRecord::FLAGS;

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at.checked_add(4)?)?.try_into().ok()?))
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at.checked_add(8)?)?.try_into().ok()?))
}

fn range(start: u64, len: u64, total: usize) -> Option<std::ops::Range<usize>> {
    let end = start.checked_add(len)?;
    (end <= total as u64).then_some(start as usize..end as usize)
}

/// Header-declared layout: (hierarchy range, page-table range, page count), if in bounds.
fn layout(b: &[u8]) -> Option<(std::ops::Range<usize>, std::ops::Range<usize>, usize)> {
    if b.len() < HEADER_SIZE {
        return None;
    }
    let hierarchy = range(u64_at(b, HIERARCHY_OFFSET_AT)?, u64_at(b, HIERARCHY_SIZE_AT)?, b.len())?;
    let table = range(u64_at(b, TABLE_OFFSET_AT)?, u64_at(b, TABLE_SIZE_AT)?, b.len())?;
    let pages = u32_at(b, PAGE_COUNT_AT)? as usize;
    // Only records that lie inside the table are rewritten; the reader rejects the rest.
    let pages = pages.min(table.len() / PAGE_RECORD_SIZE);
    Some((hierarchy, table, pages))
}

/// The header of `b` says its pages are layout pages (`docs/FORMAT.md` §4.4): stored as one
/// LZ4 block each instead of zstd frames.
fn layout_pages(b: &[u8]) -> bool {
    u32_at(b, FLAGS_AT).is_some_and(|f| f & FLAG_LAYOUT_PAGES != 0)
}

/// A page's stored bytes from its unsealed ones: zstd level 1, or one LZ4 block for layout pages.
fn compress(input: &[u8], raw: &[u8]) -> std::io::Result<Vec<u8>> {
    if layout_pages(input) {
        lz4::block::compress(raw, None, false)
    } else {
        zstd::bulk::compress(raw, 1)
    }
}

/// Rewrites the header checksum over the header's first bytes, hierarchy and page table.
fn seal_header(out: &mut [u8]) {
    let Some((hierarchy, table, _)) = layout(out) else { return };
    let Some(head) = out.first_chunk::<HEADER_SIZE>() else { return };
    let hash = meta_checksum(head, &out[hierarchy], &out[table]);
    out[CHECKSUM_AT..CHECKSUM_AT + 32].copy_from_slice(&hash);
}

/// Unsealed → real `.mres`: every page record whose byte range lies inside `input` has that
/// range zstd-compressed (level 1) and appended after the page table in record order, with
/// offset, compressed size and page checksum rewritten; then the header checksum is recomputed.
/// Anything that does not fit this shape is passed through unchanged (the reader rejects it).
pub fn seal(input: &[u8]) -> Vec<u8> {
    let Some((_, table, pages)) = layout(input) else { return input.to_vec() };
    let mut out = input[..table.end].to_vec();
    for p in 0..pages {
        let rec = table.start + p * PAGE_RECORD_SIZE;
        let (Some(offset), Some(size)) = (u64_at(input, rec + REC_OFFSET), u32_at(input, rec + REC_COMPRESSED)) else {
            continue;
        };
        let Some(raw) = range(offset, size as u64, input.len()).map(|r| &input[r]) else { continue };
        let Ok(frame) = compress(input, raw) else { continue };
        let at = out.len() as u64;
        out[rec + REC_OFFSET..rec + REC_OFFSET + 8].copy_from_slice(&at.to_le_bytes());
        out[rec + REC_COMPRESSED..rec + REC_COMPRESSED + 4].copy_from_slice(&(frame.len() as u32).to_le_bytes());
        out[rec + REC_CHECKSUM..rec + REC_CHECKSUM + 32].copy_from_slice(blake3::hash(&frame).as_bytes());
        out.extend_from_slice(&frame);
    }
    seal_header(&mut out);
    out
}

/// Real `.mres` → unsealed: pages decompressed to their encoded bytes in place of their frames
/// (offsets and compressed sizes rewritten, checksums zeroed). Used to make seeds for
/// `mres_reader_resealed`.
#[allow(dead_code)]
pub fn unseal(input: &[u8]) -> Option<Vec<u8>> {
    let (_, table, pages) = layout(input)?;
    let mut out = input[..table.end].to_vec();
    for p in 0..pages {
        let rec = table.start + p * PAGE_RECORD_SIZE;
        let offset = u64_at(input, rec + REC_OFFSET)?;
        let size = u32_at(input, rec + REC_COMPRESSED)?;
        let frame = &input[range(offset, size as u64, input.len())?];
        let raw = if layout_pages(input) {
            let raw_size = u32_at(input, rec + REC_RAW)?;
            lz4::block::decompress(frame, Some(raw_size as i32)).ok()?
        } else {
            zstd::bulk::decompress(frame, MAX_PAGE_ENCODED_SIZE).ok()?
        };
        let at = out.len() as u64;
        out[rec + REC_OFFSET..rec + REC_OFFSET + 8].copy_from_slice(&at.to_le_bytes());
        out[rec + REC_COMPRESSED..rec + REC_COMPRESSED + 4].copy_from_slice(&(raw.len() as u32).to_le_bytes());
        out[rec + REC_CHECKSUM..rec + REC_CHECKSUM + 32].fill(0);
        out.extend_from_slice(&raw);
    }
    out[CHECKSUM_AT..CHECKSUM_AT + 32].fill(0);
    Some(out)
}
