//! The DAG builder: open a source, weld, shard if large, cluster, group (METIS), simplify
//! (meshopt, group borders locked, open borders simplified along themselves), and hand the DAG to the `.mres` writer through `encode`
//! (`docs/ARCHITECTURE.md` "Data flow of one bake").
#![deny(missing_docs)]

pub mod area;
pub mod bake;
pub mod chords;
pub mod cluster;
pub mod dag;
pub mod deviation;
pub mod encode;
pub mod error;
pub mod levels;
pub mod open;
pub mod partition;
pub mod progress;
pub mod samples;
pub mod settings;
pub mod shard;
pub mod simplify;
pub mod source;
pub mod weld;
pub mod whole;

pub use settings::BakeSettings;
