// SPDX-License-Identifier: MIT
//! Twins of the functions in `shaders/wgsl/shared/`, same names and argument order.

/// The invalid marker (quiet NaN), as `invalid_f32()` in `shared/invalid.wgsl`.
pub const INVALID: f32 = f32::from_bits(0x7fc0_0000);
/// The invalid vec4.
pub const INVALID_VEC4: [f32; 4] = [INVALID; 4];

/// Twin of `invalid_f32()`.
pub fn invalid_f32() -> f32 {
    INVALID
}

/// Twin of `is_valid_f32()`: finite values are valid.
pub fn is_valid_f32(x: f32) -> bool {
    (x.to_bits() & 0x7f80_0000) != 0x7f80_0000
}

/// Twin of `kinect_sigma_m()` in `shared/kinect.wgsl`: Kinect v1 axial depth noise at `z_m`
/// (Nguyen, Izadi and Lovell 2012), metres.
pub fn kinect_sigma_m(z_m: f32) -> f32 {
    let d = z_m - 0.4;
    0.0012 + 0.0019 * d * d
}

/// Twin of `kinect_sigma_at_angle_m()` in `shared/kinect.wgsl`: the axial noise at `z_m` and
/// incidence angle `theta_rad`, metres.
pub fn kinect_sigma_at_angle_m(z_m: f32, theta_rad: f32) -> f32 {
    let mut sigma = kinect_sigma_m(z_m);
    if theta_rad > std::f32::consts::FRAC_PI_3 {
        let g = theta_rad / (std::f32::consts::FRAC_PI_2 - theta_rad);
        sigma += 0.0001 / z_m.sqrt() * g * g;
    }
    sigma
}

/// Twin of `kinect_lateral_sigma_px()` in `shared/kinect.wgsl`: the lateral noise at incidence
/// angle `theta_rad`, pixels.
pub fn kinect_lateral_sigma_px(theta_rad: f32) -> f32 {
    0.8 + 0.035 * theta_rad / (std::f32::consts::FRAC_PI_2 - theta_rad)
}

