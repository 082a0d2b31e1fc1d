//! [`LocalDisk`]: the cache as one directory on a local (POSIX) file system, shareable by any
//! number of processes at once without a lock. Layout, entry format and the concurrency
//! argument are in `cache/README.md`; the short form:
//!
//! - `put` writes a uniquely named temp file under `tmp/`, fsyncs it, renames it onto the entry
//!   path and fsyncs the directory. `rename` replaces the name atomically, so a reader opens
//!   either the old file, the new one, or nothing: never a partial file. Two writers of the
//!   same key each rename a complete file; the last one wins and both are valid.
//! - `get` verifies magic, version, length and hash, so whatever else goes wrong (disk
//!   corruption, a foreign tool truncating files) a bad entry is a miss, never a wrong hit.
//! - `gc` only ever unlinks whole files; an open file stays readable after unlink on POSIX, so
//!   eviction racing a reader or writer costs at most a re-bake.
//!
//! No global lock is needed because no operation ever modifies a file in place: every change
//! is a create-new, a rename or an unlink, each atomic on its own.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::entry::{self, ENTRY_HEADER_LEN, LAYOUT_VERSION};
use crate::key::{entry_path, key_from_entry_name};
use crate::{CacheError, CacheKey, EntryProblem, Lookup, Storage};

/// How old a temp file must be before [`LocalDisk::gc`] takes it for the leftover of a killed
/// writer and removes it. Ten minutes is far longer than writing any baked file takes, so a
/// live writer in another process never loses its temp file; a writer that does take longer
/// gets an error from its `put` (the rename fails), never a corrupt entry.
pub const DEFAULT_TEMP_GRACE: Duration = Duration::from_secs(10 * 60);

/// Name of the layout marker file in the cache root.
const MARKER: &str = "VERSION";
/// Name of the temp directory in the cache root.
const TMP_DIR: &str = "tmp";

fn marker_text() -> String {
    format!("mres-cache layout {LAYOUT_VERSION}\n")
}

/// A cache directory on a local disk. Cheap to clone; holds no open files or locks, so any
/// number of `LocalDisk`s in any number of threads and processes may use one directory.
#[derive(Debug, Clone)]
pub struct LocalDisk {
    root: PathBuf,
}

/// Counts of what is in the cache, from [`LocalDisk::stats`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Stats {
    /// Number of entry files (well-named `*.mres` files in fan-out directories; not verified).
    pub entries: u64,
    /// Total size of those entry files in bytes, headers included (what `gc`'s limit counts).
    pub bytes: u64,
    /// Number of files in `tmp/`: writes in progress, or leftovers of killed writers.
    pub temp_files: u64,
    /// Modification time (last put or hit) of the least recently used entry.
    pub oldest: Option<SystemTime>,
    /// Modification time (last put or hit) of the most recently used entry.
    pub newest: Option<SystemTime>,
}

/// One bad entry file found by [`LocalDisk::verify`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CorruptEntry {
    /// Path of the file.
    pub path: PathBuf,
    /// What is wrong with it.
    pub problem: EntryProblem,
    /// Whether it was removed (only ever with `repair`).
    pub removed: bool,
}

/// Result of [`LocalDisk::verify`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct VerifyReport {
    /// Entry files read (valid and corrupt).
    pub checked: u64,
    /// Entry files that passed every check.
    pub valid: u64,
    /// Total size of the valid entry files in bytes.
    pub valid_bytes: u64,
    /// Every entry file that failed a check.
    pub corrupt: Vec<CorruptEntry>,
}

impl VerifyReport {
    /// True when no corrupt entry was found.
    pub fn is_clean(&self) -> bool {
        self.corrupt.is_empty()
    }
}

/// Result of [`LocalDisk::gc`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GcReport {
    /// Stale temp files removed.
    pub temp_removed: u64,
    /// Their total size in bytes.
    pub temp_bytes_removed: u64,
    /// Entries evicted.
    pub entries_removed: u64,
    /// Their total size in bytes.
    pub bytes_removed: u64,
    /// Entries left.
    pub entries_kept: u64,
    /// Their total size in bytes (at most the limit, unless entries vanished or appeared
    /// concurrently).
    pub bytes_kept: u64,
}

