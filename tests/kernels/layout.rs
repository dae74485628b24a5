// SPDX-License-Identifier: MIT
//! Every `#[repr(C)]` parameter struct matches its WGSL twin as naga laid it out: size, member
//! names, order and offsets. This replaces "keep in sync" comments.

use std::mem::{offset_of, size_of};

use webfusion_core::kernels::{self, GpuIntrinsics};
use webfusion_shaders as shaders;

macro_rules! check_layout {
    ($kernel:expr, $wgsl:literal, $ty:ty, [$($field:ident),* $(,)?]) => {{
        let layout = $kernel.struct_layout($wgsl).unwrap_or_else(|| panic!("{} has no struct {}", $kernel.name, $wgsl));
        assert_eq!(size_of::<$ty>() as u32, layout.size_bytes, "size of {}", $wgsl);
        let rust: Vec<(&str, u32)> = vec![$((stringify!($field), offset_of!($ty, $field) as u32)),*];
        let wgsl: Vec<(&str, u32)> = layout.members.iter().map(|m| (m.name, m.offset_bytes)).collect();
        assert_eq!(rust, wgsl, "members of {}", $wgsl);
    }};
}

#[test]
fn params_structs_match_wgsl() {
    check_layout!(shaders::VERTEX_MAP, "Intrinsics", GpuIntrinsics, [fx_px, fy_px, cx_px, cy_px, width_px, height_px, _pad0, _pad1]);
    check_layout!(shaders::DEPTH_TO_METRES, "DepthToMetresParams", kernels::depth_to_metres::DepthToMetresParams,
        [width_px, height_px, metres_per_unit, min_depth_m, max_depth_m, _pad0, _pad1, _pad2]);
    check_layout!(shaders::BILATERAL_FILTER, "BilateralFilterParams", kernels::bilateral_filter::BilateralFilterParams,
        [width_px, height_px, radius_px, _pad0, sigma_space_px, sigma_range_m, _pad1, _pad2]);
    check_layout!(shaders::DEPTH_PYRAMID_DOWN, "DepthPyramidDownParams", kernels::depth_pyramid_down::DepthPyramidDownParams,
        [src_width_px, src_height_px, dst_width_px, dst_height_px, max_depth_diff_m, _pad0, _pad1, _pad2]);
    check_layout!(shaders::VERTEX_MAP, "VertexMapParams", kernels::vertex_map::VertexMapParams, [intrinsics]);
    check_layout!(shaders::VERTEX_GRADIENTS, "VertexGradientsParams", kernels::vertex_gradients::VertexGradientsParams, [width_px, height_px, _pad0, _pad1]);
    check_layout!(shaders::GRADIENT_SMOOTH, "GradientSmoothParams", kernels::gradient_smooth::GradientSmoothParams,
        [width_px, height_px, radius_px, axis, sigma_px, _pad0, _pad1, _pad2]);
    check_layout!(shaders::NORMAL_MAP, "NormalMapParams", kernels::normal_map::NormalMapParams, [width_px, height_px, min_cross_norm_sq, _pad0]);
    check_layout!(shaders::COLOR_TO_FLOAT, "ColorToFloatParams", kernels::color_to_float::ColorToFloatParams, [width_px, height_px, _pad0, _pad1]);
    check_layout!(shaders::TSDF_INTEGRATE, "VolumeDesc", webfusion_core::tsdf::VolumeDesc,
        [dim_x, dim_y, dim_z, max_weight, origin_x_m, origin_y_m, origin_z_m, voxel_size_m, truncation_m, _pad0, _pad1, _pad2]);
    check_layout!(shaders::TSDF_INTEGRATE, "TsdfIntegrateParams", kernels::tsdf_integrate::TsdfIntegrateParams,
        [volume, intrinsics, camera_from_world, color_enabled, _pad0, _pad1, _pad2]);
    check_layout!(shaders::RAYCAST, "RaycastParams", kernels::raycast::RaycastParams,
        [volume, intrinsics, world_from_camera, min_depth_m, max_depth_m, step_factor, max_steps]);
    check_layout!(shaders::ICP_REDUCE, "IcpReduceParams", kernels::icp_reduce::IcpReduceParams,
        [intrinsics, world_from_camera, camera_prev_from_world, dist_thresh_m, cos_angle_thresh, thread_count, huber_delta_m, noise_weighting, _pad0, _pad1, _pad2]);
    check_layout!(shaders::INTENSITY_PYRAMID_DOWN, "IntensityPyramidDownParams", kernels::intensity_pyramid_down::IntensityPyramidDownParams,
        [src_width_px, src_height_px, dst_width_px, dst_height_px]);
    check_layout!(shaders::RGB_REDUCE, "RgbReduceParams", kernels::rgb_reduce::RgbReduceParams,
        [intrinsics, world_from_camera, camera_prev_from_world, world_from_camera_prev, max_depth_diff_m, max_residual, thread_count, _pad0]);
    check_layout!(shaders::MC_COUNT, "VolumeDesc", webfusion_core::tsdf::VolumeDesc,
        [dim_x, dim_y, dim_z, max_weight, origin_x_m, origin_y_m, origin_z_m, voxel_size_m, truncation_m, _pad0, _pad1, _pad2]);
    check_layout!(shaders::MC_COUNT, "McCountParams", kernels::mc_count::McCountParams, [volume, n_blocks_x, n_blocks_y, n_blocks, _pad0]);
    check_layout!(shaders::MC_SCAN, "McScanParams", kernels::mc_scan::McScanParams, [n_blocks, capacity_triangles, max_workgroups_per_dimension, _pad0]);
    check_layout!(shaders::MC_SCAN, "McCounters", kernels::mc_scan::McCounters, [n_triangles, capacity_triangles, failed, n_active_blocks, generate_workgroups_x, generate_workgroups_y, generate_workgroups_z, _pad0]);
    check_layout!(shaders::MC_GENERATE, "McGenerateParams", kernels::mc_generate::McGenerateParams,
        [volume, n_blocks_x, n_blocks_y, first_triangle, capacity_triangles, has_color, _pad0, _pad1, _pad2]);
    check_layout!(shaders::MC_GENERATE, "McVertex", kernels::mc_generate::McVertex, [x_m, y_m, z_m, edge_id, normal_x, normal_y, normal_z, color_rgb8]);
}

#[test]
fn every_kernel_has_params_at_binding_zero_and_a_cpu_reference() {
    for k in shaders::ALL {
        let first = k.bindings.first().unwrap_or_else(|| panic!("{} has no bindings", k.name));
        assert_eq!((first.group, first.binding, first.kind), (0, 0, shaders::BindingKind::Uniform), "{}: params at @group(0) @binding(0)", k.name);
        assert!(k.bindings.iter().all(|b| b.group == 0), "{}: everything in group 0", k.name);
        assert!(matches!(webfusion_core::cpu::coverage(k.name), webfusion_core::cpu::CpuKernel::Present), "{} lacks a CPU reference", k.name);
        assert!(k.source.contains("//! "), "{} documents what one invocation computes", k.name);
    }
    assert_eq!(shaders::ALL.len(), 16, "kernel count changed: add its layout check above");
}
