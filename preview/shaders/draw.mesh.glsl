#version 460
// Mesh-shader draw (VK_EXT_mesh_shader): one workgroup per visible cluster decodes its
// bit-packed vertices and its triangles straight from the page. The workgroup size is a free
// choice; loops stride by it, and nothing assumes a subgroup size.
#extension GL_EXT_mesh_shader : require
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x = 32) in;
layout(triangles, max_vertices = 256, max_primitives = 128) out;

layout(set = 0, binding = 5, std430) readonly buffer VisibleBlock { uvec2 visible[]; };

struct Payload {
    uint first;
};
taskPayloadSharedEXT Payload payload;

layout(location = 0) out vec3 world_position[];
layout(location = 1) flat out uint slot[];

void main() {
    uint k = payload.first + gl_WorkGroupID.x;
    uvec2 entry = visible[k];
    Cluster c = clusters[entry.x];
    Instance inst = instances[entry.y];
    SetMeshOutputsEXT(c.vertex_count, c.triangle_count);
    for (uint v = gl_LocalInvocationIndex; v < c.vertex_count; v += gl_WorkGroupSize.x) {
        precise vec3 p = to_world(inst, decode_position(c, v, inst.grid));
        world_position[v] = p;
        slot[v] = k;
        precise vec4 clip = view.view_proj * vec4(p, 1.0);
        gl_MeshVerticesEXT[v].gl_Position = clip;
    }
    uint page = page_base[c.page];
    uint index_block = page + page_words[((page + c.header_offset) >> 2) + 8u];
    for (uint tri = gl_LocalInvocationIndex; tri < c.triangle_count; tri += gl_WorkGroupSize.x) {
        uint at = index_block + 3u * tri;
        uvec3 corners = uvec3(read_u8(at), read_u8(at + 1u), read_u8(at + 2u));
        // A mirroring transform reverses the winding: reverse it back.
        gl_PrimitiveTriangleIndicesEXT[tri] = inst.mirrored != 0u ? corners.xzy : corners;
    }
}
