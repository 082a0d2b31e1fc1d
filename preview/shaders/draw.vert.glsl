#version 460
// Vertex shader of the fallback draw: the index is (cluster << 8) | local vertex.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(location = 0) out vec3 world_position;

// Shared vertices must land on identical positions for a watertight raster, also across the
// two pipelines (front and back faces): no FMA contraction that a compiler might apply in one
// pipeline only. (`invariant` would say it more directly, but the validation layer of Debian
// bookworm (1.3.239) warns about glslang's Invariant decoration on the gl_PerVertex member.)
precise gl_Position;

void main() {
    uint index = uint(gl_VertexIndex);
    Cluster c = clusters[index >> 8];
    vec3 p = decode_position(c, index & 0xFFu);
    world_position = p;
    gl_Position = view.view_proj * vec4(p, 1.0);
}
