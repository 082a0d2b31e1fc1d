//! Picks the view-dependent cut for a camera and prints the clusters and triangles drawn, per
//! level. Reads only the file's resident prefix (header, hierarchy, page table), as a
//! streamer would before fetching any page.
//!
//! ```sh
//! cargo run -p mres-format --example cut -- FILE.mres EYE_X EYE_Y EYE_Z TAU_PX VIEWPORT_HEIGHT [FOV_Y_DEGREES]
//! # e.g. the eye at (0, 0, 2) in the model's object space, 1 px, 1080 lines, 60° field of view:
//! cargo run -p mres-format --example cut -- FILE.mres 0 0 2 1 1080
//! ```

use mres_format::{view_cut, MresIndex, ViewParams, HEADER_SIZE, NO_GROUP};
use std::error::Error;
use std::fs::File;
use std::io::Read;

const USAGE: &str = "usage: cut FILE.mres EYE_X EYE_Y EYE_Z TAU_PX VIEWPORT_HEIGHT [FOV_Y_DEGREES]";

/// Appends bytes of `file` to `bytes` until it holds `len` (fewer if the file ends first).
fn read_up_to(file: &mut File, bytes: &mut Vec<u8>, len: u64) -> std::io::Result<()> {
    let rest = len.saturating_sub(bytes.len() as u64);
    file.by_ref().take(rest).read_to_end(bytes)?;
    Ok(())
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !(6..=7).contains(&args.len()) {
        return Err(USAGE.into());
    }
    let number = |i: usize| args[i].parse::<f32>().map_err(|e| format!("{}: {e}\n{USAGE}", args[i]));
    let eye = [number(1)?, number(2)?, number(3)?];
    let (tau, height) = (number(4)?, number(5)?);
    let fov_y = if args.len() == 7 { number(6)? } else { 60.0 };

    let path = &args[0];
    let mut file = File::open(path).map_err(|e| format!("{path}: {e}"))?;
    // The fixed-size header says how long the resident prefix is.
    let mut prefix = Vec::new();
    read_up_to(&mut file, &mut prefix, HEADER_SIZE as u64)?;
    let prefix_len = MresIndex::prefix_len(&prefix).map_err(|e| format!("{path}: {e}"))?;
    read_up_to(&mut file, &mut prefix, prefix_len)?;
    let index = MresIndex::parse(&prefix).map_err(|e| format!("{path}: {e}"))?;

    let view =
        ViewParams { eye, proj_y: 1.0 / (fov_y.to_radians() * 0.5).tan(), viewport_height: height, z_near: 1e-3 };
    let cut = view_cut(&index.groups, &index.clusters, &view, tau);
    let level = |c: u32| {
        let own = index.clusters[c as usize].own_group;
        if own == NO_GROUP {
            0
        } else {
            index.groups[own as usize].level as usize + 1
        }
    };
    let levels = cut.iter().map(|&c| level(c) + 1).max().unwrap_or(0);
    let (mut clusters, mut triangles) = (vec![0u64; levels], vec![0u64; levels]);
    for &c in &cut {
        clusters[level(c)] += 1;
        triangles[level(c)] += index.clusters[c as usize].triangle_count as u64;
    }
    let mut pages: Vec<u32> =
        cut.iter().map(|&c| index.groups[index.clusters[c as usize].group as usize].page).collect();
    pages.dedup();
    println!("{path}: read {prefix_len} of {} bytes", index.file_size());
    println!("eye {eye:?}, tau {tau} px, viewport height {height} px, fov_y {fov_y}°");
    println!("{:>5} {:>9} {:>10}", "level", "clusters", "triangles");
    for l in 0..levels {
        println!("{l:>5} {:>9} {:>10}", clusters[l], triangles[l]);
    }
    println!(
        "drawn: {} clusters, {} triangles, from {} of {} pages",
        cut.len(),
        triangles.iter().sum::<u64>(),
        pages.len(),
        index.pages.len()
    );
    Ok(())
}