/// Twin of `pcg_hash()` in `shared/random.wgsl`.
pub fn pcg_hash(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// Twin of `random_uniform()` in `shared/random.wgsl`: advances `state`, returns (0, 1).
pub fn random_uniform(state: &mut u32) -> f32 {
    *state = pcg_hash(*state);
    ((*state >> 8) as f32 + 0.5) * (1.0 / 16_777_216.0)
}

/// Twin of `random_gauss2()` in `shared/random.wgsl`: two standard normal numbers.
pub fn random_gauss2(state: &mut u32) -> [f32; 2] {
    let u1 = random_uniform(state);
    let u2 = random_uniform(state);
    let r = (-2.0 * u1.ln()).sqrt();
    let phi = std::f32::consts::TAU * u2;
    [r * phi.cos(), r * phi.sin()]
}

/// Twin of `depth_to_metres()` in `shared/depth.wgsl`.
pub fn depth_to_metres(raw_units: u32, metres_per_unit: f32, min_depth_m: f32, max_depth_m: f32) -> f32 {
    if raw_units == 0 {
        return invalid_f32();
    }
    let depth_m = raw_units as f32 * metres_per_unit;
    if depth_m < min_depth_m || depth_m > max_depth_m {
        return invalid_f32();
    }
    depth_m
}

/// Twin of `back_project()` in `shared/camera.wgsl`.
pub fn back_project(k: &crate::kernels::GpuIntrinsics, u_px: f32, v_px: f32, z_m: f32) -> [f32; 3] {
    [(u_px - k.cx_px) * z_m / k.fx_px, (v_px - k.cy_px) * z_m / k.fy_px, z_m]
}

/// Packs u16 values two per u32 word, low half first (the layout `depth_raw` uses).
pub fn pack_u16_pairs(values: &[u16]) -> Vec<u32> {
    values.chunks(2).map(|c| u32::from(c[0]) | (u32::from(*c.get(1).unwrap_or(&0)) << 16)).collect()
}

/// Packs bytes four per u32 word, little-endian (the layout `rgb8` uses).
pub fn pack_bytes(bytes: &[u8]) -> Vec<u32> {
    bytes.chunks(4).map(|c| c.iter().enumerate().fold(0u32, |w, (i, b)| w | (u32::from(*b) << (8 * i)))).collect()
}

use crate::tsdf::VolumeDesc;

/// Twin of `TSDF_SCALE` in `shared/tsdf.wgsl`.
pub const TSDF_SCALE: f32 = 32767.0;

/// Twin of `FAR_TSDF`.
pub const FAR_TSDF: f32 = 0.999;

/// Twin of `BRICK_SHIFT`: bricks of 8³ voxels.
pub const BRICK_SHIFT: u32 = 3;

/// Twin of `brick_dims()`.
pub fn brick_dims(d: &VolumeDesc) -> [u32; 3] {
    [d.dim_x, d.dim_y, d.dim_z].map(|v| v.div_ceil(1 << BRICK_SHIFT))
}

/// Twin of `brick_index()`.
pub fn brick_index(d: &VolumeDesc, x: u32, y: u32, z: u32) -> u32 {
    let b = brick_dims(d);
    (x >> BRICK_SHIFT) + b[0] * ((y >> BRICK_SHIFT) + b[1] * (z >> BRICK_SHIFT))
}

/// The surface-brick words of a volume given voxel by voxel (what integrating it would have
/// marked): 1 for each brick holding an observed voxel with TSDF below [`FAR_TSDF`].
pub fn surface_bricks(d: &VolumeDesc, tsdf_volume: &[u32]) -> Vec<u32> {
    let b = brick_dims(d);
    let mut out = vec![0u32; (b[0] * b[1] * b[2]) as usize];
    for z in 0..d.dim_z {
        for y in 0..d.dim_y {
            for x in 0..d.dim_x {
                let word = tsdf_volume[voxel_index(d, x, y, z) as usize];
                if voxel_weight(word) > 0 && voxel_tsdf(word) < FAR_TSDF {
                    out[brick_index(d, x, y, z) as usize] = 1;
                }
            }
        }
    }
    out
}

/// Twin of `voxel_index()`.
pub fn voxel_index(d: &VolumeDesc, x: u32, y: u32, z: u32) -> u32 {
    x + d.dim_x * (y + d.dim_y * z)
}

/// Twin of `MAP_DENSE` (shared/tsdf.wgsl).
pub const MAP_DENSE: u32 = 0;
/// Twin of `MAP_SPARSE`.
pub const MAP_SPARSE: u32 = 1;

/// Twin of `MAX_BAND_VOXELS`: the widest truncation band, voxels.
pub const MAX_BAND_VOXELS: f32 = 16.0;

/// Twin of `truncation_band_m()` in `shared/tsdf.wgsl`: the truncation band of a sample measured
/// at `depth_m`, metres: μ, widened to `noise_band_sigmas` σ of the Kinect model where that is
/// wider, at most [`MAX_BAND_VOXELS`].
pub fn truncation_band_m(d: &VolumeDesc, depth_m: f32) -> f32 {
    let noise_m = d.noise_band_sigmas * kinect_sigma_m(depth_m);
    d.truncation_m.max(noise_m.min(MAX_BAND_VOXELS * d.voxel_size_m))
}

/// Twin of `voxel_anchor()`: the voxel whose outer corner the origin gives.
pub fn voxel_anchor(d: &VolumeDesc) -> [u32; 3] {
    if d.kind == MAP_SPARSE {
        return [d.dim_x, d.dim_y, d.dim_z].map(|v| (v >> (BRICK_SHIFT + 1)) << BRICK_SHIFT);
    }
    [0; 3]
}

/// Twin of `voxel_centre_in_world()`.
pub fn voxel_centre_in_world(d: &VolumeDesc, x: u32, y: u32, z: u32) -> [f32; 3] {
    let a = voxel_anchor(d);
    let origin = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
    let g = [x, y, z];
    std::array::from_fn(|i| origin[i] + ((g[i] as i32 - a[i] as i32) as f32 + 0.5) * d.voxel_size_m)
}

/// Twin of `box_corner_in_world()`.
pub fn box_corner_in_world(d: &VolumeDesc) -> [f32; 3] {
    let a = voxel_anchor(d);
    let origin = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
    std::array::from_fn(|i| origin[i] - a[i] as f32 * d.voxel_size_m)
}

/// Twin of `pack_voxel()`: rounds to nearest, ties to even, as WGSL `round`.
pub fn pack_voxel(tsdf: f32, weight: u32) -> u32 {
    let t = (tsdf.clamp(-1.0, 1.0) * TSDF_SCALE).round_ties_even() as i32;
    (t as u32 & 0xffff) | (weight.min(0xffff) << 16)
}

/// Twin of `voxel_tsdf()`.
pub fn voxel_tsdf(word: u32) -> f32 {
    (((word << 16) as i32) >> 16) as f32 / TSDF_SCALE
}

/// Twin of `voxel_weight()`.
pub fn voxel_weight(word: u32) -> u32 {
    word >> 16
}

/// Twin of `pack_rgb8()`.
pub fn pack_rgb8(rgb: [f32; 3]) -> u32 {
    let c = rgb.map(|v| (v.clamp(0.0, 1.0) * 255.0).round_ties_even() as u32);
    c[0] | (c[1] << 8) | (c[2] << 16)
}

/// Twin of `unpack_rgb8()`.
pub fn unpack_rgb8(word: u32) -> [f32; 3] {
    [(word & 0xff) as f32 / 255.0, ((word >> 8) & 0xff) as f32 / 255.0, ((word >> 16) & 0xff) as f32 / 255.0]
}

/// Twin of `TsdfSample` in `shared/tsdf_sample.wgsl`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TsdfSample {
    /// Interpolated TSDF, truncation units.
    pub tsdf: f32,
    /// False if a surrounding voxel was never observed or lies outside.
    pub valid: bool,
}

