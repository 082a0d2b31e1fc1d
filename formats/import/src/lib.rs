//! Importers: Wavefront OBJ (via `tobj`), glTF 2.0 / GLB (via `gltf`) and PLY (ASCII and
//! binary) into one [`SourceMesh`].
//!
//! Every importer treats its input as hostile: sizes are checked against [`ImportLimits`]
//! before anything proportional to them is allocated, every index and byte range is checked
//! before use, and every failure is an [`ImportError`] naming the file — never a panic.
//!
//! # Choices shared by all formats
//! - Degenerate triangles (two equal indices, or two exactly equal positions) are dropped and
//!   counted in [`SourceMesh::degenerate_dropped`]; a file left with no triangles is an error
//!   ([`ImportErrorKind::NoTriangles`]). Vertices are not welded or compacted.
//! - A non-finite position is an error ([`ImportErrorKind::NonFinitePosition`]). Non-finite
//!   normals and UVs are not: a normal that is non-finite or zero becomes `[0, 0, 0]`, a
//!   non-finite UV component becomes `0`. Other normals are renormalised to unit length.
//! - An attribute (normals, UVs) that only part of the mesh has is dropped for the whole mesh
//!   rather than filled with made-up values.
//!
//! # OBJ
//! - Parsed by `tobj` with one index for positions, normals and UVs, so a vertex is split
//!   wherever its UV or normal differs (UV seams stay seams). Polygons are triangulated as
//!   fans around their first vertex (fine for convex polygons); points and polylines (`l`)
//!   are ignored. All objects and groups are merged, in file order.
//! - Material index = position of the `usemtl` name in order of first use in the file;
//!   faces before any `usemtl` get one past the last name (0 if there is none). `.mtl`
//!   files are never parsed, so a missing or broken library is not an error.
//! - Every parse error names its line: face indices (0, past the end, relative before the
//!   start, or positive past the vertices read where `tobj` resolves them: at the next `o`/`g`,
//!   material change or the end of the file), malformed or NaN/infinite `v`/`vt`/`vn` lines
//!   (after dividing by `w`), faces without vertices, `usemtl` without a name, bytes that are
//!   not UTF-8 (a BOM is allowed). Vertex colours are ignored.
//!
//! # glTF 2.0 and GLB
//! - The default scene is imported (else scene 0; with no scenes, every mesh once,
//!   untransformed), every mesh node under its world transform, instancing flattened by
//!   [`import_file`]; [`import_scene`] keeps meshes placed by two or more nodes apart, placed
//!   by instances (policy on [`scene`]).
//!   Normals use the inverse-transpose; a mirroring transform flips the winding back. Skins
//!   and morph targets are ignored (bind pose).
//! - Modes TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN, indexed or not; primitives of other
//!   modes are skipped ([`ImportErrorKind::UnsupportedPrimitiveMode`] if nothing else is
//!   left). Attributes: POSITION (f32), NORMAL (f32), TEXCOORD_0 (f32, or normalised u8/u16),
//!   and with KHR_mesh_quantization (gltfpack's default output) POSITION as i8/u8/i16/u16
//!   (normalised or not), NORMAL as normalised i8/i16, TEXCOORD_0 as i8/u8/i16/u16; sparse
//!   accessors and interleaved views are supported. Buffer views compressed by
//!   EXT_meshopt_compression (`gltfpack -c`, with its octahedral, quaternion and exponential
//!   filters) are decoded with meshoptimizer's decoders.
//! - Material index = the primitive's material, or the number of materials for primitives
//!   without one.
//! - Buffers: the GLB binary chunk, base64 `data:` URIs, or files given by relative
//!   (percent-encoded) URIs inside the glTF file's directory; `..` escapes, absolute paths
//!   and `file:` URIs are refused. Only buffers of imported primitives are loaded; images
//!   are never read. A node with EXT_mesh_gpu_instancing (`gltfpack -mi`) places its mesh
//!   once per element of its TRANSLATION / ROTATION / SCALE accessors, each copy's transform
//!   before the node's own (an instance each in [`import_scene`]). A required extension
//!   (`extensionsRequired`) is an error unless it is one of those three or changes nothing
//!   read here (`KHR_materials_*`, texture formats and `KHR_texture_transform`, lights):
//!   Draco and unknown ones are refused.
//!   UVs are read as stored: a texture's `KHR_texture_transform` (where gltfpack puts the
//!   scale of quantized UVs) stays the material's to apply.
//!
//! # PLY
//! - ASCII, binary little endian and binary big endian; read by hand (the module `ply` says
//!   why no crate is used). `element vertex` gives positions (`x y z`, any scalar type),
//!   normals (`nx ny nz`) and UVs (`s t`, `u v` or `texture_u texture_v`); `element face`
//!   gives polygons (`vertex_indices` or `vertex_index`, any integer types), triangulated as
//!   fans around their first index. Faces with fewer than three indices are skipped; other
//!   properties and elements are skipped by their size.
//! - All triangles get material 0 (PLY has no materials).
//! - Declared element counts must fit in the file, indices must be below the vertex count,
//!   positions must be finite as `f32`, and nothing may follow the last element; errors name
//!   the line (header, ASCII body) or byte offset (binary body) and the element entry.

