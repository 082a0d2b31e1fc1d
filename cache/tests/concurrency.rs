//! Several threads and processes sharing one cache directory, and writers killed mid-put.
//!
//! Child processes are this test binary run again with `--exact <child test>` and an
//! environment variable naming the cache root; without the variable the child tests return at
//! once, so a plain `cargo test` runs them as no-ops.

use std::env;
use std::fs;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::thread;
use std::time::{Duration, Instant, SystemTime};

use cache::{CacheKey, KeyInputs, LocalDisk, Lookup, Storage, DEFAULT_TEMP_GRACE};

/// Cache root for a [`child_writer`] process.
const CHILD_ENV: &str = "MRES_CACHE_CHILD";
/// Writer id for a [`child_writer`] process.
const CHILD_ID_ENV: &str = "MRES_CACHE_CHILD_ID";
/// Cache root for a [`child_endless_writer`] process.
const KILL_CHILD_ENV: &str = "MRES_CACHE_KILL_CHILD";

/// Keys every writer puts; writer `w` also puts its own keys `OWN_BASE * (w + 1) + round`.
const SHARED_KEYS: u32 = 6;
const OWN_BASE: u32 = 1000;
const ROUNDS: u32 = 5;
const WRITERS: u32 = 4;

fn key(n: u32) -> CacheKey {
    let input = n.to_le_bytes();
    CacheKey::new(&KeyInputs {
        input_bytes: &input,
        referenced: vec![("n.txt".into(), n.to_string().into_bytes())],
        settings: "concurrency test",
        format_version: 1,
        baker_version: 1,
    })
}

/// Deterministic content of key `n`, 1 KiB to ~256 KiB, so writes of one key overlap in time.
fn content(n: u32) -> Vec<u8> {
    let len = 1024 + (n as usize * 37_019) % (255 * 1024);
    let mut v: Vec<u8> = (0..len).map(|i| (i as u32 ^ n.wrapping_mul(0x9e37_79b9)) as u8).collect();
    v[..4].copy_from_slice(&n.to_le_bytes());
    v
}

/// What one writer does: for each round, read and put every shared key, then put one own key.
/// Every read must be a miss or the complete, correct content.
fn writer(root: &Path, id: u32) {
    let disk = LocalDisk::open(root).unwrap();
    for round in 0..ROUNDS {
        for s in 0..SHARED_KEYS {
            match disk.get(&key(s)).unwrap() {
                Lookup::Miss => {}
                Lookup::Hit(bytes) => assert!(bytes == content(s), "writer {id}: wrong content for shared key {s}"),
                corrupt => panic!("writer {id}: {corrupt:?} for shared key {s}"),
            }
            disk.put(&key(s), &content(s)).unwrap();
        }
        let own = OWN_BASE * (id + 1) + round;
        disk.put(&key(own), &content(own)).unwrap();
    }
}

fn spawn_child(test: &str, vars: &[(&str, String)]) -> Child {
    let mut cmd = Command::new(env::current_exe().unwrap());
    cmd.args([test, "--exact", "--nocapture", "--test-threads=1"]).stdout(Stdio::piped()).stderr(Stdio::piped());
    for (k, v) in vars {
        cmd.env(k, v);
    }
    cmd.spawn().unwrap()
}

/// Child side of [`threads_and_processes_share_one_cache`].
#[test]
fn child_writer() {
    let Ok(root) = env::var(CHILD_ENV) else { return };
    let id: u32 = env::var(CHILD_ID_ENV).unwrap().parse().unwrap();
    writer(Path::new(&root), id);
}

#[test]
fn threads_and_processes_share_one_cache() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("cache");
    // Writers 0..WRITERS are threads, WRITERS..2*WRITERS are processes; they also race on
    // creating the directory and its marker.
    let children: Vec<Child> = (WRITERS..2 * WRITERS)
        .map(|id| {
            spawn_child("child_writer", &[(CHILD_ENV, root.display().to_string()), (CHILD_ID_ENV, id.to_string())])
        })
        .collect();
    let threads: Vec<_> = (0..WRITERS)
        .map(|id| {
            let root = root.clone();
            thread::spawn(move || writer(&root, id))
        })
        .collect();
    for t in threads {
        t.join().unwrap();
    }
    for child in children {
        let out = child.wait_with_output().unwrap();
        assert!(
            out.status.success(),
            "child writer failed: {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        // The child really ran the writer (and not zero tests because of a bad filter).
        assert!(String::from_utf8_lossy(&out.stdout).contains("1 passed"));
    }

    let disk = LocalDisk::open(&root).unwrap();
    let report = disk.verify(false).unwrap();
    assert!(report.is_clean(), "{report:#?}");
    let expected: Vec<u32> = (0..SHARED_KEYS)
        .chain((0..2 * WRITERS).flat_map(|w| (0..ROUNDS).map(move |r| OWN_BASE * (w + 1) + r)))
        .collect();
    assert_eq!(report.valid, expected.len() as u64);
    for n in expected {
        assert_eq!(disk.get(&key(n)).unwrap(), Lookup::Hit(content(n)), "key {n}");
    }
    let stats = disk.stats().unwrap();
    assert_eq!(stats.temp_files, 0, "a finished put left a temp file");
}