/// One entry file found by a directory walk.
struct EntryFile {
    path: PathBuf,
    /// `None` when the name is not one [`entry_path`] produces.
    key: Option<CacheKey>,
    len: u64,
    modified: SystemTime,
}

impl LocalDisk {
    /// Opens the cache at `root`, creating the directory and its `VERSION` marker if needed.
    /// Refuses (without touching anything) a directory whose marker names another layout
    /// ([`CacheError::UnknownLayout`]) and a non-empty directory without a marker that holds
    /// files a cache would not ([`CacheError::NotACache`]).
    pub fn open(root: impl Into<PathBuf>) -> Result<LocalDisk, CacheError> {
        let root = root.into();
        fs::create_dir_all(&root).map_err(CacheError::io("create directory", &root))?;
        let disk = LocalDisk { root };
        let marker = disk.root.join(MARKER);
        if read_marker(&marker)?.is_none() {
            disk.check_only_cache_files()?;
            disk.ensure_tmp_dir()?;
            disk.write_marker(&marker)?;
        }
        // Checked after writing too: another process may have won the race with another marker.
        match read_marker(&marker)? {
            Some(found) if found == marker_text().trim() => {}
            found => {
                return Err(CacheError::UnknownLayout {
                    path: marker,
                    found: found.unwrap_or_default(),
                    expected: marker_text().trim().to_string(),
                })
            }
        }
        disk.ensure_tmp_dir()?;
        Ok(disk)
    }

    /// The cache's root directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The path of `key`'s entry file: the root joined with [`entry_path`] (the file may or
    /// may not exist).
    pub fn path_of(&self, key: &CacheKey) -> PathBuf {
        self.root.join(entry_path(key))
    }

    /// Counts entries, bytes and temp files, without reading entries.
    pub fn stats(&self) -> Result<Stats, CacheError> {
        let mut s = Stats::default();
        for e in self.walk_entries()? {
            if e.key.is_none() {
                continue;
            }
            s.entries += 1;
            s.bytes += e.len;
            s.oldest = Some(s.oldest.map_or(e.modified, |t| t.min(e.modified)));
            s.newest = Some(s.newest.map_or(e.modified, |t| t.max(e.modified)));
        }
        s.temp_files = self.walk_temp()?.len() as u64;
        Ok(s)
    }

    /// Reads every entry file and checks its name against the key layout and its header and
    /// hash; lists each bad one. With `repair`, removes them. Does not count as use (leaves
    /// modification times alone). Safe to run while other processes put, get and gc.
    pub fn verify(&self, repair: bool) -> Result<VerifyReport, CacheError> {
        let mut report = VerifyReport::default();
        for e in self.walk_entries()? {
            let (file, problem) = if e.key.is_none() {
                // Opened anyway, so a removal below checks it is still the same file.
                match File::open(&e.path) {
                    Ok(file) => (file, EntryProblem::BadName),
                    Err(err) if err.kind() == io::ErrorKind::NotFound => continue,
                    Err(err) => return Err(CacheError::io("open", &e.path)(err)),
                }
            } else {
                match read_entry(&e.path)? {
                    None => continue, // Removed since the walk.
                    Some((_, Ok(content))) => {
                        report.checked += 1;
                        report.valid += 1;
                        report.valid_bytes += (content.len() + ENTRY_HEADER_LEN) as u64;
                        continue;
                    }
                    Some((file, Err(problem))) => (file, problem),
                }
            };
            report.checked += 1;
            let removed = repair && remove_if_same(&e.path, &file);
            report.corrupt.push(CorruptEntry { path: e.path, problem, removed });
        }
        Ok(report)
    }

