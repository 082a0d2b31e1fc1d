#version 460
// Front faces: grey headlight shading from the screen-space normal. Back faces: pure red, no
// lighting; on a closed mesh seen from outside any red pixel is a hole (the crack test).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(location = 0) in vec3 world_position;
layout(location = 0) out vec4 color;

void main() {
    if (!gl_FrontFacing) {
        color = vec4(1.0, 0.0, 0.0, 1.0);
        return;
    }
    vec3 n = normalize(cross(dFdx(world_position), dFdy(world_position)));
    vec3 to_eye = normalize(view.eye - world_position);
    float lambert = abs(dot(n, to_eye));
    // Never pure red: green and blue stay above zero.
    color = vec4(vec3(0.08) + vec3(0.85, 0.80, 0.72) * lambert, 1.0);
}
