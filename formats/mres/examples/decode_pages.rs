//! Decodes every page of a file with [`MresFile::page`] (checksum, zstd, page decoding to the
//! GPU layout) on one thread, `PASSES` times, and prints the best pass in MB of GPU layout per
//! second: a page decoding figure without a bake, and a fixed workload to profile
//! (`valgrind --tool=callgrind` with one pass counts instructions, immune to machine load).
//!
//! ```sh
//! cargo run --release -p mres-format --example decode_pages -- FILE.mres [PASSES]
//! ```

use mres_format::MresFile;
use std::error::Error;
use std::time::Instant;

fn main() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: decode_pages FILE.mres [PASSES]")?;
    let passes: usize = args.next().map_or(Ok(5), |p| p.parse())?;
    let file = MresFile::open(path.as_ref()).map_err(|e| format!("{path}: {e}"))?;
    let mut best = f64::INFINITY;
    let mut bytes = 0usize;
    for _ in 0..passes {
        let start = Instant::now();
        bytes = 0;
        for p in 0..file.pages.len() as u32 {
            bytes += file.page(p).map_err(|e| format!("{path}: {e}"))?.len();
        }
        best = best.min(start.elapsed().as_secs_f64());
    }
    println!(
        "{path}: {} pages, {bytes} bytes of GPU layout, best of {passes}: {:.1} ms, {:.0} MB/s",
        file.pages.len(),
        best * 1e3,
        bytes as f64 / 1e6 / best
    );
    Ok(())
}