/// Twin of WGSL `mix(a, b, t)`.
pub fn mix(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// Twin of `sample_tsdf()` (shared/tsdf_sample.wgsl), reading a map of either kind.
pub fn sample_tsdf(map: MapRef<'_>, d: &VolumeDesc, p_world: [f32; 3]) -> TsdfSample {
    let origin = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
    let g: [f32; 3] = std::array::from_fn(|i| (p_world[i] - origin[i]) / d.voxel_size_m - 0.5);
    let base_rel = g.map(f32::floor);
    let anchor = voxel_anchor(d);
    let base_f: [f32; 3] = std::array::from_fn(|i| base_rel[i] + anchor[i] as f32);
    let invalid = TsdfSample { tsdf: 0.0, valid: false };
    let dims = [d.dim_x, d.dim_y, d.dim_z];
    if (0..3).any(|i| !(base_f[i] >= 0.0) || base_f[i] >= (dims[i] - 1) as f32) {
        return invalid;
    }
    let b = base_f.map(|v| v as u32);
    let f: [f32; 3] = std::array::from_fn(|i| g[i] - base_rel[i]);
    let w = if d.kind == MAP_SPARSE && b.iter().all(|&v| v & 7 < 7) {
        // The 8 voxels share one block: one lookup.
        let block = find_block(map.block_table, d, b.map(|v| v >> BRICK_SHIFT));
        if block == NO_BLOCK {
            return invalid;
        }
        let s = (block * BLOCK_VOXELS + voxel_in_block(b[0], b[1], b[2])) as usize;
        [0, 1, 8, 9, 64, 65, 72, 73].map(|o| map.tsdf_volume[s + o])
    } else {
        let at = |dx: u32, dy: u32, dz: u32| map_word(map, d, b[0] + dx, b[1] + dy, b[2] + dz);
        [at(0, 0, 0), at(1, 0, 0), at(0, 1, 0), at(1, 1, 0), at(0, 0, 1), at(1, 0, 1), at(0, 1, 1), at(1, 1, 1)]
    };
    let observed = w.iter().copied().min().unwrap_or(0) >= 0x1_0000;
    let t = w.map(voxel_tsdf);
    let x00 = mix(t[0], t[1], f[0]);
    let x10 = mix(t[2], t[3], f[0]);
    let x01 = mix(t[4], t[5], f[0]);
    let x11 = mix(t[6], t[7], f[0]);
    TsdfSample { tsdf: mix(mix(x00, x10, f[1]), mix(x01, x11, f[1]), f[2]), valid: observed }
}

/// Twin of `BLOCK_VOXELS` (shared/map.wgsl): voxels per block of 8³.
pub const BLOCK_VOXELS: u32 = 512;
/// Twin of `EMPTY_KEY`: the key of a free hash slot.
pub const EMPTY_KEY: u32 = u32::MAX;
/// Twin of `NO_BLOCK`: the pool index of a key without a block.
pub const NO_BLOCK: u32 = u32::MAX;
/// Twin of `SWAPPED_BLOCK`: the pool index of a key whose block was swapped out to the host.
pub const SWAPPED_BLOCK: u32 = 0xffff_fffe;
/// Twin of `NO_SLOT`: the voxel slot of a voxel without a block.
pub const NO_SLOT: u32 = u32::MAX;
/// Twin of `MAP_MAX_PROBES`.
pub const MAP_MAX_PROBES: u32 = 64;
/// Twin of `NO_DEPTH_TILE`: a depth tile without a valid depth.
pub const NO_DEPTH_TILE: f32 = -1.0;
/// Twin of `MAP_COUNTER_BLOCKS_USED`.
pub const MAP_COUNTER_BLOCKS_USED: usize = 0;
/// Twin of `MAP_COUNTER_VISIBLE`.
pub const MAP_COUNTER_VISIBLE: usize = 1;
/// Twin of `MAP_COUNTER_HASH_FULL`.
pub const MAP_COUNTER_HASH_FULL: usize = 2;
/// Twin of `MAP_COUNTER_POOL_FULL`.
pub const MAP_COUNTER_POOL_FULL: usize = 3;
/// Twin of `MAP_COUNTER_OUT_OF_RANGE`.
pub const MAP_COUNTER_OUT_OF_RANGE: usize = 4;
/// Twin of `MAP_COUNTER_ARGS`.
pub const MAP_COUNTER_ARGS: usize = 5;
/// Twin of `MAP_COUNTER_FREE`.
pub const MAP_COUNTER_FREE: usize = 8;
/// Twin of `MAP_COUNTER_SWAPPED_OUT`.
pub const MAP_COUNTER_SWAPPED_OUT: usize = 9;
/// Twin of `MAP_COUNTER_SWAP_IN_REFUSED`.
pub const MAP_COUNTER_SWAP_IN_REFUSED: usize = 10;
/// Twin of `MAP_COUNTER_SWAPPED_HITS`.
pub const MAP_COUNTER_SWAPPED_HITS: usize = 11;
/// Twin of `MAP_COUNTERS`.
pub const MAP_COUNTERS: usize = 12;

/// Twin of `take_pool_block()` (map_pool.wgsl), invocations one after another: the top of the
/// free list, else the next bump-allocated block, else `NO_BLOCK`.
pub fn take_pool_block(map_counters: &mut [u32], free_blocks: &[u32], pool_blocks: u32) -> u32 {
    let free = map_counters[MAP_COUNTER_FREE];
    if free >= 1 && free <= pool_blocks {
        map_counters[MAP_COUNTER_FREE] -= 1;
        return free_blocks[free as usize - 1];
    }
    let block = map_counters[MAP_COUNTER_BLOCKS_USED];
    if block >= pool_blocks {
        return NO_BLOCK;
    }
    map_counters[MAP_COUNTER_BLOCKS_USED] += 1;
    block
}

/// Twin of `block_key()`.
pub fn block_key(b: [u32; 3]) -> u32 {
    b[0] | (b[1] << 11) | (b[2] << 22)
}

/// Twin of `block_of_key()`.
pub fn block_of_key(key: u32) -> [u32; 3] {
    [key & 0x7ff, (key >> 11) & 0x7ff, key >> 22]
}

/// Twin of `block_hash()`.
pub fn block_hash(b: [u32; 3]) -> u32 {
    let mut h = b[0].wrapping_mul(73_856_093) ^ b[1].wrapping_mul(19_349_663) ^ b[2].wrapping_mul(83_492_791);
    h ^= h >> 16;
    h = h.wrapping_mul(0x045d_9f3b);
    h ^= h >> 16;
    h
}

/// Twin of `voxel_in_block()`.
pub fn voxel_in_block(x: u32, y: u32, z: u32) -> u32 {
    (x & 7) | ((y & 7) << 3) | ((z & 7) << 6)
}

/// What map_lookup.wgsl reads: the voxel words (a dense box or a sparse pool) and the sparse
/// map's hash table (empty or a placeholder for a dense map).
#[derive(Clone, Copy, Debug)]
pub struct MapRef<'a> {
    /// Voxel words.
    pub tsdf_volume: &'a [u32],
    /// (key, pool index) per hash slot.
    pub block_table: &'a [u32],
}

