// Shared declarations of every preview shader: the GPU-visible structs (mirrored once in Rust,
// src/gpu_types.rs; the test `gpu_types::tests` parses the structs below and checks that the
// Rust offsets agree), the bindings of the one descriptor set, and the exact f32 selection rule
// of docs/FORMAT.md §6.
//
// Keep each struct member on its own line as `type name;` or `type name[N];`: the layout test
// reads them.

// One cluster's selection inputs (FORMAT.md §6) and where its data lives (§3.2, §5).
// Level-0 clusters have own_error 0; root clusters have parent_error +inf.
struct Cluster {
    vec4 own_sphere;
    vec4 parent_sphere;
    float own_error;
    float parent_error;
    uint page;
    uint header_offset;
    uint vertex_count;
    uint triangle_count;
    uint group;
    uint level;
};

// The camera and pass parameters (one per submission).
struct View {
    mat4 view_proj;
    vec4 frustum[6];
    vec3 eye;
    float proj_y;
    float viewport_height;
    float z_near;
    float tau;
    uint flags;
    vec3 grid_origin;
    float grid_step;
    uint cluster_count;
    uint max_groups;
    uint instance_count;
    uint bin_count;
    vec3 model_center;
    float model_far;
    float model_near;
    uint mode;
    uint visible_capacity;
    uint index_capacity;
};

// Atomic counters that double as indirect arguments.
struct Counters {
    uint visible_count;
    uint dispatch_x;
    uint dispatch_y;
    uint dispatch_z;
    uint index_count;
    uint instance_count;
    uint first_index;
    int vertex_offset;
    uint first_instance;
    uint task_x;
    uint task_y;
    uint task_z;
    uint triangles;
    uint work_count;
    uint select_x;
    uint select_y;
    uint select_z;
    uint index_alloc;
    uint dropped;
};

// The clusters of one DAG level: `level_order[first .. first + count]`, with the smallest own
// error and the largest parent error among them (object space).
struct LevelBin {
    uint first;
    uint count;
    float min_own_error;
    float max_parent_error;
};

// View.flags
const uint FLAG_FRUSTUM_CULL = 1u;
const uint FLAG_WRITE_PROJECTED = 2u;
const uint FLAG_DROP_SOME = 4u;
const uint FLAG_FULL_DETAIL = 8u;

// View.mode: what the front faces show.
const uint MODE_SHADED = 0u;
const uint MODE_CLUSTER = 1u;
const uint MODE_GROUP = 2u;
const uint MODE_LEVEL = 3u;
const uint MODE_ERROR = 4u;

// Clusters a task workgroup of the mesh path launches (one mesh workgroup each).
const uint CLUSTERS_PER_TASK = 32u;

layout(set = 0, binding = 0, std140) uniform ViewBlock { View view; };
layout(set = 0, binding = 1, std430) readonly buffer ClusterBlock { Cluster clusters[]; };
// Byte offset of each decompressed page inside `page_words` (a multiple of 4).
layout(set = 0, binding = 2, std430) readonly buffer PageBaseBlock { uint page_base[]; };
// Every decompressed page, as is (FORMAT.md §5), one after the other.
layout(set = 0, binding = 3, std430) readonly buffer PageBlock { uint page_words[]; };

// Bit-stream read of FORMAT.md §5.2: `width` bits (0..=32) starting `bit` bits after the
// 4-aligned byte offset `stream`, LSB first, possibly straddling two words.
uint read_bits(uint stream, uint bit, uint width) {
    if (width == 0u) {
        return 0u;
    }
    uint w = (stream >> 2) + (bit >> 5);
    uint s = bit & 31u;
    uint v = page_words[w] >> s;
    if (s + width > 32u) {
        v |= page_words[w + 1u] << (32u - s);
    }
    return width == 32u ? v : (v & ((1u << width) - 1u));
}

uint read_u8(uint byte_offset) {
    return (page_words[byte_offset >> 2] >> ((byte_offset & 3u) * 8u)) & 0xFFu;
}

// One placement of a mesh: object-to-world transform, the rows of its inverse, the mesh's
// grid, culling sphere and level bins, and the factors of the selection rule under a transform
// (docs/FORMAT.md "Scene file"): the eye moves into object space, z_near scales by near_scale,
// projected errors by error_scale. For a pure translation every factor is 1 and every
// transformed value has exactly the arithmetic of adding or subtracting the translation.
struct Instance {
    mat4 model;
    vec4 inverse_row0;
    vec4 inverse_row1;
    vec4 inverse_row2;
    vec4 grid;
    vec4 center;
    float model_near;
    float error_scale;
    float near_scale;
    float radius_scale;
    uint bin_first;
    uint bin_count;
    uint mirrored;
    uint mesh;
};

