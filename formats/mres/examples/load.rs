//! Loads a `.mres` file whole and prints its header and, per DAG level, its groups, clusters
//! and triangles.
//!
//! ```sh
//! cargo run -p mres-format --example load -- FILE.mres
//! ```

use mres_format::{MresFile, FLAG_MATERIALS, FLAG_NORMALS, FLAG_UVS, NO_GROUP};
use std::error::Error;

fn main() -> Result<(), Box<dyn Error>> {
    let path = std::env::args().nth(1).ok_or("usage: load FILE.mres")?;
    let file = MresFile::open(path.as_ref()).map_err(|e| format!("{path}: {e}"))?;
    let h = &file.header;
    println!("{path}: {} bytes, {} pages", file.file_size(), file.pages.len());
    let attributes: Vec<&str> = [(FLAG_NORMALS, "normals"), (FLAG_UVS, "uvs"), (FLAG_MATERIALS, "materials")]
        .iter()
        .filter(|(flag, _)| h.flags & flag != 0)
        .map(|&(_, name)| name)
        .collect();
    println!("attributes: {}", ["positions"].iter().chain(&attributes).copied().collect::<Vec<_>>().join(", "));
    println!("grid: origin {:?}, step {} ({} bits)", h.grid.origin, h.grid.step, h.position_bits);
    if h.flags & FLAG_NORMALS != 0 {
        println!("normals: {} bits per octahedral coordinate", h.normal_bits);
    }
    println!("source triangles: {}", h.source_triangles);

    // A cluster's level is one above the group that produced it (FORMAT.md §3.2).
    let levels = h.level_count as usize;
    let (mut groups, mut clusters, mut triangles) = (vec![0u64; levels], vec![0u64; levels], vec![0u64; levels]);
    for g in &file.groups {
        groups[g.level as usize] += 1;
    }
    for c in &file.clusters {
        let level = if c.own_group == NO_GROUP { 0 } else { file.groups[c.own_group as usize].level as usize + 1 };
        // Each group's level is at least its members', so this is below level_count in a
        // well-formed file; the reader does not check it, so skip what is not.
        if let (Some(n), Some(t)) = (clusters.get_mut(level), triangles.get_mut(level)) {
            *n += 1;
            *t += c.triangle_count as u64;
        }
    }
    println!("{:>5} {:>8} {:>9} {:>10}", "level", "groups", "clusters", "triangles");
    for level in 0..levels {
        println!("{level:>5} {:>8} {:>9} {:>10}", groups[level], clusters[level], triangles[level]);
    }
    Ok(())
}
