// SPDX-License-Identifier: MIT
//! Each invocation draws, over one pixel of a rendered view (a free view's model colour or
//! shading), seed 003's textured planar model: the world planes' quadtree meshes as they look
//! from `pose`. The pixel's ray meets every plane that faces it (front faces only, as the
//! meshes' counter-clockwise triangles and the raycast's surfaces are seen); the nearest
//! meeting at a camera depth within [`near_m`, `far_m`) that falls on a texel a quad covers (a
//! texel word with a non-zero alpha) gives the pixel that texel's colour, unless the view's
//! own surface at that pixel (`depth_m`, NaN: none) lies in front of that plane by more than
//! `occlusion_m` along its normal (a chair in front of a wall hides the wall; the wall's own
//! fused surface, within that distance of it, does not). A pixel no covered texel falls on
//! keeps what it had. Padding pixels are not touched.
#import invalid
#import camera
#import camera_pose

// One world plane and its texel grid.
struct OverlayPlane {
    // Unit normal n (xyz, world frame, towards the views that saw it) and offset d (w), metres:
    // n·p + d = 0.
    plane: vec4<f32>,
    // Texel column of a point p on the plane: dot(to_texel_x.xyz, p) + to_texel_x.w (the
    // mesh's vertices lie at integer texel coordinates, projected along n onto the plane).
    to_texel_x: vec4<f32>,
    // Texel row of a point p on the plane, likewise.
    to_texel_y: vec4<f32>,
    // Texels along a row.
    width: u32,
    // Rows.
    height: u32,
    // Index of the plane's texel (0, 0) in `texels` (rows follow one another).
    first_texel: u32,
    _pad0: u32,
}

struct PlaneOverlayParams {
    // Intrinsics of the view.
    intrinsics: Intrinsics,
    // Pixels from one row of the view to the next (≥ width_px).
    row_stride_px: u32,
    // Planes in `planes`.
    plane_count: u32,
    // Nearest camera depth drawn, metres.
    near_m: f32,
    // Farthest camera depth drawn, metres (exclusive).
    far_m: f32,
    // How far in front of a plane (along its normal) the view's surface may lie and the plane
    // still show, metres.
    occlusion_m: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneOverlayParams;
// The view's pose (world frame of the planes).
@group(0) @binding(1) var<uniform> pose: CameraPose;
// The planes.
@group(0) @binding(2) var<storage, read> planes: array<OverlayPlane>;
// Per texel of each plane: RGB in the low bytes and 0xff above where a quad covers it, 0 where
// none does.
@group(0) @binding(3) var<storage, read> texels: array<u32>;
// The view's surface depth along the camera's z, metres (NaN: none), width_px per row.
@group(0) @binding(4) var<storage, read> depth_m: array<f32>;
// In and out: the view's RGBA8 pixels (red in the low byte), rows row_stride_px apart.
@group(0) @binding(5) var<storage, read_write> rgba8: array<u32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = params.intrinsics;
    if gid.x >= k.width_px || gid.y >= k.height_px || pose.enabled == 0u {
        return;
    }
    // The ray at camera depth 1: its parameter is the camera depth.
    let ray_cam = back_project(k, f32(gid.x), f32(gid.y), 1.0);
    let m = pose.world_from_camera;
    let origin = m[3].xyz;
    let dir = (m * vec4<f32>(ray_cam, 0.0)).xyz;
    var best_z = params.far_m;
    var best = params.plane_count;
    var colour = 0u;
    for (var i = 0u; i < params.plane_count; i++) {
        let pl = planes[i];
        let facing = dot(pl.plane.xyz, dir);
        if !(facing < 0.0) {
            // Seen from behind, or along it.
            continue;
        }
        let z = -(dot(pl.plane.xyz, origin) + pl.plane.w) / facing;
        if !(z >= params.near_m && z < best_z) {
            continue;
        }
        let p = origin + dir * z;
        let tx = floor(dot(pl.to_texel_x.xyz, p) + pl.to_texel_x.w);
        let ty = floor(dot(pl.to_texel_y.xyz, p) + pl.to_texel_y.w);
        if !(tx >= 0.0 && ty >= 0.0 && tx < f32(pl.width) && ty < f32(pl.height)) {
            continue;
        }
        let word = texels[pl.first_texel + u32(ty) * pl.width + u32(tx)];
        if (word >> 24u) == 0u {
            continue;
        }
        best_z = z;
        best = i;
        colour = word;
    }
    if best == params.plane_count {
        return;
    }
    let surface_z = depth_m[gid.y * k.width_px + gid.x];
    if is_valid_f32(surface_z) {
        // The view's surface point, and how far in front of the plane it lies.
        let s = origin + dir * surface_z;
        let pl = planes[best];
        if dot(pl.plane.xyz, s) + pl.plane.w > params.occlusion_m {
            return;
        }
    }
    rgba8[gid.y * params.row_stride_px + gid.x] = colour;
}
