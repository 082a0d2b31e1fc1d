#version 460
// Front faces: headlight shading from the screen-space normal, tinted by the view mode (per
// cluster, per group, DAG level, projected error). Back faces: pure red, no lighting; on a
// closed mesh seen from outside any red pixel is a hole (the crack test).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(set = 0, binding = 5, std430) readonly buffer VisibleBlock { uvec2 visible[]; };

layout(location = 0) in vec3 world_position;
layout(location = 1) flat in uint slot;
layout(location = 0) out vec4 color;

void main() {
    if (!gl_FrontFacing) {
        color = vec4(1.0, 0.0, 0.0, 1.0);
        return;
    }
    vec3 n = normalize(cross(dFdx(world_position), dFdy(world_position)));
    vec3 to_eye = normalize(view.eye - world_position);
    float lambert = abs(dot(n, to_eye));
    if (view.mode == MODE_SHADED) {
        // Never pure red: green and blue stay above zero.
        color = vec4(vec3(0.08) + vec3(0.85, 0.80, 0.72) * lambert, 1.0);
        return;
    }
    uvec2 entry = visible[slot];
    Cluster c = clusters[entry.x];
    vec3 tint;
    if (view.mode == MODE_CLUSTER) {
        tint = id_color(entry.x);
    } else if (view.mode == MODE_GROUP) {
        tint = id_color(c.group);
    } else if (view.mode == MODE_LEVEL) {
        tint = heat_color(float(c.level) / 12.0);
    } else {
        // Own projected error over tau: 0 (level 0, exact) blue .. tau orange.
        Instance inst = instances[entry.y];
        vec3 eye = to_object(inst, view.eye);
        float d = max(distance(c.own_sphere.xyz, eye) - c.own_sphere.w, view.z_near * inst.near_scale);
        float p = c.own_error / d * view.viewport_height * 0.5 * view.proj_y * inst.error_scale;
        tint = heat_color(view.tau > 0.0 ? p / view.tau : 0.0);
    }
    color = vec4(tint * (0.25 + 0.75 * lambert), 1.0);
}
