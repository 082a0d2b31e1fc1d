//! End-to-end bakes: generated and real meshes are baked, then proved by the
//! validator — crack-free cuts at every uniform threshold and at random cameras, monotone
//! errors, nested spheres, intact pages — with one root.

use mres_build::bake::{bake as bake_source, bake_file};
use mres_build::settings::PreserveArea;
use mres_build::BakeSettings;
use mres_check::validate::{validate, Report, ValidateOptions};
use mres_cli::generate;
use mres_format::{select, MresFile, MresIndex, NO_GROUP};
use mres_import::SourceMesh;
use std::path::{Path, PathBuf};

fn check(bytes: Vec<u8>, random_cuts: usize) -> (MresFile, Report) {
    let file = MresFile::parse(bytes).expect("baked file parses");
    let report = validate(&file, &ValidateOptions { random_cuts, ..Default::default() }).expect("pages decode");
    assert!(report.ok(), "violations: {:#?}", report.violations);
    assert_eq!(report.root_groups, 1, "one root group");
    assert!(report.uniform_cuts >= 2 && report.random_cuts == random_cuts as u64);
    (file, report)
}

fn bake(mesh: SourceMesh) -> Vec<u8> {
    bake_source(mesh, &BakeSettings::default(), &|_| {}).expect("bake").bytes
}

#[test]
fn closed_sphere_reaches_one_root_cluster() {
    let (file, report) = check(bake(generate::sphere(40)), 300);
    assert_eq!(report.root_clusters, 1);
    assert!(report.level0_fill >= 120.0, "fill {}", report.level0_fill);
    assert!(report.levels >= 5);
    // Triangles halve level by level, roughly.
    let t: Vec<u64> = report.per_level.iter().map(|l| l.triangles).collect();
    assert!(t[1] * 10 < t[0] * 6 && t[1] * 10 > t[0] * 4, "level triangles {t:?}");
    assert_eq!(file.header.source_triangles, 19200);
}

#[test]
fn a_lone_top_cluster_simplifies_on_as_a_root_chain_not_counted_in_the_depth() {
    let (file, report) = check(bake(generate::sphere(40)), 100);
    let first_single = report.per_level.iter().position(|l| l.clusters == 1).expect("a single cluster");
    // Above the first single cluster, one cluster a level, each at most about half the last,
    // down to 16 triangles or fewer (the sphere can go that far).
    let chain = &report.per_level[first_single..];
    assert!(chain.len() >= 3, "root chain {chain:?}");
    for w in chain.windows(2) {
        assert!(w[1].clusters == 1 && w[1].triangles * 100 <= w[0].triangles * 85, "root chain {chain:?}");
    }
    let root = chain.last().unwrap().triangles;
    assert!(root <= 16, "root of {root} triangles");
    assert_eq!(select::uniform_cut(&file.groups, &file.clusters, f32::MAX).len(), 1);
    // The depth counts the levels down to the first single cluster only.
    let depth_violations = |depth_slack: f64| {
        let thresholds = mres_check::tables::Thresholds { max_depth_factor: 0.0, depth_slack, ..Default::default() };
        let options = ValidateOptions { random_cuts: 0, thresholds, ..Default::default() };
        let report = validate(&file, &options).expect("pages decode");
        report.violations.iter().filter(|v| v.contains("DAG depth")).count()
    };
    assert_eq!(depth_violations(first_single as f64 + 1.0), 0);
    assert_eq!(depth_violations(first_single as f64), 1);
}

#[test]
fn open_terrain_simplifies_its_boundary_to_one_root_cluster() {
    // The terrain's 400 open rim edges are simplified along themselves (marked open-border
    // edges, docs/INVARIANTS.md §1), so the coarsest cut is one small cluster; the validator
    // checks the marks and every cut.
    let (file, report) = check(bake(generate::terrain(100)), 300);
    assert_eq!(report.root_clusters, 1);
    let coarsest = select::uniform_cut(&file.groups, &file.clusters, f32::MAX);
    let triangles: u64 = coarsest.iter().map(|&c| file.clusters[c as usize].triangle_count as u64).sum();
    assert!(triangles <= 128, "coarsest cut has {triangles} triangles");
}

