use std::fs::{self, File};
use std::time::{Duration, SystemTime};

use super::*;
use crate::{KeyInputs, ENTRY_MAGIC};

fn key(n: u32) -> CacheKey {
    let input = n.to_le_bytes();
    CacheKey::new(&KeyInputs {
        input_bytes: &input,
        referenced: vec![],
        settings: "",
        format_version: 1,
        baker_version: 1,
    })
}

fn content(n: u32, len: usize) -> Vec<u8> {
    (0..len).map(|i| (i as u32).wrapping_mul(2654435761).wrapping_add(n) as u8).collect()
}

fn set_mtime(path: &Path, t: SystemTime) {
    File::open(path).unwrap().set_modified(t).unwrap();
}

fn mtime(path: &Path) -> SystemTime {
    fs::metadata(path).unwrap().modified().unwrap()
}

#[test]
fn open_creates_layout_and_reopens() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("a/b/cache");
    let disk = LocalDisk::open(&root).unwrap();
    assert_eq!(fs::read_to_string(root.join(MARKER)).unwrap(), marker_text());
    assert!(root.join(TMP_DIR).is_dir());
    // No temp file left over from writing the marker.
    assert_eq!(disk.stats().unwrap(), Stats::default());
    disk.put(&key(1), b"x").unwrap();
    let again = LocalDisk::open(&root).unwrap();
    assert_eq!(again.get(&key(1)).unwrap(), Lookup::Hit(b"x".to_vec()));
    // The parent now holds a cache directory, so it is not one itself.
    LocalDisk::open(dir.path().join("a/b")).unwrap_err();
    // An existing empty directory is fine.
    let empty = dir.path().join("empty");
    fs::create_dir(&empty).unwrap();
    LocalDisk::open(&empty).unwrap();
}

#[test]
fn open_refuses_unknown_layout_and_leaves_it_alone() {
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join(MARKER), "mres-cache layout 99\n").unwrap();
    fs::write(dir.path().join("keep.txt"), "mine").unwrap();
    match LocalDisk::open(dir.path()) {
        Err(CacheError::UnknownLayout { found, .. }) => assert_eq!(found, "mres-cache layout 99"),
        other => panic!("expected UnknownLayout, got {other:?}"),
    }
    assert_eq!(fs::read_to_string(dir.path().join(MARKER)).unwrap(), "mres-cache layout 99\n");
    assert_eq!(fs::read_to_string(dir.path().join("keep.txt")).unwrap(), "mine");
}

#[test]
fn open_refuses_a_directory_that_is_not_a_cache() {
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("notes.txt"), "mine").unwrap();
    match LocalDisk::open(dir.path()) {
        Err(CacheError::NotACache { found, .. }) => assert_eq!(found, "notes.txt"),
        other => panic!("expected NotACache, got {other:?}"),
    }
    assert!(!dir.path().join(MARKER).exists());
    assert!(!dir.path().join(TMP_DIR).exists());
}

#[test]
fn put_get_round_trip_and_miss() {
    let dir = tempfile::tempdir().unwrap();
    let disk = LocalDisk::open(dir.path()).unwrap();
    assert_eq!(disk.get(&key(1)).unwrap(), Lookup::Miss);
    for (n, len) in [(1, 0), (2, 1), (3, 100_000)] {
        disk.put(&key(n), &content(n, len)).unwrap();
    }
    for (n, len) in [(1, 0), (2, 1), (3, 100_000)] {
        assert_eq!(disk.get(&key(n)).unwrap(), Lookup::Hit(content(n, len)));
    }
    assert_eq!(disk.get(&key(4)).unwrap(), Lookup::Miss);
    let p = disk.path_of(&key(3));
    assert_eq!(p, dir.path().join(entry_path(&key(3))));
    assert_eq!(fs::metadata(&p).unwrap().len(), 100_000 + ENTRY_HEADER_LEN as u64);
    // Replacing an entry (same key again) is fine and leaves no temp file.
    disk.put(&key(3), &content(3, 100_000)).unwrap();
    assert_eq!(disk.get(&key(3)).unwrap(), Lookup::Hit(content(3, 100_000)));
    let s = disk.stats().unwrap();
    assert_eq!((s.entries, s.temp_files), (3, 0));
    assert_eq!(s.bytes, 100_001 + 3 * ENTRY_HEADER_LEN as u64);
    assert!(disk.verify(false).unwrap().is_clean());
}

