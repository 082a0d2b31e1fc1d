//! glTF 2.0 / GLB importer on the `gltf` crate, used without its `import` feature: buffers
//! are resolved here, so that paths stay inside the asset directory and sizes are checked.
//!
//! The crate trusts the document in places: its GLB parser underflows on a header length
//! below 12, its validator indexes out of bounds on a bad POSITION accessor index, and its
//! accessor reader panics (debug builds: `debug_assert`, `unreachable!`, `count - 1`) on a
//! type that does not match the use, a stride smaller than the element, a zero count, or a
//! range past the data. So the GLB container is split here ([`split_container`]), the JSON
//! is checked for those indices before the crate validates it ([`parse_document`]), and
//! every accessor is checked ([`check_accessor`]: type, count, stride, byte range within its
//! view, view within its buffer) and every buffer's data length compared with its declared
//! `byteLength` before the reader touches them.
//!
//! What is imported (scene, modes, attributes, materials, URIs) is documented on the parent
//! module.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::buffer::{Source, View};
use ::gltf::json::validation::Checked;
use ::gltf::mesh::Mode;
use ::gltf::{json, Accessor, Document, Primitive, Semantic};
use base64::Engine as _;

use super::{
    asset_dir, check_triangle_count, check_vertex_count, read_file, resolve_inside, ImportErrorKind, ImportLimits,
    InputKind, KindResult, MeshBuilder,
};
use crate::scene::{ImportedScene, Mat4, SceneInstance, SceneMesh, IDENTITY};
use crate::SourceMesh;

mod attributes;
mod gpu_instancing;
mod meshopt;

/// Most node instances a scene may expand to. A node graph that reuses nodes (a DAG) can
/// expand exponentially; real scenes stay far below this.
const MAX_NODE_INSTANCES: u64 = 1 << 24;

/// One mesh placed in the scene.
struct Instance {
    mesh: usize,
    transform: Mat4,
    /// The node that places it (`None` for a file without scenes, which places every mesh once).
    node: Option<usize>,
}

/// What the checks found: what to read and how much of it there is.
struct Plan {
    /// Per mesh index, the indices of its primitives that will be read (triangle modes).
    primitives: Vec<Vec<usize>>,
    has_normals: bool,
    has_uvs: bool,
    /// Per mesh index, whether all its read primitives have normals / UVs (the scene import
    /// decides attributes per mesh, so that a mesh's content does not depend on the others).
    mesh_attributes: Vec<(bool, bool)>,
    /// Per mesh index, (vertices, triangles) of one copy: capacity hints.
    mesh_sizes: Vec<(u64, u64)>,
    /// Per buffer index, whether a checked accessor reads from it, or a compressed view of
    /// such a buffer is decoded from it.
    used_buffers: Vec<bool>,
    /// The views stored compressed (EXT_meshopt_compression).
    compressed: meshopt::Compressed,
    /// The nodes that draw their mesh several times (EXT_mesh_gpu_instancing).
    instancing: gpu_instancing::GpuInstancing,
    vertices: u64,
    triangles: u64,
}

/// Per-buffer data, `None` for buffers the import does not read (see `Plan::used_buffers`).
type Buffers<'a> = Vec<Option<Cow<'a, [u8]>>>;

/// Imports a `.gltf` or `.glb` file whose bytes are `bytes` (not empty, size-checked).
pub(super) fn import(path: &Path, bytes: &[u8], kind: InputKind, limits: &ImportLimits) -> KindResult<SourceMesh> {
    let (json_bytes, bin) = split_container(bytes, kind)?;
    let document = parse_document(json_bytes)?;
    // Count first, check against the limits, and only then expand the node graph: a small file
    // can describe millions of instances.
    let (_, plan) = checked(json_bytes, &document, limits)?;
    let buffers = load_buffers(&document, &plan, &asset_dir(path), bin, limits)?;
    let instances = scene_instances(&document, &plan, &buffers)?;
    read_mesh(&document, &instances, &plan, &buffers)
}

/// Imports a `.gltf` or `.glb` as a scene. If some mesh is placed by two or more nodes, every
/// mesh is read once in its local space and placed by instances; a scene without instancing
/// gives [`import`]'s flattened mesh and one identity instance (policy and reasons on
/// `crate::scene`).
pub(super) fn import_scene(
    path: &Path,
    bytes: &[u8],
    kind: InputKind,
    limits: &ImportLimits,
) -> KindResult<ImportedScene> {
    let (json_bytes, bin) = split_container(bytes, kind)?;
    let document = parse_document(json_bytes)?;
    let (_, plan) = checked(json_bytes, &document, limits)?;
    let buffers = load_buffers(&document, &plan, &asset_dir(path), bin, limits)?;
    let instances = scene_instances(&document, &plan, &buffers)?;
    let material_names = document.materials().map(|m| m.name().map(str::to_owned)).collect();
    let mut scene = ImportedScene { meshes: Vec::new(), instances: Vec::new(), material_names };
    let mut uses = vec![0usize; document.meshes().len()];
    for instance in &instances {
        uses[instance.mesh] += 1;
    }
    let stem = path.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    if uses.iter().all(|&n| n < 2) {
        let mesh = read_mesh(&document, &instances, &plan, &buffers)?;
        scene.meshes.push(SceneMesh { mesh, gltf_mesh: None });
        scene.instances.push(SceneInstance { name: stem, node: None, mesh: 0, transform: IDENTITY });
        return Ok(scene);
    }
    let mut dropped = 0;
    // Degenerate-only meshes are dropped, as flattening would drop their triangles.
    let mut keep = |result: KindResult<SourceMesh>| match result {
        Ok(mesh) => Ok(Some(mesh)),
        Err(ImportErrorKind::NoTriangles { degenerate_dropped }) => {
            dropped += degenerate_dropped;
            Ok(None)
        }
        Err(e) => Err(e),
    };
    // Every mesh once, in order of first placement; instances in depth-first node order.
    let mut slot: Vec<Option<Option<usize>>> = vec![None; uses.len()];
    for instance in &instances {
        let mesh_slot = match slot[instance.mesh] {
            Some(known) => known,
            None => {
                let read = keep(read_local(&document, instance.mesh, &plan, &buffers))?;
                let known = read.map(|mesh| {
                    scene.meshes.push(SceneMesh { mesh, gltf_mesh: Some(instance.mesh) });
                    scene.meshes.len() - 1
                });
                slot[instance.mesh] = Some(known);
                known
            }
        };
        if let Some(mesh) = mesh_slot {
            let node = instance.node;
            let name = node_name(&document, node);
            scene.instances.push(SceneInstance { name, node, mesh, transform: instance.transform });
        }
    }
    if scene.meshes.is_empty() {
        return Err(ImportErrorKind::NoTriangles { degenerate_dropped: dropped });
    }
    Ok(scene)
}

