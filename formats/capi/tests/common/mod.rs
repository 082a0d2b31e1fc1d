//! A test file made here: a synthetic two-level DAG large enough for several pages, written by
//! mres-format's writer (no builder needed), and the Rust reader's view of it.

use mres_format::*;

/// Quads per side of one level-0 patch: 8 x 8 quads, 81 vertices, 128 triangles (a full
/// cluster).
const SIDE: i32 = 8;
/// Level-0 groups; each holds four patches and is simplified into one level-1 cluster.
const GROUPS: u32 = 96;

/// A deterministic height field value, so that positions do not compress to nothing.
fn height(x: i32, y: i32) -> i32 {
    let h = (x as u32).wrapping_mul(2_654_435_761) ^ (y as u32).wrapping_mul(40_503);
    (h >> 20) as i32 % 200
}

/// A patch of `side` x `side` quads of `step` grid units with its corner at (`x0`, `y0`).
fn patch(x0: i32, y0: i32, side: i32, step: i32, group: u32, own_group: u32) -> DagCluster {
    let n = side + 1;
    let positions: Vec<[i32; 3]> = (0..n * n)
        .map(|i| {
            let (x, y) = (x0 + (i % n) * step, y0 + (i / n) * step);
            [x, y, height(x, y)]
        })
        .collect();
    let mut indices = Vec::new();
    for j in 0..side {
        for i in 0..side {
            let v = |di: i32, dj: i32| ((j + dj) * n + i + di) as u8;
            indices.extend([v(0, 0), v(1, 0), v(0, 1), v(1, 0), v(1, 1), v(0, 1)]);
        }
    }
    let triangles = indices.len() / 3;
    let uv = UvQuant { min: [0.0, 0.0], extent: [1.0, 1.0] };
    DagCluster {
        group,
        own_group,
        uvs: positions.iter().map(|p| uv.decode(uv.quantize([p[0] as f32 / 4096.0, p[1] as f32 / 4096.0]))).collect(),
        normals: vec![[0.0, 0.0, 1.0]; positions.len()],
        positions,
        indices,
        materials: (0..triangles).map(|t| (t % 3) as u16).collect(),
        // The patch's first triangle has its first two edges on an open border.
        open_edges: (0..triangles).map(|t| if t == 0 { 0b011 } else { 0 }).collect(),
    }
}

/// The DAG: `GROUPS` level-0 groups of four patches each, every group simplified into one
/// coarse patch of the root group.
pub fn dag() -> Dag {
    let (q, span) = (16, 16 * SIDE);
    let mut clusters = Vec::new();
    for g in 0..GROUPS {
        let (gx, gy) = ((g % 8) as i32 * 2 * span, (g / 8) as i32 * 2 * span);
        for k in 0..4 {
            clusters.push(patch(gx + (k % 2) * span, gy + (k / 2) * span, SIDE, q, g, NO_GROUP));
        }
        clusters.push(patch(gx, gy, 2, span, GROUPS, g));
    }
    let grid = Grid { origin: [-1.0, 2.0, 0.5], step: 1.0 / 1024.0 };
    let group = |g: u32, error: f32, level: u32| {
        let center = [(g % 8) as f32 * 0.25 + 0.125, (g / 8) as f32 * 0.25 + 0.125, 0.6];
        Group { sphere: Sphere { center, radius: 0.2 }, error, level, first_cluster: 0, cluster_count: 0, page: 0 }
    };
    let mut groups: Vec<Group> = (0..GROUPS).map(|g| group(g, 0.01 + g as f32 * 1e-4, 0)).collect();
    groups.push(Group { sphere: Sphere { center: [1.0, 0.8, 0.6], radius: 2.0 }, ..group(0, f32::INFINITY, 1) });
    Dag {
        header: Header {
            flags: FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS,
            grid,
            uv: UvQuant { min: [0.0, 0.0], extent: [1.0, 1.0] },
            normal_bits: 12,
            position_bits: 12,
            level_count: 0,
            source_triangles: u64::from(GROUPS) * 4 * 128,
        },
        groups,
        clusters,
    }
}

/// The test file's bytes.
pub fn file() -> Vec<u8> {
    write_mres(&dag(), 3).expect("the synthetic DAG writes")
}

/// FNV-1a 64 over every cluster's arrays, in the order `tests/c/load.c` hashes them.
#[allow(dead_code)] // tests/ffi.rs uses the file alone.
pub fn hash(file: &MresFile) -> u64 {
    let mut h = 14_695_981_039_346_656_037u64;
    let mut byte = |b: u8| h = (h ^ u64::from(b)).wrapping_mul(1_099_511_628_211);
    for c in file.decode_all().expect("decodes") {
        c.positions.iter().flatten().flat_map(|v| v.to_le_bytes()).for_each(&mut byte);
        c.indices.iter().copied().for_each(&mut byte);
        c.materials.iter().flat_map(|m| m.to_le_bytes()).for_each(&mut byte);
        c.open_edges.iter().copied().for_each(&mut byte);
        c.normals.iter().flatten().flat_map(|v| v.to_bits().to_le_bytes()).for_each(&mut byte);
        c.uvs.iter().flatten().flat_map(|v| v.to_bits().to_le_bytes()).for_each(&mut byte);
    }
    h
}
