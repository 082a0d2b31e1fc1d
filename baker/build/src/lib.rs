//! The DAG builder: weld, shard, cluster, group (METIS), simplify (meshopt, locked borders),
//! assemble the cluster DAG and encode it as `.mres` (`docs/ARCHITECTURE.md` "One bake").
#![deny(missing_docs)]

pub mod bake;
pub mod cluster;
pub mod dag;
pub mod deviation;
pub mod error;
pub mod partition;
pub mod progress;
pub mod settings;
pub mod shard;
pub mod simplify;
pub mod weld;

pub use settings::BakeSettings;
