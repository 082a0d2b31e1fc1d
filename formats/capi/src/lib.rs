//! A C ABI over [`mres_format`]'s page-streaming reader, for engines written in C or C++.
//!
//! An engine reads the resident prefix of a `.mres` file (header, hierarchy, page table) and
//! opens an index on it ([`mres_index_open`]); it then fetches each page's byte range itself
//! ([`mres_page_range`]) and decodes it ([`mres_page_decode`]) into the GPU layout of
//! docs/FORMAT.md §5 plus per-cluster arrays. The library never opens a file, so the whole
//! file need never be in memory.
//!
//! The C declarations are in `include/mres.h`, generated from this crate by cbindgen (the
//! test `tests/header.rs` fails when the checked-in header differs from the generated one).
//! The conventions every function follows are in the crate's README and the header:
//!
//! - every function returns an [`MresStatus`]; on failure [`mres_last_error_message`] gives
//!   the full text, per thread;
//! - pointers are checked for null, lengths and indices for range, and caller buffers for
//!   size ([`MresStatus::MRES_ERR_BUFFER_TOO_SMALL`]); no panic crosses the boundary;
//! - handles ([`MresIndex`], [`MresPage`]) are created by the library and freed by it
//!   ([`mres_index_free`], [`mres_page_free`]); they are immutable, so any number of threads
//!   may query them at once.
//!
//! The functions are callable from Rust too (this crate is also an `rlib`), which is how the
//! tests drive them.

#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]
#![deny(unsafe_op_in_unsafe_fn)]

mod ffi;
mod index;
mod page;

pub use ffi::{mres_last_error_message, mres_status_name, MresStatus};
pub use index::*;
pub use page::*;
