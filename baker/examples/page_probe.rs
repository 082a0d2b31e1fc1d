use formats::mres::MresFile;
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let f = MresFile::open(std::path::Path::new(&path)).unwrap();
    for p in [0u32, 10, 30, 60] {
        let raw = f.page(p).unwrap();
        let info = &f.pages[p as usize];
        let c0 = &f.clusters[info.first_cluster as usize];
        let h = &raw[c0.page_offset as usize..c0.page_offset as usize + 48];
        let off = |i: usize| u32::from_le_bytes(h[20 + i * 4..24 + i * 4].try_into().unwrap()) as usize;
        let idx = off(3);
        let z = |b: &[u8]| zstd::bulk::compress(b, 9).unwrap().len();
        println!(
            "page {p}: raw {} comp {} stored {} | idx region {} comp {} | before idx {} comp {}",
            raw.len(),
            z(&raw),
            info.compressed_size,
            raw.len() - idx,
            z(&raw[idx..]),
            idx,
            z(&raw[..idx])
        );
    }
}
