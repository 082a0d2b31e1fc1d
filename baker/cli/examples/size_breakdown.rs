//! Where the bytes of a `.mres` file go: the resident prefix (header, hierarchy, page table)
//! and, per stream of the page encoding (docs/FORMAT.md §4.3; the writer compresses each
//! stream as its own zstd frame), the compressed bytes of every page added up, far targets
//! (copies of a source page's vertices) apart from the targets of copies within the page, and
//! how many vertices are stored, copies and far copies:
//! `cargo run --release -p mres-cli --example size_breakdown -- FILE.mres`.
use mres_format::{MresFile, FLAG_MATERIALS, FLAG_NORMALS, FLAG_UVS};

fn main() {
    let path = std::env::args().nth(1).expect("usage: size_breakdown FILE.mres");
    let bytes = std::fs::read(&path).expect("a readable file");
    let f = MresFile::parse(bytes.clone()).expect("a valid .mres file");
    let flags = f.header.flags;
    let names =
        ["indices", "marks", "references", "targets", "far targets", "positions", "normals", "uvs", "materials"];
    let mut sizes = [0usize; 9];
    // Vertices by reference flag: stored, copies, far copies.
    let mut kinds = [0usize; 3];
    let mut gpu = 0usize;
    for (p, info) in f.pages.iter().enumerate() {
        gpu += f.page(p as u32).expect("page decodes").len();
        let mut frames = Vec::new();
        let mut rest = &bytes[info.offset as usize..][..info.compressed_size as usize];
        while !rest.is_empty() {
            let n = zstd::zstd_safe::find_frame_compressed_size(rest).expect("a zstd frame");
            frames.push(n);
            rest = &rest[n..];
        }
        // Frames: preamble, index lengths and coded indices, marks, references, the target
        // planes, the far target planes and the position planes (their counts in the
        // preamble), then two planes per attribute the file carries.
        let compressed = &bytes[info.offset as usize..][..frames[0]];
        let preamble = zstd::bulk::decompress(compressed, 4).expect("a preamble frame");
        let (planes, targets, far) = (preamble[0] as usize, preamble[1] as usize, preamble[2] as usize);
        let attr = |flag: u32| if flags & flag != 0 { 2 } else { 0 };
        let counts = [3, 1, 1, targets, far, planes, attr(FLAG_NORMALS), attr(FLAG_UVS), attr(FLAG_MATERIALS)];
        let vertices: usize = f.clusters[info.first_cluster as usize..][..info.cluster_count as usize]
            .iter()
            .map(|c| c.vertex_count as usize)
            .sum();
        let at: usize = frames[..4].iter().sum();
        let references = &bytes[info.offset as usize + at..][..frames[4]];
        for &r in &zstd::bulk::decompress(references, vertices).expect("a references frame") {
            kinds[(r as usize).min(2)] += 1;
        }
        let mut at = 0;
        for (size, count) in sizes.iter_mut().zip(counts) {
            *size += frames[at..at + count].iter().sum::<usize>();
            at += count;
        }
    }
    let tris = (f.header.source_triangles as f64).max(1.0);
    let prefix = f.pages.first().map_or(f.file_size(), |p| p.offset as usize);
    println!("{:>10}: {:>9} ({:.2} B/input tri)", "prefix", prefix, prefix as f64 / tris);
    for (n, s) in names.iter().zip(sizes) {
        println!("{n:>10}: {s:>9} ({:.2} B/input tri)", s as f64 / tris);
    }
    let [stored, copies, far] = kinds;
    let all = (stored + copies + far).max(1) as f64;
    let share = |n: usize| 100.0 * n as f64 / all;
    println!(
        "vertices: {stored} stored ({:.1}%), {copies} copies ({:.1}%), {far} far copies ({:.1}%)",
        share(stored),
        share(copies),
        share(far)
    );
    println!("gpu layout {gpu} ({:.2} B/input tri)", gpu as f64 / tris);
    println!("file {} ({:.2} B/input tri)", f.file_size(), f.file_size() as f64 / tris);
}
