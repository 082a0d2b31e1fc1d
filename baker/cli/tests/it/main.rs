//! The end-to-end tests of the baker, one test binary: each module was its own binary before,
//! and every one of them linked the whole baker again (most of the test build's time).

use std::process::{Command, Output};

/// The two binaries under test.
const BAKE_ALL: &str = env!("CARGO_BIN_EXE_bake-all");
const MRES: &str = env!("CARGO_BIN_EXE_mres");

/// Runs `bin` with `args` to completion.
fn run(bin: &str, args: &[&str]) -> Output {
    Command::new(bin).args(args).output().expect("run command")
}

/// A finished command's stdout and stderr, as text.
fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

mod bake;
mod batch;
mod cli;
mod cracks;
mod scene;
mod shard;
mod terminal;