/// A node's name, or `node N` for an unnamed one.
fn node_name(document: &Document, node: Option<usize>) -> String {
    let Some(index) = node else { return String::new() };
    let named = document.nodes().nth(index).and_then(|n| n.name().map(str::to_owned));
    named.unwrap_or_else(|| format!("node {index}"))
}

/// The names of the glTF's materials, by index (`None` where unnamed), and whether
/// [`import_scene`] would find a mesh placed twice; from the JSON and accessor checks only,
/// no buffer is read.
pub(super) fn outline(bytes: &[u8], kind: InputKind) -> KindResult<(Vec<Option<String>>, bool)> {
    if bytes.is_empty() {
        return Err(ImportErrorKind::EmptyFile);
    }
    let (json_bytes, _) = split_container(bytes, kind)?;
    let document = parse_document(json_bytes)?;
    let names = document.materials().map(|m| m.name().map(str::to_owned)).collect();
    let (counts, plan) = checked(json_bytes, &document, &ImportLimits::default())?;
    let instanced = counts.iter().zip(&plan.primitives).any(|(&n, p)| n >= 2 && !p.is_empty());
    Ok((names, instanced))
}

/// The external buffer files the import of this glTF reads (see `import::referenced_files`).
pub(super) fn referenced_files(path: &Path, bytes: &[u8], kind: InputKind) -> KindResult<Vec<PathBuf>> {
    let (json_bytes, _) = split_container(bytes, kind)?;
    let document = parse_document(json_bytes)?;
    let (_, plan) = checked(json_bytes, &document, &ImportLimits::default())?;
    let dir = asset_dir(path);
    let mut files = Vec::new();
    for buffer in document.buffers() {
        if !plan.used_buffers[buffer.index()] || plan.compressed.is_placeholder(buffer.index()) {
            continue;
        }
        if let Source::Uri(uri) = buffer.source() {
            if let UriTarget::File(file) = classify_uri(uri, &dir)? {
                if !files.contains(&file) {
                    files.push(file);
                }
            }
        }
    }
    Ok(files)
}

/// Splits a GLB into its JSON and BIN chunks; a `.gltf` is all JSON.
fn split_container(bytes: &[u8], kind: InputKind) -> KindResult<(&[u8], Option<&[u8]>)> {
    if bytes.starts_with(b"glTF") {
        split_glb(bytes)
    } else if kind == InputKind::Glb {
        Err(ImportErrorKind::Parse("not a GLB file (no \"glTF\" magic)".into()))
    } else {
        Ok((bytes, None))
    }
}

/// Reads the GLB header and chunks, checking every length against the data.
fn split_glb(bytes: &[u8]) -> KindResult<(&[u8], Option<&[u8]>)> {
    let parse = |message: String| ImportErrorKind::Parse(format!("GLB: {message}"));
    let u32_at = |data: &[u8], at: usize| {
        let word = data.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes(<[u8; 4]>::try_from(word).ok()?) as usize)
    };
    let (Some(version), Some(length)) = (u32_at(bytes, 4), u32_at(bytes, 8)) else {
        return Err(parse("truncated header".into()));
    };
    if version != 2 {
        return Err(parse(format!("unsupported version {version}")));
    }
    if length < 12 || length > bytes.len() {
        return Err(parse(format!("header declares {length} bytes, the file has {} (truncated?)", bytes.len())));
    }
    let body = &bytes[12..length];
    let (mut json, mut bin) = (None, None);
    let mut at = 0;
    while let (Some(chunk_length), Some(chunk_type)) = (u32_at(body, at), body.get(at + 4..at + 8)) {
        let start = at + 8;
        let data = start
            .checked_add(chunk_length)
            .and_then(|end| body.get(start..end))
            .ok_or_else(|| parse(format!("chunk at byte {} runs past the end", at + 12)))?;
        match chunk_type {
            b"JSON" if json.is_none() => json = Some(data),
            b"BIN\0" if json.is_some() && bin.is_none() => bin = Some(data),
            _ if json.is_none() => return Err(parse("first chunk is not JSON".into())),
            _ => {} // The spec says to ignore unknown chunks.
        }
        // Chunks are padded to 4 bytes.
        at = (start + chunk_length).next_multiple_of(4);
    }
    let json = json.ok_or_else(|| parse("no JSON chunk".into()))?;
    Ok((json, bin))
}

