//! The end-to-end tests of the baker, one test binary: each module was its own binary before,
//! and every one of them linked the whole baker again (most of the test build's time).

mod bake;
mod batch;
mod cli;
mod cracks;
mod scene;
mod shard;
mod terminal;