#![deny(missing_docs)]

mod gltf;
pub mod mesh;
mod obj;
pub mod obj_stream;
mod obj_syntax;
pub mod obj_write;
mod ply;
pub mod scene;

pub use mesh::SourceMesh;
pub use scene::{ImportedScene, SceneFile};

use std::fs::File;
use std::io::Read;
use std::path::{Component, Path, PathBuf};

/// Which importer a path goes to, by extension (case-insensitive): `obj`, `gltf`, `glb`, `ply`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputKind {
    /// Wavefront OBJ (`.obj`), with optional `.mtl` material libraries.
    Obj,
    /// glTF 2.0 JSON (`.gltf`) with external or `data:` URI buffers.
    Gltf,
    /// Binary glTF 2.0 (`.glb`).
    Glb,
    /// PLY (`.ply`), ASCII or binary.
    Ply,
}

impl InputKind {
    /// The importer for `path`, chosen by its extension; `None` for any other extension.
    pub fn from_path(path: &Path) -> Option<InputKind> {
        let ext = path.extension()?.to_str()?;
        if ext.eq_ignore_ascii_case("obj") {
            Some(InputKind::Obj)
        } else if ext.eq_ignore_ascii_case("gltf") {
            Some(InputKind::Gltf)
        } else if ext.eq_ignore_ascii_case("glb") {
            Some(InputKind::Glb)
        } else if ext.eq_ignore_ascii_case("ply") {
            Some(InputKind::Ply)
        } else {
            None
        }
    }
}

/// Limits that keep a hostile file from exhausting memory; passed to [`import_file`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImportLimits {
    /// Largest file the importer reads, in bytes; applies to the mesh file and to each
    /// external glTF buffer separately. Larger files fail with [`ImportErrorKind::TooLarge`].
    pub max_file_bytes: u64,
    /// Largest number of triangles (counted before degenerate ones are dropped, glTF
    /// instancing included). The vertex count is also capped at three times this and at
    /// `u32::MAX`. Larger meshes fail with [`ImportErrorKind::TooLarge`].
    pub max_triangles: u64,
}

impl ImportLimits {
    /// Defaults: 4 GiB per file (well above any scan we bake, well below what would swap a
    /// workstation) and 500 million triangles (about 16 GB of `SourceMesh` for a closed
    /// mesh, the most a single bake is expected to handle).
    pub const DEFAULT: ImportLimits = ImportLimits { max_file_bytes: 4 << 30, max_triangles: 500_000_000 };
}

impl Default for ImportLimits {
    fn default() -> Self {
        ImportLimits::DEFAULT
    }
}

/// Why an import failed; always names the file ([`ImportError::path`]) and the problem.
///
/// The message of the underlying cause (I/O error, parser message) is part of the
/// `Display` text, so these errors expose no separate `source()`.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {kind}", path = path.display())]
pub struct ImportError {
    /// The file passed to [`import_file`] or [`referenced_files`].
    pub path: PathBuf,
    /// What went wrong.
    pub kind: ImportErrorKind,
}