/// Parses and validates the glTF JSON.
fn parse_document(json_bytes: &[u8]) -> KindResult<Document> {
    let mut root: json::Root = json::deserialize::from_slice(json_bytes)
        .map_err(|e| ImportErrorKind::Parse(format!("invalid glTF JSON: {e}")))?;
    if let Some(extension) = root.extensions_required.iter().find(|e| !importable(e)) {
        return Err(ImportErrorKind::UnsupportedGltfExtension(extension.clone()));
    }
    // The crate's validator refuses required extensions it does not know; those allowed
    // above are handled here or change nothing read here.
    root.extensions_required.clear();
    prepare_positions(&mut root)?;
    Document::from_json(root).map_err(|e| match e {
        ::gltf::Error::Validation(errors) => {
            let first: Vec<String> = errors.iter().take(3).map(|(path, error)| format!("{path}: {error}")).collect();
            let more = errors.len().saturating_sub(first.len());
            let more = if more > 0 { format!(" (and {more} more)") } else { String::new() };
            ImportErrorKind::Parse(format!("invalid glTF: {}{more}", first.join("; ")))
        }
        other => ImportErrorKind::Parse(format!("invalid glTF: {other}")),
    })
}

/// Whether the file declares `extension` in `extensionsUsed`, as glTF requires of every
/// extension it uses: the JSON is read again for an extension's blocks only then.
fn uses(document: &Document, extension: &str) -> bool {
    document.extensions_used().any(|e| e == extension)
}

/// The parts of the glTF JSON an extension module reads (the crate keeps no extension it
/// does not know); the JSON is valid, the crate parsed it.
fn extension_json<T: serde::de::DeserializeOwned>(json_bytes: &[u8]) -> KindResult<T> {
    serde_json::from_slice(json_bytes).map_err(|e| ImportErrorKind::Parse(format!("invalid glTF JSON: {e}")))
}

/// Whether a file that requires `extension` (`extensionsRequired`) can be imported: one
/// decoded here, or one that changes nothing this importer reads (it reads geometry, and
/// materials by index and name: material models, texture formats and transforms, lights).
/// The decoded ones: KHR_mesh_quantization (integer attributes, see `attributes`),
/// EXT_meshopt_compression (compressed buffer views, see `meshopt`) and
/// EXT_mesh_gpu_instancing (a node's copies, see `gpu_instancing`). Any other (Draco, one
/// unknown) could change the geometry: refused.
fn importable(extension: &str) -> bool {
    const NEUTRAL: [&str; 8] = [
        "KHR_texture_transform",
        "KHR_texture_basisu",
        "EXT_texture_webp",
        "EXT_texture_avif",
        "MSFT_texture_dds",
        "KHR_lights_punctual",
        "EXT_lights_image_based",
        "KHR_xmp_json_ld",
    ];
    let decoded = ["KHR_mesh_quantization", "EXT_meshopt_compression", "EXT_mesh_gpu_instancing"];
    decoded.contains(&extension) || extension.starts_with("KHR_materials_") || NEUTRAL.contains(&extension)
}

/// Checks POSITION accessor indices before the crate's validator indexes with them, and
/// fills in missing or malformed `min`/`max` on those accessors, which the validator
/// requires but this importer never reads (exporters sometimes omit them).
fn prepare_positions(root: &mut json::Root) -> KindResult<()> {
    let accessor_count = root.accessors.len();
    let is_vec3 = |value: &Option<json::Value>| {
        let parse = |v: &json::Value| json::deserialize::from_value::<[f32; 3]>(v.clone());
        value.as_ref().is_some_and(|v| parse(v).is_ok())
    };
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let key = Checked::Valid(json::mesh::Semantic::Positions);
            let Some(index) = primitive.attributes.get(&key) else {
                continue; // The validator reports the missing POSITION.
            };
            let Some(accessor) = root.accessors.get_mut(index.value()) else {
                return Err(ImportErrorKind::IndexOutOfRange {
                    what: format!("mesh {m} primitive {p}: POSITION accessor"),
                    index: index.value() as i64,
                    count: accessor_count as u64,
                });
            };
            for bound in [&mut accessor.min, &mut accessor.max] {
                if !is_vec3(bound) {
                    *bound = Some(json::Value::from(vec![0.0f32; 3]));
                }
            }
        }
    }
    Ok(())
}

/// How many times the scene places each mesh ([`mesh_instance_counts`]), and the [`Plan`]:
/// every check before a buffer is read.
fn checked(json_bytes: &[u8], document: &Document, limits: &ImportLimits) -> KindResult<(Vec<u64>, Plan)> {
    let instancing = match uses(document, "EXT_mesh_gpu_instancing") {
        true => gpu_instancing::GpuInstancing::new(json_bytes)?,
        false => Default::default(),
    };
    let counts = mesh_instance_counts(document, &instancing)?;
    let plan = plan(json_bytes, document, &counts, limits, instancing)?;
    Ok((counts, plan))
}

