//! One entry file: a fixed 52-byte header, then the content.
//!
//! ```text
//! offset size
//!      0    8  magic "MRESCACH"
//!      8    4  layout version, u32 LE (LAYOUT_VERSION)
//!     12    8  content length in bytes, u64 LE
//!     20   32  blake3 hash of the content
//!     52    n  content
//! ```

/// The first 8 bytes of every entry file.
pub const ENTRY_MAGIC: [u8; 8] = *b"MRESCACH";

/// Version of the on-disk layout: the entry header above and the directory layout (written to
/// the root's `VERSION` marker). Bump it when either changes; [`crate::LocalDisk::open`] then
/// refuses an old directory instead of misreading it.
pub const LAYOUT_VERSION: u32 = 1;

/// Size of the entry header in bytes (magic, layout version, content length, content hash).
pub const ENTRY_HEADER_LEN: usize = 8 + 4 + 8 + 32;

/// Why an entry file is not a valid entry. Returned in [`crate::Lookup::Corrupt`] and
/// [`crate::CorruptEntry`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EntryProblem {
    /// The file is shorter than the header.
    #[error("truncated: {len} bytes, shorter than the {ENTRY_HEADER_LEN}-byte header")]
    Truncated {
        /// Length of the file in bytes.
        len: u64,
    },
    /// The file does not start with [`ENTRY_MAGIC`].
    #[error("bad magic (not an mres cache entry)")]
    BadMagic,
    /// The header's layout version is not [`LAYOUT_VERSION`].
    #[error("layout version {found}, expected {LAYOUT_VERSION}")]
    WrongLayoutVersion {
        /// The version found in the header.
        found: u32,
    },
    /// The header's content length disagrees with the file's length.
    #[error("header says {header} content bytes, file holds {actual}")]
    LengthMismatch {
        /// Content length stated in the header.
        header: u64,
        /// Content bytes actually present after the header.
        actual: u64,
    },
    /// The content's blake3 hash differs from the header's.
    #[error("content hash mismatch")]
    HashMismatch,
    /// The file's name or directory is not what [`crate::entry_path`] produces for any key
    /// (found by [`crate::LocalDisk::verify`] only).
    #[error("file name does not match the key layout")]
    BadName,
}

/// Builds the header for `content`.
pub(crate) fn header(content: &[u8]) -> [u8; ENTRY_HEADER_LEN] {
    let mut h = [0u8; ENTRY_HEADER_LEN];
    h[0..8].copy_from_slice(&ENTRY_MAGIC);
    h[8..12].copy_from_slice(&LAYOUT_VERSION.to_le_bytes());
    h[12..20].copy_from_slice(&(content.len() as u64).to_le_bytes());
    h[20..52].copy_from_slice(blake3::hash(content).as_bytes());
    h
}

/// Checks a whole entry file and returns its content. Never panics, whatever `file` holds.
pub(crate) fn decode(file: &[u8]) -> Result<&[u8], EntryProblem> {
    if file.len() < ENTRY_HEADER_LEN {
        return Err(EntryProblem::Truncated { len: file.len() as u64 });
    }
    let (h, content) = file.split_at(ENTRY_HEADER_LEN);
    if h[0..8] != ENTRY_MAGIC {
        return Err(EntryProblem::BadMagic);
    }
    let version = u32::from_le_bytes([h[8], h[9], h[10], h[11]]);
    if version != LAYOUT_VERSION {
        return Err(EntryProblem::WrongLayoutVersion { found: version });
    }
    let mut len = [0u8; 8];
    len.copy_from_slice(&h[12..20]);
    let len = u64::from_le_bytes(len);
    if len != content.len() as u64 {
        return Err(EntryProblem::LengthMismatch { header: len, actual: content.len() as u64 });
    }
    if blake3::hash(content).as_bytes()[..] != h[20..52] {
        return Err(EntryProblem::HashMismatch);
    }
    Ok(content)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encode(content: &[u8]) -> Vec<u8> {
        let mut v = header(content).to_vec();
        v.extend_from_slice(content);
        v
    }

    #[test]
    fn round_trip() {
        for content in [&b""[..], b"x", &[7u8; 1000]] {
            assert_eq!(decode(&encode(content)), Ok(content));
        }
    }

    #[test]
    fn every_truncation_is_an_error() {
        let file = encode(b"some baked bytes");
        for len in 0..file.len() {
            assert!(decode(&file[..len]).is_err(), "truncated to {len} decoded");
        }
    }

    #[test]
    fn every_flipped_byte_is_an_error() {
        let file = encode(b"some baked bytes");
        for i in 0..file.len() {
            let mut f = file.clone();
            f[i] ^= 0x40;
            assert!(decode(&f).is_err(), "flip at {i} decoded");
        }
    }

    #[test]
    fn problems_are_specific() {
        let file = encode(b"abc");
        assert_eq!(decode(&file[..10]), Err(EntryProblem::Truncated { len: 10 }));
        let mut f = file.clone();
        f[0] = b'X';
        assert_eq!(decode(&f), Err(EntryProblem::BadMagic));
        let mut f = file.clone();
        f[8] = 9;
        assert_eq!(decode(&f), Err(EntryProblem::WrongLayoutVersion { found: 9 }));
        let mut f = file.clone();
        f.push(0);
        assert_eq!(decode(&f), Err(EntryProblem::LengthMismatch { header: 3, actual: 4 }));
        let mut f = file.clone();
        f[ENTRY_HEADER_LEN] ^= 1;
        assert_eq!(decode(&f), Err(EntryProblem::HashMismatch));
    }
}