/// The problems an import can report; each `Display` text says what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ImportErrorKind {
    /// The file could not be opened or read.
    #[error("cannot read file: {0}")]
    Io(std::io::Error),
    /// The extension is not one of `obj`, `gltf`, `glb`, `ply` (see [`InputKind::from_path`]).
    #[error("unsupported file extension (expected .obj, .gltf, .glb or .ply)")]
    UnsupportedExtension,
    /// The file has zero bytes.
    #[error("file is empty")]
    EmptyFile,
    /// The file is not valid OBJ / glTF / GLB / PLY (syntax, truncation, failed validation).
    #[error("parse error: {0}")]
    Parse(String),
    /// An index refers past the end of what it indexes (or is 0 in a 1-based OBJ index).
    #[error("{what} index {index} is out of range ({count} available)")]
    IndexOutOfRange {
        /// Where the index is and what it indexes, e.g. `line 7: vertex`.
        what: String,
        /// The index as written in the file (OBJ: 1-based or negative-relative).
        index: i64,
        /// How many elements there are to index.
        count: u64,
    },
    /// A vertex position is NaN or infinite (after the glTF node transform).
    #[error("non-finite vertex position: {0}")]
    NonFinitePosition(String),
    /// Every primitive of the glTF scene has a mode other than triangles, strips and fans.
    #[error("only unsupported primitive modes ({0}); no triangle primitives")]
    UnsupportedPrimitiveMode(String),
    /// No triangle is left (no faces at all, or all of them degenerate).
    #[error("no triangles to import ({degenerate_dropped} degenerate triangles dropped)")]
    NoTriangles {
        /// Triangles dropped as degenerate before the mesh turned out empty.
        degenerate_dropped: u64,
    },
    /// A glTF file without any mesh.
    #[error("glTF file contains no meshes")]
    NoMeshes,
    /// A glTF buffer URI that leads outside the directory of the glTF file (`..`, absolute
    /// paths, `file:` URIs).
    #[error("buffer URI {0:?} points outside the directory of the glTF file")]
    UriOutsideAssetDir(String),
    /// A glTF buffer URI that is neither a relative path nor a base64 `data:` URI.
    #[error("unsupported buffer URI {0:?} (only relative paths and base64 data: URIs)")]
    UnsupportedUri(String),
    /// An external glTF buffer file could not be read.
    #[error("cannot read buffer {uri:?}: {error}")]
    BufferIo {
        /// The URI as written in the glTF file.
        uri: String,
        /// The I/O error.
        error: std::io::Error,
    },
    /// A glTF buffer declares more bytes than its data (file, data URI, GLB chunk) has.
    #[error("buffer {buffer} declares {declared} bytes but only {actual} are available")]
    BufferTooShort {
        /// Index of the buffer in the glTF file.
        buffer: usize,
        /// `byteLength` as declared.
        declared: u64,
        /// Bytes actually available.
        actual: u64,
    },
    /// A glTF accessor has the wrong type for its use or reads outside its buffer view.
    #[error("accessor {accessor}: {reason}")]
    InvalidAccessor {
        /// Index of the accessor in the glTF file.
        accessor: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// The glTF file requires an extension this importer cannot decode (e.g. Draco).
    #[error("required glTF extension {0:?} is not supported")]
    UnsupportedGltfExtension(String),
    /// A file, triangle count or vertex count is above [`ImportLimits`].
    #[error("too large: {0}")]
    TooLarge(String),
}

/// Result of the format-specific code, which does not know the path to report.
type KindResult<T> = Result<T, ImportErrorKind>;

/// Imports one mesh file (OBJ, glTF, GLB or PLY, chosen by [`InputKind::from_path`]) into a
/// [`SourceMesh`] that satisfies the invariants documented on that type.
///
/// The [module documentation](self) says how each format's attributes, materials and
/// degenerate triangles are handled.
pub fn import_file(path: &Path, limits: &ImportLimits) -> Result<SourceMesh, ImportError> {
    import_kind(path, limits).map_err(|kind| ImportError { path: path.to_path_buf(), kind })
}

