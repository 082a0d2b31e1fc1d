#version 460
// Vertex shader of the benchmark's alternatives: an ordinary indexed mesh (positions pulled
// from a storage buffer by the index), instanced through the per-level instance list.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(set = 0, binding = 12, std430) readonly buffer PositionBlock { float positions[]; };
layout(set = 0, binding = 13, std430) readonly buffer ListBlock { uint instance_list[]; };

layout(location = 0) out vec3 world_position;
layout(location = 1) flat out uint slot;

void main() {
    uint v = uint(gl_VertexIndex);
    vec3 p = vec3(positions[3u * v], positions[3u * v + 1u], positions[3u * v + 2u]);
    p += instances[instance_list[gl_InstanceIndex]].model[3].xyz;
    world_position = p;
    slot = 0u;
    gl_Position = view.view_proj * vec4(p, 1.0);
}
