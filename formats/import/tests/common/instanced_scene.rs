//! The instanced glTF the scene tests write: a quad mesh placed by three nodes (one under a
//! rotated, scaled parent, one mirrored) and a triangle mesh placed once by an unnamed node.
//! Shared by `formats/import/tests/scene.rs` and `baker/cli/tests/it/scene.rs` (`#[path]`).

use base64::Engine as _;

/// The quad's positions (local space).
pub const QUAD: [[f32; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
/// The triangle's positions.
pub const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [0.0, 2.0, 1.0]];

/// Buffer: quad positions (48 bytes), quad normals (48), triangle positions (36), quad
/// indices (12), triangle indices (6, padded to 8).
fn buffer() -> Vec<u8> {
    let mut bytes: Vec<u8> = Vec::new();
    let floats = |bytes: &mut Vec<u8>, points: &[[f32; 3]]| {
        bytes.extend(points.iter().flatten().flat_map(|c| c.to_le_bytes()));
    };
    floats(&mut bytes, &QUAD);
    floats(&mut bytes, &[[0.0, 0.0, 1.0]; 4]);
    floats(&mut bytes, &TRI);
    bytes.extend([0u16, 1, 2, 0, 2, 3, 0, 1, 2, 0].iter().flat_map(|i| i.to_le_bytes()));
    bytes
}

/// The instanced scene (see the module docs); `instanced: false` places the quad only once.
pub fn scene_json(instanced: bool) -> String {
    let data = base64::engine::general_purpose::STANDARD.encode(buffer());
    let (bolt_b, bolt_c) = if instanced { (r#", "mesh": 0"#, r#", "mesh": 0"#) } else { ("", "") };
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0, 5]}}],
        "nodes": [
          {{"name": "root", "translation": [10, 0, 0], "children": [1, 2, 4]}},
          {{"name": "bolt_a", "mesh": 0, "translation": [0, 1, 0]}},
          {{"name": "arm", "rotation": [0, 0, 0.70710678, 0.70710678], "scale": [2, 2, 2], "children": [3]}},
          {{"name": "bolt_b", "translation": [1, 0, 0]{bolt_b}}},
          {{"mesh": 1}},
          {{"name": "bolt_c", "scale": [-1, 1, 1]{bolt_c}}}],
        "materials": [{{"name": "steel"}}, {{"name": "brass"}}],
        "meshes": [
          {{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 3, "material": 0}}]}},
          {{"primitives": [{{"attributes": {{"POSITION": 2}}, "indices": 4, "material": 1}}]}}],
        "buffers": [{{"byteLength": 152, "uri": "data:application/octet-stream;base64,{data}"}}],
        "bufferViews": [{{"buffer": 0, "byteLength": 48}}, {{"buffer": 0, "byteOffset": 48, "byteLength": 48}},
          {{"buffer": 0, "byteOffset": 96, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 132, "byteLength": 12}},
          {{"buffer": 0, "byteOffset": 144, "byteLength": 6}}],
        "accessors": [
          {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}},
          {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"}},
          {{"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,1], "max": [2,2,1]}},
          {{"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}},
          {{"bufferView": 4, "componentType": 5123, "count": 3, "type": "SCALAR"}}]}}"#
    )
}
