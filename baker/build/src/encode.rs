//! The adapter from the builder's DAG to the `.mres` writer (`docs/FORMAT.md`): clusters get
//! a local vertex array and 8-bit local indices and are encoded as they are handed over (the
//! compact form a large bake keeps), groups and the file header are made at the end.

use crate::dag::{BuiltCluster, BuiltDag, BuiltGroup, DagOutput, Frame};
use crate::error::BakeError;
use crate::settings::{BakeSettings, PageEncoding};
use crate::weld::WeldedMesh;
use mres_format::write::{write_encoded_with, EncodedCluster, PageCoding};
use mres_format::{DagCluster, Group, Header, FLAG_MATERIALS, FLAG_NORMALS, FLAG_UVS};

/// A [`DagOutput`] that encodes clusters for the `.mres` writer.
pub struct Encoder {
    normal_bits: u32,
    position_bits: u32,
    coding: PageCoding,
    clusters: Vec<EncodedCluster>,
}

impl Encoder {
    /// An encoder for clusters baked with `settings`.
    pub fn new(settings: &BakeSettings) -> Encoder {
        let coding = match (settings.page_encoding, settings.independent_pages) {
            (PageEncoding::Layout, _) => PageCoding::Layout,
            (PageEncoding::Compact, true) => PageCoding::Independent,
            (PageEncoding::Compact, false) => PageCoding::FarCopies,
        };
        Encoder {
            normal_bits: settings.normal_bits,
            position_bits: settings.position_bits,
            coding,
            clusters: Vec::new(),
        }
    }

    /// Clusters encoded so far.
    pub fn count(&self) -> usize {
        self.clusters.len()
    }

    /// The file header of a DAG with `frame` and `source_triangles`.
    fn header(&self, frame: &Frame, source_triangles: u64) -> Header {
        let flag = |on: bool, flag: u32| if on { flag } else { 0 };
        Header {
            flags: flag(frame.normals, FLAG_NORMALS)
                | flag(frame.uvs, FLAG_UVS)
                | flag(frame.multi_material, FLAG_MATERIALS),
            grid: frame.grid,
            uv: frame.uv,
            normal_bits: self.normal_bits,
            position_bits: self.position_bits,
            level_count: 0,
            source_triangles,
        }
    }
}

impl DagOutput for Encoder {
    type Cluster = EncodedCluster;

    fn convert(&self, mesh: &WeldedMesh, cluster: &BuiltCluster, index: usize) -> Result<EncodedCluster, BakeError> {
        let header = self.header(&Frame::of(mesh), 0);
        Ok(EncodedCluster::new(&dag_cluster(mesh, cluster), &header, index)?)
    }

    fn append(&mut self, clusters: Vec<EncodedCluster>, global: &dyn Fn(u32) -> u32) {
        self.clusters.extend(clusters.into_iter().map(|mut c| {
            c.group = global(c.group);
            c.own_group = global(c.own_group);
            c
        }));
    }
}

/// Writes a built DAG as `.mres` bytes, pages compressed with zstd at `zstd_level`.
pub fn write(dag: BuiltDag<Encoder>, zstd_level: i32) -> Result<Vec<u8>, BakeError> {
    let header = dag.clusters.header(&dag.frame, dag.source_triangles);
    let groups: Vec<Group> = dag.groups.iter().map(group).collect();
    let coding = dag.clusters.coding;
    Ok(write_encoded_with(&header, &groups, dag.clusters.clusters, zstd_level, coding)?)
}

/// A group in the writer's form (its clusters and page are laid out by the writer).
fn group(g: &BuiltGroup) -> Group {
    Group { sphere: g.sphere, error: g.error, level: g.level, first_cluster: 0, cluster_count: 0, page: 0 }
}

/// One cluster in the writer's form: a local vertex array (grid positions, normals, UVs) and
/// 8-bit local indices.
fn dag_cluster(mesh: &WeldedMesh, c: &BuiltCluster) -> DagCluster {
    // (meshopt_optimizeMeshletLevel 3 shrank the compressed indices by 2% on the sphere but
    // took 17% of the bake: not worth it.)
    let (vertices, indices) = meshopt::extract_meshlet_indices(&c.indices);
    let pick = |v: &u32| *v as usize;
    let triangle_vertex = indices.chunks_exact(3).map(|t| vertices[t[0] as usize] as usize);
    DagCluster {
        group: c.group,
        own_group: c.own_group,
        positions: vertices.iter().map(|v| mesh.grid_positions[pick(v)]).collect(),
        normals: mesh.normals.as_ref().map(|n| vertices.iter().map(|v| n[pick(v)]).collect()).unwrap_or_default(),
        uvs: mesh.uvs.as_ref().map(|u| vertices.iter().map(|v| u[pick(v)]).collect()).unwrap_or_default(),
        materials: if mesh.multi_material {
            triangle_vertex.map(|v| mesh.materials[v].min(u16::MAX as u32) as u16).collect()
        } else {
            Vec::new()
        },
        indices,
        open_edges: c.open.clone(),
    }
}
