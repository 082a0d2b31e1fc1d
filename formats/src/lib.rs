//! File formats of mres: importers (OBJ via `tobj`, glTF 2.0 / GLB via `gltf`) into one
//! [`SourceMesh`] type, and the `.mres` container (spec in `docs/FORMAT.md`).
#![deny(missing_docs)]

pub mod import;
pub mod mesh;
pub mod mres;
pub mod obj_write;

pub use mesh::SourceMesh;
