//! EXT_mesh_gpu_instancing (`gltfpack -mi`, and the GPU instances of Blender's and three.js's
//! exporters): a node draws its mesh once per element of its TRANSLATION, ROTATION and SCALE
//! accessors, each copy placed by that element's transform and then by the node's own. The
//! importer reads each copy as one more placement of the mesh: flattened, or an instance of a
//! scene ([`super::import_scene`]), so a scattered mesh is baked once.

use std::collections::BTreeMap;

use ::gltf::scene::Transform;
use ::gltf::Document;
use serde::Deserialize;

use super::super::{ImportErrorKind, KindResult};
use super::{attributes, check_accessor, Buffers, Use};
use crate::scene::Mat4;

#[derive(Deserialize)]
struct Instancing {
    #[serde(default)]
    attributes: BTreeMap<String, usize>,
}

#[derive(Deserialize)]
struct Extensions {
    #[serde(rename = "EXT_mesh_gpu_instancing")]
    instancing: Option<Instancing>,
}

#[derive(Deserialize)]
struct NodeJson {
    extensions: Option<Extensions>,
}

#[derive(Deserialize)]
struct RootJson {
    #[serde(default)]
    nodes: Vec<NodeJson>,
}

/// A node's instancing accessors: translation, rotation, scale (each optional).
type Accessors = [Option<usize>; 3];

/// Per node, its instancing accessors where it has the extension.
#[derive(Default)]
pub(super) struct GpuInstancing {
    nodes: Vec<Option<Accessors>>,
}

impl GpuInstancing {
    /// Reads the extension's blocks from the glTF JSON (valid JSON: the crate parsed it).
    pub(super) fn new(json_bytes: &[u8]) -> KindResult<GpuInstancing> {
        let root: RootJson = super::extension_json(json_bytes)?;
        let nodes = root
            .nodes
            .into_iter()
            .map(|n| {
                let attributes = n.extensions?.instancing?.attributes;
                Some(["TRANSLATION", "ROTATION", "SCALE"].map(|name| attributes.get(name).copied()))
            })
            .collect();
        Ok(GpuInstancing { nodes })
    }

    fn accessors(&self, node: usize) -> Option<Accessors> {
        self.nodes.get(node).copied().flatten()
    }

    /// How many copies of its mesh node `node` draws: 1 without the extension, else the
    /// element count its accessors agree on (checked, their buffers marked in `used`).
    pub(super) fn copies(&self, document: &Document, node: usize, used: &mut [bool]) -> KindResult<u64> {
        let Some(accessors) = self.accessors(node) else { return Ok(1) };
        let fail = |reason: String| ImportErrorKind::Parse(format!("node {node} (EXT_mesh_gpu_instancing): {reason}"));
        let mut count = None;
        for (index, use_) in accessors.iter().zip([Use::Translation, Use::Rotation, Use::Scale]) {
            let Some(index) = *index else { continue };
            let accessor =
                document.accessors().nth(index).ok_or_else(|| fail(format!("accessor {index} does not exist")))?;
            let n = check_accessor(&accessor, use_, used)?;
            if count.is_some_and(|c| c != n) {
                return Err(fail(format!("accessor {index} has {n} elements, another {}", count.unwrap_or(0))));
            }
            count = Some(n);
        }
        count.map(|n| n as u64).ok_or_else(|| fail("no TRANSLATION, ROTATION or SCALE".into()))
    }

    /// The transforms of node `node`'s copies, applied before its own (`None` without the
    /// extension); its accessors were checked by [`GpuInstancing::copies`].
    pub(super) fn transforms(
        &self,
        document: &Document,
        node: usize,
        buffers: &Buffers,
    ) -> KindResult<Option<Vec<Mat4>>> {
        let Some([translation, rotation, scale]) = self.accessors(node) else { return Ok(None) };
        let data = |b: ::gltf::Buffer| buffers.get(b.index()).and_then(|d| d.as_deref());
        let unreadable =
            |index: usize| ImportErrorKind::InvalidAccessor { accessor: index, reason: "could not be read".into() };
        let read3 = |index: Option<usize>, default: [f32; 3]| -> KindResult<Box<dyn Iterator<Item = [f32; 3]> + '_>> {
            let Some(index) = index else { return Ok(Box::new(std::iter::repeat(default))) };
            let accessor = document.accessors().nth(index).ok_or_else(|| unreadable(index))?;
            attributes::read::<3>(accessor, data).ok_or_else(|| unreadable(index))
        };
        let rotations: Box<dyn Iterator<Item = [f32; 4]>> = match rotation {
            None => Box::new(std::iter::repeat([0.0, 0.0, 0.0, 1.0])),
            Some(index) => {
                let accessor = document.accessors().nth(index).ok_or_else(|| unreadable(index))?;
                attributes::read::<4>(accessor, data).ok_or_else(|| unreadable(index))?
            }
        };
        // At least one accessor is given and they agree on their count (see `copies`), so the
        // zip ends with them; an absent one repeats its default.
        let copies = read3(translation, [0.0; 3])?.zip(rotations).zip(read3(scale, [1.0; 3])?);
        let transform = |((translation, rotation), scale): (([f32; 3], [f32; 4]), [f32; 3])| {
            let length = rotation.iter().map(|c| c * c).sum::<f32>().sqrt();
            let rotation = if length > 0.0 { rotation.map(|c| c / length) } else { [0.0, 0.0, 0.0, 1.0] };
            Transform::Decomposed { translation, rotation, scale }.matrix()
        };
        Ok(Some(copies.map(transform).collect()))
    }
}
