#version 460
// Fallback path (no mesh shaders): expands the visible clusters into one index buffer. An index
// is (cluster << 8) | local vertex; the vertex shader decodes the position from the page. The
// draw's index count is the atomic allocator, so the indirect draw needs no extra pass.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x = 64) in;

layout(set = 0, binding = 4, std430) buffer CounterBlock { Counters counters; };
layout(set = 0, binding = 5, std430) readonly buffer VisibleBlock { uint visible[]; };
layout(set = 0, binding = 6, std430) writeonly buffer IndexBlock { uint indices[]; };

shared uint first;

void main() {
    uint count = counters.visible_count;
    for (uint k = gl_WorkGroupID.x; k < count; k += gl_NumWorkGroups.x) {
        uint ci = visible[k];
        Cluster c = clusters[ci];
        uint tris = c.triangle_count;
        if (gl_LocalInvocationIndex == 0u) {
            first = atomicAdd(counters.index_count, 3u * tris);
        }
        barrier();
        uint base = first;
        uint page = page_base[c.page];
        uint index_block = page + page_words[((page + c.header_offset) >> 2) + 8u];
        for (uint j = gl_LocalInvocationIndex; j < 3u * tris; j += gl_WorkGroupSize.x) {
            indices[base + j] = (ci << 8) | read_u8(index_block + j);
        }
        // `first` is rewritten by the next cluster.
        barrier();
    }
}