/// How many times each mesh is instanced by the scene to import (a node's GPU instances, see
/// `gpu_instancing`, counted as node instances), without expanding the node graph (a small
/// file can describe millions of instances). Rejects cycles and scenes of more than
/// `MAX_NODE_INSTANCES` node instances or mesh placements.
fn mesh_instance_counts(document: &Document, instancing: &gpu_instancing::GpuInstancing) -> KindResult<Vec<u64>> {
    if document.meshes().len() == 0 {
        return Err(ImportErrorKind::NoMeshes);
    }
    let Some(scene) = document.default_scene().or_else(|| document.scenes().next()) else {
        return Ok(vec![1; document.meshes().len()]);
    };
    let expanded = expanded_sizes(document)?;
    let total = scene.nodes().fold(0u64, |sum, n| sum.saturating_add(expanded[n.index()]));
    if total > MAX_NODE_INSTANCES {
        return Err(ImportErrorKind::TooLarge(format!(
            "the scene expands to {total} node instances, the limit is {MAX_NODE_INSTANCES}"
        )));
    }
    // Instances per node, pushed from parents to children in topological order (Kahn).
    let nodes: Vec<_> = document.nodes().collect();
    let mut incoming = vec![0usize; nodes.len()];
    for node in &nodes {
        for child in node.children() {
            incoming[child.index()] += 1;
        }
    }
    let mut count = vec![0u64; nodes.len()];
    for root in scene.nodes() {
        count[root.index()] += 1;
    }
    let mut ready: Vec<usize> = (0..nodes.len()).filter(|&n| incoming[n] == 0).collect();
    let mut per_mesh = vec![0u64; document.meshes().len()];
    let mut scratch = vec![false; document.buffers().len()];
    while let Some(n) = ready.pop() {
        if let Some(mesh) = nodes[n].mesh() {
            let copies = count[n].saturating_mul(instancing.copies(document, n, &mut scratch)?);
            per_mesh[mesh.index()] = per_mesh[mesh.index()].saturating_add(copies);
        }
        for child in nodes[n].children() {
            let c = child.index();
            count[c] = count[c].saturating_add(count[n]);
            incoming[c] -= 1;
            if incoming[c] == 0 {
                ready.push(c);
            }
        }
    }
    let placements = per_mesh.iter().fold(0u64, |sum, &n| sum.saturating_add(n));
    if placements > MAX_NODE_INSTANCES {
        return Err(ImportErrorKind::TooLarge(format!(
            "the scene places meshes {placements} times, the limit is {MAX_NODE_INSTANCES}"
        )));
    }
    Ok(per_mesh)
}

/// The meshes of the scene to import that have triangles to read (`plan`), with their world
/// transforms, in depth-first order (a node's GPU instances in their order). Call after `plan`
/// has checked the counts, with the `buffers` loaded.
fn scene_instances(document: &Document, plan: &Plan, buffers: &Buffers) -> KindResult<Vec<Instance>> {
    let Some(scene) = document.default_scene().or_else(|| document.scenes().next()) else {
        let all = document.meshes().map(|mesh| Instance { mesh: mesh.index(), transform: IDENTITY, node: None });
        return Ok(all.collect());
    };
    let mut instances = Vec::new();
    let mut stack: Vec<_> = scene.nodes().map(|node| (node, IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        let world = multiply(&parent, &node.transform().matrix());
        if let Some(mesh) = node.mesh().filter(|m| !plan.primitives[m.index()].is_empty()) {
            let place = |transform| Instance { mesh: mesh.index(), transform, node: Some(node.index()) };
            match plan.instancing.transforms(document, node.index(), buffers)? {
                None => instances.push(place(world)),
                Some(copies) => instances.extend(copies.iter().map(|copy| place(multiply(&world, copy)))),
            }
        }
        let children: Vec<_> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|child| (child, world)));
    }
    Ok(instances)
}

/// For each node, how many node instances its subtree expands to (itself included; a node
/// listed as the child of several parents counts once per parent). Errors on a cycle.
/// Iterative, so a long chain of nodes cannot overflow the stack.
fn expanded_sizes(document: &Document) -> KindResult<Vec<u64>> {
    #[derive(Clone, Copy, PartialEq)]
    enum State {
        New,
        Open,
        Done,
    }
    let nodes: Vec<_> = document.nodes().collect();
    let mut size = vec![0u64; nodes.len()];
    let mut state = vec![State::New; nodes.len()];
    let cycle = |node: usize| ImportErrorKind::Parse(format!("node hierarchy has a cycle through node {node}"));
    for root in 0..nodes.len() {
        // (node, whether its children are done)
        let mut stack = vec![(root, false)];
        while let Some((node, children_done)) = stack.pop() {
            let children = nodes[node].children().map(|child| child.index());
            if children_done {
                let sum = children.fold(1u64, |sum, child| sum.saturating_add(size[child]));
                size[node] = sum;
                state[node] = State::Done;
                continue;
            }
            match state[node] {
                State::Done => continue,
                // Reached again from inside its own subtree.
                State::Open => return Err(cycle(node)),
                State::New => {}
            }
            state[node] = State::Open;
            stack.push((node, true));
            for child in children {
                match state[child] {
                    State::Open => return Err(cycle(child)),
                    State::New => stack.push((child, false)),
                    State::Done => {}
                }
            }
        }
    }
    Ok(size)
}

/// Checks every primitive of every instanced mesh and sizes the result against `limits`;
/// `json_bytes` is the document's JSON, for the compressed views (see `meshopt`); the GPU
/// instancing accessors of nodes placing a mesh to read are checked too.
fn plan(
    json_bytes: &[u8],
    document: &Document,
    instance_count: &[u64],
    limits: &ImportLimits,
    instancing: gpu_instancing::GpuInstancing,
) -> KindResult<Plan> {
    let mesh_count = document.meshes().len();
    let mut plan = Plan {
        instancing,
        compressed: match uses(document, "EXT_meshopt_compression") {
            true => meshopt::Compressed::new(json_bytes)?,
            false => Default::default(),
        },
        primitives: vec![Vec::new(); mesh_count],
        has_normals: true,
        has_uvs: true,
        mesh_attributes: vec![(true, true); mesh_count],
        mesh_sizes: vec![(0, 0); mesh_count],
        used_buffers: vec![false; document.buffers().len()],
        vertices: 0,
        triangles: 0,
    };
    let mut skipped_modes: Vec<String> = Vec::new();
    for mesh in document.meshes().filter(|m| instance_count[m.index()] > 0) {
        let copies = instance_count[mesh.index()];
        for primitive in mesh.primitives() {
            let mode = primitive.mode();
            if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                skipped_modes.push(format!("{mode:?}"));
                continue;
            }
            let (normals_before, uvs_before) = (plan.has_normals, plan.has_uvs);
            (plan.has_normals, plan.has_uvs) = (true, true);
            let sizes = check_primitive(&primitive, &mut plan)?;
            let attributes = &mut plan.mesh_attributes[mesh.index()];
            *attributes = (attributes.0 && plan.has_normals, attributes.1 && plan.has_uvs);
            (plan.has_normals, plan.has_uvs) = (normals_before && plan.has_normals, uvs_before && plan.has_uvs);
            let one = &mut plan.mesh_sizes[mesh.index()];
            *one = (one.0.saturating_add(sizes.0), one.1.saturating_add(sizes.1));
            plan.primitives[mesh.index()].push(primitive.index());
            plan.vertices = plan.vertices.saturating_add(sizes.0.saturating_mul(copies));
            plan.triangles = plan.triangles.saturating_add(sizes.1.saturating_mul(copies));
        }
    }
    if plan.primitives.iter().all(Vec::is_empty) {
        if skipped_modes.is_empty() {
            return Err(ImportErrorKind::NoTriangles { degenerate_dropped: 0 });
        }
        skipped_modes.sort_unstable();
        skipped_modes.dedup();
        return Err(ImportErrorKind::UnsupportedPrimitiveMode(skipped_modes.join(", ")));
    }
    check_triangle_count(plan.triangles, limits)?;
    check_vertex_count(plan.vertices, limits)?;
    for node in document.nodes() {
        if node.mesh().is_some_and(|m| instance_count[m.index()] > 0 && !plan.primitives[m.index()].is_empty()) {
            plan.instancing.copies(document, node.index(), &mut plan.used_buffers)?;
        }
    }
    plan.compressed.mark_sources(&mut plan.used_buffers);
    Ok(plan)
}

