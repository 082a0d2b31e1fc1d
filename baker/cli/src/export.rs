//! Export: turn a cut of a `.mres` file into a plain mesh (decoded positions, normals, UVs,
//! materials), welded by cluster-local vertex; material names from the scene file beside it.

use mres_format::{MresError, MresFile};
use mres_import::scene::{SceneError, SCENE_SUFFIX};
use mres_import::{SceneFile, SourceMesh};
use std::path::Path;

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

/// The material names of the `.mres` file at `mres`, from the scene file beside it (the scene
/// file of `STEM.mres` and of `STEM.meshN.mres` is `STEM.scene.json`); empty when there is no
/// scene file or it does not list `mres`. A scene file that cannot be read is an error naming it.
pub fn material_names_for(mres: &Path) -> Result<Vec<Option<String>>, SceneError> {
    let Some(name) = mres.file_name().and_then(|n| n.to_str()) else { return Ok(Vec::new()) };
    let stem = name.strip_suffix(".mres").unwrap_or(name);
    let stem = match stem.rsplit_once(".mesh") {
        Some((base, n)) if !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()) => base,
        _ => stem,
    };
    let scene_path = mres.with_file_name(format!("{stem}{SCENE_SUFFIX}"));
    if !scene_path.is_file() {
        return Ok(Vec::new());
    }
    let scene = SceneFile::read(&scene_path)?;
    let listed = (0..scene.meshes.len()).find(|&i| scene.mesh_path(&scene_path, i).file_name() == mres.file_name());
    Ok(listed.map(|i| scene.meshes[i].materials.clone()).unwrap_or_default())
}
