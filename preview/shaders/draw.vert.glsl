#version 460
// Vertex shader of the fallback draw: the index is (visible slot << 8) | local vertex.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(set = 0, binding = 5, std430) readonly buffer VisibleBlock { uvec2 visible[]; };

layout(location = 0) out vec3 world_position;
layout(location = 1) flat out uint slot;

// Shared vertices must land on identical positions for a watertight raster, also across the
// two pipelines (front and back faces): no FMA contraction that a compiler might apply in one
// pipeline only. (`invariant` would say it more directly, but the validation layer of Debian
// bookworm (1.3.239) warns about glslang's Invariant decoration on the gl_PerVertex member.)
precise gl_Position;

void main() {
    uint index = uint(gl_VertexIndex);
    uvec2 entry = visible[index >> 8];
    Cluster c = clusters[entry.x];
    Instance inst = instances[entry.y];
    precise vec3 p = to_world(inst, decode_position(c, index & 0xFFu, inst.grid));
    world_position = p;
    slot = index >> 8;
    gl_Position = view.view_proj * vec4(p, 1.0);
}
