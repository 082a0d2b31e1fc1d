//! Why a bake failed: the one error type of the builder (a leaf module: it depends on no other
//! step, so every step can return it).

/// Why a bake failed.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    /// The input could not be imported.
    #[error(transparent)]
    Import(#[from] mres_import::ImportError),
    /// The settings are out of range.
    #[error("settings: {0}")]
    Settings(String),
    /// A sharded build could not use its spill files.
    #[error("sharding: {0}")]
    Shard(String),
    /// The mesh has no triangles left after welding.
    #[error("no triangles left after welding (all {0} were degenerate)")]
    Empty(u64),
    /// The `.mres` writer refused a cluster or the DAG (a format limit broken: a builder bug),
    /// or zstd failed.
    #[error("writing .mres: {0}")]
    Write(#[from] mres_format::write::WriteError),
}