fn import_kind(path: &Path, limits: &ImportLimits) -> KindResult<SourceMesh> {
    let kind = InputKind::from_path(path).ok_or(ImportErrorKind::UnsupportedExtension)?;
    let bytes = read_file(path, limits.max_file_bytes).map_err(ImportErrorKind::Io)??;
    import_bytes(path, kind, bytes, limits)
}

/// Imports the contents `bytes` of the file `path` (which locates external glTF buffers).
fn import_bytes(path: &Path, kind: InputKind, bytes: Vec<u8>, limits: &ImportLimits) -> KindResult<SourceMesh> {
    if bytes.is_empty() {
        return Err(ImportErrorKind::EmptyFile);
    }
    match kind {
        InputKind::Obj => obj::import(bytes, limits),
        InputKind::Gltf | InputKind::Glb => gltf::import(path, &bytes, kind, limits),
        InputKind::Ply => ply::import(&bytes, limits),
    }
}

/// Imports one mesh file as a scene (policy on [`scene`]): glTF / GLB meshes placed by two
/// or more nodes become their own meshes, placed by instances; everything else is flattened
/// as [`import_file`] does. OBJ and PLY give [`import_file`]'s mesh and one identity instance.
/// Material names come with it ([`material_names`]).
pub fn import_scene(path: &Path, limits: &ImportLimits) -> Result<ImportedScene, ImportError> {
    let fail = |kind| ImportError { path: path.to_path_buf(), kind };
    let kind = InputKind::from_path(path).ok_or_else(|| fail(ImportErrorKind::UnsupportedExtension))?;
    if matches!(kind, InputKind::Gltf | InputKind::Glb) {
        let bytes = read_file(path, limits.max_file_bytes).map_err(|e| fail(ImportErrorKind::Io(e)))?.map_err(fail)?;
        if bytes.is_empty() {
            return Err(fail(ImportErrorKind::EmptyFile));
        }
        return gltf::import_scene(path, &bytes, kind, limits).map_err(fail);
    }
    let mesh = import_file(path, limits)?;
    let material_names = material_names(path)?;
    let stem = path.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let instance = scene::SceneInstance { name: stem, node: None, mesh: 0, transform: scene::IDENTITY };
    let meshes = vec![scene::SceneMesh { mesh, gltf_mesh: None }];
    Ok(ImportedScene { meshes, instances: vec![instance], material_names })
}

/// Material index -> name for the mesh file at `path`, matching [`SourceMesh::materials`]:
/// OBJ `usemtl` names in order of first use (read line by line; only `usemtl` lines are
/// checked), glTF material names (`None` where unnamed), nothing for PLY. An index past the
/// end has no material (OBJ faces before any `usemtl`, glTF primitives without one).
pub fn material_names(path: &Path) -> Result<Vec<Option<String>>, ImportError> {
    scene_outline(path).map(|outline| outline.material_names)
}

/// What a scene import of a file would give, found without reading its triangles (so that a
/// batch can look up a cached bake cheaply): [`material_names`], and whether
/// [`import_scene`] would place some mesh more than once.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneOutline {
    /// Material index -> name, as [`material_names`].
    pub material_names: Vec<Option<String>>,
    /// Whether some glTF mesh is placed by two or more nodes.
    pub instanced: bool,
}

/// The [`SceneOutline`] of the mesh file at `path`; errors like [`import_file`] for what it
/// reads.
pub fn scene_outline(path: &Path) -> Result<SceneOutline, ImportError> {
    let fail = |kind| ImportError { path: path.to_path_buf(), kind };
    let names = |names: Vec<String>| names.into_iter().map(Some).collect();
    match InputKind::from_path(path).ok_or_else(|| fail(ImportErrorKind::UnsupportedExtension))? {
        InputKind::Obj => Ok(SceneOutline {
            material_names: names(obj_stream::material_names(path).map_err(fail)?),
            instanced: false,
        }),
        InputKind::Ply => Ok(SceneOutline { material_names: Vec::new(), instanced: false }),
        kind @ (InputKind::Gltf | InputKind::Glb) => {
            let limits = ImportLimits::default();
            let bytes =
                read_file(path, limits.max_file_bytes).map_err(|e| fail(ImportErrorKind::Io(e)))?.map_err(fail)?;
            let (material_names, instanced) = gltf::outline(&bytes, kind).map_err(fail)?;
            Ok(SceneOutline { material_names, instanced })
        }
    }
}

