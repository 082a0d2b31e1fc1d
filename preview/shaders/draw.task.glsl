#version 460
// Task shader of the mesh path: task workgroup g launches one mesh workgroup for each of the
// visible clusters g * CLUSTERS_PER_TASK .. + CLUSTERS_PER_TASK (fewer in the last one). The
// workgroup size is a free choice, unrelated to the subgroup size.
#extension GL_EXT_mesh_shader : require
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x = 1) in;

layout(set = 0, binding = 4, std430) readonly buffer CounterBlock { Counters counters; };

struct Payload {
    uint first;
};
taskPayloadSharedEXT Payload payload;

void main() {
    uint g = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    uint count = min(counters.visible_count, view.visible_capacity);
    uint first = g * CLUSTERS_PER_TASK;
    payload.first = first;
    EmitMeshTasksEXT(first < count ? min(CLUSTERS_PER_TASK, count - first) : 0u, 1u, 1u);
}
