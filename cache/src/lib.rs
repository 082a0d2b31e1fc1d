//! Content-addressed store for baked `.mres` files (layout and guarantees in `cache/README.md`).
//!
//! The baker builds a [`CacheKey`] from an explicit list of inputs ([`KeyInputs`]), asks a
//! [`Storage`] for it and, on a miss, bakes and [`Storage::put`]s the bytes. The shipped backend
//! is [`LocalDisk`]: one directory that several processes may share at once, where every entry
//! is written to a temp file, fsynced and renamed into place, so a reader sees either nothing or
//! a complete entry, and a process killed at any moment leaves at most a stale temp file that
//! [`LocalDisk::gc`] removes. Every read is verified (magic, layout version, length, blake3 of
//! the content); a corrupt entry is removed and reported as [`Lookup::Corrupt`].
//!
//! This crate depends on nothing else of mres.
#![deny(missing_docs)]

mod entry;
mod error;
mod key;
mod local_disk;
mod size;
mod storage;

pub use entry::{EntryProblem, ENTRY_HEADER_LEN, ENTRY_MAGIC, LAYOUT_VERSION};
pub use error::CacheError;
pub use key::{entry_path, CacheKey, KeyInputs, ParseKeyError, KEY_SCHEMA_VERSION};
pub use local_disk::{CorruptEntry, GcReport, LocalDisk, Stats, VerifyReport, DEFAULT_TEMP_GRACE};
pub use size::parse_size;
pub use storage::{Lookup, Storage};