layout(set = 0, binding = 8, std430) readonly buffer InstanceBlock { Instance instances[]; };

// model * (p, 1), each coordinate summed in a fixed order without FMA, so that a pure
// translation gives exactly p + t ((p.x + 0) + 0 = p.x).
vec3 to_world(Instance inst, vec3 p) {
    mat4 m = inst.model;
    precise vec3 a = m[0].xyz * p.x;
    precise vec3 b = m[1].xyz * p.y;
    precise vec3 c = m[2].xyz * p.z;
    precise vec3 sum = ((a + b) + c) + m[3].xyz;
    return sum;
}

// The inverse applied to a world point, in the same fixed order: a pure translation gives
// exactly w - t.
vec3 to_object(Instance inst, vec3 w) {
    precise vec3 a = vec3(inst.inverse_row0.x, inst.inverse_row1.x, inst.inverse_row2.x) * w.x;
    precise vec3 b = vec3(inst.inverse_row0.y, inst.inverse_row1.y, inst.inverse_row2.y) * w.y;
    precise vec3 c = vec3(inst.inverse_row0.z, inst.inverse_row1.z, inst.inverse_row2.z) * w.z;
    precise vec3 sum = ((a + b) + c) + vec3(inst.inverse_row0.w, inst.inverse_row1.w, inst.inverse_row2.w);
    return sum;
}

// Object-space position of vertex `v` of cluster `c` on the grid `grid` (origin xyz, step w;
// FORMAT.md §5.3, one f32 multiply, then one f32 add, as the reference decoder does).
vec3 decode_position(Cluster c, uint v, vec4 grid) {
    uint page = page_base[c.page];
    uint header = page + c.header_offset;
    uint hw = header >> 2;
    ivec3 lo = ivec3(int(page_words[hw + 1u]), int(page_words[hw + 2u]), int(page_words[hw + 3u]));
    uint bits_word = page_words[hw + 4u];
    uvec3 bits = uvec3(bits_word & 0xFFu, (bits_word >> 8) & 0xFFu, (bits_word >> 16) & 0xFFu);
    uint stream = page + page_words[hw + 5u];
    uint bit = v * (bits.x + bits.y + bits.z);
    uint dx = read_bits(stream, bit, bits.x);
    uint dy = read_bits(stream, bit + bits.x, bits.y);
    uint dz = read_bits(stream, bit + bits.x + bits.y, bits.z);
    ivec3 q = lo + ivec3(int(dx), int(dy), int(dz));
    precise vec3 scaled = vec3(q) * grid.w;
    precise vec3 p = grid.xyz + scaled;
    return p;
}

// ---- Exact f32 arithmetic for the selection rule -------------------------------------------
//
// FORMAT.md §6 fixes every operation as one IEEE f32 operation rounded to nearest. Vulkan
// guarantees correct rounding for add, sub and mul (and `precise` stops fusing into FMA), but
// allows 2.5 ulp for division and an inversesqrt-derived precision for sqrt. So division and
// sqrt take a candidate from f64 and then correct it with checks that are exact in f64: a
// rounding midpoint between two adjacent f32 has 25 significant bits, so midpoint * f32 (49 bits)
// and midpoint^2 (50 bits) are exactly representable in f64's 53.

#ifdef NAIVE_ARITHMETIC
// Diagnostic variant (select_naive.comp.spv, `preview --naive-arithmetic`): the driver's own
// division and sqrt, to measure how far they are from the spec on a device.
float div_rn(float a, float b) {
    precise float q = a / b;
    return q;
}

float sqrt_rn(float x) {
    return sqrt(x);
}
#else
float next_up(float x) {   // x finite, >= 0
    return uintBitsToFloat(floatBitsToUint(x) + 1u);
}

float next_down(float x) { // x finite, > 0
    return uintBitsToFloat(floatBitsToUint(x) - 1u);
}

bool is_odd(float x) {
    return (floatBitsToUint(x) & 1u) != 0u;
}