    /// [`LocalDisk::gc_with`] with [`DEFAULT_TEMP_GRACE`]: removes temp files older than ten
    /// minutes, then least-recently-used entries until the entries total at most `max_bytes`
    /// (file sizes, headers included).
    pub fn gc(&self, max_bytes: u64) -> Result<GcReport, CacheError> {
        self.gc_with(max_bytes, DEFAULT_TEMP_GRACE)
    }

    /// Removes temp files whose modification time is more than `temp_grace` ago (leftovers of
    /// killed writers; `Duration::ZERO` removes all, so use it only when no writer runs), then
    /// evicts entries in order of modification time (last put or hit), oldest first, until
    /// the entries total at most `max_bytes`. Safe while other processes put and get: it may
    /// evict an entry someone is about to read (they see a miss), never corrupt one.
    pub fn gc_with(&self, max_bytes: u64, temp_grace: Duration) -> Result<GcReport, CacheError> {
        let mut report = GcReport::default();
        let now = SystemTime::now();
        for t in self.walk_temp()? {
            // A time in the future (clock skew) gives Err: treated as fresh.
            let stale = now.duration_since(t.modified).is_ok_and(|age| age >= temp_grace);
            if stale && remove_file_counted(&t.path)? {
                report.temp_removed += 1;
                report.temp_bytes_removed += t.len;
            }
        }

        let mut entries: Vec<EntryFile> = self.walk_entries()?.into_iter().filter(|e| e.key.is_some()).collect();
        let mut total: u64 = entries.iter().map(|e| e.len).sum();
        entries.sort_by(|a, b| a.modified.cmp(&b.modified).then_with(|| a.path.cmp(&b.path)));
        let mut kept = entries.len() as u64;
        for e in &entries {
            if total <= max_bytes {
                break;
            }
            if remove_file_counted(&e.path)? {
                report.entries_removed += 1;
                report.bytes_removed += e.len;
            }
            // Gone either way (by us or by a concurrent gc).
            total -= e.len;
            kept -= 1;
        }
        report.entries_kept = kept;
        report.bytes_kept = total;
        Ok(report)
    }

    /// Fails with [`CacheError::NotACache`] if the root holds a name a cache would not create.
    fn check_only_cache_files(&self) -> Result<(), CacheError> {
        for item in fs::read_dir(&self.root).map_err(CacheError::io("read directory", &self.root))? {
            let item = item.map_err(CacheError::io("read directory", &self.root))?;
            let name = item.file_name();
            let name = name.to_string_lossy();
            let is_dir = item.file_type().is_ok_and(|t| t.is_dir());
            let ours = name == MARKER || (is_dir && (name == TMP_DIR || is_fan_out_name(&name)));
            if !ours {
                return Err(CacheError::NotACache { path: self.root.clone(), found: name.into_owned() });
            }
        }
        Ok(())
    }

    fn ensure_tmp_dir(&self) -> Result<PathBuf, CacheError> {
        let tmp = self.root.join(TMP_DIR);
        fs::create_dir_all(&tmp).map_err(CacheError::io("create directory", &tmp))?;
        Ok(tmp)
    }

    /// Writes the marker atomically and without replacing one another process wrote first.
    fn write_marker(&self, marker: &Path) -> Result<(), CacheError> {
        let (mut file, tmp_path) = self.create_temp()?;
        let result = (|| {
            file.write_all(marker_text().as_bytes()).map_err(CacheError::io("write", &tmp_path))?;
            file.sync_all().map_err(CacheError::io("sync", &tmp_path))?;
            match fs::hard_link(&tmp_path, marker) {
                Ok(()) => {}
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
                // File systems without hard links: rename may replace a marker written
                // concurrently, which `open` re-reads and checks afterwards.
                Err(_) => fs::rename(&tmp_path, marker).map_err(CacheError::io("rename", marker))?,
            }
            sync_dir(&self.root).map_err(CacheError::io("sync directory", &self.root))
        })();
        let _ = fs::remove_file(&tmp_path);
        result
    }

