//! The importers only take a path (`mres_import::import_file`; the in-memory
//! `import_bytes` is private), so each input is written to one reused file in a directory of
//! its own per process: `<base>/mres-fuzz-<pid>/<subdir>/input.<ext>`, removed at exit.
//!
//! `<base>` is `$MRES_FUZZ_TMPDIR` if set, else `/dev/shm` if it exists, else the system temp
//! directory. A RAM-backed directory matters: rewriting a file on ext4 for every input makes
//! the kernel write it out to disk each time (`auto_da_alloc`): 4-15x slower than tmpfs here.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

static PROCESS_DIR: OnceLock<PathBuf> = OnceLock::new();

extern "C" fn remove_process_dir() {
    if let Some(dir) = PROCESS_DIR.get() {
        let _ = std::fs::remove_dir_all(dir);
    }
}

fn process_dir() -> &'static Path {
    PROCESS_DIR.get_or_init(|| {
        let base = match std::env::var_os("MRES_FUZZ_TMPDIR") {
            Some(dir) if !dir.is_empty() => PathBuf::from(dir),
            _ if Path::new("/dev/shm").is_dir() => PathBuf::from("/dev/shm"),
            _ => std::env::temp_dir(),
        };
        let dir = base.join(format!("mres-fuzz-{}", std::process::id()));
        // libFuzzer ends with exit(), which runs atexit handlers but no Rust destructors.
        unsafe { libc::atexit(remove_process_dir) };
        dir
    })
}

/// Creates `<process dir>/<subdir>`, writes the `extra` files into it (buffers that glTF
/// seeds refer to by relative URI, a material library) and returns the input path in it.
pub fn input_path(subdir: &str, ext: &str, extra: &[(&str, &[u8])]) -> PathBuf {
    let dir = process_dir().join(subdir);
    std::fs::create_dir_all(&dir).expect("create fuzz temp dir");
    for (name, bytes) in extra {
        std::fs::write(dir.join(name), bytes).expect("write fuzz temp file");
    }
    dir.join(format!("input.{ext}"))
}

/// Overwrites `path` with `data`.
pub fn write(path: &Path, data: &[u8]) {
    std::fs::write(path, data).expect("write fuzz input file");
}
