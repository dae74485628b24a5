// SPDX-License-Identifier: MIT
// Marching-cubes cells and the case table. A cell is the cube between the 8 voxel centres
// (x..x+1, y..y+1, z..z+1); there are (dim_x - 1) x (dim_y - 1) x (dim_z - 1). They are grouped
// in bricks ("blocks") of 8 x 8 x 4 = MC_CELLS_PER_BLOCK cells, so a surface touches few
// blocks; blocks are numbered x fastest over n_blocks_x x n_blocks_y x n_blocks_z, cells inside
// a block x fastest. Blocks at the far faces overhang the volume; their outside cells count as
// empty. In a sparse map, MC block i is the lower (i even) or upper half along z of pool block
// i / 2, at the coordinates `block_coords` holds (declared by the importing kernel, with
// `block_table` and `tsdf_volume` for map_lookup.wgsl); an unused pool block's key (EMPTY_KEY)
// lies past the box, so its cells count as empty too. Corner c sits at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1); bit c of the case is set
// when its TSDF is negative. Cube edge e runs along axis e / 4 from the offset given by mc_edge_start_offset.
// The table (`mc_table`, declared by the importing kernel) is generated in
// core/src/mesh/mc_table.rs: 4 words per case, word 0 = edge mask | triangle count << 12,
// words 1..2 = the triangles' cube edges as nibbles.
// Mirrors core/src/cpu/mesh/marching_cubes.rs.
#import map_lookup

const MC_BLOCK_CELLS_X: u32 = 8u;
const MC_BLOCK_CELLS_Y: u32 = 8u;
const MC_BLOCK_CELLS_Z: u32 = 4u;
const MC_CELLS_PER_BLOCK: u32 = 256u;

fn unit_u32(axis: u32) -> vec3<u32> {
    return vec3<u32>(u32(axis == 0u), u32(axis == 1u), u32(axis == 2u));
}

// First cell of block `block_ix`.
fn mc_block_origin(d: VolumeDesc, block_ix: u32, n_blocks_x: u32, n_blocks_y: u32) -> vec3<u32> {
    if d.kind == MAP_SPARSE {
        return (block_of_key(block_coords[block_ix / 2u]) << vec3<u32>(BRICK_SHIFT)) + vec3<u32>(0u, 0u, (block_ix % 2u) * MC_BLOCK_CELLS_Z);
    }
    let block = vec3<u32>(block_ix % n_blocks_x, (block_ix / n_blocks_x) % n_blocks_y, block_ix / (n_blocks_x * n_blocks_y));
    return block * vec3<u32>(MC_BLOCK_CELLS_X, MC_BLOCK_CELLS_Y, MC_BLOCK_CELLS_Z);
}

// Offset of cell `local_ix` (0..MC_CELLS_PER_BLOCK) from its block's first cell.
fn mc_local_cell(local_ix: u32) -> vec3<u32> {
    return vec3<u32>(local_ix % MC_BLOCK_CELLS_X, (local_ix / MC_BLOCK_CELLS_X) % MC_BLOCK_CELLS_Y, local_ix / (MC_BLOCK_CELLS_X * MC_BLOCK_CELLS_Y));
}

// Whether `cell` lies inside the volume (blocks at the far faces overhang it).
fn mc_cell_in_volume(d: VolumeDesc, cell: vec3<u32>) -> bool {
    return cell.x + 1u < d.dim_x && cell.y + 1u < d.dim_y && cell.z + 1u < d.dim_z;
}

// What the classification needs of one voxel word: MC_NEGATIVE (tsdf < 0), MC_UNOBSERVED
// (weight 0) and MC_NEAR (|tsdf| < 1, not truncated).
const MC_NEGATIVE: u32 = 1u;
const MC_UNOBSERVED: u32 = 2u;
const MC_NEAR: u32 = 4u;

fn mc_voxel_flags(word: u32) -> u32 {
    let t = voxel_tsdf(word);
    return select(0u, MC_NEGATIVE, t < 0.0) | select(0u, MC_UNOBSERVED, voxel_weight(word) == 0u) | select(0u, MC_NEAR, abs(t) < 1.0);
}

// Case of a cell from its corners' flags (corner c in bits 4c..4c+2), or 0 (no triangles)
// when any corner is unobserved or every corner is truncated.
fn mc_case_from_flags(corner_flags: u32) -> u32 {
    if (corner_flags & 0x22222222u) != 0u || (corner_flags & 0x44444444u) == 0u {
        return 0u;
    }
    var case_ix = 0u;
    for (var corner = 0u; corner < 8u; corner++) {
        case_ix |= ((corner_flags >> (4u * corner)) & MC_NEGATIVE) << corner;
    }
    return case_ix;
}

// Case of a cell (see mc_case_from_flags).
fn mc_cell_case(d: VolumeDesc, cell: vec3<u32>) -> u32 {
    var corner_flags = 0u;
    for (var corner = 0u; corner < 8u; corner++) {
        let word = map_word(d, cell.x + (corner & 1u), cell.y + ((corner >> 1u) & 1u), cell.z + ((corner >> 2u) & 1u));
        corner_flags |= mc_voxel_flags(word) << (4u * corner);
    }
    return mc_case_from_flags(corner_flags);
}

fn mc_case_triangle_count(case_ix: u32) -> u32 {
    return (mc_table[case_ix * 4u] >> 12u) & 7u;
}

// Cube edge of vertex `slot` = 3 * triangle + vertex of a case.
fn mc_case_edge(case_ix: u32, slot: u32) -> u32 {
    return (mc_table[case_ix * 4u + 1u + slot / 8u] >> (4u * (slot % 8u))) & 15u;
}

// Offset from the cell's base voxel of the lower end of cube edge `edge`.
fn mc_edge_start_offset(edge: u32) -> vec3<u32> {
    let axis = edge / 4u;
    let k = edge % 4u;
    return unit_u32((axis + 1u) % 3u) * (k & 1u) + unit_u32((axis + 2u) % 3u) * (k >> 1u);
}