/// Checks the accessors of a triangle primitive; returns its (vertex, triangle) counts and
/// records in `plan` the buffers it reads and whether it has normals and UVs.
fn check_primitive(primitive: &Primitive, plan: &mut Plan) -> KindResult<(u64, u64)> {
    let positions = primitive
        .get(&Semantic::Positions)
        .ok_or_else(|| ImportErrorKind::Parse(format!("primitive {} has no POSITION", primitive.index())))?;
    let vertices = check_accessor(&positions, Use::Position, &mut plan.used_buffers)?;
    for (semantic, use_, present) in [
        (Semantic::Normals, Use::Normal, &mut plan.has_normals),
        (Semantic::TexCoords(0), Use::TexCoord, &mut plan.has_uvs),
    ] {
        let Some(accessor) = primitive.get(&semantic) else {
            *present = false;
            continue;
        };
        let count = check_accessor(&accessor, use_, &mut plan.used_buffers)?;
        if count != vertices {
            return Err(ImportErrorKind::InvalidAccessor {
                accessor: accessor.index(),
                reason: format!("{count} elements, but POSITION has {vertices}"),
            });
        }
    }
    let corners = match primitive.indices() {
        Some(indices) => check_accessor(&indices, Use::Index, &mut plan.used_buffers)?,
        None => vertices,
    };
    let triangles = match primitive.mode() {
        Mode::Triangles => corners / 3,
        _ => corners.saturating_sub(2),
    };
    Ok((vertices as u64, triangles as u64))
}

/// What an accessor is read as; decides the types it may have.
#[derive(Clone, Copy)]
enum Use {
    Position,
    Normal,
    TexCoord,
    Index,
    /// EXT_mesh_gpu_instancing's attributes.
    Translation,
    Rotation,
    Scale,
}

/// Checks that the crate's reader can read `accessor` as `use_` without panicking or
/// reading past the declared data; returns its element count and marks its buffers used.
fn check_accessor(accessor: &Accessor, use_: Use, used_buffers: &mut [bool]) -> KindResult<usize> {
    let fail = |reason: String| ImportErrorKind::InvalidAccessor { accessor: accessor.index(), reason };
    // Besides f32, the integer types KHR_mesh_quantization allows (see `attributes`).
    let any = [DataType::F32, DataType::I8, DataType::U8, DataType::I16, DataType::U16];
    let (dimensions, types, name): (_, &[DataType], _) = match use_ {
        Use::Position => (Dimensions::Vec3, &any, "POSITION"),
        Use::Normal => (Dimensions::Vec3, &[DataType::F32, DataType::I8, DataType::I16], "NORMAL"),
        Use::TexCoord => (Dimensions::Vec2, &any, "TEXCOORD_0"),
        Use::Index => (Dimensions::Scalar, &[DataType::U8, DataType::U16, DataType::U32], "indices"),
        Use::Translation => (Dimensions::Vec3, &[DataType::F32, DataType::I8, DataType::I16], "TRANSLATION"),
        Use::Rotation => (Dimensions::Vec4, &[DataType::F32, DataType::I8, DataType::I16], "ROTATION"),
        Use::Scale => (Dimensions::Vec3, &[DataType::F32, DataType::I8, DataType::I16], "SCALE"),
    };
    if accessor.dimensions() != dimensions || !types.contains(&accessor.data_type()) {
        return Err(fail(format!(
            "{:?} {:?} cannot be used as {name} (expected {dimensions:?} of {types:?})",
            accessor.dimensions(),
            accessor.data_type()
        )));
    }
    let normalized_only = matches!(use_, Use::Normal | Use::Translation | Use::Rotation | Use::Scale);
    if normalized_only && accessor.data_type() != DataType::F32 && !accessor.normalized() {
        return Err(fail(format!("{:?} {name} must be normalized", accessor.data_type())));
    }
    let count = accessor.count();
    let element = accessor.size();
    let view =
        accessor.view().ok_or_else(|| fail("no bufferView (implicitly zero accessors are not supported)".into()))?;
    check_range(&view, accessor.offset(), count, element, used_buffers).map_err(&fail)?;
    if let Some(sparse) = accessor.sparse() {
        let (indices, values) = (sparse.indices(), sparse.values());
        let index_size = indices.index_type().size();
        check_range(&indices.view(), indices.offset(), sparse.count(), index_size, used_buffers)
            .map_err(|e| fail(format!("sparse indices: {e}")))?;
        check_range(&values.view(), values.offset(), sparse.count(), element, used_buffers)
            .map_err(|e| fail(format!("sparse values: {e}")))?;
    }
    Ok(count)
}

