#version 460
// Instance culling: one invocation per instance. An instance outside the frustum (its bounding
// sphere: the mesh's centre moved into the world, radius model_near scaled by the instance's
// largest scale) is dropped. For the others, the instance's distance bounds which DAG levels of
// its mesh can hold a selected cluster, and one work item (instance, cluster range of
// `level_order`) is appended for the selection pass.
//
// Why the range is conservative: the selection runs in the mesh's object space (eye moved
// there, z_near and tau scaled by the instance's factors). Every group sphere (c, r) satisfies
// |c - C| - r <= model_far and |c - C| + r <= model_near for the mesh centre C, so with
// D = |C - eye| every clamped sphere distance max(d - r, z_near) lies in
// [max(D - model_near, z_near), max(D + model_far, z_near)]. A cluster can only be drawn if
// own_error <= tau * dmax / k and parent_error > tau * dmin / k (k = H/2 * proj11): levels
// whose smallest own error is above the first bound or whose largest parent error is at most
// the second are skipped. The margins below cover the f32 rounding of these few operations;
// the exact test is per cluster.
#extension GL_GOOGLE_include_directive : require
// Declared before common.glsl: its grid_invocation_index reads gl_WorkGroupSize, which is
// (1, 1, 1) until the size is declared (every workgroup but the first lost its offset).
layout(local_size_x = 64) in;
#include "common.glsl"
layout(set = 0, binding = 4, std430) buffer CounterBlock { Counters counters; };
layout(set = 0, binding = 9, std430) readonly buffer BinBlock { LevelBin bins[]; };
layout(set = 0, binding = 10, std430) writeonly buffer WorkBlock { uvec4 work[]; };

void main() {
    uint i = grid_invocation_index();
    if (i >= view.instance_count) {
        return;
    }
    Instance inst = instances[i];
    if (inst.bin_count == 0u) {
        return;
    }
    vec3 center = inst.center.xyz;
    if ((view.flags & FLAG_FRUSTUM_CULL) != 0u
        && !sphere_in_frustum(vec4(to_world(inst, center), inst.model_near * inst.radius_scale))) {
        return;
    }
    uint lo = inst.bin_first;
    uint hi = inst.bin_first + inst.bin_count - 1u;
    if ((view.flags & FLAG_WRITE_PROJECTED) == 0u) {
        // In the mesh's object space, where the selection runs: tau over the error scale.
        float distance = length(center - to_object(inst, view.eye));
        float z_near = view.z_near * inst.near_scale;
        float tau = view.tau / inst.error_scale;
        float k = view.viewport_height * 0.5 * view.proj_y;
        float e_hi = tau * max(distance + inst.center.w, z_near) / k * 1.01 + 1e-30;
        float e_lo = tau * max(distance - inst.model_near, z_near) / k * 0.99;
        bool any = false;
        for (uint b = inst.bin_first; b < inst.bin_first + inst.bin_count; b++) {
            LevelBin bin = bins[b];
            if (bin.count > 0u && bin.min_own_error <= e_hi && bin.max_parent_error > e_lo) {
                if (!any) {
                    lo = b;
                }
                hi = b;
                any = true;
            }
        }
        if (!any) {
            return;
        }
    }
    uint first = bins[lo].first;
    uint count = bins[hi].first + bins[hi].count - first;
    uint w = atomicAdd(counters.work_count, 1u);
    work[w] = uvec4(i, first, count, 0u);
    // The selection pass runs one workgroup per work item: a 2D grid of max_groups-wide rows.
    atomicMax(counters.select_x, min(w + 1u, view.max_groups));
    atomicMax(counters.select_y, w / view.max_groups + 1u);
}
