//! What a bake reads triangles from: a mesh in memory, or a large OBJ file streamed in two
//! passes (`mres_import::obj_stream`) so that it never has to fit in memory as text plus a
//! mesh. Both give their vertex attributes and a way to walk their triangles.

use mres_import::mesh::{Corner, NONE};
use mres_import::obj_stream::ObjVertices;
use mres_import::{import_file, ImportError, ImportLimits, InputKind, SourceMesh};
use std::path::Path;

/// Vertex attributes plus a triangle stream: what a sharded build reads.
pub trait TriangleSource: Sync {
    /// Positions (finite).
    fn positions(&self) -> &[[f32; 3]];
    /// Normals, or empty.
    fn normals(&self) -> &[[f32; 3]];
    /// UVs, or empty.
    fn uvs(&self) -> &[[f32; 2]];
    /// Triangles to stream (an estimate is fine: it only sizes the shards).
    fn triangles(&self) -> u64;
    /// Triangles the importer already dropped as degenerate, and faces of fewer than three
    /// vertices (not streamed).
    fn dropped(&self) -> u64;
    /// Calls `f` with every triangle's corners (absent attributes: [`NONE`]) and material,
    /// always in the same order.
    fn for_each_triangle(&self, f: &mut dyn FnMut([Corner; 3], u32)) -> Result<(), ImportError>;
}

impl TriangleSource for SourceMesh {
    fn positions(&self) -> &[[f32; 3]] {
        &self.positions
    }

    fn normals(&self) -> &[[f32; 3]] {
        self.normals.as_deref().unwrap_or_default()
    }

    fn uvs(&self) -> &[[f32; 2]] {
        self.uvs.as_deref().unwrap_or_default()
    }

    fn triangles(&self) -> u64 {
        self.materials.len() as u64
    }

    fn dropped(&self) -> u64 {
        self.degenerate_dropped
    }

    fn for_each_triangle(&self, f: &mut dyn FnMut([Corner; 3], u32)) -> Result<(), ImportError> {
        // A mesh's vertex carries all its attributes: a corner's attribute index is its vertex's.
        let index_or_none = |present: bool| if present { |v: u32| v } else { |_: u32| NONE };
        let (vn, vt) = (index_or_none(self.normals.is_some()), index_or_none(self.uvs.is_some()));
        for (t, &material) in self.indices.chunks_exact(3).zip(&self.materials) {
            f([0, 1, 2].map(|k| Corner { v: t[k], vt: vt(t[k]), vn: vn(t[k]) }), material);
        }
        Ok(())
    }
}

/// An OBJ file after the streaming reader's first pass: its vertex attributes in memory, its
/// faces read from the file again on each walk.
pub struct StreamedObj<'p> {
    path: &'p Path,
    obj: ObjVertices,
}

impl TriangleSource for StreamedObj<'_> {
    fn positions(&self) -> &[[f32; 3]] {
        &self.obj.positions
    }

    fn normals(&self) -> &[[f32; 3]] {
        &self.obj.normals
    }

    fn uvs(&self) -> &[[f32; 2]] {
        &self.obj.uvs
    }

    fn triangles(&self) -> u64 {
        self.obj.triangles
    }

    fn dropped(&self) -> u64 {
        self.obj.short_faces
    }

    fn for_each_triangle(&self, f: &mut dyn FnMut([Corner; 3], u32)) -> Result<(), ImportError> {
        self.obj.for_each_triangle(self.path, f)
    }
}

/// The triangles of one bake.
pub enum Source<'p> {
    /// A mesh in memory.
    Mesh(SourceMesh),
    /// A large OBJ file, streamed.
    Obj(StreamedObj<'p>),
}

/// The fewest bytes an OBJ triangle takes ("f 1 2 3\n" is 8, before any `v` line): files
/// smaller than this times `shard_triangles` cannot need sharding and are imported whole.
const OBJ_MIN_BYTES_PER_TRIANGLE: u64 = 8;

impl<'p> Source<'p> {
    /// Opens the mesh file at `path`: an OBJ with more than `shard_triangles` triangles is
    /// streamed (its shards are fed from the file), anything else is imported.
    pub fn open(path: &'p Path, shard_triangles: u64) -> Result<Source<'p>, ImportError> {
        let limits = ImportLimits::default();
        let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        if InputKind::from_path(path) == Some(InputKind::Obj) && size / OBJ_MIN_BYTES_PER_TRIANGLE > shard_triangles {
            let obj = ObjVertices::read(path, &limits)?;
            if obj.triangles > shard_triangles {
                return Ok(Source::Obj(StreamedObj { path, obj }));
            }
        }
        Ok(Source::Mesh(import_file(path, &limits)?))
    }

    fn get(&self) -> &dyn TriangleSource {
        match self {
            Source::Mesh(mesh) => mesh,
            Source::Obj(obj) => obj,
        }
    }
}

impl From<SourceMesh> for Source<'_> {
    fn from(mesh: SourceMesh) -> Self {
        Source::Mesh(mesh)
    }
}

impl TriangleSource for Source<'_> {
    fn positions(&self) -> &[[f32; 3]] {
        self.get().positions()
    }

    fn normals(&self) -> &[[f32; 3]] {
        self.get().normals()
    }

    fn uvs(&self) -> &[[f32; 2]] {
        self.get().uvs()
    }

    fn triangles(&self) -> u64 {
        self.get().triangles()
    }

    fn dropped(&self) -> u64 {
        self.get().dropped()
    }

    fn for_each_triangle(&self, f: &mut dyn FnMut([Corner; 3], u32)) -> Result<(), ImportError> {
        self.get().for_each_triangle(f)
    }
}
