#version 460
// Per-cluster LOD selection (FORMAT.md §6): one workgroup per work item of the culling pass
// (an instance and a range of its clusters); its invocations stride over the range. A cluster
// is drawn iff projected(own) <= tau < projected(parent), with the eye moved into the
// instance's object space (and z_near and the result scaled by the instance's factors, which
// are 1 for a translation), optionally frustum-culled against the parent sphere moved into the
// world (which bounds the cluster's geometry); it is appended to the visible list as (cluster,
// instance).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x = 64) in;

layout(set = 0, binding = 4, std430) buffer CounterBlock { Counters counters; };
layout(set = 0, binding = 5, std430) writeonly buffer VisibleBlock { uvec2 visible[]; };
// With FLAG_WRITE_PROJECTED: (own, parent) projected errors of every cluster (instance 0 only).
layout(set = 0, binding = 7, std430) writeonly buffer ProjectedBlock { vec2 projected[]; };
layout(set = 0, binding = 10, std430) readonly buffer WorkBlock { uvec4 work[]; };
layout(set = 0, binding = 11, std430) readonly buffer LevelOrderBlock { uint level_order[]; };

void main() {
    uint w = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    if (w >= counters.work_count) {
        return;
    }
    uvec4 item = work[w];
    uint instance = item.x;
    Instance inst = instances[instance];
    vec3 eye = to_object(inst, view.eye);
    precise float z_near = view.z_near * inst.near_scale;
    for (uint j = item.y + gl_LocalInvocationID.x; j < item.y + item.z; j += gl_WorkGroupSize.x) {
        uint i = level_order[j];
        Cluster c = clusters[i];
        precise float own = projected_error(c.own_sphere, c.own_error, eye, z_near) * inst.error_scale;
        precise float parent = projected_error(c.parent_sphere, c.parent_error, eye, z_near) * inst.error_scale;
        if ((view.flags & FLAG_WRITE_PROJECTED) != 0u && instance == 0u) {
            projected[i] = vec2(own, parent);
        }
        if (!(own <= view.tau && view.tau < parent)) {
            continue;
        }
        if ((view.flags & FLAG_FRUSTUM_CULL) != 0u && !sphere_in_frustum(vec4(to_world(inst, c.parent_sphere.xyz), c.parent_sphere.w * inst.radius_scale))) {
            continue;
        }
        // Test hook: drop every fifth selected cluster, so that tests can show the crack test
        // sees holes.
        if ((view.flags & FLAG_DROP_SOME) != 0u && i % 5u == 0u) {
            continue;
        }
        uint slot = atomicAdd(counters.visible_count, 1u);
        if (slot >= view.visible_capacity) {
            atomicAdd(counters.dropped, 1u);
            continue;
        }
        visible[slot] = uvec2(i, instance);
        atomicAdd(counters.triangles, c.triangle_count);
        // The expansion pass: one workgroup per visible cluster, at most max_groups (the
        // device limit); its workgroups stride over the rest.
        atomicMax(counters.dispatch_x, min(slot + 1u, view.max_groups));
        // The mesh path: one task workgroup per CLUSTERS_PER_TASK visible clusters, a 2D grid
        // of max_groups-wide rows whose surplus workgroups launch nothing.
        uint task = slot / CLUSTERS_PER_TASK;
        atomicMax(counters.task_x, min(task + 1u, view.max_groups));
        atomicMax(counters.task_y, task / view.max_groups + 1u);
    }
}
