#version 460
// Mesh-shader draw (VK_EXT_mesh_shader): one workgroup per visible cluster decodes its
// vertices and triangles straight from the page. The workgroup size is a free choice; loops
// stride by it, and nothing assumes a subgroup size.
#extension GL_EXT_mesh_shader : require
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x = 32) in;
layout(triangles, max_vertices = 256, max_primitives = 128) out;

layout(set = 0, binding = 4, std430) readonly buffer CounterBlock { Counters counters; };
layout(set = 0, binding = 5, std430) readonly buffer VisibleBlock { uint visible[]; };

layout(location = 0) out vec3 world_position[];

void main() {
    uint k = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    if (k >= counters.visible_count) {
        SetMeshOutputsEXT(0u, 0u);
        return;
    }
    Cluster c = clusters[visible[k]];
    SetMeshOutputsEXT(c.vertex_count, c.triangle_count);
    for (uint v = gl_LocalInvocationIndex; v < c.vertex_count; v += gl_WorkGroupSize.x) {
        vec3 p = decode_position(c, v);
        world_position[v] = p;
        precise vec4 clip = view.view_proj * vec4(p, 1.0);
        gl_MeshVerticesEXT[v].gl_Position = clip;
    }
    uint page = page_base[c.page];
    uint index_block = page + page_words[((page + c.header_offset) >> 2) + 8u];
    for (uint t = gl_LocalInvocationIndex; t < c.triangle_count; t += gl_WorkGroupSize.x) {
        uint at = index_block + 3u * t;
        gl_PrimitiveTriangleIndicesEXT[t] = uvec3(read_u8(at), read_u8(at + 1u), read_u8(at + 2u));
    }
}
