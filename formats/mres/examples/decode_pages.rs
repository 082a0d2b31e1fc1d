//! Decodes every page of a file with [`MresIndex::page_layout`] (checksum, zstd, page decoding
//! to the GPU layout) on one thread, in file order, each page given the layouts
//! of its sources decoded before it (as a streamer holds them), `PASSES` times, and prints the
//! best pass in MB of GPU layout per second: a page decoding figure without a bake, and a fixed
//! workload to profile (`valgrind --tool=callgrind` with one pass counts instructions, immune
//! to machine load). Pages that are no page's source are dropped once decoded; the whole-file
//! reader would keep the sources decoded between passes, so it is not used here.
//!
//! ```sh
//! cargo run --release -p mres-format --example decode_pages -- FILE.mres [PASSES]
//! ```

use mres_format::MresIndex;
use std::error::Error;
use std::time::Instant;

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: decode_pages FILE.mres [PASSES]")?;
    let passes: usize = args.next().map_or(Ok(5), |p| p.parse())?;
    let file = std::fs::read(&path).map_err(|e| format!("{path}: {e}"))?;
    let named = |e: mres_format::MresError| format!("{path}: {e}");
    let index = MresIndex::parse(&file).map_err(named)?;
    // Only pages that are some page's source are kept (as `MresFile` keeps them).
    let mut is_source = vec![false; index.pages.len()];
    for p in 0..index.pages.len() as u32 {
        for s in index.page_sources(p).map_err(named)? {
            is_source[s as usize] = true;
        }
    }
    let mut best = f64::INFINITY;
    let mut bytes = 0usize;
    for _ in 0..passes {
        let start = Instant::now();
        let mut layouts: Vec<Vec<u8>> = Vec::with_capacity(index.pages.len());
        bytes = 0;
        for p in 0..index.pages.len() as u32 {
            let range = index.page_range(p).map_err(named)?;
            let sources = index.page_sources(p).map_err(named)?;
            let sources: Vec<&[u8]> = sources.iter().map(|&s| layouts[s as usize].as_slice()).collect();
            let compressed = &file[range.start as usize..range.end as usize];
            let layout = index.page_layout(p, compressed, &sources).map_err(named)?;
            bytes += layout.len();
            layouts.push(if is_source[p as usize] { layout } else { Vec::new() });
        }
        best = best.min(start.elapsed().as_secs_f64());
    }
    println!(
        "{path}: {} pages, {bytes} bytes of GPU layout, best of {passes}: {:.1} ms, {:.0} MB/s",
        index.pages.len(),
        best * 1e3,
        bytes as f64 / 1e6 / best
    );
    Ok(())
}
