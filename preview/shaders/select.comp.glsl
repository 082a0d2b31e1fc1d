#version 460
// Flat per-cluster LOD selection (FORMAT.md §6): one invocation per cluster draws iff
// projected(own) <= tau < projected(parent), optionally frustum-culled against the parent sphere
// (which bounds the cluster's geometry), and appends the cluster to the visible list.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x = 64) in;

layout(set = 0, binding = 4, std430) buffer CounterBlock { Counters counters; };
layout(set = 0, binding = 5, std430) writeonly buffer VisibleBlock { uint visible[]; };
// With FLAG_WRITE_PROJECTED: (own, parent) projected errors of every cluster, for diagnostics.
layout(set = 0, binding = 7, std430) writeonly buffer ProjectedBlock { vec2 projected[]; };

bool sphere_in_frustum(vec4 sphere) {
    for (int i = 0; i < 6; i++) {
        vec4 plane = view.frustum[i];
        if (dot(plane.xyz, sphere.xyz) + plane.w < -sphere.w) {
            return false;
        }
    }
    return true;
}

void main() {
    uint group = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    uint i = group * gl_WorkGroupSize.x + gl_LocalInvocationID.x;
    if (i >= view.cluster_count) {
        return;
    }
    Cluster c = clusters[i];
    float own = projected_error(c.own_sphere, c.own_error);
    float parent = projected_error(c.parent_sphere, c.parent_error);
    if ((view.flags & FLAG_WRITE_PROJECTED) != 0u) {
        projected[i] = vec2(own, parent);
    }
    if (!(own <= view.tau && view.tau < parent)) {
        return;
    }
    if ((view.flags & FLAG_FRUSTUM_CULL) != 0u && !sphere_in_frustum(c.parent_sphere)) {
        return;
    }
    // Test hook: drop every fifth selected cluster, so that tests can show the crack test
    // sees holes.
    if ((view.flags & FLAG_DROP_SOME) != 0u && i % 5u == 0u) {
        return;
    }
    uint slot = atomicAdd(counters.visible_count, 1u);
    visible[slot] = i;
    atomicAdd(counters.triangles, c.triangle_count);
    // The expansion pass is dispatched indirectly with one workgroup per visible cluster, at
    // most max_groups (the device limit); its workgroups stride over the rest.
    atomicMax(counters.dispatch_x, min(slot + 1u, view.max_groups));
    // The mesh-shader draw needs exactly one workgroup per cluster: a 2D grid of
    // max_groups-wide rows, whose surplus workgroups in the last row emit nothing.
    atomicMax(counters.mesh_x, min(slot + 1u, view.max_groups));
    atomicMax(counters.mesh_y, slot / view.max_groups + 1u);
}