/// The probe sequence of `find_block()` and `insert_block()` (map.wgsl), one after another:
/// the hash slot holding block `b`'s key or, where it is absent, the first free slot on its
/// probe sequence; `None` when neither comes within `MAP_MAX_PROBES` slots.
pub fn probe_slot(block_table: &[u32], d: &VolumeDesc, b: [u32; 3]) -> Option<usize> {
    let key = block_key(b);
    let mask = d.hash_slots - 1;
    let mut s = block_hash(b) & mask;
    for _ in 0..MAP_MAX_PROBES {
        let k = block_table[2 * s as usize];
        if k == key || k == EMPTY_KEY {
            return Some(s as usize);
        }
        s = (s + 1) & mask;
    }
    None
}

/// Twin of `find_slot()` (map_lookup.wgsl): the hash slot holding block `b`'s key.
pub fn find_slot(block_table: &[u32], d: &VolumeDesc, b: [u32; 3]) -> Option<usize> {
    probe_slot(block_table, d, b).filter(|&s| block_table[2 * s] == block_key(b))
}

/// Twin of `find_block()` (without its memo of the last block, which changes no result): the
/// pool index of block `b`, `NO_BLOCK` when it is absent, has none or is swapped out.
pub fn find_block(block_table: &[u32], d: &VolumeDesc, b: [u32; 3]) -> u32 {
    match find_slot(block_table, d, b) {
        Some(s) if block_table[2 * s + 1] != SWAPPED_BLOCK => block_table[2 * s + 1],
        _ => NO_BLOCK,
    }
}

