//! The one storage interface; each backend lives in its own file (`local_disk.rs`).

use crate::{CacheError, CacheKey, EntryProblem};

/// The result of [`Storage::get`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Lookup {
    /// A valid entry: its content, verified against the stored hash.
    Hit(Vec<u8>),
    /// No entry for the key.
    Miss,
    /// An entry existed but failed verification; the caller treats it as a miss (bakes and
    /// puts again) and may count or log it.
    Corrupt {
        /// What was wrong with it.
        problem: EntryProblem,
        /// Whether the bad entry was removed (false if removing failed, e.g. for lack of
        /// permission, or another process replaced it in the meantime).
        removed: bool,
    },
}

impl Lookup {
    /// The content on a hit, `None` on a miss or a corrupt entry.
    pub fn into_hit(self) -> Option<Vec<u8>> {
        match self {
            Lookup::Hit(bytes) => Some(bytes),
            Lookup::Miss | Lookup::Corrupt { .. } => None,
        }
    }
}

/// A content-addressed store of baked files. Implementations must make `put` atomic (a
/// concurrent or later `get` sees either no entry or the complete one) and `get` verified.
pub trait Storage {
    /// Looks `key` up. The content is verified before it is returned; a corrupt entry is
    /// removed and reported as [`Lookup::Corrupt`], never returned as a hit. Errors are
    /// failures of the store itself (e.g. permission denied), not missing or bad entries.
    fn get(&self, key: &CacheKey) -> Result<Lookup, CacheError>;

    /// Stores `bytes` under `key`, atomically. Putting a key that already exists replaces the
    /// entry (same key means same content, so readers cannot tell).
    fn put(&self, key: &CacheKey, bytes: &[u8]) -> Result<(), CacheError>;
}
