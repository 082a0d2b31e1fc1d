//! The mres baker: weld, cluster, group (METIS), simplify (meshopt, locked borders), assemble
//! the DAG and write `.mres`; plus the validator and the helpers behind the commands.
#![deny(missing_docs)]

pub mod bake;
pub mod batch;
pub mod bench;
pub mod bvh;
pub mod cluster;
pub mod conditioning;
pub mod config;
pub mod dag;
pub mod deviation;
pub mod edges;
pub mod export;
pub mod generate;
pub mod honesty;
pub mod partition;
pub mod parts;
pub mod settings;
pub mod shard;
pub mod simplify;
pub mod validate;
pub mod weld;

pub use settings::BakeSettings;
