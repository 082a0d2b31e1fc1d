//! The service behind the `bake-all` and `mres` commands: the batch over the cache, the
//! pipeline configuration, the clusterlod comparison, test-mesh generators and cut export.
#![deny(missing_docs)]

pub mod batch;
pub mod bench;
pub mod config;
pub mod export;
pub mod generate;
pub mod inspect;
pub mod log;
pub mod tree;
pub mod view_cost;