    /// Creates a new, uniquely named file in `tmp/`: pid, time and a process-wide counter,
    /// created with `create_new` so even a name reused after a pid wrap cannot clash.
    fn create_temp(&self) -> Result<(File, PathBuf), CacheError> {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let tmp = self.root.join(TMP_DIR);
        let mut last_err = None;
        for _ in 0..16 {
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let nanos = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos());
            let path = tmp.join(format!("{}-{nanos:x}-{n}.tmp", std::process::id()));
            match OpenOptions::new().write(true).create_new(true).open(&path) {
                Ok(f) => return Ok((f, path)),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last_err = Some((e, path)),
                // Someone removed tmp/ by hand: recreate it and retry.
                Err(e) if e.kind() == io::ErrorKind::NotFound => {
                    self.ensure_tmp_dir()?;
                    last_err = Some((e, path));
                }
                Err(e) => return Err(CacheError::io("create temp file", path)(e)),
            }
        }
        let (e, path) = last_err.expect("the loop ran at least once");
        Err(CacheError::io("create temp file", path)(e))
    }

    /// Every file in a fan-out directory whose name ends in `.mres`. Files and directories
    /// that vanish during the walk are skipped; other names are not ours and are ignored.
    fn walk_entries(&self) -> Result<Vec<EntryFile>, CacheError> {
        let mut out = Vec::new();
        for dir in read_dir_skip_missing(&self.root)? {
            let dir_name = dir.file_name();
            let Some(dir_name) = dir_name.to_str().filter(|n| is_fan_out_name(n)) else { continue };
            if !dir.file_type().is_ok_and(|t| t.is_dir()) {
                continue;
            }
            let dir_path = dir.path();
            for item in read_dir_skip_missing(&dir_path)? {
                let name = item.file_name();
                let name = name.to_string_lossy();
                if !name.ends_with(".mres") || !item.file_type().is_ok_and(|t| t.is_file()) {
                    continue;
                }
                let path = item.path();
                let Some((len, modified)) = file_len_and_mtime(&path)? else { continue };
                out.push(EntryFile { key: key_from_entry_name(dir_name, &name), path, len, modified });
            }
        }
        Ok(out)
    }

    /// Every file in `tmp/`.
    fn walk_temp(&self) -> Result<Vec<EntryFile>, CacheError> {
        let mut out = Vec::new();
        for item in read_dir_skip_missing(&self.root.join(TMP_DIR))? {
            if !item.file_type().is_ok_and(|t| t.is_file()) {
                continue;
            }
            let path = item.path();
            let Some((len, modified)) = file_len_and_mtime(&path)? else { continue };
            out.push(EntryFile { path, key: None, len, modified });
        }
        Ok(out)
    }
}

impl Storage for LocalDisk {
    /// Reads and verifies `key`'s entry. On a hit, sets the file's modification time to now
    /// (best effort: a cache shared between users may not allow it), which is what `gc`'s
    /// least-recently-used order reads. A corrupt entry is removed unless another process has
    /// replaced it since it was opened.
    fn get(&self, key: &CacheKey) -> Result<Lookup, CacheError> {
        let path = self.path_of(key);
        match read_entry(&path)? {
            None => Ok(Lookup::Miss),
            Some((file, Ok(content))) => {
                let _ = file.set_modified(SystemTime::now());
                Ok(Lookup::Hit(content))
            }
            Some((file, Err(problem))) => Ok(Lookup::Corrupt { problem, removed: remove_if_same(&path, &file) }),
        }
    }

