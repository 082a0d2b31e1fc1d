//! The one in-memory mesh type every importer produces and the baker consumes.

/// A triangle mesh as imported, before welding: flat, indexed, one material index per triangle.
///
/// Invariants (established by the importers, relied on by the baker):
/// - `indices.len() == 3 * materials.len()` and every index is `< positions.len()`;
/// - every position is finite;
/// - `normals`, when present, has one entry per position (unit length or zero);
/// - `uvs`, when present, has one entry per position (finite);
/// - no triangle has two equal indices (degenerate ones are dropped and counted in
///   [`SourceMesh::degenerate_dropped`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SourceMesh {
    /// Vertex positions, object space (glTF node transforms already applied).
    pub positions: Vec<[f32; 3]>,
    /// Per-vertex normals, if the source had them for every vertex.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Per-vertex texture coordinates (TEXCOORD_0 / `vt`), if the source had them for every vertex.
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Triangle list, three indices per triangle into `positions`.
    pub indices: Vec<u32>,
    /// Material index per triangle (OBJ: order of first `usemtl`; glTF: material index, with
    /// primitives without a material mapped to one past the last material).
    pub materials: Vec<u32>,
    /// Triangles dropped because two of their indices were equal or their positions coincided.
    pub degenerate_dropped: u64,
}

impl SourceMesh {
    /// A mesh of positions and a triangle list alone: no normals or UVs, one material, nothing
    /// dropped (generated meshes and tests).
    pub fn positions_only(positions: Vec<[f32; 3]>, indices: Vec<u32>) -> SourceMesh {
        let materials = vec![0; indices.len() / 3];
        SourceMesh { positions, normals: None, uvs: None, indices, materials, degenerate_dropped: 0 }
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Axis-aligned bounds `(min, max)` of all positions; `None` for an empty mesh.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        bounds(&self.positions)
    }
}

/// Axis-aligned bounds `(min, max)` of `points`; `None` if there are none.
pub fn bounds(points: &[[f32; 3]]) -> Option<([f32; 3], [f32; 3])> {
    let first = *points.first()?;
    Some(
        points.iter().fold((first, first), |(lo, hi), p| {
            ([0, 1, 2].map(|k| lo[k].min(p[k])), [0, 1, 2].map(|k| hi[k].max(p[k])))
        }),
    )
}

/// "No such attribute" in a [`Corner`].
pub const NONE: u32 = u32::MAX;

/// One face vertex: indices into a triangle source's attribute arrays (0-based), [`NONE`] where absent.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Corner {
    /// Position.
    pub v: u32,
    /// Texture coordinate.
    pub vt: u32,
    /// Normal.
    pub vn: u32,
}