/// Twin of `voxel_slot()`.
pub fn voxel_slot(map: MapRef<'_>, d: &VolumeDesc, x: u32, y: u32, z: u32) -> u32 {
    if d.kind == MAP_DENSE {
        return voxel_index(d, x, y, z);
    }
    let block = find_block(map.block_table, d, [x, y, z].map(|v| v >> BRICK_SHIFT));
    if block == NO_BLOCK {
        return NO_SLOT;
    }
    block * BLOCK_VOXELS + voxel_in_block(x, y, z)
}

/// Twin of `map_word()`.
pub fn map_word(map: MapRef<'_>, d: &VolumeDesc, x: u32, y: u32, z: u32) -> u32 {
    let s = voxel_slot(map, d, x, y, z);
    if s == NO_SLOT {
        return 0;
    }
    map.tsdf_volume[s as usize]
}

/// `m * v` for a column-major 4x4 matrix, as WGSL `mat4x4<f32> * vec4<f32>`.
pub fn mat4_mul_vec4(m: &[[f32; 4]; 4], v: [f32; 4]) -> [f32; 4] {
    std::array::from_fn(|r| m[0][r] * v[0] + m[1][r] * v[1] + m[2][r] * v[2] + m[3][r] * v[3])
}

/// `m * (p, 1)`, dropping w.
pub fn transform_point(m: &[[f32; 4]; 4], p: [f32; 3]) -> [f32; 3] {
    let r = mat4_mul_vec4(m, [p[0], p[1], p[2], 1.0]);
    [r[0], r[1], r[2]]
}

