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
    /// The group the cluster is a member of (its parent pair; for per-group colours).
    pub group: u32,
    /// DAG level of that group (0 = original geometry).
    pub level: u32,
}

/// Camera and pass parameters of one submission (GLSL `View`, a std140 uniform, 256 bytes).
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
    /// Number of instances in the instance buffer.
    pub instance_count: u32,
    /// Number of [`GpuLevelBin`]s (DAG levels).
    pub bin_count: u32,
    /// A point of the model (object space) that instance culling measures distances from.
    pub model_center: [f32; 3],
    /// Largest `|c - model_center| - r` over all group spheres (c, r), object space.
    pub model_far: f32,
    /// Largest `|c - model_center| + r` over all group spheres: the instance's bounding radius.
    pub model_near: f32,
    /// `MODE_*`: what front faces show.
    pub mode: u32,
    /// Entries of the visible list buffer; clusters beyond it are dropped and counted.
    pub visible_capacity: u32,
    /// Entries of the fallback path's index buffer.
    pub index_capacity: u32,
}

/// `GpuView::mode`: grey headlight shading.
pub const MODE_SHADED: u32 = 0;
/// `GpuView::mode`: a colour per cluster.
pub const MODE_CLUSTER: u32 = 1;
/// `GpuView::mode`: a colour per group (the cluster's parent group).
pub const MODE_GROUP: u32 = 2;
/// `GpuView::mode`: DAG level, blue (0) to orange (12+).
pub const MODE_LEVEL: u32 = 3;
/// `GpuView::mode`: the cluster's own projected error over τ, blue (0) to orange (τ).
pub const MODE_ERROR: u32 = 4;

/// The clusters of one DAG level in the level-sorted order (GLSL `LevelBin`, std430, 16 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuLevelBin {
    /// First index into the level order.
    pub first: u32,
    /// Clusters of the level.
    pub count: u32,
    /// Smallest own error among them (object space).
    pub min_own_error: f32,
    /// Largest parent error among them (object space; `+inf` if any is a root).
    pub max_parent_error: f32,
}

/// One placement of a mesh (GLSL `Instance`, std430, 176 bytes): its transform, what the
/// selection needs in the mesh's object space (docs/FORMAT.md "Scene file" gives the rule and
/// why it is conservative; `crate::instances` builds these), and which mesh it places.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuInstance {
    /// Object to world, column-major (`model[col][row]`), affine.
    pub model: [[f32; 4]; 4],
    /// Rows 0..3 of the inverse (world to object): `object.x = dot(row0.xyz, world) + row0.w`.
    pub inverse_row0: [f32; 4],
    /// Row 1 of the inverse.
    pub inverse_row1: [f32; 4],
    /// Row 2 of the inverse.
    pub inverse_row2: [f32; 4],
    /// The mesh's position grid: origin xyz, step w (FORMAT.md §2).
    pub grid: [f32; 4],
    /// The mesh's culling centre xyz (object space, `SceneData::bounds`) and `model_far` w.
    pub center: [f32; 4],
    /// The mesh's `model_near` (object space).
    pub model_near: f32,
    /// `s_max / s_min` of the upper 3×3 (1 for a rigid motion with uniform scale): multiplies
    /// every object-space projected error.
    pub error_scale: f32,
    /// `1 / s_min`: the view's `z_near` in object space is `z_near * near_scale`.
    pub near_scale: f32,
    /// `s_max`: world radius of an object-space sphere of radius 1.
    pub radius_scale: f32,
    /// The mesh's first level bin (index into the bin buffer).
    pub bin_first: u32,
    /// The mesh's level bins.
    pub bin_count: u32,
    /// 1 if the transform mirrors (negative determinant): triangles are drawn reversed.
    pub mirrored: u32,
    /// The mesh (index into `SceneData::parts`).
    pub mesh: u32,
}

/// `GpuView::flags`: cull clusters whose parent sphere is outside the frustum.
pub const FLAG_FRUSTUM_CULL: u32 = 1;
/// `GpuView::flags`: write every cluster's (own, parent) projected error for diagnostics.
pub const FLAG_WRITE_PROJECTED: u32 = 2;
/// `GpuView::flags`: test hook that drops every fifth selected cluster (makes holes).
pub const FLAG_DROP_SOME: u32 = 4;
/// `GpuView::flags`: the benchmark's alternatives draw every instance at level 0.
pub const FLAG_FULL_DETAIL: u32 = 8;

/// Atomic counters that double as indirect arguments (GLSL `Counters`, std430, 76 bytes).
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
    /// `VkDrawMeshTasksIndirectCommandEXT` of the mesh-shader path: task workgroups (one per
    /// 32 visible clusters) in max_groups-wide rows.
    pub task_x: u32,
    /// Rows of task workgroups (at least 1).
    pub task_y: u32,
    /// Always 1.
    pub task_z: u32,
    /// Triangles of the visible clusters.
    pub triangles: u32,
    /// Work items (instance, cluster range) written by instance culling.
    pub work_count: u32,
    /// `VkDispatchIndirectCommand` of the selection pass: one workgroup per work item, in rows.
    pub select_x: u32,
    /// Rows of the selection dispatch (at least 1).
    pub select_y: u32,
    /// Always 1.
    pub select_z: u32,
    /// Index-buffer allocator of the fallback expansion.
    pub index_alloc: u32,
    /// Clusters dropped because the visible list or the index buffer was full.
    pub dropped: u32,
}