/// Every file the import of `path` reads besides `path` itself, in a deterministic order
/// (order of first reference, no duplicates); meant for cache keys.
///
/// - OBJ: the `mtllib` material libraries that exist (and lie inside the OBJ's directory).
///   The import itself only numbers materials by `usemtl` name, but a library is listed
///   because a change to it may be meant to change the bake.
/// - glTF / GLB: the external buffer files used by the meshes. Images are never read and
///   never listed; `data:` URIs and the GLB binary chunk are part of `path`.
/// - PLY: none (its header is checked).
///
/// Errors like [`import_file`] with default limits (unreadable file, bad syntax, buffer URIs
/// outside the asset directory).
pub fn referenced_files(path: &Path) -> Result<Vec<PathBuf>, ImportError> {
    referenced_kind(path).map_err(|kind| ImportError { path: path.to_path_buf(), kind })
}

fn referenced_kind(path: &Path) -> KindResult<Vec<PathBuf>> {
    let kind = InputKind::from_path(path).ok_or(ImportErrorKind::UnsupportedExtension)?;
    let limits = ImportLimits::default();
    let bytes = read_file(path, limits.max_file_bytes).map_err(ImportErrorKind::Io)??;
    if bytes.is_empty() {
        return Err(ImportErrorKind::EmptyFile);
    }
    match kind {
        InputKind::Obj => obj::referenced_files(path, &bytes),
        InputKind::Gltf | InputKind::Glb => gltf::referenced_files(path, &bytes, kind),
        InputKind::Ply => ply::referenced_files(&bytes),
    }
}

/// Reads a whole file, refusing (without reading it) one above `max_bytes`.
///
/// The outer error is I/O, the inner one [`ImportErrorKind::TooLarge`], so callers can wrap
/// the I/O error in the variant that fits (mesh file or glTF buffer).
fn read_file(path: &Path, max_bytes: u64) -> std::io::Result<KindResult<Vec<u8>>> {
    let file = File::open(path)?;
    let declared = file.metadata()?.len();
    let too_large = |size: u64| {
        Err(ImportErrorKind::TooLarge(format!("{} is {size} bytes, the limit is {max_bytes}", path.display())))
    };
    if declared > max_bytes {
        return Ok(too_large(declared));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(declared).unwrap_or(0));
    // Read at most one byte past the limit, in case the file grows while we read it.
    file.take(max_bytes.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Ok(too_large(bytes.len() as u64));
    }
    Ok(Ok(bytes))
}

