//! The commands as a user runs them: exit codes, messages that name the file, outputs.

use std::path::Path;
use std::process::{Command, Output};

fn run(bin: &str, args: &[&str]) -> Output {
    Command::new(bin).args(args).output().expect("run command")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

const BAKE_ALL: &str = env!("CARGO_BIN_EXE_bake-all");
const MRES: &str = env!("CARGO_BIN_EXE_mres");

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
    assert!(msg.contains("1 other files skipped"), "{msg}");
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
    assert_eq!(report["source_triangles"], 1800);
    let i = run(MRES, &["inspect", file.to_str().unwrap(), "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&i.stdout).expect("json");
    assert_eq!(info["source_triangles"], 1800);
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
    let o = run(MRES, &["bench", obj.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let runs: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(runs[0]["builder"], "mres");
    assert_eq!(runs[1]["builder"], "clusterlod");
    for r in runs.as_array().unwrap() {
        assert_eq!(r["input_triangles"], 3072);
        assert_eq!(r["cut_triangles"][0], 3072, "the cut at error 0 is the original");
        assert!(r["peak_rss_bytes"].as_u64().unwrap() > 0);
    }
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
