//! `bake-all` as a pipeline service: cache hits and misses on every key input, overrides,
//! reports, concurrent bakers, a killed baker, corrupt cache entries; settings discovery,
//! stale outputs, skipped files, output checks before any work.

use crate::{run, text, BAKE_ALL, MRES};
use std::path::{Path, PathBuf};
use std::process::Command;

struct Tree {
    _dir: tempfile::TempDir,
    assets: PathBuf,
    out: PathBuf,
    cache: PathBuf,
    report: PathBuf,
}

fn tree() -> Tree {
    let dir = tempfile::tempdir().unwrap();
    let assets = dir.path().join("assets");
    std::fs::create_dir_all(assets.join("scans")).unwrap();
    for (kind, n, rel) in
        [("sphere", "8", "ball.obj"), ("terrain", "16", "scans/ground.obj"), ("boxes", "8", "scans/crates.obj")]
    {
        let o = run(MRES, &["generate", kind, n, "-o", assets.join(rel).to_str().unwrap()]);
        assert!(o.status.success(), "{}", text(&o));
    }
    // An OBJ that references a material library: the .mtl is part of its cache key.
    let obj = std::fs::read_to_string(assets.join("ball.obj")).unwrap();
    std::fs::write(assets.join("painted.obj"), format!("mtllib painted.mtl\n{obj}")).unwrap();
    std::fs::write(assets.join("painted.mtl"), "newmtl m0\nKd 1 0 0\n").unwrap();
    Tree {
        out: dir.path().join("out"),
        cache: dir.path().join("cache"),
        report: dir.path().join("report.json"),
        assets,
        _dir: dir,
    }
}

