//! What is wrong with a `.mres` file ([`MresError`]), and the two helpers every decoding step
//! reports with (a leaf module, so that the reader and the page decoder share it without
//! importing each other).

use crate::VERSION;

/// What is wrong with a `.mres` file.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MresError {
    /// The file ends before a section it declares.
    #[error("truncated: {what} needs bytes {start}..{end} but the file has {len}")]
    Truncated {
        /// The section.
        what: String,
        /// First byte needed.
        start: u64,
        /// One past the last byte needed.
        end: u64,
        /// File length.
        len: u64,
    },
    /// The file could not be read.
    #[error("{0}")]
    Io(String),
    /// Not a `.mres` file.
    #[error("not a .mres file (bad magic)")]
    BadMagic,
    /// A version this reader does not know.
    #[error("unsupported .mres version {found} (this reader reads version {VERSION})")]
    WrongVersion {
        /// Version in the file.
        found: u32,
    },
    /// A checksum does not match.
    #[error("checksum mismatch in {0}")]
    Checksum(String),
    /// A value or reference is out of range or inconsistent.
    #[error("corrupt {0}")]
    Corrupt(String),
    /// The bytes given for a page are not as long as the page table says.
    #[error("page {page}: {len} compressed bytes given, the page table says {expected}")]
    PageLength {
        /// Page index.
        page: u32,
        /// Bytes given.
        len: u64,
        /// `compressed_size` in the page table.
        expected: u32,
    },
    /// A page was given another number of source layouts than it has sources (FORMAT.md
    /// §4.3: its dependencies stored before it).
    #[error("page {page}: {given} source layouts given, the page has {expected} sources")]
    SourceCount {
        /// Page index.
        page: u32,
        /// Layouts given.
        given: usize,
        /// Sources the page table gives it.
        expected: usize,
    },
    /// A source layout given for a page is not as long as the source's `raw_size`.
    #[error("page {page}: source page {source_page}'s layout has {len} bytes, the page table says {expected}")]
    SourceLength {
        /// Page index.
        page: u32,
        /// The source page.
        source_page: u32,
        /// Bytes given.
        len: usize,
        /// The source's `raw_size`.
        expected: u32,
    },
    /// A page does not decompress to its declared size.
    #[error("page {page}: {problem}")]
    Decompress {
        /// Page index.
        page: u32,
        /// What went wrong.
        problem: String,
    },
}

/// Returns `bytes[start..start+len]` or a `Truncated` error naming `what`.
pub(crate) fn section<'a>(bytes: &'a [u8], start: u64, len: u64, what: &str) -> Result<&'a [u8], MresError> {
    let end = start.saturating_add(len);
    if end > bytes.len() as u64 {
        return Err(MresError::Truncated { what: what.into(), start, end, len: bytes.len() as u64 });
    }
    Ok(&bytes[start as usize..end as usize])
}

/// A `Corrupt` error with `msg`.
pub(crate) fn corrupt(msg: String) -> MresError {
    MresError::Corrupt(msg)
}
