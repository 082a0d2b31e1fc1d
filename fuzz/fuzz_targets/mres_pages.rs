//! The page-level reader on raw bytes, as a streamer drives it: `MresIndex::prefix_len` and
//! `MresIndex::parse` on the input taken as a prefix of a file whose length is unknown, then
//! `decode_page` on each page's byte range in file order, cut from the input where it holds it
//! and empty otherwise (so that a page the prefix does not reach still meets the length check),
//! given the layouts of its sources (`page_sources`) decoded before it; a source that did not
//! decode is passed empty (so that the source checks run too).
#![no_main]

use libfuzzer_sys::fuzz_target;
use mres_format::MresIndex;

fuzz_target!(|data: &[u8]| {
    let _ = MresIndex::prefix_len(data);
    let Ok(index) = MresIndex::parse(data) else { return };
    let mut layouts: Vec<Vec<u8>> = Vec::with_capacity(index.pages.len());
    for p in 0..index.pages.len() as u32 {
        let sources = index.page_sources(p).unwrap_or_default();
        let sources: Vec<&[u8]> =
            sources.iter().map(|&s| layouts.get(s as usize).map_or(&[][..], Vec::as_slice)).collect();
        let bytes = index.page_range(p).ok().and_then(|r| {
            let (start, end) = (usize::try_from(r.start).ok()?, usize::try_from(r.end).ok()?);
            Some(data.get(start..end).unwrap_or(&[]))
        });
        let page = bytes.map(|bytes| index.decode_page(p, bytes, &sources));
        layouts.push(page.and_then(Result::ok).map(|page| page.bytes).unwrap_or_default());
    }
});