/// Checks that `count` elements of `element` bytes at `offset` in `view` (with its stride)
/// lie inside the view and the view inside its buffer's declared length, with the same
/// arithmetic as the crate's reader, but overflow-checked.
fn check_range(
    view: &View,
    offset: usize,
    count: usize,
    element: usize,
    used_buffers: &mut [bool],
) -> Result<(), String> {
    if count == 0 {
        return Err("count is 0".into());
    }
    let stride = view.stride().unwrap_or(element);
    if stride < element {
        return Err(format!(
            "byteStride {stride} of bufferView {} is smaller than the element ({element} bytes)",
            view.index()
        ));
    }
    let end = (count as u64 - 1)
        .checked_mul(stride as u64)
        .and_then(|bytes| bytes.checked_add(offset as u64))
        .and_then(|bytes| bytes.checked_add(element as u64));
    let view_length = view.length() as u64;
    match end {
        Some(end) if end <= view_length => {}
        _ => {
            return Err(format!(
                "{count} elements of {element} bytes (stride {stride}) from offset {offset} \
                 do not fit in bufferView {} ({view_length} bytes)",
                view.index()
            ))
        }
    }
    let buffer = view.buffer();
    let view_end = (view.offset() as u64).checked_add(view_length);
    if view_end.is_none_or(|end| end > buffer.length() as u64) {
        return Err(format!(
            "bufferView {} (offset {}, {view_length} bytes) runs past the end of buffer {} \
             ({} bytes)",
            view.index(),
            view.offset(),
            buffer.index(),
            buffer.length()
        ));
    }
    if let Some(used) = used_buffers.get_mut(buffer.index()) {
        *used = true;
    }
    Ok(())
}

/// Loads every used buffer, checking that its data is at least as long as declared.
fn load_buffers<'a>(
    document: &Document,
    plan: &Plan,
    dir: &Path,
    bin: Option<&'a [u8]>,
    limits: &ImportLimits,
) -> KindResult<Buffers<'a>> {
    let mut buffers = Vec::with_capacity(plan.used_buffers.len());
    for buffer in document.buffers() {
        // A placeholder of compressed views has no data to load: they are decoded into it.
        if !plan.used_buffers[buffer.index()] || plan.compressed.is_placeholder(buffer.index()) {
            buffers.push(None);
            continue;
        }
        let data: Cow<'a, [u8]> = match buffer.source() {
            Source::Bin => Cow::Borrowed(bin.ok_or_else(|| {
                ImportErrorKind::Parse(format!(
                    "buffer {} refers to the GLB binary chunk, but there is none",
                    buffer.index()
                ))
            })?),
            Source::Uri(uri) => match classify_uri(uri, dir)? {
                UriTarget::Data(bytes) => Cow::Owned(bytes),
                UriTarget::File(file) => Cow::Owned(
                    read_file(&file, limits.max_file_bytes)
                        .map_err(|error| ImportErrorKind::BufferIo { uri: short(uri), error })??,
                ),
            },
        };
        if data.len() < buffer.length() {
            return Err(ImportErrorKind::BufferTooShort {
                buffer: buffer.index(),
                declared: buffer.length() as u64,
                actual: data.len() as u64,
            });
        }
        buffers.push(Some(data));
    }
    let lengths: Vec<usize> = document.buffers().map(|b| b.length()).collect();
    plan.compressed.decode(&mut buffers, &lengths, &plan.used_buffers, limits.max_file_bytes)?;
    Ok(buffers)
}

/// Where a buffer URI leads.
enum UriTarget {
    /// A `data:` URI, decoded.
    Data(Vec<u8>),
    /// A file inside the asset directory.
    File(PathBuf),
}

/// Decodes a `data:` URI or resolves a relative (percent-encoded) path against `dir`.
/// Anything leading outside `dir` (`..`, absolute paths, `file:`) is refused.
fn classify_uri(uri: &str, dir: &Path) -> KindResult<UriTarget> {
    if let Some(scheme) = uri_scheme(uri) {
        if scheme.eq_ignore_ascii_case("data") {
            return decode_data_uri(uri).map(UriTarget::Data);
        }
        // A one-letter "scheme" is a Windows drive letter: an absolute path.
        if scheme.eq_ignore_ascii_case("file") || scheme.len() == 1 {
            return Err(ImportErrorKind::UriOutsideAssetDir(short(uri)));
        }
        return Err(ImportErrorKind::UnsupportedUri(short(uri)));
    }
    let decoded = percent_decode(uri)
        .ok_or_else(|| ImportErrorKind::Parse(format!("malformed percent-encoding in URI {:?}", short(uri))))?;
    resolve_inside(dir, &decoded).map(UriTarget::File).ok_or_else(|| ImportErrorKind::UriOutsideAssetDir(short(uri)))
}

/// The scheme of an absolute URI (RFC 3986: a letter, then letters, digits, `+-.`, then
/// `:`); `None` for a relative reference.
fn uri_scheme(uri: &str) -> Option<&str> {
    let (scheme, _) = uri.split_once(':')?;
    let mut chars = scheme.chars();
    let first_ok = chars.next().is_some_and(|c| c.is_ascii_alphabetic());
    let rest_ok = chars.all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c));
    (first_ok && rest_ok).then_some(scheme)
}

