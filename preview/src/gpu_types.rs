//! GPU-visible structs, defined once here and mirrored in `shaders/common.glsl`. The tests
//! below parse the GLSL declarations, compute their std430/std140 offsets and check that every
//! member has the same name, offset and size here, so the two sides cannot drift apart.

use bytemuck::{Pod, Zeroable};

/// One cluster's selection inputs and data location (GLSL `Cluster`, std430, 64 bytes).
///
/// Spheres and errors are object-space, copied bit for bit from the file's group records
/// (FORMAT.md §3.1): *own* is the group that produced the cluster (error 0 for a level-0
/// cluster, sphere then unused), *parent* the group it is a member of (error `+inf` for a root).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuCluster {
    /// Own group's bounding sphere: centre xyz, radius w.
    pub own_sphere: [f32; 4],
    /// Parent group's bounding sphere: centre xyz, radius w.
    pub parent_sphere: [f32; 4],
    /// Own group's object-space error (0 at level 0).
    pub own_error: f32,
    /// Parent group's object-space error (`+inf` for a root group).
    pub parent_error: f32,
    /// Page holding the cluster (index into the page base table).
    pub page: u32,
    /// Byte offset of the cluster header inside its decompressed page (FORMAT.md §3.2).
    pub header_offset: u32,
    /// Vertices (1..=256).
    pub vertex_count: u32,
    /// Triangles (1..=128).
    pub triangle_count: u32,
    /// Padding to 64 bytes.
    pub pad0: u32,
    /// Padding to 64 bytes.
    pub pad1: u32,
}

/// Camera and pass parameters of one submission (GLSL `View`, a std140 uniform, 224 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuView {
    /// Projection × view, column-major (`view_proj[col][row]`), reverse-Z infinite far plane.
    pub view_proj: [[f32; 4]; 4],
    /// Six world-space frustum planes `(n, d)`, inside where `dot(n, p) + d >= 0`, `|n| = 1`.
    pub frustum: [[f32; 4]; 6],
    /// Eye position, object space.
    pub eye: [f32; 3],
    /// `proj[1][1]` = 1 / tan(fov_y / 2).
    pub proj_y: f32,
    /// Viewport height in pixels.
    pub viewport_height: f32,
    /// Near plane distance, object space; selection distances are clamped to it.
    pub z_near: f32,
    /// Selection threshold in pixels.
    pub tau: f32,
    /// `FLAG_*` bits.
    pub flags: u32,
    /// Grid origin of the file (FORMAT.md §2).
    pub grid_origin: [f32; 3],
    /// Grid step of the file.
    pub grid_step: f32,
    /// Number of clusters in the cluster buffer.
    pub cluster_count: u32,
    /// Most workgroups of one indirect dispatch dimension (device limit).
    pub max_groups: u32,
    /// Padding.
    pub pad0: u32,
    /// Padding.
    pub pad1: u32,
}

/// `GpuView::flags`: cull clusters whose parent sphere is outside the frustum.
pub const FLAG_FRUSTUM_CULL: u32 = 1;
/// `GpuView::flags`: write every cluster's (own, parent) projected error for diagnostics.
pub const FLAG_WRITE_PROJECTED: u32 = 2;
/// `GpuView::flags`: test hook that drops every fifth selected cluster (makes holes).
pub const FLAG_DROP_SOME: u32 = 4;

/// Atomic counters that double as indirect arguments (GLSL `Counters`, std430, 52 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuCounters {
    /// Clusters appended to the visible list.
    pub visible_count: u32,
    /// `VkDispatchIndirectCommand` of the expansion pass: min(visible, max_groups).
    pub dispatch_x: u32,
    /// Always 1.
    pub dispatch_y: u32,
    /// Always 1.
    pub dispatch_z: u32,
    /// `VkDrawIndexedIndirectCommand::indexCount`, the atomic allocator of the index buffer.
    pub index_count: u32,
    /// Always 1.
    pub instance_count: u32,
    /// Always 0.
    pub first_index: u32,
    /// Always 0.
    pub vertex_offset: i32,
    /// Always 0.
    pub first_instance: u32,
    /// `VkDrawMeshTasksIndirectCommandEXT` of the mesh-shader path: min(visible, max_groups).
    pub mesh_x: u32,
    /// ceil(visible / max_groups) (at least 1).
    pub mesh_y: u32,
    /// Always 1.
    pub mesh_z: u32,
    /// Triangles of the visible clusters.
    pub triangles: u32,
}

impl GpuCounters {
    /// The values a pass starts from: zero counts, unit y/z and instance counts.
    pub fn reset() -> GpuCounters {
        GpuCounters { dispatch_y: 1, dispatch_z: 1, instance_count: 1, mesh_y: 1, mesh_z: 1, ..Default::default() }
    }
}