impl Tree {
    fn bake(&self, extra: &[&str]) -> serde_json::Value {
        let mut args = vec![
            self.assets.to_str().unwrap(),
            "-o",
            self.out.to_str().unwrap(),
            "--cache-dir",
            self.cache.to_str().unwrap(),
            "--report",
            self.report.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = run(BAKE_ALL, &args);
        assert!(o.status.success(), "{}", text(&o));
        serde_json::from_str(&std::fs::read_to_string(&self.report).unwrap()).unwrap()
    }

    fn baked_names(report: &serde_json::Value) -> Vec<String> {
        let mut names: Vec<String> = report["assets"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|a| a["status"] == "baked")
            .map(|a| Path::new(a["input"].as_str().unwrap()).file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }
}

#[test]
fn second_run_bakes_nothing_and_each_key_input_rebakes_exactly_its_assets() {
    let t = tree();
    let first = t.bake(&[]);
    assert_eq!(first["baked"], 4);
    assert_eq!(first["skipped"], 0, "the .mtl is used by painted.obj: not skipped");
    assert_eq!(first["companion_files"], 1);
    let a = &first["assets"][0];
    for field in [
        "input_triangles",
        "level0_triangles",
        "degenerate_dropped",
        "levels",
        "clusters",
        "groups",
        "root_clusters",
        "bytes",
        "bytes_per_input_triangle",
        "seconds",
        "cache_hit",
    ] {
        assert!(!a[field].is_null(), "report lacks {field}");
    }
    let outputs: Vec<Vec<u8>> = ["ball", "painted", "scans/ground", "scans/crates"]
        .iter()
        .map(|n| std::fs::read(t.out.join(format!("{n}.mres"))).unwrap())
        .collect();

    let second = t.bake(&[]);
    assert_eq!(second["baked"], 0);
    assert_eq!(second["cached"], 4);

    // Input bytes: touch one asset.
    let ball = t.assets.join("ball.obj");
    let mut text = std::fs::read_to_string(&ball).unwrap();
    text.push_str("# edited\n");
    std::fs::write(&ball, text).unwrap();
    assert_eq!(Tree::baked_names(&t.bake(&[])), ["ball.obj"]);

    // A referenced file.
    std::fs::write(t.assets.join("painted.mtl"), "newmtl m0\nKd 0 1 0\n").unwrap();
    assert_eq!(Tree::baked_names(&t.bake(&[])), ["painted.obj"]);

    // One setting, for the assets an override matches.
    std::fs::write(t.assets.join("pipeline.toml"), "[[override]]\nglob = \"scans/**\"\nnormal_bits = 8\n").unwrap();
    assert_eq!(Tree::baked_names(&t.bake(&[])), ["crates.obj", "ground.obj"]);
    // A global setting re-bakes everything.
    std::fs::write(t.assets.join("pipeline.toml"), "[bake]\nposition_bits = 15\n").unwrap();
    assert_eq!(t.bake(&[])["baked"], 4);
    // Back to the defaults: everything comes from the cache, byte-identical to the first run.
    std::fs::remove_file(t.assets.join("pipeline.toml")).unwrap();
    std::fs::write(
        &ball,
        std::fs::read(t.assets.join("painted.obj"))
            .unwrap()
            .split(|&b| b == b'\n')
            .skip(1)
            .collect::<Vec<_>>()
            .join(&b'\n'),
    )
    .unwrap();
    std::fs::write(t.assets.join("painted.mtl"), "newmtl m0\nKd 1 0 0\n").unwrap();
    let back = t.bake(&[]);
    assert_eq!(back["baked"], 0, "{back:#}");
    for (n, bytes) in ["ball", "painted", "scans/ground", "scans/crates"].iter().zip(&outputs) {
        assert_eq!(&std::fs::read(t.out.join(format!("{n}.mres"))).unwrap(), bytes, "{n}");
    }
}

#[test]
fn corrupt_cache_entries_are_detected_and_rebaked() {
    let t = tree();
    t.bake(&[]);
    // Flip a byte in every cache entry.
    let mut entries = Vec::new();
    for fan in std::fs::read_dir(&t.cache).unwrap().flatten().filter(|e| e.path().is_dir() && e.file_name() != "tmp") {
        entries.extend(std::fs::read_dir(fan.path()).unwrap().flatten().map(|e| e.path()));
    }
    assert_eq!(entries.len(), 4);
    for e in &entries {
        let mut b = std::fs::read(e).unwrap();
        let n = b.len();
        b[n - 10] ^= 0xff;
        std::fs::write(e, b).unwrap();
    }
    let v = run(MRES, &["cache", "verify", "--cache-dir", t.cache.to_str().unwrap()]);
    assert_eq!(v.status.code(), Some(1), "{}", text(&v));
    assert!(text(&v).contains("4 corrupt"), "{}", text(&v));
    let report = t.bake(&[]);
    assert_eq!(report["baked"], 4);
    assert!(report["assets"].as_array().unwrap().iter().all(|a| a["cache_repaired"] == true));
    let v = run(MRES, &["cache", "verify", "--cache-dir", t.cache.to_str().unwrap()]);
    assert!(v.status.success(), "{}", text(&v));
}

#[test]
fn concurrent_bakers_share_one_cache() {
    let t = tree();
    let out2 = t.out.with_file_name("out2");
    let spawn = |out: &Path| {
        Command::new(BAKE_ALL)
            .args([
                t.assets.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "--cache-dir",
                t.cache.to_str().unwrap(),
                "-q",
            ])
            .spawn()
            .unwrap()
    };
    let (mut a, mut b) = (spawn(&t.out), spawn(&out2));
    assert!(a.wait().unwrap().success() && b.wait().unwrap().success());
    for n in ["ball", "painted", "scans/ground", "scans/crates"] {
        let f = format!("{n}.mres");
        assert_eq!(std::fs::read(t.out.join(&f)).unwrap(), std::fs::read(out2.join(&f)).unwrap(), "{n}");
    }
    let v = run(MRES, &["cache", "verify", "--cache-dir", t.cache.to_str().unwrap()]);
    assert!(v.status.success() && text(&v).contains("0 corrupt"), "{}", text(&v));
}

#[test]
fn a_killed_baker_leaves_the_cache_clean() {
    let t = tree();
    // A bigger asset so that the kill lands mid-bake.
    let big = t.assets.join("big.obj");
    assert!(run(MRES, &["generate", "sphere", "120", "-o", big.to_str().unwrap()]).status.success());
    let mut child = Command::new(BAKE_ALL)
        .args([
            t.assets.to_str().unwrap(),
            "-o",
            t.out.to_str().unwrap(),
            "--cache-dir",
            t.cache.to_str().unwrap(),
            "-q",
        ])
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(300));
    child.kill().unwrap();
    child.wait().unwrap();
    let v = run(MRES, &["cache", "verify", "--cache-dir", t.cache.to_str().unwrap()]);
    assert!(v.status.success() && text(&v).contains("0 corrupt"), "{}", text(&v));
    // No partial outputs: every .mres present validates.
    for e in walk(&t.out) {
        let o = run(MRES, &["validate", e.to_str().unwrap(), "--random-cuts", "10"]);
        assert!(o.status.success(), "{}: {}", e.display(), text(&o));
    }
    // And the next run completes.
    assert_eq!(t.bake(&[])["failed"], 0);
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(walk(&p));
            } else if p.extension().is_some_and(|x| x == "mres") {
                out.push(p);
            }
        }
    }
    out
}