/// Size of each entry [`child_endless_writer`] puts: large enough that a put takes a while.
const BIG: usize = 16 << 20;
const BIG_BASE: u32 = 50_000;

fn big_content(n: u32) -> Vec<u8> {
    let mut v = vec![(n % 251) as u8; BIG];
    v[..4].copy_from_slice(&n.to_le_bytes());
    v
}

/// Child side of [`killed_writer_leaves_no_partial_entry`]: puts large entries until killed.
#[test]
fn child_endless_writer() {
    let Ok(root) = env::var(KILL_CHILD_ENV) else { return };
    let disk = LocalDisk::open(&root).unwrap();
    for n in BIG_BASE.. {
        disk.put(&key(n), &big_content(n)).unwrap();
    }
}

fn temp_files(root: &Path) -> usize {
    fs::read_dir(root.join("tmp")).map_or(0, |d| d.count())
}

#[test]
fn killed_writer_leaves_no_partial_entry() {
    let dir = tempfile::tempdir().unwrap();
    let disk = LocalDisk::open(dir.path()).unwrap();
    let mut leftovers = false;
    for _attempt in 0..4 {
        let mut child = spawn_child("child_endless_writer", &[(KILL_CHILD_ENV, dir.path().display().to_string())]);
        // Kill it mid-put: once at least one entry is complete and the next temp file exists.
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if disk.stats().unwrap().entries > 0 && temp_files(dir.path()) > 0 {
                break;
            }
            assert!(child.try_wait().unwrap().is_none(), "the endless writer exited");
            thread::sleep(Duration::from_micros(200));
        }
        child.kill().unwrap();
        child.wait().unwrap();
        if temp_files(dir.path()) > 0 {
            leftovers = true;
            break;
        }
    }
    assert!(leftovers, "never caught the writer mid-put");

    // No partial entry is visible: every entry verifies and reads back complete and correct.
    let report = disk.verify(false).unwrap();
    assert!(report.is_clean(), "{report:#?}");
    assert!(report.valid > 0);
    let mut hits = 0;
    for n in BIG_BASE..BIG_BASE + 1000 {
        match disk.get(&key(n)).unwrap() {
            Lookup::Hit(bytes) => {
                assert!(bytes == big_content(n), "entry {n} has wrong content");
                hits += 1;
            }
            Lookup::Miss => {}
            corrupt => panic!("entry {n}: {corrupt:?}"),
        }
    }
    assert_eq!(hits, report.valid);

    // The leftover temp files are ignored by stats' entry counts, kept by gc while they could
    // still belong to a live writer, and removed once stale.
    let stats = disk.stats().unwrap();
    assert!(stats.temp_files > 0);
    assert_eq!(stats.entries, report.valid);
    let r = disk.gc(u64::MAX).unwrap();
    assert_eq!((r.temp_removed, r.entries_removed), (0, 0));
    let stale = SystemTime::now() - DEFAULT_TEMP_GRACE - Duration::from_secs(1);
    for t in fs::read_dir(dir.path().join("tmp")).unwrap() {
        fs::File::open(t.unwrap().path()).unwrap().set_modified(stale).unwrap();
    }
    let r = disk.gc(u64::MAX).unwrap();
    assert_eq!((r.temp_removed, r.entries_removed), (stats.temp_files, 0));
    assert_eq!(disk.stats().unwrap().temp_files, 0);
    assert!(disk.verify(false).unwrap().is_clean());
}

/// gc evicting everything while writers put: writers never fail and never see a bad entry.
#[test]
fn gc_racing_writers_never_corrupts() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().to_path_buf();
    LocalDisk::open(&root).unwrap();
    let writers: Vec<_> = (0..2)
        .map(|id| {
            let root = root.clone();
            thread::spawn(move || writer(&root, id))
        })
        .collect();
    let disk = LocalDisk::open(&root).unwrap();
    while !writers.iter().all(|w| w.is_finished()) {
        disk.gc(0).unwrap();
        assert!(disk.verify(false).unwrap().is_clean());
    }
    for w in writers {
        w.join().unwrap();
    }
    assert!(disk.verify(false).unwrap().is_clean());
}
