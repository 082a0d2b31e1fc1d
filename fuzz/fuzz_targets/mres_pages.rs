//! The page-level reader on raw bytes, as a streamer drives it: `MresIndex::prefix_len` and
//! `MresIndex::parse` on the input taken as a prefix of a file whose length is unknown, then
//! `decode_page` on each page's byte range, cut from the input where it holds it and empty
//! otherwise (so that a page the prefix does not reach still meets the length check).
#![no_main]

use libfuzzer_sys::fuzz_target;
use mres_format::MresIndex;

fuzz_target!(|data: &[u8]| {
    let _ = MresIndex::prefix_len(data);
    let Ok(index) = MresIndex::parse(data) else { return };
    for p in 0..index.pages.len() as u32 {
        let Ok(range) = index.page_range(p) else { continue };
        let (Ok(start), Ok(end)) = (usize::try_from(range.start), usize::try_from(range.end)) else { continue };
        let _ = index.decode_page(p, data.get(start..end).unwrap_or(&[]));
    }
});