    /// Writes `bytes` under `key`: temp file in `tmp/`, fsync, rename onto the entry path,
    /// fsync the fan-out directory (and the root, when the fan-out directory was new). On any
    /// error the temp file is removed and the previous entry, if any, is untouched.
    fn put(&self, key: &CacheKey, bytes: &[u8]) -> Result<(), CacheError> {
        let final_path = self.path_of(key);
        let fan_dir = self.root.join(&key.hex()[..2]);
        let (mut file, tmp_path) = self.create_temp()?;
        let result = (|| {
            file.write_all(&entry::header(bytes)).map_err(CacheError::io("write", &tmp_path))?;
            file.write_all(bytes).map_err(CacheError::io("write", &tmp_path))?;
            file.sync_all().map_err(CacheError::io("sync", &tmp_path))?;
            drop(file);
            let created = match fs::create_dir(&fan_dir) {
                Ok(()) => true,
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => false,
                Err(e) => return Err(CacheError::io("create directory", &fan_dir)(e)),
            };
            if created {
                sync_dir(&self.root).map_err(CacheError::io("sync directory", &self.root))?;
            }
            fs::rename(&tmp_path, &final_path).map_err(CacheError::io("rename", &final_path))?;
            sync_dir(&fan_dir).map_err(CacheError::io("sync directory", &fan_dir))
        })();
        if result.is_err() {
            let _ = fs::remove_file(&tmp_path);
        }
        result
    }
}

fn is_fan_out_name(name: &str) -> bool {
    name.len() == 2 && name.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// Reads the marker, trimmed and cut to 200 characters; `None` if there is none.
fn read_marker(marker: &Path) -> Result<Option<String>, CacheError> {
    match fs::read(marker) {
        Ok(bytes) => Ok(Some(String::from_utf8_lossy(&bytes).trim().chars().take(200).collect())),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(CacheError::io("read", marker)(e)),
    }
}

/// An entry file's content (header stripped), or what is wrong with it.
type Checked = Result<Vec<u8>, EntryProblem>;

/// Opens and reads a whole entry file and checks it. `None` if the file does not exist; on
/// success the returned content has the header stripped. The open file is returned so the
/// caller can touch it or check it is still the one at `path` before removing it.
fn read_entry(path: &Path) -> Result<Option<(File, Checked)>, CacheError> {
    let mut file = match File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(CacheError::io("open", path)(e)),
    };
    let len = file.metadata().map_err(CacheError::io("stat", path))?.len();
    let mut buf = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.read_to_end(&mut buf).map_err(CacheError::io("read", path))?;
    let checked = match entry::decode(&buf) {
        Ok(_) => {
            buf.drain(..ENTRY_HEADER_LEN);
            Ok(buf)
        }
        Err(problem) => Err(problem),
    };
    Ok(Some((file, checked)))
}

/// Removes `path` if it is still the file `opened` (not one renamed over it since), so a
/// corrupt file is never confused with a fresh valid entry another process just put.
/// Returns whether it removed it. Best effort: failures are reported as `false`.
fn remove_if_same(path: &Path, opened: &File) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let (Ok(a), Ok(b)) = (opened.metadata(), fs::symlink_metadata(path)) else { return false };
        if (a.dev(), a.ino()) != (b.dev(), b.ino()) {
            return false;
        }
    }
    #[cfg(not(unix))]
    let _ = opened;
    fs::remove_file(path).is_ok()
}

/// Removes a file; `Ok(false)` if it was already gone.
fn remove_file_counted(path: &Path) -> Result<bool, CacheError> {
    match fs::remove_file(path) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(CacheError::io("remove", path)(e)),
    }
}

/// The items of a directory; none if the directory does not exist (any more). Items that
/// fail to read are skipped: they are being removed concurrently.
fn read_dir_skip_missing(dir: &Path) -> Result<Vec<fs::DirEntry>, CacheError> {
    match fs::read_dir(dir) {
        Ok(items) => Ok(items.filter_map(Result::ok).collect()),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Vec::new()),
        Err(e) => Err(CacheError::io("read directory", dir)(e)),
    }
}

/// Length and modification time of a file; `None` if it vanished.
fn file_len_and_mtime(path: &Path) -> Result<Option<(u64, SystemTime)>, CacheError> {
    match fs::symlink_metadata(path) {
        Ok(m) => Ok(Some((m.len(), m.modified().map_err(CacheError::io("stat", path))?))),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(CacheError::io("stat", path)(e)),
    }
}

/// Makes a directory's entries (a rename into it) durable. A no-op where directories cannot
/// be opened as files.
fn sync_dir(dir: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        File::open(dir)?.sync_all()
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

#[cfg(test)]
mod tests;