#[test]
fn thousand_disconnected_boxes_reach_one_root_cluster() {
    let (_, report) = check(bake(generate::boxes(1000, 4)), 200);
    assert_eq!(report.root_clusters, 1);
    assert!(report.level0_fill >= 120.0, "fill {}", report.level0_fill);
}

#[test]
fn errors_of_groups_whose_parts_all_vanished_do_not_add_up() {
    // 250 flat boxes: their simplification is exact, and a box that vanishes counts its own
    // size at most (docs/INVARIANTS.md §4), so no group's error exceeds the largest box's
    // diagonal. At the top levels every level-0 sample has vanished; measured against their
    // members plus the members' errors instead of the original, the errors added up level by
    // level (1.5 to 7.4).
    let mesh = generate::boxes(250, 4);
    let per_box = mesh.positions.len() / 250;
    let diagonal = |points: &[[f32; 3]]| {
        let (lo, hi) = mres_import::mesh::bounds(points).expect("a box has corners");
        (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f32>().sqrt()
    };
    let largest = mesh.positions.chunks_exact(per_box).map(diagonal).fold(0.0, f32::max);
    let (file, _) = check(bake(mesh), 50);
    let errors: Vec<f32> = file.groups.iter().map(|g| g.error).filter(|e| e.is_finite()).collect();
    let worst = errors.iter().copied().fold(0.0, f32::max);
    // The baker's part sizes are of the welded positions, on the 16-bit grid: 1e-3 for that.
    assert!(worst <= largest * 1.001, "group error {worst} beyond the largest box's diagonal {largest}: {errors:?}");
}

#[test]
fn uv_seams_and_materials_survive() {
    let mesh = generate::seamed_sphere(30);
    let per_material = 2 * 30 * 30;
    let (file, report) = check(bake(mesh), 200);
    assert_eq!(report.root_clusters, 1, "seams must not stop simplification");
    assert_ne!(file.header.flags & mres_format::FLAG_MATERIALS, 0);
    let decoded = file.decode_all().unwrap();
    let mut counts = [0usize; 6];
    for (d, info) in decoded.iter().zip(&file.clusters) {
        if info.own_group == NO_GROUP {
            for &m in &d.materials {
                counts[m as usize] += 1;
            }
            assert_eq!(d.uvs.len(), d.positions.len());
        }
    }
    assert_eq!(counts, [per_material; 6]);
}

#[test]
fn foliage_keeps_its_area_with_preserve_area() {
    // 3,000 cards: coarse levels remove most of them. With `preserve_area` the cards kept grow
    // so that every cut keeps about the card area of full detail; without it the coarsest cut
    // keeps a few percent. Both validate (crack-free, honest errors, one root).
    let cuts = [0.05, 0.2, f32::MAX];
    let area = |preserve_area: PreserveArea, shard_triangles: u64| {
        let settings = BakeSettings { preserve_area, shard_triangles, ..BakeSettings::default() };
        let bytes = bake_source(generate::cards(3000), &settings, &|_| {}).expect("bake").bytes;
        let (file, report) = check(bytes, 200);
        assert!(report.honesty.worst_ratio <= 1.0, "honesty {}", report.honesty.worst);
        mres_cli::inspect::cut_area_fractions(&file, &cuts).expect("pages decode")
    };
    let whole = BakeSettings::default().shard_triangles;
    let plain = area(PreserveArea::Off, whole);
    assert!(plain[2] < 0.1, "without preserve_area the coarsest cut keeps {plain:?}");
    // Whole, and in shards of 2,000 triangles (the merged stages grow the parts on).
    for grown in [area(PreserveArea::On, whole), area(PreserveArea::On, 2000)] {
        for (cut, kept) in cuts.iter().zip(&grown) {
            assert!((0.6..1.6).contains(kept), "cut at {cut}: area kept {kept} (all: {grown:?})");
        }
    }
}

#[test]
fn a_mesh_far_from_the_origin_gets_the_errors_it_gets_at_the_origin() {
    // A unit sphere 2,000 radii from the origin (a part placed in map or world coordinates):
    // the rounding of the measure's distances depends on the mesh's size, not on where it
    // lies. Before, every error included 64 ulps of the largest coordinate (0.015 here: the
    // median group error was 0.024 against 0.010 at the origin; 32 m on a terrain in map
    // coordinates).
    let near = generate::sphere(24);
    let mut far = near.clone();
    for p in &mut far.positions {
        p[0] += 2000.0;
    }
    let median_error = |mesh: SourceMesh| {
        let (file, report) = check(bake(mesh), 100);
        assert!(report.honesty.worst_ratio <= 1.0, "honesty {}", report.honesty.worst);
        let mut errors: Vec<f32> = file.groups.iter().map(|g| g.error).filter(|e| e.is_finite()).collect();
        errors.sort_by(f32::total_cmp);
        errors[errors.len() / 2]
    };
    let (at_origin, away) = (median_error(near), median_error(far));
    assert!(away <= 1.25 * at_origin, "median group error {away} away from the origin, {at_origin} at it");
}

/// A 10 × 10 floor and a 10 × 5 wall standing on it at `wall_y` (0: on one of its edges, an
/// L; 5: on its middle line, a T), grids of `n` squares per 10 units, the wall's triangles
/// wound like the floor's in its own plane: on the floor's edge the two sides' half-edges run
/// the same way (one panel is flipped, as in many exported scenes).
fn floor_and_wall(n: u32, wall_y: f32) -> SourceMesh {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    let mut panel = |rows: u32, at: &dyn Fn(f32, f32) -> [f32; 3]| {
        let base = positions.len() as u32;
        let step = 10.0 / n as f32;
        for j in 0..=rows {
            for i in 0..=n {
                positions.push(at(i as f32 * step, j as f32 * step));
            }
        }
        let id = |i: u32, j: u32| base + j * (n + 1) + i;
        for j in 0..rows {
            for i in 0..n {
                indices.extend([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    };
    panel(n, &|u, v| [u, v, 0.0]);
    panel(n / 2, &|u, v| [u, wall_y, v]);
    SourceMesh::positions_only(positions, indices)
}

#[test]
fn a_wall_on_a_flipped_floor_simplifies_without_folding() {
    // The regular simplifier cannot collapse along the fold (its half-edges do not pair) and
    // once the panels are fans on it, it folds the wall onto the floor (an error of half the
    // diagonal); the permissive run collapses along it.
    assert_small_and_accurate(floor_and_wall(80, 0.0));
}

#[test]
fn a_wall_standing_inside_a_floor_simplifies_along_its_foot() {
    // The wall's foot is an edge of three triangles (two of the floor, one of the wall) at
    // every step, so its positions are locked as non-manifold. Once the rest is simplified,
    // the group's only result folded the wall (297 triangles at every error up to a third of
    // the diagonal); a result that jumps so far above its members' error is now tried again
    // with those positions unlocked, and the smaller error is kept.
    assert_small_and_accurate(floor_and_wall(80, 5.0));
}

#[test]
fn a_wall_with_normals_standing_inside_a_floor_simplifies() {
    // With normals the foot is an attribute seam too (the floor's vertices face up, the
    // wall's sideways): meshoptimizer keeps such a position where it is even unlocked, and the
    // regular run folded the wall (298 triangles up to a third of the diagonal). A regular
    // result that folds gets the permissive run beside it, with attributes as without.
    let mut mesh = floor_and_wall(80, 5.0);
    let floor = 81 * 81;
    let normal = |v: usize| if v < floor { [0.0, 0.0, 1.0] } else { [0.0, 1.0, 0.0] };
    mesh.normals = Some((0..mesh.positions.len()).map(normal).collect());
    assert_small_and_accurate(mesh);
}

#[test]
fn crossing_walls_with_normals_and_uvs_inside_a_floor_simplify() {
    // Three sheets with their own normals and UVs meet on the feet and the crossing line: unlocked,
    // those positions still stay put in a regular run, and the top groups folded the walls
    // (the root 1.6 % of the diagonal from the input). The lenient run (stuck, or jumped) tries
    // the permissive run beside the regular one where there are attributes.
    let mut mesh = generate::walls(80);
    let (floor, wall) = (81 * 81, 81 * 41);
    let normal = |v: usize| match v {
        v if v < floor => [0.0, 0.0, 1.0],
        v if v < floor + wall => [0.0, 1.0, 0.0],
        _ => [1.0, 0.0, 0.0],
    };
    mesh.normals = Some((0..mesh.positions.len()).map(normal).collect());
    // Each sheet's own UVs: (column, row) over its grid.
    let uv = |v: usize| {
        let (local, rows) = if v < floor { (v, 80) } else { ((v - floor) % wall, 40) };
        [(local % 81) as f32 / 80.0, (local / 81) as f32 / rows as f32]
    };
    mesh.uvs = Some((0..mesh.positions.len()).map(uv).collect());
    // The stored errors count meshoptimizer's attribute error (the normals' seams are gone),
    // so the measured distance of the coarsest cut tells whether the shape is kept.
    let diagonal = mres_cli::bench::diagonal(&mesh);
    let input = mres_cli::bench::triangles(&mesh);
    // Some cut of at most 128 triangles (the top of the hierarchy, or a link of the root chain
    // above it) keeps the shape: within 1e-3 × diagonal of the input.
    let built = mres_cli::bench::run_mres(mesh, &BakeSettings::default()).expect("bake");
    let thresholds = (0..=40).map(|k| diagonal as f32 * 10f32.powf(-4.0 + k as f32 * 0.1));
    let small = thresholds.map(|t| (built.cut)(t)).filter(|cut| cut.len() <= 128);
    let nearest = small.map(|cut| mres_check::distance::two_sided(&cut, &input, 50_000).scaled(diagonal).max);
    let nearest = nearest.fold(f64::INFINITY, f64::min);
    assert!(nearest < 1e-3, "the nearest cut of at most 128 triangles is {nearest} × diagonal from the input");
}

#[test]
fn a_book_of_pages_on_one_spine_simplifies() {
    // Eight flat pages share the spine: each of its edges is used by eight triangles, every
    // spine position is locked as non-manifold, and the top groups folded pages onto each
    // other (8.6 × clusterlod's triangles at equal measured error on a larger book).
    let mut book = SourceMesh::positions_only(Vec::new(), Vec::new());
    for page in 0..8 {
        let angle = std::f32::consts::PI * 0.8 * page as f32 / 7.0;
        let (along, out) = ([0.0, 0.0, 10.0], [5.0 * angle.cos(), 5.0 * angle.sin(), 0.0]);
        generate::panel(&mut book, ([0.0; 3], along, out), (40, 20), &|_, _| false);
    }
    assert_small_and_accurate(book);
}

/// Bakes `mesh` and checks it: the cut at 1e-3 × diagonal keeps at most 128 triangles, and no
/// group below the root chain (the levels up to the first single cluster, whose top folds
/// nothing) has an error of 1 % of the diagonal.
fn assert_small_and_accurate(mesh: SourceMesh) {
    let diagonal = mres_cli::bench::diagonal(&mesh) as f32;
    let (file, report) = check(bake(mesh), 100);
    let cut = select::uniform_cut(&file.groups, &file.clusters, 1e-3 * diagonal);
    let triangles: u64 = cut.iter().map(|&c| file.clusters[c as usize].triangle_count as u64).sum();
    assert!(triangles <= 128, "the cut at 1e-3 × diagonal keeps {triangles} triangles");
    // The validator's depth: the levels down to the first single cluster.
    let first_single = report.conditioning.depth - 1;
    let below = file.groups.iter().filter(|g| g.level < first_single).map(|g| g.error);
    assert!(below.fold(0.0f32, f32::max) < 0.01 * diagonal, "levels {:?}", report.per_level);
}

#[test]
fn auto_preserve_area_grows_a_card_field_and_leaves_a_closed_mesh_as_it_is() {
    // "auto" decides per mesh: a card field (all of its area in small open parts) bakes as
    // with it on, a closed sphere and a terrain (one large open part) as with it off.
    let with = |preserve_area| BakeSettings { preserve_area, ..BakeSettings::default() };
    let bytes = |mesh: fn() -> SourceMesh, setting| bake_source(mesh(), &with(setting), &|_| {}).expect("bake").bytes;
    let cards = || generate::cards(1000);
    let on = bytes(cards, PreserveArea::On);
    assert_ne!(on, bytes(cards, PreserveArea::Off), "the cards grow with it on");
    assert_eq!(bytes(cards, PreserveArea::Auto), on);
    for mesh in [(|| generate::sphere(20)) as fn() -> SourceMesh, || generate::terrain(40)] {
        assert_eq!(bytes(mesh, PreserveArea::Auto), bytes(mesh, PreserveArea::Off));
    }
}

/// Writes a glTF with two primitives (a sphere with normals, a terrain with UVs) in one mesh,
/// instanced by two nodes with different transforms, buffers as a data URI.
fn write_two_primitive_gltf(dir: &Path) -> PathBuf {
    use base64::Engine;
    let a = generate::sphere(8);
    let b = generate::terrain(16);
    let mut buffer: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut push =
        |data: Vec<u8>, count: usize, kind: &str, component: u32, target: u32, minmax: Option<([f32; 3], [f32; 3])>| {
            let offset = buffer.len();
            buffer.extend_from_slice(&data);
            while !buffer.len().is_multiple_of(4) {
                buffer.push(0);
            }
            views
                .push(format!(r#"{{"buffer":0,"byteOffset":{offset},"byteLength":{},"target":{target}}}"#, data.len()));
            let bounds = minmax.map_or(String::new(), |(lo, hi)| format!(r#","min":{lo:?},"max":{hi:?}"#));
            accessors.push(format!(
                r#"{{"bufferView":{},"componentType":{component},"count":{count},"type":"{kind}"{bounds}}}"#,
                views.len() - 1
            ));
            accessors.len() - 1
        };
    let floats = |v: &[[f32; 3]]| v.iter().flatten().flat_map(|f| f.to_le_bytes()).collect::<Vec<u8>>();
    let ints = |v: &[u32]| v.iter().flat_map(|i| i.to_le_bytes()).collect::<Vec<u8>>();
    let pa = push(floats(&a.positions), a.positions.len(), "VEC3", 5126, 34962, a.bounds());
    let na = push(floats(a.normals.as_ref().unwrap()), a.positions.len(), "VEC3", 5126, 34962, None);
    let ia = push(ints(&a.indices), a.indices.len(), "SCALAR", 5125, 34963, None);
    let pb = push(floats(&b.positions), b.positions.len(), "VEC3", 5126, 34962, b.bounds());
    let uv: Vec<u8> = b.uvs.as_ref().unwrap().iter().flatten().flat_map(|f| f.to_le_bytes()).collect();
    let tb = push(uv, b.positions.len(), "VEC2", 5126, 34962, None);
    let ib = push(ints(&b.indices), b.indices.len(), "SCALAR", 5125, 34963, None);
    let uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&buffer));
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0,1]}}],
"nodes":[{{"mesh":0,"translation":[10,0,0],"scale":[2,2,2]}},{{"mesh":0,"translation":[-10,0,0]}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":{pa},"NORMAL":{na}}},"indices":{ia},"material":0}},
{{"attributes":{{"POSITION":{pb},"TEXCOORD_0":{tb}}},"indices":{ib},"material":1}}]}}],
"materials":[{{}},{{}}],
"buffers":[{{"byteLength":{},"uri":"{uri}"}}],"bufferViews":[{}],"accessors":[{}]}}"#,
        buffer.len(),
        views.join(","),
        accessors.join(",")
    );
    let path = dir.join("two_primitives.gltf");
    std::fs::write(&path, json).unwrap();
    path
}

