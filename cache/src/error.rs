//! The crate's error type.

use std::io;
use std::path::PathBuf;

/// An operation on the cache failed. A corrupt entry is not an error (it is reported as
/// [`crate::Lookup::Corrupt`] or in a [`crate::VerifyReport`]); these are failures of the
/// directory itself or of the file system.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// A file-system call failed.
    #[error("{op} {}: {source}", path.display())]
    Io {
        /// What was being done, e.g. "create directory", "rename".
        op: &'static str,
        /// The path it was done to.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
    /// The directory's `VERSION` marker names a layout this build does not know. The
    /// directory is left untouched.
    #[error("{} holds cache layout {found:?}, this build writes {expected:?}; use another directory or remove it", path.display())]
    UnknownLayout {
        /// The marker file.
        path: PathBuf,
        /// The marker's contents (trimmed, at most 200 bytes).
        found: String,
        /// The marker this build writes.
        expected: String,
    },
    /// The directory has no `VERSION` marker but holds files a cache would not create, so it is
    /// probably not meant as a cache; [`crate::LocalDisk::open`] refuses it rather than
    /// mixing entries in (and later letting `gc` loose on it).
    #[error("{} is not empty and not an mres cache (found {found:?}); use an empty or new directory", path.display())]
    NotACache {
        /// The directory.
        path: PathBuf,
        /// The first unexpected name found in it.
        found: String,
    },
}

impl CacheError {
    pub(crate) fn io(op: &'static str, path: impl Into<PathBuf>) -> impl FnOnce(io::Error) -> CacheError {
        let path = path.into();
        move |source| CacheError::Io { op, path, source }
    }
}