/// Resolves a relative path written in a mesh file (glTF buffer URI after percent-decoding,
/// OBJ `mtllib`) against the directory `dir` of that file.
///
/// Returns `None` if it would leave `dir`: absolute paths, Windows prefixes, or more `..`
/// components than directories before them. The check is lexical; symbolic links inside the
/// asset directory are followed on purpose (asset trees are often assembled from links).
fn resolve_inside(dir: &Path, relative: &str) -> Option<PathBuf> {
    if relative.is_empty() || relative.contains('\0') {
        return None;
    }
    // glTF URIs use '/', but a file written on Windows may use '\'; treat both as separators.
    let normalized = relative.replace('\\', "/");
    let mut parts: Vec<&str> = Vec::new();
    for component in Path::new(&normalized).components() {
        match component {
            Component::Normal(part) => parts.push(part.to_str()?),
            Component::CurDir => {}
            Component::ParentDir => {
                parts.pop()?;
            }
            Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    // A drive letter ("C:/...") is not a prefix on Unix; refuse it explicitly.
    if parts.first().is_some_and(|p| p.len() == 2 && p.ends_with(':')) {
        return None;
    }
    if parts.is_empty() {
        return None;
    }
    Some(parts.iter().fold(dir.to_path_buf(), |acc, part| acc.join(part)))
}

/// The directory relative references in `path` are resolved against.
fn asset_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Builds a [`SourceMesh`], dropping degenerate triangles and sanitising attributes.
struct MeshBuilder {
    mesh: SourceMesh,
}

impl MeshBuilder {
    /// A builder whose mesh has normals / UVs exactly when `normals` / `uvs` is true; the
    /// capacities are hints (callers pass counts already checked against the limits).
    fn new(normals: bool, uvs: bool, vertex_capacity: usize, triangle_capacity: usize) -> Self {
        let mesh = SourceMesh {
            positions: Vec::with_capacity(vertex_capacity),
            normals: normals.then(|| Vec::with_capacity(vertex_capacity)),
            uvs: uvs.then(|| Vec::with_capacity(vertex_capacity)),
            indices: Vec::with_capacity(triangle_capacity.saturating_mul(3)),
            materials: Vec::with_capacity(triangle_capacity),
            degenerate_dropped: 0,
        };
        MeshBuilder { mesh }
    }

    fn vertex_count(&self) -> usize {
        self.mesh.positions.len()
    }

    fn has_normals(&self) -> bool {
        self.mesh.normals.is_some()
    }

    fn has_uvs(&self) -> bool {
        self.mesh.uvs.is_some()
    }

    /// Appends a vertex. The position must be finite (callers check it, to report where);
    /// `normal` / `uv` are ignored when the mesh has no such attribute.
    fn push_vertex(&mut self, position: [f32; 3], normal: [f32; 3], uv: [f32; 2]) {
        debug_assert!(position.iter().all(|c| c.is_finite()));
        self.mesh.positions.push(position);
        if let Some(normals) = &mut self.mesh.normals {
            normals.push(unit_or_zero(normal));
        }
        if let Some(uvs) = &mut self.mesh.uvs {
            uvs.push(uv.map(|c| if c.is_finite() { c } else { 0.0 }));
        }
    }

    /// Appends a triangle of already pushed vertices, or counts it as degenerate.
    fn push_triangle(&mut self, triangle: [u32; 3], material: u32) {
        let [a, b, c] = triangle;
        let p = &self.mesh.positions;
        debug_assert!(triangle.iter().all(|&i| (i as usize) < p.len()));
        let (pa, pb, pc) = (p[a as usize], p[b as usize], p[c as usize]);
        if a == b || b == c || a == c || pa == pb || pb == pc || pa == pc {
            self.mesh.degenerate_dropped += 1;
            return;
        }
        self.mesh.indices.extend_from_slice(&triangle);
        self.mesh.materials.push(material);
    }

    /// The finished mesh, or [`ImportErrorKind::NoTriangles`] if no triangle survived.
    fn finish(self) -> KindResult<SourceMesh> {
        if self.mesh.materials.is_empty() {
            return Err(ImportErrorKind::NoTriangles { degenerate_dropped: self.mesh.degenerate_dropped });
        }
        Ok(self.mesh)
    }
}

/// `v` scaled to unit length, or zero if that is not possible (zero, tiny or non-finite).
pub(crate) fn unit_or_zero(v: [f32; 3]) -> [f32; 3] {
    let length = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if length.is_finite() && length > 0.0 {
        let unit = v.map(|c| c / length);
        if unit.iter().all(|c| c.is_finite()) {
            return unit;
        }
    }
    [0.0; 3]
}

/// Error for a vertex count above the limits (see [`ImportLimits::max_triangles`]).
fn check_vertex_count(vertices: u64, limits: &ImportLimits) -> KindResult<()> {
    let max = limits.max_triangles.saturating_mul(3).min(u64::from(u32::MAX));
    if vertices > max {
        return Err(ImportErrorKind::TooLarge(format!("{vertices} vertices, the limit is {max}")));
    }
    Ok(())
}

/// Error for a triangle count above [`ImportLimits::max_triangles`].
fn check_triangle_count(triangles: u64, limits: &ImportLimits) -> KindResult<()> {
    if triangles > limits.max_triangles {
        return Err(ImportErrorKind::TooLarge(format!("{triangles} triangles, the limit is {}", limits.max_triangles)));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn input_kind_by_extension_ignores_case() {
        assert_eq!(InputKind::from_path(Path::new("a/b.OBJ")), Some(InputKind::Obj));
        assert_eq!(InputKind::from_path(Path::new("b.glTF")), Some(InputKind::Gltf));
        assert_eq!(InputKind::from_path(Path::new("b.Glb")), Some(InputKind::Glb));
        assert_eq!(InputKind::from_path(Path::new("b.Ply")), Some(InputKind::Ply));
        assert_eq!(InputKind::from_path(Path::new("b.stl")), None);
        assert_eq!(InputKind::from_path(Path::new("obj")), None);
    }

    #[test]
    fn resolve_inside_refuses_escapes() {
        let dir = Path::new("/assets/x");
        assert_eq!(resolve_inside(dir, "a.bin"), Some(dir.join("a.bin")));
        assert_eq!(resolve_inside(dir, "./sub/../a.bin"), Some(dir.join("a.bin")));
        assert_eq!(resolve_inside(dir, "sub/a.bin"), Some(dir.join("sub/a.bin")));
        for bad in [
            "../a.bin",
            "../../etc/passwd",
            "sub/../../a.bin",
            "/etc/passwd",
            "\\etc\\passwd",
            "..\\a.bin",
            "C:/Windows/a.bin",
            "",
            ".",
            "a\0b",
        ] {
            assert_eq!(resolve_inside(dir, bad), None, "{bad:?}");
        }
    }

    #[test]
    fn builder_drops_degenerates_and_sanitises() {
        let mut b = MeshBuilder::new(true, true, 4, 3);
        b.push_vertex([0.0; 3], [0.0, 0.0, 2.0], [f32::NAN, 1.0]);
        b.push_vertex([1.0, 0.0, 0.0], [f32::INFINITY, 0.0, 0.0], [0.5, 0.5]);
        b.push_vertex([0.0, 1.0, 0.0], [0.0; 3], [0.0, 0.0]);
        b.push_vertex([0.0, 1.0, 0.0], [0.0; 3], [0.0, 0.0]);
        b.push_triangle([0, 1, 2], 7);
        b.push_triangle([0, 0, 2], 7);
        b.push_triangle([0, 2, 3], 7);
        let mesh = b.finish().unwrap();
        assert_eq!(mesh.indices, vec![0, 1, 2]);
        assert_eq!(mesh.materials, vec![7]);
        assert_eq!(mesh.degenerate_dropped, 2);
        let normals = mesh.normals.unwrap();
        assert_eq!(normals[0], [0.0, 0.0, 1.0]);
        assert_eq!(normals[1], [0.0; 3]);
        assert_eq!(mesh.uvs.unwrap()[0], [0.0, 1.0]);
    }

    /// Imports every truncation of `valid` and `valid` with each byte flipped by a few
    /// masks; each import must return (`Ok` or `Err`), never panic. In-process, from memory,
    /// so that thousands of variants take well under a second.
    fn fuzz(name: &str, valid: &[u8]) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name);
        let kind = InputKind::from_path(&path).unwrap();
        let limits = ImportLimits::default();
        assert!(import_bytes(&path, kind, valid.to_vec(), &limits).is_ok());
        for length in 0..valid.len() {
            check_located(kind, import_bytes(&path, kind, valid[..length].to_vec(), &limits));
        }
        for position in 0..valid.len() {
            for mask in [0x01, 0x02, 0x10, 0x20, 0x80, 0xff] {
                let mut bytes = valid.to_vec();
                bytes[position] ^= mask;
                check_located(kind, import_bytes(&path, kind, bytes, &limits));
            }
        }
    }

    /// OBJ and PLY syntax, index and position errors must say where (line or byte offset).
    fn check_located(kind: InputKind, result: KindResult<SourceMesh>) {
        let Err(err) = result else { return };
        let located = matches!(
            err,
            ImportErrorKind::Parse(_) | ImportErrorKind::IndexOutOfRange { .. } | ImportErrorKind::NonFinitePosition(_)
        );
        if located && matches!(kind, InputKind::Obj | InputKind::Ply) {
            let message = err.to_string();
            assert!(message.contains("line ") || message.contains("byte "), "no location: {message}");
        }
    }

    #[test]
    fn fuzz_ply() {
        fuzz("cube_ascii.ply", include_bytes!("../tests/data/cube_ascii.ply"));
        fuzz("faces_first_pentagon.ply", include_bytes!("../tests/data/faces_first_pentagon.ply"));
        for (name, bytes) in [
            ("cube_binary_le.ply", &include_bytes!("../tests/data/cube_binary_le.ply")[..]),
            ("cube_binary_be.ply", &include_bytes!("../tests/data/cube_binary_be.ply")[..]),
        ] {
            fuzz(name, bytes);
            // Every byte of a binary PLY belongs to the header or an element: each
            // truncation is an error.
            for length in 0..bytes.len() {
                let result =
                    import_bytes(Path::new(name), InputKind::Ply, bytes[..length].to_vec(), &Default::default());
                assert!(result.is_err(), "{name} cut to {length} bytes imported");
            }
        }
    }

    #[test]
    fn fuzz_obj_new_paths() {
        fuzz("cube.obj", include_bytes!("../tests/data/cube.obj"));
        fuzz("partial_vertex_colours.obj", include_bytes!("../tests/data/partial_vertex_colours.obj"));
    }

    #[test]
    fn fuzz_glb() {
        fuzz("triangle.glb", include_bytes!("../tests/data/triangle.glb"));
    }

    #[test]
    fn fuzz_gltf() {
        fuzz("strip_fan.gltf", include_bytes!("../tests/data/strip_fan.gltf"));
        fuzz("interleaved_sparse.gltf", include_bytes!("../tests/data/interleaved_sparse.gltf"));
        fuzz("two_primitives_transform.gltf", include_bytes!("../tests/data/two_primitives_transform.gltf"));
    }

    /// Replaces each number in a glTF's JSON with values chosen to break size arithmetic
    /// (zero, negative, off by one, powers of two at integer-width limits, huge floats).
    #[test]
    fn fuzz_gltf_numbers() {
        const VALUES: [&str; 12] = [
            "0",
            "-1",
            "1",
            "3",
            "5",
            "255",
            "65536",
            "2147483648",
            "4294967295",
            "18446744073709551615",
            "1e30",
            "-1e30",
        ];
        let files = [
            ("strip_fan.gltf", include_str!("../tests/data/strip_fan.gltf")),
            ("interleaved_sparse.gltf", include_str!("../tests/data/interleaved_sparse.gltf")),
        ];
        for (name, text) in files {
            let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name);
            let import = |text: String| {
                let _ = import_bytes(&path, InputKind::Gltf, text.into_bytes(), &Default::default());
            };
            // Numbers after the buffers (whose data URI would only change buffer bytes).
            let bytes = text.as_bytes();
            let mut i = text.find("\"bufferViews\"").unwrap_or(0);
            while i < bytes.len() {
                if !(bytes[i].is_ascii_digit() || bytes[i] == b'-') {
                    i += 1;
                    continue;
                }
                let end = (i..bytes.len())
                    .find(|&j| !matches!(bytes[j], b'0'..=b'9' | b'.' | b'-' | b'+' | b'e' | b'E'))
                    .unwrap_or(bytes.len());
                for value in VALUES {
                    import(format!("{}{value}{}", &text[..i], &text[end..]));
                }
                i = end;
            }
        }
    }

    #[test]
    fn fuzz_obj() {
        fuzz("partial_uvs.obj", include_bytes!("../tests/data/partial_uvs.obj"));
        fuzz("quads_ngon.obj", include_bytes!("../tests/data/quads_ngon.obj"));
        fuzz("two_objects.obj", include_bytes!("../tests/data/two_objects.obj"));
    }

    #[test]
    fn empty_builder_is_no_triangles() {
        let b = MeshBuilder::new(false, false, 0, 0);
        assert!(matches!(b.finish(), Err(ImportErrorKind::NoTriangles { degenerate_dropped: 0 })));
    }
}
