//! Export: turn a cut of a `.mres` file into a plain mesh (decoded positions, normals, UVs,
//! materials), welded by cluster-local vertex.

use mres_format::{MresError, MresFile};
use mres_import::SourceMesh;

/// The mesh made of the clusters in `cut` (indices into `file.clusters`).
pub fn cut_mesh(file: &MresFile, cut: &[u32]) -> Result<SourceMesh, MresError> {
    let mut mesh = SourceMesh::default();
    let h = &file.header;
    let (mut normals, mut uvs) = (Vec::new(), Vec::new());
    let mut page_cache: Option<(u32, Vec<u8>)> = None;
    for &c in cut {
        let page = file.groups[file.clusters[c as usize].group as usize].page;
        if page_cache.as_ref().is_none_or(|(p, _)| *p != page) {
            page_cache = Some((page, file.page(page)?));
        }
        let raw = &page_cache.as_ref().map(|(_, r)| r.as_slice()).unwrap_or(&[]);
        let d = file.decode_cluster(raw, c)?;
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(d.positions.iter().map(|q| h.grid.decode(*q)));
        normals.extend_from_slice(&d.normals);
        uvs.extend_from_slice(&d.uvs);
        mesh.indices.extend(d.indices.iter().map(|&i| base + i as u32));
        if d.materials.is_empty() {
            mesh.materials.extend(std::iter::repeat_n(0, d.indices.len() / 3));
        } else {
            mesh.materials.extend(d.materials.iter().map(|&m| m as u32));
        }
    }
    mesh.normals = (h.flags & mres_format::FLAG_NORMALS != 0).then_some(normals);
    mesh.uvs = (h.flags & mres_format::FLAG_UVS != 0).then_some(uvs);
    Ok(mesh)
}
