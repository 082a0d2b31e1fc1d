#version 460
// Fallback path (no mesh shaders): expands the visible clusters into one index buffer. An index
// is (visible slot << 8) | local vertex; the vertex shader reads the (cluster, instance) of the
// slot and decodes the position from the page. Workgroups allocate their range of the index
// buffer with an atomic; a cluster that does not fit is dropped (and counted), and the draw's
// index count is the end of the last range written, so it never reads an unwritten index
// (ranges are handed out in increasing order: every range before a dropped one was written).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x = 64) in;

layout(set = 0, binding = 4, std430) buffer CounterBlock { Counters counters; };
layout(set = 0, binding = 5, std430) readonly buffer VisibleBlock { uvec2 visible[]; };
layout(set = 0, binding = 6, std430) writeonly buffer IndexBlock { uint indices[]; };

shared uint first;

void main() {
    uint count = min(counters.visible_count, view.visible_capacity);
    for (uint k = gl_WorkGroupID.x; k < count; k += gl_NumWorkGroups.x) {
        uint ci = visible[k].x;
        bool mirrored = instances[visible[k].y].mirrored != 0u;
        Cluster c = clusters[ci];
        uint n = 3u * c.triangle_count;
        if (gl_LocalInvocationIndex == 0u) {
            first = atomicAdd(counters.index_alloc, n);
            if (first + n <= view.index_capacity) {
                atomicMax(counters.index_count, first + n);
            } else {
                atomicAdd(counters.dropped, 1u);
            }
        }
        barrier();
        uint base = first;
        if (base + n <= view.index_capacity) {
            uint page = page_base[c.page];
            uint index_block = page + page_words[((page + c.header_offset) >> 2) + 8u];
            for (uint j = gl_LocalInvocationIndex; j < n; j += gl_WorkGroupSize.x) {
                // A mirroring transform reverses the winding: swap each triangle's last two.
                uint corner = j % 3u;
                uint source = mirrored && corner != 0u ? j + 3u - 2u * corner : j;
                indices[base + j] = (k << 8) | read_u8(index_block + source);
            }
        }
        // `first` is rewritten by the next cluster.
        barrier();
    }
}