#[test]
fn gltf_with_two_primitives_and_node_transforms() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_two_primitive_gltf(dir.path());
    let baked = bake_file(&path, &BakeSettings::default(), &|_| {}).expect("bake glTF");
    assert_eq!(baked.stats.source_triangles, 2 * (768 + 512));
    let (file, _) = check(baked.bytes, 200);
    // Instances at x = +10 (scaled 2: sphere radius 2, terrain 0..2) and x = -10.
    let decoded = file.decode_all().unwrap();
    let xs: Vec<f32> =
        decoded.iter().flat_map(|d| d.positions.iter().map(|q| file.header.grid.decode(*q)[0])).collect();
    let (lo, hi) = xs.iter().fold((f32::MAX, f32::MIN), |(l, h), &x| (l.min(x), h.max(x)));
    assert!((lo - -11.0).abs() < 1e-3 && (hi - 12.0).abs() < 1e-3, "x range {lo}..{hi}");
    assert!(xs.iter().all(|&x| !(-8.9..=7.9).contains(&x)), "geometry between the instances");
}

fn asset(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets").join(rel)
}

#[test]
fn real_meshes_validate() {
    for (rel, closed) in [
        ("scans/nefertiti.glb", true),
        ("scans/hammer_rawscan.glb", true),
        ("scans/demosthenes_photoscan.obj", false),
        ("models/flight_helmet.glb", false),
    ] {
        let baked = bake_file(&asset(rel), &BakeSettings::default(), &|_| {}).unwrap_or_else(|e| panic!("{rel}: {e}"));
        let (_, report) = check(baked.bytes, 200);
        if closed {
            assert_eq!(report.root_clusters, 1, "{rel}");
        }
        assert!(report.level0_fill >= 115.0, "{rel}: fill {}", report.level0_fill);
    }
}