/// A way of damaging an entry file (of 64 content bytes), with the problem `get` must report.
type Damage = (&'static str, fn(&mut Vec<u8>), EntryProblem);

fn damages() -> Vec<Damage> {
    vec![
        ("flip content byte", |f| f[ENTRY_HEADER_LEN + 5] ^= 0x01, EntryProblem::HashMismatch),
        ("flip hash byte", |f| f[30] ^= 0x80, EntryProblem::HashMismatch),
        ("truncate content", |f| f.truncate(f.len() - 1), EntryProblem::LengthMismatch { header: 64, actual: 63 }),
        ("truncate header", |f| f.truncate(20), EntryProblem::Truncated { len: 20 }),
        ("empty file", |f| f.clear(), EntryProblem::Truncated { len: 0 }),
        ("wrong magic", |f| f[..8].copy_from_slice(b"MRESCACX"), EntryProblem::BadMagic),
        ("wrong version", |f| f[8] = 2, EntryProblem::WrongLayoutVersion { found: 2 }),
        ("trailing garbage", |f| f.push(0), EntryProblem::LengthMismatch { header: 64, actual: 65 }),
    ]
}

#[test]
fn corrupt_entries_are_reported_removed_then_missed() {
    let dir = tempfile::tempdir().unwrap();
    let disk = LocalDisk::open(dir.path()).unwrap();
    for (n, (what, damage, problem)) in damages().into_iter().enumerate() {
        let k = key(n as u32);
        disk.put(&k, &content(n as u32, 64)).unwrap();
        let path = disk.path_of(&k);
        let mut bytes = fs::read(&path).unwrap();
        assert_eq!(bytes[..8], ENTRY_MAGIC);
        damage(&mut bytes);
        fs::write(&path, &bytes).unwrap();
        assert_eq!(disk.get(&k).unwrap(), Lookup::Corrupt { problem, removed: true }, "{what}");
        assert!(!path.exists(), "{what}: corrupt entry left in place");
        assert_eq!(disk.get(&k).unwrap(), Lookup::Miss, "{what}");
    }
}

#[test]
fn verify_lists_corrupt_entries_and_repairs_them() {
    let dir = tempfile::tempdir().unwrap();
    let disk = LocalDisk::open(dir.path()).unwrap();
    let damages = damages();
    for n in 0..(damages.len() + 3) as u32 {
        disk.put(&key(n), &content(n, 64)).unwrap();
    }
    for (n, (_, damage, _)) in damages.iter().enumerate() {
        let path = disk.path_of(&key(n as u32));
        let mut bytes = fs::read(&path).unwrap();
        damage(&mut bytes);
        fs::write(&path, &bytes).unwrap();
    }
    // A valid entry under a name that is not a key (uppercase hex), and one in a directory that
    // is not a fan-out directory (ignored: not ours).
    let good = disk.path_of(&key(100));
    disk.put(&key(100), b"good").unwrap();
    let bad_name =
        good.with_file_name(good.file_name().unwrap().to_str().unwrap().replace("mres", "").to_uppercase() + "mres");
    fs::rename(&good, &bad_name).unwrap();
    fs::create_dir(dir.path().join("zz")).unwrap();
    fs::write(dir.path().join("zz/x.mres"), "not ours").unwrap();

    let report = disk.verify(false).unwrap();
    let n_bad = damages.len() + 1;
    assert_eq!(report.corrupt.len(), n_bad, "{report:#?}");
    assert_eq!((report.checked, report.valid), (n_bad as u64 + 3, 3));
    assert_eq!(report.valid_bytes, 3 * (64 + ENTRY_HEADER_LEN as u64));
    assert!(report.corrupt.iter().all(|c| !c.removed && c.path.exists()));
    for (n, (what, _, problem)) in damages.iter().enumerate() {
        let path = disk.path_of(&key(n as u32));
        let found = report.corrupt.iter().find(|c| c.path == path).unwrap_or_else(|| panic!("{what} not found"));
        assert_eq!(&found.problem, problem, "{what}");
    }
    assert!(report.corrupt.iter().any(|c| c.path == bad_name && c.problem == EntryProblem::BadName));

    let repaired = disk.verify(true).unwrap();
    assert_eq!(repaired.corrupt.len(), n_bad);
    assert!(repaired.corrupt.iter().all(|c| c.removed && !c.path.exists()));
    let after = disk.verify(false).unwrap();
    assert!(after.is_clean());
    assert_eq!(after.valid, 3);
    assert!(dir.path().join("zz/x.mres").exists(), "a file that is not ours was touched");
    for n in damages.len() as u32..damages.len() as u32 + 3 {
        assert_eq!(disk.get(&key(n)).unwrap(), Lookup::Hit(content(n, 64)));
    }
}

#[test]
fn gc_evicts_least_recently_used_and_a_hit_refreshes() {
    let dir = tempfile::tempdir().unwrap();
    let disk = LocalDisk::open(dir.path()).unwrap();
    let size = 1000 + ENTRY_HEADER_LEN as u64;
    let now = SystemTime::now();
    // Entry n was last used (5 - n) * 100 s ago: 1 is the oldest.
    for n in 1..=4 {
        disk.put(&key(n), &content(n, 1000)).unwrap();
        set_mtime(&disk.path_of(&key(n)), now - Duration::from_secs((5 - n as u64) * 100));
    }
    let s = disk.stats().unwrap();
    assert_eq!((s.entries, s.bytes), (4, 4 * size));
    assert_eq!(s.oldest, Some(now - Duration::from_secs(400)));
    assert_eq!(s.newest, Some(now - Duration::from_secs(100)));

    // A hit on the oldest makes it the newest.
    assert_eq!(disk.get(&key(1)).unwrap(), Lookup::Hit(content(1, 1000)));
    assert!(mtime(&disk.path_of(&key(1))) >= now);

    // Under the limit: nothing to do.
    let r = disk.gc(4 * size).unwrap();
    assert_eq!((r.entries_removed, r.entries_kept, r.bytes_kept), (0, 4, 4 * size));

    let r = disk.gc(2 * size + 10).unwrap();
    assert_eq!((r.entries_removed, r.bytes_removed), (2, 2 * size));
    assert_eq!((r.entries_kept, r.bytes_kept), (2, 2 * size));
    let hit = |n| matches!(disk.get(&key(n)).unwrap(), Lookup::Hit(_));
    assert!(!hit(2) && !hit(3), "the two least recently used should be gone");
    assert!(hit(1) && hit(4));

    let r = disk.gc(0).unwrap();
    assert_eq!((r.entries_removed, r.entries_kept, r.bytes_kept), (2, 0, 0));
    assert_eq!(disk.stats().unwrap().entries, 0);
}

#[test]
fn gc_removes_only_stale_temp_files_and_stats_count_them_apart() {
    let dir = tempfile::tempdir().unwrap();
    let disk = LocalDisk::open(dir.path()).unwrap();
    disk.put(&key(1), b"entry").unwrap();
    let tmp = dir.path().join(TMP_DIR);
    fs::write(tmp.join("fresh.tmp"), vec![0u8; 10]).unwrap();
    fs::write(tmp.join("stale.tmp"), vec![0u8; 20]).unwrap();
    set_mtime(&tmp.join("stale.tmp"), SystemTime::now() - DEFAULT_TEMP_GRACE - Duration::from_secs(1));

    let s = disk.stats().unwrap();
    assert_eq!((s.entries, s.bytes, s.temp_files), (1, 5 + ENTRY_HEADER_LEN as u64, 2));

    let r = disk.gc(u64::MAX).unwrap();
    assert_eq!((r.temp_removed, r.temp_bytes_removed, r.entries_removed), (1, 20, 0));
    assert!(tmp.join("fresh.tmp").exists() && !tmp.join("stale.tmp").exists());

    let r = disk.gc_with(u64::MAX, Duration::ZERO).unwrap();
    assert_eq!((r.temp_removed, r.entries_kept), (1, 1));
    assert_eq!(disk.stats().unwrap().temp_files, 0);
    assert_eq!(disk.get(&key(1)).unwrap(), Lookup::Hit(b"entry".to_vec()));
}

#[test]
fn put_recreates_a_removed_tmp_directory() {
    let dir = tempfile::tempdir().unwrap();
    let disk = LocalDisk::open(dir.path()).unwrap();
    fs::remove_dir(dir.path().join(TMP_DIR)).unwrap();
    disk.put(&key(1), b"x").unwrap();
    assert_eq!(disk.get(&key(1)).unwrap(), Lookup::Hit(b"x".to_vec()));
}
