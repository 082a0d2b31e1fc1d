//! The `.mres` validator: proves a file against the invariants of `docs/INVARIANTS.md` —
//! format integrity, monotone errors and nested spheres, crack-free cuts ([`validate`]), a
//! well-conditioned DAG ([`conditioning`]) and honest errors ([`honesty`]).
//!
//! It depends on the container crate only (and the shared geometry helpers), never on the
//! builder it checks.
#![deny(missing_docs)]

pub mod conditioning;
pub mod distance;
pub mod honesty;
pub mod lod_chain;
pub mod tables;
pub mod validate;