// a / b rounded to nearest even, for finite a >= 0 and finite b > 0.
float div_rn(float a, float b) {
    float q = float(double(a) / double(b));
    if (isinf(q) || a == 0.0) {
        return q;
    }
    double da = double(a);
    double db = double(b);
    for (int i = 0; i < 2; i++) {
        precise double mid = (double(q) + double(next_up(q))) * 0.5lf;
        precise double m = mid * db;
        if (da > m || (da == m && is_odd(q))) {
            q = next_up(q);
        } else {
            break;
        }
    }
    for (int i = 0; i < 2; i++) {
        if (q == 0.0) {
            break;
        }
        precise double mid = (double(q) + double(next_down(q))) * 0.5lf;
        precise double m = mid * db;
        if (da < m || (da == m && is_odd(q))) {
            q = next_down(q);
        } else {
            break;
        }
    }
    return q;
}

// sqrt(x) rounded to nearest even, for finite x >= 0.
float sqrt_rn(float x) {
    if (x == 0.0) {
        return x;
    }
    float s = float(sqrt(double(x)));
    double dx = double(x);
    for (int i = 0; i < 2; i++) {
        precise double mid = (double(s) + double(next_up(s))) * 0.5lf;
        precise double m = mid * mid;
        if (dx > m || (dx == m && is_odd(s))) {
            s = next_up(s);
        } else {
            break;
        }
    }
    for (int i = 0; i < 2; i++) {
        if (s == 0.0) {
            break;
        }
        precise double mid = (double(s) + double(next_down(s))) * 0.5lf;
        precise double m = mid * mid;
        if (dx < m || (dx == m && is_odd(s))) {
            s = next_down(s);
        } else {
            break;
        }
    }
    return s;
}
#endif

// FORMAT.md §6: projected(sphere, error) in pixels for an eye in the cluster's object space
// (the view's eye moved into the instance's object space; exactly the view's eye for an
// identity instance) and the near distance z_near there, with the spec's operations in its
// order: dx = center - eye; d = sqrt((dx*dx + dy*dy) + dz*dz); d = max(d - radius, z_near);
// p = ((error / d) * (H * 0.5)) * proj11. +inf stays +inf. Under a transform the caller
// multiplies the result by the instance's error_scale.
float projected_error(vec4 sphere, float error, vec3 eye, float z_near) {
    if (error == 0.0) {
        return 0.0;
    }
    precise float dx = sphere.x - eye.x;
    precise float dy = sphere.y - eye.y;
    precise float dz = sphere.z - eye.z;
    precise float xx = dx * dx;
    precise float yy = dy * dy;
    precise float zz = dz * dz;
    precise float sum = (xx + yy) + zz;
    float distance = sqrt_rn(sum);
    precise float near_d = distance - sphere.w;
    float d = max(near_d, z_near);
    float q = isinf(error) ? error : div_rn(error, d);
    precise float half_h = view.viewport_height * 0.5;
    precise float scaled = q * half_h;
    precise float p = scaled * view.proj_y;
    return p;
}

// Whether the sphere (xyz centre, w radius; world space) is at least partly inside the
// view frustum (View.frustum: six inward planes, dot(plane.xyz, p) + plane.w >= 0 inside).
bool sphere_in_frustum(vec4 sphere) {
    for (int i = 0; i < 6; i++) {
        vec4 plane = view.frustum[i];
        if (dot(plane.xyz, sphere.xyz) + plane.w < -sphere.w) {
            return false;
        }
    }
    return true;
}

// Index of this invocation in a compute dispatch laid out as a 2D grid of 1D workgroups whose
// rows are gl_NumWorkGroups.x wide (the culling passes; the Rust side splits the groups so).
// Only for compute shaders.
#ifdef GL_COMPUTE_SHADER
uint grid_invocation_index() {
    return (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * gl_WorkGroupSize.x + gl_LocalInvocationID.x;
}
#endif

// A colour for an integer, never pure red (the crack test's flag).
vec3 id_color(uint id) {
    uint h = id * 0x9E3779B1u;
    h ^= h >> 15;
    h *= 0x85EBCA77u;
    h ^= h >> 13;
    return vec3(0.25) + 0.7 * vec3(float(h & 255u), float((h >> 8) & 255u), float((h >> 16) & 255u)) / 255.0;
}

// Heat colour for t in [0, 1]: blue, green, yellow, orange (never pure red).
vec3 heat_color(float t) {
    t = clamp(t, 0.0, 1.0);
    return mix(mix(vec3(0.1, 0.2, 0.9), vec3(0.1, 0.8, 0.3), min(t * 2.0, 1.0)),
               vec3(1.0, 0.55, 0.1), max(t * 2.0 - 1.0, 0.0));
}