/// Decodes `data:[<media type>];base64,<data>`; other `data:` encodings are not supported.
fn decode_data_uri(uri: &str) -> KindResult<Vec<u8>> {
    let (header, payload) =
        uri.split_once(',').ok_or_else(|| ImportErrorKind::Parse(format!("malformed data URI {:?}", short(uri))))?;
    if !header.to_ascii_lowercase().ends_with(";base64") {
        return Err(ImportErrorKind::UnsupportedUri(short(uri)));
    }
    let engine = base64::engine::GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        base64::engine::GeneralPurposeConfig::new()
            .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
    );
    engine.decode(payload).map_err(|e| ImportErrorKind::Parse(format!("invalid base64 in data URI: {e}")))
}

/// Decodes `%XX` escapes; `None` for a malformed escape or a result that is not UTF-8.
fn percent_decode(text: &str) -> Option<String> {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = bytes.get(i + 1..i + 3)?;
            if !hex.iter().all(u8::is_ascii_hexdigit) {
                return None;
            }
            out.push(u8::from_str_radix(std::str::from_utf8(hex).ok()?, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// A URI shortened for error messages (data URIs can be megabytes long).
fn short(uri: &str) -> String {
    const MAX_CHARS: usize = 80;
    match uri.char_indices().nth(MAX_CHARS) {
        Some((cut, _)) => format!("{}...", &uri[..cut]),
        None => uri.to_owned(),
    }
}

/// Reads every planned primitive of every instance into one mesh.
fn read_mesh(document: &Document, instances: &[Instance], plan: &Plan, buffers: &Buffers) -> KindResult<SourceMesh> {
    let meshes: Vec<_> = document.meshes().collect();
    let unassigned_material = document.materials().len() as u32;
    let mut builder = MeshBuilder::new(plan.has_normals, plan.has_uvs, plan.vertices as usize, plan.triangles as usize);
    for instance in instances {
        let transform = Transform::new(&instance.transform);
        let primitives: Vec<_> = meshes[instance.mesh].primitives().collect();
        for &p in &plan.primitives[instance.mesh] {
            let primitive = &primitives[p];
            let material = primitive.material().index();
            let material = material.map_or(unassigned_material, |m| m as u32);
            let at = format!("mesh {} primitive {p}", instance.mesh);
            read_primitive(primitive, &at, &transform, buffers, material, &mut builder)?;
        }
    }
    builder.finish()
}

/// Reads the planned primitives of mesh `mesh` untransformed (its local space), with the
/// normals and UVs that all of them have.
fn read_local(document: &Document, mesh: usize, plan: &Plan, buffers: &Buffers) -> KindResult<SourceMesh> {
    let unassigned_material = document.materials().len() as u32;
    let (normals, uvs) = plan.mesh_attributes[mesh];
    let (vertices, triangles) = plan.mesh_sizes[mesh];
    let mut builder = MeshBuilder::new(normals, uvs, vertices as usize, triangles as usize);
    let identity = Transform::new(&IDENTITY);
    let primitives: Vec<_> = document.meshes().nth(mesh).map(|m| m.primitives().collect()).unwrap_or_default();
    for &p in &plan.primitives[mesh] {
        let primitive = &primitives[p];
        let material = primitive.material().index().map_or(unassigned_material, |m| m as u32);
        let at = format!("mesh {mesh} primitive {p}");
        read_primitive(primitive, &at, &identity, buffers, material, &mut builder)?;
    }
    builder.finish()
}

/// Appends one primitive's vertices (transformed) and triangles to `builder`; `at` names
/// the primitive in errors.
fn read_primitive(
    primitive: &Primitive,
    at: &str,
    transform: &Transform,
    buffers: &Buffers,
    material: u32,
    builder: &mut MeshBuilder,
) -> KindResult<()> {
    let data = |b: ::gltf::Buffer| buffers.get(b.index()).and_then(|d| d.as_deref());
    let reader = primitive.reader(data);
    let unreadable = |accessor: Option<Accessor>| ImportErrorKind::InvalidAccessor {
        accessor: accessor.map_or(0, |a| a.index()),
        reason: "could not be read".into(),
    };
    // Any component type the checks let through, as floats (see `attributes`).
    let accessor = |semantic: Semantic| primitive.get(&semantic);
    let floats3 = |semantic: Semantic| {
        accessor(semantic.clone())
            .and_then(|a| attributes::read::<3>(a, data))
            .ok_or_else(|| unreadable(accessor(semantic)))
    };
    let positions = floats3(Semantic::Positions)?;
    let mut normals = match builder.has_normals() {
        true => Some(floats3(Semantic::Normals)?),
        false => None,
    };
    let mut uvs = match builder.has_uvs() {
        true => Some(
            accessor(Semantic::TexCoords(0))
                .and_then(|a| attributes::read::<2>(a, data))
                .ok_or_else(|| unreadable(accessor(Semantic::TexCoords(0))))?,
        ),
        false => None,
    };
    let base = builder.vertex_count();
    for (i, local) in positions.enumerate() {
        let position = transform.point(local);
        if !position.iter().all(|c| c.is_finite()) {
            return Err(ImportErrorKind::NonFinitePosition(format!("{at} vertex {i}: {local:?} (world {position:?})")));
        }
        let normal = normals.as_mut().and_then(Iterator::next);
        let uv = uvs.as_mut().and_then(Iterator::next);
        builder.push_vertex(position, normal.map_or([0.0; 3], |n| transform.normal(n)), uv.unwrap_or([0.0; 2]));
    }
    let vertices = builder.vertex_count() - base;

    let corners: Vec<u32> = match (primitive.indices(), reader.read_indices()) {
        (None, _) => (0..vertices as u32).collect(),
        (Some(_), Some(indices)) => indices.into_u32().collect(),
        (Some(accessor), None) => return Err(unreadable(Some(accessor))),
    };
    let vertex = |index: u32| {
        if index as usize >= vertices {
            return Err(ImportErrorKind::IndexOutOfRange {
                what: format!("{at}: vertex"),
                index: i64::from(index),
                count: vertices as u64,
            });
        }
        Ok((base + index as usize) as u32)
    };
    let mut triangle = |a: u32, b: u32, c: u32| -> KindResult<()> {
        let (a, b, c) = (vertex(a)?, vertex(b)?, vertex(c)?);
        // A mirroring transform turns counter-clockwise into clockwise: swap back.
        let corners = if transform.mirrors { [a, c, b] } else { [a, b, c] };
        builder.push_triangle(corners, material);
        Ok(())
    };
    match primitive.mode() {
        Mode::TriangleStrip => {
            for (i, w) in corners.windows(3).enumerate() {
                match i % 2 {
                    0 => triangle(w[0], w[1], w[2])?,
                    _ => triangle(w[0], w[2], w[1])?,
                }
            }
        }
        Mode::TriangleFan => {
            for w in corners.get(1..).unwrap_or_default().windows(2) {
                triangle(corners[0], w[0], w[1])?;
            }
        }
        _ => {
            for t in corners.chunks_exact(3) {
                triangle(t[0], t[1], t[2])?;
            }
        }
    }
    Ok(())
}

/// A node's world transform, prepared for points and normals.
struct Transform {
    matrix: Mat4,
    /// Columns of the inverse-transpose of the upper 3×3, up to a positive factor (normals
    /// are renormalised afterwards).
    normal_columns: [[f32; 3]; 3],
    /// Whether the determinant is negative, so the winding must be flipped.
    mirrors: bool,
}

impl Transform {
    fn new(matrix: &Mat4) -> Self {
        let column = |c: usize| [matrix[c][0], matrix[c][1], matrix[c][2]];
        let (a, b, c) = (column(0), column(1), column(2));
        // For M = [a b c], inverse(M)ᵀ = [b×c, c×a, a×b] / det(M).
        let (bc, ca, ab) = (cross(b, c), cross(c, a), cross(a, b));
        let determinant = dot(a, bc);
        let sign = if determinant < 0.0 { -1.0 } else { 1.0 };
        Transform {
            matrix: *matrix,
            normal_columns: [bc, ca, ab].map(|v| v.map(|x| x * sign)),
            mirrors: determinant < 0.0,
        }
    }

    fn point(&self, p: [f32; 3]) -> [f32; 3] {
        let m = &self.matrix;
        [0, 1, 2].map(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])
    }

    /// The transformed normal, not normalised.
    fn normal(&self, n: [f32; 3]) -> [f32; 3] {
        let c = &self.normal_columns;
        [0, 1, 2].map(|r| c[0][r] * n[0] + c[1][r] * n[1] + c[2][r] * n[2])
    }
}

fn multiply(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut out = [[0.0; 4]; 4];
    for (c, column) in out.iter_mut().enumerate() {
        for (r, value) in column.iter_mut().enumerate() {
            *value = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    out
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uri_classification() {
        let dir = Path::new("/assets");
        let file = |uri| match classify_uri(uri, dir) {
            Ok(UriTarget::File(path)) => Some(path),
            _ => None,
        };
        assert_eq!(file("a%20b.bin"), Some(dir.join("a b.bin")));
        assert_eq!(file("sub/x.bin"), Some(dir.join("sub/x.bin")));
        for outside in [
            "../x.bin",
            "%2e%2e/%2e%2e/etc/passwd",
            "/etc/passwd",
            "file:///etc/passwd",
            "FILE:/etc/passwd",
            "C:/x.bin",
        ] {
            assert!(matches!(classify_uri(outside, dir), Err(ImportErrorKind::UriOutsideAssetDir(_))), "{outside}");
        }
        assert!(matches!(classify_uri("https://example.com/x.bin", dir), Err(ImportErrorKind::UnsupportedUri(_))));
        assert!(matches!(classify_uri("data:text/plain,hello", dir), Err(ImportErrorKind::UnsupportedUri(_))));
        for malformed in ["bad%zz.bin", "bad%+1.bin", "bad%4", "bad%ff.bin"] {
            let result = classify_uri(malformed, dir);
            assert!(matches!(result, Err(ImportErrorKind::Parse(_))), "{malformed}");
        }
        match classify_uri("data:application/octet-stream;base64,AQID", dir) {
            Ok(UriTarget::Data(bytes)) => assert_eq!(bytes, vec![1, 2, 3]),
            _ => panic!("data URI not decoded"),
        }
    }

    #[test]
    fn transform_of_normals_and_winding() {
        // Scale x by -2: mirrors, normals along x keep their direction, y untouched.
        let mut m = IDENTITY;
        m[0][0] = -2.0;
        m[3] = [1.0, 2.0, 3.0, 1.0];
        let t = Transform::new(&m);
        assert!(t.mirrors);
        assert_eq!(t.point([1.0, 1.0, 1.0]), [-1.0, 3.0, 4.0]);
        let n = t.normal([1.0, 0.0, 0.0]);
        assert!(n[0] < 0.0 && n[1] == 0.0 && n[2] == 0.0);
        // Non-uniform scale: the normal of the plane x = y must stay perpendicular to it.
        let mut s = IDENTITY;
        s[0][0] = 4.0;
        let t = Transform::new(&s);
        let n = t.normal([1.0, -1.0, 0.0]);
        let along_plane = t.point([1.0, 1.0, 0.0]);
        assert!(dot(n, along_plane).abs() < 1e-6);
    }

    #[test]
    fn multiply_composes_translation_then_scale() {
        let mut translate = IDENTITY;
        translate[3] = [1.0, 0.0, 0.0, 1.0];
        let mut scale = IDENTITY;
        scale[0][0] = 2.0;
        // parent (translate) * child (scale): scale first, then translate.
        let m = multiply(&translate, &scale);
        assert_eq!(Transform::new(&m).point([1.0, 0.0, 0.0]), [3.0, 0.0, 0.0]);
    }
}