/// `m * (d, 0)`, dropping w.
pub fn transform_vector(m: &[[f32; 4]; 4], d: [f32; 3]) -> [f32; 3] {
    let r = mat4_mul_vec4(m, [d[0], d[1], d[2], 0.0]);
    [r[0], r[1], r[2]]
}

/// Dot product.
pub fn dot3(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product.
pub fn cross3(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Twin of `NE_WORKGROUP_SIZE` in `shared/normal_equations.wgsl`.
pub const NE_WORKGROUP_SIZE: u32 = 128;
/// Floats per workgroup sum (8 vec4).
pub const NE_SUM_FLOATS: usize = 32;

/// Twin of `ne_add_jacobian()`: adds JᵀJ and Jᵀr of the row `J = [a, b]` with residual `r`.
pub fn ne_add_jacobian(acc: &mut [f32; NE_SUM_FLOATS], a: [f32; 3], b: [f32; 3], r: f32) {
    let [j0, j1, j2] = a;
    let [j3, j4, j5] = b;
    let terms = [
        j0 * j0, j0 * j1, j0 * j2, j0 * j3, j0 * j4, j0 * j5, j1 * j1, j1 * j2, j1 * j3, j1 * j4, j1 * j5, j2 * j2, j2 * j3, j2 * j4, j2 * j5, j3 * j3, j3 * j4,
        j3 * j5, j4 * j4, j4 * j5, j5 * j5, j0 * r, j1 * r, j2 * r, j3 * r, j4 * r, j5 * r,
    ];
    for (a, t) in acc.iter_mut().zip(terms) {
        *a += t;
    }
}

/// Twin of `ne_add_icp_stats()`.
pub fn ne_add_icp_stats(acc: &mut [f32; NE_SUM_FLOATS], r: f32) {
    acc[27] += r * r;
    acc[28] += 1.0;
}

/// Twin of `ne_add_rgb_stats()`.
pub fn ne_add_rgb_stats(acc: &mut [f32; NE_SUM_FLOATS], r: f32) {
    acc[29] += r * r;
    acc[30] += 1.0;
}

/// The kernels' grid-stride walk plus `ne_reduce_and_store()`: thread `lid` of workgroup `wid`
/// visits pixels `wid * 128 + lid`, then every `thread_count`-th; `pixel(ix, acc)` is the
/// kernel's loop body, adding its rows to the thread's accumulator. Fills one
/// [`NE_SUM_FLOATS`] block per workgroup in the same tree order.
pub fn reduce_normal_equations(thread_count: u32, pixel_count: u32, partial_sums: &mut [f32], pixel: impl Fn(usize, &mut [f32; NE_SUM_FLOATS])) {
    for wid in 0..thread_count.div_ceil(NE_WORKGROUP_SIZE) {
        let mut scratch = vec![[0.0f32; NE_SUM_FLOATS]; NE_WORKGROUP_SIZE as usize];
        for lid in 0..NE_WORKGROUP_SIZE {
            let mut ix = wid * NE_WORKGROUP_SIZE + lid;
            while ix < pixel_count {
                pixel(ix as usize, &mut scratch[lid as usize]);
                ix += thread_count;
            }
        }
        let mut stride = NE_WORKGROUP_SIZE as usize / 2;
        while stride > 0 {
            for lid in 0..stride {
                for i in 0..NE_SUM_FLOATS {
                    scratch[lid][i] += scratch[lid + stride][i];
                }
            }
            stride >>= 1;
        }
        partial_sums[wid as usize * NE_SUM_FLOATS..][..NE_SUM_FLOATS].copy_from_slice(&scratch[0]);
    }
}

/// A column-major 4x4 matrix, as WGSL `mat4x4<f32>`.
pub type Mat4 = [[f32; 4]; 4];

/// The identity.
pub const IDENTITY: Mat4 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// `a * b`, as WGSL `mat4x4 * mat4x4`.
pub fn mat4_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    std::array::from_fn(|c| mat4_mul_vec4(a, b[c]))
}

/// `v / |v|`.
pub fn normalize3(v: [f32; 3]) -> [f32; 3] {
    let len = dot3(v, v).sqrt();
    v.map(|c| c / len)
}

/// Twin of `rigid_inverse()`: `[Rᵀ | -Rᵀ t]`.
pub fn rigid_inverse(m: &Mat4) -> Mat4 {
    // Rows of Rᵀ are the columns of R.
    let rt = |i: usize| [m[0][i], m[1][i], m[2][i]];
    let t = [m[3][0], m[3][1], m[3][2]];
    // (Rᵀ t)_i = column i of R · t.
    let rtt: [f32; 3] = std::array::from_fn(|i| m[i][0] * t[0] + m[i][1] * t[1] + m[i][2] * t[2]);
    let (c0, c1, c2) = (rt(0), rt(1), rt(2));
    [[c0[0], c0[1], c0[2], 0.0], [c1[0], c1[1], c1[2], 0.0], [c2[0], c2[1], c2[2], 0.0], [-rtt[0], -rtt[1], -rtt[2], 1.0]]
}

/// Twin of `twist_exp_mat()`: `[R(ω) | t]` with R(ω) the axis-angle rotation (Rodrigues).
pub fn twist_exp_mat(omega: [f32; 3], t: [f32; 3]) -> Mat4 {
    let angle = dot3(omega, omega).sqrt();
    let mut r = [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    if angle > 0.0 {
        let k = omega.map(|c| c / angle);
        let (c, s) = (angle.cos(), angle.sin());
        let v = 1.0 - c;
        r = [
            [c + k[0] * k[0] * v, k[1] * k[0] * v + k[2] * s, k[2] * k[0] * v - k[1] * s],
            [k[0] * k[1] * v - k[2] * s, c + k[1] * k[1] * v, k[2] * k[1] * v + k[0] * s],
            [k[0] * k[2] * v + k[1] * s, k[1] * k[2] * v - k[0] * s, c + k[2] * k[2] * v],
        ];
    }
    [[r[0][0], r[0][1], r[0][2], 0.0], [r[1][0], r[1][1], r[1][2], 0.0], [r[2][0], r[2][1], r[2][2], 0.0], [t[0], t[1], t[2], 1.0]]
}

/// Twin of `orthonormalised()`.
pub fn orthonormalised(m: &Mat4) -> Mat4 {
    let x = normalize3([m[0][0], m[0][1], m[0][2]]);
    let m1 = [m[1][0], m[1][1], m[1][2]];
    let d = dot3(x, m1);
    let y = normalize3([m1[0] - d * x[0], m1[1] - d * x[1], m1[2] - d * x[2]]);
    let z = cross3(x, y);
    [[x[0], x[1], x[2], 0.0], [y[0], y[1], y[2], 0.0], [z[0], z[1], z[2], 0.0], [m[3][0], m[3][1], m[3][2], 1.0]]
}

/// Twin of `rotation_angle_rad()`.
pub fn rotation_angle_rad(m: &Mat4) -> f32 {
    (0.5 * (m[0][0] + m[1][1] + m[2][2] - 1.0)).clamp(-1.0, 1.0).acos()
}

/// Twin of `camera_pose()`.
pub fn camera_pose(world_from_camera: &Mat4, enabled: u32) -> crate::kernels::gpu_data::CameraPose {
    crate::kernels::gpu_data::CameraPose { world_from_camera: *world_from_camera, camera_from_world: rigid_inverse(world_from_camera), enabled, ..Default::default() }
}

/// Twin of `pack_rgba8()` in `shared/colormap.wgsl`: channels clamped to [0, 1], truncated to
/// 0..255, red in the low byte.
pub fn pack_rgba8(c: [f32; 4]) -> u32 {
    let q = c.map(|v| (v.clamp(0.0, 1.0) * 255.0) as u32);
    q[0] | (q[1] << 8) | (q[2] << 16) | (q[3] << 24)
}

/// Twin of `depth_colour()` in `shared/colormap.wgsl`.
pub fn depth_colour(depth_m: f32, max_m: f32) -> u32 {
    if !(is_valid_f32(depth_m) && depth_m > 0.0) {
        return pack_rgba8([0.0, 0.0, 0.0, 1.0]);
    }
    let t = (depth_m / max_m).clamp(0.0, 1.0);
    let r = 0.27 + t * (-0.6 + t * 1.33);
    let g = t * 0.9;
    let b = 0.33 + t * (1.2 - t * 1.45);
    pack_rgba8([r, g, b, 1.0])
}

/// Twin of `normal_colour()` in `shared/colormap.wgsl`.
pub fn normal_colour(n: [f32; 4]) -> u32 {
    if !is_valid_f32(n[0]) {
        return pack_rgba8([0.0, 0.0, 0.0, 1.0]);
    }
    pack_rgba8([0.5 - 0.5 * n[0], 0.5 - 0.5 * n[1], 0.5 - 0.5 * n[2], 1.0])
}

/// Twin of `FAST_ARC` in `shared/features.wgsl`: FAST-9's arc length.
pub const FAST_ARC: u32 = 9;
/// Twin of `DESCRIPTOR_WORDS`: 32-bit words per binary descriptor.
pub const DESCRIPTOR_WORDS: usize = 8;
/// Twin of `DESCRIPTOR_BITS`: binary tests per descriptor.
pub const DESCRIPTOR_BITS: u32 = 256;
/// Twin of `NO_MATCH`: an unmatched query's index.
pub const NO_MATCH: u32 = u32::MAX;

/// Twin of `fast_circle_offset()`: pixel `k` (0..16) of the radius-3 Bresenham circle,
/// clockwise from the top (x right, y down).
pub fn fast_circle_offset(k: u32) -> [i32; 2] {
    const CIRCLE: [[i32; 2]; 16] = [[0, -3], [1, -3], [2, -2], [3, -1], [3, 0], [3, 1], [2, 2], [1, 3], [0, 3], [-1, 3], [-2, 2], [-3, 1], [-3, 0], [-3, -1], [-2, -2], [-1, -3]];
    CIRCLE[k as usize]
}

/// Twin of `plane_colour()` in `shared/colormap.wgsl`: a distinct colour per plane label.
pub fn plane_colour(label: u32) -> [f32; 3] {
    let f = label as f32 * 0.618_034;
    let h = (f - f.floor()) * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let c = match h as u32 {
        0 => [1.0, x, 0.0],
        1 => [x, 1.0, 0.0],
        2 => [0.0, 1.0, x],
        3 => [0.0, x, 1.0],
        4 => [x, 0.0, 1.0],
        _ => [1.0, 0.0, x],
    };
    c.map(|v| (40.0 + 215.0 * v) / 255.0)
}

/// Twin of `cholesky_solve6()` (shared/linear_solve.wgsl): the solution of `s x = y` for the
/// symmetric row-major 6 × 6 `s`, or `None` when a pivot is not above `min_pivot`.
pub fn cholesky_solve6(s: &[f32; 36], y: &[f32; 6], min_pivot: f32) -> Option<[f32; 6]> {
    let mut l = [0.0f32; 36];
    for j in 0..6 {
        let mut diag = s[j * 7];
        for k in 0..j {
            diag -= l[j * 6 + k] * l[j * 6 + k];
        }
        if !(diag > min_pivot) {
            return None;
        }
        let ljj = diag.sqrt();
        l[j * 7] = ljj;
        for i in j + 1..6 {
            let mut v = s[i * 6 + j];
            for k in 0..j {
                v -= l[i * 6 + k] * l[j * 6 + k];
            }
            l[i * 6 + j] = v / ljj;
        }
    }
    let mut g = [0.0f32; 6];
    for i in 0..6 {
        let mut v = y[i];
        for k in 0..i {
            v -= l[i * 6 + k] * g[k];
        }
        g[i] = v / l[i * 7];
    }
    let mut x = [0.0f32; 6];
    for i in (0..6).rev() {
        let mut v = g[i];
        for k in i + 1..6 {
            v -= l[k * 6 + i] * x[k];
        }
        x[i] = v / l[i * 7];
    }
    Some(x)
}
