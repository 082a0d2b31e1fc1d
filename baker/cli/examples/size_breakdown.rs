//! Where the bytes of a `.mres` file go, by page section, each compressed separately:
//! `cargo run --release -p mres-cli --example size_breakdown -- FILE.mres`.
use mres_format::MresFile;
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let f = MresFile::open(std::path::Path::new(&path)).expect("a readable .mres file");
    let mut cats: Vec<Vec<u8>> = vec![Vec::new(); 6];
    for p in 0..f.pages.len() as u32 {
        let raw = f.page(p).unwrap();
        let info = &f.pages[p as usize];
        for c in info.first_cluster..info.first_cluster + info.cluster_count {
            let ci = &f.clusters[c as usize];
            let h = &raw[ci.page_offset as usize..ci.page_offset as usize + 48];
            cats[0].extend_from_slice(h);
            let off = |i: usize| u32::from_le_bytes(h[20 + i * 4..24 + i * 4].try_into().unwrap()) as usize;
            let vc = ci.vertex_count as usize;
            let tc = ci.triangle_count as usize;
            let pb = (h[16] + h[17] + h[18]) as usize;
            let nb = (h[44] + h[45]) as usize;
            let lens = [(vc * pb).div_ceil(32) * 4, (vc * nb).div_ceil(32) * 4, vc * 4, tc * 3, tc * 2];
            for i in 0..5 {
                if off(i) != 0 {
                    cats[i + 1].extend_from_slice(&raw[off(i)..off(i) + lens[i]]);
                }
            }
        }
    }
    let names = ["headers", "positions", "normals", "uvs", "indices", "materials"];
    let tris = f.header.source_triangles as f64;
    for (n, c) in names.iter().zip(&cats) {
        let z = zstd::bulk::compress(c, 9).unwrap().len();
        println!(
            "{n:>10}: raw {:>9} ({:.2} B/input tri)  zstd {:>9} ({:.2} B/input tri)",
            c.len(),
            c.len() as f64 / tri_or(tris),
            z,
            z as f64 / tri_or(tris)
        );
    }
    println!("file {} ({:.2} B/tri)", f.file_size(), f.file_size() as f64 / tris);
}
fn tri_or(t: f64) -> f64 {
    t.max(1.0)
}