#[test]
fn output_is_identical_for_any_jobs() {
    let t = tree();
    t.bake(&["--no-cache", "--jobs", "1"]);
    let one: Vec<Vec<u8>> = walk(&t.out).iter().map(|p| std::fs::read(p).unwrap()).collect();
    std::fs::remove_dir_all(&t.out).unwrap();
    t.bake(&["--no-cache", "--jobs", "2"]);
    let two: Vec<Vec<u8>> = walk(&t.out).iter().map(|p| std::fs::read(p).unwrap()).collect();
    assert_eq!(one.len(), 4);
    assert_eq!(one, two);
}

/// `bake-all ARGS` in full: exit code and stdout + stderr.
fn bake_all(args: &[&str]) -> (Option<i32>, String) {
    let o = run(BAKE_ALL, args);
    (o.status.code(), text(&o))
}

/// position_bits of a baked file, from `mres inspect --json`.
fn position_bits(file: &Path) -> u64 {
    let o = run(MRES, &["inspect", file.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    v["position_bits"].as_u64().unwrap()
}

#[test]
fn settings_are_found_above_a_subfolder_or_a_file_and_outputs_mirror_the_tree() {
    let t = tree();
    let config = t.assets.join("pipeline.toml");
    std::fs::write(&config, "[bake]\nposition_bits = 12\n[[override]]\nglob = \"scans/**\"\nposition_bits = 14\n")
        .unwrap();
    let canonical = config.canonicalize().unwrap();
    let whole = t.bake(&["--no-cache"]);
    assert_eq!(whole["config"], canonical.to_str().unwrap());
    assert_eq!(position_bits(&t.out.join("ball.mres")), 12);
    let ground = t.out.join("scans/ground.mres");
    assert_eq!(position_bits(&ground), 14);

    // A subfolder: same settings, same override, same output path below the output directory.
    let sub_out = t.out.with_file_name("sub-out");
    let scans = t.assets.join("scans");
    let (code, msg) = bake_all(&[scans.to_str().unwrap(), "-o", sub_out.to_str().unwrap(), "--no-cache"]);
    assert_eq!(code, Some(0), "{msg}");
    assert!(msg.contains(&format!("config: {}", canonical.display())), "{msg}");
    assert_eq!(std::fs::read(sub_out.join("scans/ground.mres")).unwrap(), std::fs::read(&ground).unwrap());
    // One file.
    let file_out = t.out.with_file_name("file-out");
    let obj = scans.join("ground.obj");
    let (code, msg) = bake_all(&[obj.to_str().unwrap(), "-o", file_out.to_str().unwrap(), "--no-cache"]);
    assert_eq!(code, Some(0), "{msg}");
    assert_eq!(std::fs::read(file_out.join("scans/ground.mres")).unwrap(), std::fs::read(&ground).unwrap());
    // --config replaces it; a file outside the tree makes the input directory the root.
    let elsewhere = t.out.with_file_name("cfg");
    std::fs::create_dir_all(&elsewhere).unwrap();
    std::fs::write(elsewhere.join("other.toml"), "[bake]\nposition_bits = 13\n").unwrap();
    let other_out = t.out.with_file_name("other-out");
    let (code, msg) = bake_all(&[
        obj.to_str().unwrap(),
        "-o",
        other_out.to_str().unwrap(),
        "--no-cache",
        "--config",
        elsewhere.join("other.toml").to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{msg}");
    assert!(msg.contains("other.toml"), "{msg}");
    assert_eq!(position_bits(&other_out.join("ground.mres")), 13);
}

#[test]
fn settings_above_the_repository_root_do_not_apply() {
    let t = tree();
    let outer = t.assets.parent().unwrap();
    std::fs::write(outer.join("pipeline.toml"), "[bake]\nposition_bits = 12\n").unwrap();
    std::fs::create_dir(t.assets.join(".git")).unwrap();
    let report = t.bake(&["--no-cache"]);
    assert!(report["config"].is_null(), "{}", report["config"]);
    assert_eq!(position_bits(&t.out.join("ball.mres")), 16);
    let (_, msg) = bake_all(&[t.assets.to_str().unwrap(), "-o", t.out.to_str().unwrap(), "--no-cache"]);
    assert!(msg.contains("config: embedded defaults"), "{msg}");
}

#[test]
fn stale_outputs_are_listed_and_pruned_and_nothing_else_is_touched() {
    let t = tree();
    // Marks the tree's root, so that a subfolder's batch knows where it lies in the tree.
    std::fs::write(t.assets.join("pipeline.toml"), "").unwrap();
    t.bake(&["--no-cache"]);
    std::fs::rename(t.assets.join("ball.obj"), t.assets.join("ball2.obj")).unwrap();
    std::fs::write(t.out.join("notes.txt"), "keep").unwrap();
    let report = t.bake(&["--no-cache"]);
    let stale = t.out.join("ball.mres");
    // The generated OBJ names its material (`usemtl m0`), so it has a scene file too.
    let stale_scene = t.out.join("ball.scene.json");
    assert_eq!(report["stale"], serde_json::json!([stale.to_str().unwrap(), stale_scene.to_str().unwrap()]));
    assert!(stale.is_file(), "listed, not deleted, without --prune");
    let (code, msg) = bake_all(&[t.assets.to_str().unwrap(), "-o", t.out.to_str().unwrap(), "--no-cache"]);
    assert_eq!(code, Some(0));
    assert!(
        msg.contains("warning: 2 stale .mres/scene files") && msg.contains("ball.mres") && msg.contains("--prune"),
        "{msg}"
    );
    // A subfolder's batch only looks at its own part of the output directory.
    let scans = t.assets.join("scans");
    let (_, msg) = bake_all(&[scans.to_str().unwrap(), "-o", t.out.to_str().unwrap(), "--no-cache"]);
    assert!(!msg.contains("stale"), "{msg}");

    let report = t.bake(&["--no-cache", "--prune"]);
    assert_eq!(report["pruned"], serde_json::json!([stale.to_str().unwrap(), stale_scene.to_str().unwrap()]));
    assert!(!stale.exists() && !stale_scene.exists());
    assert!(t.out.join("ball2.mres").is_file() && t.out.join("notes.txt").is_file());
    assert_eq!(walk(&t.out).len(), 4);
}

#[test]
fn skipped_files_are_named_with_the_reason_and_companions_are_not_skipped() {
    let t = tree();
    std::fs::write(t.assets.join("scans/statue.fbx"), "binary").unwrap();
    std::fs::write(t.assets.join("pipeline.toml"), "").unwrap();
    let report = t.bake(&["--no-cache"]);
    assert_eq!(report["skipped"], 1, "{report:#}");
    assert_eq!(report["companion_files"], 2, "painted.mtl and pipeline.toml");
    let skipped = &report["skipped_files"][0];
    assert!(skipped["path"].as_str().unwrap().ends_with("scans/statue.fbx"), "{skipped}");
    assert_eq!(skipped["reason"], "no importer for .fbx files");
    let (_, msg) = bake_all(&[t.assets.to_str().unwrap(), "-o", t.out.to_str().unwrap(), "--no-cache"]);
    assert!(msg.contains("1 files skipped (--verbose names them)") && !msg.contains("statue.fbx"), "{msg}");
    let (_, msg) = bake_all(&[t.assets.to_str().unwrap(), "-o", t.out.to_str().unwrap(), "--no-cache", "--verbose"]);
    assert!(msg.contains("statue.fbx: no importer for .fbx files"), "{msg}");
}

#[test]
fn an_empty_input_fails_and_an_unmatched_glob_warns() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    std::fs::write(empty.join("notes.txt"), "").unwrap();
    let out = dir.path().join("out");
    let (code, msg) = bake_all(&[empty.to_str().unwrap(), "-o", out.to_str().unwrap(), "--no-cache"]);
    assert_eq!(code, Some(1), "{msg}");
    assert!(msg.contains("no assets found under") && msg.contains("empty"), "{msg}");

    let t = tree();
    std::fs::write(
        t.assets.join("pipeline.toml"),
        "[[override]]\nglob = \"scans/**\"\nnormal_bits = 8\n[[override]]\nglob = \"props/**\"\nnormal_bits = 8\n",
    )
    .unwrap();
    let report = t.bake(&["--no-cache"]);
    let unmatched = report["unmatched_overrides"].as_array().unwrap();
    assert_eq!(unmatched.len(), 1, "{unmatched:?}");
    assert!(unmatched[0].as_str().unwrap().contains("\"props/**\" matches no asset"), "{unmatched:?}");
    let (code, msg) = bake_all(&[t.assets.to_str().unwrap(), "-o", t.out.to_str().unwrap(), "--no-cache"]);
    assert_eq!(code, Some(0));
    assert!(msg.contains("warning: ") && msg.contains("props/**"), "{msg}");
}

#[test]
fn an_unusable_output_directory_or_report_fails_before_any_bake() {
    let t = tree();
    let blocker = t.out.with_file_name("blocker");
    std::fs::write(&blocker, "a file, not a directory").unwrap();
    let bad_out = blocker.join("out");
    let (code, msg) = bake_all(&[
        t.assets.to_str().unwrap(),
        "-o",
        bad_out.to_str().unwrap(),
        "--cache-dir",
        t.cache.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(2), "{msg}");
    assert!(msg.contains(bad_out.to_str().unwrap()), "{msg}");
    assert!(!t.cache.exists(), "nothing was baked into the cache");
    let bad_report = blocker.join("r.json");
    let (code, msg) = bake_all(&[
        t.assets.to_str().unwrap(),
        "-o",
        t.out.to_str().unwrap(),
        "--cache-dir",
        t.cache.to_str().unwrap(),
        "--report",
        bad_report.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(2), "{msg}");
    assert!(msg.contains("r.json"), "{msg}");
    assert!(!t.cache.exists() && walk(&t.out).is_empty(), "nothing was baked");
}

#[test]
fn the_log_has_no_colour_codes_when_stderr_is_not_a_terminal() {
    let t = tree();
    let o = Command::new(BAKE_ALL)
        .args([t.assets.to_str().unwrap(), "-o", t.out.to_str().unwrap(), "--no-cache"])
        .env("RUST_LOG", "info")
        .env_remove("NO_COLOR")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("INFO"), "{log}");
    assert!(!log.contains('\u{1b}'), "ANSI escape in a redirected log: {log:?}");
}