impl GpuCounters {
    /// The values a pass starts from: zero counts, unit y/z and instance counts.
    pub fn reset() -> GpuCounters {
        GpuCounters {
            dispatch_y: 1,
            dispatch_z: 1,
            instance_count: 1,
            task_y: 1,
            task_z: 1,
            select_y: 1,
            select_z: 1,
            ..Default::default()
        }
    }
}

/// Byte offset of the expansion pass's `VkDispatchIndirectCommand` in [`GpuCounters`].
pub const DISPATCH_ARGS_OFFSET: u64 = std::mem::offset_of!(GpuCounters, dispatch_x) as u64;
/// Byte offset of the `VkDrawIndexedIndirectCommand` in [`GpuCounters`].
pub const DRAW_ARGS_OFFSET: u64 = std::mem::offset_of!(GpuCounters, index_count) as u64;
/// Byte offset of the `VkDrawMeshTasksIndirectCommandEXT` in [`GpuCounters`].
pub const MESH_ARGS_OFFSET: u64 = std::mem::offset_of!(GpuCounters, task_x) as u64;
/// Byte offset of the selection pass's `VkDispatchIndirectCommand` in [`GpuCounters`].
pub const SELECT_ARGS_OFFSET: u64 = std::mem::offset_of!(GpuCounters, select_x) as u64;

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
            vertex_count, triangle_count, group, level);
        check("Cluster", false, &m, size_of::<GpuCluster>());
        assert_eq!(size_of::<GpuCluster>(), 64);
    }

    #[test]
    fn view_matches_glsl_std140() {
        let m = members!(GpuView: view_proj, frustum, eye, proj_y, viewport_height, z_near, tau, flags,
            grid_origin, grid_step, cluster_count, max_groups, instance_count, bin_count, model_center, model_far,
            model_near, mode, visible_capacity, index_capacity);
        check("View", true, &m, size_of::<GpuView>());
    }

    #[test]
    fn counters_match_glsl_std430_and_vulkan_commands() {
        let m = members!(GpuCounters: visible_count, dispatch_x, dispatch_y, dispatch_z, index_count,
            instance_count, first_index, vertex_offset, first_instance, task_x, task_y, task_z, triangles, work_count,
            select_x, select_y, select_z, index_alloc, dropped);
        check("Counters", false, &m, size_of::<GpuCounters>());
        // Indirect commands must be 4-aligned and laid out as Vulkan's structs.
        assert_eq!(size_of::<ash::vk::DispatchIndirectCommand>(), 12);
        assert_eq!(size_of::<ash::vk::DrawIndexedIndirectCommand>(), 20);
        assert_eq!(DRAW_ARGS_OFFSET + 20, MESH_ARGS_OFFSET);
        assert_eq!(DISPATCH_ARGS_OFFSET % 4, 0);
        assert_eq!(size_of::<ash::vk::DrawMeshTasksIndirectCommandEXT>(), 12);
        assert_eq!(MESH_ARGS_OFFSET % 4, 0);
        assert_eq!(SELECT_ARGS_OFFSET % 4, 0);
    }

    #[test]
    fn instance_matches_glsl_std430() {
        let m = members!(GpuInstance: model, inverse_row0, inverse_row1, inverse_row2, grid, center, model_near,
            error_scale, near_scale, radius_scale, bin_first, bin_count, mirrored, mesh);
        check("Instance", false, &m, size_of::<GpuInstance>());
        assert_eq!(size_of::<GpuInstance>(), 176);
    }

    #[test]
    fn level_bin_matches_glsl_std430() {
        let m = members!(GpuLevelBin: first, count, min_own_error, max_parent_error);
        check("LevelBin", false, &m, size_of::<GpuLevelBin>());
    }

    #[test]
    fn mode_and_flag_constants_match_glsl() {
        for (name, value) in [
            ("MODE_SHADED", MODE_SHADED),
            ("MODE_CLUSTER", MODE_CLUSTER),
            ("MODE_GROUP", MODE_GROUP),
            ("MODE_LEVEL", MODE_LEVEL),
            ("MODE_ERROR", MODE_ERROR),
            ("FLAG_FRUSTUM_CULL", FLAG_FRUSTUM_CULL),
            ("FLAG_WRITE_PROJECTED", FLAG_WRITE_PROJECTED),
            ("FLAG_DROP_SOME", FLAG_DROP_SOME),
            ("FLAG_FULL_DETAIL", FLAG_FULL_DETAIL),
        ] {
            assert!(
                COMMON_GLSL.contains(&format!("const uint {name} = {value}u;")),
                "{name} = {value} not in common.glsl"
            );
        }
    }

    #[test]
    fn layout_parser_sees_a_drifted_member() {
        // The checker itself: a GLSL struct with a vec3 followed by a float packs them together.
        let (m, size) = glsl_layout("View", true);
        let eye = m.iter().find(|(n, _, _)| n == "eye").unwrap();
        let proj = m.iter().find(|(n, _, _)| n == "proj_y").unwrap();
        assert_eq!((eye.1, proj.1), (160, 172));
        assert_eq!(size, 256);
    }
}
