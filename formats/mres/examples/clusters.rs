//! Iterates the clusters of a uniform cut page by page, the way a streamer does: reads the
//! resident prefix, picks the cut, fetches only the pages holding its clusters, and prints
//! each cluster's vertices and triangles in object space.
//!
//! ```sh
//! cargo run -p mres-format --example clusters -- FILE.mres [ERROR [TRIANGLES_PER_CLUSTER]]
//! # the coarsest cut (the root clusters), two triangles of each:
//! cargo run -p mres-format --example clusters -- FILE.mres
//! # the cut at object-space error 0.001, every triangle:
//! cargo run -p mres-format --example clusters -- FILE.mres 0.001 128
//! ```

use mres_format::{uniform_cut, MresIndex, HEADER_SIZE};
use std::error::Error;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};

const USAGE: &str = "usage: clusters FILE.mres [ERROR [TRIANGLES_PER_CLUSTER]]";

/// Bytes `range` of `file` (fewer if the file ends first: the reader then reports it).
fn read_range(file: &mut File, range: std::ops::Range<u64>) -> std::io::Result<Vec<u8>> {
    file.seek(SeekFrom::Start(range.start))?;
    let mut bytes = Vec::new();
    file.by_ref().take(range.end.saturating_sub(range.start)).read_to_end(&mut bytes)?;
    Ok(bytes)
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().ok_or(USAGE)?;
    let arg = |i: usize, default: &str| args.get(i).map_or(default, String::as_str).to_string();
    // The largest finite threshold selects the clusters whose parent error is infinite: the roots.
    let threshold: f32 = arg(1, &f32::MAX.to_string()).parse().map_err(|e| format!("ERROR: {e}\n{USAGE}"))?;
    let shown: usize = arg(2, "2").parse().map_err(|e| format!("TRIANGLES_PER_CLUSTER: {e}\n{USAGE}"))?;

    let named = |e: mres_format::MresError| format!("{path}: {e}");
    let mut file = File::open(path).map_err(|e| format!("{path}: {e}"))?;
    let prefix_len = MresIndex::prefix_len(&read_range(&mut file, 0..HEADER_SIZE as u64)?).map_err(named)?;
    let index = MresIndex::parse(&read_range(&mut file, 0..prefix_len)?).map_err(named)?;
    let cut = uniform_cut(&index.groups, &index.clusters, threshold);
    let at = if args.len() > 1 { format!("at error {threshold}") } else { "coarsest".into() };
    println!("{path}: {at} cut: {} clusters", cut.len());

    let grid = index.header.grid;
    // The pages to fetch: those holding the cut, and the sources (docs/FORMAT.md §4.3) of
    // every page fetched, which come before it; a streamer would not fetch the others.
    let page_of = |c: u32| index.groups[index.clusters[c as usize].group as usize].page as usize;
    let mut needed = vec![false; index.pages.len()];
    for &c in &cut {
        needed[page_of(c)] = true;
    }
    for p in (0..index.pages.len()).rev() {
        if !needed[p] {
            continue;
        }
        for s in index.page_sources(p as u32).map_err(named)? {
            needed[s as usize] = true;
        }
    }
    let mut layouts: Vec<Vec<u8>> = vec![Vec::new(); index.pages.len()];
    let mut cut = cut.into_iter().peekable();
    let mut triangles = 0u64;
    for p in (0..index.pages.len() as u32).filter(|&p| needed[p as usize]) {
        let info = &index.pages[p as usize];
        let in_page = info.first_cluster..info.first_cluster + info.cluster_count;
        let sources = index.page_sources(p).map_err(named)?;
        let sources: Vec<&[u8]> = sources.iter().map(|&s| layouts[s as usize].as_slice()).collect();
        let compressed = read_range(&mut file, index.page_range(p).map_err(named)?)?;
        let page = index.decode_page(p, &compressed, &sources).map_err(named)?;
        layouts[p as usize] = page.bytes.clone();
        println!("page {p}: {} compressed bytes, {} decompressed", info.compressed_size, page.bytes.len());
        while let Some(c) = cut.next_if(|c| in_page.contains(c)) {
            let cluster = &page.clusters[(c - page.first_cluster) as usize];
            let group = &index.groups[index.clusters[c as usize].group as usize];
            println!(
                "  cluster {c}: {} vertices, {} triangles, parent error {}",
                cluster.positions.len(),
                cluster.indices.len() / 3,
                group.error
            );
            for (t, corners) in cluster.indices.chunks_exact(3).enumerate().take(shown) {
                let at = |k: usize| grid.decode(cluster.positions[corners[k] as usize]);
                println!("    triangle {t}: {:?} {:?} {:?}", at(0), at(1), at(2));
            }
            triangles += cluster.indices.len() as u64 / 3;
        }
    }
    println!("{triangles} triangles");
    Ok(())
}