#[test]
fn output_is_identical_for_any_thread_count() {
    let path = asset("models/flight_helmet.glb");
    let bake_with = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| bake_file(&path, &BakeSettings::default(), &|_| {}).unwrap().bytes)
    };
    let one = bake_with(1);
    assert_eq!(one, bake_with(2));
    assert_eq!(one, bake_with(4));
    assert_eq!(one, bake_with(1), "repeat run");
}

/// `page_encoding = "layout"` stores every page as its GPU layout (docs/FORMAT.md §4.4): the
/// default bake's layouts, each page decoding alone, in more bytes; the same bytes at any
/// thread count.
#[test]
fn layout_pages_hold_the_default_bakes_layouts() {
    let mesh = || generate::sphere(60);
    let compact = MresFile::parse(bake(mesh())).unwrap();
    let settings = BakeSettings { page_encoding: mres_build::settings::PageEncoding::Layout, ..Default::default() };
    let bake_with = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| bake_source(mesh(), &settings, &|_| {}).expect("bake").bytes)
    };
    let layout = bake_with(1);
    assert_eq!(layout, bake_with(4));
    assert!(layout.len() > compact.file_size());
    let index = MresIndex::parse(&layout).unwrap();
    assert_eq!(index.header.flags & mres_format::FLAG_LAYOUT_PAGES, mres_format::FLAG_LAYOUT_PAGES);
    assert!(compact.pages.len() > 1 && index.pages.len() == compact.pages.len());
    for p in 0..index.pages.len() as u32 {
        let r = index.page_range(p).unwrap();
        let page = index.decode_page(p, &layout[r.start as usize..r.end as usize], &[]).expect("decodes alone");
        assert_eq!(page.bytes, compact.page(p).unwrap(), "page {p}: the same GPU layout");
    }
}

