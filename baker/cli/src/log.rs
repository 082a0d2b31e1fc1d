//! The tracing log both commands write to stderr.

use std::io::IsTerminal;

/// Logs to stderr at the level `RUST_LOG` asks for (default: warnings only; `RUST_LOG=info`
/// shows each bake's stages and levels), as JSON lines with `json`; colours only when stderr
/// is a terminal.
pub fn init(json: bool) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal());
    if json {
        builder.json().init();
    } else {
        builder.init();
    }
}
