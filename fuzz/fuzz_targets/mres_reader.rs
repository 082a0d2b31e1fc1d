//! `.mres` reader on raw bytes: `MresFile::parse`, then `decode_all` on success.
//!
//! Errors are expected for almost every input (the header checksum gates the hierarchy and
//! page table, and each page has its own checksum); the target checks that nothing panics,
//! aborts or allocates in proportion to a size the file merely claims. For deeper coverage
//! past the checksums see `mres_reader_resealed`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use mres_format::MresFile;

fuzz_target!(|data: &[u8]| {
    if let Ok(file) = MresFile::parse(data.to_vec()) {
        let _ = file.decode_all();
    }
});