/// `independent_pages = true` writes no far copy (docs/FORMAT.md §4.3): every page decodes
/// alone, to the same GPU layout as the default bake's, which has pages that need their
/// sources and is smaller.
#[test]
fn independent_pages_decode_alone() {
    let mesh = || generate::sphere(60);
    let far = bake(mesh());
    let settings = BakeSettings { independent_pages: true, ..Default::default() };
    let alone = bake_source(mesh(), &settings, &|_| {}).expect("bake").bytes;
    assert!(far.len() < alone.len(), "{} bytes with far copies, {} without", far.len(), alone.len());
    let (index_far, index_alone) = (MresIndex::parse(&far).unwrap(), MresIndex::parse(&alone).unwrap());
    assert_eq!(index_far.pages.len(), index_alone.pages.len());
    let whole = MresFile::parse(far.clone()).unwrap();
    let fetch = |bytes: &[u8], index: &MresIndex, p: u32| {
        let r = index.page_range(p).unwrap();
        bytes[r.start as usize..r.end as usize].to_vec()
    };
    let mut needing = 0;
    for p in 0..index_far.pages.len() as u32 {
        // A reference flag 2 would need the page's sources: decoding without them proves none.
        let page = index_alone.decode_page(p, &fetch(&alone, &index_alone, p), &[]).expect("decodes alone");
        assert_eq!(page.bytes, whole.page(p).unwrap(), "page {p}: the same GPU layout");
        needing += index_far.decode_page(p, &fetch(&far, &index_far, p), &[]).is_err() as usize;
    }
    assert!(needing > 0, "the default bake has no far copies");
}

