#version 460
// Instance culling and LOD choice of the benchmark's alternatives (a discrete LOD chain, or the
// full-resolution mesh): one invocation per instance; frustum test of the instance's bounding
// sphere, then the coarsest level whose projected error (FORMAT.md §6's formula at the sphere's
// nearest point, the same rule as the DAG's) is <= tau, or level 0 with FLAG_FULL_DETAIL. The
// instance is appended to its level's list, whose draw command counts it.
#extension GL_GOOGLE_include_directive : require
// Declared before common.glsl: its grid_invocation_index reads gl_WorkGroupSize, which is
// (1, 1, 1) until the size is declared (every workgroup but the first lost its offset).
layout(local_size_x = 64) in;
#include "common.glsl"
layout(set = 0, binding = 13, std430) writeonly buffer ListBlock { uint instance_list[]; };
// Per level: x = object-space error.
layout(set = 0, binding = 14, std430) readonly buffer ChainBlock { vec4 chain_levels[]; };
// One VkDrawIndexedIndirectCommand (5 words) per level.
layout(set = 0, binding = 15, std430) buffer DrawBlock { uint draws[]; };

void main() {
    uint i = grid_invocation_index();
    if (i >= view.instance_count) {
        return;
    }
    vec3 center = view.model_center + instances[i].model[3].xyz;
    if ((view.flags & FLAG_FRUSTUM_CULL) != 0u && !sphere_in_frustum(vec4(center, view.model_near))) {
        return;
    }
    uint level = 0u;
    if ((view.flags & FLAG_FULL_DETAIL) == 0u) {
        float d = max(distance(center, view.eye) - view.model_near, view.z_near);
        float k = view.viewport_height * 0.5 * view.proj_y;
        for (uint l = 1u; l < view.bin_count; l++) {
            if (chain_levels[l].x / d * k <= view.tau) {
                level = l;
            }
        }
    }
    uint slot = atomicAdd(draws[level * 5u + 1u], 1u);
    instance_list[level * view.instance_count + slot] = i;
}