/// Byte offset of the expansion pass's `VkDispatchIndirectCommand` in [`GpuCounters`].
pub const DISPATCH_ARGS_OFFSET: u64 = std::mem::offset_of!(GpuCounters, dispatch_x) as u64;
/// Byte offset of the `VkDrawIndexedIndirectCommand` in [`GpuCounters`].
pub const DRAW_ARGS_OFFSET: u64 = std::mem::offset_of!(GpuCounters, index_count) as u64;
/// Byte offset of the `VkDrawMeshTasksIndirectCommandEXT` in [`GpuCounters`].
pub const MESH_ARGS_OFFSET: u64 = std::mem::offset_of!(GpuCounters, mesh_x) as u64;

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{offset_of, size_of};

    const COMMON_GLSL: &str = include_str!("../shaders/common.glsl");

    /// (name, offset, size) of each member of GLSL struct `name`, laid out with std430 or std140.
    fn glsl_layout(name: &str, std140: bool) -> (Vec<(String, usize, usize)>, usize) {
        let start = COMMON_GLSL.find(&format!("struct {name} {{")).unwrap_or_else(|| panic!("no struct {name}"));
        let body = &COMMON_GLSL[start..];
        let body = &body[body.find('{').unwrap() + 1..body.find("};").unwrap()];
        let mut members = Vec::new();
        let mut at = 0usize;
        let mut max_align = 4usize;
        for line in body.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with("//")) {
            let line = line.trim_end_matches(';');
            let (ty, name) = line.split_once(' ').unwrap_or_else(|| panic!("cannot parse `{line}`"));
            let (name, count) = match name.split_once('[') {
                Some((n, c)) => (n, Some(c.trim_end_matches(']').parse::<usize>().unwrap())),
                None => (name, None),
            };
            // (size, base alignment) of the type (GLSL spec §7.6.2.2 rules 1–5).
            let (size, align): (usize, usize) = match ty {
                "float" | "uint" | "int" => (4, 4),
                "vec2" | "uvec2" | "ivec2" => (8, 8),
                "vec3" | "uvec3" | "ivec3" => (12, 16),
                "vec4" | "uvec4" | "ivec4" => (16, 16),
                "mat4" => (64, 16),
                other => panic!("type {other} not handled by the layout test"),
            };
            let (size, align) = match count {
                // Arrays: stride rounded to the element alignment (std140: to 16).
                Some(n) => {
                    let a = if std140 { align.max(16) } else { align };
                    (size.next_multiple_of(a) * n, a)
                }
                None => (size, align),
            };
            at = at.next_multiple_of(align);
            members.push((name.to_string(), at, size));
            at += size;
            max_align = max_align.max(align);
        }
        let struct_align = if std140 { max_align.max(16) } else { max_align };
        (members, at.next_multiple_of(struct_align))
    }

    fn check(name: &str, std140: bool, rust: &[(&str, usize, usize)], rust_size: usize) {
        let (glsl, glsl_size) = glsl_layout(name, std140);
        let rust: Vec<(String, usize, usize)> = rust.iter().map(|&(n, o, s)| (n.to_string(), o, s)).collect();
        assert_eq!(rust, glsl, "{name}: Rust members (name, offset, size) differ from shaders/common.glsl");
        assert_eq!(rust_size, glsl_size, "{name}: size differs");
    }

    macro_rules! members {
        ($t:ty: $($f:ident),* $(,)?) => {{
            fn size_of_field<T, F>(_: impl Fn(&T) -> &F) -> usize { size_of::<F>() }
            vec![$((stringify!($f), offset_of!($t, $f), size_of_field(|x: &$t| &x.$f))),*]
        }};
    }

    #[test]
    fn cluster_matches_glsl_std430() {
        let m = members!(GpuCluster: own_sphere, parent_sphere, own_error, parent_error, page, header_offset,
            vertex_count, triangle_count, pad0, pad1);
        check("Cluster", false, &m, size_of::<GpuCluster>());
        assert_eq!(size_of::<GpuCluster>(), 64);
    }

    #[test]
    fn view_matches_glsl_std140() {
        let m = members!(GpuView: view_proj, frustum, eye, proj_y, viewport_height, z_near, tau, flags,
            grid_origin, grid_step, cluster_count, max_groups, pad0, pad1);
        check("View", true, &m, size_of::<GpuView>());
    }

    #[test]
    fn counters_match_glsl_std430_and_vulkan_commands() {
        let m = members!(GpuCounters: visible_count, dispatch_x, dispatch_y, dispatch_z, index_count,
            instance_count, first_index, vertex_offset, first_instance, mesh_x, mesh_y, mesh_z, triangles);
        check("Counters", false, &m, size_of::<GpuCounters>());
        // Indirect commands must be 4-aligned and laid out as Vulkan's structs.
        assert_eq!(size_of::<ash::vk::DispatchIndirectCommand>(), 12);
        assert_eq!(size_of::<ash::vk::DrawIndexedIndirectCommand>(), 20);
        assert_eq!(DRAW_ARGS_OFFSET + 20, MESH_ARGS_OFFSET);
        assert_eq!(DISPATCH_ARGS_OFFSET % 4, 0);
    }

    #[test]
    fn layout_parser_sees_a_drifted_member() {
        // The checker itself: a GLSL struct with a vec3 followed by a float packs them together.
        let (m, size) = glsl_layout("View", true);
        let eye = m.iter().find(|(n, _, _)| n == "eye").unwrap();
        let proj = m.iter().find(|(n, _, _)| n == "proj_y").unwrap();
        assert_eq!((eye.1, proj.1), (160, 172));
        assert_eq!(size, 224);
    }
}