#[test]
fn the_dag_draws_fewer_triangles_than_the_lod_chain_and_the_view_cost_follows_stored_errors() {
    // What a renderer draws at 1 px (copies from near to far): the DAG's view cuts against a
    // discrete LOD chain of the same level-0 mesh, both with honest errors (the DAG must beat
    // the chain). A terrain: 0.70 of the chain (docs/BENCHMARKS.md "View cost" lists where
    // the DAG does not win: the smallest meshes, cards, a mesh of defects).
    let mut file = MresFile::parse(bake(generate::terrain(100))).expect("parses");
    let chain = mres_check::lod_chain::LodChain::build(&file, 128, usize::MAX).expect("chain");
    let cost = mres_cli::view_cost::view_cost(&file, &chain);
    assert_eq!(cost.full_triangles, 20000);
    assert!(cost.chain_errors.len() >= 5 && cost.chain_errors.windows(2).all(|w| w[0] <= w[1]), "{cost:?}");
    assert!(cost.dag_triangles < cost.chain_triangles, "dag {} chain {}", cost.dag_triangles, cost.chain_triangles);
    // Near copies draw more than far ones, for both.
    let (near, far) = (cost.per_distance[0], cost.per_distance[cost.per_distance.len() - 1]);
    assert!(near.1 > far.1 && near.2 > far.2, "{near:?} {far:?}");
    // Looser stored errors draw more: four times the errors, and the DAG no longer wins.
    for g in &mut file.groups {
        g.error *= 4.0;
    }
    let loose = mres_cli::view_cost::view_cost(&file, &chain);
    assert!(loose.dag_triangles > cost.chain_triangles, "loose {} chain {}", loose.dag_triangles, cost.chain_triangles);
}

#[test]
fn the_lod_chain_depends_on_level_0_alone_not_on_the_page_layout() {
    // Two bakes with the same level 0 (group size changes only the levels above, and so how
    // the clusters are laid into pages) give the same chain: the benchmark's reference does not
    // move with the DAG it is compared with.
    let chain = |group_size| {
        let settings = BakeSettings { group_size, ..Default::default() };
        let bytes = bake_source(generate::sphere(40), &settings, &|_| {}).expect("bake").bytes;
        let file = MresFile::parse(bytes).expect("parses");
        let order: Vec<u32> =
            (0..file.clusters.len() as u32).filter(|&c| file.clusters[c as usize].own_group == NO_GROUP).collect();
        (order, mres_check::lod_chain::LodChain::build(&file, 128, usize::MAX).expect("chain"))
    };
    let ((order_a, a), (order_b, b)) = (chain(16), chain(6));
    assert_ne!(order_a, order_b, "the two bakes lay level 0 out alike: the test shows nothing");
    assert_eq!(a.levels, b.levels);
    assert_eq!((a.positions, a.indices), (b.positions, b.indices));
}
