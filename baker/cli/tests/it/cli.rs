//! The commands as a user runs them: exit codes, messages that name the file, outputs.

use crate::{run, text, BAKE_ALL, MRES};
use std::path::Path;

/// A tree with two good meshes, one broken one and a non-mesh file.
fn asset_tree(dir: &Path) {
    let sub = dir.join("props");
    std::fs::create_dir_all(&sub).unwrap();
    let ok = run(MRES, &["generate", "sphere", "10", "-o", dir.join("ball.obj").to_str().unwrap()]);
    assert!(ok.status.success(), "{}", text(&ok));
    let ok = run(MRES, &["generate", "boxes", "20", "-o", sub.join("crates.obj").to_str().unwrap()]);
    assert!(ok.status.success(), "{}", text(&ok));
    std::fs::write(sub.join("broken.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    std::fs::write(dir.join("notes.txt"), "not a mesh").unwrap();
}

#[test]
fn bake_all_bakes_the_good_reports_the_bad_and_fails() {
    let dir = tempfile::tempdir().unwrap();
    let assets = dir.path().join("assets");
    asset_tree(&assets);
    let out = dir.path().join("out");
    let o = run(BAKE_ALL, &[assets.to_str().unwrap(), "-o", out.to_str().unwrap(), "--no-cache"]);
    let msg = text(&o);
    assert_eq!(o.status.code(), Some(1), "{msg}");
    assert!(msg.contains("broken.obj") && msg.contains("FAILED"), "{msg}");
    assert!(msg.contains("1 files skipped"), "{msg}");
    assert!(out.join("ball.mres").is_file() && out.join("props/crates.mres").is_file());
    assert!(!out.join("props/broken.mres").exists());

    // Each output validates; a corrupted copy does not.
    let ball = out.join("ball.mres");
    let v = run(MRES, &["validate", ball.to_str().unwrap(), "--random-cuts", "100"]);
    assert!(v.status.success(), "{}", text(&v));
    assert!(text(&v).contains("OK"));
    let mut bytes = std::fs::read(&ball).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0x55;
    let bad = dir.path().join("bad.mres");
    std::fs::write(&bad, bytes).unwrap();
    let v = run(MRES, &["validate", bad.to_str().unwrap()]);
    assert!(!v.status.success());
    assert!(text(&v).contains("bad.mres") && text(&v).contains("checksum"), "{}", text(&v));
}

#[test]
fn validate_json_and_inspect() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("t.obj");
    assert!(run(MRES, &["generate", "terrain", "30", "-o", obj.to_str().unwrap()]).status.success());
    let o = run(BAKE_ALL, &[obj.to_str().unwrap(), "-o", dir.path().to_str().unwrap(), "--no-cache"]);
    assert!(o.status.success(), "{}", text(&o));
    let file = dir.path().join("t.mres");
    let v = run(MRES, &["validate", file.to_str().unwrap(), "--json", "--random-cuts", "50"]);
    let report: serde_json::Value = serde_json::from_slice(&v.stdout).expect("json");
    assert_eq!(report["violation_count"], 0);
    assert_eq!(report["random_cuts"], 50);
    assert_eq!(report["input_triangles"], 1800);
    let i = run(MRES, &["inspect", file.to_str().unwrap(), "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&i.stdout).expect("json");
    assert_eq!(info["input_triangles"], 1800);
}

#[test]
fn export_writes_the_cut_as_obj() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("s.obj");
    assert!(run(MRES, &["generate", "sphere", "12", "-o", obj.to_str().unwrap()]).status.success());
    assert!(run(BAKE_ALL, &[obj.to_str().unwrap(), "-o", dir.path().to_str().unwrap(), "--no-cache"]).status.success());
    let file = dir.path().join("s.mres");
    let full = dir.path().join("full.obj");
    let o = run(MRES, &["export", file.to_str().unwrap(), "--error", "0", "-o", full.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let mesh = mres_import::import_file(&full, &Default::default()).unwrap();
    assert_eq!(mesh.triangle_count(), 12 * 12 * 12);
    let coarse = dir.path().join("coarse.obj");
    let o = run(
        MRES,
        &["export", file.to_str().unwrap(), "--camera", "0,0,50", "--tau", "2", "-o", coarse.to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", text(&o));
    let mesh = mres_import::import_file(&coarse, &Default::default()).unwrap();
    assert!(mesh.triangle_count() < 12 * 12 * 12 / 4, "far camera should select a coarse cut");
    let o = run(MRES, &["export", file.to_str().unwrap(), "-o", coarse.to_str().unwrap()]);
    assert!(!o.status.success());
}

#[test]
fn bench_compares_with_clusterlod() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("s.obj");
    assert!(run(MRES, &["generate", "sphere", "16", "-o", obj.to_str().unwrap()]).status.success());
    let report = dir.path().join("bench.json");
    let o = run(MRES, &["bench", obj.to_str().unwrap(), "--report", report.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("3072 input triangles"), "{}", text(&o));
    assert!(text(&o).contains("at equal mean error: geomean"), "{}", text(&o));
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).expect("json");
    let runs = &report["runs"];
    assert_eq!(runs[0]["builder"], "mres");
    assert_eq!(runs[1]["builder"], "clusterlod");
    for r in runs.as_array().unwrap() {
        assert_eq!(r["input_triangles"], 3072);
        let finest = &r["cuts"][0];
        assert_eq!(finest["triangles"], 3072, "the cut at error 0 is the original");
        // Only grid rounding (ours) separates the finest cut from the input.
        assert!(finest["distance"]["max"].as_f64().unwrap() < 1e-4, "{finest}");
        let coarsest = r["cuts"].as_array().unwrap().last().unwrap();
        assert_eq!(coarsest["coarsest"], true);
        assert!(coarsest["distance"]["max"].as_f64().unwrap() > 1e-4, "{coarsest}");
        assert!(r["peak_rss_bytes"].as_u64().unwrap() > 0);
    }
    assert_eq!(report["quality"]["targets"].as_array().unwrap().len(), 5);
    // The view cost beside the LOD chain, ours only.
    let view = &runs[0]["view"];
    assert_eq!(view["full_triangles"], 3072, "{view}");
    assert!(view["dag_triangles"].as_f64().unwrap() > 0.0 && view["chain_triangles"].as_f64().unwrap() > 0.0);
    assert!(runs[1]["view"].is_null());
    assert!(text(&o).contains("view cost at 1 px"), "{}", text(&o));
}

#[test]
fn missing_input_and_bad_config_are_clear_errors() {
    let o = run(BAKE_ALL, &["/nonexistent/assets"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains("/nonexistent/assets"), "{}", text(&o));
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("p.toml");
    std::fs::write(&cfg, "[bake]\nmax_triangles = 1000\n").unwrap();
    let o = run(BAKE_ALL, &[dir.path().to_str().unwrap(), "--config", cfg.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains("p.toml") && text(&o).contains("max_triangles"), "{}", text(&o));
    let o = run(MRES, &["validate", "/nonexistent.mres"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains("/nonexistent.mres"));
}

/// Generates `kind n` as OBJ and bakes it next to it; returns the .mres path.
fn baked(dir: &Path, kind: &str, n: &str) -> std::path::PathBuf {
    let obj = dir.join(format!("{kind}.obj"));
    let o = run(MRES, &["generate", kind, n, "-o", obj.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let o = run(BAKE_ALL, &[obj.to_str().unwrap(), "-o", dir.to_str().unwrap(), "--no-cache"]);
    assert!(o.status.success(), "{}", text(&o));
    dir.join(format!("{kind}.mres"))
}

#[test]
fn export_rejects_bad_numbers_before_writing_anything() {
    let dir = tempfile::tempdir().unwrap();
    let file = baked(dir.path(), "sphere", "6");
    let obj = dir.path().join("cut.obj");
    let (f, o) = (file.to_str().unwrap(), obj.to_str().unwrap());
    for (args, named) in [
        (vec!["--error", "-1"], "-1"),
        (vec!["--error", "nan"], "nan"),
        (vec!["--error", "inf"], "inf"),
        (vec!["--error=-0.5"], "-0.5"),
        (vec!["--camera", "0,0,5", "--tau", "0"], "0"),
        (vec!["--camera", "0,0,5", "--tau", "-2"], "-2"),
        (vec!["--camera", "0,nan,5", "--tau", "1"], "nan"),
        (vec!["--camera", "-1,2", "--tau", "1"], "-1,2"),
        (vec!["--camera", "0,0,5", "--tau", "1", "--height", "0"], "0"),
    ] {
        let mut all = vec!["export", f, "-o", o];
        all.extend(&args);
        let r = run(MRES, &all);
        assert_eq!(r.status.code(), Some(2), "{args:?}: {}", text(&r));
        assert!(text(&r).contains(named) && text(&r).contains("error"), "{args:?}: {}", text(&r));
        assert!(!obj.exists(), "{args:?} wrote {o}");
    }
    let r = run(MRES, &["export", f, "--error", "0", "-o", dir.path().join("missing/cut.obj").to_str().unwrap()]);
    assert_eq!(r.status.code(), Some(2), "{}", text(&r));
    assert!(text(&r).contains("missing/cut.obj"), "{}", text(&r));
    let r = run(MRES, &["generate", "cube", "3", "-o", o]);
    assert_eq!(r.status.code(), Some(2));
    assert!(text(&r).contains("seamed-sphere"), "the error lists the kinds: {}", text(&r));
    let r = run(MRES, &["generate", "sphere", "3", "-o", dir.path().join("missing/s.obj").to_str().unwrap()]);
    assert_eq!(r.status.code(), Some(2), "{}", text(&r));
    assert!(text(&r).contains("missing/s.obj"), "{}", text(&r));
}

#[test]
fn a_damaged_page_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = baked(dir.path(), "sphere", "12");
    let parsed = mres_format::MresFile::open(&file).unwrap();
    // The last page holds level 0, which every command reads.
    let page = parsed.pages.last().unwrap();
    let mut bytes = std::fs::read(&file).unwrap();
    bytes[page.offset as usize + page.compressed_size as usize / 2] ^= 0x5a;
    let bad = dir.path().join("damaged.mres");
    std::fs::write(&bad, bytes).unwrap();
    let obj = dir.path().join("cut.obj");
    for args in [
        vec!["inspect", bad.to_str().unwrap()],
        vec!["inspect", bad.to_str().unwrap(), "--json"],
        vec!["export", bad.to_str().unwrap(), "--error", "0", "-o", obj.to_str().unwrap()],
    ] {
        let r = run(MRES, &args);
        assert_eq!(r.status.code(), Some(2), "{args:?}: {}", text(&r));
        assert!(text(&r).contains("damaged.mres") && text(&r).contains("checksum"), "{args:?}: {}", text(&r));
    }
    assert!(!obj.exists(), "no partial OBJ");
}

#[test]
fn inspect_summarises_levels_and_cuts_without_float_noise() {
    let dir = tempfile::tempdir().unwrap();
    let file = baked(dir.path(), "sphere", "20");
    let r = run(MRES, &["inspect", file.to_str().unwrap(), "--json"]);
    assert!(r.status.success(), "{}", text(&r));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(v["input_triangles"], 4800);
    assert_eq!(v["level0_triangles"], 4800);
    assert_eq!(v["attributes"], serde_json::json!({"normals": true, "uvs": false, "materials": false}));
    let levels = v["per_level"].as_array().unwrap();
    assert_eq!(levels.len() as u64, v["levels"].as_u64().unwrap());
    let sum = |key: &str| levels.iter().map(|l| l[key].as_u64().unwrap()).sum::<u64>();
    assert_eq!(sum("clusters"), v["clusters"].as_u64().unwrap());
    assert_eq!(sum("groups"), v["groups"].as_u64().unwrap());
    assert_eq!(levels[0]["triangles"], 4800);
    let diagonal = v["diagonal"].as_f64().unwrap();
    assert!((diagonal - 12f64.sqrt()).abs() < 1e-3, "a unit sphere's box diagonal: {diagonal}");
    for l in levels.iter().filter(|l| !l["error_max"].is_null()) {
        let (lo, hi) = (l["error_min"].as_f64().unwrap(), l["error_max"].as_f64().unwrap());
        assert!(0.0 < lo && lo <= hi, "{l}");
        assert!((l["error_max_fraction"].as_f64().unwrap() - hi / diagonal).abs() < 1e-6, "{l}");
    }
    let cuts = v["uniform_cuts"].as_array().unwrap();
    assert_eq!(cuts[0]["triangles"], 4800, "the cut at error 0 is level 0");
    let tris: Vec<u64> = cuts.iter().map(|c| c["triangles"].as_u64().unwrap()).collect();
    assert!(tris.windows(2).all(|w| w[0] >= w[1]) && tris.last() < tris.first(), "{tris:?}");

    let r = run(MRES, &["inspect", file.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&r.stdout).into_owned();
    for needle in [
        "4,800 input, 4,800 at level 0, 0 degenerate or duplicate dropped",
        "normals (10-bit octahedral), no UVs, no materials",
        "per level",
        "E / diagonal",
    ] {
        assert!(out.contains(needle), "{needle:?} not in:\n{out}");
    }
    assert_eq!(
        out.lines().filter(|l| l.trim_start().starts_with(|c: char| c.is_ascii_digit())).count(),
        levels.len() + cuts.len(),
        "{out}"
    );
    // No float noise: no number with more than 5 digits after the point.
    let noisy = out
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .find(|w| w.split('.').nth(1).is_some_and(|f| f.len() > 5));
    assert_eq!(noisy, None, "{out}");
}

#[test]
fn every_command_counts_input_triangles_alike_and_reports_degenerates() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("t.obj");
    assert!(run(MRES, &["generate", "terrain", "10", "-o", obj.to_str().unwrap()]).status.success());
    // 200 triangles, plus one with two equal indices (dropped by the importer) and one whose
    // two distinct corners fall on the same grid point (dropped when welding).
    let mut text_obj = std::fs::read_to_string(&obj).unwrap();
    text_obj.push_str("v 0.25 0 0.25\nv 0.2500002 0 0.25\nv 0.3 0 0.35\nf 1 1 2\nf 122 123 124\n");
    std::fs::write(&obj, text_obj).unwrap();
    let (report, cache) = (dir.path().join("r.json"), dir.path().join("cache"));
    let bake = || {
        let o = run(
            BAKE_ALL,
            &[
                obj.to_str().unwrap(),
                "-o",
                dir.path().to_str().unwrap(),
                "--report",
                report.to_str().unwrap(),
                "--cache-dir",
                cache.to_str().unwrap(),
            ],
        );
        assert!(o.status.success(), "{}", text(&o));
        let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        (text(&o), r)
    };
    for (msg, r) in [bake(), bake()] {
        // Baked, then from the cache: the same figures.
        assert!(msg.contains("202 input triangles (2 degenerate or duplicate dropped)"), "{msg}");
        assert_eq!(
            (r["input_triangles"].as_u64(), r["level0_triangles"].as_u64(), r["degenerate_dropped"].as_u64()),
            (Some(202), Some(200), Some(2)),
            "{r:#}"
        );
        assert_eq!(r["assets"][0]["degenerate_dropped"], 2);
    }
    let file = dir.path().join("t.mres");
    let v = run(MRES, &["validate", file.to_str().unwrap(), "--json", "--random-cuts", "10"]);
    let v: serde_json::Value = serde_json::from_slice(&v.stdout).unwrap();
    assert_eq!((v["input_triangles"].as_u64(), v["level0_triangles"].as_u64()), (Some(202), Some(200)));
    let t = run(MRES, &["validate", file.to_str().unwrap(), "--random-cuts", "10"]);
    assert!(
        text(&t).contains("202 input triangles (200 at level 0, 2 degenerate or duplicate dropped)"),
        "{}",
        text(&t)
    );
    let i = run(MRES, &["inspect", file.to_str().unwrap(), "--json"]);
    let i: serde_json::Value = serde_json::from_slice(&i.stdout).unwrap();
    assert_eq!(
        (i["input_triangles"].as_u64(), i["level0_triangles"].as_u64(), i["degenerate_dropped"].as_u64()),
        (Some(202), Some(200), Some(2))
    );
    let bench = dir.path().join("bench.json");
    let b = run(MRES, &["bench", obj.to_str().unwrap(), "--report", bench.to_str().unwrap()]);
    assert!(b.status.success(), "{}", text(&b));
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&bench).unwrap()).unwrap();
    let runs = &report["runs"];
    for r in runs.as_array().unwrap() {
        assert_eq!(r["input_triangles"], 202, "{r}");
    }
    assert_eq!(runs[0]["level0_triangles"], 200);
}

#[test]
fn read_only_commands_print_json_with_json_and_bakers_write_reports() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let r = run(MRES, &["cache", "stats", "--json", "--cache-dir", cache.to_str().unwrap()]);
    assert!(r.status.success(), "{}", text(&r));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(v["entries"], 0);
    let r = run(MRES, &["cache", "verify", "--json", "--cache-dir", cache.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(v["corrupt"], serde_json::json!([]));
    // bench writes its figures with --report FILE, like bake-all; --json is for printing.
    let r = run(MRES, &["bench", "x.obj", "--json"]);
    assert_eq!(r.status.code(), Some(2));
}

/// `mres repack` stores the pages the other way (docs/FORMAT.md §4.4) and back, byte for byte;
/// the layout file validates, reads as the same DAG, and is an ordinary file (not owner-only).
#[test]
fn repack_to_layout_pages_and_back_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let ball = baked(dir.path(), "sphere", "12");
    let layout = dir.path().join("layout.mres");
    let back = dir.path().join("back.mres");
    let (b, l, k) = (ball.to_str().unwrap(), layout.to_str().unwrap(), back.to_str().unwrap());
    let o = run(MRES, &["repack", b, "--pages", "layout", "-o", l]);
    assert!(o.status.success() && text(&o).contains("B per input triangle"), "{}", text(&o));
    let (compact, laid) = (std::fs::read(&ball).unwrap(), std::fs::read(&layout).unwrap());
    assert!(laid.len() > compact.len(), "{} layout bytes, {} compact", laid.len(), compact.len());
    let flags = |bytes: &[u8]| u32::from_le_bytes(bytes[12..16].try_into().unwrap());
    assert_eq!(flags(&laid), flags(&compact) | mres_format::FLAG_LAYOUT_PAGES);
    let v = run(MRES, &["validate", l, "--random-cuts", "50"]);
    assert!(v.status.success(), "{}", text(&v));
    let i = run(MRES, &["inspect", l, "--json"]);
    let summary: serde_json::Value = serde_json::from_slice(&i.stdout).unwrap();
    assert_eq!(summary["page_encoding"], "layout", "{}", text(&i));
    let layouts = |bytes: Vec<u8>| {
        let file = mres_format::MresFile::parse(bytes).unwrap();
        (0..file.pages.len() as u32).map(|p| file.page(p).unwrap()).collect::<Vec<_>>()
    };
    assert_eq!(layouts(laid), layouts(compact.clone()));
    let o = run(MRES, &["repack", l, "--pages", "compact", "-o", k]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(std::fs::read(&back).unwrap(), compact);
    // The same permissions as the baked file's (the umask's), not a temporary file's 0600.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode();
        assert_eq!(mode(&layout), mode(&ball));
    }
    // A damaged input is refused before anything is written.
    let o = run(MRES, &["repack", dir.path().join("none.mres").to_str().unwrap(), "--pages", "layout", "-o", k]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("none.mres"), "{}", text(&o));
    // A damaged page is named once, with the file.
    let mut bytes = compact;
    let last = bytes.len() - 1;
    bytes[last] ^= 0x55;
    let bad = dir.path().join("bad.mres");
    std::fs::write(&bad, bytes).unwrap();
    let o = run(MRES, &["repack", bad.to_str().unwrap(), "--pages", "layout", "-o", k]);
    let msg = text(&o);
    assert_eq!(o.status.code(), Some(2), "{msg}");
    assert!(msg.contains("bad.mres") && msg.matches("checksum mismatch").count() == 1, "{msg}");
}

#[test]
fn thin_geometry_dropped_on_the_grid_is_warned_about_by_file() {
    // A 1000 × 1000 floor and a 1000-long strip beside it, `width` wide, in 20 quads: at 16
    // position bits the grid step is about 0.015, so a strip 0.005 wide collapses to lines.
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, width: f32| {
        let mut obj = String::from("v 0 0 0\nv 1000 0 0\nv 1000 1000 0\nv 0 1000 0\nf 1 2 3\nf 1 3 4\n");
        for k in 0..=20 {
            let x = 50.0 * k as f32;
            obj += &format!("v {x} -10 0\nv {x} {} 0\n", -10.0 + width);
        }
        for k in 0..20 {
            let a = 5 + 2 * k;
            obj += &format!("f {a} {} {}\nf {a} {} {}\n", a + 2, a + 3, a + 3, a + 1);
        }
        let path = dir.path().join(name);
        std::fs::write(&path, obj).unwrap();
        path
    };
    let bake = |path: &Path| {
        let o = run(BAKE_ALL, &[path.to_str().unwrap(), "-o", dir.path().join("out").to_str().unwrap(), "--no-cache"]);
        assert!(o.status.success(), "{}", text(&o));
        text(&o)
    };
    let msg = bake(&write("strip.obj", 0.005));
    assert!(msg.contains("strip.obj") && msg.contains("thinner than the position grid"), "{msg}");
    assert!(msg.contains("40 triangles"), "{msg}");
    let msg = bake(&write("wide.obj", 0.5));
    assert!(!msg.contains("thinner"), "{msg}");
}
